//! The BBW solvers: L-BFGS on the dual, stopped on a measured duality gap.

use std::cell::RefCell;
use std::time::Instant;

use ndarray::Array2;
use rayon::prelude::*;

use super::dual::{box_eval, pou_eval, project_box, project_pou, DualPoint};
use super::lbfgs::{minimize, LbfgsOptions, Step};
use super::problem::EliminatedProblem;
use crate::error::SkinResult;
use crate::invalid;
use crate::progress::{Event, Progress};

/// Iterations between two evaluations of the duality gap.
const GAP_EVERY: usize = 5;

/// Which algorithm solves the dual.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Solver {
    /// The paper's method (Sec. 6, 8): L-BFGS on `Y = U o U` from a random start scaled so each
    /// column of `U o U` sums to 1.
    LbfgsSquared,
    /// The default: a short L-BFGS run to guess the zero set of `W`, then a primal-dual active
    /// set method that solves the equality-constrained problem on the guessed support exactly
    /// and swaps KKT violators ([`super::active_set`]).
    ActiveSet,
}

impl Solver {
    pub fn parse(s: &str) -> SkinResult<Self> {
        match s {
            "lbfgs-squared" => Ok(Solver::LbfgsSquared),
            "active-set" => Ok(Solver::ActiveSet),
            _ => invalid!("unknown solver {s:?}; choose one of \"active-set\", \"lbfgs-squared\""),
        }
    }
    pub fn name(self) -> &'static str {
        match self {
            Solver::LbfgsSquared => "lbfgs-squared",
            Solver::ActiveSet => "active-set",
        }
    }
}

#[derive(Debug, Clone)]
pub struct BbwOptions {
    pub solver: Solver,
    /// Stop when the duality gap, relative to the energy, is at most `tol`.
    pub tol: f64,
    pub max_iter: usize,
    /// Enforce rows summing to one (eq. 3); otherwise `0 <= W <= 1` (App. A, eq. A1).
    pub partition_of_unity: bool,
    /// Seed of the random start.
    pub seed: u64,
    /// L-BFGS memory.
    pub memory: usize,
}

impl Default for BbwOptions {
    fn default() -> Self {
        BbwOptions {
            solver: Solver::ActiveSet,
            tol: 1e-9,
            max_iter: 100_000,
            partition_of_unity: true,
            seed: 0,
            memory: 10,
        }
    }
}

/// Diagnostics of one solve.
#[derive(Debug, Clone, Default)]
pub struct BbwInfo {
    pub solver: String,
    /// L-BFGS iterations (for `active-set`: those of the warm start and of any fallbacks).
    pub iterations: usize,
    /// Objective/gradient evaluations, i.e. multi-column solves with the Cholesky factor.
    pub evaluations: usize,
    /// Active-set rounds (support guesses solved exactly) and the conjugate-gradient iterations
    /// they took in total; zero for `lbfgs-squared`.
    pub rounds: usize,
    pub cg_iterations: usize,
    /// Hand-overs from the active-set rounds to L-BFGS on the dual (0 when the rounds alone
    /// closed the gap).
    pub fallbacks: usize,
    /// `1/2 tr(W^T B W)` of the returned (feasible) weights.
    pub energy: f64,
    /// Best lower bound on the optimal energy found (Lagrangian of the dual).
    pub lower_bound: f64,
    /// Dual objective (eq. 12 or B6) at the final iterate.
    pub dual_objective: f64,
    /// `energy - lower_bound`, and that relative to `energy`.
    pub gap: f64,
    pub relative_gap: f64,
    /// Most negative (and, without partition of unity, largest) raw recovered weight before
    /// projection onto the feasible set.
    pub min_raw_weight: f64,
    pub max_raw_weight: f64,
    pub converged: bool,
    /// Seconds: assembly + Cholesky of `B_ff`, the whole solve, and within it the L-BFGS phase
    /// and the active-set phase.
    pub time_factor: f64,
    pub time_solve: f64,
    pub time_lbfgs: f64,
    pub time_active_set: f64,
    /// Within the active-set phase: factoring the per-column support blocks, and CG on `mu`.
    pub time_support_factor: f64,
    pub time_cg: f64,
}

