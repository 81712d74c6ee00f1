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

/// Greedy colouring of a graph on the vertices `0..n`, in vertex order: each vertex takes the
/// smallest colour that none of its neighbours coloured before it holds. `neighbours(v, visit)`
/// calls `visit` on each neighbour of `v` (`v` itself may be among them). Returns each vertex's
/// colour and the number of colours.
pub(crate) fn greedy_colouring(
    n: usize,
    mut neighbours: impl FnMut(usize, &mut dyn FnMut(usize)),
) -> (Vec<usize>, usize) {
    let mut colour = vec![usize::MAX; n];
    // taken[c] == v + 1: a neighbour of vertex v holds colour c.
    let mut taken: Vec<usize> = Vec::new();
    for v in 0..n {
        neighbours(v, &mut |u| {
            if colour[u] != usize::MAX {
                taken[colour[u]] = v + 1;
            }
        });
        let c = (0..taken.len())
            .find(|&c| taken[c] != v + 1)
            .unwrap_or(taken.len());
        if c == taken.len() {
            taken.push(0);
        }
        colour[v] = c;
    }
    let count = taken.len();
    (colour, count)
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn greedy_colouring_alternates_along_a_path_and_never_shares_a_colour_across_an_edge() {
        let a = path_matrix(9);
        let neighbours = |v: usize, visit: &mut dyn FnMut(usize)| {
            a.symbolic()
                .row_idx_of_col_raw(v)
                .iter()
                .for_each(|&u| visit(u));
        };
        let (colour, count) = greedy_colouring(9, neighbours);
        assert_eq!(count, 2);
        assert_eq!(colour, vec![0, 1, 0, 1, 0, 1, 0, 1, 0]);
        // A triangle with a tail: three colours, the tail vertex reusing colour 0.
        let edges = [(0, 1), (1, 2), (0, 2), (2, 3)];
        let (colour, count) = greedy_colouring(4, |v, visit| {
            for &(p, q) in &edges {
                if p == v {
                    visit(q);
                } else if q == v {
                    visit(p);
                }
            }
        });
        assert_eq!((colour, count), (vec![0, 1, 2, 0], 3));
    }
}
