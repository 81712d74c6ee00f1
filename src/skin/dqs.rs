//! Dual-quaternion skinning (Kavan, Collins, Zara, O'Sullivan 2008, "Geometric skinning with
//! approximate dual quaternion blending", Algorithm 1): blend unit dual quaternions
//! `q0 + eps qe` linearly (with hemisphere alignment), normalise by `|b0|`, apply as a rigid
//! motion. Unlike LBS, the blend of rotations stays a rotation, so twisted joints keep volume.

use ndarray::{Array2, ArrayView2, ArrayView3, ArrayViewMut2};

use super::blend::{
    blend, first_nonfinite, par_chunks, to_skin_error, ChunkError, Held, Influences, Lanes,
};
use super::quat::{from_matrix, Quat};
use super::{
    check_normals, explain_nonfinite, outputs, slice_of, standard2, transform_blocks, Weights,
};
use crate::error::SkinResult;
use crate::geometry::cross;
use crate::invalid;

/// Largest accepted deviation `max |R^T R - I|` of a transform's linear part from a rotation.
pub const RIGID_TOL: f64 = 1e-6;

/// Dual-quaternion skinning of 3D points.
///
/// Inputs:
/// * `v`  `(n, 3)` rest positions
/// * `w`  weights over `m` handles, dense `(n, m)` or packed (see [`Weights`])
/// * `t`  `(m, 3, 4)` rigid transforms `[R | t]` (`R` a rotation within [`RIGID_TOL`])
///
/// Output: `(n, 3)` deformed positions. Errors when a transform is not rigid or a vertex's
/// blended rotation vanishes (weights summing to zero).
pub fn dqs(
    v: ArrayView2<'_, f64>,
    w: &Weights<'_>,
    t: ArrayView3<'_, f64>,
) -> SkinResult<Array2<f64>> {
    let mut u = Array2::zeros(v.dim());
    dqs_into(v, w, t, None, u.view_mut(), None)?;
    Ok(u)
}

/// Dual-quaternion skinning of points and normals: as [`dqs`], plus `normals (n, 3)` rotated by
/// each vertex's blended rotation. Outputs `(u, n)`.
pub fn dqs_with_normals(
    v: ArrayView2<'_, f64>,
    w: &Weights<'_>,
    t: ArrayView3<'_, f64>,
    normals: ArrayView2<'_, f64>,
) -> SkinResult<(Array2<f64>, Array2<f64>)> {
    let mut u = Array2::zeros(v.dim());
    let mut nu = Array2::zeros(v.dim());
    dqs_into(v, w, t, Some(normals), u.view_mut(), Some(nu.view_mut()))?;
    Ok((u, nu))
}

/// Dual-quaternion skinning into preallocated C-contiguous outputs `out (n, 3)` (and
/// `nout (n, 3)` when `normals` is given).
pub fn dqs_into(
    v: ArrayView2<'_, f64>,
    w: &Weights<'_>,
    t: ArrayView3<'_, f64>,
    normals: Option<ArrayView2<'_, f64>>,
    mut out: ArrayViewMut2<'_, f64>,
    nout: Option<ArrayViewMut2<'_, f64>>,
) -> SkinResult<()> {
    if v.ncols() != 3 {
        return invalid!("dqs needs V of shape (n, 3), got {:?}", v.dim());
    }
    let table = dual_quaternions(t)?;
    let (n, m) = (v.nrows(), table.len());
    w.check(n, m)?;
    check_normals(normals.as_ref(), n, 3)?;
    let vs = standard2(v);
    let vsl = slice_of(&vs)?;
    let ns = normals.map(standard2);
    let nsl = match &ns {
        Some(a) => Some(slice_of(a)?),
        None => None,
    };
    let (o, no) = outputs(n, 3, &mut out, nout, nsl.is_some())?;
    let held = Held::new(w);
    let inf = held.influences()?;
    let avx = crate::cpu::has_avx2();
    let kernel = |first: usize, o: &mut [f64], no: Option<&mut [f64]>| {
        let rows = o.len() / 3;
        let vc = &vsl[first * 3..(first + rows) * 3];
        let nc = nsl.map(|s| &s[first * 3..(first + rows) * 3]);
        chunk(avx, &inf, &table, first, vc, o, nc.zip(no))
    };
    par_chunks(3, o, no, kernel)
        .map_err(|e| to_skin_error(e, m, |i| explain_nonfinite(i, v, w, normals)))
}

