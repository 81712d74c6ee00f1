//! Element geometry shared by the operators: corner points, element measures and the
//! validation every operator runs before touching the mesh.

use ndarray::ArrayView2;
use rayon::prelude::*;

use crate::error::SkinResult;
use crate::invalid;

pub(crate) use crate::geometry::P3;
use crate::geometry::{cross, norm, sub, triple};

/// Corner `i` of `v` as a 3D point (2D points get z = 0).
#[inline]
pub(crate) fn point(v: &ArrayView2<f64>, i: usize) -> P3 {
    let mut p = [0.0; 3];
    for (d, x) in p.iter_mut().enumerate().take(v.ncols()) {
        *x = v[[i, d]];
    }
    p
}

/// What kind of simplices `(v, f)` describes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Simplex {
    /// Triangles in the plane (signed area).
    Triangle2,
    /// Triangles in space (unsigned area).
    Triangle3,
    /// Tetrahedra in space (signed volume).
    Tet,
}

impl Simplex {
    pub(crate) fn of(v: &ArrayView2<f64>, f: &ArrayView2<usize>) -> SkinResult<Simplex> {
        match (f.ncols(), v.ncols()) {
            (3, 2) => Ok(Simplex::Triangle2),
            (3, 3) => Ok(Simplex::Triangle3),
            (4, 3) => Ok(Simplex::Tet),
            (4, d) => invalid!("tetrahedra need 3D vertices, V has {d} columns"),
            (3, d) => invalid!("triangles need 2D or 3D vertices, V has {d} columns"),
            (s, _) => {
                invalid!("elements must have 3 (triangles) or 4 (tetrahedra) columns, got {s}")
            }
        }
    }

    fn name(self) -> &'static str {
        match self {
            Simplex::Tet => "tet",
            _ => "triangle",
        }
    }

    fn measure_name(self) -> &'static str {
        match self {
            Simplex::Tet => "volume",
            _ => "area",
        }
    }

    /// Dimension of the element (2 for triangles, 3 for tets): the power of the length scale
    /// in its measure.
    fn dim(self) -> i32 {
        match self {
            Simplex::Tet => 3,
            _ => 2,
        }
    }
}

/// The vertex indices of element `t` (unused trailing slots are 0).
#[inline]
pub(crate) fn corners(f: &ArrayView2<usize>, t: usize) -> [usize; 4] {
    let mut e = [0; 4];
    for (k, x) in e.iter_mut().enumerate().take(f.ncols()) {
        *x = f[[t, k]];
    }
    e
}

/// Measure of element `e` (indices must be valid).
fn measure(kind: Simplex, v: &ArrayView2<f64>, e: &[usize]) -> f64 {
    let p0 = point(v, e[0]);
    let a = sub(&point(v, e[1]), &p0);
    let b = sub(&point(v, e[2]), &p0);
    match kind {
        Simplex::Triangle2 => 0.5 * cross(&a, &b)[2],
        Simplex::Triangle3 => 0.5 * norm(&cross(&a, &b)),
        Simplex::Tet => triple(&a, &b, &sub(&point(v, e[3]), &p0)) / 6.0,
    }
}

/// Measure of every element.
///
/// Inputs:
///   v  #V by dim vertex positions (dim 2 or 3)
///   f  #F by 3 triangles or #F by 4 tetrahedra (rows index `v`)
/// Output:
///   #F measures: signed areas for triangles in 2D (positive when counter-clockwise), unsigned
///   areas for triangles in 3D, signed volumes for tets (positive when
///   det[b-a, c-a, d-a] > 0). Elements with an index outside `0..#V`, and every element when
///   the shapes of `v` and `f` do not match, get NaN; [`check_elements`] reports those cases.
pub fn element_measures(v: ArrayView2<f64>, f: ArrayView2<usize>) -> Vec<f64> {
    let Ok(kind) = Simplex::of(&v, &f) else {
        return vec![f64::NAN; f.nrows()];
    };
    let n = v.nrows();
    (0..f.nrows())
        .into_par_iter()
        .with_min_len(1024)
        .map(|t| {
            let e = corners(&f, t);
            if e[..f.ncols()].iter().any(|&i| i >= n) {
                f64::NAN
            } else {
                measure(kind, &v, &e)
            }
        })
        .collect()
}

/// Length of the diagonal of the bounding box of `v`.
fn bbox_diagonal(v: &ArrayView2<f64>) -> f64 {
    let mut d2 = 0.0;
    for col in v.columns() {
        let (lo, hi) = col
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &x| {
                (lo.min(x), hi.max(x))
            });
        if hi >= lo {
            d2 += (hi - lo) * (hi - lo);
        }
    }
    d2.sqrt()
}

