//! The dual problems and their certificates.
//!
//! With partition of unity (eq. 12): `f(Y) = 1/2 tr(P_m Y^T Q11 Y) + tr(R^T Y)`, `Y >= 0`, where
//! `Q11 = A^{-1}` on the free rows and `R = W0`. Its gradient (eq. 16) is the recovered primal
//! `W(Y) = W0 + A^{-1} Y P_m` (eq. 15).
//!
//! Without partition of unity but with `W <= 1` (App. B, eq. B6): variables `Y, U >= 0`,
//! `f(Y, U) = 1/2 <Y - U, A^{-1}(Y - U)> + <W0, Y - U> + sum U`, `W = W0 + A^{-1}(Y - U)`.
//!
//! Both are certified by a duality gap: the Lagrangian at the dual point is a lower bound on the
//! primal optimum, and the projection of `W` onto the primal feasible set (clamp, and renormalise
//! rows for partition of unity) is an upper bound.

use rayon::prelude::*;

use super::problem::EliminatedProblem;
use super::vector::dot;

/// One evaluation of a dual: objective, the recovered primal `W` (= gradient w.r.t. `Y`) and what
/// its lower bound needs besides `W`'s energy.
pub struct DualPoint {
    /// Dual objective `f` (to be minimised).
    pub objective: f64,
    /// Recovered primal free rows `W`, `nf x m` column-major (may be slightly infeasible).
    pub w: Vec<f64>,
    /// The Lagrangian's multiplier terms at `W`: the lower bound is `E(W) - multiplier_terms`.
    multiplier_terms: f64,
}

impl DualPoint {
    /// The Lagrangian at this dual point, a lower bound on the optimal energy. It costs an
    /// energy evaluation, so the dual's evaluations leave it to the certificates that need it.
    pub fn lower_bound(&self, p: &EliminatedProblem) -> f64 {
        // `E` is evaluated from W itself rather than through `A W = -G + Y P_m`: that shortcut
        // sums terms as large as B's entries (see `energy`).
        p.energy(&self.w) - self.multiplier_terms
    }
}

/// Evaluates the partition-of-unity dual at `y` (`nf x m`, `y >= 0`).
pub fn pou_eval(p: &EliminatedProblem, y: &[f64]) -> DualPoint {
    let (nf, m) = (p.nf(), p.m);
    // Y P_m: subtract each row's mean (eq. 13).
    let mut mean = vec![0.0; nf];
    for col in y.chunks(nf) {
        mean.par_iter_mut().zip(col).for_each(|(a, v)| *a += v);
    }
    mean.par_iter_mut().for_each(|a| *a /= m as f64);
    let mut x = vec![0.0; nf * m];
    x.par_chunks_mut(nf)
        .zip(y.par_chunks(nf))
        .for_each(|(xc, yc)| {
            xc.iter_mut()
                .zip(yc.iter().zip(&mean))
                .for_each(|(x, (y, a))| *x = y - a);
        });
    // x = Q11 Y P_m. The rows of Y P_m sum to zero, so those of x do too: the last column is
    // minus the sum of the others, and the solve needs only m - 1 right-hand sides.
    let (head, last) = x.split_at_mut(nf * (m - 1));
    p.solve_in_place(head);
    last.par_iter_mut().enumerate().for_each(|(i, v)| {
        *v = -(0..m - 1).map(|j| head[j * nf + i]).sum::<f64>();
    });
    let objective = 0.5 * dot(y, &x) + dot(y, &p.w0);
    // W(Y) = W0 + x, formed in place: at scale each `nf x m` vector is tens of MB.
    let mut w = x;
    w.par_iter_mut().zip(&p.w0).for_each(|(v, a)| *v += a);
    // The Lagrangian `E(W) - <Y, W>` at its minimiser W(Y) over the partition-of-unity plane.
    let multiplier_terms = dot(&w, y);
    DualPoint {
        objective,
        w,
        multiplier_terms,
    }
}

/// Evaluates the box dual (no partition of unity) at `y, u` (each `nf x m`, `>= 0`).
pub fn box_eval(p: &EliminatedProblem, y: &[f64], u: &[f64]) -> DualPoint {
    let mut x: Vec<f64> = y.iter().zip(u).map(|(a, b)| a - b).collect();
    let ymu = x.clone();
    p.solve_in_place(&mut x);
    let w: Vec<f64> = p.w0.iter().zip(&x).map(|(a, b)| a + b).collect();
    let usum: f64 = u.iter().sum();
    let objective = 0.5 * dot(&ymu, &x) + dot(&p.w0, &ymu) + usum;
    // The Lagrangian `E(W) - <Y - U, W> - sum U` at its minimiser W.
    let multiplier_terms = dot(&w, &ymu) + usum;
    DualPoint {
        objective,
        w,
        multiplier_terms,
    }
}

/// Projects recovered weights onto the partition-of-unity feasible set: clamp below at 0 and
/// renormalise each row (the paper's post-processing, Sec. 8). A row with no positive entry
/// becomes uniform (a feasible, if poor, point).
pub fn project_pou(w: &[f64], nf: usize, m: usize) -> Vec<f64> {
    let mut out: Vec<f64> = w.iter().map(|x| x.max(0.0)).collect();
    for i in 0..nf {
        let s: f64 = (0..m).map(|c| out[c * nf + i]).sum();
        for c in 0..m {
            out[c * nf + i] = if s > 0.0 {
                out[c * nf + i] / s
            } else {
                1.0 / m as f64
            };
        }
    }
    out
}

/// Projects onto the box `0 <= W <= 1`.
pub fn project_box(w: &[f64]) -> Vec<f64> {
    w.iter().map(|x| x.clamp(0.0, 1.0)).collect()
}
