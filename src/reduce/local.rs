//! The local iteration of Sec. 3.1: block Gauss-Seidel (optionally over-relaxed) over the
//! colour classes of `Q`, every class in parallel, each vertex's block an exact `k`-variable QP.

use ndarray::Array2;
use rayon::prelude::*;
use std::sync::atomic::{AtomicUsize, Ordering};

use crate::error::{SkinError, SkinResult};
use crate::progress::Progress;

use super::basis::Basis;
use super::blocks::FastOps;
use super::iteration::{record, should_stop, SolveOptions, SolveReport};
use super::problem::{qp_error, Problem, Scratch};

/// Rows of `E (n, q)` during the update of one class `[start, end)`: the class's own rows are
/// borrowed mutably, all others (which no vertex of the class changes) shared.
struct Rows<'e> {
    before: &'e [f64],
    after: &'e [f64],
    start: usize,
    end: usize,
    q: usize,
}

impl Rows<'_> {
    /// Row `u`, which must lie outside the class.
    #[inline]
    fn get(&self, u: usize) -> &[f64] {
        let q = self.q;
        if u < self.start {
            &self.before[u * q..(u + 1) * q]
        } else {
            let o = u - self.end;
            &self.after[o * q..(o + 1) * q]
        }
    }
}

impl Problem<'_> {
    /// Updates vertex `vi` in place: `alpha_v (k)` and its error row `e_v (q)`, reading the rows
    /// of its `Q`-neighbours (other classes) from `others`.
    ///
    /// With all other vertices fixed, the objective in `alpha_v` is
    /// `Q_vv |B alpha|^2 + 2 alpha^T B^T (R_v - Q_vv x_v) + const`, `R = Q E`.
    #[allow(clippy::too_many_arguments)]
    fn local_update(
        &self,
        vi: usize,
        alpha_v: &mut [f64],
        e_v: &mut [f64],
        others: &Rows,
        omega: f64,
        fast: Option<&FastOps>,
        sc: &mut Scratch,
    ) -> SkinResult<bool> {
        let k = self.k();
        let q = self.basis.q();
        let c = &self.coupling;
        let set = self.sets.row(vi);
        let set = set.as_slice().expect("sets are standard layout");
        // g = B^T R_v, R_v = sum_u Q_vu e_u.
        match self.basis {
            Basis::Select { .. } => {
                for (t, &i) in set.iter().enumerate() {
                    let mut r = 0.0;
                    for p in c.col(vi) {
                        let u = c.rows[p];
                        let eu = if u == vi { e_v[i] } else { others.get(u)[i] };
                        r += c.val[p] * eu;
                    }
                    sc.g[t] = r;
                }
            }
            _ => {
                sc.r.iter_mut().for_each(|x| *x = 0.0);
                for p in c.col(vi) {
                    let u = c.rows[p];
                    let eu: &[f64] = if u == vi { e_v } else { others.get(u) };
                    let qv = c.val[p];
                    for (r, x) in sc.r.iter_mut().zip(eu) {
                        *r += qv * x;
                    }
                }
                self.basis.fill(vi, set, &mut sc.b);
                for t in 0..k {
                    sc.g[t] = sc.b[t * q..(t + 1) * q]
                        .iter()
                        .zip(&sc.r)
                        .map(|(a, b)| a * b)
                        .sum();
                }
            }
        }
        // Fast path: the block minimiser under the equality rows alone is
        // alpha_old - P_v B^T R_v (B^T R_v is the block gradient at alpha_old); when it is
        // non-negative (or bounds are off) it is the exact solution of the local QP.
        let mut converged = true;
        let fast_done = match fast {
            Some(ops) if ops.ok[vi] => {
                let pv = &ops.p[vi * k * k..(vi + 1) * k * k];
                for a in 0..k {
                    let d: f64 = (0..k).map(|b| pv[a * k + b] * sc.g[b]).sum();
                    sc.x[a] = alpha_v[a] - d;
                }
                // Keep the sum exactly on 1 (rounding would otherwise drift over many sweeps).
                let shift = (sc.x.iter().sum::<f64>() - 1.0) / k as f64;
                sc.x.iter_mut().for_each(|x| *x -= shift);
                !self.nonneg || sc.x.iter().all(|&x| x >= 0.0)
            }
            _ => false,
        };
        if !fast_done {
            self.local_hessian(vi, set, &mut sc.gram, &mut sc.h);
            for a in 0..k {
                let ha: f64 = (0..k).map(|b| sc.h[a * k + b] * alpha_v[b]).sum();
                sc.g[a] -= ha;
            }
            self.equality(vi, &mut sc.e_mat, &mut sc.e_rhs);
            converged = sc
                .solve_qp(alpha_v, self.nonneg)
                .map_err(|e| qp_error(self.order[vi], e))?
                .converged;
        }
        // Over-relaxation along the block step, shortened so the weights stay non-negative.
        // Any step in (0, 2) of the exact block minimiser decreases the block's quadratic.
        let mut t = omega;
        if self.nonneg {
            for (a, x) in alpha_v.iter().zip(&sc.x) {
                let d = x - a;
                if d < 0.0 {
                    t = t.min(a / -d);
                }
            }
        }
        for (tcol, (a, x)) in alpha_v.iter_mut().zip(&sc.x).enumerate() {
            let mut new = *a + t * (x - *a);
            if self.nonneg && new < 0.0 {
                new = 0.0;
            }
            let da = new - *a;
            *a = new;
            if da != 0.0 {
                match self.basis {
                    Basis::Select { .. } => e_v[set[tcol]] += da,
                    _ => {
                        for (x, bq) in e_v.iter_mut().zip(&sc.b[tcol * q..(tcol + 1) * q]) {
                            *x += da * bq;
                        }
                    }
                }
            }
        }
        Ok(converged)
    }

    /// The local iteration of Sec. 3.1: sweeps over the colour classes, every class in parallel.
    pub(super) fn solve_local(
        &self,
        alpha: &mut Array2<f64>,
        opts: &SolveOptions,
        fast: Option<&FastOps>,
        decoupled: bool,
        progress: &mut dyn Progress,
    ) -> SkinResult<SolveReport> {
        let k = self.k();
        let q = self.basis.q();
        let r_rows = self.rows();
        let mut e = self.error(alpha.view());
        let mut history = Vec::new();
        record(&mut history, self.objective(&e), progress)?;
        let capped = AtomicUsize::new(0);
        let mut converged = false;
        // Decoupled vertices: the exact block minimiser (no over-relaxation) in one sweep.
        let omega = if decoupled { 1.0 } else { opts.relaxation };
        let max_sweeps = if decoupled {
            opts.max_sweeps.min(1)
        } else {
            opts.max_sweeps
        };
        for sweep in 1..=max_sweeps {
            let a_all = alpha
                .as_slice_mut()
                .ok_or_else(|| SkinError::Numerical("weights not contiguous".into()))?;
            for w in self.classes.windows(2) {
                let (start, end) = (w[0], w[1]);
                let (before, rest) = e.split_at_mut(start * q);
                let (mine, after) = rest.split_at_mut((end - start) * q);
                let others = Rows {
                    before,
                    after,
                    start,
                    end,
                    q,
                };
                let a_mine = &mut a_all[start * k..end * k];
                mine.par_chunks_mut(q)
                    .zip(a_mine.par_chunks_mut(k))
                    .enumerate()
                    .try_for_each_init(
                        || Scratch::new(k, q, r_rows),
                        |sc, (i, (ev, av))| -> SkinResult<()> {
                            let conv =
                                self.local_update(start + i, av, ev, &others, omega, fast, sc)?;
                            if !conv {
                                capped.fetch_add(1, Ordering::Relaxed);
                            }
                            Ok(())
                        },
                    )?;
            }
            // E is updated incrementally; refresh it now and then against rounding drift.
            if sweep % 16 == 0 {
                e = self.error(alpha.view());
            }
            record(&mut history, self.objective(&e), progress)?;
            if decoupled || should_stop(&history, opts.tol) {
                converged = true;
                break;
            }
        }
        Ok(SolveReport {
            objective: history,
            converged,
            qp_capped: capped.into_inner(),
        })
    }
}
