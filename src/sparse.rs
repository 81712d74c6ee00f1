//! Small helpers around `faer` sparse matrices used across capabilities.

use faer::sparse::{SparseColMat, Triplet};

use crate::error::{SkinError, SkinResult};

mod llt_plan;
mod tree_llt;
pub(crate) use llt_plan::{LltPlan, SparseLlt};
pub(crate) use tree_llt::TreeLlt;

/// Compressed sparse column matrix with `usize` indices, the crate's one sparse type.
pub type Csc = SparseColMat<usize, f64>;

/// Assembles an `nrows x ncols` matrix from (row, col, value) triplets; duplicates are summed.
pub fn from_triplets(
    nrows: usize,
    ncols: usize,
    triplets: &[Triplet<usize, usize, f64>],
) -> SkinResult<Csc> {
    SparseColMat::try_new_from_triplets(nrows, ncols, triplets)
        .map_err(|e| SkinError::Numerical(format!("sparse assembly failed: {e:?}")))
}

/// Diagonal matrix with the given entries.
pub fn diagonal(d: &[f64]) -> SkinResult<Csc> {
    let t: Vec<_> = d
        .iter()
        .enumerate()
        .map(|(i, &x)| Triplet::new(i, i, x))
        .collect();
    from_triplets(d.len(), d.len(), &t)
}
/// The tridiagonal `[-1 2 -1]` matrix of a path graph `0 - 1 - ... - (n-1)` (a test fixture).
#[cfg(test)]
pub(crate) fn path_matrix(n: usize) -> Csc {
    let mut trip = Vec::new();
    for i in 0..n {
        trip.push(Triplet::new(i, i, 2.0));
        if i + 1 < n {
            trip.push(Triplet::new(i, i + 1, -1.0));
            trip.push(Triplet::new(i + 1, i, -1.0));
        }
    }
    from_triplets(n, n, &trip).unwrap()
}
