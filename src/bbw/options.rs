//! What a BBW solve is asked to do ([`BbwOptions`], [`Solver`]) and what it reports
//! ([`BbwInfo`]).

use crate::error::SkinResult;
use crate::invalid;

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
    /// Bytes the solve's large allocations may take: the factor of `B_ff`, the dense vectors
    /// ([`BbwOptions::vector_bytes`]) and the active set's support factors. `usize::MAX`: no
    /// limit.
    pub memory_limit: usize,
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
            memory_limit: usize::MAX,
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
    /// Within the active-set phase: factoring the per-column support blocks, CG on `mu`, and
    /// the smoother's sweeps.
    pub time_support_factor: f64,
    pub time_cg: f64,
    pub time_smooth: f64,
    /// Bytes of the factor of `B_ff`, of the dense vectors ([`BbwOptions::vector_bytes`]), and
    /// the most the support factors of one active-set round took (or would have taken, when
    /// they did not fit `memory_limit`).
    pub factor_bytes: usize,
    pub vector_bytes: usize,
    pub support_factor_bytes: usize,
    /// The support factors did not fit `memory_limit`, and L-BFGS on the dual finished the solve.
    pub memory_fallback: bool,
}

impl BbwOptions {
    /// Number of `nf x m` blocks of dual variables: `Y` with partition of unity, `(Y, U)`
    /// without (App. B).
    pub(crate) fn dual_blocks(&self) -> usize {
        if self.partition_of_unity {
            1
        } else {
            2
        }
    }

    /// Bytes of the dense vectors a solve with `nf` free rows and `m` columns holds besides the
    /// factors: L-BFGS's `memory` correction pairs (two single-precision vectors each) and
    /// about a dozen double-precision working copies, each of the size of the dual variables.
    pub(crate) fn vector_bytes(&self, nf: usize, m: usize) -> usize {
        let entries = nf.saturating_mul(m).saturating_mul(self.dual_blocks());
        entries.saturating_mul(8 * (self.memory + 12))
    }
}
