//! What both iterations share: their options, their report, the stopping rule and the
//! progress record.

use crate::error::SkinResult;
use crate::progress::{Event, Progress};

pub(crate) struct SolveOptions {
    pub max_sweeps: usize,
    pub tol: f64,
    pub relaxation: f64,
    /// Conjugate gradients (vertices in input order, one class) instead of the local iteration.
    pub cg: bool,
}

/// The measured, scale-aware stopping rule: stop once the mean decrease of the objective over
/// the last (up to) [`STOP_WINDOW`] iterations is at most `tol` times the decrease achieved since
/// the start, `h[0] - h[s]`. Relative to what the iteration has achieved (not to `h[s]`, which
/// may be near zero or dominated by an error no weight can remove), so it does not depend on the
/// units of the poses; the window smooths the uneven decrease of conjugate gradients.
pub(crate) fn should_stop(history: &[f64], tol: f64) -> bool {
    let s = history.len() - 1;
    if s == 0 {
        return false;
    }
    let w = s.min(STOP_WINDOW);
    let recent = (history[s - w] - history[s]) / w as f64;
    recent <= tol * (history[0] - history[s])
}

/// Iterations averaged by [`should_stop`].
pub(crate) const STOP_WINDOW: usize = 4;

pub(crate) struct SolveReport {
    /// Objective before the first sweep and after each sweep.
    pub objective: Vec<f64>,
    pub converged: bool,
    /// Local QPs that hit the active-set iteration cap (kept feasible, not optimal).
    pub qp_capped: usize,
}

/// Appends the objective after a sweep (or the start) and reports it as progress.
pub(super) fn record(
    history: &mut Vec<f64>,
    f: f64,
    progress: &mut dyn Progress,
) -> SkinResult<()> {
    history.push(f);
    progress.report(Event {
        stage: "reduce",
        iteration: history.len() - 1,
        value: f,
    })
}
