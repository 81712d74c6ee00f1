//! Example poses, deformation by (packed) weights over all poses (the shared linear blend
//! skinning of [`crate::skin`]), the approximate normal transform of paper 002 Sec. 5 and the
//! error metrics of Sec. 6.

use ndarray::{s, Array2, Array3, ArrayView2, ArrayView3, ArrayView4, Axis};
use rayon::prelude::*;

use crate::error::SkinResult;
use crate::geometry::cross;
use crate::invalid;
use crate::skin::{lbs_into, lbs_with_normals, per_vertex_normals, Weights};

/// Row `i` of `v`, zero-padded to 3D.
pub(crate) fn point(v: ArrayView2<f64>, i: usize) -> [f64; 3] {
    let mut x = [0.0; 3];
    for (c, xc) in x.iter_mut().enumerate().take(v.ncols()) {
        *xc = v[[i, c]];
    }
    x
}

/// Example poses of a rig: what every handle does in every pose.
#[derive(Clone, Copy, Debug)]
pub enum Poses<'a> {
    /// `(p, m, d)`: the position of each of the `m` control points in each of the `p` poses
    /// (cages deformed through barycentric coordinates, eq. 1).
    ControlPoints(ArrayView3<'a, f64>),
    /// `(p, m, d, d + 1)`: per-pose affine bone transforms `[A | t]` (skeletons, Sec. 4).
    Bones(ArrayView4<'a, f64>),
}

impl Poses<'_> {
    /// Number of poses `p`.
    pub fn count(&self) -> usize {
        match self {
            Poses::ControlPoints(c) => c.shape()[0],
            Poses::Bones(t) => t.shape()[0],
        }
    }

    /// Number of handles `m`.
    pub fn handles(&self) -> usize {
        match self {
            Poses::ControlPoints(c) => c.shape()[1],
            Poses::Bones(t) => t.shape()[1],
        }
    }

    /// Checks shapes against `m` handles in dimension `d`, and finiteness.
    pub fn check(&self, m: usize, d: usize) -> SkinResult<()> {
        let (name, shape, want) = match self {
            Poses::ControlPoints(c) => ("control_points", c.shape().to_vec(), vec![m, d]),
            Poses::Bones(t) => ("bone_transforms", t.shape().to_vec(), vec![m, d, d + 1]),
        };
        if shape[0] == 0 {
            return invalid!("{name} holds no pose (shape {shape:?})");
        }
        if shape[1..] != want[..] {
            return invalid!(
                "{name} must have shape (p, {}) for {m} handles in {d}D, got {shape:?}",
                want.iter()
                    .map(|x| x.to_string())
                    .collect::<Vec<_>>()
                    .join(", ")
            );
        }
        let finite = match self {
            Poses::ControlPoints(c) => c.iter().all(|x| x.is_finite()),
            Poses::Bones(t) => t.iter().all(|x| x.is_finite()),
        };
        if !finite {
            return invalid!("{name} has a NaN or infinite entry");
        }
        Ok(())
    }

    /// Position of handle `i` acting on rest point `x` in pose `j`: `c_i^j` or `M_i^j x`.
    #[inline]
    pub(crate) fn handle_point(&self, j: usize, i: usize, x: &[f64; 3], d: usize, out: &mut [f64]) {
        match self {
            Poses::ControlPoints(c) => {
                for a in 0..d {
                    out[a] = c[[j, i, a]];
                }
            }
            Poses::Bones(t) => {
                for a in 0..d {
                    let mut s = t[[j, i, a, d]];
                    for b in 0..d {
                        s += t[[j, i, a, b]] * x[b];
                    }
                    out[a] = s;
                }
            }
        }
    }
}

