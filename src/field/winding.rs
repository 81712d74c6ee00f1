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
//!
//! Layout: [`exact`] holds the exact per-element angles and the exact 2D sum without a tree;
//! [`expansion`] the per-node far-field moments, their bottom-up merge and their evaluation;
//! this module the tree walk ([`FastWinding`]) that picks one or the other per node.

mod exact;
mod expansion;
#[cfg(test)]
mod tests;

use ndarray::ArrayView2;
use rayon::prelude::*;

use super::boundary::{check_queries, Boundary};
use super::{norm2, par_map_coherent, sub};
use crate::error::SkinResult;
use crate::invalid;
use exact::Element;
pub use exact::{segment_angle, solid_angle, winding_number_2d};
use expansion::{expansion, merge, Expansion};

const FOUR_PI: f64 = 4.0 * std::f64::consts::PI;
const TWO_PI: f64 = 2.0 * std::f64::consts::PI;
/// Elements per leaf of the winding-number tree (exact angles below that).
const WINDING_LEAF: usize = 8;
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
