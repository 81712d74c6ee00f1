//! The far field of a cluster of elements (module doc of [`super`]): the order-2 expansion of
//! one tree node around its area-weighted centre, built from a leaf's elements or merged from
//! its two children, and evaluated at a query point.

use super::exact::{area_vector, Element};
use crate::field::boundary::Boundary;
use crate::field::bvh::Aabb;
use crate::field::{add, dot, norm2, scale, sub};

/// Per-node far-field data.
#[derive(Clone, Copy, Debug)]
pub(super) struct Expansion<const D: usize> {
    pub(super) center: [f64; D],
    /// Squared `beta * R`: the expansion is used for `|q - c|^2 > reach2`.
    pub(super) reach2: f64,
    pub(super) n: [f64; D],
    pub(super) m: [[f64; D]; D],
    /// `C[i][j][k]`, symmetric in `j, k`.
    pub(super) c: [[[f64; D]; D]; D],
    /// Total measure and sum of element centroids (to merge children into their parent).
    pub(super) area: f64,
    pub(super) csum: [f64; D],
}

impl<const D: usize> Expansion<D> {
    /// The order-2 far-field angle at `q` (not yet divided by the full angle).
    ///
    /// Written in the unit direction `u = r / d` and powers of `1 / d`, so that no intermediate
    /// grows with a power of the distance: far queries underflow to 0 instead of giving
    /// `inf * 0 = NaN`.
    #[inline]
    pub(super) fn eval(&self, q: &[f64; D]) -> f64 {
        let r = sub(&self.center, q);
        let d = norm2(&r).sqrt();
        let u = scale(&r, 1.0 / d);
        let dd = D as f64;
        let inv = 1.0 / d;
        // 1 / d^(D-1), 1 / d^D, 1 / d^(D+1)
        let inv_a = if D == 3 { inv * inv } else { inv };
        let inv_b = inv_a * inv;
        let inv_c = inv_b * inv;
        // Order 0: g(r) . N = (u . N) / d^(D-1).
        let o0 = dot(&u, &self.n) * inv_a;
        // Order 1: J : M = (tr(M) - D u^T M u) / d^D.
        let mut tr = 0.0;
        let mut umu = 0.0;
        for i in 0..D {
            tr += self.m[i][i];
            umu += u[i] * dot(&self.m[i], &u);
        }
        let o1 = (tr - dd * umu) * inv_b;
        // Order 2: H : C = (-D (2 sum_ik C_iik u_k + sum_i u_i sum_j C_ijj)
        //                  + D (D+2) C[u, u, u]) / d^(D+1)   (C symmetric in its last two indices).
        let mut a = 0.0;
        let mut b = 0.0;
        let mut e = 0.0;
        for i in 0..D {
            let ci = &self.c[i];
            a += dot(&ci[i], &u);
            let mut t = 0.0;
            let mut ucu = 0.0;
            for j in 0..D {
                t += ci[j][j];
                ucu += u[j] * dot(&ci[j], &u);
            }
            b += u[i] * t;
            e += u[i] * ucu;
        }
        let o2 = 0.5 * (-dd * (2.0 * a + b) + dd * (dd + 2.0) * e) * inv_c;
        o0 + o1 + o2
    }
}

/// Expansion of the elements `elems` (a leaf's range of the permutation).
pub(super) fn expansion<const D: usize>(
    b: &Boundary<D>,
    elems: &[u32],
    bbox: &Aabb<D>,
    beta: f64,
) -> Expansion<D> {
    let dd = D as f64;
    // Area-weighted centre; plain mean of centroids if every element is degenerate.
    let mut area = 0.0;
    let mut wc = [0.0; D];
    let mut csum = [0.0; D];
    for &t in elems {
        let p = b.corners(t as usize);
        let a = norm2(&area_vector(&p)).sqrt();
        let cen = scale(&p.iter().fold([0.0; D], |s, x| add(&s, x)), 1.0 / dd);
        area += a;
        wc = add(&wc, &scale(&cen, a));
        csum = add(&csum, &cen);
    }
    let center = if area > 0.0 {
        scale(&wc, 1.0 / area)
    } else {
        scale(&csum, 1.0 / elems.len() as f64)
    };
    let mut n = [0.0; D];
    let mut m = [[0.0; D]; D];
    let mut c = [[[0.0; D]; D]; D];
    let den = dd * (dd + 1.0);
    for &t in elems {
        let p = b.corners(t as usize);
        let an = area_vector(&p);
        let y: [[f64; D]; D] = std::array::from_fn(|v| sub(&p[v], &center));
        let s = y.iter().fold([0.0; D], |acc, x| add(&acc, x));
        // Exact second moment / area: (sum_v y_v y_v^T + s s^T) / (D (D + 1)).
        let mom: [[f64; D]; D] = std::array::from_fn(|j| {
            std::array::from_fn(|k| {
                (y.iter().map(|yv| yv[j] * yv[k]).sum::<f64>() + s[j] * s[k]) / den
            })
        });
        for i in 0..D {
            n[i] += an[i];
            for j in 0..D {
                m[i][j] += an[i] * s[j] / dd;
                for k in 0..D {
                    c[i][j][k] += an[i] * mom[j][k];
                }
            }
        }
    }
    Expansion {
        center,
        reach2: reach2(&center, bbox, beta),
        n,
        m,
        c,
        area,
        csum,
    }
}

/// `(beta R)^2` with `R` the farthest corner of the node's box from the centre (as libigl's
/// UT_SolidAngle). The farthest vertex would be tighter, but the box radius also bounds how far
/// the elements spread sideways, and at beta = 2 it halves the worst-case error for ~20% time.
fn reach2<const D: usize>(center: &[f64; D], bbox: &Aabb<D>, beta: f64) -> f64 {
    let r2: f64 = (0..D)
        .map(|k| {
            let d = (center[k] - bbox.lo[k])
                .abs()
                .max((bbox.hi[k] - center[k]).abs());
            d * d
        })
        .sum();
    beta * beta * r2
}

/// Parent expansion from its two children: moments move to the new centre `c` with
/// `y' = y + d`, `d = c_child - c`:
///   M'_ij = M_ij + N_i d_j,   C'_ijk = C_ijk + M_ij d_k + M_ik d_j + N_i d_j d_k.
pub(super) fn merge<const D: usize>(
    l: &Expansion<D>,
    r: &Expansion<D>,
    bbox: &Aabb<D>,
    count: u32,
    beta: f64,
) -> Expansion<D> {
    let area = l.area + r.area;
    let csum = add(&l.csum, &r.csum);
    let center = if area > 0.0 {
        scale(
            &add(&scale(&l.center, l.area), &scale(&r.center, r.area)),
            1.0 / area,
        )
    } else {
        // Every element degenerate: mean of the centroids, as in `expansion`.
        scale(&csum, 1.0 / count as f64)
    };
    let mut n = [0.0; D];
    let mut m = [[0.0; D]; D];
    let mut c = [[[0.0; D]; D]; D];
    for ch in [l, r] {
        let d = sub(&ch.center, &center);
        for i in 0..D {
            n[i] += ch.n[i];
            for j in 0..D {
                m[i][j] += ch.m[i][j] + ch.n[i] * d[j];
                for k in 0..D {
                    c[i][j][k] += ch.c[i][j][k]
                        + ch.m[i][j] * d[k]
                        + ch.m[i][k] * d[j]
                        + ch.n[i] * d[j] * d[k];
                }
            }
        }
    }
    Expansion {
        center,
        reach2: reach2(&center, bbox, beta),
        n,
        m,
        c,
        area,
        csum,
    }
}
