//! The default BBW solver: a primal-dual active-set method on the eliminated QP.
//!
//! Inputs: an [`EliminatedProblem`] (`A = B_ff` factored once, `G`, `W0`) and [`BbwOptions`].
//! Output: the best certified feasible weights, written into [`CertifiedBounds`], and
//! diagnostics. `docs/solver.md` gives each rule below with the measurement behind it.
//!
//! With partition of unity the KKT conditions of eq. 3 on the free rows are, per column `j`,
//!
//! ```text
//!   A w_j + g_j + mu - y_j = 0,   w_j >= 0,  y_j >= 0,  w_j o y_j = 0,   sum_j w_j = 1,
//! ```
//!
//! where `y_j` is the dual variable `Y` of eq. 12 and `mu` the multiplier of partition of unity
//! (so `Y P_m = A W + G`, eq. 15). Given a guess of each column's support `F_j` (`y_j = 0` there,
//! `w_j = 0` off it) the system is linear: `w_j = -A_{F_j F_j}^{-1} (g_j + mu)` on `F_j`, and
//! `mu` solves the `nf x nf` SPD system `S mu = rowsum(W(0)) - 1` with
//! `S = sum_j E_j A_{F_j F_j}^{-1} E_j^T`. `S` is never formed: conjugate gradients apply it
//! with one sparse Cholesky factor per column support ([`support_factor`]), preconditioned by
//! `A / m` (exact when every support is the whole mesh, where `S = m A^{-1}`) ([`pcg`]).
//! Entries of the support whose weight came out negative leave it, entries off it whose
//! multiplier `y` came out negative join it, damped ([`next_support`]), and the round repeats
//! until no sign is violated (the KKT conditions then hold to round-off) ([`pou_rounds`]).
//! Each round's weights are also smoothed by projected Gauss-Seidel ([`smooth`]), and an entry
//! leaves the support only where neither the smoothed weights nor the sign rules keep it.
//!
//! The first support comes from a short run of the paper's L-BFGS on the dual (a duality gap of
//! [`WARM_GAP`], or twice that once the support stops moving, [`SETTLED`]), its projected
//! weights smoothed as a round's are (with fewer sweeps). Every
//! round is certified like the L-BFGS iterates: the projected weights give an upper bound on
//! the optimal energy, the dual (eq. 12) at `y` made non-negative by
//! [`spread::spread_negative`] a lower bound, and the solve stops once their relative gap is
//! below `tol`. Without partition of unity (App. A) the columns decouple and each one is a
//! box-constrained QP solved the same way with two bounds and no `mu` ([`box_rounds`]).
//! Primal-dual active sets are not guaranteed to converge when `A` is not an M-matrix (the
//! biharmonic one is not): if the gap stalls ([`stall`]), L-BFGS warm-started from the last
//! multipliers runs for at most [`INTERMISSION`] iterations, then the rounds resume until
//! neither of their own bounds moves any more, and L-BFGS finishes.

mod box_rounds;
mod next_support;
mod pcg;
mod pou_rounds;
mod smooth;
mod spread;
mod stall;
mod support_factor;

use std::time::Instant;

use self::box_rounds::box_rounds;
use self::pou_rounds::{pou_rounds, RoundsState};
use self::stall::{Outcome, Watch, STALL_ROUNDS};
use super::bounds::CertifiedBounds;
use super::options::{BbwInfo, BbwOptions};
use super::problem::EliminatedProblem;
use super::squared_lbfgs::{random_start, run_lbfgs, LbfgsStop, SettledSupport};
use crate::error::SkinResult;
use crate::progress::Progress;

/// Relative duality gap at which the L-BFGS warm start stops; its projected weights, after the
/// smoother's sweeps, above this value (and each row's largest) form the first support.
pub const WARM_GAP: f64 = 3e-3;
/// The warm start stops earlier, at twice [`WARM_GAP`], once the support it names has settled:
/// at most 5 % of its entries (above [`WARM_GAP`]) changed since the previous gap check.
/// On the armadillos of `bench scale` that holds from about that gap on (0.6-3.6 % a check)
/// and the rounds are the same from either stop; on hand-403, big2d and the pants the support
/// still churns there (15-76 % a check) and stopping early costs rounds (docs/solver.md,
/// WARM_GAP).
const SETTLED: SettledSupport = SettledSupport {
    gap: 2.0 * WARM_GAP,
    above: WARM_GAP,
    change: 0.05,
};
/// L-BFGS iterations of the first fallback before the rounds resume.
const INTERMISSION: usize = 150;