/// Checks packed weights `(indices, weights)`, both `(n, k)`, against `m` handles.
pub(crate) fn check_packed(
    idx: ArrayView2<usize>,
    w: ArrayView2<f64>,
    n: usize,
    m: usize,
) -> SkinResult<()> {
    if idx.dim() != w.dim() {
        return invalid!(
            "indices and weights must have the same shape, got {:?} and {:?}",
            idx.dim(),
            w.dim()
        );
    }
    if idx.nrows() != n {
        return invalid!(
            "weights must have one row per vertex ({n}), got {}",
            idx.nrows()
        );
    }
    if let Some(bad) = idx.iter().find(|&&i| i >= m) {
        return invalid!("indices holds handle {bad}, outside 0..{m}");
    }
    if w.iter().any(|x| !x.is_finite()) {
        return invalid!("weights has a NaN or infinite entry");
    }
    Ok(())
}

/// The `(m, d, d + 1)` transforms of pose `j`: the bone transforms, or for a cage `[0 | c_i^j]`,
/// with which linear blend skinning is the cage blend `sum_i w_i c_i^j` (eq. 1).
fn pose_transforms(poses: &Poses, j: usize, d: usize) -> Array3<f64> {
    match poses {
        Poses::Bones(t) => t.index_axis(Axis(0), j).to_owned(),
        Poses::ControlPoints(c) => {
            let m = c.shape()[1];
            let mut t = Array3::zeros((m, d, d + 1));
            t.slice_mut(s![.., .., d]).assign(&c.index_axis(Axis(0), j));
            t
        }
    }
}

/// Deforms the rest vertices over every pose: `x_v^j = sum_i w_vi q(v, i, j)` with
/// `q = c_i^j` (cages) or `M_i^j v` (bones), by [`crate::skin::lbs_into`].
///
/// Inputs: `v (n, d)` rest vertices; `w` dense or packed weights over the `m` handles of
/// `poses`. Output: `(p, n, d)` deformed positions.
pub fn deform(v: ArrayView2<f64>, w: &Weights, poses: &Poses) -> SkinResult<Array3<f64>> {
    let (n, d) = v.dim();
    if !(2..=3).contains(&d) {
        return invalid!("V must have 2 or 3 columns, got {d}");
    }
    poses.check(poses.handles(), d)?;
    let mut out = Array3::zeros((poses.count(), n, d));
    for (j, x) in out.outer_iter_mut().enumerate() {
        lbs_into(v, w, pose_transforms(poses, j, d).view(), None, x, None)?;
    }
    Ok(out)
}

#[cfg(test)]
fn det3(m: &[[f64; 3]; 3]) -> f64 {
    m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
        - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
        + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
}

/// Adjugate `adj(m) = det(m) m^-1`, i.e. the transpose of the cofactor matrix.
fn adjugate3(m: &[[f64; 3]; 3]) -> [[f64; 3]; 3] {
    let mut a = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            // cofactor C_ji, placed at (i, j)
            let (r0, r1) = ((j + 1) % 3, (j + 2) % 3);
            let (c0, c1) = ((i + 1) % 3, (i + 2) % 3);
            a[i][j] = m[r0][c0] * m[r1][c1] - m[r0][c1] * m[r1][c0];
        }
    }
    a
}

fn matvec3(m: &[[f64; 3]; 3], x: &[f64; 3]) -> [f64; 3] {
    std::array::from_fn(|i| m[i][0] * x[0] + m[i][1] * x[1] + m[i][2] * x[2])
}

