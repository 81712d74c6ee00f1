//! Linear blend skinning: `u_i = (sum_j w_ij T_j) [v_i; 1]` (paper 000, eq. (1)).
//!
//! The kernel blends the `d x (d+1)` matrices first (one multiply-add of `d (d+1)` lanes per
//! influence) and applies the blended matrix once per vertex; vertices are processed in
//! parallel chunks with no allocation per vertex, and the output's finiteness is checked per
//! chunk while it is still in cache (so the inputs need no separate NaN pass).

use ndarray::{Array2, ArrayView2, ArrayView3, ArrayViewMut2};

use super::blend::{
    blend, first_nonfinite, par_chunks, to_skin_error, ChunkError, Held, Influences, Lanes,
};
use super::{
    check_normals, explain_nonfinite, outputs, slice_of, standard2, transform_blocks, Weights,
};
use crate::error::SkinResult;
use crate::invalid;

/// Linear blend skinning of points.
///
/// Inputs:
/// * `v`  `(n, d)` rest positions, `d` = 2 or 3
/// * `w`  weights over `m` handles, dense `(n, m)` or packed (see [`Weights`])
/// * `t`  `(m, d, d+1)` affine transforms `[R | t]`, mapping `x -> R x + t`
///
/// Output: `(n, d)` deformed positions `u_i = sum_j w_ij (R_j v_i + t_j)`.
pub fn lbs(
    v: ArrayView2<'_, f64>,
    w: &Weights<'_>,
    t: ArrayView3<'_, f64>,
) -> SkinResult<Array2<f64>> {
    let mut u = Array2::zeros(v.dim());
    lbs_into(v, w, t, None, u.view_mut(), None)?;
    Ok(u)
}

/// Linear blend skinning of points and their normals.
///
/// Inputs as [`lbs`], plus `normals (n, d)` rest normals.
/// Outputs: `(u, n)`: deformed positions and unit deformed normals. A normal transforms by the
/// cofactor matrix `cof(A) = det(A) A^{-T}` of the blended linear part `A` (this is exactly how
/// a face normal `e1 x e2` of a small triangle transforms, `(A e1) x (A e2) = cof(A) (e1 x e2)`),
/// then is normalised; where `cof(A) n` vanishes (a degenerate blend) the normal is zero.
pub fn lbs_with_normals(
    v: ArrayView2<'_, f64>,
    w: &Weights<'_>,
    t: ArrayView3<'_, f64>,
    normals: ArrayView2<'_, f64>,
) -> SkinResult<(Array2<f64>, Array2<f64>)> {
    let mut u = Array2::zeros(v.dim());
    let mut nu = Array2::zeros(v.dim());
    lbs_into(v, w, t, Some(normals), u.view_mut(), Some(nu.view_mut()))?;
    Ok((u, nu))
}

/// Linear blend skinning into preallocated outputs (no allocation: for posing many frames).
///
/// Inputs as [`lbs`] / [`lbs_with_normals`]; `out (n, d)` (and `nout (n, d)` when `normals` is
/// given) must be in standard (C-contiguous) layout. On error the outputs hold partial results.
pub fn lbs_into(
    v: ArrayView2<'_, f64>,
    w: &Weights<'_>,
    t: ArrayView3<'_, f64>,
    normals: Option<ArrayView2<'_, f64>>,
    out: ArrayViewMut2<'_, f64>,
    nout: Option<ArrayViewMut2<'_, f64>>,
) -> SkinResult<()> {
    match v.ncols() {
        2 => run::<2>(v, w, t, normals, out, nout),
        3 => run::<3>(v, w, t, normals, out, nout),
        d => invalid!("V must have 2 or 3 columns, got {d}"),
    }
}

fn run<const D: usize>(
    v: ArrayView2<'_, f64>,
    w: &Weights<'_>,
    t: ArrayView3<'_, f64>,
    normals: Option<ArrayView2<'_, f64>>,
    mut out: ArrayViewMut2<'_, f64>,
    nout: Option<ArrayViewMut2<'_, f64>>,
) -> SkinResult<()> {
    let table = transform_blocks::<D>(t)?;
    let (n, m) = (v.nrows(), table.len());
    w.check(n, m)?;
    check_normals(normals.as_ref(), n, D)?;
    let vs = standard2(v);
    let vsl = slice_of(&vs)?;
    let ns = normals.map(standard2);
    let nsl = match &ns {
        Some(a) => Some(slice_of(a)?),
        None => None,
    };
    let (o, no) = outputs(n, D, &mut out, nout, nsl.is_some())?;
    let held = Held::new(w);
    let inf = held.influences()?;

    let avx = crate::cpu::has_avx2();
    let kernel = |first: usize, o: &mut [f64], no: Option<&mut [f64]>| {
        let rows = o.len() / D;
        let vc = &vsl[first * D..(first + rows) * D];
        let nc = nsl.map(|s| &s[first * D..(first + rows) * D]);
        chunk::<D>(avx, &inf, &table, first, vc, o, nc.zip(no))
    };
    par_chunks(D, o, no, kernel)
        .map_err(|e| to_skin_error(e, m, |i| explain_nonfinite(i, v, w, normals)))
}

