//! Input checks of [`super::reduce_weights`] and the influence sets (the k-largest reduction).

use ndarray::{Array2, ArrayView2};
use rayon::prelude::*;

use crate::error::SkinResult;
use crate::invalid;

use super::{Method, Poses, ReduceOptions};

/// Tolerance on `|sum_i W_vi - 1|` for the methods that need partition of unity.
const POU_TOL: f64 = 1e-6;

/// Influence sets: the `k` largest weights of every row (ties to the lower index), in decreasing
/// order, and those weights renormalised to sum to one (the k-largest reduction). One pass per
/// row keeping the best `k` in a sorted buffer: most entries are rejected by one comparison
/// with the current k-th largest.
pub(super) fn influence_sets(
    w: ArrayView2<f64>,
    k: usize,
) -> SkinResult<(Array2<usize>, Array2<f64>)> {
    let (n, m) = w.dim();
    let ws = crate::skin::standard2(w);
    let ws = ws.as_slice().expect("standard layout");
    let mut sets = Array2::<usize>::zeros((n, k));
    let mut alpha = Array2::<f64>::zeros((n, k));
    let bad = sets
        .as_slice_mut()
        .expect("fresh array is contiguous")
        .par_chunks_mut(k)
        .zip(
            alpha
                .as_slice_mut()
                .expect("fresh array is contiguous")
                .par_chunks_mut(k),
        )
        .enumerate()
        .find_map_first(|(v, (idx, val))| {
            let row = &ws[v * m..(v + 1) * m];
            if !row.iter().fold(true, |ok, x| ok & x.is_finite()) {
                return Some((v, f64::NAN));
            }
            // Insert `x` (handle `i`) into the sorted best `len` (shifting out the last when full);
            // equal values stay behind the earlier, lower index.
            let insert = |val: &mut [f64], idx: &mut [usize], len: usize, x: f64, i: usize| {
                let mut p = len.min(k - 1);
                while p > 0 && val[p - 1] < x {
                    val[p] = val[p - 1];
                    idx[p] = idx[p - 1];
                    p -= 1;
                }
                val[p] = x;
                idx[p] = i;
            };
            for (i, &x) in row[..k].iter().enumerate() {
                insert(val, idx, i, x, i);
            }
            let mut threshold = val[k - 1];
            for (i, &x) in row.iter().enumerate().skip(k) {
                if x > threshold {
                    insert(val, idx, k, x, i);
                    threshold = val[k - 1];
                }
            }
            let s: f64 = val.iter().sum();
            if s.is_nan() || s <= 0.0 {
                return Some((v, s));
            }
            val.iter_mut().for_each(|x| *x /= s);
            None
        });
    match bad {
        Some((v, s)) if s.is_nan() => invalid!("W has a NaN or infinite entry (row {v})"),
        Some((v, s)) => {
            invalid!("the k largest weights of W row {v} sum to {s}: cannot renormalise")
        }
        None => Ok((sets, alpha)),
    }
}

/// Checks `W (n, m)` and `k`.
pub(super) fn check_weights(w: ArrayView2<f64>, k: usize, method: Method) -> SkinResult<()> {
    let (n, m) = w.dim();
    if n == 0 || m == 0 {
        return invalid!("W must have at least one row and one column, got shape ({n}, {m})");
    }
    if k < 1 || k > m {
        return invalid!("k must be between 1 and the number of handles m = {m}, got {k}");
    }
    if method == Method::KLargest {
        return Ok(()); // `influence_sets` rejects non-finite entries in its single pass
    }
    let ws = crate::skin::standard2(w);
    let ws = ws.as_slice().expect("standard layout");
    let bad = ws.par_chunks(m).enumerate().find_map_first(|(v, r)| {
        let s: f64 = r.iter().sum();
        (!s.is_finite() || (s - 1.0).abs() > POU_TOL).then_some((v, s))
    });
    match bad {
        Some((v, _)) if ws[v * m..(v + 1) * m].iter().any(|x| !x.is_finite()) => {
            invalid!("W has a NaN or infinite entry (row {v})")
        }
        Some((v, s)) => invalid!(
            "W row {v} sums to {s}, not 1 (tolerance {POU_TOL}); {method:?} reduction needs \
             partition-of-unity weights: normalise the rows first"
        ),
        None => Ok(()),
    }
}

