//! The coordinate range skinrs accepts, and its checks.
//!
//! Squared distances, areas, volumes and the fourth-order moments of the fast winding numbers
//! are formed from coordinates directly; with every coordinate at most [`COORD_MAX`] in
//! magnitude none of them can overflow, and with a shape at least [`EXTENT_MIN`] across none of
//! its element measures underflows. Outside that range skinrs refuses the input with a message
//! that says "overflow" or "underflow" instead of returning inf, NaN or a "degenerate" error.
//! The geometric field normalises its shape to the unit box internally.

use ndarray::ArrayView2;

use crate::error::SkinResult;
use crate::invalid;

/// Largest accepted coordinate magnitude (`COORD_MAX^4` is still a finite double).
pub const COORD_MAX: f64 = 1e75;

/// Smallest accepted extent (bounding-box diagonal) of a mesh.
pub const EXTENT_MIN: f64 = 1e-75;

/// Every entry of `x` is finite and at most [`COORD_MAX`] in magnitude; `name` is the
/// argument named in the error.
pub fn check_coordinates(name: &str, x: &ArrayView2<f64>) -> SkinResult<()> {
    for (r, row) in x.rows().into_iter().enumerate() {
        for &v in row.iter() {
            if !v.is_finite() {
                return invalid!("{name} has a NaN or infinite entry (row {r})");
            }
            if v.abs() > COORD_MAX {
                return invalid!(
                    "{name} row {r} has an entry of magnitude {:e}, beyond {COORD_MAX:e}: \
                     distances and areas would overflow double precision; rescale the data",
                    v.abs()
                );
            }
        }
    }
    Ok(())
}

/// The extent (bounding-box diagonal) `diag` of a mesh is at least [`EXTENT_MIN`].
pub fn check_extent(name: &str, diag: f64) -> SkinResult<()> {
    if diag > 0.0 && diag < EXTENT_MIN {
        return invalid!(
            "{name} spans only {diag:e} (bounding-box diagonal), below {EXTENT_MIN:e}: its \
             lengths, areas and volumes would underflow double precision; rescale the data"
        );
    }
    Ok(())
}