/// Unit dual quaternion `[q0; qe]` of each rigid transform, `qe = 1/2 (0, t) q0`.
pub(crate) fn dual_quaternions(t: ArrayView3<'_, f64>) -> SkinResult<Vec<Lanes<2>>> {
    if t.ndim() == 3 && t.shape()[1..] == [2, 3] {
        return invalid!("dqs needs 3D transforms (m, 3, 4); embed 2D data in 3D (z = 0)");
    }
    let blocks = transform_blocks::<3>(t)?;
    let mut out = Vec::with_capacity(blocks.len());
    for (j, b) in blocks.iter().enumerate() {
        let r = [
            [b[0][0], b[0][1], b[0][2]],
            [b[1][0], b[1][1], b[1][2]],
            [b[2][0], b[2][1], b[2][2]],
        ];
        let dev = rigidity_error(&r);
        if dev > RIGID_TOL {
            return invalid!(
                "T[{j}] is not a rigid motion (max |R^T R - I| = {dev:.3e}, det R = {:.6}): dqs \
                 needs rotations; use lbs for scaling or shear",
                det3(&r)
            );
        }
        let q0 = from_matrix(&r);
        let tv = [b[0][3], b[1][3], b[2][3]];
        // qe = 1/2 (0, t) q0
        let qe: Quat = super::quat::mul(&[0.0, tv[0], tv[1], tv[2]], &q0);
        out.push([q0, [0.5 * qe[0], 0.5 * qe[1], 0.5 * qe[2], 0.5 * qe[3]]]);
    }
    Ok(out)
}

fn det3(r: &[[f64; 3]; 3]) -> f64 {
    let c = cross(&r[1], &r[2]);
    r[0][0] * c[0] + r[0][1] * c[1] + r[0][2] * c[2]
}

/// `max |R^T R - I|`, or infinity for a reflection.
fn rigidity_error(r: &[[f64; 3]; 3]) -> f64 {
    if det3(r) <= 0.0 {
        return f64::INFINITY;
    }
    let mut dev: f64 = 0.0;
    for a in 0..3 {
        for b in 0..3 {
            let g: f64 = (0..3).map(|k| r[k][a] * r[k][b]).sum();
            let id = if a == b { 1.0 } else { 0.0 };
            dev = dev.max((g - id).abs());
        }
    }
    dev
}

