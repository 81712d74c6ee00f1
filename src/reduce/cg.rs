//! Projected preconditioned conjugate gradients for the reductions without bounds.
//!
//! The objective is the quadratic `Phi(alpha) = tr(E^T Q E)`, `E = X(alpha) - Xbar`, under
//! the per-vertex equality rows `E_v alpha_v = e_v` only (sum to one, linear precision), so
//! its minimiser solves one sparse linear KKT system. The preconditioner is the block-diagonal
//! `P = diag(P_v)` of [`super::blocks`], the same `k x k` blocks the local iteration uses:
//! `P_v g` is the equality-constrained block step, and `E_v P_v = 0`, so every search direction
//! keeps the constraints (null-space PCG, Gould et al. 2001), plus the coarse space of
//! [`super::coarse`]. Halving everything, `grad_v = B_v^T (Q E)_v` and
//! `(H d)_v = B_v^T (Q B d)_v + eps_v d_v` (the small `eps_v` of
//! [`Problem::proximal_weight`] keeps `H` definite where the poses do not fix every weight).
//! Every step is an exact line search, so the objective never increases; it is reported after
//! every iteration, which plays the role of a sweep for `max_sweeps` and `tol`.
//!
//! The smooth method (`x_v` = the weight row, `q = m`) works on the weights alone:
//! `(H p)_v[t] = sum_u Q_vu p_u[s]` over the slots `s` of `u` holding handle `S_vt`, with
//! `Phi = alpha.H alpha - 2 alpha.b0 + c0`, `b0 = B^T Q Xbar`, `c0 = tr(Xbar^T Q Xbar)`, so the
//! dense `E, R (n, m)` are never formed. The other bases keep `E = X - Xbar` and `R = Q E`
//! (`q` is small) and measure `Phi = tr(E^T R)` directly.

use ndarray::Array2;
use rayon::prelude::*;

use crate::error::{SkinError, SkinResult};
use crate::progress::Progress;

use super::basis::Basis;
use super::blocks::FastOps;
use super::coarse::Coarse;
use super::iteration::{record, should_stop, SolveOptions, SolveReport};
use super::problem::{alpha_view, Problem};

/// Iterations between two measurements of the objective and gradient from scratch (against
/// the drift of the incremental updates).
const REMEASURE: usize = 32;

/// Minimises `pb` from the feasible start `alpha (n, k)`, in place.
pub(super) fn solve(
    pb: &Problem,
    alpha: &mut Array2<f64>,
    opts: &SolveOptions,
    fast: &FastOps,
    progress: &mut dyn Progress,
) -> SkinResult<SolveReport> {
    let cg = Cg::new(pb, fast)?;
    let a = alpha
        .as_slice_mut()
        .ok_or_else(|| SkinError::Numerical("weights not contiguous".into()))?;
    cg.run(a, opts, progress)
}

/// The smooth method's constants: for every coupling entry and slot the slot of the neighbour
/// holding the same handle, `b0 = B^T Q Xbar` and `c0 = tr(Xbar^T Q Xbar)`.
struct Select {
    slots: Vec<u8>,
    b0: Vec<f64>,
    c0: f64,
}

/// `E = X - Xbar`, `R = Q E` and the search direction's `D = B p`, `W = Q D`, flat `(n, q)`
/// (empty for the smooth method).
#[derive(Default)]
struct Errors {
    e: Vec<f64>,
    r: Vec<f64>,
    d: Vec<f64>,
    w: Vec<f64>,
}

/// The operators of one conjugate-gradient solve.
struct Cg<'p, 'a> {
    pb: &'p Problem<'a>,
    fast: &'p FastOps,
    coarse: Option<Coarse>,
    /// Proximal weight `eps_v` of every vertex.
    eps: Vec<f64>,
    select: Option<Select>,
    n: usize,
    k: usize,
    q: usize,
}

impl<'p, 'a> Cg<'p, 'a> {
    fn new(pb: &'p Problem<'a>, fast: &'p FastOps) -> SkinResult<Self> {
        let (n, k) = pb.sets.dim();
        let q = pb.basis.q();
        // The coarse space applies when the equality rows are the sums alone.
        let coarse = if pb.rows() == 1 {
            Some(Coarse::new(pb)?)
        } else {
            None
        };
        let mut cg = Cg {
            pb,
            fast,
            coarse,
            eps: proximal_weights(pb),
            select: None,
            n,
            k,
            q,
        };
        if matches!(pb.basis, Basis::Select { .. }) {
            cg.select = Some(cg.select_constants());
        }
        Ok(cg)
    }

