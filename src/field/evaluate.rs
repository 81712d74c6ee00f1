//! Evaluation of the optimised field (eq. 7 with eqs. 2, 9, 14) at arbitrary points and at the
//! input's vertices (App. A, "Evaluation on the boundary").
//!
//! [`GeometricField::evaluate`]: Q #Q by D (input units) -> W #Q by K and a status per row:
//!   0 the kernel of eq. 4 saw some point,  1 no point was visible: plain Gaussian kernel,
//!   2 no point within the kernel support at all: the nearest point's value.
//! [`GeometricField::vertex_weights`]: V #V by D, boundary elements (for vertex normals) and
//! adjacency elements -> W #V by K with status 0 (direct), 3 (flood-filled), 1 or 2 as above.
//! Rays start at `v - 1e-5 n_v` (nudged inward along the area-weighted vertex normal); vertices
//! outside (`wn < wn_l` at the nudged point) or occluded from every point take the average of
//! their already-valid neighbours, sweep after sweep; what remains uses the kernel without
//! visibility.

use ndarray::{Array2, ArrayView2};
use rayon::prelude::*;

use super::kernel::FieldValue;
use super::optimize::GeometricField;
use super::{cross, norm2, sub, Boundary, BoundaryQueries};
use crate::error::SkinResult;
use crate::progress::{Event, Progress};

/// Rows per block between two progress reports of an evaluation.
const EVAL_BLOCK: usize = 4096;

/// Inward nudge of the ray origins of vertex evaluations (unit-box units, App. A).
pub const NUDGE: f64 = 1e-5;

impl<const D: usize> GeometricField<D>
where
    Boundary<D>: BoundaryQueries<D>,
{
    /// Weights at `z` (unit box) with rays from `o`; false if no point is visible.
    pub fn weights_at(
        &self,
        z: &[f64; D],
        o: &[f64; D],
        visibility: bool,
        out: &mut [f64],
    ) -> bool {
        let mut val = FieldValue::default();
        if !self.alpha_hat(z, o, visibility, &mut val) {
            return false;
        }
        let mut a = val.alpha.clone();
        if self.opts.neumann {
            if let Some(b) = &self.domain.boundary {
                let eps = self.opts.eps_sigma * self.sigma0;
                let c = b.closest(z);
                let mut vp = FieldValue::default();
                if c.dist < eps && self.alpha_hat(&c.point, o, visibility, &mut vp) {
                    let w = super::mollifier::bump(c.dist, eps);
                    for (x, y) in a.iter_mut().zip(&vp.alpha) {
                        *x = (1.0 - w) * *x + w * y;
                    }
                }
            }
        }
        self.finish(z, &a, out);
        true
    }

    /// `out = e~(z) + (1 - sum e~) a` (eq. 7).
    fn finish(&self, z: &[f64; D], a: &[f64], out: &mut [f64]) {
        let mut e = vec![0.0; self.k()];
        let mut near = Vec::new();
        let se = self.cons.eval(z, &mut e, &mut near);
        for kk in 0..self.k() {
            out[kk] = e[kk] + (1.0 - se) * a[kk];
        }
    }

    /// Value from the nearest point of the field (last resort).
    fn nearest_weights(&self, z: &[f64; D], out: &mut [f64]) {
        let i = self.points.grid.knn(z, 1, None)[0].1;
        let k = self.k();
        let row = &self.f[i * k..(i + 1) * k];
        let sp: Vec<f64> = row.iter().map(|&t| super::kernel::softplus(t)).collect();
        let s: f64 = sp.iter().sum();
        let a: Vec<f64> = sp.iter().map(|x| x / s).collect();
        self.finish(z, &a, out);
    }

    /// One row with the fallbacks of the module doc, returning its status.
    fn row_with_fallback(&self, z: &[f64; D], o: &[f64; D], out: &mut [f64]) -> u8 {
        if self.weights_at(z, o, self.opts.visibility, out) {
            0
        } else if self.weights_at(z, z, false, out) {
            1
        } else {
            self.nearest_weights(z, out);
            2
        }
    }

    /// Weights at the rows of `q` (input units); see the module doc. Blocks of rows report to
    /// `progress` in between (Ctrl-C stops the evaluation there).
    pub fn evaluate(
        &self,
        q: ArrayView2<f64>,
        progress: &mut dyn Progress,
    ) -> SkinResult<(Array2<f64>, Vec<u8>)> {
        let k = self.k();
        let n = q.nrows();
        let mut rows: Vec<(Vec<f64>, u8)> = Vec::with_capacity(n);
        for start in (0..n).step_by(EVAL_BLOCK) {
            let end = (start + EVAL_BLOCK).min(n);
            rows.par_extend((start..end).into_par_iter().map(|i| {
                let z = self.to_unit(&super::row(&q, i));
                let mut out = vec![0.0; k];
                let s = self.row_with_fallback(&z, &z, &mut out);
                (out, s)
            }));
            progress.report(Event {
                stage: "evaluate",
                iteration: end,
                value: f64::NAN,
            })?;
        }
        Ok(collect_rows(rows, k))
    }

    /// Weights at the vertices `v` (input units); `normal_elems` (#E by D, may be empty) give
    /// the vertex normals, `adj` (#A by any) the neighbours for the flood fill.
    pub fn vertex_weights(
        &self,
        v: ArrayView2<f64>,
        normal_elems: ArrayView2<usize>,
        adj: ArrayView2<usize>,
    ) -> (Array2<f64>, Vec<u8>) {
        let k = self.k();
        let n = v.nrows();
        let vu: Vec<[f64; D]> = (0..n).map(|i| self.to_unit(&super::row(&v, i))).collect();
        let normals = vertex_normals(&vu, normal_elems);
        let first: Vec<(Vec<f64>, bool)> = (0..n)
            .into_par_iter()
            .map(|i| {
                let z = vu[i];
                let o: [f64; D] = std::array::from_fn(|c| z[c] - NUDGE * normals[i][c]);
                let mut out = vec![0.0; k];
                let inside =
                    self.domain.winding.is_none() || self.domain.wn(&o) >= self.domain.wn_l;
                let ok = inside && self.weights_at(&z, &o, self.opts.visibility, &mut out);
                (out, ok)
            })
            .collect();
        let mut w: Vec<Vec<f64>> = first.iter().map(|r| r.0.clone()).collect();
        let mut status: Vec<u8> = first.iter().map(|r| if r.1 { 0 } else { 255 }).collect();
        flood_fill(&mut w, &mut status, &neighbours(n, adj), k);
        // Flood-filled rows get the mollifier of their own position (eq. 7): handles and paint
        // stay exact there too, and rows still sum to 1.
        for i in 0..n {
            if status[i] == 3 {
                let a = w[i].clone();
                self.finish(&vu[i], &a, &mut w[i]);
            }
        }
        for i in 0..n {
            if status[i] == 255 {
                let z = vu[i];
                status[i] = if self.weights_at(&z, &z, false, &mut w[i]) {
                    1
                } else {
                    self.nearest_weights(&z, &mut w[i]);
                    2
                };
            }
        }
        let rows = w.into_iter().zip(status).collect();
        collect_rows(rows, k)
    }
}

