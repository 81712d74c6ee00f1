//! Limited-memory BFGS with a backtracking Armijo line search, for smooth unconstrained
//! minimisation. The caller supplies the objective/gradient and decides when to stop (the BBW
//! solvers stop on a measured duality gap, not on an iteration count).

use super::vector;
use crate::error::SkinResult;

/// What the caller says after each accepted iterate.
pub enum Step {
    Continue,
    Stop,
}

pub struct LbfgsOptions {
    /// Number of correction pairs kept (SciPy's default is 10).
    pub memory: usize,
    pub max_iter: usize,
}

/// Minimises `fg(x, grad) -> f` from `x` (overwritten with the final iterate). After every
/// accepted step `monitor(iteration, x, f, grad)` decides whether to go on. Returns the number of
/// iterations taken.
pub fn minimize(
    x: &mut [f64],
    opts: &LbfgsOptions,
    mut fg: impl FnMut(&[f64], &mut [f64]) -> f64,
    mut monitor: impl FnMut(usize, &[f64], f64, &[f64]) -> SkinResult<Step>,
) -> SkinResult<usize> {
    let n = x.len();
    // The iterate lives in `xc` so that accepting a step is a swap, not a copy.
    let mut xc = x.to_vec();
    let mut g = vec![0.0; n];
    let mut f = fg(&xc, &mut g);
    let mut hist = History::new(opts.memory, n);
    let mut d = vec![0.0; n];
    let mut x_new = vec![0.0; n];
    let mut g_new = vec![0.0; n];
    let mut iterations = opts.max_iter;
    if let Step::Stop = monitor(0, &xc, f, &g)? {
        return Ok(0);
    }
    for it in 1..=opts.max_iter {
        let mut slope = hist.direction(&g, &mut d);
        if slope >= 0.0 {
            // Not a descent direction (numerical trouble): restart with steepest descent.
            hist.clear();
            slope = vector::combine_dot(&mut d, (-1.0, &g), &[], &g);
        }
        // First step: scale so that |step| = 1; afterwards the BFGS scaling makes t = 1 natural.
        let mut t = if hist.is_empty() {
            1.0 / vector::dot(&d, &d).sqrt().max(1e-300)
        } else {
            1.0
        };
        let mut accepted = false;
        for _ in 0..60 {
            vector::add_scaled(&mut x_new, &xc, t, &d);
            let f_new = fg(&x_new, &mut g_new);
            if f_new.is_finite() && f_new <= f + 1e-4 * t * slope {
                hist.offer((&x_new, &xc), (&g_new, &g));
                std::mem::swap(&mut xc, &mut x_new);
                std::mem::swap(&mut g, &mut g_new);
                f = f_new;
                accepted = true;
                break;
            }
            t *= 0.5;
        }
        if !accepted {
            // The line search cannot decrease f any further: we are at machine precision.
            iterations = it;
            break;
        }
        if let Step::Stop = monitor(it, &xc, f, &g)? {
            iterations = it;
            break;
        }
    }
    x.copy_from_slice(&xc);
    Ok(iterations)
}

/// The last `memory` correction pairs `(s, y)`, oldest first, stored in single precision, with
/// their inner products. The direction is `-H g` for the L-BFGS matrix `H` of the stored
/// (rounded) pairs, so it is a descent direction like any other; storing them in half the
/// bytes halves the memory traffic that bounds the direction at large `n`. Storage of the pair
/// that drops out is reused for the next one.
struct History {
    memory: usize,
    s: Vec<Vec<f32>>,
    y: Vec<Vec<f32>>,
    /// `sy[i][j] = <s_i, y_j>` and `yy[i][j] = <y_i, y_j>` of the stored pairs.
    sy: Vec<Vec<f64>>,
    yy: Vec<Vec<f64>>,
    /// The newest pair's inner products are still to be computed; the next `direction` does it
    /// in the same pass over the pairs as its own products.
    pending: bool,
    /// The newest pair's stored values in double precision while `pending`; otherwise the
    /// buffers a new pair is formed in.
    s_new: Vec<f64>,
    y_new: Vec<f64>,
}

impl History {
    fn new(memory: usize, n: usize) -> Self {
        History {
            memory,
            s: Vec::new(),
            y: Vec::new(),
            sy: Vec::new(),
            yy: Vec::new(),
            pending: false,
            s_new: vec![0.0; n],
            y_new: vec![0.0; n],
        }
    }

    fn is_empty(&self) -> bool {
        self.s.is_empty()
    }

    fn clear(&mut self) {
        self.s.clear();
        self.y.clear();
        self.sy.clear();
        self.yy.clear();
        self.pending = false;
    }

