//! The per-vertex basis `B_v` of the reduction objective: what a vertex's handles do over the
//! example poses (see [`super::problem`]).

use ndarray::{Array2, ArrayView2};
use rayon::prelude::*;

use crate::error::SkinResult;
use crate::invalid;

use super::deform::{deform, point, Poses};

/// What a vertex's handles do over the example poses (the columns of `B_v`).
pub(crate) enum Basis {
    /// Control points: column `t` of `B_v` is row `S_t` of `cq (m, q)` (every pose stacked),
    /// `gram = cq cq^T`.
    Cage { cq: Array2<f64>, gram: Array2<f64> },
    /// Bones: column `t` of `B_v` stacks `M_{S_t}^j v` over the poses `j`. `B_v` and its Gram
    /// matrix depend on the vertex; both are precomputed (`b (n, k, q)`, `gram (n, k, k)`).
    Bones {
        b: Vec<f64>,
        gram: Vec<f64>,
        q: usize,
    },
    /// Smooth method: `x_v` is the weight row itself, `B_v` scatters into the influence set.
    Select { m: usize },
}

impl Basis {
    /// Precomputes the skeletal basis `B_v` (columns `M_{S_t}^j v`) and its Gram matrices.
    pub(crate) fn bones(poses: &Poses, v: ArrayView2<f64>, sets: &Array2<usize>) -> Self {
        let (n, k) = sets.dim();
        let d = v.ncols();
        let q = poses.count() * d;
        let mut b = vec![0.0; n * k * q];
        let mut gram = vec![0.0; n * k * k];
        b.par_chunks_mut(k * q)
            .zip(gram.par_chunks_mut(k * k))
            .enumerate()
            .for_each(|(vi, (bv, gv))| {
                let x = point(v, vi);
                for (t, &i) in sets.row(vi).iter().enumerate() {
                    for j in 0..poses.count() {
                        let o = t * q + j * d;
                        poses.handle_point(j, i, &x, d, &mut bv[o..o + d]);
                    }
                }
                for a in 0..k {
                    for c in a..k {
                        let s: f64 = bv[a * q..(a + 1) * q]
                            .iter()
                            .zip(&bv[c * q..(c + 1) * q])
                            .map(|(x, y)| x * y)
                            .sum();
                        gv[a * k + c] = s;
                        gv[c * k + a] = s;
                    }
                }
            });
        Basis::Bones { b, gram, q }
    }

    pub(crate) fn q(&self) -> usize {
        match self {
            Basis::Cage { cq, .. } => cq.ncols(),
            Basis::Bones { q, .. } => *q,
            Basis::Select { m } => *m,
        }
    }

    /// Fills `b (k * q)`, column `t` (length q) contiguous. Not used for `Select`.
    pub(super) fn fill(&self, vi: usize, set: &[usize], b: &mut [f64]) {
        let q = self.q();
        match self {
            Basis::Cage { cq, .. } => {
                for (t, &i) in set.iter().enumerate() {
                    for (dst, src) in b[t * q..(t + 1) * q].iter_mut().zip(cq.row(i)) {
                        *dst = *src;
                    }
                }
            }
            Basis::Bones { b: all, .. } => {
                let kq = set.len() * q;
                b[..kq].copy_from_slice(&all[vi * kq..(vi + 1) * kq]);
            }
            Basis::Select { .. } => {}
        }
    }

    /// `G = B_v^T B_v (k x k)`.
    pub(super) fn gram(&self, vi: usize, set: &[usize], g: &mut [f64]) {
        let k = set.len();
        match self {
            Basis::Cage { gram, .. } => {
                for (a, &i) in set.iter().enumerate() {
                    for (c, &j) in set.iter().enumerate() {
                        g[a * k + c] = gram[[i, j]];
                    }
                }
            }
            Basis::Bones { gram, .. } => {
                g[..k * k].copy_from_slice(&gram[vi * k * k..(vi + 1) * k * k]);
            }
            Basis::Select { .. } => {
                g.iter_mut().for_each(|x| *x = 0.0);
                for a in 0..k {
                    g[a * k + a] = 1.0;
                }
            }
        }
    }