/// How many vertices ahead the kernel prefetches weights.
const PREFETCH_AHEAD: usize = 16;

/// One chunk, through the AVX2/FMA kernel when the CPU has it.
fn chunk<const D: usize>(
    avx: bool,
    inf: &Influences<'_>,
    table: &[Lanes<D>],
    first: usize,
    v: &[f64],
    out: &mut [f64],
    normals: Option<(&[f64], &mut [f64])>,
) -> Result<(), ChunkError> {
    #[cfg(target_arch = "x86_64")]
    {
        if avx {
            // SAFETY: `avx` comes from runtime detection of AVX2 and FMA.
            return unsafe { chunk_avx2::<D>(inf, table, first, v, out, normals) };
        }
    }
    let _ = avx;
    kernel::<D, false>(inf, table, first, v, out, normals)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn chunk_avx2<const D: usize>(
    inf: &Influences<'_>,
    table: &[Lanes<D>],
    first: usize,
    v: &[f64],
    out: &mut [f64],
    normals: Option<(&[f64], &mut [f64])>,
) -> Result<(), ChunkError> {
    kernel::<D, true>(inf, table, first, v, out, normals)
}

/// Rows `first..first + out.len() / D` on the AVX2/FMA path (no normals), into `out`; the
/// caller checks finiteness.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn avx_rows<const D: usize>(
    inf: &Influences<'_>,
    table: &[Lanes<D>],
    first: usize,
    v: &[f64],
    out: &mut [f64],
) -> Result<(), ChunkError> {
    let m = table.len();
    let done = match *inf {
        Influences::Dense { w, m } => {
            // blocks of B vertices share the loads of each handle's rows (see
            // `lbs_dense_block` for why B = 3 in 3D, 4 in 2D)
            dense_blocks::<D>(w, m, inf, table, first, v, out)
        }
        Influences::Packed { idx, w, k } => {
            let rows = out.len() / D;
            let (ic, wc) = (&idx[first * k..(first + rows) * k], &w[first * k..]);
            use super::blend::avx::lbs_packed_rows as rows_k;
            // SAFETY: only called on the AVX2/FMA path, after runtime detection.
            let bad = unsafe {
                match k {
                    1 => rows_k::<D, 1>(ic, wc, k, table, v, out),
                    2 => rows_k::<D, 2>(ic, wc, k, table, v, out),
                    3 => rows_k::<D, 3>(ic, wc, k, table, v, out),
                    4 => rows_k::<D, 4>(ic, wc, k, table, v, out),
                    6 => rows_k::<D, 6>(ic, wc, k, table, v, out),
                    8 => rows_k::<D, 8>(ic, wc, k, table, v, out),
                    _ => rows_k::<D, 0>(ic, wc, k, table, v, out),
                }
            };
            if let Some((r, s)) = bad {
                return Err(ChunkError::BadIndex(first + r, s, ic[r * k + s]));
            }
            rows
        }
    };
    // the rows the dense blocks left (fewer than one block)
    for ((r, x), o) in v
        .chunks_exact(D)
        .enumerate()
        .zip(out.chunks_exact_mut(D))
        .skip(done)
    {
        let (w, index) = inf.row(first + r, m)?;
        // SAFETY: only called on the AVX2/FMA path, after runtime detection.
        unsafe { super::blend::avx::lbs_point::<D>(w, index, table, x, o) };
    }
    Ok(())
}

/// The dense AVX2 blocks of a chunk; returns how many rows it did (the rest go one by one).
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn dense_blocks<const D: usize>(
    w: &[f64],
    m: usize,
    inf: &Influences<'_>,
    table: &[Lanes<D>],
    first: usize,
    v: &[f64],
    out: &mut [f64],
) -> usize {
    // B * D accumulators + D handle rows + B broadcasts must fit in 16 registers
    let b = if D == 3 { 3 } else { 4 };
    let rows = out.len() / D;
    let mut r = 0;
    while r + b <= rows {
        inf.prefetch(first + r + PREFETCH_AHEAD, b);
        let i = first + r;
        let (x, o) = (&v[r * D..(r + b) * D], &mut out[r * D..(r + b) * D]);
        let wb = &w[i * m..(i + b) * m];
        // SAFETY: only called on the AVX2/FMA path, after runtime detection.
        unsafe {
            if D == 3 {
                super::blend::avx::lbs_dense_block::<D, 3>(wb, table, x, o)
            } else {
                super::blend::avx::lbs_dense_block::<D, 4>(wb, table, x, o)
            }
        };
        r += b;
    }
    r
}

