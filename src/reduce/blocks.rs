//! Per-vertex projected inverses `P_v`: the equality-constrained block step of the local
//! iteration and the block preconditioner of conjugate gradients.

use rayon::prelude::*;

use super::problem::{Problem, Scratch};
use super::qp;

/// Most entries of the per-vertex `k x k` blocks kept in memory (256 MB).
pub(crate) const FAST_LIMIT: usize = 1 << 25;

/// Precomputed per-vertex projected inverses (see [`Problem::fast_operators`]).
pub(super) struct FastOps {
    /// `(n, k, k)`.
    pub(super) p: Vec<f64>,
    /// False where the constraints were degenerate (that vertex always runs the QP).
    pub(super) ok: Vec<bool>,
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

impl Problem<'_> {
    /// Per-vertex projected inverses `P_v = H^-1 - H^-1 E^T (E H^-1 E^T)^-1 E H^-1`: with them
    /// an equality-constrained block step is one `k x k` product. `None` when they would take
    /// more than [`FAST_LIMIT`] entries (then every step runs the active-set QP).
    pub(super) fn fast_operators(&self) -> Option<FastOps> {
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
}
