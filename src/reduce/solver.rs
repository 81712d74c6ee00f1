//! The local iteration of paper 002 Sec. 3.1, shared by the smooth (3.1), geometric (3.2),
//! Poisson (3.3) and skeletal (Sec. 4) reductions.
//!
//! Every method minimises, over the packed weights `alpha_v (k)` of each vertex,
//!
//! ```text
//!   Phi(alpha) = tr(E^T Q E),   E = X(alpha) - Xbar,   x_v(alpha) = B_v alpha_v
//! ```
//!
//! where row `x_v` stacks what the vertex does in every pose (`B_v`'s columns are the positions
//! `c_i^j` or `M_i^j v` of its `k` handles over all poses, or for the smooth method the unit
//! vectors of its influence set) and `Xbar` is the same for the original weights. `Q` is the
//! identity (geometric, eq. 3), `L M^-1 L` (squared Laplacian, eqs. 4-5 discretised as
//! `int (lap e)^2 dA ~ (L e)^T M^-1 (L e)`) or `-L` (gradient form `int |grad e|^2 dA`), `L` the
//! cotangent Laplacian and `M` the lumped mass.
//!
//! One vertex's block of `Phi` with all other vertices fixed is
//! `Q_vv |B_v alpha|^2 + 2 alpha^T B_v^T (R_v - Q_vv x_v)` with `R = Q E`, `E = X - Xbar`: a
//! `k`-variable QP solved exactly by [`super::qp`]. Vertices not coupled by `Q` (distance > 2 for
//! the squared Laplacian, > 1 for `-L`) do not interact, so a greedy colouring of `Q`'s graph gives
//! classes that are updated in parallel; the sweep over all classes is block Gauss-Seidel,
//! optionally over-relaxed. `E` and `R` are kept up to date, so the global objective is measured
//! after every sweep.
//!
//! Without bounds the problem is linear (one sparse KKT system), and [`Problem::solve_cg`]
//! minimises it by projected conjugate gradients with the same per-vertex blocks as
//! preconditioner plus an aggregation coarse space ([`super::coarse`]); it reports the
//! objective after every iteration in the same way. Both stop by [`should_stop`]: when the
//! mean decrease over the last few sweeps is at most `tol` times the decrease since the start.

use ndarray::{Array2, ArrayView2};
use rayon::prelude::*;
use std::sync::atomic::{AtomicUsize, Ordering};

use crate::error::{SkinError, SkinResult};
use crate::progress::{Event, Progress};
use crate::sparse::Csc;

