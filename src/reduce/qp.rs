//! Exact solver for the small per-vertex quadratic programs of the local iteration (paper 002,
//! Sec. 3.1): `k` unknowns, `r` equality rows (sum to one, plus linear precision for cages) and
//! optional non-negativity,
//!
//! ```text
//!   min_x  1/2 x^T H x + g^T x   s.t.  E x = e,  x >= 0 (optional)
//! ```
//!
//! with `H` symmetric positive definite. A primal active-set method (Nocedal & Wright, Alg. 16.3)
//! solves it exactly: every iterate stays feasible, each equality-constrained subproblem is solved
//! through a Cholesky factor of `H_FF` and the `r x r` Schur complement `E_F H_FF^-1 E_F^T`. An
//! infeasible start (negative entries, or linear precision not yet satisfied) is first moved into
//! the feasible set by Lawson & Hanson's non-negative least squares on `E x = e`.
//!
//! The multipliers are returned so callers (and tests) can check the KKT conditions
//! `H x + g + E^T lambda - mu = 0`, `mu >= 0`, `mu_i x_i = 0`.

/// Why a local QP has no solution.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum QpFailure {
    /// `H` (restricted to the free variables) is not positive definite.
    NotPositiveDefinite,
    /// The equality rows restricted to the free variables are linearly dependent.
    DependentConstraints,
    /// No `x >= 0` satisfies `E x = e`.
    Infeasible,
}

/// One local QP; matrices are dense row-major.
pub(crate) struct LocalQp<'a> {
    /// `k x k` symmetric positive definite.
    pub h: &'a [f64],
    /// `k`
    pub g: &'a [f64],
    /// `r x k`
    pub e_mat: &'a [f64],
    /// `r`
    pub e_rhs: &'a [f64],
    pub nonneg: bool,
}

/// Result of [`solve`]: the solution is written into the caller's `x`.
#[derive(Debug, Clone, Copy)]
pub(crate) struct QpStatus {
    pub iterations: usize,
    /// False when the active-set iteration cap was hit; `x` is then feasible and no worse than
    /// the start, but not optimal.
    pub converged: bool,
}

/// Scratch space reused across the many local QPs one thread solves.
#[derive(Default)]
pub(crate) struct QpWork {
    free: Vec<bool>,
    fidx: Vec<usize>,
    chol: Vec<f64>,
    y: Vec<f64>,
    z: Vec<f64>,
    s: Vec<f64>,
    s_copy: Vec<f64>,
    rhs: Vec<f64>,
    grad: Vec<f64>,
}

/// In-place Cholesky `A = L L^T` of the `n x n` row-major matrix (lower triangle used/overwritten).
/// Fails when a pivot is not clearly positive relative to the diagonal scale.
pub(crate) fn cholesky(a: &mut [f64], n: usize) -> bool {
    let scale = (0..n).map(|i| a[i * n + i].abs()).fold(0.0, f64::max);
    for j in 0..n {
        let mut d = a[j * n + j];
        for p in 0..j {
            d -= a[j * n + p] * a[j * n + p];
        }
        if !d.is_finite() || d <= 1e-14 * scale {
            return false;
        }
        let d = d.sqrt();
        a[j * n + j] = d;
        for i in j + 1..n {
            let mut s = a[i * n + j];
            for p in 0..j {
                s -= a[i * n + p] * a[j * n + p];
            }
            a[i * n + j] = s / d;
        }
    }
    true
}

/// Solves `L L^T x = b` in place with the factor from [`cholesky`].
pub(crate) fn cholesky_solve(l: &[f64], n: usize, b: &mut [f64]) {
    for i in 0..n {
        let mut s = b[i];
        for p in 0..i {
            s -= l[i * n + p] * b[p];
        }
        b[i] = s / l[i * n + i];
    }
    for i in (0..n).rev() {
        let mut s = b[i];
        for p in i + 1..n {
            s -= l[p * n + i] * b[p];
        }
        b[i] = s / l[i * n + i];
    }
}

