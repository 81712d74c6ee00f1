//! The one error type of the crate. The Python layer maps each variant to an exception:
//! `InvalidInput` -> `ValueError`, `Interrupted` -> `KeyboardInterrupt`, `Numerical` -> `RuntimeError`,
//! `OutOfMemory` -> `MemoryError`.

use std::fmt;

#[derive(Debug, Clone, PartialEq)]
pub enum SkinError {
    /// The caller's data is wrong (shape, range, degenerate geometry, ...). The message says what.
    InvalidInput(String),
    /// A progress callback or Ctrl-C asked the computation to stop.
    Interrupted,
    /// A factorisation or solver failed on data that passed validation.
    Numerical(String),
    /// A computation would allocate more than the memory it was given; the message says how
    /// much and which argument sets the limit.
    OutOfMemory(String),
}

pub type SkinResult<T> = Result<T, SkinError>;

impl fmt::Display for SkinError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            SkinError::InvalidInput(s) => write!(f, "{s}"),
            SkinError::Interrupted => write!(f, "interrupted"),
            SkinError::Numerical(s) | SkinError::OutOfMemory(s) => write!(f, "{s}"),
        }
    }
}

impl std::error::Error for SkinError {}

/// Shorthand for `Err(SkinError::InvalidInput(format!(...)))`.
#[macro_export]
macro_rules! invalid {
    ($($arg:tt)*) => {
        Err($crate::error::SkinError::InvalidInput(format!($($arg)*)))
    };
}
