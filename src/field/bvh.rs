//! Bounding volume hierarchy over boundary primitives and the two queries the geometric-field
//! method needs from the boundary.
//!
//! Inputs (to [`Boundary::new`]):
//!   v  #V by D vertex positions, D = 3 (triangles) or D = 2 (segments)
//!   f  #F by D primitives: triangles `[a, b, c]` in 3D, segments `[a, b]` in 2D (rows index v)
//! Queries ([`BoundaryQueries`]):
//!   segment_hits(p, q) -> bool          does the open segment p -> q cross a primitive? (eq. 4)
//!   closest(x)         -> [`Closest`]   distance, closest point, primitive id and unit normal
//!   segment_hits_batch(P, Q) -> #Q bools,  closest_batch(X) -> #X results (rayon-parallel)
//!
//! The tree is a flat array of nodes in depth-first order (left child = node + 1), built with a
//! binned surface-area heuristic: boundary meshes are very non-uniform (long thin triangles,
//! dense details next to big flat faces) and SAH keeps both segment and nearest queries close to
//! logarithmic on them, where a median split wastes work on nearly empty boxes. Every subtree
//! owns a contiguous range of the primitive permutation, and children follow their parent in
//! the array, so per-node aggregates (the winding-number expansions of [`super::winding`]) are
//! computed per leaf in parallel and merged bottom-up. Large subtrees are built on two threads.
//!
//! Degenerate primitives (zero area or length, repeated vertices) are allowed, as soups have
//! them: they are never hit, and closest-point queries still return a point on them (their
//! normal is zero).

use ndarray::{ArrayView2, Axis};
use rayon::prelude::*;

use super::{add, coherent_order, cross, cross2, dot, norm2, row, scale, scatter, sub, P2, P3};
use crate::error::SkinResult;
use crate::invalid;

/// Axis-aligned box.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Aabb<const D: usize> {
    pub lo: [f64; D],
    pub hi: [f64; D],
}

impl<const D: usize> Aabb<D> {
    pub fn empty() -> Self {
        Aabb {
            lo: [f64::INFINITY; D],
            hi: [f64::NEG_INFINITY; D],
        }
    }

    pub fn grow(&mut self, p: &[f64; D]) {
        for (k, &x) in p.iter().enumerate() {
            self.lo[k] = self.lo[k].min(x);
            self.hi[k] = self.hi[k].max(x);
        }
    }

    pub fn merge(&mut self, b: &Aabb<D>) {
        for k in 0..D {
            self.lo[k] = self.lo[k].min(b.lo[k]);
            self.hi[k] = self.hi[k].max(b.hi[k]);
        }
    }

    pub fn center(&self) -> [f64; D] {
        std::array::from_fn(|k| 0.5 * (self.lo[k] + self.hi[k]))
    }

    /// Half the surface area in 3D, the half perimeter in 2D: the SAH's probability measure.
    fn half_area(&self) -> f64 {
        if self.lo[0] > self.hi[0] {
            return 0.0;
        }
        let e: [f64; D] = std::array::from_fn(|k| self.hi[k] - self.lo[k]);
        if D == 3 {
            e[0] * e[1] + e[1] * e[2] + e[2] * e[0]
        } else {
            e.iter().sum()
        }
    }

    /// Squared distance from `p` to the box (0 inside).
    #[inline]
    pub fn dist2(&self, p: &[f64; D]) -> f64 {
        let mut s = 0.0;
        for (k, &x) in p.iter().enumerate() {
            let d = (self.lo[k] - x).max(0.0).max(x - self.hi[k]);
            s += d * d;
        }
        s
    }

