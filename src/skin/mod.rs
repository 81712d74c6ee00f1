//! skin: deforming a mesh with per-handle transforms.
//!
//! * [`lbs::lbs`]: linear blend skinning, `u_i = sum_j w_ij T_j [v_i; 1]`.
//! * [`dqs::dqs`]: dual-quaternion skinning (Kavan et al. 2008, "Geometric skinning with
//!   approximate dual quaternion blending", Algorithm 1), for rigid transforms.
//! * [`fk::forward_kinematics`]: per-bone relative rotations about each bone's rest joint,
//!   composed parent -> child, to absolute affine transforms.
//! * [`normals`]: area-weighted vertex normals of a triangle mesh.
//!
//! Weights come dense `(n, m)` or packed with a fixed number `k` of influences per vertex
//! (`index (n, k)`, `weight (n, k)`); see [`Weights`].

pub mod dqs;
pub mod fk;
pub mod lbs;
pub mod normals;
pub mod quat;

mod blend;

use ndarray::{ArrayView2, ArrayView3, ArrayViewMut2, CowArray, Ix2};

use crate::error::{SkinError, SkinResult};
use crate::invalid;

pub use dqs::{dqs, dqs_into, dqs_with_normals};
pub use fk::{bone_parents, forward_kinematics};
pub use lbs::{lbs, lbs_into, lbs_with_normals};
pub use normals::per_vertex_normals;

/// Skinning weights of `n` vertices over `m` handles.
#[derive(Debug, Clone, Copy)]
pub enum Weights<'a> {
    /// `W (n, m)`: weight of handle `j` at vertex `i` is `W[i, j]`.
    Dense(ArrayView2<'a, f64>),
    /// Fixed `k` influences per vertex: handle `index[i, l]` has weight `weight[i, l]`.
    /// Unused slots carry weight 0 (with any valid index).
    Packed {
        index: ArrayView2<'a, i64>,
        weight: ArrayView2<'a, f64>,
    },
}

impl Weights<'_> {
    /// Number of vertices the weights describe.
    pub fn rows(&self) -> usize {
        match self {
            Weights::Dense(w) => w.nrows(),
            Weights::Packed { weight, .. } => weight.nrows(),
        }
    }

    /// Checks the layout against `n` vertices and `m` handles.
    fn check(&self, n: usize, m: usize) -> SkinResult<()> {
        match self {
            Weights::Dense(w) => {
                if w.dim() != (n, m) {
                    return invalid!(
                        "W has shape {:?}, expected ({n}, {m}): one row per vertex, one column per \
                         transform",
                        w.dim()
                    );
                }
            }
            Weights::Packed { index, weight } => {
                if index.dim() != weight.dim() {
                    return invalid!(
                        "packed weights: indices {:?} and weights {:?} must have the same shape",
                        index.dim(),
                        weight.dim()
                    );
                }
                if weight.nrows() != n {
                    return invalid!(
                        "packed weights have {} rows, expected {n} (one per vertex)",
                        weight.nrows()
                    );
                }
                if weight.ncols() == 0 {
                    return invalid!("packed weights need at least one influence per vertex");
                }
            }
        }
        Ok(())
    }
}

/// Row-major contiguous data of a 2D view (copies only when the view is not already so).
pub(crate) fn standard2<A: Clone>(a: ArrayView2<'_, A>) -> CowArray<'_, A, Ix2> {
    if a.is_standard_layout() {
        CowArray::from(a)
    } else {
        CowArray::from(a.as_standard_layout().into_owned())
    }
}

/// The contiguous slice of a standard-layout array.
pub(crate) fn slice_of<'a, A, D: ndarray::Dimension>(
    a: &'a CowArray<'_, A, D>,
) -> SkinResult<&'a [A]> {
    a.as_slice()
        .ok_or_else(|| SkinError::Numerical("internal: array not contiguous".into()))
}

