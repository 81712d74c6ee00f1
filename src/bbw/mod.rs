//! Bounded biharmonic weights through the convex dual (paper 000: Solomon & Stein 2025).
//!
//! The primal (eq. 3) minimises `1/2 tr(W^T B W)` subject to partition of unity, `W >= 0` and
//! `W[b] = bc`. Because the constraint `C W = D` is a vertex selection, the constrained rows are
//! eliminated and the KKT system of eq. 7 reduces to the SPD block `A = B_ff`, factored once
//! ([`problem`]). The dual (eq. 12) is a non-negative least-squares problem in `Y` whose gradient
//! is the recovered primal `W = R + Q11 Y P_m` (eqs. 15-16) ([`dual`]); it is solved by L-BFGS on
//! `Y = U o U` (the paper's method, [`squared_lbfgs`]) or by a primal-dual active-set method
//! warm-started by a short run of it (the default, [`active_set`]), both stopped on a certified
//! duality gap ([`bounds`]).
//!
//! Dependencies run one way: [`solve`] (the front door) calls the solvers; [`active_set`] calls
//! [`squared_lbfgs`]; both read [`options`], [`bounds`], [`dual`] and [`problem`].

pub mod active_set;
mod bounds;
pub mod dual;
mod energy;
pub mod lbfgs;
mod options;
pub mod problem;
mod solve;
mod squared_lbfgs;
mod vector;

pub use energy::LaplacianEnergy;
pub use options::{BbwInfo, BbwOptions, Solver};
pub use problem::EliminatedProblem;
pub use solve::bbw_dual;
