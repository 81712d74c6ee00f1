//! One reduction problem: the influence sets, the basis `B_v`, the coupling `Q`, the target
//! `Xbar` and the per-vertex equality rows, with what every iteration needs from them (the
//! error `E`, the objective, the local Hessian blocks, feasible starts). The method is described
//! in [`super::solver`].

use ndarray::{Array2, ArrayView2};
use rayon::prelude::*;

use crate::error::{SkinError, SkinResult};

use super::basis::Basis;
use super::coupling::Coupling;
use super::qp::{self, LocalQp, QpFailure, QpWork};

/// Linear precision `sum_t alpha_t c_t = v` for cage weights (smooth method, Sec. 3.1).
pub(crate) struct LinearPrecision<'a> {
    pub rest_points: ArrayView2<'a, f64>,
    /// Rest vertices, in the problem's vertex order.
    pub v: Array2<f64>,
}

/// One reduction problem (see the module comment). Vertices are renumbered class by class
/// (`classes` holds the boundaries), so each colour class is a contiguous block of rows of the
/// weights and of `E` and can be updated in place in parallel.
pub(crate) struct Problem<'a> {
    pub sets: Array2<usize>,
    pub basis: Basis,
    pub coupling: Coupling,
    /// `Xbar (n, q)`.
    pub target: Array2<f64>,
    pub lp: Option<LinearPrecision<'a>>,
    pub nonneg: bool,
    pub classes: Vec<usize>,
    /// Original index of every (renumbered) vertex, for messages.
    pub order: Vec<usize>,
}

/// Per-thread scratch.
pub(super) struct Scratch {
    pub(super) b: Vec<f64>,
    pub(super) r: Vec<f64>,
    pub(super) gram: Vec<f64>,
    pub(super) h: Vec<f64>,
    pub(super) g: Vec<f64>,
    pub(super) e_mat: Vec<f64>,
    pub(super) e_rhs: Vec<f64>,
    pub(super) x: Vec<f64>,
    pub(super) lambda: Vec<f64>,
    pub(super) mu: Vec<f64>,
    pub(super) work: QpWork,
}

impl Scratch {
    pub(super) fn new(k: usize, q: usize, r: usize) -> Self {
        Scratch {
            b: vec![0.0; k * q],
            r: vec![0.0; q],
            gram: vec![0.0; k * k],
            h: vec![0.0; k * k],
            g: vec![0.0; k],
            e_mat: vec![0.0; r * k],
            e_rhs: vec![0.0; r],
            x: vec![0.0; k],
            lambda: vec![0.0; r],
            mu: vec![0.0; k],
            work: QpWork::default(),
        }
    }
}

impl Scratch {
    /// Solves the local QP held in `h, g, e_mat, e_rhs` from the start `x0` into `x`.
    pub(super) fn solve_qp(&mut self, x0: &[f64], nonneg: bool) -> Result<qp::QpStatus, QpFailure> {
        self.x.copy_from_slice(x0);
        let qp = LocalQp {
            h: &self.h,
            g: &self.g,
            e_mat: &self.e_mat,
            e_rhs: &self.e_rhs,
            nonneg,
        };
        qp::solve(
            &qp,
            &mut self.x,
            &mut self.lambda,
            &mut self.mu,
            &mut self.work,
        )
    }
}

pub(super) fn qp_error(v: usize, e: QpFailure) -> SkinError {
    match e {
        QpFailure::Infeasible => SkinError::InvalidInput(format!(
            "vertex {v} lies outside the convex hull of its k largest-weight control points: \
             no non-negative weights on its influence set have linear precision; increase k or \
             pass nonnegative=False"
        )),
        QpFailure::DependentConstraints => SkinError::InvalidInput(format!(
            "the k largest-weight control points of vertex {v} are affinely dependent, so the \
             linear precision constraints are degenerate; increase k"
        )),
        QpFailure::NotPositiveDefinite => SkinError::Numerical(format!(
            "the local quadratic of vertex {v} is not positive definite"
        )),
    }
}