    /// Does the closed segment `p + t d`, `t` in `[0, 1]`, touch the box? (slab test)
    #[inline]
    fn hits_segment(&self, p: &[f64; D], d: &[f64; D], inv: &[f64; D]) -> bool {
        let (mut t0, mut t1) = (0.0f64, 1.0f64);
        for k in 0..D {
            if d[k] == 0.0 {
                // Parallel to the slab: inside it or never.
                if p[k] < self.lo[k] || p[k] > self.hi[k] {
                    return false;
                }
                continue;
            }
            let a = (self.lo[k] - p[k]) * inv[k];
            let b = (self.hi[k] - p[k]) * inv[k];
            let (a, b) = if a < b { (a, b) } else { (b, a) };
            t0 = t0.max(a);
            t1 = t1.min(b);
            if t0 > t1 {
                return false;
            }
        }
        true
    }
}

/// One tree node. Leaves have `right == 0` (node 0 is the root, never a right child).
#[derive(Clone, Copy, Debug)]
pub struct Node<const D: usize> {
    pub bbox: Aabb<D>,
    /// The subtree's primitives are `order[start..start + count]`.
    pub start: u32,
    pub count: u32,
    /// Index of the right child (the left child is the next node).
    pub right: u32,
}

impl<const D: usize> Node<D> {
    #[inline]
    pub fn is_leaf(&self) -> bool {
        self.right == 0
    }
}

/// Flat BVH over primitive bounding boxes.
#[derive(Clone, Debug)]
pub struct Bvh<const D: usize> {
    pub nodes: Vec<Node<D>>,
    /// Permutation of the primitives; each node owns a contiguous range.
    pub order: Vec<u32>,
}

const BINS: usize = 16;

impl<const D: usize> Bvh<D> {
    /// Builds the tree over the boxes of `boxes.len() >= 1` primitives, at most `leaf_size`
    /// primitives per leaf.
    pub fn build(boxes: &[Aabb<D>], leaf_size: usize) -> Self {
        let n = boxes.len();
        let centers: Vec<[f64; D]> = boxes.par_iter().map(|b| b.center()).collect();
        let mut order: Vec<u32> = (0..n as u32).collect();
        let b = Builder {
            boxes,
            centers: &centers,
            leaf_size: leaf_size.max(1),
        };
        let nodes = b.subtree(&mut order, 0);
        Bvh { nodes, order }
    }
}

struct Builder<'a, const D: usize> {
    boxes: &'a [Aabb<D>],
    centers: &'a [[f64; D]],
    leaf_size: usize,
}

/// Subtrees larger than this are built on two threads (`rayon::join`); below it the cost of
/// concatenating node arrays would outweigh the gain.
const PAR_BUILD: usize = 8192;

