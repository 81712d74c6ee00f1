//! Bounded biharmonic weights through the convex dual (paper 000: Solomon & Stein 2025).
//!
//! The primal (eq. 3) minimises `1/2 tr(W^T B W)` subject to partition of unity, `W >= 0` and
//! `W[b] = bc`. Because the constraint `C W = D` is a vertex selection, the constrained rows are
//! eliminated and the KKT system of eq. 7 reduces to the SPD block `A = B_ff`, factored once
//! ([`problem`]). The dual (eq. 12) is a non-negative least-squares problem in `Y` whose gradient
//! is the recovered primal `W = R + Q11 Y P_m` (eqs. 15-16) ([`dual`]); it is solved by L-BFGS on
//! `Y = U o U` (the paper's method, [`lbfgs`]) and stopped on a measured duality gap.

pub mod active_set;
pub mod dual;
pub mod lbfgs;
pub mod problem;
mod solve;
mod vector;

pub use problem::EliminatedProblem;
pub use solve::{bbw_dual, BbwInfo, BbwOptions, Solver};