impl Problem<'_> {
    pub(super) fn k(&self) -> usize {
        self.sets.ncols()
    }

    pub(super) fn rows(&self) -> usize {
        1 + self.lp.as_ref().map_or(0, |lp| lp.v.ncols())
    }

    /// Equality rows `E alpha = e`: sum to one, then (cages, smooth) linear precision written
    /// relative to the vertex, `sum_t alpha_t (c_t - v) = 0`, which is better scaled.
    pub(super) fn equality(&self, vi: usize, e_mat: &mut [f64], e_rhs: &mut [f64]) {
        let k = self.k();
        let set = self.sets.row(vi);
        e_mat[..k].iter_mut().for_each(|x| *x = 1.0);
        e_rhs[0] = 1.0;
        if let Some(lp) = &self.lp {
            for c in 0..lp.v.ncols() {
                for (t, &i) in set.iter().enumerate() {
                    e_mat[(c + 1) * k + t] = lp.rest_points[[i, c]] - lp.v[[vi, c]];
                }
                e_rhs[c + 1] = 0.0;
            }
        }
    }

    /// For every coupling entry `(v, u)` (in storage order) and slot `t` of `v`: the slot of `u`
    /// holding the same handle, or `u8::MAX` (smooth method; `k <= 254`).
    pub(super) fn shared_slots(&self) -> Vec<u8> {
        let k = self.k();
        let c = &self.coupling;
        let mut out = vec![u8::MAX; c.rows.len() * k];
        let n = self.sets.nrows();
        let ptr = &c.ptr;
        let chunks: Vec<(usize, &mut [u8])> = {
            let mut v = Vec::with_capacity(n);
            let mut rest: &mut [u8] = &mut out;
            for col in 0..n {
                let len = (ptr[col + 1] - ptr[col]) * k;
                let (head, tail) = rest.split_at_mut(len);
                v.push((col, head));
                rest = tail;
            }
            v
        };
        chunks.into_par_iter().for_each(|(v, o)| {
            let sv = self.sets.row(v);
            for (x, pos) in c.col(v).enumerate() {
                let su = self.sets.row(c.rows[pos]);
                for (t, &i) in sv.iter().enumerate() {
                    if let Some(sl) = su.iter().position(|&j| j == i) {
                        o[x * k + t] = sl as u8;
                    }
                }
            }
        });
        out
    }

    /// `c = B_v^T B_u (k x k)`, row-major.
    pub(crate) fn cross_gram(&self, v: usize, u: usize, c: &mut [f64]) {
        let k = self.k();
        let (sv, su) = (self.sets.row(v), self.sets.row(u));
        match &self.basis {
            Basis::Cage { gram, .. } => {
                let m = gram.ncols();
                let gram = gram.as_slice().expect("gram is standard layout");
                for (t, &i) in sv.iter().enumerate() {
                    let row = &gram[i * m..(i + 1) * m];
                    for (s, &j) in su.iter().enumerate() {
                        c[t * k + s] = row[j];
                    }
                }
            }
            Basis::Select { .. } => {
                for (t, &i) in sv.iter().enumerate() {
                    for (s, &j) in su.iter().enumerate() {
                        c[t * k + s] = (i == j) as u8 as f64;
                    }
                }
            }
            Basis::Bones { b, q, .. } => {
                let q = *q;
                let (bv, bu) = (
                    &b[v * k * q..(v + 1) * k * q],
                    &b[u * k * q..(u + 1) * k * q],
                );
                for t in 0..k {
                    for s in 0..k {
                        c[t * k + s] = bv[t * q..(t + 1) * q]
                            .iter()
                            .zip(&bu[s * q..(s + 1) * q])
                            .map(|(x, y)| x * y)
                            .sum();
                    }
                }
            }
        }
    }

    pub(super) fn feasible(&self, vi: usize, alpha: &[f64], sc: &mut Scratch) -> bool {
        if self.nonneg && alpha.iter().any(|&a| a < 0.0) {
            return false;
        }
        self.equality(vi, &mut sc.e_mat, &mut sc.e_rhs);
        let k = self.k();
        (0..self.rows()).all(|c| {
            let row = &sc.e_mat[c * k..(c + 1) * k];
            let s: f64 = row.iter().zip(alpha).map(|(a, b)| a * b).sum();
            let scale = row
                .iter()
                .zip(alpha)
                .fold(1.0f64, |m, (a, b)| m.max((a * b).abs()));
            (s - sc.e_rhs[c]).abs() <= 1e-13 * scale
        })
    }

    /// Moves an infeasible start (k-largest weights without linear precision, or with negative
    /// entries when non-negativity is on) to the nearest feasible point.
    pub(crate) fn make_feasible(&self, alpha: &mut Array2<f64>) -> SkinResult<()> {
        let k = self.k();
        let r = self.rows();
        let slice = alpha
            .as_slice_mut()
            .ok_or_else(|| SkinError::Numerical("weights not contiguous".into()))?;
        slice.par_chunks_mut(k).enumerate().try_for_each_init(
            || Scratch::new(k, 0, r),
            |sc, (vi, a)| -> SkinResult<()> {
                if self.feasible(vi, a, sc) {
                    return Ok(());
                }
                sc.h.iter_mut().for_each(|x| *x = 0.0);
                for t in 0..k {
                    sc.h[t * k + t] = 1.0;
                    sc.g[t] = -a[t];
                }
                self.equality(vi, &mut sc.e_mat, &mut sc.e_rhs);
                sc.solve_qp(a, self.nonneg)
                    .map_err(|e| qp_error(self.order[vi], e))?;
                a.copy_from_slice(&sc.x);
                Ok(())
            },
        )
    }

    /// `E = X(alpha) - Xbar`, flat `(n, q)`.
    pub(super) fn error(&self, alpha: ArrayView2<f64>) -> Vec<f64> {
        let q = self.basis.q();
        let mut e = vec![0.0; self.sets.nrows() * q];
        self.per_vertex(&mut e, q, |v, set, b, ev| {
            let a = alpha.row(v);
            let a = a.as_slice().expect("weights are standard layout");
            self.basis.position(v, set, a, b, ev);
            for (x, t) in ev.iter_mut().zip(self.target.row(v)) {
                *x -= t;
            }
        });
        e
    }

    /// Runs `f(v, S_v, scratch (k q), out_v)` for every vertex in parallel, `out` split into
    /// rows of `width`.
    pub(super) fn per_vertex<F>(&self, out: &mut [f64], width: usize, f: F)
    where
        F: Fn(usize, &[usize], &mut [f64], &mut [f64]) + Sync,
    {
        let kq = self.k() * self.basis.q();
        out.par_chunks_mut(width).enumerate().for_each_init(
            || vec![0.0; kq],
            |b, (v, o)| {
                let set = self.sets.row(v);
                f(v, set.as_slice().expect("sets are standard layout"), b, o)
            },
        )
    }

    /// `tr(E^T Q E)`.
    pub(super) fn objective(&self, e: &[f64]) -> f64 {
        let q = self.basis.q();
        let c = &self.coupling;
        let rows: Vec<f64> = e
            .par_chunks(q)
            .enumerate()
            .map(|(v, ev)| {
                let mut s = 0.0;
                for p in c.col(v) {
                    let (u, qv) = (c.rows[p], c.val[p]);
                    let eu = &e[u * q..(u + 1) * q];
                    s += qv * ev.iter().zip(eu).map(|(a, b)| a * b).sum::<f64>();
                }
                s
            })
            .collect();
        rows.iter().sum()
    }

    /// `1e-9 Q_vv tr(G) / k` for the Gram matrix `G (k x k)` of vertex `vi`: the weight of the
    /// proximal term of [`Self::local_hessian`].
    pub(super) fn proximal_weight(&self, vi: usize, gram: &[f64], k: usize) -> f64 {
        let tr: f64 = (0..k).map(|t| gram[t * k + t]).sum::<f64>() / k as f64;
        1e-9 * self.coupling.diag[vi] * tr
    }

    /// `H = Q_vv G + eps I` of vertex `vi`. The proximal term `eps |alpha - alpha_old|^2 / 2`
    /// keeps H definite when the poses do not determine all k weights (e.g. 3p < k); it does
    /// not move the fixed point.
    pub(super) fn local_hessian(&self, vi: usize, set: &[usize], gram: &mut [f64], h: &mut [f64]) {
        let k = set.len();
        let s_v = self.coupling.diag[vi];
        self.basis.gram(vi, set, gram);
        let eps = self.proximal_weight(vi, gram, k) + f64::MIN_POSITIVE;
        for a in 0..k {
            for b in 0..k {
                h[a * k + b] = s_v * gram[a * k + b] + if a == b { eps } else { 0.0 };
            }
        }
    }
}

/// `(n, k)` view of the flat weights.
pub(super) fn alpha_view(a: &[f64], n: usize, k: usize) -> ArrayView2<'_, f64> {
    ArrayView2::from_shape((n, k), a).expect("n * k weights")
}