impl<const D: usize> Builder<'_, D> {
    /// Nodes of the subtree over `order` (which starts at `start` in the full permutation), in
    /// depth-first order with child indices relative to the subtree's root.
    fn subtree(&self, order: &mut [u32], start: usize) -> Vec<Node<D>> {
        let mut nodes = Vec::with_capacity(2 * order.len() / self.leaf_size + 1);
        self.split(order, start, &mut nodes);
        nodes
    }

    /// Appends the subtree over `order` to `nodes`.
    fn split(&self, order: &mut [u32], start: usize, nodes: &mut Vec<Node<D>>) {
        let mut bbox = Aabb::empty();
        let mut cbox = Aabb::empty();
        for &i in order.iter() {
            bbox.merge(&self.boxes[i as usize]);
            cbox.grow(&self.centers[i as usize]);
        }
        let id = nodes.len();
        let count = order.len();
        nodes.push(Node {
            bbox,
            start: start as u32,
            count: count as u32,
            right: 0,
        });
        if count <= self.leaf_size {
            return;
        }
        // Split axis: longest extent of the centroids.
        let mut axis = 0;
        for k in 1..D {
            if cbox.hi[k] - cbox.lo[k] > cbox.hi[axis] - cbox.lo[axis] {
                axis = k;
            }
        }
        let (lo, ext) = (cbox.lo[axis], cbox.hi[axis] - cbox.lo[axis]);
        let mid = if ext > 0.0 {
            self.sah_partition(order, axis, lo, ext)
        } else {
            None
        };
        // Coincident centroids or no useful plane: split the list in half (keeps depth bounded).
        let mid = mid.unwrap_or(count / 2);
        let (left, right) = order.split_at_mut(mid);
        if count > PAR_BUILD {
            let (l, r) = rayon::join(
                || self.subtree(left, start),
                || self.subtree(right, start + mid),
            );
            let shift = |mut n: Node<D>, by: usize| {
                if !n.is_leaf() {
                    n.right += by as u32;
                }
                n
            };
            let base = id + 1;
            nodes[id].right = (base + l.len()) as u32;
            let nl = l.len();
            nodes.extend(l.into_iter().map(|n| shift(n, base)));
            nodes.extend(r.into_iter().map(|n| shift(n, base + nl)));
        } else {
            self.split(left, start, nodes);
            nodes[id].right = nodes.len() as u32;
            self.split(right, start + mid, nodes);
        }
    }

    /// Binned SAH along `axis`; partitions `order` and returns the split index.
    fn sah_partition(&self, order: &mut [u32], axis: usize, lo: f64, ext: f64) -> Option<usize> {
        let scale = BINS as f64 / ext;
        let bin_of = |c: &[f64; D]| (((c[axis] - lo) * scale) as usize).min(BINS - 1);
        let mut bin_box = [Aabb::<D>::empty(); BINS];
        let mut bin_n = [0usize; BINS];
        for &i in order.iter() {
            let b = bin_of(&self.centers[i as usize]);
            bin_box[b].merge(&self.boxes[i as usize]);
            bin_n[b] += 1;
        }
        // Sweep from the right for suffix areas, then from the left for the best plane.
        let mut right_area = [0.0; BINS];
        let mut acc = Aabb::empty();
        for b in (1..BINS).rev() {
            acc.merge(&bin_box[b]);
            right_area[b] = acc.half_area();
        }
        let mut right_n = [0usize; BINS];
        let mut s = 0;
        for b in (1..BINS).rev() {
            s += bin_n[b];
            right_n[b] = s;
        }
        let (mut best, mut best_cost) = (0, f64::INFINITY);
        let mut left = Aabb::empty();
        let mut left_n = 0;
        for b in 0..BINS - 1 {
            left.merge(&bin_box[b]);
            left_n += bin_n[b];
            if left_n == 0 || right_n[b + 1] == 0 {
                continue;
            }
            let cost = left_n as f64 * left.half_area() + right_n[b + 1] as f64 * right_area[b + 1];
            if cost < best_cost {
                best_cost = cost;
                best = b;
            }
        }
        if !best_cost.is_finite() {
            return None;
        }
        // In-place partition: bins 0..=best go left.
        let slice = order;
        let mut i = 0;
        let mut j = slice.len();
        while i < j {
            if bin_of(&self.centers[slice[i] as usize]) <= best {
                i += 1;
            } else {
                j -= 1;
                slice.swap(i, j);
            }
        }
        Some(i)
    }
}

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

/// Möller–Trumbore: does `p + t d`, `0 < t < 1`, cross triangle `abc` (edges included)?
/// Coplanar segments (zero determinant) never hit: they cannot separate the two sides.
#[inline]
pub fn segment_triangle(p: &P3, d: &P3, a: &P3, b: &P3, c: &P3) -> bool {
    let e1 = sub(b, a);
    let e2 = sub(c, a);
    let h = cross(d, &e2);
    let det = dot(&e1, &h);
    if det == 0.0 {
        return false;
    }
    let inv = 1.0 / det;
    let s = sub(p, a);
    let u = inv * dot(&s, &h);
    if !(0.0..=1.0).contains(&u) {
        return false;
    }
    let qv = cross(&s, &e1);
    let v = inv * dot(d, &qv);
    if v < 0.0 || u + v > 1.0 {
        return false;
    }
    let t = inv * dot(&e2, &qv);
    t > 0.0 && t < 1.0
}

