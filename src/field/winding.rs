//! Generalized winding numbers (Jacobson et al. 2013) of triangle meshes, open meshes and soups
//! in 3D and of segment sets in 2D, with the fast hierarchical evaluation of Barill et al. 2018
//! ("Fast winding numbers for soups and clouds").
//!
//! [`FastWinding`]`<D>`:
//!   v  #V by D vertex positions, f #F by D elements (triangles in 3D, segments in 2D; rows
//!      index v), beta > 0 accuracy
//!   eval(q) -> w(q) = sum over elements of the signed solid angle (3D, / 4 pi) or signed angle
//!              (2D, / 2 pi) subtended at q
//!   eval_batch(Q) #Q by D -> #Q values (rayon-parallel)
//! [`winding_number_2d`]: the exact 2D sum without a tree (reference and small inputs).
//!
//! Convention (libigl's): 1 inside a closed mesh with outward (counter-clockwise seen from
//! outside) triangles or inside a counter-clockwise polygon, 0 outside; for open meshes and
//! soups the value varies smoothly in between.
//!
//! Far field. The angle subtended by a cluster `T` of elements seen from `q` is
//! `Omega(q) = sum_t int_t n_t . g(x - q) dA`, `g(r) = r / |r|^D`. Expanding `g` around the
//! cluster's area-weighted centre `c` (Barill et al., eq. 9-11), with `r = c - q`, `d = |r|`:
//!   Omega ~ g(r) . N + J(r) : M + 1/2 H(r) : C
//!   J_ij  = delta_ij / d^D - D r_i r_j / d^(D+2)
//!   H_ijk = -D (delta_ij r_k + delta_ik r_j + delta_jk r_i) / d^(D+2) + D (D+2) r_i r_j r_k / d^(D+4)
//! where `N = sum a_t n_t` (dipole), `M_ij = sum a_t n_ti (x_t - c)_j` (`x_t` the centroid) and
//! `C_ijk = sum n_ti int_t (x - c)_j (x - c)_k dA`, the latter exact through the element's
//! second moment `int_t y y^T dA = a_t / (D (D + 1)) (sum_v y_v y_v^T + (sum_v y_v)(sum_v y_v)^T)`
//! (1/12 for triangles, 1/6 for segments). A node is used through its expansion when
//! `|q - c| > beta * R`, `R` the distance from `c` to the farthest corner of the node's box;
//! otherwise its children, or at a leaf the exact angles (van Oosterom & Strackee 1983 in 3D,
//! `atan2` in 2D), are used. `beta = 2` is Barill et al.'s (and libigl's) default; a node's
//! truncation error decays like `beta^-3` relative to its dipole term.

use ndarray::ArrayView2;
use rayon::prelude::*;

use super::boundary::{check_queries, Boundary};
use super::bvh::Aabb;
use super::{add, cross, cross2, dot, norm2, par_map_coherent, row, scale, sub, P2, P3};
use crate::error::SkinResult;
use crate::invalid;

const FOUR_PI: f64 = 4.0 * std::f64::consts::PI;
const TWO_PI: f64 = 2.0 * std::f64::consts::PI;
/// Elements per leaf of the winding-number tree (exact angles below that).
const WINDING_LEAF: usize = 8;

/// Per-node far-field data.
#[derive(Clone, Copy, Debug)]
struct Expansion<const D: usize> {
    center: [f64; D],
    /// Squared `beta * R`: the expansion is used for `|q - c|^2 > reach2`.
    reach2: f64,
    n: [f64; D],
    m: [[f64; D]; D],
    /// `C[i][j][k]`, symmetric in `j, k`.
    c: [[[f64; D]; D]; D],
    /// Total measure and sum of element centroids (to merge children into their parent).
    area: f64,
    csum: [f64; D],
}

