//! Generalized winding numbers (Jacobson et al. 2013) of triangle meshes, open meshes and soups,
//! with the fast hierarchical evaluation of Barill et al. 2018 ("Fast winding numbers for soups
//! and clouds"); and the exact 2D winding number of a set of segments.
//!
//! 3D, [`FastWinding`]:
//!   v  #V by 3 vertex positions, f #F by 3 triangles (rows index v), beta > 0 accuracy
//!   eval(q) -> w(q) = (1 / 4 pi) sum over triangles of the signed solid angle seen from q
//!   eval_batch(Q) #Q by 3 -> #Q values (rayon-parallel)
//! 2D, [`winding_number_2d`]:
//!   v  #V by 2, f #F by 2 segments, Q #Q by 2 -> #Q values, (1 / 2 pi) sum of signed angles
//!
//! Convention (libigl's): 1 inside a closed mesh with outward (counter-clockwise seen from
//! outside) triangles, 0 outside; for open meshes and soups the value varies smoothly in between.
//!
//! Far field. The solid angle of a cluster of triangles `T` seen from `q` is
//! `Omega(q) = sum_t int_t n_t . g(x - q) dA`, `g(r) = r / |r|^3`. Expanding `g` around the
//! cluster's area-weighted centre `c` (Barill et al., eq. 9-11), with `r = c - q`:
//!   Omega ~ g(r) . N + J(r) : M + 1/2 H(r) : C
//! where `N = sum a_t n_t` (dipole), `M_ij = sum a_t n_ti (x_t - c)_j` (`x_t` the centroid) and
//! `C_ijk = sum n_ti int_t (x - c)_j (x - c)_k dA`, the latter exact through the triangle's
//! second moment `int_t y y^T dA = a_t / 12 (sum_v y_v y_v^T + (sum_v y_v)(sum_v y_v)^T)`.
//! `J = grad g` and `H = grad grad g` are written out in [`Expansion::eval`]. A node is used
//! through its expansion when `|q - c| > beta * R`, `R` the largest distance from `c` to a
//! corner of the node's box; otherwise its children (or, at a leaf, the exact solid angles of van
//! Oosterom & Strackee 1983) are used. `beta = 2` is Barill et al.'s default; the truncation
//! error of a node decays like `beta^-3` relative to its dipole term.
//!
//! 2D. An exact sum of `atan2` over segments is cheap next to everything else the 2D method
//! does, so no tree is used there.

use ndarray::ArrayView2;
use rayon::prelude::*;

use super::bvh::{check_queries, Aabb, Boundary};
use super::{add, cross, cross2, dot, norm2, par_map_coherent, row, scale, sub, P2, P3};
use crate::error::SkinResult;
use crate::invalid;

const FOUR_PI: f64 = 4.0 * std::f64::consts::PI;
/// Triangles per leaf of the winding-number tree (exact solid angles below that).
const WINDING_LEAF: usize = 8;
const TWO_PI: f64 = 2.0 * std::f64::consts::PI;

/// Per-node far-field data.
#[derive(Clone, Copy, Debug)]
struct Expansion {
    center: P3,
    /// Squared `beta * R`: the expansion is used for `|q - c|^2 > reach2`.
    reach2: f64,
    n: P3,
    m: [[f64; 3]; 3],
    /// `C_i,jk` with `jk` in the order xx, yy, zz, xy, xz, yz (C is symmetric in j, k).
    c: [[f64; 6]; 3],
    /// Total area and sum of triangle centroids (to merge children into their parent).
    area: f64,
    csum: P3,
}

impl Expansion {
    /// The order-2 far-field solid angle at `q`.
    #[inline]
    fn eval(&self, q: &P3) -> f64 {
        let r = sub(&self.center, q);
        let d2 = norm2(&r);
        let d = d2.sqrt();
        let inv3 = 1.0 / (d2 * d);
        let inv5 = inv3 / d2;
        let inv7 = inv5 / d2;
        // Order 0: g(r) . N.
        let o0 = dot(&r, &self.n) * inv3;
        // Order 1: J_ij = delta_ij / d^3 - 3 r_i r_j / d^5.
        let m = &self.m;
        let tr = m[0][0] + m[1][1] + m[2][2];
        let mut rmr = 0.0;
        for i in 0..3 {
            for j in 0..3 {
                rmr += r[i] * m[i][j] * r[j];
            }
        }
        let o1 = tr * inv3 - 3.0 * rmr * inv5;
        // Order 2: H_ijk = -3 (d_ij r_k + d_ik r_j + d_jk r_i) / d^5 + 15 r_i r_j r_k / d^7, so
        // H : C = -3 (2 sum_ik C_iik r_k + sum_i r_i tr_jk C_ijj) / d^5 + 15 C[r, r, r] / d^7.
        let mut a = 0.0; // sum_ik C_i,ik r_k
        let mut b = 0.0; // sum_i r_i (C_i,xx + C_i,yy + C_i,zz)
        let mut e = 0.0; // C[r, r, r]
        for i in 0..3 {
            let ci = &self.c[i];
            let cik = |k: usize| sym(ci, i, k);
            a += cik(0) * r[0] + cik(1) * r[1] + cik(2) * r[2];
            b += r[i] * (ci[0] + ci[1] + ci[2]);
            let rcr = ci[0] * r[0] * r[0]
                + ci[1] * r[1] * r[1]
                + ci[2] * r[2] * r[2]
                + 2.0 * (ci[3] * r[0] * r[1] + ci[4] * r[0] * r[2] + ci[5] * r[1] * r[2]);
            e += r[i] * rcr;
        }
        let o2 = 0.5 * (-3.0 * (2.0 * a + b) * inv5 + 15.0 * e * inv7);
        o0 + o1 + o2
    }
}