    fn select_constants(&self) -> Select {
        let (n, q) = (self.n, self.q);
        let mut qx = vec![0.0; n * q];
        let xbar = self
            .pb
            .target
            .as_slice()
            .expect("target is standard layout");
        self.pb.coupling.apply(xbar, q, &mut qx);
        let mut b0 = vec![0.0; n * self.k];
        self.gather(&qx, &mut b0);
        Select {
            slots: self.pb.shared_slots(),
            b0,
            c0: dot(xbar, &qx),
        }
    }

    /// `y_v = B_v^T x_v` for every vertex (`x (n, q)` -> `y (n, k)`).
    fn gather(&self, x: &[f64], y: &mut [f64]) {
        let (pb, q) = (self.pb, self.q);
        pb.per_vertex(y, self.k, |v, set, b, yv| {
            pb.basis.transpose(v, set, &x[v * q..(v + 1) * q], b, yv)
        })
    }

    /// Two-level preconditioner: `z_v = P_v g_v`, plus `Z H_c^-1 Z^T g`.
    fn precondition(&self, g: &[f64], z: &mut [f64]) {
        let k = self.k;
        z.par_chunks_mut(k).enumerate().for_each(|(v, zv)| {
            let pv = &self.fast.p[v * k * k..(v + 1) * k * k];
            let gv = &g[v * k..(v + 1) * k];
            for (i, zi) in zv.iter_mut().enumerate() {
                *zi = pv[i * k..(i + 1) * k]
                    .iter()
                    .zip(gv)
                    .map(|(x, y)| x * y)
                    .sum();
            }
        });
        if let Some(c) = &self.coarse {
            c.add_correction(g, z);
        }
    }

    /// `hp = H p` of the smooth method.
    fn hessian_select(&self, slots: &[u8], p: &[f64], hp: &mut [f64]) {
        let (c, k) = (&self.pb.coupling, self.k);
        hp.par_chunks_mut(k).enumerate().for_each(|(v, h)| {
            h.iter_mut().for_each(|x| *x = 0.0);
            for pos in c.col(v) {
                let (u, w) = (c.rows[pos], c.val[pos]);
                let pu = &p[u * k..(u + 1) * k];
                for (t, hv) in h.iter_mut().enumerate() {
                    let sl = slots[pos * k + t];
                    if sl != u8::MAX {
                        *hv += w * pu[sl as usize];
                    }
                }
            }
        });
    }

    /// `hp = H p`; for the bases with `E`, also `D = B p` and `W = Q D` into `errs`.
    fn hessian(&self, p: &[f64], hp: &mut [f64], errs: &mut Errors) {
        if let Some(s) = &self.select {
            return self.hessian_select(&s.slots, p, hp);
        }
        let (pb, k, q) = (self.pb, self.k, self.q);
        pb.per_vertex(&mut errs.d, q, |v, set, b, dv| {
            pb.basis.position(v, set, &p[v * k..(v + 1) * k], b, dv)
        });
        pb.coupling.apply(&errs.d, q, &mut errs.w);
        self.gather(&errs.w, hp);
        hp.par_chunks_mut(k)
            .zip(p.par_chunks(k))
            .zip(self.eps.par_iter())
            .for_each(|((h, pv), &ev)| h.iter_mut().zip(pv).for_each(|(x, y)| *x += ev * y));
    }

    /// The objective at `a` and the halved gradient `g = B^T Q (X - Xbar)`, from scratch.
    fn measure(&self, a: &[f64], g: &mut [f64], errs: &mut Errors) -> f64 {
        if let Some(s) = &self.select {
            self.hessian_select(&s.slots, a, g);
            let f = dot(a, g) - 2.0 * dot(a, &s.b0) + s.c0;
            g.par_iter_mut()
                .zip(s.b0.par_iter())
                .for_each(|(x, y)| *x -= y);
            return f;
        }
        errs.e = self.pb.error(alpha_view(a, self.n, self.k));
        errs.r.resize(self.n * self.q, 0.0);
        self.pb.coupling.apply(&errs.e, self.q, &mut errs.r);
        self.gather(&errs.r, g);
        dot(&errs.e, &errs.r)
    }