impl<const D: usize> Expansion<D> {
    /// The order-2 far-field angle at `q` (not yet divided by the full angle).
    ///
    /// Written in the unit direction `u = r / d` and powers of `1 / d`, so that no intermediate
    /// grows with a power of the distance: far queries underflow to 0 instead of giving
    /// `inf * 0 = NaN`.
    #[inline]
    fn eval(&self, q: &[f64; D]) -> f64 {
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
trait Element<const D: usize> {
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
fn area_vector<const D: usize>(p: &[[f64; D]; D]) -> [f64; D] {
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

/// Fast winding number of a triangle mesh or soup (`D = 3`) or of a set of segments (`D = 2`).
#[derive(Clone, Debug)]
pub struct FastWinding<const D: usize> {
    boundary: Boundary<D>,
    exp: Vec<Expansion<D>>,
}

impl<const D: usize> FastWinding<D> {
    /// Builds the tree and the per-node expansions. `beta` (> 0) trades accuracy for speed:
    /// larger is more accurate; `f64::INFINITY` gives the exact sum (slowly).
    pub fn new(v: ArrayView2<f64>, f: ArrayView2<usize>, beta: f64) -> SkinResult<Self> {
        if beta.is_nan() || beta <= 0.0 {
            return invalid!("beta must be positive, got {beta}");
        }
        if D != 2 && D != 3 {
            return invalid!("winding numbers are defined in 2D and 3D, not {D}D");
        }
        let boundary = Boundary::<D>::with_leaf_size(v, f, WINDING_LEAF)?;
        let b = &boundary;
        let nodes = &b.bvh.nodes;
        // Leaves from their elements (in parallel), inner nodes bottom-up by shifting their
        // children's moments (children come after their parent in the flat array): O(#F)
        // instead of O(#F log #F) for summing every subtree's elements again.
        let mut exp: Vec<Option<Expansion<D>>> = nodes
            .par_iter()
            .map(|node| {
                node.is_leaf().then(|| {
                    let s = node.start as usize;
                    expansion(
                        b,
                        &b.bvh.order[s..s + node.count as usize],
                        &node.bbox,
                        beta,
                    )
                })
            })
            .collect();
        for i in (0..nodes.len()).rev() {
            if !nodes[i].is_leaf() {
                let l = exp[i + 1].expect("child computed before parent");
                let r = exp[nodes[i].right as usize].expect("child computed before parent");
                exp[i] = Some(merge(&l, &r, &nodes[i].bbox, nodes[i].count, beta));
            }
        }
        let exp = exp.into_iter().map(|e| e.expect("every node")).collect();
        Ok(FastWinding { boundary, exp })
    }

    /// The tree and elements (also usable for segment and closest-point queries).
    pub fn boundary(&self) -> &Boundary<D> {
        &self.boundary
    }

    /// Winding number at `q`.
    pub fn eval(&self, q: &[f64; D]) -> f64 {
        let b = &self.boundary;
        let mut omega = 0.0;
        let mut stack: Vec<u32> = Vec::with_capacity(64);
        stack.push(0);
        while let Some(ni) = stack.pop() {
            let e = &self.exp[ni as usize];
            if norm2(&sub(q, &e.center)) > e.reach2 {
                omega += e.eval(q);
                continue;
            }
            let node = &b.bvh.nodes[ni as usize];
            if node.is_leaf() {
                let s = node.start as usize;
                for &t in &b.bvh.order[s..s + node.count as usize] {
                    omega += b.exact(q, t as usize);
                }
            } else {
                stack.push(node.right);
                stack.push(ni + 1);
            }
        }
        omega / if D == 3 { FOUR_PI } else { TWO_PI }
    }

    /// Winding numbers at the rows of `q` (#Q by D), in parallel.
    pub fn eval_batch(&self, q: ArrayView2<f64>) -> SkinResult<Vec<f64>> {
        check_queries::<D>(&q, "Q")?;
        Ok(par_map_coherent(&q, |x: &[f64; D]| self.eval(x)))
    }
}

/// Expansion of the elements `elems` (a leaf's range of the permutation).
fn expansion<const D: usize>(
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
fn merge<const D: usize>(
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

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::array;

    fn exact(b: &Boundary<3>, q: &P3) -> f64 {
        b.elems
            .iter()
            .map(|&[i, j, k]| solid_angle(q, &b.verts[i], &b.verts[j], &b.verts[k]))
            .sum::<f64>()
            / FOUR_PI
    }

    /// UV sphere with outward triangles.
    fn sphere(nu: usize, nv: usize) -> (ndarray::Array2<f64>, ndarray::Array2<usize>) {
        let mut v = vec![[0.0, 0.0, 1.0]];
        for i in 1..nv {
            let th = std::f64::consts::PI * i as f64 / nv as f64;
            for j in 0..nu {
                let ph = TWO_PI * j as f64 / nu as f64;
                v.push([th.sin() * ph.cos(), th.sin() * ph.sin(), th.cos()]);
            }
        }
        v.push([0.0, 0.0, -1.0]);
        let south = v.len() - 1;
        let id = |i: usize, j: usize| 1 + (i - 1) * nu + (j % nu);
        let mut f = Vec::new();
        for j in 0..nu {
            f.push([0, id(1, j), id(1, j + 1)]);
            f.push([south, id(nv - 1, j + 1), id(nv - 1, j)]);
        }
        for i in 1..nv - 1 {
            for j in 0..nu {
                f.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
                f.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
            }
        }
        let va = ndarray::Array2::from_shape_fn((v.len(), 3), |(i, k)| v[i][k]);
        let fa = ndarray::Array2::from_shape_fn((f.len(), 3), |(i, k)| f[i][k]);
        (va, fa)
    }

    #[test]
    fn sphere_inside_outside_and_far_field_accuracy() {
        let (v, f) = sphere(40, 20);
        // The centre of a sphere is the worst case for the expansion: every node is seen from
        // about the same distance, so the truncation errors add up coherently.
        for (beta, tol) in [(2.0, 3e-3), (4.0, 3e-4)] {
            let fw = FastWinding::<3>::new(v.view(), f.view(), beta).unwrap();
            for q in [
                [0.1, -0.2, 0.3],
                [0.3, 0.2, 0.8],
                [1.1, 0.0, 0.0],
                [-2.0, 1.0, 0.5],
            ] {
                let (a, e) = (fw.eval(&q), exact(fw.boundary(), &q));
                assert!(
                    (a - e).abs() < tol,
                    "beta {beta} at {q:?}: fast {a} exact {e}"
                );
            }
        }
        let fw = FastWinding::<3>::new(v.view(), f.view(), f64::INFINITY).unwrap();
        assert!((fw.eval(&[0.1, -0.2, 0.3]) - 1.0).abs() < 1e-12);
        assert!(fw.eval(&[3.0, 0.0, 0.0]).abs() < 1e-12);
    }

    #[test]
    fn expansion_error_is_third_order() {
        // Two triangles seen from farther and farther away: the order-2 expansion's error falls
        // like d^-5 (solid angle d^-2 times (R / d)^3), i.e. ~32x per doubling.
        let v = array![
            [0.0, 0.0, 0.0],
            [1.0, 0.2, 0.0],
            [0.3, 1.0, 0.1],
            [0.5, 0.5, 0.8]
        ];
        let f = array![[0usize, 1, 2], [0, 3, 1]];
        let fw = FastWinding::<3>::new(v.view(), f.view(), 2.0).unwrap();
        let err = |s: f64| {
            let q = [0.3 + 0.4 * s, 0.2 - 0.5 * s, 0.1 + 0.7 * s];
            (fw.exp[0].eval(&q) - exact(fw.boundary(), &q) * FOUR_PI).abs()
        };
        let (e8, e16, e32) = (err(8.0), err(16.0), err(32.0));
        assert!(e8 / e16 > 30.0 && e16 / e32 > 30.0, "{e8} {e16} {e32}");
    }

    #[test]
    fn single_triangle_expansion_matches_exact_far_away() {
        let v = array![[0.0, 0.0, 0.0], [1.0, 0.2, 0.0], [0.3, 1.0, 0.1]];
        let f = array![[0usize, 1, 2]];
        let fw = FastWinding::<3>::new(v.view(), f.view(), 2.0).unwrap();
        let q = [3.0, -2.0, 4.0];
        let e = solid_angle(&q, &[0.0, 0.0, 0.0], &[1.0, 0.2, 0.0], &[0.3, 1.0, 0.1]);
        let a = fw.exp[0].eval(&q);
        // Third-order truncation: relative error ~ (R / d)^3 ~ 1e-2 at d / R ~ 5.
        assert!((a - e).abs() < 1e-3 * e.abs().max(1e-3), "{a} vs {e}");
    }

    #[test]
    fn merged_expansions_equal_direct_sums() {
        let (v, f) = sphere(30, 15);
        let fw = FastWinding::<3>::new(v.view(), f.view(), 2.0).unwrap();
        let b = fw.boundary();
        for (node, e) in b.bvh.nodes.iter().zip(&fw.exp) {
            let s = node.start as usize;
            let d = expansion(b, &b.bvh.order[s..s + node.count as usize], &node.bbox, 2.0);
            let close = |x: f64, y: f64| (x - y).abs() < 1e-12;
            assert!((0..3).all(|k| close(e.center[k], d.center[k]) && close(e.n[k], d.n[k])));
            assert!((0..3).all(|i| (0..3).all(|j| close(e.m[i][j], d.m[i][j]))));
            assert!(
                (0..3).all(|i| (0..3).all(|j| (0..3).all(|k| close(e.c[i][j][k], d.c[i][j][k]))))
            );
            assert!(close(e.reach2, d.reach2));
        }
    }

    #[test]
    fn fast_2d_matches_exact_sum() {
        // In 2D the kernel decays like 1/d only, so at equal beta the far field is less accurate
        // than in 3D (see docs/field.md for the errors at beta = 2, 3, 4).
        // A wiggly star polygon (counter-clockwise), 600 segments.
        let n = 600;
        let v = ndarray::Array2::from_shape_fn((n, 2), |(i, k)| {
            let t = TWO_PI * i as f64 / n as f64;
            let r = 1.0 + 0.3 * (7.0 * t).sin();
            if k == 0 {
                r * t.cos()
            } else {
                r * t.sin()
            }
        });
        let f = ndarray::Array2::from_shape_fn((n, 2), |(i, k)| (i + k) % n);
        let q = ndarray::Array2::from_shape_fn((400, 2), |(i, k)| {
            let x = ((i * 7919 + k * 104729) % 1000) as f64 / 1000.0;
            3.0 * x - 1.5
        });
        let exact = winding_number_2d(v.view(), f.view(), q.view()).unwrap();
        for (beta, tol) in [
            (2.0, 1.5e-2),
            (3.0, 3e-3),
            (4.0, 1e-3),
            (f64::INFINITY, 1e-12),
        ] {
            let fw = FastWinding::<2>::new(v.view(), f.view(), beta).unwrap();
            let w = fw.eval_batch(q.view()).unwrap();
            let err = w
                .iter()
                .zip(&exact)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f64::max);
            assert!(err < tol, "beta {beta}: max error {err}");
        }
        assert!(exact.iter().any(|&w| (w - 1.0).abs() < 1e-9));
        assert!(exact.iter().any(|&w| w.abs() < 1e-9));
    }

    #[test]
    fn expansion_error_is_third_order_2d() {
        let v = array![[0.0, 0.0], [1.0, 0.3], [1.5, 1.0]];
        let f = array![[0usize, 1], [1, 2]];
        let fw = FastWinding::<2>::new(v.view(), f.view(), 2.0).unwrap();
        let b = fw.boundary();
        let err = |s: f64| {
            let q = [0.3 + 0.6 * s, 0.2 - 0.8 * s];
            let e: f64 = (0..2).map(|t| b.exact(&q, t)).sum();
            (fw.exp[0].eval(&q) - e).abs()
        };
        // Angle ~ d^-1 times (R / d)^3: ~16x per doubling.
        let (e8, e16, e32) = (err(8.0), err(16.0), err(32.0));
        assert!(e8 / e16 > 14.0 && e16 / e32 > 14.0, "{e8} {e16} {e32}");
    }

    #[test]
    fn square_2d_winding() {
        let v = array![[0., 0.], [1., 0.], [1., 1.], [0., 1.]];
        let f = array![[0usize, 1], [1, 2], [2, 3], [3, 0]];
        let q = array![[0.5, 0.5], [2.0, 0.3]];
        let w = winding_number_2d(v.view(), f.view(), q.view()).unwrap();
        assert!((w[0] - 1.0).abs() < 1e-14 && w[1].abs() < 1e-14);
    }
}
