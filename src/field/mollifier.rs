//! Hard constraints by reparameterisation (Sec. 4.3, App. B): the Lagrange mollifier of
//! eqs. 7, 15, 16 for handles and painted Dirichlet conditions, and the bump function.
//!
//! Every constraint is a primitive `c` (a bone segment, a point handle, or a painted point) with
//! a target weight vector `g_c` (one-hot for handles, user weights for paint). With
//! `w_c = w(d_c(x))` the bump of the distance to `c` (eq. 16, radius `eps`), eq. 15 generalises to
//!   `e~(x) = max_c w_c * sum_c w_c g_c / sum_c w_c`           (0 outside every neighbourhood)
//! and the weights are `alpha = e~ + (1 - sum e~) alpha_hat` (eq. 7). For one-hot targets this
//! is exactly eq. 15; on a handle `e~` is its one-hot row, so the Lagrange property holds.

use super::primitives::closest_on_segment;
use super::sampling::dist2;
use super::HashGrid;
use crate::error::SkinResult;
use crate::invalid;

/// The smooth step of eq. 16: 0 for `t <= 0`, 1 for `t >= 1`, all derivatives 0 at both ends.
#[inline]
pub fn smooth_step(t: f64) -> f64 {
    if t <= 0.0 {
        0.0
    } else if t >= 1.0 {
        1.0
    } else {
        let a = (-1.0 / t).exp();
        let b = (-1.0 / (1.0 - t)).exp();
        a / (a + b)
    }
}

/// Bump `w(d) = 1 - smooth_step(d^2 / eps^2)` (eq. 16): 1 at 0, 0 from `eps` on, `w'(0) = 0`.
#[inline]
pub fn bump(d: f64, eps: f64) -> f64 {
    1.0 - smooth_step(d * d / (eps * eps))
}

/// Handles and painted points with their targets.
#[derive(Clone, Debug)]
pub struct Constraints<const D: usize> {
    /// Number of weight columns K.
    pub k: usize,
    /// Handle primitives: segment `a -> b` (`a == b` for point handles) and its column.
    pub handles: Vec<([f64; D], [f64; D], usize)>,
    /// Painted Dirichlet points, their K-vectors (row-major) and a grid over them.
    pub painted: Vec<[f64; D]>,
    pub painted_w: Vec<f64>,
    painted_grid: Option<HashGrid<D>>,
    /// Radius of every neighbourhood.
    pub eps: f64,
}

impl<const D: usize> Constraints<D> {
    /// Constraints of `handles` (segments with their column, K columns) with radius `eps`.
    pub fn new(k: usize, handles: Vec<([f64; D], [f64; D], usize)>, eps: f64) -> Self {
        Constraints {
            k,
            handles,
            painted: Vec::new(),
            painted_w: Vec::new(),
            painted_grid: None,
            eps,
        }
    }

    /// Adds painted points `p` with weight rows `w` (row-major, K each; rows must be >= 0 and
    /// sum to 1). Points replace earlier paint within `1e-12` of them.
    pub fn paint(&mut self, p: &[[f64; D]], w: &[f64]) -> SkinResult<()> {
        if w.len() != p.len() * self.k {
            return invalid!("paint needs one weight row of {} per point", self.k);
        }
        for (r, row) in w.chunks(self.k).enumerate() {
            let s: f64 = row.iter().sum();
            if row.iter().any(|&x| x.is_nan() || x < 0.0) || (s - 1.0).abs() > 1e-9 {
                return invalid!("painted weight row {r} must be >= 0 and sum to 1 (sums to {s})");
            }
        }
        for (q, row) in p.iter().zip(w.chunks(self.k)) {
            if let Some(j) = self.painted.iter().position(|x| dist2(x, q) < 1e-24) {
                self.painted_w[j * self.k..(j + 1) * self.k].copy_from_slice(row);
            } else {
                self.painted.push(*q);
                self.painted_w.extend_from_slice(row);
            }
        }
        self.rebuild()
    }

    /// Sets the radius (the paper shrinks it with sigma when upsampling, App. A).
    pub fn set_eps(&mut self, eps: f64) -> SkinResult<()> {
        self.eps = eps;
        self.rebuild()
    }

    fn rebuild(&mut self) -> SkinResult<()> {
        self.painted_grid = if self.painted.is_empty() {
            None
        } else {
            let a = super::sampling::to_array(&self.painted);
            Some(HashGrid::<D>::new(a.view(), self.eps)?)
        };
        Ok(())
    }

    /// Mollified indicator `e~(x)` (K values, into `e`); returns `sum e~` (0 when `x` is in no
    /// neighbourhood, then `e` is all zero).
    pub fn eval(&self, x: &[f64; D], e: &mut [f64], near: &mut Vec<usize>) -> f64 {
        e.iter_mut().for_each(|v| *v = 0.0);
        let (mut wmax, mut wsum) = (0.0f64, 0.0f64);
        for (a, b, col) in &self.handles {
            let c = closest_on_segment(x, a, b);
            let w = bump(dist2(x, &c).sqrt(), self.eps);
            if w > 0.0 {
                e[*col] += w;
                wmax = wmax.max(w);
                wsum += w;
            }
        }
        if let Some(g) = &self.painted_grid {
            near.clear();
            g.radius(x, self.eps, near);
            for &j in near.iter() {
                let w = bump(dist2(x, &self.painted[j]).sqrt(), self.eps);
                if w > 0.0 {
                    let row = &self.painted_w[j * self.k..(j + 1) * self.k];
                    for (a, &b) in e.iter_mut().zip(row) {
                        *a += w * b;
                    }
                    wmax = wmax.max(w);
                    wsum += w;
                }
            }
        }
        if wsum == 0.0 {
            return 0.0;
        }
        let s = wmax / wsum;
        e.iter_mut().for_each(|v| *v *= s);
        wmax
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bump_and_partition() {
        assert_eq!(bump(0.0, 0.1), 1.0);
        assert_eq!(bump(0.1, 0.1), 0.0);
        assert!((bump(0.05, 0.1) - (1.0 - smooth_step(0.25))).abs() < 1e-15);
        let c = Constraints::<2>::new(
            2,
            vec![([0.0, 0.0], [1.0, 0.0], 0), ([1.0, 0.0], [1.0, 1.0], 1)],
            0.1,
        );
        let mut e = vec![0.0; 2];
        let mut near = Vec::new();
        // On bone 0 only: one-hot.
        assert_eq!(c.eval(&[0.5, 0.0], &mut e, &mut near), 1.0);
        assert_eq!(e, vec![1.0, 0.0]);
        // At the shared joint: split equally.
        c.eval(&[1.0, 0.0], &mut e, &mut near);
        assert_eq!(e, vec![0.5, 0.5]);
        assert_eq!(c.eval(&[0.5, 0.5], &mut e, &mut near), 0.0);
    }
}