/// Entry `(j, k)` of a symmetric 3x3 matrix stored as xx, yy, zz, xy, xz, yz.
#[inline]
fn sym(c: &[f64; 6], j: usize, k: usize) -> f64 {
    match (j.min(k), j.max(k)) {
        (0, 0) => c[0],
        (1, 1) => c[1],
        (2, 2) => c[2],
        (0, 1) => c[3],
        (0, 2) => c[4],
        _ => c[5],
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

/// Fast winding number of a triangle mesh or soup.
#[derive(Clone, Debug)]
pub struct FastWinding {
    boundary: Boundary<3>,
    exp: Vec<Expansion>,
}

impl FastWinding {
    /// Builds the tree and the per-node expansions. `beta` (> 0) trades accuracy for speed:
    /// larger is more accurate; `f64::INFINITY` gives the exact sum (slowly).
    pub fn new(v: ArrayView2<f64>, f: ArrayView2<usize>, beta: f64) -> SkinResult<Self> {
        if beta.is_nan() || beta <= 0.0 {
            return invalid!("beta must be positive, got {beta}");
        }
        let boundary = Boundary::<3>::with_leaf_size(v, f, WINDING_LEAF)?;
        let b = &boundary;
        let nodes = &b.bvh.nodes;
        // Leaves from their triangles (in parallel), inner nodes bottom-up by shifting their
        // children's moments (children come after their parent in the flat array): O(#F)
        // instead of O(#F log #F) for summing every subtree's triangles again.
        let mut exp: Vec<Option<Expansion>> = nodes
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

    /// The tree and primitives (also usable for segment and closest-point queries).
    pub fn boundary(&self) -> &Boundary<3> {
        &self.boundary
    }

    /// Winding number at `q`.
    pub fn eval(&self, q: &P3) -> f64 {
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
                    let [i, j, k] = b.elems[t as usize];
                    omega += solid_angle(q, &b.verts[i], &b.verts[j], &b.verts[k]);
                }
            } else {
                stack.push(node.right);
                stack.push(ni + 1);
            }
        }
        omega / FOUR_PI
    }

    /// Winding numbers at the rows of `q` (#Q by 3), in parallel.
    pub fn eval_batch(&self, q: ArrayView2<f64>) -> SkinResult<Vec<f64>> {
        check_queries::<3>(&q, "Q")?;
        Ok(par_map_coherent(&q, |x: &P3| self.eval(x)))
    }
}

