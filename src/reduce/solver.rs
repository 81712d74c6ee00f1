//! The minimisation shared by the smooth (paper 002 Sec. 3.1), geometric (3.2), Poisson (3.3)
//! and skeletal (Sec. 4) reductions, and the choice of iteration for it.
//!
//! Every method minimises, over the packed weights `alpha_v (k)` of each vertex,
//!
//! ```text
//!   Phi(alpha) = tr(E^T Q E),   E = X(alpha) - Xbar,   x_v(alpha) = B_v alpha_v
//! ```
//!
//! where row `x_v` stacks what the vertex does in every pose (`B_v`'s columns are the positions
//! `c_i^j` or `M_i^j v` of its `k` handles over all poses, or for the smooth method the unit
//! vectors of its influence set) and `Xbar` is the same for the original weights. `Q` is the
//! identity (geometric, eq. 3), `L M^-1 L` (squared Laplacian, eqs. 4-5 discretised as
//! `int (lap e)^2 dA ~ (L e)^T M^-1 (L e)`) or `-L` (gradient form `int |grad e|^2 dA`), `L` the
//! cotangent Laplacian and `M` the lumped mass.
//!
//! One vertex's block of `Phi` with all other vertices fixed is
//! `Q_vv |B_v alpha|^2 + 2 alpha^T B_v^T (R_v - Q_vv x_v)` with `R = Q E`, `E = X - Xbar`: a
//! `k`-variable QP solved exactly by [`super::qp`]. Vertices not coupled by `Q` (distance > 2 for
//! the squared Laplacian, > 1 for `-L`) do not interact, so a greedy colouring of `Q`'s graph gives
//! classes that are updated in parallel; the sweep over all classes is block Gauss-Seidel,
//! optionally over-relaxed ([`super::local`]). `E` and `R` are kept up to date, so the global
//! objective is measured after every sweep.
//!
//! Without bounds the problem is linear (one sparse KKT system), and [`super::cg`]
//! minimises it by projected conjugate gradients with the same per-vertex blocks as
//! preconditioner plus an aggregation coarse space ([`super::coarse`]); it reports the
//! objective after every iteration in the same way. Both stop by [`should_stop`]: when the
//! mean decrease over the last few sweeps is at most `tol` times the decrease since the start.
//!
//! The modules: [`super::problem`] (the data and the objective), [`super::basis`] (`B_v`),
//! [`super::coupling`] (`Q`), [`super::blocks`] (the per-vertex projected inverses),
//! [`super::local`] and [`super::cg`] (the two iterations), [`super::coarse`] (the coarse space
//! of conjugate gradients).

use ndarray::Array2;

use crate::error::{SkinError, SkinResult};
use crate::progress::Progress;

#[cfg(doc)]
use super::iteration::should_stop;
use super::iteration::{SolveOptions, SolveReport};
use super::problem::{qp_error, Problem};
use super::qp::QpFailure;

/// Which iteration minimises a coupled problem.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Solver {
    /// Conjugate gradients when there are no bounds, the local iteration otherwise.
    Auto,
    /// The local iteration of Sec. 3.1 (block Gauss-Seidel / SOR over the colour classes).
    Local,
    /// Projected preconditioned conjugate gradients (equality constraints only).
    Cg,
}

impl Solver {
    /// Parses `"auto"`, `"local"` or `"cg"`.
    pub fn parse(s: &str) -> SkinResult<Self> {
        match s {
            "auto" => Ok(Solver::Auto),
            "local" => Ok(Solver::Local),
            "cg" => Ok(Solver::Cg),
            _ => crate::invalid!("unknown solver {s:?}: use 'auto', 'local' or 'cg'"),
        }
    }
}

impl Problem<'_> {
    /// Minimises from the feasible start `alpha` (n, k), in place: one exact sweep when no two
    /// vertices interact (geometric), projected conjugate gradients for coupled problems
    /// without bounds ([`Solver::Auto`] / [`Solver::Cg`]), the local iteration otherwise.
    pub(crate) fn solve(
        &self,
        alpha: &mut Array2<f64>,
        opts: &SolveOptions,
        progress: &mut dyn Progress,
    ) -> SkinResult<SolveReport> {
        let decoupled = self.coupling.is_diagonal();
        // One exact sweep of decoupled vertices solves each local QP once: no blocks to reuse.
        let fast = if decoupled {
            None
        } else {
            self.fast_operators()
        };
        if !opts.cg {
            return self.solve_local(alpha, opts, fast.as_ref(), decoupled, progress);
        }
        match &fast {
            Some(f) => match f.ok.iter().position(|&x| !x) {
                None => super::cg::solve(self, alpha, opts, f, progress),
                Some(v) => Err(qp_error(self.order[v], QpFailure::DependentConstraints)),
            },
            None => Err(SkinError::InvalidInput(
                "conjugate gradients need n k^2 <= 2^25 (memory for the per-vertex blocks); \
                 use solver='local'"
                    .into(),
            )),
        }
    }
}