/// What the Laplacian methods need of `F (t, 3)` beyond [`crate::operators::check_elements`]:
/// triangles, no repeated vertex in a triangle, every vertex used by some triangle (a vertex
/// off the surface would have an empty Laplacian row and an undetermined weight).
pub(super) fn check_surface(n: usize, f: ArrayView2<usize>) -> SkinResult<()> {
    if f.ncols() != 3 || f.nrows() == 0 {
        return invalid!(
            "F must hold at least one triangle (t, 3), got shape {:?}",
            f.dim()
        );
    }
    let mut used = vec![false; n];
    for (t, tri) in f.rows().into_iter().enumerate() {
        let (i, j, k) = (tri[0], tri[1], tri[2]);
        if i >= n || j >= n || k >= n {
            return invalid!("F row {t} holds an index outside 0..{n}");
        }
        if i == j || j == k || i == k {
            return invalid!("F row {t} repeats a vertex: [{i}, {j}, {k}]");
        }
        used[i] = true;
        used[j] = true;
        used[k] = true;
    }
    if let Some(u) = used.iter().position(|&x| !x) {
        return invalid!(
            "V row {u} is not used by any triangle of F; the Laplacian-based methods need every \
             vertex on the surface (drop unreferenced vertices and reindex F)"
        );
    }
    Ok(())
}

pub(super) fn need<T>(x: Option<T>, what: &str, method: Method) -> SkinResult<T> {
    match x {
        Some(x) => Ok(x),
        None => invalid!("{method:?} reduction needs {what}"),
    }
}

/// Checks `V`, the poses and the options against `W (n, m)` before any work.
pub(super) fn check_inputs(
    (n, m): (usize, usize),
    method: Method,
    v: Option<ArrayView2<f64>>,
    poses: Option<&Poses>,
    opts: &ReduceOptions,
) -> SkinResult<()> {
    if let Some(v) = v {
        if v.nrows() != n {
            return invalid!("V must have one row per row of W ({n}), got {}", v.nrows());
        }
        if !(2..=3).contains(&v.ncols()) {
            return invalid!("V must have 2 or 3 columns, got {}", v.ncols());
        }
        if v.iter().any(|x| !x.is_finite()) {
            return invalid!("V has a NaN or infinite entry");
        }
    }
    if let Some(p) = poses {
        let d = match (p, v) {
            (_, Some(v)) => v.ncols(),
            (Poses::ControlPoints(c), None) => c.shape()[2],
            (Poses::Bones(_), None) => return invalid!("bone_transforms need the rest vertices V"),
        };
        p.check(m, d)?;
    }
    if !(opts.relaxation > 0.0 && opts.relaxation < 2.0) {
        return invalid!("relaxation must lie in (0, 2), got {}", opts.relaxation);
    }
    if opts.tol.is_nan() || opts.tol < 0.0 {
        return invalid!("tol must be >= 0, got {}", opts.tol);
    }
    if opts.rest_control_points.is_some() && method != Method::Smooth {
        return invalid!(
            "the rest control points C (linear precision) are used by the smooth method only"
        );
    }
    Ok(())
}

/// Checks the rest control points `C (m, d)` of linear precision against `V` and `k`.
pub(super) fn check_linear_precision(
    c: ArrayView2<f64>,
    v: Option<ArrayView2<f64>>,
    (m, k): (usize, usize),
    method: Method,
) -> SkinResult<()> {
    let v = need(v, "the rest vertices V for linear precision", method)?;
    let d = v.ncols();
    if c.dim() != (m, d) {
        return invalid!("C must have shape ({m}, {d}), got {:?}", c.dim());
    }
    if c.iter().any(|x| !x.is_finite()) {
        return invalid!("C has a NaN or infinite entry");
    }
    if k < d + 1 {
        return invalid!("linear precision in {d}D needs k >= {}, got k = {k}", d + 1);
    }
    Ok(())
}