#[inline(always)]
fn kernel<const D: usize, const AVX: bool>(
    inf: &Influences<'_>,
    table: &[Lanes<D>],
    first: usize,
    v: &[f64],
    out: &mut [f64],
    mut normals: Option<(&[f64], &mut [f64])>,
) -> Result<(), ChunkError> {
    let m = table.len();
    #[cfg(target_arch = "x86_64")]
    {
        if AVX && normals.is_none() {
            avx_rows::<D>(inf, table, first, v, out)?;
            return first_nonfinite(first, D, out);
        }
    }
    for ((r, x), o) in v.chunks_exact(D).enumerate().zip(out.chunks_exact_mut(D)) {
        let (w, index) = inf.row(first + r, m)?;
        let a = blend::<D, AVX>(w, index, table);
        // u_p = t_p + sum_q R_pq x_q  (row p of the blended [R | t] is group p)
        for p in 0..D {
            let mut s = a[p][D];
            for q in 0..D {
                s += a[p][q] * x[q];
            }
            o[p] = s;
        }
        if let Some((nin, nout)) = normals.as_mut() {
            let nr = &nin[r * D..(r + 1) * D];
            let no = &mut nout[r * D..(r + 1) * D];
            cofactor_normal::<D>(&a, nr, no);
        }
    }
    first_nonfinite(first, D, out)?;
    if let Some((_, nout)) = normals {
        first_nonfinite(first, D, nout)?;
    }
    Ok(())
}

/// `out = cof(A) n / |cof(A) n|` for the linear part `A` of the blended `D x (D+1)` block `a`.
#[inline(always)]
fn cofactor_normal<const D: usize>(a: &Lanes<D>, n: &[f64], out: &mut [f64]) {
    let e = |p: usize, q: usize| a[p][q];
    let mut c = [0.0; 3];
    if D == 2 {
        // cof([[a, b], [c, d]]) = [[d, -c], [-b, a]]
        c[0] = e(1, 1) * n[0] - e(1, 0) * n[1];
        c[1] = -e(0, 1) * n[0] + e(0, 0) * n[1];
    } else {
        // Rows of the cofactor matrix are cross products of the other two rows of A.
        let r = |p: usize| [e(p, 0), e(p, 1), e(p, 2)];
        let (r0, r1, r2) = (r(0), r(1), r(2));
        let rows = [
            crate::geometry::cross(&r1, &r2),
            crate::geometry::cross(&r2, &r0),
            crate::geometry::cross(&r0, &r1),
        ];
        for p in 0..3 {
            c[p] = rows[p][0] * n[0] + rows[p][1] * n[1] + rows[p][2] * n[2];
        }
    }
    let len2: f64 = c[..D].iter().map(|x| x * x).sum();
    let inv = if len2 > 0.0 { 1.0 / len2.sqrt() } else { 0.0 };
    for p in 0..D {
        out[p] = c[p] * inv;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::{array, Array3};

    #[test]
    fn dense_and_packed_agree_with_direct_sum() {
        let v = array![[0.0, 0.0, 0.0], [1.0, 2.0, 3.0], [-1.0, 0.5, 2.0]];
        let mut t = Array3::<f64>::zeros((3, 3, 4));
        for j in 0..3 {
            for a in 0..3 {
                for b in 0..4 {
                    t[[j, a, b]] = ((j * 12 + a * 4 + b) as f64 * 0.37).sin();
                }
            }
        }
        let w = array![[0.2, 0.3, 0.5], [1.0, 0.0, 0.0], [0.0, 0.6, 0.4]];
        let u = lbs(v.view(), &Weights::Dense(w.view()), t.view()).unwrap();
        let idx = array![[0i64, 1, 2], [0, 1, 2], [2, 1, 0]];
        let pw = array![[0.2, 0.3, 0.5], [1.0, 0.0, 0.0], [0.4, 0.6, 0.0]];
        let up = lbs(
            v.view(),
            &Weights::Packed {
                index: idx.view(),
                weight: pw.view(),
            },
            t.view(),
        )
        .unwrap();
        for i in 0..3 {
            for p in 0..3 {
                let mut s = 0.0;
                for j in 0..3 {
                    let mut y = t[[j, p, 3]];
                    for q in 0..3 {
                        y += t[[j, p, q]] * v[[i, q]];
                    }
                    s += w[[i, j]] * y;
                }
                assert!((u[[i, p]] - s).abs() < 1e-14);
                assert!((up[[i, p]] - s).abs() < 1e-14);
            }
        }
    }

    #[test]
    fn bad_index_and_nan_are_errors() {
        let v = array![[0.0, 0.0], [1.0, 2.0]];
        let t = Array3::<f64>::zeros((2, 2, 3));
        let idx = array![[0i64], [2]];
        let pw = array![[1.0], [1.0]];
        let e = lbs(
            v.view(),
            &Weights::Packed {
                index: idx.view(),
                weight: pw.view(),
            },
            t.view(),
        );
        assert!(matches!(e, Err(crate::SkinError::InvalidInput(_))));
        let w = array![[1.0, f64::NAN], [1.0, 0.0]];
        let e = lbs(v.view(), &Weights::Dense(w.view()), t.view()).unwrap_err();
        assert!(e.to_string().contains("W has a NaN"), "{e}");
    }
}
