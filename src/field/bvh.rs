//! Bounding volume hierarchy over the boundary primitives (used by [`super::boundary`] and
//! [`super::winding`]).
//!
//! The tree is a flat array of nodes in depth-first order (left child = node + 1), built with a
//! binned surface-area heuristic: boundary meshes are very non-uniform (long thin triangles,
//! dense details next to big flat faces) and SAH keeps both segment and nearest queries close to
//! logarithmic on them, where a median split wastes work on nearly empty boxes. Every subtree
//! owns a contiguous range of the primitive permutation, and children follow their parent in
//! the array, so per-node aggregates (the winding-number expansions of [`super::winding`]) are
//! computed per leaf in parallel and merged bottom-up. Large subtrees are built on two threads.

use rayon::prelude::*;

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
    pub(crate) fn hits_segment(&self, p: &[f64; D], d: &[f64; D], inv: &[f64; D]) -> bool {
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
