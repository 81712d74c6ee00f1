//! Constrained vertices `b` and their values `bc` from point handles and bones.

use ndarray::{Array2, ArrayView1, ArrayView2};
use rayon::prelude::*;

use crate::error::SkinResult;
use crate::invalid;

/// Default distance tolerance, relative to the bounding-box diagonal of `V`. On unit-size
/// meshes it equals libigl's `FLOAT_EPS` test on squared distances (`sqrd <= 1e-7`).
pub const DEFAULT_TOL: f64 = 3.162_277_660_168_379_5e-4;

/// Constrained vertices and their prescribed weights.
#[derive(Debug, Clone, PartialEq)]
pub struct BoundaryConditions {
    /// Constrained vertex indices, strictly increasing, `(k,)`.
    pub b: Vec<usize>,
    /// Prescribed weights, `(k, m)` with `m = #P + #BE`; each row sums to 1.
    pub bc: Array2<f64>,
}

/// Finds the mesh vertices that lie on point handles and bone segments.
///
/// Inputs:
///   v   `(n, d)` vertex positions (d = 2 or 3)
///   c   `(h, d)` control-point (joint) positions
///   p   `(#P,)` indices into `c` of point handles
///   be  `(#BE, 2)` bone edges, indices into `c`
///   tol distance tolerance relative to the bounding-box diagonal of `v`
/// Output: `b` sorted, and `bc (k, #P + #BE)`. A vertex on a point handle or bone gets 1 in that
/// column; a vertex on several (a joint shared by bones) is shared equally between them, as
/// libigl's `boundary_conditions` does.
///
/// Errors: a handle or bone with no vertex on it (libigl silently returns zero weights then),
/// duplicate point handles, duplicate or zero-length bones.
pub fn boundary_conditions(
    v: ArrayView2<f64>,
    c: ArrayView2<f64>,
    p: &[usize],
    be: ArrayView2<usize>,
    tol: f64,
) -> SkinResult<BoundaryConditions> {
    let d = v.ncols();
    if c.ncols() != d {
        return invalid!("C has {} columns but V has {d}; they must match", c.ncols());
    }
    if !(tol.is_finite() && tol > 0.0) {
        return invalid!("tol must be a positive finite number, got {tol}");
    }
    let m = p.len() + be.nrows();
    if m == 0 {
        return invalid!("no handles: give point handles P and/or bone edges BE");
    }
    check_distinct_handles(c, p, be)?;
    let eps = tol * bbox_diagonal(v);
    let eps2 = eps * eps;

    // For each column, the vertices within `eps` of its handle or bone (parallel over columns).
    let hits: Vec<Vec<usize>> = (0..m)
        .into_par_iter()
        .map(|col| {
            (0..v.nrows())
                .filter(|&i| {
                    let x = v.row(i);
                    if col < p.len() {
                        dist2(x, c.row(p[col])) <= eps2
                    } else {
                        let e = col - p.len();
                        segment_dist2(x, c.row(be[[e, 0]]), c.row(be[[e, 1]]), eps) <= eps2
                    }
                })
                .collect()
        })
        .collect();

    for (col, h) in hits.iter().enumerate() {
        if h.is_empty() {
            let what = if col < p.len() {
                format!("point handle {col} (C row {})", p[col])
            } else {
                let e = col - p.len();
                format!("bone {e} (C rows {} -> {})", be[[e, 0]], be[[e, 1]])
            };
            return invalid!(
                "{what} has no mesh vertex within {eps:.3e} of it; insert its samples as vertices \
                 (e.g. skinrs.mesh_with_skeleton) or raise tol"
            );
        }
    }

    let mut b: Vec<usize> = hits.iter().flatten().copied().collect();
    b.sort_unstable();
    b.dedup();
    let mut bc = Array2::<f64>::zeros((b.len(), m));
    for (col, h) in hits.iter().enumerate() {
        for &i in h {
            let r = b.binary_search(&i).expect("hit vertex is in b");
            bc[[r, col]] = 1.0;
        }
    }
    for mut row in bc.rows_mut() {
        let s = row.sum();
        row.mapv_inplace(|x| x / s);
    }
    Ok(BoundaryConditions { b, bc })
}

