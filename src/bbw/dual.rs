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

use super::problem::EliminatedProblem;

/// One evaluation of a dual: objective, the recovered primal `W` (= gradient w.r.t. `Y`) and the
/// certificate pieces.
pub struct DualPoint {
    /// Dual objective `f` (to be minimised).
    pub objective: f64,
    /// Recovered primal free rows `W`, `nf x m` column-major (may be slightly infeasible).
    pub w: Vec<f64>,
    /// Lower bound on the optimal energy (the Lagrangian at this dual point).
    pub lower_bound: f64,
}

/// Evaluates the partition-of-unity dual at `y` (`nf x m`, `y >= 0`).
pub fn pou_eval(p: &EliminatedProblem, y: &[f64]) -> DualPoint {
    let (nf, m) = (p.nf(), p.m);
    // Y P_m: subtract each row's mean (eq. 13).
    let mut x = y.to_vec();
    for i in 0..nf {
        let mean = (0..m).map(|c| y[c * nf + i]).sum::<f64>() / m as f64;
        for c in 0..m {
            x[c * nf + i] -= mean;
        }
    }
    p.solve_in_place(&mut x); // x = Q11 Y P_m; its rows have zero mean.
    let w: Vec<f64> = p.w0.iter().zip(&x).map(|(a, b)| a + b).collect();
    let yx: f64 = y.iter().zip(&x).map(|(a, b)| a * b).sum();
    let yw0: f64 = y.iter().zip(&p.w0).map(|(a, b)| a * b).sum();
    let objective = 0.5 * yx + yw0;
    // Lagrangian at W(Y): uses A W = -G + Y P_m, so no extra product is needed.
    let wg: f64 = w.iter().zip(&p.g).map(|(a, b)| a * b).sum();
    let wy: f64 = w.iter().zip(y).map(|(a, b)| a * b).sum();
    let ysum: f64 = y.iter().sum();
    let lower_bound = 0.5 * wg - 0.5 * wy - ysum / (2.0 * m as f64) + p.c0;
    DualPoint {
        objective,
        w,
        lower_bound,
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
    let lower_bound = 0.5 * dot(&w, &p.g) - 0.5 * dot(&w, &ymu) - usum + p.c0;
    DualPoint {
        objective,
        w,
        lower_bound,
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

pub fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}