use super::coarse::Coarse;
use super::deform::{point, Poses};
use super::qp::{self, LocalQp, QpFailure, QpWork};

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
    fn fill(&self, vi: usize, set: &[usize], b: &mut [f64]) {
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
    fn gram(&self, vi: usize, set: &[usize], g: &mut [f64]) {
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
    fn position(&self, vi: usize, set: &[usize], alpha: &[f64], b: &mut [f64], x: &mut [f64]) {
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
    fn transpose(&self, vi: usize, set: &[usize], y: &[f64], b: &mut [f64], out: &mut [f64]) {
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

/// The symmetric positive semi-definite `n x n` matrix `Q` of the objective `sum tr(E^T Q E)`,
/// `E = X(alpha) - Xbar`, stored by columns (= rows).
pub(crate) struct Coupling {
    ptr: Vec<usize>,
    rows: Vec<usize>,
    val: Vec<f64>,
    /// `Q_vv`.
    diag: Vec<f64>,
}

impl Coupling {
    /// `Q = I` (geometric reduction, eq. 3).
    pub(crate) fn identity(n: usize) -> Self {
        Coupling {
            ptr: (0..=n).collect(),
            rows: (0..n).collect(),
            val: vec![1.0; n],
            diag: vec![1.0; n],
        }
    }

    fn from_parts(ptr: Vec<usize>, rows: Vec<usize>, val: Vec<f64>) -> Self {
        let n = ptr.len() - 1;
        let diag = (0..n)
            .map(|v| {
                (ptr[v]..ptr[v + 1])
                    .find(|&p| rows[p] == v)
                    .map_or(0.0, |p| val[p])
            })
            .collect();
        Coupling {
            ptr,
            rows,
            val,
            diag,
        }
    }

    /// `Q = -L`: the Dirichlet energy `int |grad e|^2 dA` of the error.
    pub(crate) fn dirichlet(l: &Csc) -> Self {
        let sym = l.symbolic();
        Self::from_parts(
            sym.col_ptr().to_vec(),
            sym.row_idx().to_vec(),
            l.val().iter().map(|x| -x).collect(),
        )
    }

    /// `Q = L M^-1 L`: the squared-Laplacian energy `int (lap e)^2 dA` of eqs. (4)-(5).
    /// `L` must be exactly symmetric; then so is `Q` (terms are summed in the same order).
    pub(crate) fn squared_laplacian(l: &Csc, mass: &[f64]) -> Self {
        let sym = l.symbolic();
        let (lp, lr, lv) = (sym.col_ptr(), sym.row_idx(), l.val());
        let n = mass.len();
        let mut ptr = Vec::with_capacity(n + 1);
        let mut rows = Vec::new();
        let mut val = Vec::new();
        let mut acc = vec![0.0; n];
        let mut seen = vec![usize::MAX; n];
        let mut touched = Vec::new();
        ptr.push(0);
        for v in 0..n {
            touched.clear();
            // Column v of Q = sum_w L[:, w] L_wv / M_w, w ascending.
            for p in lp[v]..lp[v + 1] {
                let (w, lwv) = (lr[p], lv[p]);
                let f = lwv / mass[w];
                for p2 in lp[w]..lp[w + 1] {
                    let u = lr[p2];
                    if seen[u] != v {
                        seen[u] = v;
                        acc[u] = 0.0;
                        touched.push(u);
                    }
                    acc[u] += lv[p2] * f;
                }
            }
            touched.sort_unstable();
            for &u in &touched {
                rows.push(u);
                val.push(acc[u]);
            }
            ptr.push(rows.len());
        }
        Self::from_parts(ptr, rows, val)
    }

    fn n(&self) -> usize {
        self.diag.len()
    }

    /// No two vertices interact (geometric reduction): one exact sweep solves the problem.
    fn is_diagonal(&self) -> bool {
        (0..self.n()).all(|v| self.col(v).all(|p| self.rows[p] == v))
    }

    fn col(&self, v: usize) -> std::ops::Range<usize> {
        self.ptr[v]..self.ptr[v + 1]
    }

    /// The entries `(u, Q_vu)` of row (= column) `v`.
    pub(crate) fn entries(&self, v: usize) -> impl Iterator<Item = (usize, f64)> + '_ {
        self.col(v).map(move |p| (self.rows[p], self.val[p]))
    }

    /// `out = Q x` for `x (n, q)` flat, in parallel over rows (`Q` is symmetric: columns = rows).
    fn apply(&self, x: &[f64], q: usize, out: &mut [f64]) {
        out.par_chunks_mut(q).enumerate().for_each(|(v, o)| {
            o.iter_mut().for_each(|y| *y = 0.0);
            for p in self.col(v) {
                let (u, w) = (self.rows[p], self.val[p]);
                for (y, xu) in o.iter_mut().zip(&x[u * q..(u + 1) * q]) {
                    *y += w * xu;
                }
            }
        });
    }

    /// Greedy colouring such that no two vertices of one class are coupled by `Q`. Returns the
    /// vertices ordered class by class and the class boundaries (`ptr`, length classes + 1).
    pub(crate) fn colour_order(&self) -> (Vec<usize>, Vec<usize>) {
        let n = self.n();
        let mut colour = vec![usize::MAX; n];
        let mut stamp: Vec<usize> = Vec::new();
        let mut counts: Vec<usize> = Vec::new();
        for v in 0..n {
            for p in self.col(v) {
                let c = colour[self.rows[p]];
                if c != usize::MAX {
                    stamp[c] = v + 1;
                }
            }
            let c = (0..stamp.len())
                .find(|&c| stamp[c] != v + 1)
                .unwrap_or(stamp.len());
            if c == stamp.len() {
                stamp.push(0);
                counts.push(0);
            }
            colour[v] = c;
            counts[c] += 1;
        }
        let mut ptr = vec![0; counts.len() + 1];
        for c in 0..counts.len() {
            ptr[c + 1] = ptr[c] + counts[c];
        }
        let mut next = ptr.clone();
        let mut order = vec![0; n];
        for v in 0..n {
            order[next[colour[v]]] = v;
            next[colour[v]] += 1;
        }
        (order, ptr)
    }

    /// `Q[order, order]`: the coupling of the renumbered vertices `i -> order[i]`.
    pub(crate) fn permuted(&self, order: &[usize]) -> Self {
        let n = self.n();
        let mut inv = vec![0; n];
        for (i, &v) in order.iter().enumerate() {
            inv[v] = i;
        }
        let mut ptr = Vec::with_capacity(n + 1);
        let mut rows = Vec::with_capacity(self.rows.len());
        let mut val = Vec::with_capacity(self.val.len());
        let mut entries = Vec::new();
        ptr.push(0);
        for &v in order {
            entries.clear();
            entries.extend(self.col(v).map(|p| (inv[self.rows[p]], self.val[p])));
            entries.sort_unstable_by_key(|e| e.0);
            for &(r, x) in &entries {
                rows.push(r);
                val.push(x);
            }
            ptr.push(rows.len());
        }
        Self::from_parts(ptr, rows, val)
    }
}

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

pub(crate) struct SolveOptions {
    pub max_sweeps: usize,
    pub tol: f64,
    pub relaxation: f64,
    /// Conjugate gradients (vertices in input order, one class) instead of the local iteration.
    pub cg: bool,
}

/// Which iteration minimises a coupled problem.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Solver {
    /// Conjugate gradients when there are no bounds, the local iteration otherwise.
    Auto,
    /// The local iteration of Sec. 3.1 (block Gauss-Seidel / SOR over the colour classes).
    Local,
    /// Projected preconditioned conjugate gradients (equality constraints only).
    Cg,
}

impl Solver {
    /// Parses `"auto"`, `"local"` or `"cg"`.
    pub fn parse(s: &str) -> SkinResult<Self> {
        match s {
            "auto" => Ok(Solver::Auto),
            "local" => Ok(Solver::Local),
            "cg" => Ok(Solver::Cg),
            _ => crate::invalid!("unknown solver {s:?}: use 'auto', 'local' or 'cg'"),
        }
    }
}

/// The measured, scale-aware stopping rule: stop once the mean decrease of the objective over
/// the last (up to) [`STOP_WINDOW`] iterations is at most `tol` times the decrease achieved since
/// the start, `h[0] - h[s]`. Relative to what the iteration has achieved (not to `h[s]`, which
/// may be near zero or dominated by an error no weight can remove), so it does not depend on the
/// units of the poses; the window smooths the uneven decrease of conjugate gradients.
pub(crate) fn should_stop(history: &[f64], tol: f64) -> bool {
    let s = history.len() - 1;
    if s == 0 {
        return false;
    }
    let w = s.min(STOP_WINDOW);
    let recent = (history[s - w] - history[s]) / w as f64;
    recent <= tol * (history[0] - history[s])
}

/// Most entries of the per-vertex `k x k` blocks kept in memory (256 MB).
pub(crate) const FAST_LIMIT: usize = 1 << 25;

/// Iterations averaged by [`should_stop`].
pub(crate) const STOP_WINDOW: usize = 4;

pub(crate) struct SolveReport {
    /// Objective before the first sweep and after each sweep.
    pub objective: Vec<f64>,
    pub converged: bool,
    /// Local QPs that hit the active-set iteration cap (kept feasible, not optimal).
    pub qp_capped: usize,
}

/// Per-thread scratch.
struct Scratch {
    b: Vec<f64>,
    r: Vec<f64>,
    gram: Vec<f64>,
    h: Vec<f64>,
    g: Vec<f64>,
    e_mat: Vec<f64>,
    e_rhs: Vec<f64>,
    x: Vec<f64>,
    lambda: Vec<f64>,
    mu: Vec<f64>,
    work: QpWork,
}

impl Scratch {
    fn new(k: usize, q: usize, r: usize) -> Self {
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
    fn solve_qp(&mut self, x0: &[f64], nonneg: bool) -> Result<qp::QpStatus, QpFailure> {
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

fn qp_error(v: usize, e: QpFailure) -> SkinError {
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

/// Precomputed per-vertex projected inverses (see [`Problem::fast_operators`]).
struct FastOps {
    /// `(n, k, k)`.
    p: Vec<f64>,
    /// False where the constraints were degenerate (that vertex always runs the QP).
    ok: Vec<bool>,
}

/// `P = H^-1 - H^-1 E^T (E H^-1 E^T)^-1 E H^-1` into `out (k x k)`; `h` is overwritten.
fn projected_inverse(h: &mut [f64], e_mat: &[f64], k: usize, r: usize, out: &mut [f64]) -> bool {
    if !qp::cholesky(h, k) {
        return false;
    }
    // out = H^-1, column by column (symmetric).
    let mut col = vec![0.0; k];
    for j in 0..k {
        col.iter_mut()
            .enumerate()
            .for_each(|(i, x)| *x = (i == j) as u8 as f64);
        qp::cholesky_solve(h, k, &mut col);
        for i in 0..k {
            out[i * k + j] = col[i];
        }
    }
    // Y = H^-1 E^T (k x r), S = E Y (r x r).
    let mut y = vec![0.0; k * r];
    for c in 0..r {
        for i in 0..k {
            y[i * r + c] = (0..k).map(|j| out[i * k + j] * e_mat[c * k + j]).sum();
        }
    }
    let mut sm = vec![0.0; r * r];
    for a in 0..r {
        for b in 0..r {
            sm[a * r + b] = (0..k).map(|i| e_mat[a * k + i] * y[i * r + b]).sum();
        }
    }
    if !qp::cholesky(&mut sm, r) {
        return false;
    }
    // out -= Y S^-1 Y^T
    let mut z = vec![0.0; r];
    for i in 0..k {
        z.copy_from_slice(&y[i * r..(i + 1) * r]);
        qp::cholesky_solve(&sm, r, &mut z);
        for j in 0..k {
            let v: f64 = (0..r).map(|c| z[c] * y[j * r + c]).sum();
            out[j * k + i] -= v;
        }
    }
    out.iter().all(|x| x.is_finite())
}

/// Rows of `E (n, q)` during the update of one class `[start, end)`: the class's own rows are
/// borrowed mutably, all others (which no vertex of the class changes) shared.
struct Rows<'e> {
    before: &'e [f64],
    after: &'e [f64],
    start: usize,
    end: usize,
    q: usize,
}

impl Rows<'_> {
    /// Row `u`, which must lie outside the class.
    #[inline]
    fn get(&self, u: usize) -> &[f64] {
        let q = self.q;
        if u < self.start {
            &self.before[u * q..(u + 1) * q]
        } else {
            let o = u - self.end;
            &self.after[o * q..(o + 1) * q]
        }
    }
}

impl Problem<'_> {
    fn k(&self) -> usize {
        self.sets.ncols()
    }

    fn rows(&self) -> usize {
        1 + self.lp.as_ref().map_or(0, |lp| lp.v.ncols())
    }

    /// Equality rows `E alpha = e`: sum to one, then (cages, smooth) linear precision written
    /// relative to the vertex, `sum_t alpha_t (c_t - v) = 0`, which is better scaled.
    fn equality(&self, vi: usize, e_mat: &mut [f64], e_rhs: &mut [f64]) {
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
    fn shared_slots(&self) -> Vec<u8> {
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

    fn feasible(&self, vi: usize, alpha: &[f64], sc: &mut Scratch) -> bool {
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
    fn error(&self, alpha: ArrayView2<f64>) -> Vec<f64> {
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
    fn per_vertex<F>(&self, out: &mut [f64], width: usize, f: F)
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
    fn objective(&self, e: &[f64]) -> f64 {
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

    /// Updates vertex `vi` in place: `alpha_v (k)` and its error row `e_v (q)`, reading the rows
    /// of its `Q`-neighbours (other classes) from `others`.
    ///
    /// With all other vertices fixed, the objective in `alpha_v` is
    /// `Q_vv |B alpha|^2 + 2 alpha^T B^T (R_v - Q_vv x_v) + const`, `R = Q E`.
    #[allow(clippy::too_many_arguments)]
    fn local_update(
        &self,
        vi: usize,
        alpha_v: &mut [f64],
        e_v: &mut [f64],
        others: &Rows,
        omega: f64,
        fast: Option<&FastOps>,
        sc: &mut Scratch,
    ) -> SkinResult<bool> {
        let k = self.k();
        let q = self.basis.q();
        let c = &self.coupling;
        let set = self.sets.row(vi);
        let set = set.as_slice().expect("sets are standard layout");
        // g = B^T R_v, R_v = sum_u Q_vu e_u.
        match self.basis {
            Basis::Select { .. } => {
                for (t, &i) in set.iter().enumerate() {
                    let mut r = 0.0;
                    for p in c.col(vi) {
                        let u = c.rows[p];
                        let eu = if u == vi { e_v[i] } else { others.get(u)[i] };
                        r += c.val[p] * eu;
                    }
                    sc.g[t] = r;
                }
            }
            _ => {
                sc.r.iter_mut().for_each(|x| *x = 0.0);
                for p in c.col(vi) {
                    let u = c.rows[p];
                    let eu: &[f64] = if u == vi { e_v } else { others.get(u) };
                    let qv = c.val[p];
                    for (r, x) in sc.r.iter_mut().zip(eu) {
                        *r += qv * x;
                    }
                }
                self.basis.fill(vi, set, &mut sc.b);
                for t in 0..k {
                    sc.g[t] = sc.b[t * q..(t + 1) * q]
                        .iter()
                        .zip(&sc.r)
                        .map(|(a, b)| a * b)
                        .sum();
                }
            }
        }
        // Fast path: the block minimiser under the equality rows alone is
        // alpha_old - P_v B^T R_v (B^T R_v is the block gradient at alpha_old); when it is
        // non-negative (or bounds are off) it is the exact solution of the local QP.
        let mut converged = true;
        let fast_done = match fast {
            Some(ops) if ops.ok[vi] => {
                let pv = &ops.p[vi * k * k..(vi + 1) * k * k];
                for a in 0..k {
                    let d: f64 = (0..k).map(|b| pv[a * k + b] * sc.g[b]).sum();
                    sc.x[a] = alpha_v[a] - d;
                }
                // Keep the sum exactly on 1 (rounding would otherwise drift over many sweeps).
                let shift = (sc.x.iter().sum::<f64>() - 1.0) / k as f64;
                sc.x.iter_mut().for_each(|x| *x -= shift);
                !self.nonneg || sc.x.iter().all(|&x| x >= 0.0)
            }
            _ => false,
        };
        if !fast_done {
            self.local_hessian(vi, set, &mut sc.gram, &mut sc.h);
            for a in 0..k {
                let ha: f64 = (0..k).map(|b| sc.h[a * k + b] * alpha_v[b]).sum();
                sc.g[a] -= ha;
            }
            self.equality(vi, &mut sc.e_mat, &mut sc.e_rhs);
            converged = sc
                .solve_qp(alpha_v, self.nonneg)
                .map_err(|e| qp_error(self.order[vi], e))?
                .converged;
        }
        // Over-relaxation along the block step, shortened so the weights stay non-negative.
        // Any step in (0, 2) of the exact block minimiser decreases the block's quadratic.
        let mut t = omega;
        if self.nonneg {
            for (a, x) in alpha_v.iter().zip(&sc.x) {
                let d = x - a;
                if d < 0.0 {
                    t = t.min(a / -d);
                }
            }
        }
        for (tcol, (a, x)) in alpha_v.iter_mut().zip(&sc.x).enumerate() {
            let mut new = *a + t * (x - *a);
            if self.nonneg && new < 0.0 {
                new = 0.0;
            }
            let da = new - *a;
            *a = new;
            if da != 0.0 {
                match self.basis {
                    Basis::Select { .. } => e_v[set[tcol]] += da,
                    _ => {
                        for (x, bq) in e_v.iter_mut().zip(&sc.b[tcol * q..(tcol + 1) * q]) {
                            *x += da * bq;
                        }
                    }
                }
            }
        }
        Ok(converged)
    }

    /// `H = Q_vv G + eps I` of vertex `vi`. The proximal term `eps |alpha - alpha_old|^2 / 2`
    /// keeps H definite when the poses do not determine all k weights (e.g. 3p < k); it does
    /// not move the fixed point.
    fn local_hessian(&self, vi: usize, set: &[usize], gram: &mut [f64], h: &mut [f64]) {
        let k = set.len();
        let s_v = self.coupling.diag[vi];
        self.basis.gram(vi, set, gram);
        let tr: f64 = (0..k).map(|t| gram[t * k + t]).sum::<f64>() / k as f64;
        let eps = 1e-9 * s_v * tr + f64::MIN_POSITIVE;
        for a in 0..k {
            for b in 0..k {
                h[a * k + b] = s_v * gram[a * k + b] + if a == b { eps } else { 0.0 };
            }
        }
    }

    /// Per-vertex projected inverses `P_v = H^-1 - H^-1 E^T (E H^-1 E^T)^-1 E H^-1`: with them
    /// an equality-constrained block step is one `k x k` product. `None` when they would take
    /// more than [`FAST_LIMIT`] entries (then every step runs the active-set QP).
    fn fast_operators(&self) -> Option<FastOps> {
        let n = self.sets.nrows();
        let k = self.k();
        let r = self.rows();
        if n.saturating_mul(k * k) > FAST_LIMIT {
            return None;
        }
        let mut p = vec![0.0; n * k * k];
        let mut ok = vec![false; n];
        p.par_chunks_mut(k * k)
            .zip(ok.par_iter_mut())
            .enumerate()
            .for_each_init(
                || Scratch::new(k, 0, r),
                |sc, (vi, (pv, okv))| {
                    let set = self.sets.row(vi);
                    let set = set.as_slice().expect("sets are standard layout");
                    self.local_hessian(vi, set, &mut sc.gram, &mut sc.h);
                    self.equality(vi, &mut sc.e_mat, &mut sc.e_rhs);
                    *okv = projected_inverse(&mut sc.h, &sc.e_mat, k, r, pv);
                },
            );
        Some(FastOps { p, ok })
    }

    /// Minimises from the feasible start `alpha` (n, k), in place: one exact sweep when no two
    /// vertices interact (geometric), projected conjugate gradients for coupled problems
    /// without bounds ([`Solver::Auto`] / [`Solver::Cg`]), the local iteration otherwise.
    pub(crate) fn solve(
        &self,
        alpha: &mut Array2<f64>,
        opts: &SolveOptions,
        progress: &mut dyn Progress,
    ) -> SkinResult<SolveReport> {
        let decoupled = self.coupling.is_diagonal();
        // One exact sweep of decoupled vertices solves each local QP once: no blocks to reuse.
        let fast = if decoupled {
            None
        } else {
            self.fast_operators()
        };
        if !opts.cg {
            return self.solve_local(alpha, opts, fast.as_ref(), decoupled, progress);
        }
        match &fast {
            Some(f) => match f.ok.iter().position(|&x| !x) {
                None => self.solve_cg(alpha, opts, f, progress),
                Some(v) => Err(qp_error(self.order[v], QpFailure::DependentConstraints)),
            },
            None => Err(SkinError::InvalidInput(
                "conjugate gradients need n k^2 <= 2^25 (memory for the per-vertex blocks); \
                 use solver='local'"
                    .into(),
            )),
        }
    }

    /// The local iteration of Sec. 3.1: sweeps over the colour classes, every class in parallel.
    fn solve_local(
        &self,
        alpha: &mut Array2<f64>,
        opts: &SolveOptions,
        fast: Option<&FastOps>,
        decoupled: bool,
        progress: &mut dyn Progress,
    ) -> SkinResult<SolveReport> {
        let k = self.k();
        let q = self.basis.q();
        let r_rows = self.rows();
        let mut e = self.error(alpha.view());
        let mut history = Vec::new();
        record(&mut history, self.objective(&e), progress)?;
        let capped = AtomicUsize::new(0);
        let mut converged = false;
        // Decoupled vertices: the exact block minimiser (no over-relaxation) in one sweep.
        let omega = if decoupled { 1.0 } else { opts.relaxation };
        let max_sweeps = if decoupled {
            opts.max_sweeps.min(1)
        } else {
            opts.max_sweeps
        };
        for sweep in 1..=max_sweeps {
            let a_all = alpha
                .as_slice_mut()
                .ok_or_else(|| SkinError::Numerical("weights not contiguous".into()))?;
            for w in self.classes.windows(2) {
                let (start, end) = (w[0], w[1]);
                let (before, rest) = e.split_at_mut(start * q);
                let (mine, after) = rest.split_at_mut((end - start) * q);
                let others = Rows {
                    before,
                    after,
                    start,
                    end,
                    q,
                };
                let a_mine = &mut a_all[start * k..end * k];
                mine.par_chunks_mut(q)
                    .zip(a_mine.par_chunks_mut(k))
                    .enumerate()
                    .try_for_each_init(
                        || Scratch::new(k, q, r_rows),
                        |sc, (i, (ev, av))| -> SkinResult<()> {
                            let conv =
                                self.local_update(start + i, av, ev, &others, omega, fast, sc)?;
                            if !conv {
                                capped.fetch_add(1, Ordering::Relaxed);
                            }
                            Ok(())
                        },
                    )?;
            }
            // E is updated incrementally; refresh it now and then against rounding drift.
            if sweep % 16 == 0 {
                e = self.error(alpha.view());
            }
            record(&mut history, self.objective(&e), progress)?;
            if decoupled || should_stop(&history, opts.tol) {
                converged = true;
                break;
            }
        }
        Ok(SolveReport {
            objective: history,
            converged,
            qp_capped: capped.into_inner(),
        })
    }
    /// Projected preconditioned conjugate gradients for the problems without bounds.
    ///
    /// The objective is the quadratic `Phi(alpha) = tr(E^T Q E)`, `E = X(alpha) - Xbar`, under
    /// the per-vertex equality rows `E_v alpha_v = e_v` only (sum to one, linear precision), so
    /// its minimiser solves one sparse linear KKT system. The preconditioner is the block-diagonal
    /// `P = diag(P_v)` of [`Problem::fast_operators`], the same `k x k` blocks the local iteration
    /// uses: `P_v g` is the equality-constrained block step, and `E_v P_v = 0`, so every search
    /// direction keeps the constraints (null-space PCG, Gould et al. 2001). Halving everything,
    /// `grad_v = B_v^T (Q E)_v` and `(H d)_v = B_v^T (Q B d)_v + eps_v d_v` (the small `eps_v` of
    /// [`Problem::local_hessian`] keeps `H` definite where the poses do not fix every weight).
    /// Every step is an exact line search, so the objective never increases; it is reported
    /// after every iteration, which plays the role of a sweep for `max_sweeps` and `tol`.
    fn solve_cg(
        &self,
        alpha: &mut Array2<f64>,
        opts: &SolveOptions,
        fast: &FastOps,
        progress: &mut dyn Progress,
    ) -> SkinResult<SolveReport> {
        let n = self.sets.nrows();
        let k = self.k();
        let q = self.basis.q();
        let a = alpha
            .as_slice_mut()
            .ok_or_else(|| SkinError::Numerical("weights not contiguous".into()))?;
        let eps: Vec<f64> = (0..n)
            .into_par_iter()
            .map_init(
                || vec![0.0; k * k],
                |g, v| {
                    let set = self.sets.row(v);
                    let set = set.as_slice().expect("sets are standard layout");
                    self.basis.gram(v, set, g);
                    let tr: f64 = (0..k).map(|t| g[t * k + t]).sum::<f64>() / k as f64;
                    1e-9 * self.coupling.diag[v] * tr
                },
            )
            .collect();
        // Partial sums in a fixed order: results do not depend on the thread schedule.
        let dot = |x: &[f64], y: &[f64]| -> f64 {
            let parts: Vec<f64> = x
                .par_chunks(4096)
                .zip(y.par_chunks(4096))
                .map(|(a, b)| a.iter().zip(b).map(|(u, w)| u * w).sum::<f64>())
                .collect();
            parts.iter().sum()
        };
        // y_v = B_v^T x_v for every vertex (x (n, q) -> y (n, k)).
        let gather = |x: &[f64], y: &mut [f64]| {
            self.per_vertex(y, k, |v, set, b, yv| {
                self.basis.transpose(v, set, &x[v * q..(v + 1) * q], b, yv)
            })
        };
        // Two-level preconditioner (see `coarse`): z_v = P_v g_v, plus Z H_c^-1 Z^T g.
        let coarse = if self.rows() == 1 {
            Some(Coarse::new(self)?)
        } else {
            None
        };
        let precondition = |g: &[f64], z: &mut [f64]| {
            z.par_chunks_mut(k).enumerate().for_each(|(v, zv)| {
                let pv = &fast.p[v * k * k..(v + 1) * k * k];
                let gv = &g[v * k..(v + 1) * k];
                for (i, zi) in zv.iter_mut().enumerate() {
                    *zi = pv[i * k..(i + 1) * k]
                        .iter()
                        .zip(gv)
                        .map(|(x, y)| x * y)
                        .sum();
                }
            });
            if let Some(c) = &coarse {
                c.add_correction(g, z);
            }
        };
        // The smooth method (`x_v` = the weight row, q = m) works on the weights alone:
        // `(H p)_v[t] = sum_u Q_vu p_u[s]` over the slots `s` of u holding handle `S_vt`, with
        // `Phi = alpha.H alpha - 2 alpha.b0 + c`, `b0 = B^T Q Xbar`, `c = tr(Xbar^T Q Xbar)`, so
        // the dense `E, R (n, m)` are never formed. The other bases keep `E = X - Xbar` and
        // `R = Q E` (q is small) and measure `Phi = tr(E^T R)` directly.
        let select = matches!(self.basis, Basis::Select { .. });
        let slots = if select {
            self.shared_slots()
        } else {
            Vec::new()
        };
        let hess_select = |p: &[f64], hp: &mut [f64]| {
            let c = &self.coupling;
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
        };
        let (mut e, mut r) = (Vec::new(), Vec::new());
        let mut g = vec![0.0; n * k];
        let (b0, c0) = if select {
            let mut qx = vec![0.0; n * q];
            let xbar = self.target.as_slice().expect("target is standard layout");
            self.coupling.apply(xbar, q, &mut qx);
            let mut b0 = vec![0.0; n * k];
            gather(&qx, &mut b0);
            (b0, dot(xbar, &qx))
        } else {
            (Vec::new(), 0.0)
        };
        // Objective and halved gradient g = B^T Q (X - Xbar) from alpha.
        let measure = |a: &[f64], g: &mut [f64], e: &mut Vec<f64>, r: &mut Vec<f64>| {
            if select {
                hess_select(a, g);
                let f = dot(a, g) - 2.0 * dot(a, &b0) + c0;
                g.par_iter_mut()
                    .zip(b0.par_iter())
                    .for_each(|(x, y)| *x -= y);
                f
            } else {
                *e = self.error(alpha_view(a, n, k));
                r.resize(n * q, 0.0);
                self.coupling.apply(e, q, r);
                gather(r, g);
                dot(e, r)
            }
        };
        let mut f = measure(a, &mut g, &mut e, &mut r);
        let mut history = Vec::new();
        record(&mut history, f, progress)?;
        let mut z = vec![0.0; n * k];
        precondition(&g, &mut z);
        let mut p: Vec<f64> = z.iter().map(|x| -x).collect();
        let mut gz = dot(&g, &z);
        let (mut d, mut w) = if select {
            (Vec::new(), Vec::new())
        } else {
            (vec![0.0; n * q], vec![0.0; n * q])
        };
        let mut hp = vec![0.0; n * k];
        let mut converged = gz <= 0.0;
        for it in 1..=opts.max_sweeps {
            if converged {
                break;
            }
            if select {
                hess_select(&p, &mut hp);
            } else {
                // D = B p, W = Q D, Hp = B^T W + eps p.
                self.per_vertex(&mut d, q, |v, set, b, dv| {
                    self.basis.position(v, set, &p[v * k..(v + 1) * k], b, dv)
                });
                self.coupling.apply(&d, q, &mut w);
                gather(&w, &mut hp);
                hp.par_chunks_mut(k)
                    .zip(p.par_chunks(k))
                    .zip(eps.par_iter())
                    .for_each(|((h, pv), &ev)| {
                        h.iter_mut().zip(pv).for_each(|(x, y)| *x += ev * y)
                    });
            }
            let php = dot(&p, &hp);
            let gp = dot(&g, &p);
            if !(php > 0.0 && php.is_finite()) || gp >= 0.0 {
                converged = true;
                break;
            }
            // Exact line search along p.
            let t = -gp / php;
            axpy(t, &p, a);
            axpy(t, &hp, &mut g);
            if it % 32 == 0 {
                // Against rounding drift: measure from scratch now and then.
                f = measure(a, &mut g, &mut e, &mut r);
            } else if select {
                // Phi(alpha + t p) = Phi + 2 t g.p + t^2 p.Hp = Phi + t g.p (g, H halved).
                f += t * gp;
            } else {
                axpy(t, &d, &mut e);
                axpy(t, &w, &mut r);
                f = dot(&e, &r);
            }
            record(&mut history, f, progress)?;
            if should_stop(&history, opts.tol) {
                converged = true;
                break;
            }
            precondition(&g, &mut z);
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
        // Put every row exactly back on sum one (each step moves it by rounding only).
        a.par_chunks_mut(k).for_each(|av| {
            let shift = (av.iter().sum::<f64>() - 1.0) / k as f64;
            av.iter_mut().for_each(|x| *x -= shift);
        });
        // The last entry is the objective of the returned weights, measured from scratch.
        let f_end = measure(a, &mut g, &mut e, &mut r);
        if let Some(last) = history.last_mut() {
            *last = f_end;
        }
        Ok(SolveReport {
            objective: history,
            converged,
            qp_capped: 0,
        })
    }
}

/// `y += t x`, in parallel.
fn axpy(t: f64, x: &[f64], y: &mut [f64]) {
    y.par_iter_mut()
        .zip(x.par_iter())
        .for_each(|(y, x)| *y += t * x);
}

/// Appends the objective after a sweep (or the start) and reports it as progress.
fn record(history: &mut Vec<f64>, f: f64, progress: &mut dyn Progress) -> SkinResult<()> {
    history.push(f);
    progress.report(Event {
        stage: "reduce",
        iteration: history.len() - 1,
        value: f,
    })
}

/// `(n, k)` view of the flat weights.
fn alpha_view(a: &[f64], n: usize, k: usize) -> ArrayView2<'_, f64> {
    ArrayView2::from_shape((n, k), a).expect("n * k weights")
}
