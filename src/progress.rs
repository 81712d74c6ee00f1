//! How long computations report progress and learn that they should stop.
//!
//! Numerical code calls [`Progress::report`] every iteration (cheaply); the Python binding
//! implementation throttles, checks for Ctrl-C and forwards to the user's callback.

use crate::error::SkinResult;

/// One progress event of a long computation.
#[derive(Debug, Clone, Copy)]
pub struct Event<'a> {
    /// Which phase is running, e.g. `"factor"`, `"dual"`, `"polish"`.
    pub stage: &'a str,
    /// Iteration within the phase.
    pub iteration: usize,
    /// A phase-specific measure (objective, residual, ...), `NaN` when there is none.
    pub value: f64,
}

pub trait Progress {
    /// Called now and then by a long computation; an `Err` (usually
    /// [`crate::SkinError::Interrupted`]) stops it and is returned to the caller.
    fn report(&mut self, event: Event<'_>) -> SkinResult<()>;
}

/// Reports nothing, never interrupts.
pub struct Silent;

impl Progress for Silent {
    fn report(&mut self, _event: Event<'_>) -> SkinResult<()> {
        Ok(())
    }
}
