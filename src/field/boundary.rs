//! The two queries the geometric-field method needs from the boundary, on a bounding volume
//! hierarchy ([`super::bvh`]).
//!
//! Inputs (to [`Boundary::new`]):
//!   v  #V by D vertex positions, D = 3 (triangles) or D = 2 (segments)
//!   f  #F by D primitives: triangles `[a, b, c]` in 3D, segments `[a, b]` in 2D (rows index v)
//! Queries ([`BoundaryQueries`]):
//!   segment_hits(p, q) -> bool          does the open segment p -> q cross a primitive? (eq. 4)
//!   closest(x)         -> [`Closest`]   distance, closest point, primitive id and unit normal
//!   segment_hits_batch(P, Q) -> #Q bools,  closest_batch(X) -> #X results (rayon-parallel)
//!
//! Degenerate primitives (zero area or length, repeated vertices) are allowed, as soups have
//! them: they are never hit, and closest-point queries still return a point on them (their
//! normal is zero).

use ndarray::{ArrayView2, Axis};
use rayon::prelude::*;

use super::bvh::{Aabb, Bvh};
use super::primitives::{
    closest_on_segment, closest_on_triangle, segment_normal, segment_segment, segment_triangle,
    triangle_normal,
};
use super::{coherent_order, norm2, row, scatter, sub, P2, P3};
use crate::error::SkinResult;
use crate::invalid;

/// Result of a closest-point query.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Closest<const D: usize> {
    pub dist: f64,
    pub point: [f64; D],
    /// Row of `f` holding the closest point (the lowest such row on exact ties).
    pub prim: usize,
    /// Unit normal of that primitive: `(b - a) x (c - a)` normalised for triangles, `(b - a)`
    /// turned clockwise by 90 degrees for segments (outward for a counter-clockwise polygon);
    /// zero for degenerate primitives.
    pub normal: [f64; D],
}

/// A boundary (triangles in 3D, segments in 2D) with its BVH.
#[derive(Clone, Debug)]
pub struct Boundary<const D: usize> {
    pub verts: Vec<[f64; D]>,
    pub elems: Vec<[usize; D]>,
    pub bvh: Bvh<D>,
}

/// Primitives per leaf: small leaves favour the early-exit segment test and nearest queries.
const LEAF_SIZE: usize = 4;

impl<const D: usize> Boundary<D> {
    /// Copies `v` (#V by D) and `f` (#F by D, indices into `v`) and builds the tree.
    pub fn new(v: ArrayView2<f64>, f: ArrayView2<usize>) -> SkinResult<Self> {
        Self::with_leaf_size(v, f, LEAF_SIZE)
    }

    /// As [`Boundary::new`] with at most `leaf_size` (>= 1) primitives per leaf.
    pub fn with_leaf_size(
        v: ArrayView2<f64>,
        f: ArrayView2<usize>,
        leaf_size: usize,
    ) -> SkinResult<Self> {
        if v.ncols() != D || f.ncols() != D {
            return invalid!(
                "boundary in {D}D needs V with {D} columns and F with {D} columns, got V {:?} and F {:?}",
                v.dim(),
                f.dim()
            );
        }
        if f.nrows() == 0 {
            return invalid!("the boundary has no elements (F is empty)");
        }
        if f.nrows() >= u32::MAX as usize {
            return invalid!(
                "too many elements ({}); the tree indexes them with u32",
                f.nrows()
            );
        }
        let nv = v.nrows();
        crate::limits::check_coordinates("V", &v)?;
        let verts: Vec<[f64; D]> = (0..nv).map(|i| row(&v, i)).collect();
        let mut elems = Vec::with_capacity(f.nrows());
        for (e, r) in f.axis_iter(Axis(0)).enumerate() {
            let mut idx = [0usize; D];
            for k in 0..D {
                if r[k] >= nv {
                    return invalid!("F row {e} holds index {}, outside 0..{nv}", r[k]);
                }
                idx[k] = r[k];
            }
            elems.push(idx);
        }
        let boxes: Vec<Aabb<D>> = elems
            .iter()
            .map(|e| {
                let mut b = Aabb::empty();
                for &i in e {
                    b.grow(&verts[i]);
                }
                b
            })
            .collect();
        let bvh = Bvh::build(&boxes, leaf_size);
        Ok(Boundary { verts, elems, bvh })
    }

