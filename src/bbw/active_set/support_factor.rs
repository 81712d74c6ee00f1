//! Sparse Cholesky factors of `A` restricted to each column's support, computed in parallel
//! once their symbolic analyses say that they fit the memory budget.

use std::sync::Mutex;
use std::time::Instant;

use faer::sparse::SymbolicSparseColMat;
use faer::Par;
use rayon::prelude::*;

use crate::bbw::options::{BbwInfo, BbwOptions};
use crate::bbw::problem::EliminatedProblem;
use crate::error::{SkinError, SkinResult};
use crate::heap::return_free_memory;
use crate::sparse::{Csc, LltPlan, SparseLlt};

/// Cholesky factor of `A` restricted to one column's support `idx` (sorted free-row indices).
pub(super) struct SupportFactor {
    pub idx: Vec<usize>,
    llt: Option<SparseLlt>,
}

impl SupportFactor {
    /// `A_FF^{-1} x[F]`, as a vector over `F`.
    pub fn solve_gathered(&self, x: &[f64]) -> Vec<f64> {
        let mut r: Vec<f64> = self.idx.iter().map(|&i| x[i]).collect();
        if let Some(llt) = &self.llt {
            llt.solve_in_place(&mut r);
        }
        r
    }
}

/// One column's support `F` with the symbolic analysis of its block `A_FF`, which says the
/// factor's size before it is allocated. The block itself is gathered again to be factored:
/// held for every column at once between the two steps, the blocks raised the peak resident
/// size of the 85k armadillo of `bench scale` by 70 MiB (1,140 MB of factors).
struct SupportPlan {
    idx: Vec<usize>,
    plan: Option<LltPlan>,
}

impl SupportPlan {
    fn new(a: &Csc, idx: Vec<usize>) -> SkinResult<Self> {
        if idx.is_empty() {
            return Ok(SupportPlan { idx, plan: None });
        }
        let plan = LltPlan::new(&lower_block(a, &idx)).map_err(failed)?;
        Ok(SupportPlan {
            idx,
            plan: Some(plan),
        })
    }

    fn factor_bytes(&self) -> usize {
        self.plan.as_ref().map_or(0, LltPlan::factor_bytes)
    }

    fn factor(self, a: &Csc, par: Par) -> SkinResult<SupportFactor> {
        let llt = match self.plan {
            Some(plan) => {
                let block = lower_block(a, &self.idx);
                Some(plan.factor_with(&block, par).map_err(failed)?)
            }
            None => None,
        };
        Ok(SupportFactor { idx: self.idx, llt })
    }
}

/// A principal submatrix of the SPD `A` is SPD, so its factorisation fails only on round-off.
fn failed(e: String) -> SkinError {
    SkinError::Numerical(format!("Cholesky of a support block: {e}"))
}

/// The lower triangle of `A` on the rows and columns `idx` (sorted). `A`'s rows are sorted and
/// the new indices increase along `idx`, so the block is built column by column in CSC order,
/// without the sort that assembling from triplets costs.
fn lower_block(a: &Csc, idx: &[usize]) -> Csc {
    let mut pos = vec![usize::MAX; a.nrows()];
    for (k, &i) in idx.iter().enumerate() {
        pos[i] = k;
    }
    let k = idx.len();
    let (mut col_ptr, mut row_idx, mut val) = (Vec::with_capacity(k + 1), vec![], vec![]);
    col_ptr.push(0);
    for &j in idx {
        let rows = a.symbolic().row_idx_of_col_raw(j);
        // The lower triangle: the rows from j on.
        let from = rows.partition_point(|&i| i < j);
        for (&i, &v) in rows[from..].iter().zip(&a.val_of_col(j)[from..]) {
            if pos[i] != usize::MAX {
                row_idx.push(pos[i]);
                val.push(v);
            }
        }
        col_ptr.push(row_idx.len());
    }
    Csc::new(
        SymbolicSparseColMat::new_checked(k, k, col_ptr, None, row_idx),
        val,
    )
}