/// Deforms rest normals without mesh adjacency (paper 002 Sec. 5).
///
/// Skeletons: `n' ~ (sum_t w_t A_t)^-T n`, computed as the cofactor matrix `adj(A)^T n` (the
/// determinant only scales and the result is renormalised). Cages: the weighted least-squares
/// affine map `x -> A x + b` taking the rest control points `c_t` to the deformed `c^_t` with
/// weights `w_t^2` is fitted per vertex; with centred points (`d_t = c_t - cbar`,
/// `d^_t = c^_t - c^bar`, weighted centroids) `A^-T ~ adj(sum w_t^2 d_t d^_t^T) (sum w_t^2 d_t d_t^T)`,
/// the paper's formula. It is exact when the influence set has 4 affinely independent points or
/// the cage moves affinely.
///
/// Inputs: `nrm (n, 3)` rest normals; `idx, w (n, k)` packed weights; `poses` (3D);
/// `rest (m, 3)` rest control points (cages only).
/// Output: `(p, n, 3)` unit normals (zero where the local map is degenerate).
pub fn transform_normals(
    nrm: ArrayView2<f64>,
    idx: ArrayView2<usize>,
    w: ArrayView2<f64>,
    poses: &Poses,
    rest: Option<ArrayView2<f64>>,
) -> SkinResult<Array3<f64>> {
    let n = nrm.nrows();
    if nrm.ncols() != 3 {
        return invalid!("N must have shape (n, 3), got {:?}", nrm.dim());
    }
    if nrm.iter().any(|x| !x.is_finite()) {
        return invalid!("N has a NaN or infinite entry");
    }
    let m = poses.handles();
    poses.check(m, 3)?;
    check_packed(idx, w, n, m)?;
    let p = poses.count();
    let cp = match (poses, rest) {
        (Poses::Bones(_), _) => {
            // The cofactor transform of linear blend skinning with normals.
            let index = idx.mapv(|i| i as i64);
            let packed = Weights::Packed {
                index: index.view(),
                weight: w,
            };
            let mut out = Array3::zeros((p, n, 3));
            for (j, mut o) in out.outer_iter_mut().enumerate() {
                let t = pose_transforms(poses, j, 3);
                o.assign(&lbs_with_normals(nrm, &packed, t.view(), nrm)?.1);
            }
            return Ok(out);
        }
        (Poses::ControlPoints(_), None) => {
            return invalid!("normals of a cage deformation need the rest control points C")
        }
        (Poses::ControlPoints(_), Some(c)) if c.dim() != (m, 3) => {
            return invalid!("C must have shape ({m}, 3), got {:?}", c.dim())
        }
        (Poses::ControlPoints(_), Some(c)) if c.iter().any(|x| !x.is_finite()) => {
            return invalid!("C has a NaN or infinite entry")
        }
        (Poses::ControlPoints(cp), Some(c0)) => (cp, c0),
    };
    let (cp, c0) = cp;
    let mut buf = vec![0.0; n * p * 3];
    buf.par_chunks_mut(p * 3).enumerate().for_each(|(vi, out)| {
        let n0 = point(nrm, vi);
        let (ids, ws) = (idx.row(vi), w.row(vi));
        for j in 0..p {
            let (mut sw, mut cb, mut hb) = (0.0, [0.0; 3], [0.0; 3]);
            for (&i, &wt) in ids.iter().zip(ws.iter()) {
                let w2 = wt * wt;
                sw += w2;
                for a in 0..3 {
                    cb[a] += w2 * c0[[i, a]];
                    hb[a] += w2 * cp[[j, i, a]];
                }
            }
            if sw > 0.0 {
                cb.iter_mut().chain(hb.iter_mut()).for_each(|x| *x /= sw);
            }
            let (mut x, mut s) = ([[0.0; 3]; 3], [[0.0; 3]; 3]);
            for (&i, &wt) in ids.iter().zip(ws.iter()) {
                let w2 = wt * wt;
                let dc: [f64; 3] = std::array::from_fn(|a| c0[[i, a]] - cb[a]);
                let dh: [f64; 3] = std::array::from_fn(|a| cp[[j, i, a]] - hb[a]);
                for a in 0..3 {
                    for b in 0..3 {
                        x[a][b] += w2 * dc[a] * dh[b];
                        s[a][b] += w2 * dc[a] * dc[b];
                    }
                }
            }
            let r = matvec3(&adjugate3(&x), &matvec3(&s, &n0));
            let l = r.iter().map(|c| c * c).sum::<f64>().sqrt();
            let inv = if l > 0.0 { 1.0 / l } else { 0.0 };
            for a in 0..3 {
                out[j * 3 + a] = r[a] * inv;
            }
        }
    });
    let a = Array3::from_shape_vec((n, p, 3), buf).expect("buffer has n*p*3 entries");
    Ok(a.permuted_axes([1, 0, 2]).as_standard_layout().into_owned())
}