    /// Depth-first search for any primitive accepted by `hit` among the leaves whose box the
    /// closed segment `p -> q` touches.
    fn any_on_segment(&self, p: &[f64; D], q: &[f64; D], hit: impl Fn(usize) -> bool) -> bool {
        let d = sub(q, p);
        if d.iter().all(|&x| x == 0.0) {
            return false; // the open segment is empty
        }
        let inv: [f64; D] = std::array::from_fn(|k| 1.0 / d[k]);
        let mut stack = [0u32; 64];
        let mut top = 1;
        stack[0] = 0;
        let mut overflow: Vec<u32> = Vec::new();
        loop {
            let ni = if top > 0 {
                top -= 1;
                stack[top]
            } else if let Some(x) = overflow.pop() {
                x
            } else {
                return false;
            };
            let node = &self.bvh.nodes[ni as usize];
            if !node.bbox.hits_segment(p, &d, &inv) {
                continue;
            }
            if node.is_leaf() {
                let s = node.start as usize;
                for &e in &self.bvh.order[s..s + node.count as usize] {
                    if hit(e as usize) {
                        return true;
                    }
                }
            } else {
                for c in [node.right, ni + 1] {
                    if top < stack.len() {
                        stack[top] = c;
                        top += 1;
                    } else {
                        overflow.push(c);
                    }
                }
            }
        }
    }

    /// Branch-and-bound nearest primitive: `closest(e)` gives the squared distance, point and
    /// normal of primitive `e`.
    fn nearest(
        &self,
        x: &[f64; D],
        closest: impl Fn(usize) -> (f64, [f64; D]),
    ) -> (f64, [f64; D], usize) {
        let mut best = (f64::INFINITY, *x, usize::MAX);
        let mut stack: Vec<(u32, f64)> = Vec::with_capacity(64);
        stack.push((0, self.bvh.nodes[0].bbox.dist2(x)));
        while let Some((ni, d2)) = stack.pop() {
            if d2 > best.0 && best.2 != usize::MAX {
                continue;
            }
            let node = &self.bvh.nodes[ni as usize];
            if node.is_leaf() {
                let s = node.start as usize;
                for &e in &self.bvh.order[s..s + node.count as usize] {
                    let (d2, p) = closest(e as usize);
                    // `best.2 == usize::MAX`: take the first candidate even if its distance is
                    // not finite, so a primitive is always returned.
                    if d2 < best.0
                        || (d2 == best.0 && (e as usize) < best.2)
                        || best.2 == usize::MAX
                    {
                        best = (d2, p, e as usize);
                    }
                }
            } else {
                let (l, r) = (ni + 1, node.right);
                let dl = self.bvh.nodes[l as usize].bbox.dist2(x);
                let dr = self.bvh.nodes[r as usize].bbox.dist2(x);
                // Push the farther child first so the nearer one is searched first.
                if dl <= dr {
                    stack.push((r, dr));
                    stack.push((l, dl));
                } else {
                    stack.push((l, dl));
                    stack.push((r, dr));
                }
            }
        }
        best
    }
}

/// The queries every boundary answers, in 2D and 3D.
pub trait BoundaryQueries<const D: usize>: Sync {
    /// True if the open segment `p -> q` crosses a primitive (the endpoints themselves do not
    /// count, so samples lying exactly on the boundary see their neighbours).
    fn segment_hits(&self, p: &[f64; D], q: &[f64; D]) -> bool;

    /// Closest point of the boundary to `x`.
    fn closest(&self, x: &[f64; D]) -> Closest<D>;