    /// `x_v = B_v alpha` into `x (q)`.
    pub(super) fn position(
        &self,
        vi: usize,
        set: &[usize],
        alpha: &[f64],
        b: &mut [f64],
        x: &mut [f64],
    ) {
        let q = self.q();
        x.iter_mut().for_each(|c| *c = 0.0);
        match self {
            Basis::Select { .. } => {
                for (&i, &a) in set.iter().zip(alpha) {
                    x[i] += a;
                }
            }
            Basis::Cage { cq, .. } => {
                let cq = cq.as_slice().expect("cq is standard layout");
                for (&i, &a) in set.iter().zip(alpha) {
                    for (xc, bc) in x.iter_mut().zip(&cq[i * q..(i + 1) * q]) {
                        *xc += a * bc;
                    }
                }
            }
            Basis::Bones { .. } => {
                self.fill(vi, set, b);
                for (t, &a) in alpha.iter().enumerate() {
                    for (xc, bc) in x.iter_mut().zip(&b[t * q..(t + 1) * q]) {
                        *xc += a * bc;
                    }
                }
            }
        }
    }
}

impl Basis {
    /// `out = B_v^T y` for `y (q)` into `out (k)`; `b (k * q)` is scratch.
    pub(super) fn transpose(
        &self,
        vi: usize,
        set: &[usize],
        y: &[f64],
        b: &mut [f64],
        out: &mut [f64],
    ) {
        let q = self.q();
        match self {
            Basis::Select { .. } => {
                for (o, &i) in out.iter_mut().zip(set) {
                    *o = y[i];
                }
            }
            Basis::Cage { cq, .. } => {
                let cq = cq.as_slice().expect("cq is standard layout");
                for (o, &i) in out.iter_mut().zip(set) {
                    *o = cq[i * q..(i + 1) * q]
                        .iter()
                        .zip(y)
                        .map(|(a, c)| a * c)
                        .sum();
                }
            }
            Basis::Bones { .. } => {
                self.fill(vi, set, b);
                for (t, o) in out.iter_mut().enumerate() {
                    *o = b[t * q..(t + 1) * q]
                        .iter()
                        .zip(y)
                        .map(|(a, c)| a * c)
                        .sum();
                }
            }
        }
    }
}

/// The basis of the pose-matching methods and the full-weight deformation `Xbar (n, q)`.
pub(super) fn pose_basis(
    w: ArrayView2<f64>,
    v: Option<ArrayView2<f64>>,
    poses: Poses,
    sets: &Array2<usize>,
) -> SkinResult<(Basis, Array2<f64>)> {
    let (n, m) = w.dim();
    let p = poses.count();
    match poses {
        Poses::ControlPoints(c) => {
            let d = c.shape()[2];
            // cq row i = c_i over all poses; Xbar = W cq.
            let mut cq = Array2::<f64>::zeros((m, p * d));
            for i in 0..m {
                for j in 0..p {
                    for a in 0..d {
                        cq[[i, j * d + a]] = c[[j, i, a]];
                    }
                }
            }
            let gram = cq.dot(&cq.t());
            let target = w.dot(&cq);
            Ok((Basis::Cage { cq, gram }, target))
        }
        Poses::Bones(_) => {
            let v = match v {
                Some(v) => v,
                None => return invalid!("bone_transforms need the rest vertices V"),
            };
            let x = deform(v, &crate::skin::Weights::Dense(w), &poses)?;
            let d = v.ncols();
            // (p, n, d) -> (n, p * d)
            let target = Array2::from_shape_fn((n, p * d), |(vi, c)| x[[c / d, vi, c % d]]);
            Ok((Basis::bones(&poses, v, sets), target))
        }
    }
}