/// Runs the active-set solver (see the module docs), writing into `best` and `info`.
pub(crate) fn solve(
    prob: &EliminatedProblem,
    opts: &BbwOptions,
    best: &mut CertifiedBounds,
    info: &mut BbwInfo,
    progress: &mut dyn Progress,
) -> SkinResult<()> {
    solve_with_stall(prob, opts, STALL_ROUNDS, best, info, progress)
}

/// [`solve`] with the stall window of the first rounds as a parameter (tests force the
/// L-BFGS hand-over with a window of 0).
fn solve_with_stall(
    prob: &EliminatedProblem,
    opts: &BbwOptions,
    stall_rounds: usize,
    best: &mut CertifiedBounds,
    info: &mut BbwInfo,
    progress: &mut dyn Progress,
) -> SkinResult<()> {
    let (nf, m) = (prob.nf(), prob.m);
    let t = Instant::now();
    let start = random_start(nf, m, opts.dual_blocks(), opts.seed);
    let stop = LbfgsStop {
        tol: WARM_GAP.max(opts.tol),
        // Partition of unity only: with it the box rounds of the 7.7k armadillo took 66, not 65.
        settled: (opts.partition_of_unity && SETTLED.gap > opts.tol).then_some(SETTLED),
    };
    let u_warm = run_lbfgs(prob, opts, stop, start, best, info, progress)?;
    info.time_lbfgs = t.elapsed().as_secs_f64();
    if best.relative_gap() <= opts.tol {
        return Ok(());
    }
    let t = Instant::now();
    // The warm start's projected weights name the first support.
    let w = best.w.clone();
    if !opts.partition_of_unity {
        let outcome = box_rounds(prob, opts, &w, best, info, progress)?;
        info.time_active_set = t.elapsed().as_secs_f64();
        return hand_over(prob, opts, outcome, u_warm, best, info, progress);
    }
    let sweeps = Instant::now();
    let mut state = RoundsState::from_warm_start(prob, &w, WARM_GAP);
    info.time_smooth += sweeps.elapsed().as_secs_f64();
    let watch = Watch::Gap(stall_rounds);
    let mut outcome = pou_rounds(prob, opts, &mut state, watch, best, info, progress)?;
    info.time_active_set = t.elapsed().as_secs_f64();
    if let Outcome::Stalled(y) = outcome {
        // The rounds cycle or their lower bound lags. A short L-BFGS intermission from their
        // multipliers lifts the lower bound; if that does not close the gap the rounds resume
        // (their upper bound still falls, where L-BFGS alone crawls).
        fallback_lbfgs(prob, opts, INTERMISSION, &y, best, info, progress)?;
        if best.relative_gap() <= opts.tol {
            return Ok(());
        }
        let t = Instant::now();
        outcome = pou_rounds(prob, opts, &mut state, Watch::Bounds, best, info, progress)?;
        info.time_active_set += t.elapsed().as_secs_f64();
    }
    hand_over(prob, opts, outcome, u_warm, best, info, progress)
}

/// What follows the last run of rounds: L-BFGS on the dual until `tol` or `max_iter` when the
/// rounds stalled, or when their next support factors would not fit `memory_limit` (L-BFGS
/// needs only the factor of `A`). It starts from the last round's multipliers, or, when no
/// round ran, goes on from the warm start's iterate `u_warm`.
fn hand_over(
    prob: &EliminatedProblem,
    opts: &BbwOptions,
    outcome: Outcome,
    u_warm: Vec<f64>,
    best: &mut CertifiedBounds,
    info: &mut BbwInfo,
    progress: &mut dyn Progress,
) -> SkinResult<()> {
    match outcome {
        Outcome::Done => Ok(()),
        Outcome::Stalled(y) => fallback_lbfgs(prob, opts, opts.max_iter, &y, best, info, progress),
        Outcome::OverBudget(Some(y)) => {
            info.memory_fallback = true;
            fallback_lbfgs(prob, opts, opts.max_iter, &y, best, info, progress)
        }
        Outcome::OverBudget(None) => {
            info.memory_fallback = true;
            info.fallbacks += 1;
            let t = Instant::now();
            let stop = LbfgsStop::at_gap(opts.tol);
            run_lbfgs(prob, opts, stop, u_warm, best, info, progress)?;
            info.time_lbfgs += t.elapsed().as_secs_f64();
            Ok(())
        }
    }
}

