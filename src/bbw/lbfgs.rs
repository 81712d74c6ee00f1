//! Limited-memory BFGS with a backtracking Armijo line search, for smooth unconstrained
//! minimisation. The caller supplies the objective/gradient and decides when to stop (the BBW
//! solvers stop on a measured duality gap, not on an iteration count).

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
    let mut g = vec![0.0; n];
    let mut f = fg(x, &mut g);
    let mut s_hist: Vec<Vec<f64>> = Vec::new();
    let mut y_hist: Vec<Vec<f64>> = Vec::new();
    let mut rho_hist: Vec<f64> = Vec::new();
    let mut d = vec![0.0; n];
    let mut x_new = vec![0.0; n];
    let mut g_new = vec![0.0; n];
    if let Step::Stop = monitor(0, x, f, &g)? {
        return Ok(0);
    }
    for it in 1..=opts.max_iter {
        two_loop(&g, &s_hist, &y_hist, &rho_hist, &mut d);
        let mut slope: f64 = d.iter().zip(&g).map(|(a, b)| a * b).sum();
        if slope >= 0.0 {
            // Not a descent direction (numerical trouble): restart with steepest descent.
            s_hist.clear();
            y_hist.clear();
            rho_hist.clear();
            for (di, gi) in d.iter_mut().zip(&g) {
                *di = -gi;
            }
            slope = -g.iter().map(|v| v * v).sum::<f64>();
        }
        // First step: scale so that |step| = 1; afterwards the BFGS scaling makes t = 1 natural.
        let mut t = if s_hist.is_empty() {
            1.0 / d.iter().map(|v| v * v).sum::<f64>().sqrt().max(1e-300)
        } else {
            1.0
        };
        let mut accepted = false;
        for _ in 0..60 {
            for i in 0..n {
                x_new[i] = x[i] + t * d[i];
            }
            let f_new = fg(&x_new, &mut g_new);
            if f_new.is_finite() && f_new <= f + 1e-4 * t * slope {
                let mut s = vec![0.0; n];
                let mut yv = vec![0.0; n];
                for i in 0..n {
                    s[i] = x_new[i] - x[i];
                    yv[i] = g_new[i] - g[i];
                }
                let sy: f64 = s.iter().zip(&yv).map(|(a, b)| a * b).sum();
                if sy
                    > 1e-16
                        * s.iter().map(|v| v * v).sum::<f64>().sqrt()
                        * yv.iter().map(|v| v * v).sum::<f64>().sqrt()
                {
                    if s_hist.len() == opts.memory {
                        s_hist.remove(0);
                        y_hist.remove(0);
                        rho_hist.remove(0);
                    }
                    s_hist.push(s);
                    y_hist.push(yv);
                    rho_hist.push(1.0 / sy);
                }
                x.copy_from_slice(&x_new);
                g.copy_from_slice(&g_new);
                f = f_new;
                accepted = true;
                break;
            }
            t *= 0.5;
        }
        if !accepted {
            // The line search cannot decrease f any further: we are at machine precision.
            return Ok(it);
        }
        if let Step::Stop = monitor(it, x, f, &g)? {
            return Ok(it);
        }
    }
    Ok(opts.max_iter)
}

/// The L-BFGS two-loop recursion: `d = -H g`.
fn two_loop(g: &[f64], s: &[Vec<f64>], y: &[Vec<f64>], rho: &[f64], d: &mut [f64]) {
    let k = s.len();
    d.iter_mut().zip(g).for_each(|(di, gi)| *di = -gi);
    let mut alpha = vec![0.0; k];
    for i in (0..k).rev() {
        let a = rho[i] * s[i].iter().zip(d.iter()).map(|(p, q)| p * q).sum::<f64>();
        alpha[i] = a;
        d.iter_mut().zip(&y[i]).for_each(|(di, yi)| *di -= a * yi);
    }
    if k > 0 {
        let yy: f64 = y[k - 1].iter().map(|v| v * v).sum();
        let gamma = 1.0 / (rho[k - 1] * yy);
        d.iter_mut().for_each(|di| *di *= gamma);
    }
    for i in 0..k {
        let beta = rho[i] * y[i].iter().zip(d.iter()).map(|(p, q)| p * q).sum::<f64>();
        d.iter_mut()
            .zip(&s[i])
            .for_each(|(di, si)| *di += (alpha[i] - beta) * si);
    }
}
