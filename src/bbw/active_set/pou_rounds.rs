//! Rounds of the partition-of-unity active-set method (see the parent module's docs).
//!
//! The CG tolerances below are partition-of-unity residuals (an absolute weight error)
//! accepted from [`pcg`]; only the support decisions depend on them, since the certificate is
//! computed on renormalised weights either way.

use std::time::Instant;

use rayon::prelude::*;

use super::next_support::{next_support, SignThresholds};
use super::pcg::{pcg, row_sums_minus_one};
use super::smooth::{gauss_seidel_pou, SweepPlan};
use super::spread::spread_negative;
use super::stall::{Outcome, OwnBounds, StallWatch, Watch, MAX_ROUNDS};
use super::support_factor::{factor_within_limit, longest_first};
use crate::bbw::bounds::CertifiedBounds;
use crate::bbw::dual::{pou_eval, project_pou};
use crate::bbw::options::{BbwInfo, BbwOptions};
use crate::bbw::problem::EliminatedProblem;
use crate::bbw::vector::above;
use crate::error::SkinResult;
use crate::progress::{Event, Progress};

/// CG tolerance of the first round, while the support is still far from right.
const CG_TOL_FIRST: f64 = 1e-4;
/// While KKT signs still flip, the CG tolerance is this fraction of the last round's relative
/// gap (and never rises): a decision that CG noise of a tenth of the gap could flip does not
/// move the bounds.
const CG_TOL_PER_GAP: f64 = 0.1;
/// Lower limit of that tolerance while signs flip, relative to `tol`.
const CG_TOL_SIGNS: f64 = 1.0;
/// CG tolerance relative to `tol` once every sign holds: rows are renormalised afterwards, so a
/// tighter residual changes nothing.
const CG_TOL_FINAL: f64 = 1e-2;

/// Projected Gauss-Seidel sweeps over a round's projected weights ([`gauss_seidel_pou`]):
/// each sweep moves the supports' edges by about a ring of `A`, and a round's exact solve
/// costs far more than a sweep, the more so the larger the mesh (rounds at 10, 20, 30 and 50
/// sweeps in docs/solver.md's smoother row).
const SMOOTH_SWEEPS: usize = 30;
/// Sweeps over the warm start's projected weights before the first support is read off them:
/// 30 took as many rounds as 10 (docs/solver.md's WARM_GAP row).
const FIRST_SWEEPS: usize = 10;
/// The next support: the entries whose smoothed weight is above the solve's `tol`
/// (`smoothed_above`), and those the sign rules keep or join (`rules`, [`next_support`]).
///
/// The smoothed weights settle the zero set near the supports' edges, which the sign rules move
/// a ring per round; where they are below the solve's `tol` they are the smoother's slowly
/// decaying tails, which at 0 overgrow the supports in 2D. An entry leaves only where both drop
/// it. The smoother alone drops whole negative bands, where the projected weights are 0 and the
/// sweeps keep them there, and so cuts into the optimal support as the sign rules' outer-half
/// rule is there to prevent: on the 85k-vertex armadillo of `bench scale`, 4 seeds in 10 then
/// took 15-16 rounds, where both take 10-12 (docs/solver.md). Both decide in every round: near
/// the optimum the smoother's support alone cycled with the rules' joins, and the rounds had to
/// leave it; the union did not, and following it to the end took the 2D pants 40 and 33 rounds
/// against 51 and 36, the other cases the same.
fn smoothed_support(smoothed_above: &[bool], mut rules: Vec<bool>) -> Vec<bool> {
    rules
        .iter_mut()
        .zip(smoothed_above)
        .for_each(|(kept, &s)| *kept |= s);
    rules
}

/// The rounds' state, kept across an L-BFGS intermission: the support guess
/// (`support[j * nf + i]`), the partition-of-unity multiplier, the CG tolerance and the
/// smoother's plan of `A`'s rows.
pub(super) struct RoundsState {
    support: Vec<bool>,
    mu: Vec<f64>,
    cg_tol: f64,
    sweep_plan: SweepPlan,
}