    /// Stores the pair of an accepted step unless its curvature `<s, y>` is not safely positive.
    fn offer(&mut self, (x1, x0): (&[f64], &[f64]), (g1, g0): (&[f64], &[f64])) {
        if self.pending {
            self.products(&[]);
        }
        let [ss, yy, sy] =
            vector::correction_pair(&mut self.s_new, &mut self.y_new, (x1, x0), (g1, g0));
        if sy <= 1e-16 * ss.sqrt() * yy.sqrt() || self.memory == 0 {
            return;
        }
        let (mut s_next, mut y_next) = if self.s.len() == self.memory {
            for m in [&mut self.sy, &mut self.yy] {
                m.remove(0);
                m.iter_mut().for_each(|row| {
                    row.remove(0);
                });
            }
            (self.s.remove(0), self.y.remove(0))
        } else {
            let n = self.s_new.len();
            (vec![0.0; n], vec![0.0; n])
        };
        store_rounded(&mut s_next, &mut self.s_new);
        store_rounded(&mut y_next, &mut self.y_new);
        self.s.push(s_next);
        self.y.push(y_next);
        for m in [&mut self.sy, &mut self.yy] {
            m.iter_mut().for_each(|row| row.push(0.0));
            m.push(vec![0.0; m.len() + 1]);
        }
        self.pending = true;
    }

    /// One pass over the stored pairs: `[<s_i, v>.., <y_i, v>..]` for each `v` in `with`, and
    /// the pending inner products of the newest pair. A newest pair whose rounded curvature is
    /// not positive is dropped.
    fn products(&mut self, with: &[&[f64]]) -> Vec<Vec<f64>> {
        let k = self.s.len();
        let rows: Vec<&[f32]> = self.s.iter().chain(&self.y).map(Vec::as_slice).collect();
        let mut cols: Vec<&[f64]> = with.to_vec();
        if self.pending {
            cols.extend([self.y_new.as_slice(), self.s_new.as_slice()]);
        }
        let nc = cols.len();
        let g = vector::inner_products(&rows, &cols);
        let col = |j: usize| -> Vec<f64> { (0..2 * k).map(|i| g[i * nc + j]).collect() };
        if self.pending {
            let (y_new, s_new) = (col(with.len()), col(with.len() + 1));
            let n = k - 1;
            for i in 0..k {
                self.sy[i][n] = y_new[i];
                self.sy[n][i] = s_new[k + i];
                self.yy[i][n] = y_new[k + i];
                self.yy[n][i] = y_new[k + i];
            }
            self.pending = false;
            if self.sy[n][n] <= 0.0 || self.yy[n][n] <= 0.0 {
                for m in [&mut self.sy, &mut self.yy] {
                    m.pop();
                    m.iter_mut().for_each(|row| {
                        row.pop();
                    });
                }
                self.s.pop();
                self.y.pop();
                return self.products(with);
            }
        }
        (0..with.len()).map(col).collect()
    }

    /// `d = -H g` by the compact representation of the L-BFGS matrix (Byrd, Nocedal & Schnabel
    /// 1994, eq. 3.1, `H_0 = gamma I`); returns `<d, g>`. It equals the two-loop recursion
    /// (Nocedal & Wright, Alg. 7.4) and, like it, reads every stored vector twice; the two-loop
    /// besides reads and writes `d` once per pair.
    fn direction(&mut self, g: &[f64], d: &mut [f64]) -> f64 {
        let pq = if self.is_empty() {
            Vec::new()
        } else {
            self.products(&[g]).remove(0)
        };
        let k = self.s.len();
        if k == 0 {
            return vector::combine_dot(d, (-1.0, g), &[], g);
        }
        let (p, q) = pq.split_at(k);
        let (sy, yy) = (&self.sy, &self.yy);
        let gamma = sy[k - 1][k - 1] / yy[k - 1][k - 1];
        // a = R^{-1} p, R the upper triangle of S^T Y.
        let mut a = vec![0.0; k];
        for i in (0..k).rev() {
            let r: f64 = (i + 1..k).map(|j| sy[i][j] * a[j]).sum();
            a[i] = (p[i] - r) / sy[i][i];
        }
        // c = R^{-T} ((D + gamma Y^T Y) a - gamma q), D the diagonal of S^T Y.
        let mut c = vec![0.0; k];
        for i in 0..k {
            let t = sy[i][i] * a[i] + gamma * (0..k).map(|j| yy[i][j] * a[j]).sum::<f64>()
                - gamma * q[i];
            let r: f64 = (0..i).map(|j| sy[j][i] * c[j]).sum();
            c[i] = (t - r) / sy[i][i];
        }
        // -H g = -gamma g - S c + gamma Y a.
        let mut terms: Vec<(f64, &[f32])> = Vec::with_capacity(2 * k);
        terms.extend(c.iter().zip(&self.s).map(|(c, s)| (-c, s.as_slice())));
        terms.extend(
            a.iter()
                .zip(&self.y)
                .map(|(a, y)| (gamma * a, y.as_slice())),
        );
        vector::combine_dot(d, (-gamma, g), &terms, g)
    }
}