impl QpWork {
    /// Solves the equality-constrained QP on the free set `F` (with `x_W = 0`):
    /// `min 1/2 y^T H_FF y + g_F^T y  s.t.  E_F y = e`. Leaves `y` (length |F|) and
    /// `lambda` (length r) in `self.y` / `lambda`.
    fn solve_eqp(&mut self, qp: &LocalQp, lambda: &mut [f64]) -> Result<(), QpFailure> {
        let k = qp.g.len();
        let r = qp.e_rhs.len();
        self.fidx.clear();
        self.fidx.extend((0..k).filter(|&i| self.free[i]));
        let f = self.fidx.len();
        self.chol.clear();
        for &i in &self.fidx {
            for &j in &self.fidx {
                self.chol.push(qp.h[i * k + j]);
            }
        }
        if !cholesky(&mut self.chol, f) {
            return Err(QpFailure::NotPositiveDefinite);
        }
        // y0 = -H^-1 g_F
        self.y.clear();
        self.y.extend(self.fidx.iter().map(|&i| -qp.g[i]));
        cholesky_solve(&self.chol, f, &mut self.y);
        // Z = H^-1 E_F^T, stored column by column (r columns of length f).
        self.z.clear();
        for c in 0..r {
            let start = self.z.len();
            self.z
                .extend(self.fidx.iter().map(|&i| qp.e_mat[c * k + i]));
            cholesky_solve(&self.chol, f, &mut self.z[start..start + f]);
        }
        // S = E_F Z (r x r), rhs = E_F y0 - e.
        self.s.clear();
        self.rhs.clear();
        for a in 0..r {
            for b in 0..r {
                let zb = &self.z[b * f..(b + 1) * f];
                let v: f64 = self
                    .fidx
                    .iter()
                    .zip(zb)
                    .map(|(&i, z)| qp.e_mat[a * k + i] * z)
                    .sum();
                self.s.push(v);
            }
            let ey: f64 = self
                .fidx
                .iter()
                .zip(&self.y)
                .map(|(&i, y)| qp.e_mat[a * k + i] * y)
                .sum();
            self.rhs.push(ey - qp.e_rhs[a]);
        }
        if r > 0 {
            self.s_copy.clear();
            self.s_copy.extend_from_slice(&self.s);
            if !cholesky(&mut self.s, r) {
                // E_F has dependent rows: this happens when bounds leave fewer free variables
                // than equality rows at a start that satisfies E x = e only to rounding (the
                // feasible set is then locally a point). Damped least squares keeps the
                // consistent part; a truly inconsistent system is rejected by the final
                // residual check in `solve`.
                let tr: f64 = (0..r).map(|i| self.s_copy[i * r + i]).sum::<f64>() / r as f64;
                self.s.copy_from_slice(&self.s_copy);
                for i in 0..r {
                    self.s[i * r + i] += 1e-12 * tr + f64::MIN_POSITIVE;
                }
                if !cholesky(&mut self.s, r) {
                    return Err(QpFailure::DependentConstraints);
                }
            }
            cholesky_solve(&self.s, r, &mut self.rhs);
        }
        lambda.copy_from_slice(&self.rhs[..r]);
        // y = y0 - Z lambda
        for (c, &l) in lambda.iter().enumerate() {
            for (yi, zi) in self.y.iter_mut().zip(&self.z[c * f..(c + 1) * f]) {
                *yi -= zi * l;
            }
        }
        Ok(())
    }

    /// Gradient of the Lagrangian without the bound term: `H x + g + E^T lambda`.
    fn lagrangian_gradient(&mut self, qp: &LocalQp, x: &[f64], lambda: &[f64]) {
        let k = x.len();
        self.grad.clear();
        for i in 0..k {
            let mut v = qp.g[i];
            for j in 0..k {
                v += qp.h[i * k + j] * x[j];
            }
            for (c, l) in lambda.iter().enumerate() {
                v += qp.e_mat[c * k + i] * l;
            }
            self.grad.push(v);
        }
    }
}

/// Residual `max |E x - e|` and the scale it is measured against.
fn equality_residual(qp: &LocalQp, x: &[f64]) -> (f64, f64) {
    let k = x.len();
    let mut res: f64 = 0.0;
    let mut scale: f64 = 0.0;
    for (c, &ec) in qp.e_rhs.iter().enumerate() {
        let row = &qp.e_mat[c * k..(c + 1) * k];
        let mut v = -ec;
        let mut s = ec.abs();
        for (a, b) in row.iter().zip(x) {
            v += a * b;
            s = s.max((a * b).abs());
        }
        res = res.max(v.abs());
        scale = scale.max(s);
    }
    (res, scale.max(f64::MIN_POSITIVE))
}

