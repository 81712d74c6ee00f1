//! The paper's solver (Sec. 6, 8): L-BFGS on the dual in `U` with `Y = U o U`, from a random
//! start, stopped on the certified duality gap. The active-set solver uses it for its warm start
//! and its fallbacks.

use std::cell::RefCell;

use rayon::prelude::*;

use super::bounds::CertifiedBounds;
use super::dual::{box_eval, pou_eval, project_box, project_pou, DualPoint};
use super::lbfgs::{minimize, LbfgsOptions, Step};
use super::options::{BbwInfo, BbwOptions};
use super::problem::EliminatedProblem;
use super::vector;
use crate::error::SkinResult;
use crate::progress::{Event, Progress};
use crate::rng::Rng;

/// Iterations between two evaluations of the duality gap.
const GAP_EVERY: usize = 5;

/// Projects recovered weights onto the primal feasible set of the variant being solved.
fn project(opts: &BbwOptions, w: &[f64], nf: usize, m: usize) -> Vec<f64> {
    if opts.partition_of_unity {
        project_pou(w, nf, m)
    } else {
        project_box(w)
    }
}

/// An early stop for a warm start, whose use is the support it names: once the duality gap is
/// at most `gap` and the projected iterate's support (its entries above `above`) differs from
/// the previous gap check's in at most a `change` fraction of its entries, further iterations
/// would hand the rounds the same first support.
#[derive(Clone, Copy, Debug)]
pub(crate) struct SettledSupport {
    pub gap: f64,
    pub above: f64,
    pub change: f64,
}

/// The support of the projected iterate at the previous gap check, for [`SettledSupport`].
struct SupportWatch {
    rule: SettledSupport,
    previous: Vec<bool>,
}

impl SupportWatch {
    /// Whether the support of `w` (projected weights) has settled; remembers it for the next
    /// check.
    fn settled(&mut self, w: &[f64]) -> bool {
        let support = vector::above(w, self.rule.above);
        let size = support.par_iter().filter(|&&s| s).count();
        let changed = if self.previous.len() == support.len() {
            support
                .par_iter()
                .zip(self.previous.par_iter())
                .filter(|(a, b)| a != b)
                .count()
        } else {
            usize::MAX
        };
        self.previous = support;
        (changed as f64) <= self.rule.change * size as f64
    }
}

/// When [`run_lbfgs`] stops: at a relative duality gap of `tol`, or earlier where `settled`
/// says the support the iterate names no longer moves (a warm start's).
#[derive(Clone, Copy, Debug)]
pub(crate) struct LbfgsStop {
    pub tol: f64,
    pub settled: Option<SettledSupport>,
}

impl LbfgsStop {
    /// Stops at a relative duality gap of `tol` only.
    pub fn at_gap(tol: f64) -> Self {
        LbfgsStop { tol, settled: None }
    }
}

/// The paper's solver: L-BFGS on the dual in `U` with `Y = U o U`, from `u`, until the duality
/// gap of the best projected iterate is at most `stop.tol` (relative), `stop.settled` holds, or
/// `opts.max_iter`. Adds its iterations and evaluations to `info`; returns the last iterate `U`.
pub(crate) fn run_lbfgs(
    prob: &EliminatedProblem,
    opts: &BbwOptions,
    stop: LbfgsStop,
    mut u: Vec<f64>,
    best: &mut CertifiedBounds,
    info: &mut BbwInfo,
    progress: &mut dyn Progress,
) -> SkinResult<Vec<f64>> {
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
    let mut watch = stop.settled.map(|rule| SupportWatch {
        rule,
        previous: Vec::new(),
    });
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
        // The certificate costs a projection and two energy evaluations (the projected primal's
        // and the dual's lower bound); checking it every few iterations keeps the stop at most
        // GAP_EVERY - 1 iterations late.
        let mut done = false;
        if it % GAP_EVERY == 0 {
            // Taken, so that the certificate after the loop is not computed again for it.
            let dp = last.borrow_mut().take();
            let dp = dp.expect("objective evaluated before monitor");
            let feasible = project(opts, &dp.w, nf, m);
            let upper = prob.energy(&feasible);
            let settled_gap = watch
                .as_mut()
                .and_then(|w| w.settled(&feasible).then_some(w.rule.gap));
            best.update(&dp, dp.lower_bound(prob), feasible, upper);
            let gap = best.relative_gap();
            done = gap <= stop.tol || settled_gap.is_some_and(|g| gap <= g);
        }
        progress.report(Event {
            stage: "dual",
            iteration: it,
            value: best.relative_gap(),
        })?;
        Ok(if done { Step::Stop } else { Step::Continue })
    })?;
    // Certify the final iterate too if the loop ended between two gap checks.
    if let Some(dp) = last.borrow_mut().take() {
        let feasible = project(opts, &dp.w, nf, m);
        let upper = prob.energy(&feasible);
        best.update(&dp, dp.lower_bound(prob), feasible, upper);
    }
    info.iterations += iterations;
    info.evaluations += evaluations;
    Ok(u)
}

/// The paper's start (Sec. 8): uniform random `U`, scaled so each column of `U o U` sums to 1.
pub(crate) fn random_start(nf: usize, m: usize, blocks: usize, seed: u64) -> Vec<f64> {
    let mut rng = Rng::unmixed(seed);
    let mut u: Vec<f64> = (0..nf * m * blocks).map(|_| rng.uniform()).collect();
    for col in u.chunks_mut(nf) {
        let s: f64 = col.iter().map(|v| v * v).sum();
        let scale = 1.0 / s.sqrt().max(1e-300);
        col.iter_mut().for_each(|v| *v *= scale);
    }
    u
}

#[cfg(test)]
mod tests {
    use super::*;

    fn watch() -> SupportWatch {
        SupportWatch {
            rule: SettledSupport {
                gap: 6e-3,
                above: 0.1,
                change: 0.05,
            },
            previous: Vec::new(),
        }
    }

    #[test]
    fn a_support_settles_only_once_it_has_been_seen_twice() {
        let w: Vec<f64> = (0..100).map(|i| f64::from(i % 2)).collect();
        let mut watch = watch();
        assert!(!watch.settled(&w), "no previous support to compare with");
        assert!(watch.settled(&w));
    }

    #[test]
    fn a_support_settles_when_at_most_the_fraction_of_its_entries_changed() {
        // 50 entries above 0.1; 2 changed is 4 % of them, 3 is 6 %.
        let w: Vec<f64> = (0..100).map(|i| f64::from(i % 2)).collect();
        let mut two = w.clone();
        two[0] = 1.0;
        two[1] = 0.05;
        let mut three = two.clone();
        three[2] = 0.2;
        let mut watch = watch();
        watch.settled(&w);
        assert!(watch.settled(&two));
        watch.settled(&w);
        assert!(!watch.settled(&three));
    }
}
