//! Deformation by (packed) weights, per-vertex normals, the approximate normal transform of
//! paper 002 Sec. 5, the error metrics of Sec. 6 and forward kinematics for random poses.
//!
//! The linear blend skinning here is a small private copy so weight reduction does not depend on
//! the `skin` capability written concurrently; it is tested against gpytoolbox.

use ndarray::{Array2, Array3, ArrayView2, ArrayView3, ArrayView4, Axis};
use rayon::prelude::*;

use crate::error::SkinResult;
use crate::invalid;

use super::laplacian::point;

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

/// Deforms the rest vertices with packed weights: `x_v^j = sum_t w_vt q(v, idx_vt, j)`.
///
/// Inputs: `v (n, d)` rest vertices; `idx (n, k)`, `w (n, k)` packed weights (dense weights are
/// the case `idx = [0..m]` per row); `poses` for `m` handles.
/// Output: `(p, n, d)` deformed positions.
pub fn deform_packed(
    v: ArrayView2<f64>,
    idx: ArrayView2<usize>,
    w: ArrayView2<f64>,
    poses: &Poses,
) -> SkinResult<Array3<f64>> {
    let (n, d) = v.dim();
    if !(2..=3).contains(&d) {
        return invalid!("V must have 2 or 3 columns, got {d}");
    }
    if v.iter().any(|x| !x.is_finite()) {
        return invalid!("V has a NaN or infinite entry");
    }
    let m = poses.handles();
    poses.check(m, d)?;
    check_packed(idx, w, n, m)?;
    let p = poses.count();
    let mut buf = vec![0.0; n * p * d];
    buf.par_chunks_mut(p * d).enumerate().for_each(|(vi, out)| {
        let x = point(v, vi);
        let mut q = [0.0; 3];
        for (&i, &wt) in idx.row(vi).iter().zip(w.row(vi).iter()) {
            for j in 0..p {
                poses.handle_point(j, i, &x, d, &mut q);
                for a in 0..d {
                    out[j * d + a] += wt * q[a];
                }
            }
        }
    });
    let a = Array3::from_shape_vec((n, p, d), buf).expect("buffer has n*p*d entries");
    Ok(a.permuted_axes([1, 0, 2]).as_standard_layout().into_owned())
}