/// `stored <- v` in single precision, and `v <- stored` (what the products must be of).
fn store_rounded(stored: &mut [f32], v: &mut [f64]) {
    use rayon::prelude::*;
    stored
        .par_chunks_mut(1 << 14)
        .zip(v.par_chunks_mut(1 << 14))
        .for_each(|(s, v)| {
            s.iter_mut().zip(v.iter_mut()).for_each(|(s, v)| {
                *s = *v as f32;
                *v = f64::from(*s);
            })
        });
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The textbook two-loop recursion (Nocedal & Wright, Alg. 7.4), serial.
    fn two_loop(g: &[f64], s: &[Vec<f64>], y: &[Vec<f64>]) -> Vec<f64> {
        let dot = |a: &[f64], b: &[f64]| -> f64 { a.iter().zip(b).map(|(p, q)| p * q).sum() };
        let k = s.len();
        let rho: Vec<f64> = (0..k).map(|i| 1.0 / dot(&s[i], &y[i])).collect();
        let mut q = g.to_vec();
        let mut alpha = vec![0.0; k];
        for i in (0..k).rev() {
            alpha[i] = rho[i] * dot(&s[i], &q);
            q.iter_mut()
                .zip(&y[i])
                .for_each(|(qi, yi)| *qi -= alpha[i] * yi);
        }
        let gamma = dot(&s[k - 1], &y[k - 1]) / dot(&y[k - 1], &y[k - 1]);
        q.iter_mut().for_each(|v| *v *= gamma);
        for i in 0..k {
            let beta = rho[i] * dot(&y[i], &q);
            q.iter_mut()
                .zip(&s[i])
                .for_each(|(qi, si)| *qi += (alpha[i] - beta) * si);
        }
        q.iter().map(|v| -v).collect()
    }

    #[test]
    fn compact_direction_equals_the_textbook_two_loop_as_pairs_roll_over() {
        // Steps of a strictly convex quadratic 1/2 x^T diag(h) x give pairs with <s, y> > 0.
        let n = 40_000;
        let h: Vec<f64> = (0..n).map(|i| 1.0 + (i % 97) as f64).collect();
        let mut hist = History::new(4, n);
        let mut x0: Vec<f64> = (0..n).map(|i| ((i * 31) % 17) as f64 - 8.0).collect();
        let (mut kept_s, mut kept_y): (Vec<Vec<f64>>, Vec<Vec<f64>>) = (vec![], vec![]);
        for step in 0..7 {
            let x1: Vec<f64> = x0
                .iter()
                .enumerate()
                .map(|(i, v)| v * (0.5 + 0.05 * ((i + step) % 7) as f64))
                .collect();
            let g0: Vec<f64> = x0.iter().zip(&h).map(|(x, h)| x * h).collect();
            let g1: Vec<f64> = x1.iter().zip(&h).map(|(x, h)| x * h).collect();
            hist.offer((&x1, &x0), (&g1, &g0));
            // The history keeps its pairs in single precision.
            let rounded = |v: f64| f64::from(v as f32);
            kept_s.push(x1.iter().zip(&x0).map(|(a, b)| rounded(a - b)).collect());
            kept_y.push(g1.iter().zip(&g0).map(|(a, b)| rounded(a - b)).collect());
            if kept_s.len() > 4 {
                kept_s.remove(0);
                kept_y.remove(0);
            }
            if step == 3 {
                x0 = x1; // two pairs offered before the next direction
                continue;
            }
            let mut d = vec![0.0; n];
            let slope = hist.direction(&g1, &mut d);
            let dg: f64 = d.iter().zip(&g1).map(|(a, b)| a * b).sum();
            assert!((slope - dg).abs() <= 1e-12 * dg.abs(), "step {step}");
            let expect = two_loop(&g1, &kept_s, &kept_y);
            let scale = expect.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            let err = d
                .iter()
                .zip(&expect)
                .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
            assert!(err <= 1e-10 * scale, "step {step}: {err} vs scale {scale}");
            x0 = x1;
        }
    }
}