/// Transforms `T (m, d, d+1)` as `m` blocks of `d` rows `[R_p0 .. R_p(d-1), t_p]` padded with
/// zeros to 4 lanes (see [`blend::Lanes`]), each checked finite.
pub(crate) fn transform_blocks<const D: usize>(
    t: ArrayView3<'_, f64>,
) -> SkinResult<Vec<blend::Lanes<D>>> {
    let (m, r, c) = t.dim();
    if m == 0 {
        return invalid!("T must hold at least one transform");
    }
    if (r, c) != (D, D + 1) {
        return invalid!(
            "T has shape ({m}, {r}, {c}); for {D}D points each transform must be {D}x{} [R | t]",
            D + 1
        );
    }
    let mut out = vec![[[0.0; 4]; D]; m];
    for (j, block) in out.iter_mut().enumerate() {
        for a in 0..D {
            for b in 0..=D {
                let x = t[[j, a, b]];
                if !x.is_finite() {
                    return invalid!("T[{j}] has a NaN or infinite entry");
                }
                block[a][b] = x;
            }
        }
    }
    Ok(out)
}

/// Names the first non-finite input after a skinning result came out non-finite at `vertex`.
pub(crate) fn explain_nonfinite(
    vertex: usize,
    v: ArrayView2<'_, f64>,
    w: &Weights<'_>,
    extra: Option<ArrayView2<'_, f64>>,
) -> SkinError {
    let bad_row = |a: ArrayView2<'_, f64>| a.row(vertex).iter().any(|x| !x.is_finite());
    let msg = if bad_row(v) {
        format!("V has a NaN or infinite entry (row {vertex})")
    } else if match w {
        Weights::Dense(w) => bad_row(*w),
        Weights::Packed { weight, .. } => bad_row(*weight),
    } {
        format!("W has a NaN or infinite entry (row {vertex})")
    } else if extra.is_some_and(bad_row) {
        format!("N has a NaN or infinite entry (row {vertex})")
    } else {
        format!("the skinned position of vertex {vertex} overflowed (huge V, W or T entries)")
    };
    SkinError::InvalidInput(msg)
}

/// Checks that the rest normals, when given, have one row of `d` entries per vertex.
pub(crate) fn check_normals(
    normals: Option<&ArrayView2<'_, f64>>,
    n: usize,
    d: usize,
) -> SkinResult<()> {
    match normals {
        Some(a) if a.dim() != (n, d) => {
            invalid!("N must have shape ({n}, {d}) like V, got {:?}", a.dim())
        }
        _ => Ok(()),
    }
}

/// Checks the output arrays of a skinning call and returns them as flat slices.
/// `want_normals` says whether normals were given (then `nout` is required).
pub(crate) fn outputs<'a, 'b>(
    n: usize,
    d: usize,
    out: &'a mut ArrayViewMut2<'b, f64>,
    nout: Option<ArrayViewMut2<'a, f64>>,
    want_normals: bool,
) -> SkinResult<(&'a mut [f64], Option<&'a mut [f64]>)> {
    if out.dim() != (n, d) {
        return invalid!("out has shape {:?}, expected ({n}, {d}) like V", out.dim());
    }
    let o = match out.as_slice_mut() {
        Some(o) => o,
        None => return invalid!("out must be a C-contiguous array"),
    };
    let no = match (nout, want_normals) {
        (None, false) => None,
        (Some(nv), true) => {
            if nv.dim() != (n, d) {
                return invalid!(
                    "the normals output must have shape ({n}, {d}), got {:?}",
                    nv.dim()
                );
            }
            match nv.into_slice() {
                Some(s) => Some(s),
                None => return invalid!("the normals output must be a C-contiguous array"),
            }
        }
        _ => {
            return Err(SkinError::Numerical(
                "internal: normals input and output must come together".into(),
            ))
        }
    };
    Ok((o, no))
}

/// Vertices per parallel work item: big enough to amortise scheduling, small enough that the
/// chunk's output stays in L1/L2 for the finiteness check and that 2+ threads get balanced work.
pub(crate) const CHUNK: usize = 2048;