/// Does `p + t d`, `0 < t < 1`, cross segment `ab` (endpoints included)? Parallel: never.
#[inline]
pub fn segment_segment(p: &P2, d: &P2, a: &P2, b: &P2) -> bool {
    let e = sub(b, a);
    let den = cross2(d, &e);
    if den == 0.0 {
        return false;
    }
    let w = sub(a, p);
    let t = cross2(&w, &e) / den;
    let s = cross2(&w, d) / den;
    t > 0.0 && t < 1.0 && (0.0..=1.0).contains(&s)
}

/// Closest point on triangle `abc` to `x` (Ericson, Real-Time Collision Detection 5.1.5): the
/// Voronoi regions of the vertices, edges and face are tested in turn, no square roots, and
/// degenerate triangles fall through to an edge or vertex.
pub fn closest_on_triangle(x: &P3, a: &P3, b: &P3, c: &P3) -> P3 {
    let ab = sub(b, a);
    let ac = sub(c, a);
    let ap = sub(x, a);
    let d1 = dot(&ab, &ap);
    let d2 = dot(&ac, &ap);
    if d1 <= 0.0 && d2 <= 0.0 {
        return *a;
    }
    let bp = sub(x, b);
    let d3 = dot(&ab, &bp);
    let d4 = dot(&ac, &bp);
    if d3 >= 0.0 && d4 <= d3 {
        return *b;
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let v = d1 / (d1 - d3);
        return add(a, &scale(&ab, v));
    }
    let cp = sub(x, c);
    let d5 = dot(&ab, &cp);
    let d6 = dot(&ac, &cp);
    if d6 >= 0.0 && d5 <= d6 {
        return *c;
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let w = d2 / (d2 - d6);
        return add(a, &scale(&ac, w));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return add(b, &scale(&sub(c, b), w));
    }
    let den = va + vb + vc;
    if den == 0.0 || !den.is_finite() {
        // Degenerate (collinear) triangle that slipped through: best of the three edges.
        return [(a, b), (b, c), (c, a)]
            .iter()
            .map(|(s, t)| closest_on_segment(x, s, t))
            .min_by(|p, q| norm2(&sub(x, p)).total_cmp(&norm2(&sub(x, q))))
            .unwrap_or(*a);
    }
    let v = vb / den;
    let w = vc / den;
    add(&add(a, &scale(&ab, v)), &scale(&ac, w))
}

/// Closest point on segment `ab` to `x` (a point for `a == b`).
pub fn closest_on_segment<const D: usize>(x: &[f64; D], a: &[f64; D], b: &[f64; D]) -> [f64; D] {
    let e = sub(b, a);
    let l2 = norm2(&e);
    if l2 == 0.0 {
        return *a;
    }
    let t = (dot(&sub(x, a), &e) / l2).clamp(0.0, 1.0);
    add(a, &scale(&e, t))
}

/// Unit normal of a triangle, zero if degenerate.
pub fn triangle_normal(a: &P3, b: &P3, c: &P3) -> P3 {
    let n = cross(&sub(b, a), &sub(c, a));
    // Divide by the largest entry first: the squared length neither overflows nor underflows.
    let big = n.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    if !(big > 0.0 && big.is_finite()) {
        return [0.0; 3];
    }
    let n = scale(&n, 1.0 / big);
    let l = norm2(&n).sqrt();
    if l > 0.0 {
        scale(&n, 1.0 / l)
    } else {
        [0.0; 3]
    }
}

/// Unit normal of segment `ab`: its direction turned clockwise (outward for a CCW polygon).
pub fn segment_normal(a: &P2, b: &P2) -> P2 {
    let e = sub(b, a);
    let l = norm2(&e).sqrt();
    if l > 0.0 {
        [e[1] / l, -e[0] / l]
    } else {
        [0.0; 2]
    }
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
