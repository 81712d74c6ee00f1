//! Adam (Kingma & Ba 2014) with the field's settings (App. A: beta2 = 0.8, lr 0.2 divided by 3
//! at every upsampling).
//!
//! State: first and second moments `m`, `v` (one per parameter) and the step count `t`.
//! The moments are plain buffers so that upsampling can interpolate them onto new points.

/// Adam state and hyper-parameters.
#[derive(Clone, Debug)]
pub struct Adam {
    pub m: Vec<f64>,
    pub v: Vec<f64>,
    pub t: u64,
    pub beta1: f64,
    pub beta2: f64,
    pub eps: f64,
}

impl Adam {
    /// Zero moments for `n` parameters.
    pub fn new(n: usize, beta1: f64, beta2: f64, eps: f64) -> Self {
        Adam {
            m: vec![0.0; n],
            v: vec![0.0; n],
            t: 0,
            beta1,
            beta2,
            eps,
        }
    }

    /// One step `x -= lr * m_hat / (sqrt(v_hat) + eps)` from gradient `g` (same length as x).
    pub fn step(&mut self, x: &mut [f64], g: &[f64], lr: f64) {
        use rayon::prelude::*;
        self.t += 1;
        let (b1, b2, eps) = (self.beta1, self.beta2, self.eps);
        let c1 = 1.0 - b1.powi(self.t as i32);
        let c2 = 1.0 - b2.powi(self.t as i32);
        // Elementwise, so the parallel split cannot change the result.
        x.par_chunks_mut(CHUNK)
            .zip(self.m.par_chunks_mut(CHUNK))
            .zip(self.v.par_chunks_mut(CHUNK))
            .zip(g.par_chunks(CHUNK))
            .for_each(|(((x, m), v), g)| {
                for (((xi, mi), vi), &gi) in x.iter_mut().zip(m).zip(v).zip(g) {
                    *mi = b1 * *mi + (1.0 - b1) * gi;
                    *vi = b2 * *vi + (1.0 - b2) * gi * gi;
                    *xi -= lr * (*mi / c1) / ((*vi / c2).sqrt() + eps);
                }
            });
    }
}

/// Parameters per parallel work item of [`Adam::step`].
const CHUNK: usize = 1 << 14;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn minimises_a_quadratic() {
        let mut x = vec![3.0, -2.0];
        let mut a = Adam::new(2, 0.9, 0.8, 1e-12);
        for _ in 0..2000 {
            let g = vec![2.0 * x[0], 8.0 * x[1]];
            a.step(&mut x, &g, 0.01);
        }
        assert!(x[0].abs() < 1e-2 && x[1].abs() < 1e-2, "{x:?}");
    }
}