fn collect_rows(rows: Vec<(Vec<f64>, u8)>, k: usize) -> (Array2<f64>, Vec<u8>) {
    let n = rows.len();
    let mut w = Array2::<f64>::zeros((n, k));
    let mut s = Vec::with_capacity(n);
    for (i, (r, st)) in rows.into_iter().enumerate() {
        for kk in 0..k {
            w[[i, kk]] = r[kk];
        }
        s.push(st);
    }
    (w, s)
}

/// Vertex adjacency from element rows (every pair in a row), sorted and deduplicated.
fn neighbours(n: usize, adj: ArrayView2<usize>) -> Vec<Vec<usize>> {
    let mut nb = vec![Vec::new(); n];
    for r in adj.rows() {
        for a in 0..r.len() {
            for b in 0..r.len() {
                if a != b && r[a] < n && r[b] < n && r[a] != r[b] {
                    nb[r[a]].push(r[b]);
                }
            }
        }
    }
    for l in nb.iter_mut() {
        l.sort_unstable();
        l.dedup();
    }
    nb
}

/// Jacobi sweeps: every unset (`255`) vertex with set neighbours takes their average (status 3).
fn flood_fill(w: &mut [Vec<f64>], status: &mut [u8], nb: &[Vec<usize>], k: usize) {
    loop {
        let mut updates = Vec::new();
        for i in 0..w.len() {
            if status[i] != 255 {
                continue;
            }
            let set: Vec<usize> = nb[i]
                .iter()
                .copied()
                .filter(|&j| status[j] != 255)
                .collect();
            if set.is_empty() {
                continue;
            }
            let mut avg = vec![0.0; k];
            for &j in &set {
                for kk in 0..k {
                    avg[kk] += w[j][kk] / set.len() as f64;
                }
            }
            updates.push((i, avg));
        }
        if updates.is_empty() {
            return;
        }
        for (i, a) in updates {
            w[i] = a;
            status[i] = 3;
        }
    }
}

/// Area-weighted unit vertex normals from triangles (3D) or segments (2D); zero where none.
fn vertex_normals<const D: usize>(v: &[[f64; D]], elems: ArrayView2<usize>) -> Vec<[f64; D]> {
    let mut nrm = vec![[0.0; D]; v.len()];
    if elems.ncols() == D {
        for r in elems.rows() {
            if r.iter().any(|&i| i >= v.len()) {
                continue;
            }
            let a: [f64; D] = if D == 3 {
                let p = |i: usize| -> [f64; 3] { std::array::from_fn(|c| v[r[i]][c % D]) };
                let c = cross(&sub(&p(1), &p(0)), &sub(&p(2), &p(0)));
                std::array::from_fn(|q| c[q])
            } else {
                let e = sub(&v[r[1]], &v[r[0]]);
                std::array::from_fn(|q| if q == 0 { e[1 % D] } else { -e[0] })
            };
            for &i in r.iter() {
                for c in 0..D {
                    nrm[i][c] += a[c];
                }
            }
        }
    }
    for x in nrm.iter_mut() {
        let l = norm2(x).sqrt();
        if l > 0.0 {
            for c in x.iter_mut() {
                *c /= l;
            }
        }
    }
    nrm
}