impl RoundsState {
    /// The first support from the warm start's projected weights `w` after [`FIRST_SWEEPS`]
    /// of the rounds' smoother: the entries above `first_above` and each row's largest.
    pub fn from_warm_start(prob: &EliminatedProblem, w: &[f64], first_above: f64) -> Self {
        let (nf, m) = (prob.nf(), prob.m);
        // The smoother settles the zero set near the supports' edges here as it does after
        // each round (rounds at tol 1e-9 in docs/solver.md's WARM_GAP row).
        let sweep_plan = SweepPlan::new(&prob.a);
        let w = gauss_seidel_pou(&sweep_plan, &prob.g, w, nf, m, FIRST_SWEEPS);
        // The warm start is only accurate to its gap: weights below it are mostly the smooth
        // tails of W(Y) (eq. 15) over regions that are zero at the optimum, and leaving them
        // out of the first support saves rounds.
        let mut support = above(&w, first_above);
        for i in 0..nf {
            // Every row needs a support entry; its largest weight is the safest.
            let jmax = (0..m)
                .max_by(|&a, &b| w[a * nf + i].total_cmp(&w[b * nf + i]))
                .unwrap_or(0);
            support[jmax * nf + i] = true;
        }
        RoundsState {
            support,
            mu: vec![0.0; nf],
            cg_tol: CG_TOL_FIRST,
            sweep_plan,
        }
    }
}

