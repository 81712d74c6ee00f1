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
        hist.direction(&g, &mut d);
        let mut slope = vector::dot(&d, &g);
        if slope >= 0.0 {
            // Not a descent direction (numerical trouble): restart with steepest descent.
            hist.clear();
            slope = vector::update_dot(0.0, &mut d, -1.0, &g, Some(&g));
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

/// The last `memory` correction pairs `(s, y)` with `rho = 1 / <s, y>`, oldest first. Storage
/// of the pair that drops out is reused for the next one.
struct History {
    memory: usize,
    s: Vec<Vec<f64>>,
    y: Vec<Vec<f64>>,
    rho: Vec<f64>,
    /// `<y, y>` of the newest pair (the initial Hessian scaling).
    yy_last: f64,
    /// Buffers for the next pair.
    s_free: Vec<f64>,
    y_free: Vec<f64>,
}

impl History {
    fn new(memory: usize, n: usize) -> Self {
        History {
            memory,
            s: Vec::new(),
            y: Vec::new(),
            rho: Vec::new(),
            yy_last: 0.0,
            s_free: vec![0.0; n],
            y_free: vec![0.0; n],
        }
    }

    fn is_empty(&self) -> bool {
        self.s.is_empty()
    }

    fn clear(&mut self) {
        self.s.clear();
        self.y.clear();
        self.rho.clear();
    }

    /// Stores the pair of an accepted step unless its curvature `<s, y>` is not safely positive.
    fn offer(&mut self, (x1, x0): (&[f64], &[f64]), (g1, g0): (&[f64], &[f64])) {
        let [ss, yy, sy] =
            vector::correction_pair(&mut self.s_free, &mut self.y_free, (x1, x0), (g1, g0));
        if sy <= 1e-16 * ss.sqrt() * yy.sqrt() || self.memory == 0 {
            return;
        }
        let n = self.s_free.len();
        let (s_next, y_next) = if self.s.len() == self.memory {
            self.rho.remove(0);
            (self.s.remove(0), self.y.remove(0))
        } else {
            (vec![0.0; n], vec![0.0; n])
        };
        self.s.push(std::mem::replace(&mut self.s_free, s_next));
        self.y.push(std::mem::replace(&mut self.y_free, y_next));
        self.rho.push(1.0 / sy);
        self.yy_last = yy;
    }

    /// The two-loop recursion (Nocedal & Wright, Alg. 7.4), `d = -H g`. Each update of `d` is
    /// fused with the inner product the next step needs, so `d` is streamed once per stored
    /// vector.
    fn direction(&self, g: &[f64], d: &mut [f64]) {
        let k = self.s.len();
        let mut alpha = vec![0.0; k];
        let mut next = vector::update_dot(0.0, d, -1.0, g, self.s.last().map(|v| v.as_slice()));
        for i in (0..k).rev() {
            alpha[i] = self.rho[i] * next;
            let z = if i > 0 {
                Some(self.s[i - 1].as_slice())
            } else {
                None
            };
            next = vector::update_dot(1.0, d, -alpha[i], &self.y[i], z);
        }
        if k == 0 {
            return;
        }
        let gamma = 1.0 / (self.rho[k - 1] * self.yy_last);
        next = vector::update_dot(gamma, d, 0.0, g, Some(&self.y[0]));
        for (i, (a, rho)) in alpha.iter().zip(&self.rho).enumerate() {
            let beta = rho * next;
            let z = self.y.get(i + 1).map(|v| v.as_slice());
            next = vector::update_dot(1.0, d, a - beta, &self.s[i], z);
        }
    }
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
    fn fused_direction_equals_the_textbook_two_loop_as_pairs_roll_over() {
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
            kept_s.push(x1.iter().zip(&x0).map(|(a, b)| a - b).collect());
            kept_y.push(g1.iter().zip(&g0).map(|(a, b)| a - b).collect());
            if kept_s.len() > 4 {
                kept_s.remove(0);
                kept_y.remove(0);
            }
            let mut d = vec![0.0; n];
            hist.direction(&g1, &mut d);
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
