//! Sparse Cholesky factors of `A` restricted to each column's support, computed in parallel.

use faer::linalg::solvers::Solve;
use faer::sparse::linalg::solvers::Llt;
use faer::sparse::SymbolicSparseColMat;
use faer::MatMut;
use rayon::prelude::*;

use crate::error::{SkinError, SkinResult};
use crate::sparse::{cholesky, Csc};

/// Cholesky factor of `A` restricted to one column's support `idx` (sorted free-row indices).
pub(super) struct SupportFactor {
    pub idx: Vec<usize>,
    llt: Option<Llt<usize, f64>>,
}

impl SupportFactor {
    fn new(a: &Csc, idx: Vec<usize>) -> SkinResult<Self> {
        if idx.is_empty() {
            return Ok(SupportFactor { idx, llt: None });
        }
        let mut pos = vec![usize::MAX; a.nrows()];
        for (k, &i) in idx.iter().enumerate() {
            pos[i] = k;
        }
        // Only the lower triangle is read by the factorisation. `A`'s rows are sorted and `pos`
        // is increasing on `idx`, so the submatrix is built column by column in CSC order,
        // without the sort that assembling from triplets costs.
        let k = idx.len();
        let (mut col_ptr, mut row_idx, mut val) = (Vec::with_capacity(k + 1), vec![], vec![]);
        col_ptr.push(0);
        for &j in &idx {
            let rows = a.symbolic().row_idx_of_col_raw(j);
            for (&i, &v) in rows.iter().zip(a.val_of_col(j)) {
                if i >= j && pos[i] != usize::MAX {
                    row_idx.push(pos[i]);
                    val.push(v);
                }
            }
            col_ptr.push(row_idx.len());
        }
        let sub = Csc::new(
            SymbolicSparseColMat::new_checked(k, k, col_ptr, None, row_idx),
            val,
        );
        // A principal submatrix of the SPD `A` is SPD, so this fails only on round-off.
        let llt = cholesky(&sub)
            .map_err(|e| SkinError::Numerical(format!("Cholesky of a support block: {e}")))?;
        Ok(SupportFactor {
            idx,
            llt: Some(llt),
        })
    }

    /// `A_FF^{-1} x[F]`, as a vector over `F`.
    pub fn solve_gathered(&self, x: &[f64]) -> Vec<f64> {
        let mut r: Vec<f64> = self.idx.iter().map(|&i| x[i]).collect();
        if let Some(llt) = &self.llt {
            let k = r.len();
            llt.solve_in_place(MatMut::from_column_major_slice_mut(&mut r, k, 1));
        }
        r
    }
}

/// Factors `A` on every column's support (`support[j * nf + i]`), in parallel over columns,
/// largest support first.
pub(super) fn factor_supports(
    a: &Csc,
    support: &[bool],
    nf: usize,
) -> SkinResult<Vec<SupportFactor>> {
    let columns: Vec<&[bool]> = support.chunks(nf).collect();
    let sizes: Vec<usize> = columns
        .par_iter()
        .map(|col| col.iter().filter(|&&s| s).count())
        .collect();
    longest_first(&sizes, |j| {
        let idx = (0..nf).filter(|&i| columns[j][i]).collect();
        SupportFactor::new(a, idx)
    })
    .into_iter()
    .collect()
}

/// `[f(0), ..., f(n - 1)]`, computed on the rayon pool longest job first: each worker takes the
/// next index in decreasing `cost` (greedy list scheduling). The columns' supports differ in
/// size by 2-3x, and an even split of the columns over the threads leaves one idle.
pub(super) fn longest_first<T: Send>(cost: &[usize], f: impl Fn(usize) -> T + Sync) -> Vec<T> {
    use std::sync::atomic::{AtomicUsize, Ordering};
    use std::sync::Mutex;
    let mut order: Vec<usize> = (0..cost.len()).collect();
    order.sort_by_key(|&i| std::cmp::Reverse(cost[i]));
    let next = AtomicUsize::new(0);
    let slots: Vec<Mutex<Option<T>>> = (0..cost.len()).map(|_| Mutex::new(None)).collect();
    let workers = rayon::current_num_threads().min(cost.len());
    rayon::scope(|s| {
        for _ in 0..workers {
            s.spawn(|_| {
                while let Some(&i) = order.get(next.fetch_add(1, Ordering::Relaxed)) {
                    let out = f(i);
                    if let Ok(mut slot) = slots[i].lock() {
                        *slot = Some(out);
                    }
                }
            });
        }
    });
    // The workers take every index once (a panic in `f` propagates out of the scope).
    slots
        .into_iter()
        .map(|s| {
            s.into_inner()
                .ok()
                .flatten()
                .expect("every index is computed")
        })
        .collect()
}
