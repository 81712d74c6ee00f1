//! The bound tracker of the certified duality gap.

use super::dual::DualPoint;

/// The bounds that certify a solve: the lowest energy of a feasible point seen so far (with that
/// point) and the highest lower bound on the optimal energy (from a dual point). Their relative
/// difference is the certified gap the solvers stop on.
pub(crate) struct CertifiedBounds {
    /// Energy of `w`, the best feasible point.
    pub upper: f64,
    /// Best lower bound on the optimal energy.
    pub lower: f64,
    /// Free rows of the best feasible weights, `nf x m` column-major.
    pub w: Vec<f64>,
    /// Dual objective at the last dual point recorded.
    pub dual_objective: f64,
    /// Extremes of the raw (unprojected) weights `w` was projected from.
    pub min_raw: f64,
    pub max_raw: f64,
}

impl CertifiedBounds {
    pub fn new() -> Self {
        CertifiedBounds {
            upper: f64::INFINITY,
            lower: f64::NEG_INFINITY,
            w: vec![],
            dual_objective: f64::NAN,
            min_raw: f64::NAN,
            max_raw: f64::NAN,
        }
    }
    /// Records the dual point's lower bound `lower` and, if it is better, the projected primal.
    pub fn update(&mut self, dp: &DualPoint, lower: f64, feasible: Vec<f64>, upper: f64) {
        self.bound(dp, lower);
        self.offer(&dp.w, feasible, upper);
    }
    /// Records the dual point's lower bound `lower` ([`DualPoint::lower_bound`]) only.
    pub fn bound(&mut self, dp: &DualPoint, lower: f64) {
        self.lower = self.lower.max(lower);
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
