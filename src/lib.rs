//! skinrs: exact bounded biharmonic skinning weights, weight reduction and skinning.
//!
//! The crate is organised by capability, one folder each. Every numerical routine is plain Rust
//! on `ndarray` views and `faer` sparse matrices; the PyO3 bindings live in [`py`] and hold no
//! numerics.

pub mod bbw;
pub mod constraints;
mod cpu;
pub mod error;
pub mod field;
mod geometry;
mod heap;
pub mod limits;
pub mod operators;
pub mod progress;
pub mod reduce;
pub mod rng;
pub mod skin;
pub mod sparse;

mod py;

pub use error::{SkinError, SkinResult};
pub use progress::{Progress, Silent};