/// Lawson & Hanson NNLS for `min |E x - e|^2, x >= 0`; used only to find a feasible start.
fn feasible_start(qp: &LocalQp, x: &mut [f64]) -> Result<(), QpFailure> {
    let k = x.len();
    let r = qp.e_rhs.len();
    let e = qp.e_mat;
    x.iter_mut().for_each(|v| *v = 0.0);
    let mut passive = vec![false; k];
    let mut z = vec![0.0; k];
    let resid = |x: &[f64]| -> Vec<f64> {
        (0..r)
            .map(|c| qp.e_rhs[c] - (0..k).map(|i| e[c * k + i] * x[i]).sum::<f64>())
            .collect()
    };
    let col_scale = (0..k)
        .map(|i| (0..r).map(|c| e[c * k + i].abs()).fold(0.0, f64::max))
        .fold(0.0, f64::max)
        .max(f64::MIN_POSITIVE);
    let rhs_scale = qp.e_rhs.iter().fold(0.0f64, |a, b| a.max(b.abs())).max(1.0);
    // Least squares on the passive set through the normal equations (|P| <= r + a few).
    let ls = |passive: &[bool], z: &mut [f64]| -> bool {
        let p: Vec<usize> = (0..k).filter(|&i| passive[i]).collect();
        let np = p.len();
        let mut a = vec![0.0; np * np];
        let mut b = vec![0.0; np];
        for (ii, &i) in p.iter().enumerate() {
            for (jj, &j) in p.iter().enumerate() {
                a[ii * np + jj] = (0..r).map(|c| e[c * k + i] * e[c * k + j]).sum();
            }
            b[ii] = (0..r).map(|c| e[c * k + i] * qp.e_rhs[c]).sum();
        }
        let tr: f64 = (0..np).map(|i| a[i * np + i]).sum();
        for i in 0..np {
            a[i * np + i] += 1e-15 * tr;
        }
        if !cholesky(&mut a, np) {
            return false;
        }
        cholesky_solve(&a, np, &mut b);
        z.iter_mut().for_each(|v| *v = 0.0);
        for (ii, &i) in p.iter().enumerate() {
            z[i] = b[ii];
        }
        true
    };
    for _outer in 0..(3 * k + 10) {
        let res = resid(x);
        let w: Vec<f64> = (0..k)
            .map(|i| (0..r).map(|c| e[c * k + i] * res[c]).sum())
            .collect();
        let cand = (0..k)
            .filter(|&i| !passive[i])
            .max_by(|&a, &b| w[a].total_cmp(&w[b]));
        let Some(j) = cand else { break };
        if w[j] <= 1e-13 * col_scale * rhs_scale {
            break;
        }
        passive[j] = true;
        for _inner in 0..(3 * k + 10) {
            if !ls(&passive, &mut z) {
                passive[j] = false;
                break;
            }
            if (0..k).filter(|&i| passive[i]).all(|i| z[i] > 0.0) {
                x.copy_from_slice(&z);
                break;
            }
            let mut alpha = f64::INFINITY;
            for i in (0..k).filter(|&i| passive[i] && z[i] <= 0.0) {
                alpha = alpha.min(x[i] / (x[i] - z[i]));
            }
            for i in 0..k {
                x[i] += alpha * (z[i] - x[i]);
                if passive[i] && x[i] <= 1e-15 {
                    x[i] = 0.0;
                    passive[i] = false;
                }
            }
        }
    }
    let (res, scale) = equality_residual(qp, x);
    if res > 1e-9 * scale {
        return Err(QpFailure::Infeasible);
    }
    Ok(())
}

/// Rejects a result that misses `E x = e` (only possible with dependent equality rows).
fn consistent(qp: &LocalQp, x: &[f64], status: QpStatus) -> Result<QpStatus, QpFailure> {
    let (res, scale) = equality_residual(qp, x);
    if res > 1e-9 * scale {
        return Err(QpFailure::DependentConstraints);
    }
    Ok(status)
}

