//! The front door of the BBW solvers: checks the options, runs the chosen solver and reports.

use std::time::Instant;

use ndarray::Array2;

use super::bounds::CertifiedBounds;
use super::options::{BbwInfo, BbwOptions, Solver};
use super::problem::EliminatedProblem;
use super::squared_lbfgs::{random_start, run_lbfgs, LbfgsStop};
use crate::error::SkinResult;
use crate::invalid;
use crate::progress::Progress;

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
    let mut best = CertifiedBounds::new();
    let mut info = BbwInfo {
        solver: opts.solver.name().to_string(),
        time_factor: prob.time_factor,
        factor_bytes: prob.factor_bytes,
        vector_bytes: opts.vector_bytes(prob.nf(), prob.m),
        ..Default::default()
    };
    if prob.nf() == 0 {
        // Every vertex is constrained: nothing to solve.
        let energy = prob.energy(&[]);
        best.lower = energy;
        best.dual_objective = 0.0;
        best.offer(&[], vec![], energy);
    } else {
        match opts.solver {
            Solver::LbfgsSquared => {
                let t = Instant::now();
                let start = random_start(prob.nf(), prob.m, opts.dual_blocks(), opts.seed);
                let stop = LbfgsStop::at_gap(opts.tol);
                run_lbfgs(prob, opts, stop, start, &mut best, &mut info, progress)?;
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