    /// `segment_hits` for each pair of rows of `p` and `q` (#Q by D each), in parallel.
    fn segment_hits_batch(&self, p: ArrayView2<f64>, q: ArrayView2<f64>) -> SkinResult<Vec<bool>> {
        check_queries::<D>(&p, "P")?;
        check_queries::<D>(&q, "Q")?;
        if p.nrows() != q.nrows() {
            return invalid!(
                "P and Q must have the same number of rows, got {} and {}",
                p.nrows(),
                q.nrows()
            );
        }
        let order = coherent_order::<D>(&p);
        let vals: Vec<bool> = order
            .par_iter()
            .map(|&i| self.segment_hits(&row(&p, i), &row(&q, i)))
            .collect();
        Ok(scatter(&order, vals))
    }

    /// `closest` for each row of `x` (#X by D), in parallel.
    fn closest_batch(&self, x: ArrayView2<f64>) -> SkinResult<Vec<Closest<D>>> {
        check_queries::<D>(&x, "Q")?;
        let order = coherent_order::<D>(&x);
        let vals: Vec<Closest<D>> = order
            .par_iter()
            .map(|&i| self.closest(&row(&x, i)))
            .collect();
        Ok(scatter(&order, vals))
    }
}

/// Query arrays must have D columns and finite entries.
pub(crate) fn check_queries<const D: usize>(x: &ArrayView2<f64>, name: &str) -> SkinResult<()> {
    if x.ncols() != D {
        return invalid!(
            "{name} must have {D} columns like V, got shape {:?}",
            x.dim()
        );
    }
    crate::limits::check_coordinates(name, x)
}

impl BoundaryQueries<3> for Boundary<3> {
    fn segment_hits(&self, p: &P3, q: &P3) -> bool {
        let d = sub(q, p);
        self.any_on_segment(p, q, |e| {
            let [a, b, c] = self.elems[e];
            segment_triangle(p, &d, &self.verts[a], &self.verts[b], &self.verts[c])
        })
    }

    fn closest(&self, x: &P3) -> Closest<3> {
        let (d2, point, prim) = self.nearest(x, |e| {
            let [a, b, c] = self.elems[e];
            let p = closest_on_triangle(x, &self.verts[a], &self.verts[b], &self.verts[c]);
            (norm2(&sub(x, &p)), p)
        });
        let [a, b, c] = self.elems[prim];
        Closest {
            dist: d2.sqrt(),
            point,
            prim,
            normal: triangle_normal(&self.verts[a], &self.verts[b], &self.verts[c]),
        }
    }
}

impl BoundaryQueries<2> for Boundary<2> {
    fn segment_hits(&self, p: &P2, q: &P2) -> bool {
        let d = sub(q, p);
        self.any_on_segment(p, q, |e| {
            let [a, b] = self.elems[e];
            segment_segment(p, &d, &self.verts[a], &self.verts[b])
        })
    }

