//! The exact angles of single elements (van Oosterom & Strackee 1983 in 3D, `atan2` in 2D),
//! the per-element geometry the far-field expansion is built from (corners, area vector), and
//! [`winding_number_2d`], the exact 2D sum over all segments without a tree (reference and
//! small inputs).

use ndarray::ArrayView2;
use rayon::prelude::*;

use super::TWO_PI;
use crate::error::SkinResult;
use crate::field::boundary::{check_queries, Boundary};
use crate::field::{cross, cross2, dot, norm2, row, sub, P2, P3};

/// Signed solid angle of triangle `abc` seen from `q` (van Oosterom & Strackee 1983); positive
/// when `q` is behind the triangle (on the side opposite its normal `(b - a) x (c - a)`).
#[inline]
pub fn solid_angle(q: &P3, a: &P3, b: &P3, c: &P3) -> f64 {
    let a = sub(a, q);
    let b = sub(b, q);
    let c = sub(c, q);
    let (la, lb, lc) = (norm2(&a).sqrt(), norm2(&b).sqrt(), norm2(&c).sqrt());
    let det = dot(&a, &cross(&b, &c));
    let den = la * lb * lc + dot(&a, &b) * lc + dot(&b, &c) * la + dot(&c, &a) * lb;
    2.0 * det.atan2(den)
}

/// Signed angle of segment `ab` seen from `q`; positive when `q` is on the side opposite its
/// normal (`b - a` turned clockwise), i.e. inside a counter-clockwise polygon.
#[inline]
pub fn segment_angle(q: &P2, a: &P2, b: &P2) -> f64 {
    let u = sub(a, q);
    let w = sub(b, q);
    cross2(&u, &w).atan2(dot(&u, &w))
}

/// Copies the first `min(D, 3)` coordinates into a 3-vector (zero padded); lets the generic
/// code call the 3D formulas without out-of-range indexing when `D = 2`.
#[inline]
fn pad3<const D: usize>(p: &[f64; D]) -> P3 {
    let mut o = [0.0; 3];
    for (k, x) in p.iter().take(3).enumerate() {
        o[k] = *x;
    }
    o
}

#[inline]
fn pad2<const D: usize>(p: &[f64; D]) -> P2 {
    [p[0], if D > 1 { p[1] } else { 0.0 }]
}

/// The dimension-specific pieces: element corners, area vector `a_t n_t` and exact angle.
pub(super) trait Element<const D: usize> {
    fn corners(&self, e: usize) -> [[f64; D]; D];
    fn exact(&self, q: &[f64; D], e: usize) -> f64;
}

impl<const D: usize> Element<D> for Boundary<D> {
    #[inline]
    fn corners(&self, e: usize) -> [[f64; D]; D] {
        std::array::from_fn(|k| self.verts[self.elems[e][k]])
    }

    #[inline]
    fn exact(&self, q: &[f64; D], e: usize) -> f64 {
        let p = self.corners(e);
        if D == 3 {
            solid_angle(&pad3(q), &pad3(&p[0]), &pad3(&p[1]), &pad3(&p[2 % D]))
        } else {
            segment_angle(&pad2(q), &pad2(&p[0]), &pad2(&p[1 % D]))
        }
    }
}

/// `a_t n_t`: half the cross product for a triangle, `b - a` turned clockwise for a segment.
#[inline]
pub(super) fn area_vector<const D: usize>(p: &[[f64; D]; D]) -> [f64; D] {
    let mut out = [0.0; D];
    if D == 3 {
        let (a, b, c) = (pad3(&p[0]), pad3(&p[1]), pad3(&p[2 % D]));
        let n = cross(&sub(&b, &a), &sub(&c, &a));
        for (k, o) in out.iter_mut().enumerate() {
            *o = 0.5 * n[k];
        }
    } else {
        let e = sub(&pad2(&p[1 % D]), &pad2(&p[0]));
        out[0] = e[1];
        out[1 % D] = -e[0];
    }
    out
}

/// Exact 2D winding number of segments at each row of `q`, in parallel, without a tree.
///
/// Inputs: v #V by 2, f #F by 2 (rows index v), q #Q by 2. Output: #Q values, 1 inside a
/// counter-clockwise closed polygon, -1 inside a clockwise one, 0 outside.
pub fn winding_number_2d(
    v: ArrayView2<f64>,
    f: ArrayView2<usize>,
    q: ArrayView2<f64>,
) -> SkinResult<Vec<f64>> {
    // Boundary::new validates shapes, indices and coordinates.
    let b = Boundary::<2>::new(v, f)?;
    check_queries::<2>(&q, "Q")?;
    let segs: Vec<(P2, P2)> = b
        .elems
        .iter()
        .map(|&[i, j]| (b.verts[i], b.verts[j]))
        .collect();
    Ok((0..q.nrows())
        .into_par_iter()
        .map(|i| {
            let x: P2 = row(&q, i);
            segs.iter()
                .map(|(a, c)| segment_angle(&x, a, c))
                .sum::<f64>()
                / TWO_PI
        })
        .collect())
}
