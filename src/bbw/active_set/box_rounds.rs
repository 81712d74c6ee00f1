//! Rounds of the box-constrained active-set method (no partition of unity, App. A).

use rayon::prelude::*;

use super::spread::spread_negative;
use super::stall::{Outcome, StallWatch, MAX_ROUNDS, STALL_ROUNDS};
use super::support_factor::factor_within_limit;
use crate::bbw::bounds::CertifiedBounds;
use crate::bbw::dual::{box_eval, project_box};
use crate::bbw::options::{BbwInfo, BbwOptions};
use crate::bbw::problem::EliminatedProblem;
use crate::error::SkinResult;
use crate::progress::{Event, Progress};

/// Rounds of the box-constrained active-set method (no partition of unity, App. A): each column
/// is an independent QP with `0 <= w_j <= 1`, solved exactly on its free set.
pub(super) fn box_rounds(
    prob: &EliminatedProblem,
    opts: &BbwOptions,
    w: &[f64],
    best: &mut CertifiedBounds,
    info: &mut BbwInfo,
    progress: &mut dyn Progress,
) -> SkinResult<Outcome> {
    let (nf, m) = (prob.nf(), prob.m);
    // state: 0 free, 1 at the lower bound, 2 at the upper bound.
    let mut state: Vec<u8> = w
        .iter()
        .map(|&x| {
            if x <= 0.0 {
                1
            } else if x >= 1.0 {
                2
            } else {
                0
            }
        })
        .collect();
    let mut watch = StallWatch::new(best.relative_gap());
    // The last round's dual point `(Y, U)`, for L-BFGS when the next round's factors do not fit.
    let mut last_dual: Option<Vec<f64>> = None;
    for round in 0..opts.max_iter.min(MAX_ROUNDS) {
        let free: Vec<bool> = state.iter().map(|&s| s == 0).collect();
        let Some(factors) = factor_within_limit(prob, opts, &free, info)? else {
            return Ok(Outcome::OverBudget(last_dual));
        };
        info.rounds += 1;
        // w_j: 1 on the upper set, A_FF^{-1}(-g - A_FU 1) on the free set, 0 elsewhere.
        let upper_ind: Vec<f64> = state.iter().map(|&s| f64::from(s == 2)).collect();
        let a_upper = prob.apply_a(&upper_ind);
        let cols: Vec<Vec<f64>> = factors
            .par_iter()
            .enumerate()
            .map(|(j, f)| {
                let rhs: Vec<f64> = (0..nf)
                    .map(|i| -prob.g[j * nf + i] - a_upper[j * nf + i])
                    .collect();
                f.solve_gathered(&rhs)
            })
            .collect();
        let mut w = upper_ind;
        for (j, (f, col)) in factors.iter().zip(&cols).enumerate() {
            for (&i, &v) in f.idx.iter().zip(col) {
                w[j * nf + i] = v;
            }
        }
        let aw = prob.apply_a(&w);
        let mut y = vec![0.0; nf * m]; // multipliers of w >= 0
        let mut u = vec![0.0; nf * m]; // multipliers of w <= 1
        let mut scale: f64 = 1.0;
        let mut changes = 0usize;
        for k in 0..nf * m {
            let grad = aw[k] + prob.g[k];
            scale = scale.max(grad.abs());
            match state[k] {
                1 => y[k] = grad,
                2 => u[k] = -grad,
                _ => {}
            }
        }
        for k in 0..nf * m {
            let new = match state[k] {
                0 if w[k] < -1e-12 => 1,
                0 if w[k] > 1.0 + 1e-12 => 2,
                1 | 2 if y[k] < -1e-12 * scale || u[k] < -1e-12 * scale => 0,
                s => s,
            };
            if new != state[k] {
                changes += 1;
                state[k] = new;
            }
        }
        let feasible = project_box(&w);
        let upper = prob.energy(&feasible);
        best.offer(&w, feasible, upper);
        // Spread, not clamped (see `spread_negative`): a clamped lower bound lags, the gap
        // stalls and an L-BFGS fallback has to finish.
        spread_negative(&mut y, &prob.a, nf);
        spread_negative(&mut u, &prob.a, nf);
        let dp = box_eval(prob, &y, &u);
        best.bound(&dp, dp.lower_bound(prob));
        progress.report(Event {
            stage: "active-set",
            iteration: round,
            value: best.relative_gap(),
        })?;
        // The columns are cheap to solve exactly, so iterate to the exact optimum: a small gap
        // alone does not pin down weights where the energy is flat.
        if changes == 0 {
            return Ok(Outcome::Done);
        }
        y.extend_from_slice(&u);
        if watch.stalled(best.relative_gap(), STALL_ROUNDS) {
            if best.relative_gap() <= opts.tol {
                return Ok(Outcome::Done); // certified; the last swaps only cycle at round-off
            }
            return Ok(Outcome::Stalled(y));
        }
        last_dual = Some(y);
    }
    Ok(Outcome::Done)
}