/// Solves BBW on an eliminated problem. Returns the full `n x m` weights (rows of `b` equal `bc`)
/// and diagnostics. The returned weights are always feasible (the best projected iterate:
/// clamped and, with partition of unity, row-normalised) and their energy is within `gap` of the
/// optimum.
pub fn bbw_dual(
    prob: &EliminatedProblem,
    opts: &BbwOptions,
    progress: &mut dyn Progress,
) -> SkinResult<(Array2<f64>, BbwInfo)> {
    if !(opts.tol.is_finite() && opts.tol > 0.0) {
        return invalid!("tol must be a positive finite number, got {}", opts.tol);
    }
    let t0 = Instant::now();
    let mut best = Best::new();
    let mut info = BbwInfo {
        solver: opts.solver.name().to_string(),
        time_factor: prob.time_factor,
        ..Default::default()
    };
    if prob.nf() == 0 {
        // Every vertex is constrained: nothing to solve.
        let dp = DualPoint {
            objective: 0.0,
            w: vec![],
            lower_bound: prob.c0,
        };
        best.update(&dp, vec![], prob.c0);
    } else {
        match opts.solver {
            Solver::LbfgsSquared => {
                let t = Instant::now();
                let start = random_start(prob.nf(), prob.m, blocks(opts), opts.seed);
                run_lbfgs(prob, opts, opts.tol, start, &mut best, &mut info, progress)?;
                info.time_lbfgs = t.elapsed().as_secs_f64();
            }
            Solver::ActiveSet => {
                super::active_set::solve(prob, opts, &mut best, &mut info, progress)?;
            }
        }
    }
    info.energy = best.upper;
    info.lower_bound = best.lower;
    info.dual_objective = best.dual_objective;
    info.gap = best.upper - best.lower;
    info.relative_gap = best.relative_gap();
    info.min_raw_weight = best.min_raw;
    info.max_raw_weight = best.max_raw;
    info.converged = best.relative_gap() <= opts.tol;
    info.time_solve = t0.elapsed().as_secs_f64();
    Ok((prob.full_weights(&best.w), info))
}

/// Number of `nf x m` blocks of dual variables: `Y` with partition of unity, `(Y, U)` without.
pub(crate) fn blocks(opts: &BbwOptions) -> usize {
    if opts.partition_of_unity {
        1
    } else {
        2
    }
}

/// Projects recovered weights onto the primal feasible set of the variant being solved.
fn project(opts: &BbwOptions, w: &[f64], nf: usize, m: usize) -> Vec<f64> {
    if opts.partition_of_unity {
        project_pou(w, nf, m)
    } else {
        project_box(w)
    }
}