/// L-BFGS on the dual (at most `max_iter` iterations) warm-started from multipliers `y`.
fn fallback_lbfgs(
    prob: &EliminatedProblem,
    opts: &BbwOptions,
    max_iter: usize,
    y: &[f64],
    best: &mut CertifiedBounds,
    info: &mut BbwInfo,
    progress: &mut dyn Progress,
) -> SkinResult<()> {
    // Adding a constant to every entry leaves W(Y) unchanged (P_m removes row means) and
    // moves every entry off 0, where the squared parameterisation has no gradient.
    let delta = 1e-9 * y.iter().copied().fold(0.0, f64::max) + 1e-300;
    let u: Vec<f64> = y.iter().map(|v| (v + delta).sqrt()).collect();
    info.fallbacks += 1;
    let capped = BbwOptions {
        max_iter: max_iter.min(opts.max_iter),
        ..opts.clone()
    };
    let t = Instant::now();
    let stop = LbfgsStop::at_gap(opts.tol);
    run_lbfgs(prob, &capped, stop, u, best, info, progress)?;
    info.time_lbfgs += t.elapsed().as_secs_f64();
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bbw::options::Solver;
    use crate::operators::{biharmonic_matrix, MassKind};
    use crate::progress::Silent;
    use ndarray::Array2;

    /// A `k x k` grid of the unit square with handles at three corners and the centre.
    fn grid_problem(k: usize) -> EliminatedProblem {
        let h = 1.0 / (k - 1) as f64;
        let v = Array2::from_shape_fn((k * k, 2), |(i, c)| {
            h * if c == 0 { i % k } else { i / k } as f64
        });
        let mut f = Vec::new();
        for r in 0..k - 1 {
            for c in 0..k - 1 {
                let i = r * k + c;
                f.extend([i, i + 1, i + k + 1, i, i + k + 1, i + k]);
            }
        }
        let f = Array2::from_shape_vec((f.len() / 3, 3), f).unwrap();
        let bmat = biharmonic_matrix(v.view(), f.view(), MassKind::Voronoi).unwrap();
        let b = vec![0, k - 1, (k / 2) * k + k / 2, k * k - 1];
        let bc = Array2::from_shape_fn((4, 4), |(i, j)| f64::from(i == j));
        EliminatedProblem::new(&bmat, &b, bc.view()).unwrap()
    }

    fn run(prob: &EliminatedProblem, stall_rounds: usize) -> (CertifiedBounds, BbwInfo) {
        let opts = BbwOptions {
            solver: Solver::ActiveSet,
            tol: 1e-11,
            ..Default::default()
        };
        let (mut best, mut info) = (CertifiedBounds::new(), BbwInfo::default());
        solve_with_stall(prob, &opts, stall_rounds, &mut best, &mut info, &mut Silent).unwrap();
        (best, info)
    }

    #[test]
    fn rounds_resume_after_the_lbfgs_intermission() {
        let prob = grid_problem(25);
        let (plain, plain_info) = run(&prob, STALL_ROUNDS);
        assert_eq!(
            plain_info.fallbacks, 0,
            "the plain rounds should not stall here"
        );
        assert!(plain.relative_gap() <= 1e-11);
        // A window of 0 hands over to L-BFGS after the first round; 150 L-BFGS iterations do
        // not reach 1e-11, so the rounds must resume and finish the job.
        let (forced, info) = run(&prob, 0);
        assert!(info.fallbacks >= 1, "no hand-over: {info:?}");
        assert!(info.rounds > 1, "the rounds did not resume: {info:?}");
        assert!(
            forced.relative_gap() <= 1e-11,
            "gap {} {info:?} plain {plain_info:?}",
            forced.relative_gap()
        );
        let dw = plain
            .w
            .iter()
            .zip(&forced.w)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        assert!(dw < 1e-6, "max |dW| {dw}");
    }
}