/// Checks that `(v, f)` is a mesh the operators can use.
///
/// Inputs:
///   v  #V by dim vertex positions
///   f  #F by 3 triangles (dim 2 or 3) or #F by 4 tetrahedra (dim 3)
/// Errors (`InvalidInput`, naming the first offending row/element):
///   - shapes that do not match, indices outside `0..#V`, NaN or infinite coordinates;
///   - a degenerate element: |measure| <= 1e-14 * (bounding-box diagonal)^k with k = 2 for
///     triangles, 3 for tets;
///   - an inverted tet (negative volume).
///
/// Triangles in 2D may have either orientation: the cotangent Laplacian and the mass matrices
/// do not depend on it.
pub fn check_elements(v: ArrayView2<f64>, f: ArrayView2<usize>) -> SkinResult<()> {
    let kind = Simplex::of(&v, &f)?;
    let n = v.nrows();
    if let Some((t, i)) = f
        .rows()
        .into_iter()
        .enumerate()
        .find_map(|(t, r)| r.iter().copied().find(|&i| i >= n).map(|i| (t, i)))
    {
        return invalid!("{} {t} holds vertex index {i}, outside 0..{n}", kind.name());
    }
    if let Some(r) = v
        .rows()
        .into_iter()
        .position(|r| r.iter().any(|x| !x.is_finite()))
    {
        return invalid!("V row {r} has a NaN or infinite coordinate");
    }
    crate::limits::check_coordinates("V", &v)?;
    let diag = bbox_diagonal(&v);
    crate::limits::check_extent("V", diag)?;
    let tol = 1e-14 * diag.powi(kind.dim());
    let measures = element_measures(v, f);
    let bad = measures
        .par_iter()
        .position_first(|&x| x.is_nan() || x.abs() <= tol || (kind == Simplex::Tet && x < 0.0));
    if let Some(t) = bad {
        let x = measures[t];
        let verts: Vec<usize> = f.row(t).to_vec();
        if kind == Simplex::Tet && x < -tol {
            return invalid!(
                "tet {t} (vertices {verts:?}) is inverted (volume {x:e}); reorient it by \
                 swapping two of its vertices"
            );
        }
        return invalid!(
            "{} {t} (vertices {verts:?}) is degenerate: {} {x:e} is below 1e-14 * \
             bbox-diagonal^{} = {tol:e}",
            kind.name(),
            kind.measure_name(),
            kind.dim()
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::array;

    #[test]
    fn measures_of_simple_elements() {
        let v = array![[0.0, 0.0], [2.0, 0.0], [0.0, 1.0]];
        let f = array![[0usize, 1, 2], [0, 2, 1]];
        assert_eq!(element_measures(v.view(), f.view()), vec![1.0, -1.0]);
        let v3 = array![
            [0.0, 0.0, 0.0],
            [2.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 3.0]
        ];
        let t = array![[0usize, 1, 2, 3], [1, 0, 2, 3]];
        assert_eq!(element_measures(v3.view(), t.view()), vec![1.0, -1.0]);
        let tri = array![[0usize, 1, 3]];
        assert_eq!(element_measures(v3.view(), tri.view()), vec![3.0]);
    }

    #[test]
    fn check_reports_bad_elements() {
        let v = array![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 1.0]
        ];
        assert!(check_elements(v.view(), array![[0usize, 1, 2, 3]].view()).is_ok());
        let e = check_elements(v.view(), array![[0usize, 1, 2, 3], [1, 0, 2, 3]].view());
        assert!(format!("{:?}", e).contains("tet 1"), "{e:?}");
        assert!(format!("{:?}", e).contains("inverted"), "{e:?}");
        let flat = array![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [2.0, 0.0, 0.0],
            [0.0, 0.0, 1.0]
        ];
        let e = check_elements(flat.view(), array![[0usize, 1, 3], [0, 1, 2]].view());
        assert!(format!("{:?}", e).contains("triangle 1"), "{e:?}");
        let e = check_elements(v.view(), array![[0usize, 1, 7]].view());
        assert!(format!("{:?}", e).contains("index 7"), "{e:?}");
        let mut nan = v.clone();
        nan[[2, 1]] = f64::NAN;
        let e = check_elements(nan.view(), array![[0usize, 1, 3]].view());
        assert!(format!("{:?}", e).contains("row 2"), "{e:?}");
        // clockwise 2D triangles are fine
        let v2 = array![[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]];
        assert!(check_elements(v2.view(), array![[0usize, 2, 1]].view()).is_ok());
    }
}