fn check_distinct_handles(
    c: ArrayView2<f64>,
    p: &[usize],
    be: ArrayView2<usize>,
) -> SkinResult<()> {
    for i in 0..p.len() {
        for j in 0..i {
            if c.row(p[i]) == c.row(p[j]) {
                return invalid!("point handles {j} and {i} are at the same position");
            }
        }
    }
    let key = |e: usize| {
        let (a, b) = (be[[e, 0]], be[[e, 1]]);
        if c.row(a) == c.row(b) {
            None
        } else {
            Some((a.min(b), a.max(b)))
        }
    };
    for e in 0..be.nrows() {
        let Some(ke) = key(e) else {
            return invalid!("bone {e} has zero length (both ends at the same position)");
        };
        for f in 0..e {
            let same_pos = |x: usize, y: usize| c.row(x) == c.row(y);
            let (a, b) = (be[[e, 0]], be[[e, 1]]);
            let (x, y) = (be[[f, 0]], be[[f, 1]]);
            if key(f) == Some(ke)
                || (same_pos(a, x) && same_pos(b, y))
                || (same_pos(a, y) && same_pos(b, x))
            {
                return invalid!("bones {f} and {e} coincide");
            }
        }
    }
    Ok(())
}

fn bbox_diagonal(v: ArrayView2<f64>) -> f64 {
    let mut s = 0.0;
    for col in v.columns() {
        let lo = col.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = col.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        s += (hi - lo) * (hi - lo);
    }
    // A single vertex has no extent; fall back to an absolute scale of 1.
    if s > 0.0 {
        s.sqrt()
    } else {
        1.0
    }
}

fn dist2(a: ArrayView1<f64>, b: ArrayView1<f64>) -> f64 {
    a.iter().zip(b.iter()).map(|(x, y)| (x - y) * (x - y)).sum()
}

/// Squared distance from `x` to the segment `s0 s1`; infinite when the projection parameter
/// falls outside the segment by more than `eps` along it.
fn segment_dist2(x: ArrayView1<f64>, s0: ArrayView1<f64>, s1: ArrayView1<f64>, eps: f64) -> f64 {
    let mut dd = 0.0;
    let mut xd = 0.0;
    for k in 0..x.len() {
        let dk = s1[k] - s0[k];
        dd += dk * dk;
        xd += (x[k] - s0[k]) * dk;
    }
    let t = xd / dd;
    let slack = eps / dd.sqrt();
    if t < -slack || t > 1.0 + slack {
        return f64::INFINITY;
    }
    (0..x.len())
        .map(|k| {
            let q = s0[k] + t * (s1[k] - s0[k]);
            (x[k] - q) * (x[k] - q)
        })
        .sum()
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::array;

    #[test]
    fn joint_is_shared_between_bones() {
        let v = array![
            [0.0, 0.0],
            [0.5, 0.0],
            [1.0, 0.0],
            [1.5, 0.0],
            [2.0, 0.0],
            [1.0, 1.0]
        ];
        let c = array![[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]];
        let be = array![[0usize, 1], [1, 2]];
        let r = boundary_conditions(v.view(), c.view(), &[], be.view(), DEFAULT_TOL).unwrap();
        assert_eq!(r.b, vec![0, 1, 2, 3, 4]);
        assert_eq!(r.bc.row(2).to_vec(), vec![0.5, 0.5]);
        assert_eq!(r.bc.row(0).to_vec(), vec![1.0, 0.0]);
    }

    #[test]
    fn bone_without_vertex_is_an_error() {
        let v = array![[0.0, 0.0], [1.0, 0.0]];
        let c = array![[0.0, 0.5], [1.0, 0.5]];
        let be = array![[0usize, 1]];
        let e = boundary_conditions(v.view(), c.view(), &[], be.view(), DEFAULT_TOL).unwrap_err();
        assert!(format!("{e}").contains("bone 0"));
    }
}
