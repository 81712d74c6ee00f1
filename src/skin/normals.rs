//! Vertex normals of a triangle mesh.

use ndarray::{Array2, ArrayView2};
use rayon::prelude::*;

use crate::error::SkinResult;
use crate::geometry::cross;
use crate::invalid;

/// Area-weighted per-vertex normals (libigl `per_vertex_normals` with
/// `PER_VERTEX_NORMALS_WEIGHTING_TYPE_AREA`).
///
/// Inputs: `v (n, 3)` positions, `f (k, 3)` triangles (indices checked by the caller or here).
/// Output: `(n, 3)` unit normals: the normalised sum of `(v1 - v0) x (v2 - v0)` (twice the area
/// times the unit face normal) over incident faces. A vertex with no incident face of positive
/// area gets the zero vector.
pub fn per_vertex_normals(
    v: ArrayView2<'_, f64>,
    f: ArrayView2<'_, usize>,
) -> SkinResult<Array2<f64>> {
    if v.ncols() != 3 {
        return invalid!(
            "per_vertex_normals needs V of shape (n, 3), got {:?}",
            v.dim()
        );
    }
    if f.ncols() != 3 {
        return invalid!("F must hold triangles (k, 3), got {:?}", f.dim());
    }
    let n = v.nrows();
    if let Some(&bad) = f.iter().find(|&&i| i >= n) {
        return invalid!("F holds index {bad}, outside 0..{n}");
    }
    crate::limits::check_coordinates("V", &v)?;
    let p = |i: usize| [v[[i, 0]], v[[i, 1]], v[[i, 2]]];
    let face: Vec<[f64; 3]> = (0..f.nrows())
        .into_par_iter()
        .map(|k| {
            let (a, b, c) = (p(f[[k, 0]]), p(f[[k, 1]]), p(f[[k, 2]]));
            cross(
                &[b[0] - a[0], b[1] - a[1], b[2] - a[2]],
                &[c[0] - a[0], c[1] - a[1], c[2] - a[2]],
            )
        })
        .collect();
    let mut acc = Array2::<f64>::zeros((n, 3));
    for (k, nf) in face.iter().enumerate() {
        for s in 0..3 {
            let i = f[[k, s]];
            for d in 0..3 {
                acc[[i, d]] += nf[d];
            }
        }
    }
    if let Some(flat) = acc.as_slice_mut() {
        flat.par_chunks_mut(3).for_each(|row| {
            // Divide by the largest entry first so the squared length cannot overflow.
            let big = row.iter().fold(0.0f64, |m, x| m.max(x.abs()));
            if big > 0.0 && big.is_finite() {
                row.iter_mut().for_each(|x| *x /= big);
                let len = (row[0] * row[0] + row[1] * row[1] + row[2] * row[2]).sqrt();
                row.iter_mut().for_each(|x| *x /= len);
            }
        });
    }
    if acc.iter().any(|x| !x.is_finite()) {
        return invalid!("V has a NaN or infinite entry (normals are not finite)");
    }
    Ok(acc)
}