    fn closest(&self, x: &P2) -> Closest<2> {
        let (d2, point, prim) = self.nearest(x, |e| {
            let [a, b] = self.elems[e];
            let p = closest_on_segment(x, &self.verts[a], &self.verts[b]);
            (norm2(&sub(x, &p)), p)
        });
        let [a, b] = self.elems[prim];
        Closest {
            dist: d2.sqrt(),
            point,
            prim,
            normal: segment_normal(&self.verts[a], &self.verts[b]),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::array;

    /// Unit cube [0,1]^3 as 12 outward triangles.
    pub(crate) fn cube() -> (ndarray::Array2<f64>, ndarray::Array2<usize>) {
        let v = array![
            [0., 0., 0.],
            [1., 0., 0.],
            [1., 1., 0.],
            [0., 1., 0.],
            [0., 0., 1.],
            [1., 0., 1.],
            [1., 1., 1.],
            [0., 1., 1.]
        ];
        let f = array![
            [0, 2, 1],
            [0, 3, 2],
            [4, 5, 6],
            [4, 6, 7],
            [0, 1, 5],
            [0, 5, 4],
            [1, 2, 6],
            [1, 6, 5],
            [2, 3, 7],
            [2, 7, 6],
            [3, 0, 4],
            [3, 4, 7]
        ];
        (v, f)
    }

    #[test]
    fn cube_segments_and_closest() {
        let (v, f) = cube();
        let b = Boundary::<3>::new(v.view(), f.view()).unwrap();
        assert!(!b.segment_hits(&[0.2, 0.3, 0.4], &[0.8, 0.7, 0.6]));
        assert!(b.segment_hits(&[0.5, 0.5, 0.5], &[0.5, 0.5, 1.5]));
        assert!(b.segment_hits(&[-1.0, 0.3, 0.4], &[2.0, 0.3, 0.4]));
        assert!(!b.segment_hits(&[-1.0, 0.3, 0.4], &[-0.5, 0.3, 0.4]));
        let c = b.closest(&[0.5, 0.5, 1.25]);
        assert!((c.dist - 0.25).abs() < 1e-15);
        assert_eq!(c.normal, [0.0, 0.0, 1.0]);
        assert!(c.prim == 2 || c.prim == 3);
        let c = b.closest(&[2.0, 2.0, 2.0]);
        assert!((c.dist - 3f64.sqrt()).abs() < 1e-15);
        assert_eq!(c.point, [1.0, 1.0, 1.0]);
    }

    #[test]
    fn square_2d() {
        let v = array![[0., 0.], [1., 0.], [1., 1.], [0., 1.]];
        let f = array![[0, 1], [1, 2], [2, 3], [3, 0]];
        let b = Boundary::<2>::new(v.view(), f.view()).unwrap();
        assert!(!b.segment_hits(&[0.1, 0.1], &[0.9, 0.8]));
        assert!(b.segment_hits(&[0.5, 0.5], &[1.5, 0.5]));
        let c = b.closest(&[0.5, -0.5]);
        assert!((c.dist - 0.5).abs() < 1e-15);
        assert_eq!(c.prim, 0);
        assert_eq!(c.normal, [0.0, -1.0]);
    }

    #[test]
    fn many_primitives_match_brute_force() {
        // A strip of 200 thin triangles: tree answers equal the linear scan.
        let n = 200;
        let mut v = ndarray::Array2::<f64>::zeros((2 * n + 2, 3));
        let mut f = ndarray::Array2::<usize>::zeros((2 * n, 3));
        for i in 0..=n {
            let x = i as f64 / n as f64;
            v.row_mut(2 * i)
                .assign(&array![x, 0.0, (7.0 * x).sin() * 0.1]);
            v.row_mut(2 * i + 1)
                .assign(&array![x, 1.0, (5.0 * x).cos() * 0.1]);
        }
        for i in 0..n {
            f.row_mut(2 * i)
                .assign(&array![2 * i, 2 * i + 2, 2 * i + 1]);
            f.row_mut(2 * i + 1)
                .assign(&array![2 * i + 1, 2 * i + 2, 2 * i + 3]);
        }
        let b = Boundary::<3>::new(v.view(), f.view()).unwrap();
        let mut s = 1u64;
        let mut rnd = || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (s >> 11) as f64 / (1u64 << 53) as f64
        };
        for _ in 0..300 {
            let p = [rnd() * 1.2 - 0.1, rnd() * 1.2 - 0.1, rnd() - 0.5];
            let q = [rnd() * 1.2 - 0.1, rnd() * 1.2 - 0.1, rnd() - 0.5];
            let d = sub(&q, &p);
            let brute = b
                .elems
                .iter()
                .any(|&[i, j, k]| segment_triangle(&p, &d, &b.verts[i], &b.verts[j], &b.verts[k]));
            assert_eq!(b.segment_hits(&p, &q), brute);
            let best = b
                .elems
                .iter()
                .map(|&[i, j, k]| {
                    norm2(&sub(
                        &p,
                        &closest_on_triangle(&p, &b.verts[i], &b.verts[j], &b.verts[k]),
                    ))
                })
                .fold(f64::INFINITY, f64::min);
            assert_eq!(b.closest(&p).dist, best.sqrt());
        }
    }
}