fn cross(a: &[f64; 3], b: &[f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn normalize(x: &mut [f64; 3]) {
    let l = (x[0] * x[0] + x[1] * x[1] + x[2] * x[2]).sqrt();
    if l > 0.0 {
        x.iter_mut().for_each(|c| *c /= l);
    }
}

fn check_tris(f: ArrayView2<usize>, n: usize) -> SkinResult<()> {
    if f.ncols() != 3 {
        return invalid!("F must hold triangles (3 columns), got {}", f.ncols());
    }
    if let Some(bad) = f.iter().find(|&&i| i >= n) {
        return invalid!("F holds index {bad}, outside 0..{n}");
    }
    Ok(())
}

/// Area-weighted unit vertex normals of a 3D triangle mesh (sum of the unnormalised face normals
/// around each vertex). A vertex whose normals cancel or that no triangle uses gets `(0, 0, 0)`.
///
/// Inputs: `v (n, 3)`, `f (t, 3)`. Output: `(n, 3)`.
pub fn vertex_normals(v: ArrayView2<f64>, f: ArrayView2<usize>) -> SkinResult<Array2<f64>> {
    if v.ncols() != 3 {
        return invalid!("normals need 3D vertices, V has {} columns", v.ncols());
    }
    check_tris(f, v.nrows())?;
    let mut acc = vec![[0.0f64; 3]; v.nrows()];
    for tri in f.rows() {
        let (a, b, c) = (point(v, tri[0]), point(v, tri[1]), point(v, tri[2]));
        let e1 = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
        let e2 = [c[0] - a[0], c[1] - a[1], c[2] - a[2]];
        let nf = cross(&e1, &e2);
        for &i in tri.iter() {
            for x in 0..3 {
                acc[i][x] += nf[x];
            }
        }
    }
    let mut out = Array2::zeros((v.nrows(), 3));
    for (mut row, mut a) in out.rows_mut().into_iter().zip(acc) {
        normalize(&mut a);
        row.assign(&ndarray::arr1(&a));
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
    if let Poses::ControlPoints(_) = poses {
        match rest {
            None => {
                return invalid!("normals of a cage deformation need the rest control points C")
            }
            Some(c) if c.dim() != (m, 3) => {
                return invalid!("C must have shape ({m}, 3), got {:?}", c.dim())
            }
            Some(c) if c.iter().any(|x| !x.is_finite()) => {
                return invalid!("C has a NaN or infinite entry")
            }
            _ => {}
        }
    }
    let p = poses.count();
    let mut buf = vec![0.0; n * p * 3];
    buf.par_chunks_mut(p * 3).enumerate().for_each(|(vi, out)| {
        let n0 = point(nrm, vi);
        let (ids, ws) = (idx.row(vi), w.row(vi));
        for j in 0..p {
            let mut r = match poses {
                Poses::Bones(t) => {
                    let mut a = [[0.0; 3]; 3];
                    for (&i, &wt) in ids.iter().zip(ws.iter()) {
                        for (r, row) in a.iter_mut().enumerate() {
                            for (c, x) in row.iter_mut().enumerate() {
                                *x += wt * t[[j, i, r, c]];
                            }
                        }
                    }
                    // (adj A)^T n = cofactor(A) n = det(A) A^-T n
                    let adj = adjugate3(&a);
                    std::array::from_fn(|r| {
                        adj[0][r] * n0[0] + adj[1][r] * n0[1] + adj[2][r] * n0[2]
                    })
                }
                Poses::ControlPoints(cp) => {
                    let c0 = rest.expect("checked above");
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
                    matvec3(&adjugate3(&x), &matvec3(&s, &n0))
                }
            };
            normalize(&mut r);
            out[j * 3..j * 3 + 3].copy_from_slice(&r);
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
    check_tris(f, n)?;
    let mut normal_angle = Array2::zeros((p, n));
    let mut normal_rms = Vec::with_capacity(p);
    let mut position_rms = Vec::with_capacity(p);
    for j in 0..p {
        let (a, b) = (full.index_axis(Axis(0), j), approx.index_axis(Axis(0), j));
        let (na, nb) = (vertex_normals(a, f)?, vertex_normals(b, f)?);
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

/// Parent bone of every bone (`None` for roots): the bone whose tail joint is this bone's head.
fn bone_parents(be: ArrayView2<usize>, joints: usize) -> SkinResult<Vec<Option<usize>>> {
    if be.ncols() != 2 {
        return invalid!("BE must have shape (m, 2), got {:?}", be.dim());
    }
    let mut into = vec![None; joints];
    for (b, e) in be.rows().into_iter().enumerate() {
        if e[0] >= joints || e[1] >= joints {
            return invalid!("BE row {b} holds a joint outside 0..{joints}");
        }
        if e[0] == e[1] {
            return invalid!(
                "BE row {b} is a zero-length bone (joint {} to itself)",
                e[0]
            );
        }
        if let Some(other) = into[e[1]] {
            return invalid!(
                "joint {} is the tail of bones {other} and {b}; BE must be a forest",
                e[1]
            );
        }
        into[e[1]] = Some(b);
    }
    Ok(be.rows().into_iter().map(|e| into[e[0]]).collect())
}

/// Forward kinematics: absolute affine transforms from relative bone rotations.
///
/// Bone `b` rotates by `rot_b` about its head joint `C[BE[b, 0]]` and then follows its parent
/// (the bone ending at that joint): `T_b = T_parent o [R_b | c - R_b c]`.
///
/// Inputs: `c (j, 3)` rest joints; `be (m, 2)` bones (head, tail); `rot (m, 3, 3)` rotations.
/// Output: `(m, 3, 4)` transforms `[A | t]`.
pub fn forward_kinematics(
    c: ArrayView2<f64>,
    be: ArrayView2<usize>,
    rot: ArrayView3<f64>,
) -> SkinResult<Array3<f64>> {
    if c.ncols() != 3 {
        return invalid!("C must have shape (j, 3), got {:?}", c.dim());
    }
    let m = be.nrows();
    if rot.dim() != (m, 3, 3) {
        return invalid!("rotations must have shape ({m}, 3, 3), got {:?}", rot.dim());
    }
    if c.iter().chain(rot.iter()).any(|x| !x.is_finite()) {
        return invalid!("C or the rotations have a NaN or infinite entry");
    }
    let parent = bone_parents(be, c.nrows())?;
    let mut out = Array3::<f64>::zeros((m, 3, 4));
    let mut done = vec![false; m];
    for start in 0..m {
        // Walk up to the first finished ancestor, then fill the chain top-down.
        let mut chain = vec![start];
        let mut b = start;
        while let Some(pb) = parent[b] {
            if done[pb] {
                break;
            }
            if chain.len() > m {
                return invalid!("BE has a cycle through bone {start}");
            }
            chain.push(pb);
            b = pb;
        }
        for &b in chain.iter().rev() {
            if done[b] {
                continue;
            }
            let h = point(c, be[[b, 0]]);
            // local = [R | h - R h]
            let mut local = [[0.0; 4]; 3];
            for r in 0..3 {
                let mut rh = 0.0;
                for k in 0..3 {
                    local[r][k] = rot[[b, r, k]];
                    rh += rot[[b, r, k]] * h[k];
                }
                local[r][3] = h[r] - rh;
            }
            let glob = match parent[b] {
                None => local,
                Some(pb) => {
                    let mut g = [[0.0; 4]; 3];
                    for r in 0..3 {
                        for k in 0..4 {
                            let mut s = if k == 3 { out[[pb, r, 3]] } else { 0.0 };
                            for l in 0..3 {
                                s += out[[pb, r, l]] * local[l][k];
                            }
                            g[r][k] = s;
                        }
                    }
                    g
                }
            };
            for r in 0..3 {
                for k in 0..4 {
                    out[[b, r, k]] = glob[r][k];
                }
            }
            done[b] = true;
        }
    }
    Ok(out)
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