/// [`factor_supports`] within what `opts.memory_limit` leaves besides `A`'s factor and the
/// solve's vectors, timed and with the factors' bytes recorded in `info`; `None` when they do
/// not fit.
pub(super) fn factor_within_limit(
    prob: &EliminatedProblem,
    opts: &BbwOptions,
    support: &[bool],
    info: &mut BbwInfo,
) -> SkinResult<Option<Vec<SupportFactor>>> {
    let t = Instant::now();
    // The last round's factors are gone; their pages go back before the new ones are allocated.
    return_free_memory();
    let held = prob
        .factor_bytes
        .saturating_add(opts.vector_bytes(prob.nf(), prob.m));
    let budget = opts.memory_limit.saturating_sub(held);
    let outcome = factor_supports(&prob.a, support, prob.nf(), budget)?;
    info.time_support_factor += t.elapsed().as_secs_f64();
    Ok(match outcome {
        Supports::Factored { factors, bytes } => {
            info.support_factor_bytes = info.support_factor_bytes.max(bytes);
            Some(factors)
        }
        Supports::OverBudget { bytes } => {
            info.support_factor_bytes = info.support_factor_bytes.max(bytes);
            None
        }
    })
}

/// The support factors of one round, or the bytes they would take beyond the budget.
enum Supports {
    Factored {
        factors: Vec<SupportFactor>,
        bytes: usize,
    },
    OverBudget {
        bytes: usize,
    },
}

/// Factors `A` on every column's support (`support[j * nf + i]`), in parallel over columns,
/// largest support first, unless the factors would take more than `budget` bytes: the solve
/// holds them all at once (CG on `mu` needs every column's solve in each iteration), so that
/// is decided from the symbolic analyses before any factor is allocated.
fn factor_supports(a: &Csc, support: &[bool], nf: usize, budget: usize) -> SkinResult<Supports> {
    let columns: Vec<&[bool]> = support.chunks(nf).collect();
    let sizes: Vec<usize> = columns
        .par_iter()
        .map(|col| col.iter().filter(|&&s| s).count())
        .collect();
    let plans = longest_first(&sizes, |j| {
        let idx = (0..nf).filter(|&i| columns[j][i]).collect();
        SupportPlan::new(a, idx).map(|p| Mutex::new(Some(p)))
    })
    .into_iter()
    .collect::<SkinResult<Vec<_>>>()?;
    let bytes = plans
        .iter()
        .filter_map(|p| p.lock().ok()?.as_ref().map(SupportPlan::factor_bytes))
        .fold(0usize, usize::saturating_add);
    if bytes > budget {
        return Ok(Supports::OverBudget { bytes });
    }
    // The smallest block is factored last, while the other threads run out of blocks: its
    // factorisation may use them (faer's parallel supernodal factorisation gives the same
    // values as its sequential one). With 3 columns on 2 threads a thread was otherwise idle
    // for a third of each round.
    let last = (0..sizes.len()).min_by_key(|&j| sizes[j]);
    let factors = longest_first(&sizes, |j| {
        let plan = plans[j].lock().ok().and_then(|mut p| p.take());
        let par = if Some(j) == last {
            Par::rayon(0)
        } else {
            Par::Seq
        };
        plan.expect("each plan is factored once").factor(a, par)
    })
    .into_iter()
    .collect::<SkinResult<_>>()?;
    // The blocks gathered and freed while factoring go back before CG and the dual's vectors.
    return_free_memory();
    Ok(Supports::Factored { factors, bytes })
}

/// `[f(0), ..., f(n - 1)]`, computed on the rayon pool longest job first: each worker takes the
/// next index in decreasing `cost` (greedy list scheduling). The columns' supports differ in
/// size by 2-3x, and an even split of the columns over the threads leaves one idle.
pub(super) fn longest_first<T: Send>(cost: &[usize], f: impl Fn(usize) -> T + Sync) -> Vec<T> {
    use std::sync::atomic::{AtomicUsize, Ordering};
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