    /// The objective after the step `a += t p` (with `g.p = gp`), updated incrementally or,
    /// every [`REMEASURE`] iterations, measured from scratch (which also refreshes `g`).
    #[allow(clippy::too_many_arguments)]
    fn objective_after_step(
        &self,
        it: usize,
        t: f64,
        gp: f64,
        f: f64,
        a: &[f64],
        g: &mut [f64],
        errs: &mut Errors,
    ) -> f64 {
        if it.is_multiple_of(REMEASURE) {
            self.measure(a, g, errs)
        } else if self.select.is_some() {
            // Phi(alpha + t p) = Phi + 2 t g.p + t^2 p.Hp = Phi + t g.p (g, H halved).
            f + t * gp
        } else {
            axpy(t, &errs.d, &mut errs.e);
            axpy(t, &errs.w, &mut errs.r);
            dot(&errs.e, &errs.r)
        }
    }

    fn run(
        &self,
        a: &mut [f64],
        opts: &SolveOptions,
        progress: &mut dyn Progress,
    ) -> SkinResult<SolveReport> {
        let nk = self.n * self.k;
        let mut errs = Errors::default();
        if self.select.is_none() {
            errs.d = vec![0.0; self.n * self.q];
            errs.w = vec![0.0; self.n * self.q];
        }
        let (mut g, mut z, mut hp) = (vec![0.0; nk], vec![0.0; nk], vec![0.0; nk]);
        let mut history = Vec::new();
        let mut f = self.measure(a, &mut g, &mut errs);
        record(&mut history, f, progress)?;
        self.precondition(&g, &mut z);
        let mut p: Vec<f64> = z.iter().map(|x| -x).collect();
        let mut gz = dot(&g, &z);
        let mut converged = gz <= 0.0;
        for it in 1..=opts.max_sweeps {
            if converged {
                break;
            }
            self.hessian(&p, &mut hp, &mut errs);
            let (php, gp) = (dot(&p, &hp), dot(&g, &p));
            if !(php > 0.0 && php.is_finite()) || gp >= 0.0 {
                converged = true;
                break;
            }
            // Exact line search along p.
            let t = -gp / php;
            axpy(t, &p, a);
            axpy(t, &hp, &mut g);
            f = self.objective_after_step(it, t, gp, f, a, &mut g, &mut errs);
            record(&mut history, f, progress)?;
            if should_stop(&history, opts.tol) {
                converged = true;
                break;
            }
            self.precondition(&g, &mut z);
            let gz_new = dot(&g, &z);
            let beta = gz_new / gz;
            gz = gz_new;
            if gz.is_nan() || gz <= 0.0 {
                converged = true;
                break;
            }
            p.par_iter_mut()
                .zip(z.par_iter())
                .for_each(|(x, y)| *x = beta * *x - y);
        }
        self.finish(a, &mut g, &mut errs, &mut history);
        Ok(SolveReport {
            objective: history,
            converged,
            qp_capped: 0,
        })
    }

    /// Puts every row exactly back on sum one (each step moves it by rounding only) and makes
    /// the last entry of `history` the objective of the returned weights, measured from scratch.
    fn finish(&self, a: &mut [f64], g: &mut [f64], errs: &mut Errors, history: &mut [f64]) {
        let k = self.k;
        a.par_chunks_mut(k).for_each(|av| {
            let shift = (av.iter().sum::<f64>() - 1.0) / k as f64;
            av.iter_mut().for_each(|x| *x -= shift);
        });
        let f_end = self.measure(a, g, errs);
        if let Some(last) = history.last_mut() {
            *last = f_end;
        }
    }
}

/// `eps_v` of every vertex (see [`Problem::proximal_weight`]).
fn proximal_weights(pb: &Problem) -> Vec<f64> {
    let (n, k) = pb.sets.dim();
    (0..n)
        .into_par_iter()
        .map_init(
            || vec![0.0; k * k],
            |g, v| {
                let set = pb.sets.row(v);
                let set = set.as_slice().expect("sets are standard layout");
                pb.basis.gram(v, set, g);
                pb.proximal_weight(v, g, k)
            },
        )
        .collect()
}

/// `x . y` from partial sums in a fixed order: results do not depend on the thread schedule.
fn dot(x: &[f64], y: &[f64]) -> f64 {
    let parts: Vec<f64> = x
        .par_chunks(4096)
        .zip(y.par_chunks(4096))
        .map(|(a, b)| a.iter().zip(b).map(|(u, w)| u * w).sum::<f64>())
        .collect();
    parts.iter().sum()
}

/// `y += t x`, in parallel.
fn axpy(t: f64, x: &[f64], y: &mut [f64]) {
    y.par_iter_mut()
        .zip(x.par_iter())
        .for_each(|(y, x)| *y += t * x);
}
