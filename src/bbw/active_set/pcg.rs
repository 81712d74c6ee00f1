//! Preconditioned conjugate gradients on the partition-of-unity system `S mu = r`.

use crate::bbw::problem::EliminatedProblem;
use crate::bbw::vector::dot;
use crate::error::SkinResult;
use crate::progress::{Event, Progress};

/// `rowsum(W) - 1` for the `nf x m` column-major `w`.
pub(super) fn row_sums_minus_one(w: &[f64], nf: usize, m: usize) -> Vec<f64> {
    let mut r = vec![-1.0; nf];
    for col in w.chunks(nf).take(m) {
        r.iter_mut().zip(col).for_each(|(ri, wi)| *ri += wi);
    }
    r
}

/// Preconditioned conjugate gradients for `S x = b` from `x = 0`, preconditioner `A / m`; stops
/// when `max |b - S x| <= tol` (a partition-of-unity violation, so an absolute weight error).
/// `apply_s(p)` returns `S p` and what its caller keeps of the product (`T`), handed back as
/// `step(alpha, &T)` when `x` moves by `alpha p`.
pub(super) fn pcg<T>(
    prob: &EliminatedProblem,
    apply_s: impl Fn(&[f64]) -> (Vec<f64>, T),
    mut step: impl FnMut(f64, &T),
    b: &[f64],
    tol: f64,
    progress: &mut dyn Progress,
) -> SkinResult<(Vec<f64>, usize)> {
    let n = b.len();
    // Scaling a preconditioner does not change CG's iterates; `A / m` keeps `z` at the scale
    // of `x`.
    let inv_m = 1.0 / prob.m as f64;
    let precondition = |r: &[f64]| -> Vec<f64> {
        let mut z = prob.apply_a(r);
        z.iter_mut().for_each(|v| *v *= inv_m);
        z
    };
    let max_abs = |v: &[f64]| v.iter().fold(0.0f64, |a, x| a.max(x.abs()));
    let mut x = vec![0.0; n];
    let mut r = b.to_vec();
    if max_abs(&r) <= tol {
        return Ok((x, 0));
    }
    let mut z = precondition(&r);
    let mut p = z.clone();
    let mut rz = dot(&r, &z);
    // CG on an SPD system of size n converges in n steps in exact arithmetic; far fewer here.
    for it in 1..=n.max(1) {
        let (q, aux) = apply_s(&p);
        let pq = dot(&p, &q);
        if pq.is_nan() || pq <= 0.0 {
            return Ok((x, it)); // round-off has taken over: keep what we have
        }
        let alpha = rz / pq;
        x.iter_mut().zip(&p).for_each(|(xi, pi)| *xi += alpha * pi);
        step(alpha, &aux);
        r.iter_mut().zip(&q).for_each(|(ri, qi)| *ri -= alpha * qi);
        progress.report(Event {
            stage: "active-set cg",
            iteration: it,
            value: max_abs(&r),
        })?;
        if max_abs(&r) <= tol {
            return Ok((x, it));
        }
        z = precondition(&r);
        let rz_new = dot(&r, &z);
        let beta = rz_new / rz;
        rz = rz_new;
        p.iter_mut()
            .zip(&z)
            .for_each(|(pi, zi)| *pi = zi + beta * *pi);
    }
    Ok((x, n))
}