fn chunk(
    avx: bool,
    inf: &Influences<'_>,
    table: &[Lanes<2>],
    first: usize,
    v: &[f64],
    out: &mut [f64],
    normals: Option<(&[f64], &mut [f64])>,
) -> Result<(), ChunkError> {
    #[cfg(target_arch = "x86_64")]
    {
        if avx {
            // SAFETY: `avx` comes from runtime detection of AVX2 and FMA.
            return unsafe { chunk_avx2(inf, table, first, v, out, normals) };
        }
    }
    let _ = avx;
    kernel::<false>(inf, table, first, v, out, normals)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn chunk_avx2(
    inf: &Influences<'_>,
    table: &[Lanes<2>],
    first: usize,
    v: &[f64],
    out: &mut [f64],
    normals: Option<(&[f64], &mut [f64])>,
) -> Result<(), ChunkError> {
    kernel::<true>(inf, table, first, v, out, normals)
}

/// Index of the largest entry (the first one on ties).
#[inline(always)]
fn argmax(row: &[f64]) -> usize {
    let mut best = 0;
    for (j, &x) in row.iter().enumerate() {
        if x > row[best] {
            best = j;
        }
    }
    best
}

#[inline(always)]
fn kernel<const AVX: bool>(
    inf: &Influences<'_>,
    table: &[Lanes<2>],
    first: usize,
    v: &[f64],
    out: &mut [f64],
    mut normals: Option<(&[f64], &mut [f64])>,
) -> Result<(), ChunkError> {
    let m = table.len();
    let mut signed = vec![0.0; inf.width()];
    for ((r, x), o) in v.chunks_exact(3).enumerate().zip(out.chunks_exact_mut(3)) {
        let i = first + r;
        let (w, index) = inf.row(i, m)?;
        // Hemisphere alignment (Kavan et al. 2008, Sec. 4): q and -q are the same rotation, so
        // take every influence on the side of the largest-weight one (the pivot) before blending.
        let handle = |l: usize| index.map_or(l, |ix| ix[l] as usize);
        let pivot = table[handle(argmax(w))][0];
        for (l, (s, &wl)) in signed.iter_mut().zip(w).enumerate() {
            let q = &table[handle(l)][0];
            let dot = q[0] * pivot[0] + q[1] * pivot[1] + q[2] * pivot[2] + q[3] * pivot[3];
            *s = if dot < 0.0 { -wl } else { wl };
        }
        let [b0, be] = blend::<2, AVX>(&signed, index, table);
        let len = (b0[0] * b0[0] + b0[1] * b0[1] + b0[2] * b0[2] + b0[3] * b0[3]).sqrt();
        if len == 0.0 {
            return Err(ChunkError::Vanished(i));
        }
        let inv = 1.0 / len;
        let (a0, d0) = (b0[0] * inv, [b0[1] * inv, b0[2] * inv, b0[3] * inv]);
        let (ae, de) = (be[0] * inv, [be[1] * inv, be[2] * inv, be[3] * inv]);
        let (d0, de) = ([d0[0], d0[1], d0[2]], [de[0], de[1], de[2]]);
        let x = [x[0], x[1], x[2]];
        // Kavan et al. 2008, Algorithm 1:
        // u = x + 2 d0 x (d0 x x + a0 x) + 2 (a0 de - ae d0 + d0 x de)
        let c = cross(&d0, &x);
        let rot = cross(&d0, &[c[0] + a0 * x[0], c[1] + a0 * x[1], c[2] + a0 * x[2]]);
        let dd = cross(&d0, &de);
        for p in 0..3 {
            o[p] = x[p] + 2.0 * rot[p] + 2.0 * (a0 * de[p] - ae * d0[p] + dd[p]);
        }
        if let Some((nin, nout)) = normals.as_mut() {
            let nr = [nin[r * 3], nin[r * 3 + 1], nin[r * 3 + 2]];
            let c = cross(&d0, &nr);
            let rot = cross(
                &d0,
                &[c[0] + a0 * nr[0], c[1] + a0 * nr[1], c[2] + a0 * nr[2]],
            );
            for p in 0..3 {
                nout[r * 3 + p] = nr[p] + 2.0 * rot[p];
            }
        }
    }
    first_nonfinite(first, 3, out)?;
    if let Some((_, nout)) = normals {
        first_nonfinite(first, 3, nout)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::{array, Array3};

    fn rot_z(theta: f64, about: [f64; 3]) -> [[f64; 4]; 3] {
        let (s, c) = theta.sin_cos();
        let r = [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]];
        let mut t = [[0.0; 4]; 3];
        for a in 0..3 {
            for b in 0..3 {
                t[a][b] = r[a][b];
            }
            t[a][3] = about[a] - (0..3).map(|k| r[a][k] * about[k]).sum::<f64>();
        }
        t
    }

    #[test]
    fn single_influence_is_the_rigid_motion() {
        let v = array![[1.0, 2.0, 3.0], [-0.5, 0.2, 0.0]];
        let mut t = Array3::<f64>::zeros((2, 3, 4));
        for (j, th) in [0.4, 3.0].iter().enumerate() {
            let m = rot_z(*th, [0.3, -0.2, 1.0]);
            for a in 0..3 {
                for b in 0..4 {
                    t[[j, a, b]] = m[a][b];
                }
            }
        }
        let w = array![[0.0, 1.0], [1.0, 0.0]];
        let u = dqs(v.view(), &Weights::Dense(w.view()), t.view()).unwrap();
        for i in 0..2 {
            let j = if i == 0 { 1 } else { 0 };
            for p in 0..3 {
                let e = t[[j, p, 3]] + (0..3).map(|q| t[[j, p, q]] * v[[i, q]]).sum::<f64>();
                assert!((u[[i, p]] - e).abs() < 1e-13, "{} vs {}", u[[i, p]], e);
            }
        }
    }

    #[test]
    fn scaling_is_rejected() {
        let v = array![[1.0, 2.0, 3.0]];
        let mut t = Array3::<f64>::zeros((1, 3, 4));
        for a in 0..3 {
            t[[0, a, a]] = 2.0;
        }
        let w = array![[1.0]];
        assert!(dqs(v.view(), &Weights::Dense(w.view()), t.view()).is_err());
    }
}
