//! Small helpers around `faer` sparse matrices used across capabilities.

use faer::sparse::{SparseColMat, Triplet};

use crate::error::{SkinError, SkinResult};

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
