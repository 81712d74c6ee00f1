//! The BBW solvers: L-BFGS on the dual, stopped on a measured duality gap.

use std::cell::RefCell;
use std::time::Instant;

use ndarray::Array2;

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
}

impl Solver {
    pub fn parse(s: &str) -> SkinResult<Self> {
        match s {
            "lbfgs-squared" => Ok(Solver::LbfgsSquared),
            _ => invalid!("unknown solver {s:?}; choose one of \"lbfgs-squared\""),
        }
    }
    pub fn name(self) -> &'static str {
        match self {
            Solver::LbfgsSquared => "lbfgs-squared",
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
            solver: Solver::LbfgsSquared,
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
    pub iterations: usize,
    /// Objective/gradient evaluations, i.e. multi-column solves with the Cholesky factor.
    pub evaluations: usize,
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
    pub time_factor: f64,
    pub time_solve: f64,
}

/// Solves BBW on an eliminated problem. Returns the full `n x m` weights (rows of `b` equal `bc`)
/// and diagnostics. The returned weights are the projection of the best dual iterate's recovered
/// `W` onto the feasible set (clamped and, with partition of unity, row-normalised), so they are
/// always feasible and their energy is within `gap` of the optimum.
pub fn bbw_dual(
    prob: &EliminatedProblem,
    opts: &BbwOptions,
    progress: &mut dyn Progress,
) -> SkinResult<(Array2<f64>, BbwInfo)> {
    if !(opts.tol.is_finite() && opts.tol > 0.0) {
        return invalid!("tol must be a positive finite number, got {}", opts.tol);
    }
    let t0 = Instant::now();
    let (nf, m) = (prob.nf(), prob.m);
    let nvar = if opts.partition_of_unity {
        nf * m
    } else {
        2 * nf * m
    };

    let eval = |y: &[f64]| -> DualPoint {
        if opts.partition_of_unity {
            pou_eval(prob, y)
        } else {
            box_eval(prob, &y[..nf * m], &y[nf * m..])
        }
    };
    let project = |w: &[f64]| {
        if opts.partition_of_unity {
            project_pou(w, nf, m)
        } else {
            project_box(w)
        }
    };

    let mut best = Best::new();
    let mut iterations = 0;
    let mut evaluations = 0;
    if nf > 0 {
        let mut u = random_start(nf, m, nvar / (nf * m), opts.seed);
        let last: RefCell<Option<DualPoint>> = RefCell::new(None);
        let fg = |u: &[f64], grad: &mut [f64]| -> f64 {
            evaluations += 1;
            let y: Vec<f64> = u.iter().map(|v| v * v).collect();
            let dp = eval(&y);
            // d f(U o U) / dU = 2 U o grad_Y f, with grad_Y f = W (eq. 16) or (W, 1 - W).
            for k in 0..nf * m {
                grad[k] = 2.0 * u[k] * dp.w[k];
            }
            for k in nf * m..u.len() {
                grad[k] = 2.0 * u[k] * (1.0 - dp.w[k - nf * m]);
            }
            let f = dp.objective;
            *last.borrow_mut() = Some(dp);
            f
        };
        let lopts = LbfgsOptions {
            memory: opts.memory,
            max_iter: opts.max_iter,
        };
        iterations = minimize(&mut u, &lopts, fg, |it, _x, _f, _g| {
            // The certificate costs a sparse product; checking it every few iterations keeps the
            // stop at most GAP_EVERY - 1 iterations late.
            if it % GAP_EVERY != 0 {
                progress.report(Event {
                    stage: "dual",
                    iteration: it,
                    value: best.relative_gap(),
                })?;
                return Ok(Step::Continue);
            }
            let dp = last.borrow();
            let dp = dp.as_ref().expect("objective evaluated before monitor");
            let feasible = project(&dp.w);
            let upper = prob.energy(&feasible);
            best.update(dp, feasible, upper);
            progress.report(Event {
                stage: "dual",
                iteration: it,
                value: best.relative_gap(),
            })?;
            Ok(if best.relative_gap() <= opts.tol {
                Step::Stop
            } else {
                Step::Continue
            })
        })?;
        // Certify the final iterate too (the loop may end between two gap checks).
        let final_point = last.borrow_mut().take();
        if let Some(dp) = final_point {
            let feasible = project(&dp.w);
            let upper = prob.energy(&feasible);
            best.update(&dp, feasible, upper);
        }
    } else {
        // Every vertex is constrained: nothing to solve.
        best.update(
            &DualPoint {
                objective: 0.0,
                w: vec![],
                lower_bound: prob.c0,
            },
            vec![],
            prob.c0,
        );
    }

    let info = BbwInfo {
        solver: opts.solver.name().to_string(),
        iterations,
        evaluations,
        energy: best.upper,
        lower_bound: best.lower,
        dual_objective: best.dual_objective,
        gap: best.upper - best.lower,
        relative_gap: best.relative_gap(),
        min_raw_weight: best.min_raw,
        max_raw_weight: best.max_raw,
        converged: best.relative_gap() <= opts.tol,
        time_factor: prob.time_factor,
        time_solve: t0.elapsed().as_secs_f64(),
    };
    Ok((prob.full_weights(&best.w), info))
}

/// Best certified pair seen so far: the lowest feasible energy and the highest lower bound.
struct Best {
    upper: f64,
    lower: f64,
    w: Vec<f64>,
    dual_objective: f64,
    min_raw: f64,
    max_raw: f64,
}

impl Best {
    fn new() -> Self {
        Best {
            upper: f64::INFINITY,
            lower: f64::NEG_INFINITY,
            w: vec![],
            dual_objective: f64::NAN,
            min_raw: f64::NAN,
            max_raw: f64::NAN,
        }
    }
    fn update(&mut self, dp: &DualPoint, feasible: Vec<f64>, upper: f64) {
        self.lower = self.lower.max(dp.lower_bound);
        self.dual_objective = dp.objective;
        if upper < self.upper {
            self.upper = upper;
            self.w = feasible;
            self.min_raw = dp.w.iter().copied().fold(f64::INFINITY, f64::min);
            self.max_raw = dp.w.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        }
    }
    fn relative_gap(&self) -> f64 {
        (self.upper - self.lower).max(0.0) / self.upper.abs().max(1e-300)
    }
}

/// The paper's start (Sec. 8): uniform random `U`, scaled so each column of `U o U` sums to 1.
fn random_start(nf: usize, m: usize, blocks: usize, seed: u64) -> Vec<f64> {
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
