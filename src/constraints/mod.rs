//! Handle and bone constraints: which mesh vertices are held, and to which values.
//!
//! Columns of the weight matrix are ordered as in libigl: point handles `P` first, then bones
//! `BE` (paper 000, Sec. 7: "C and D are binary matrices that enforce the Kronecker delta
//! constraints").

mod boundary_conditions;

pub use boundary_conditions::{boundary_conditions, BoundaryConditions, DEFAULT_TOL};