/// Solves one local QP exactly. `x` holds the start on entry (used as a warm start when it is
/// feasible) and the solution on exit; `lambda (r)` and `mu (k)` receive the multipliers.
pub(crate) fn solve(
    qp: &LocalQp,
    x: &mut [f64],
    lambda: &mut [f64],
    mu: &mut [f64],
    work: &mut QpWork,
) -> Result<QpStatus, QpFailure> {
    let k = qp.g.len();
    let r = qp.e_rhs.len();
    debug_assert!(qp.h.len() == k * k && qp.e_mat.len() == r * k && x.len() == k);
    mu.iter_mut().for_each(|m| *m = 0.0);
    work.free.clear();
    work.free.resize(k, true);
    if !qp.nonneg {
        // Equality constraints only: one KKT solve.
        work.solve_eqp(qp, lambda)?;
        x.copy_from_slice(&work.y);
        return consistent(
            qp,
            x,
            QpStatus {
                iterations: 1,
                converged: true,
            },
        );
    }
    let (res, scale) = equality_residual(qp, x);
    if x.iter().any(|&v| v.is_nan() || v < 0.0) || res > 1e-12 * scale {
        feasible_start(qp, x)?;
    }
    // Working set: with the single sum row, every zero entry can start active (some entry is
    // positive, so E_F keeps full rank). With more rows start empty, which keeps the working
    // set independent of the equality rows (N&W 16.3).
    if r == 1 {
        let row_ok = |i: usize| qp.e_mat[i] != 0.0;
        let keep = (0..k).any(|i| x[i] > 0.0 && row_ok(i));
        if keep {
            for i in 0..k {
                work.free[i] = x[i] > 0.0;
            }
        }
    }
    let max_iter = 5 * k + 20;
    for it in 1..=max_iter {
        work.solve_eqp(qp, lambda)?;
        // Step p = y - x_F; longest feasible step length t <= 1.
        let mut t = 1.0;
        let mut block = None;
        for (a, &i) in work.fidx.iter().enumerate() {
            let p = work.y[a] - x[i];
            if p < 0.0 {
                let ti = x[i] / -p;
                if ti < t {
                    t = ti;
                    block = Some(i);
                }
            }
        }
        if let Some(b) = block {
            for (a, &i) in work.fidx.iter().enumerate() {
                let v = x[i] + t * (work.y[a] - x[i]);
                // Rounding may push a non-blocking entry a hair below zero: keep it at zero
                // (still free; if it must stay there the next step blocks on it).
                x[i] = if v > 0.0 { v } else { 0.0 };
            }
            x[b] = 0.0;
            work.free[b] = false;
            continue;
        }
        for (a, &i) in work.fidx.iter().enumerate() {
            x[i] = work.y[a].max(0.0);
        }
        // Full step: check the bound multipliers of the working set.
        work.lagrangian_gradient(qp, x, lambda);
        let gscale = work
            .grad
            .iter()
            .chain(qp.g.iter())
            .fold(0.0f64, |a, b| a.max(b.abs()))
            .max(f64::MIN_POSITIVE);
        let mut worst = None;
        let mut worst_mu = -1e-12 * gscale;
        for i in 0..k {
            if !work.free[i] && work.grad[i] < worst_mu {
                worst_mu = work.grad[i];
                worst = Some(i);
            }
        }
        match worst {
            Some(i) => work.free[i] = true,
            None => {
                for i in 0..k {
                    mu[i] = if work.free[i] { 0.0 } else { work.grad[i] };
                }
                return consistent(
                    qp,
                    x,
                    QpStatus {
                        iterations: it,
                        converged: true,
                    },
                );
            }
        }
    }
    work.lagrangian_gradient(qp, x, lambda);
    for i in 0..k {
        mu[i] = if work.free[i] { 0.0 } else { work.grad[i] };
    }
    Ok(QpStatus {
        iterations: max_iter,
        converged: false,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn simplex_projection_matches_closed_form() {
        // min 1/2 |x - c|^2 on the simplex; c = (0.8, 0.6, -0.5) -> (0.6, 0.4, 0).
        let h = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0];
        let g = [-0.8, -0.6, 0.5];
        let e = [1.0, 1.0, 1.0];
        let qp = LocalQp {
            h: &h,
            g: &g,
            e_mat: &e,
            e_rhs: &[1.0],
            nonneg: true,
        };
        let mut x = [1.0 / 3.0; 3];
        let (mut l, mut mu) = ([0.0], [0.0; 3]);
        let st = solve(&qp, &mut x, &mut l, &mut mu, &mut QpWork::default()).unwrap();
        assert!(st.converged);
        assert!((x[0] - 0.6).abs() < 1e-14 && (x[1] - 0.4).abs() < 1e-14 && x[2] == 0.0);
        assert!(mu[2] > 0.0);
    }

    #[test]
    fn infeasible_start_is_repaired() {
        // x >= 0, x0 + x1 + x2 = 1, x0 - x2 = 0.5
        let h = [2.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0];
        let g = [0.0, 0.0, 0.0];
        let e = [1.0, 1.0, 1.0, 1.0, 0.0, -1.0];
        let qp = LocalQp {
            h: &h,
            g: &g,
            e_mat: &e,
            e_rhs: &[1.0, 0.5],
            nonneg: true,
        };
        let mut x = [-1.0, 3.0, 0.0];
        let (mut l, mut mu) = ([0.0; 2], [0.0; 3]);
        solve(&qp, &mut x, &mut l, &mut mu, &mut QpWork::default()).unwrap();
        assert!((x[0] + x[1] + x[2] - 1.0).abs() < 1e-14);
        assert!((x[0] - x[2] - 0.5).abs() < 1e-14);
        assert!(x.iter().all(|&v| v >= 0.0));
    }
}