/// The paper's solver: L-BFGS on the dual in `U` with `Y = U o U`, from `start`, until the
/// duality gap of the best projected iterate is at most `tol` (relative) or `opts.max_iter`.
/// Adds its iterations and evaluations to `info`.
pub(crate) fn run_lbfgs(
    prob: &EliminatedProblem,
    opts: &BbwOptions,
    tol: f64,
    mut u: Vec<f64>,
    best: &mut Best,
    info: &mut BbwInfo,
    progress: &mut dyn Progress,
) -> SkinResult<()> {
    let (nf, m) = (prob.nf(), prob.m);
    let eval = |y: &[f64]| -> DualPoint {
        if opts.partition_of_unity {
            pou_eval(prob, y)
        } else {
            box_eval(prob, &y[..nf * m], &y[nf * m..])
        }
    };
    let last: RefCell<Option<DualPoint>> = RefCell::new(None);
    let mut evaluations = 0;
    let fg = |u: &[f64], grad: &mut [f64]| -> f64 {
        evaluations += 1;
        let y: Vec<f64> = u.par_iter().map(|v| v * v).collect();
        let dp = eval(&y);
        // d f(U o U) / dU = 2 U o grad_Y f, with grad_Y f = W (eq. 16) or (W, 1 - W).
        let (gy, gu) = grad.split_at_mut(nf * m);
        let (uy, uu) = u.split_at(nf * m);
        gy.par_iter_mut()
            .zip(uy.par_iter().zip(dp.w.par_iter()))
            .for_each(|(g, (u, w))| *g = 2.0 * u * w);
        gu.par_iter_mut()
            .zip(uu.par_iter().zip(dp.w.par_iter()))
            .for_each(|(g, (u, w))| *g = 2.0 * u * (1.0 - w));
        let f = dp.objective;
        *last.borrow_mut() = Some(dp);
        f
    };
    let lopts = LbfgsOptions {
        memory: opts.memory,
        max_iter: opts.max_iter,
    };
    let iterations = minimize(&mut u, &lopts, fg, |it, _x, _f, _g| {
        // The certificate costs a sparse product; checking it every few iterations keeps the
        // stop at most GAP_EVERY - 1 iterations late.
        if it % GAP_EVERY == 0 {
            let dp = last.borrow();
            let dp = dp.as_ref().expect("objective evaluated before monitor");
            let feasible = project(opts, &dp.w, nf, m);
            let upper = prob.energy(&feasible);
            best.update(dp, feasible, upper);
        }
        progress.report(Event {
            stage: "dual",
            iteration: it,
            value: best.relative_gap(),
        })?;
        Ok(if it % GAP_EVERY == 0 && best.relative_gap() <= tol {
            Step::Stop
        } else {
            Step::Continue
        })
    })?;
    // Certify the final iterate too (the loop may end between two gap checks).
    if let Some(dp) = last.borrow_mut().take() {
        let feasible = project(opts, &dp.w, nf, m);
        let upper = prob.energy(&feasible);
        best.update(&dp, feasible, upper);
    }
    info.iterations += iterations;
    info.evaluations += evaluations;
    Ok(())
}

/// Best certified pair seen so far: the lowest feasible energy and the highest lower bound.
pub(crate) struct Best {
    pub upper: f64,
    pub lower: f64,
    pub w: Vec<f64>,
    pub dual_objective: f64,
    pub min_raw: f64,
    pub max_raw: f64,
}

impl Best {
    pub fn new() -> Self {
        Best {
            upper: f64::INFINITY,
            lower: f64::NEG_INFINITY,
            w: vec![],
            dual_objective: f64::NAN,
            min_raw: f64::NAN,
            max_raw: f64::NAN,
        }
    }
    /// Records the dual point's lower bound and, if it is better, the projected primal.
    pub fn update(&mut self, dp: &DualPoint, feasible: Vec<f64>, upper: f64) {
        self.bound(dp);
        self.offer(&dp.w, feasible, upper);
    }
    /// Records the dual point's lower bound only.
    pub fn bound(&mut self, dp: &DualPoint) {
        self.lower = self.lower.max(dp.lower_bound);
        self.dual_objective = dp.objective;
    }
    /// Records a feasible point (projected from `raw`) if its energy is lower.
    pub fn offer(&mut self, raw: &[f64], feasible: Vec<f64>, upper: f64) {
        if upper < self.upper {
            self.upper = upper;
            self.w = feasible;
            self.min_raw = raw.iter().copied().fold(f64::INFINITY, f64::min);
            self.max_raw = raw.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        }
    }
    pub fn relative_gap(&self) -> f64 {
        (self.upper - self.lower).max(0.0) / self.upper.abs().max(1e-300)
    }
}

/// The paper's start (Sec. 8): uniform random `U`, scaled so each column of `U o U` sums to 1.
pub(crate) fn random_start(nf: usize, m: usize, blocks: usize, seed: u64) -> Vec<f64> {
    let mut state = seed ^ 0x9E37_79B9_7F4A_7C15;
    let mut next = move || {
        // splitmix64
        state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = state;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
    };
    let mut u: Vec<f64> = (0..nf * m * blocks).map(|_| next()).collect();
    for col in u.chunks_mut(nf) {
        let s: f64 = col.iter().map(|v| v * v).sum();
        let scale = 1.0 / s.sqrt().max(1e-300);
        col.iter_mut().for_each(|v| *v *= scale);
    }
    u
}