/// Rounds of the partition-of-unity active-set method from `state`, until the gap is below
/// `tol`, the KKT signs hold, or `watch` says the rounds have stopped paying.
pub(super) fn pou_rounds(
    prob: &EliminatedProblem,
    opts: &BbwOptions,
    state: &mut RoundsState,
    watch: Watch,
    best: &mut CertifiedBounds,
    info: &mut BbwInfo,
    progress: &mut dyn Progress,
) -> SkinResult<Outcome> {
    let (nf, m) = (prob.nf(), prob.m);
    let mut gap_watch = StallWatch::new(best.relative_gap());
    let mut own_bounds = OwnBounds::new();
    let budget = opts.max_iter.min(MAX_ROUNDS).saturating_sub(info.rounds);
    // The last round's dual point, for L-BFGS when the next round's factors do not fit.
    let mut last_dual: Option<Vec<f64>> = None;
    for _ in 0..budget {
        let RoundsState {
            support,
            mu,
            cg_tol,
            sweep_plan,
        } = &mut *state;
        let Some(factors) = factor_within_limit(prob, opts, support, info)? else {
            return Ok(Outcome::OverBudget(last_dual));
        };
        let round = info.rounds;
        info.rounds += 1;
        let sizes: Vec<usize> = factors.iter().map(|f| f.idx.len()).collect();
        let weights = |mu: &[f64]| -> Vec<f64> {
            let cols = longest_first(&sizes, |j| {
                let gj = &prob.g[j * nf..(j + 1) * nf];
                let rhs: Vec<f64> = gj.iter().zip(mu).map(|(g, u)| g + u).collect();
                factors[j].solve_gathered(&rhs)
            });
            let mut w = vec![0.0; nf * m];
            for (j, (f, col)) in factors.iter().zip(&cols).enumerate() {
                for (&i, &v) in f.idx.iter().zip(col) {
                    w[j * nf + i] = -v;
                }
            }
            w
        };
        // `S x` and, per column, `A_FF^{-1} x[F]`.
        let apply_s = |x: &[f64]| -> (Vec<f64>, Vec<Vec<f64>>) {
            let cols = longest_first(&sizes, |j| factors[j].solve_gathered(x));
            let mut out = vec![0.0; nf];
            for (f, col) in factors.iter().zip(&cols) {
                for (&i, &v) in f.idx.iter().zip(col) {
                    out[i] += v;
                }
            }
            (out, cols)
        };
        // S delta = rowsum(W(mu)) - 1, warm-started at the previous round's mu. W is linear in
        // mu, so W(mu + delta) = W(mu) - sum_k alpha_k A_FF^{-1} p_k is accumulated from the
        // solves CG makes anyway (recomputing it would cost one more solve per column).
        let mut w = weights(mu);
        let residual = row_sums_minus_one(&w, nf, m);
        let t = Instant::now();
        let step = |alpha: f64, cols: &Vec<Vec<f64>>| {
            w.par_chunks_mut(nf)
                .zip(factors.par_iter().zip(cols))
                .for_each(|(wc, (f, col))| {
                    for (&i, &v) in f.idx.iter().zip(col) {
                        wc[i] -= alpha * v;
                    }
                });
        };
        let (delta, iters) = pcg(prob, apply_s, step, &residual, *cg_tol, progress)?;
        info.time_cg += t.elapsed().as_secs_f64();
        info.cg_iterations += iters;
        mu.iter_mut().zip(&delta).for_each(|(u, d)| *u += d);
        // The certificate's vectors need not sit on top of the round's factors in memory.
        drop(factors);

        // Multipliers y = A w + g + mu on the zero set (eq. 15 read backwards).
        let mut y = prob.apply_a(&w);
        let mut scale: f64 = 1.0;
        for k in 0..nf * m {
            let grad = y[k] + prob.g[k];
            scale = scale.max(grad.abs());
            y[k] = if support[k] { 0.0 } else { grad + mu[k % nf] };
        }
        // Certificate: projected w (upper bound), dual at y spread to >= 0 (lower bound). The
        // smoothed weights are feasible too, never higher, and often a tighter upper bound.
        let feasible = project_pou(&w, nf, m);
        let upper = prob.energy(&feasible);
        let t = Instant::now();
        let smoothed = gauss_seidel_pou(sweep_plan, &prob.g, &feasible, nf, m, SMOOTH_SWEEPS);
        info.time_smooth += t.elapsed().as_secs_f64();
        best.offer(&w, feasible, upper);
        // What the next support needs of the smoothed weights, so that they can move to `best`.
        let smoothed_above = above(&smoothed, opts.tol);
        let energy = prob.energy(&smoothed);
        if energy < best.upper {
            // Its raw extremes are those of the round's weights it was smoothed from.
            best.offer(&w, smoothed, energy);
        }
        // The dual's own recovered W(Y) is not offered as a primal candidate: it is smooth but
        // nowhere exactly zero, and once projected can win on energy by a hair while sitting
        // far off the optimum in flat directions.
        let mut y_plus = y.clone();
        spread_negative(&mut y_plus, &prob.a, nf);
        let own = pou_eval(prob, &y_plus);
        let own_lower = own.lower_bound(prob);
        let own_gap = (upper - own_lower) / upper.abs().max(1e-300);
        best.bound(&own, own_lower);
        progress.report(Event {
            stage: "active-set",
            iteration: round,
            value: best.relative_gap(),
        })?;
        // Certified: the next support (two graph searches per column) is not needed.
        if best.relative_gap() <= opts.tol {
            return Ok(Outcome::Done);
        }
        let thresholds = SignThresholds::new(opts.tol, scale);
        let step = next_support(&prob.a, support, &w, &y, thresholds, nf);
        let exact = step.negative == 0 && step.joined == 0;
        let next = smoothed_support(&smoothed_above, step.next);
        if exact && *cg_tol <= CG_TOL_FINAL * opts.tol {
            // Every KKT sign holds and PoU to round-off: this is the optimum; the gap is as
            // small as floating point allows.
            return Ok(Outcome::Done);
        }
        // The rounds' own bounds (best may hold an L-BFGS point from the intermission).
        let quiet = own_bounds.quiet_rounds(upper, own_lower, 0.5 * opts.tol);
        let stalled = match watch {
            Watch::Gap(window) => gap_watch.stalled(best.relative_gap(), window),
            Watch::Bounds => quiet >= 2,
        };
        if stalled {
            return Ok(Outcome::Stalled(y_plus));
        }
        last_dual = Some(y_plus);
        // Rows are renormalised at the end, so a PoU residual far below tol changes nothing;
        // while signs still flip, one of a tenth of the gap, down to CG_TOL_SIGNS * tol,
        // decides them as well.
        *cg_tol = if exact {
            CG_TOL_FINAL * opts.tol
        } else {
            (CG_TOL_PER_GAP * own_gap)
                .max(CG_TOL_SIGNS * opts.tol)
                .min(*cg_tol)
        }
        .max(1e-13);
        *support = next;
    }
    Ok(Outcome::Done)
}

#[cfg(test)]
mod tests {
    use super::smoothed_support;
    use crate::bbw::vector::above;

    #[test]
    fn an_entry_leaves_only_where_smoother_and_rules_both_drop_it() {
        // Entries: smoothed above / at / below the threshold, crossed with kept or dropped by the
        // rules.
        let smoothed = [2e-9, 2e-9, 1e-9, 1e-9, 0.0, 0.0];
        let rules = [true, false, true, false, true, false];
        let next = smoothed_support(&above(&smoothed, 1e-9), rules.to_vec());
        assert_eq!(next, vec![true, true, true, false, true, false]);
    }
}