/// Angle between two vectors, accurate for small angles; 0 when either is zero.
fn angle(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    let c = cross(a, b);
    let s = (c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt();
    s.atan2(a[0] * b[0] + a[1] * b[1] + a[2] * b[2])
}

/// Errors of paper 002 Sec. 6 between a reference and an approximate animation.
pub struct DeformationErrors {
    /// `(p, n)` angle in radians between the area-weighted vertex normals of the two meshes.
    pub normal_angle: Array2<f64>,
    /// `(p,)` RMS over vertices of `normal_angle` (radians).
    pub normal_rms: Vec<f64>,
    /// `(p,)` RMS vertex distance as a percentage of the reference pose's bounding-box diagonal.
    pub position_rms: Vec<f64>,
}

/// Compares a reference animation `full (p, n, 3)` (e.g. all weights) with `approx (p, n, 3)`
/// (e.g. reduced weights) on the triangle mesh `f (t, 3)`.
pub fn deformation_errors(
    f: ArrayView2<usize>,
    full: ArrayView3<f64>,
    approx: ArrayView3<f64>,
) -> SkinResult<DeformationErrors> {
    if full.dim() != approx.dim() {
        return invalid!(
            "the two animations must have the same shape, got {:?} and {:?}",
            full.dim(),
            approx.dim()
        );
    }
    let (p, n, d) = full.dim();
    if d != 3 {
        return invalid!(
            "error metrics need 3D positions (p, n, 3), got {:?}",
            full.dim()
        );
    }
    if full.iter().chain(approx.iter()).any(|x| !x.is_finite()) {
        return invalid!("the animations have a NaN or infinite entry");
    }
    if f.ncols() != 3 {
        return invalid!("F must hold triangles (3 columns), got {}", f.ncols());
    }
    let mut normal_angle = Array2::zeros((p, n));
    let mut normal_rms = Vec::with_capacity(p);
    let mut position_rms = Vec::with_capacity(p);
    for j in 0..p {
        let (a, b) = (full.index_axis(Axis(0), j), approx.index_axis(Axis(0), j));
        let (na, nb) = (per_vertex_normals(a, f)?, per_vertex_normals(b, f)?);
        let mut sq = 0.0;
        for vi in 0..n {
            let t = angle(&point(na.view(), vi), &point(nb.view(), vi));
            normal_angle[[j, vi]] = t;
            sq += t * t;
        }
        normal_rms.push((sq / n.max(1) as f64).sqrt());
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        let mut dist = 0.0;
        for vi in 0..n {
            let (x, y) = (point(a, vi), point(b, vi));
            for c in 0..3 {
                lo[c] = lo[c].min(x[c]);
                hi[c] = hi[c].max(x[c]);
                dist += (x[c] - y[c]).powi(2);
            }
        }
        let diag = (0..3).map(|c| (hi[c] - lo[c]).powi(2)).sum::<f64>().sqrt();
        if diag.is_nan() || diag <= 0.0 {
            return invalid!("reference pose {j} has a zero bounding box");
        }
        position_rms.push(100.0 * (dist / n.max(1) as f64).sqrt() / diag);
    }
    Ok(DeformationErrors {
        normal_angle,
        normal_rms,
        position_rms,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn adjugate_is_det_times_inverse() {
        let m = [[2.0, 1.0, 0.5], [0.1, 3.0, -1.0], [0.3, 0.2, 1.5]];
        let a = adjugate3(&m);
        let d = det3(&m);
        for i in 0..3 {
            for j in 0..3 {
                let s: f64 = (0..3).map(|k| a[i][k] * m[k][j]).sum();
                let want = if i == j { d } else { 0.0 };
                assert!((s - want).abs() < 1e-12);
            }
        }
    }
}