/// Expansion of the triangles `tris` (a node's range of the permutation).
fn expansion(b: &Boundary<3>, tris: &[u32], bbox: &Aabb<3>, beta: f64) -> Expansion {
    let corners = |t: u32| {
        let [i, j, k] = b.elems[t as usize];
        (b.verts[i], b.verts[j], b.verts[k])
    };
    // Area-weighted centre; plain mean of centroids if every triangle is degenerate.
    let mut area = 0.0;
    let mut wc = [0.0; 3];
    let mut mc = [0.0; 3];
    for &t in tris {
        let (p0, p1, p2) = corners(t);
        let a = 0.5 * norm2(&cross(&sub(&p1, &p0), &sub(&p2, &p0))).sqrt();
        let cen = scale(&add(&add(&p0, &p1), &p2), 1.0 / 3.0);
        area += a;
        wc = add(&wc, &scale(&cen, a));
        mc = add(&mc, &cen);
    }
    let center = if area > 0.0 {
        scale(&wc, 1.0 / area)
    } else {
        scale(&mc, 1.0 / tris.len() as f64)
    };
    let mut n = [0.0; 3];
    let mut m = [[0.0; 3]; 3];
    let mut c = [[0.0; 6]; 3];
    for &t in tris {
        let (p0, p1, p2) = corners(t);
        // Area vector a_t n_t.
        let an = scale(&cross(&sub(&p1, &p0), &sub(&p2, &p0)), 0.5);
        let y = [sub(&p0, &center), sub(&p1, &center), sub(&p2, &center)];
        let s = add(&add(&y[0], &y[1]), &y[2]);
        // (sum_v y_v y_v^T + s s^T) / 12 in xx, yy, zz, xy, xz, yz order.
        let mom = |j: usize, k: usize| {
            (y[0][j] * y[0][k] + y[1][j] * y[1][k] + y[2][j] * y[2][k] + s[j] * s[k]) / 12.0
        };
        let second = [
            mom(0, 0),
            mom(1, 1),
            mom(2, 2),
            mom(0, 1),
            mom(0, 2),
            mom(1, 2),
        ];
        for i in 0..3 {
            n[i] += an[i];
            for j in 0..3 {
                m[i][j] += an[i] * s[j] / 3.0;
            }
            for jk in 0..6 {
                c[i][jk] += an[i] * second[jk];
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
        csum: mc,
    }
}

/// `(beta R)^2` with `R` the farthest corner of the node's box from the centre (as libigl's
/// UT_SolidAngle). The farthest vertex would be tighter, but the box radius also bounds how far
/// the triangles spread sideways, and at beta = 2 it halves the worst-case error for ~20% time.
fn reach2(center: &P3, bbox: &Aabb<3>, beta: f64) -> f64 {
    let r2: f64 = (0..3)
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
fn merge(l: &Expansion, r: &Expansion, bbox: &Aabb<3>, count: u32, beta: f64) -> Expansion {
    let area = l.area + r.area;
    let csum = add(&l.csum, &r.csum);
    let center = if area > 0.0 {
        scale(
            &add(&scale(&l.center, l.area), &scale(&r.center, r.area)),
            1.0 / area,
        )
    } else {
        // Every triangle degenerate: mean of the centroids, as in `expansion`.
        scale(&csum, 1.0 / count as f64)
    };
    let mut n = [0.0; 3];
    let mut m = [[0.0; 3]; 3];
    let mut c = [[0.0; 6]; 3];
    const JK: [(usize, usize); 6] = [(0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2)];
    for ch in [l, r] {
        let d = sub(&ch.center, &center);
        for i in 0..3 {
            n[i] += ch.n[i];
            for j in 0..3 {
                m[i][j] += ch.m[i][j] + ch.n[i] * d[j];
            }
            for (jk, &(j, k)) in JK.iter().enumerate() {
                c[i][jk] +=
                    ch.c[i][jk] + ch.m[i][j] * d[k] + ch.m[i][k] * d[j] + ch.n[i] * d[j] * d[k];
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

/// Exact 2D winding number of segments at each row of `q`, in parallel.
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
            let mut s = 0.0;
            for (a, c) in &segs {
                let u = sub(a, &x);
                let w = sub(c, &x);
                s += cross2(&u, &w).atan2(dot(&u, &w));
            }
            s / TWO_PI
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
            let fw = FastWinding::new(v.view(), f.view(), beta).unwrap();
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
        let fw = FastWinding::new(v.view(), f.view(), f64::INFINITY).unwrap();
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
        let fw = FastWinding::new(v.view(), f.view(), 2.0).unwrap();
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
        let fw = FastWinding::new(v.view(), f.view(), 2.0).unwrap();
        let q = [3.0, -2.0, 4.0];
        let e = solid_angle(&q, &[0.0, 0.0, 0.0], &[1.0, 0.2, 0.0], &[0.3, 1.0, 0.1]);
        let a = fw.exp[0].eval(&q);
        // Third-order truncation: relative error ~ (R / d)^3 ~ 1e-2 at d / R ~ 5.
        assert!((a - e).abs() < 1e-3 * e.abs().max(1e-3), "{a} vs {e}");
    }

    #[test]
    fn merged_expansions_equal_direct_sums() {
        let (v, f) = sphere(30, 15);
        let fw = FastWinding::new(v.view(), f.view(), 2.0).unwrap();
        let b = fw.boundary();
        for (node, e) in b.bvh.nodes.iter().zip(&fw.exp) {
            let s = node.start as usize;
            let d = expansion(b, &b.bvh.order[s..s + node.count as usize], &node.bbox, 2.0);
            let close = |x: f64, y: f64| (x - y).abs() < 1e-12;
            assert!((0..3).all(|k| close(e.center[k], d.center[k]) && close(e.n[k], d.n[k])));
            assert!((0..3).all(|i| (0..3).all(|j| close(e.m[i][j], d.m[i][j]))));
            assert!((0..3).all(|i| (0..6).all(|j| close(e.c[i][j], d.c[i][j]))));
            assert!(close(e.reach2, d.reach2));
        }
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
