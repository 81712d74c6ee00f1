//! Monte-Carlo biharmonic energy of the field and its hand-derived gradient (Sec. 5, eqs. 7, 9,
//! 10, 11, 13).
//!
//! For samples `y_j` (uniform in the domain, weight `omega_j` of eq. 11) and directions `v_j`
//! (uniform on the sphere), with `y+- = y +- h v`:
//!   `Lap alpha_k(y) = (alpha_k(y+) + alpha_k(y-) - 2 alpha_k(y)) / h^2`          (eq. 13)
//!   `E = V(P) / M * sum_j omega_j sum_k (Lap alpha_k(y_j))^2`                    (eqs. 10-11)
//! where every evaluation for sample `j` (at `y`, `y+`, `y-` and, with zero Neumann conditions,
//! at their closest boundary points) uses only the points visible from `y` (Sec. 5.3, Fig. 9).
//!
//! The gradient with respect to every `f_i` is the chain rule through eq. 7 (the mollifier does
//! not depend on `f`), eq. 9 (`alpha = (1 - w) alpha_hat(z) + w alpha_hat(p)`), the
//! normalisation, the softplus and eq. 2, see [`super::kernel::FieldValue::backward`].
//! A sample where some evaluation point sees no point of the field contributes nothing.
//!
//! Work is split into [`CHUNKS`] fixed chunks of samples, each accumulating into its own
//! gradient buffer; the buffers are summed in chunk order, so the result is bitwise the same
//! for any thread count.

use rayon::prelude::*;

use super::kernel::{backward3, eval3, FieldValue, PointSet, RayStats};
use super::mollifier::{bump, Constraints};
use super::sampling::Domain;
use super::{add, scale, sub, Boundary, BoundaryQueries};

/// Fixed number of gradient buffers (the reduction tree does not depend on the threads).
pub const CHUNKS: usize = 4;

/// One Monte-Carlo term: centre, direction and eq. 11 weight.
#[derive(Clone, Copy, Debug)]
pub struct McSample<const D: usize> {
    pub y: [f64; D],
    pub v: [f64; D],
    pub weight: f64,
    /// Index of `y` in the sample pool (key of the visibility cache).
    pub pool: usize,
}

/// Per pool sample, the points visible from it within the candidate radius, computed on first
/// use. Visibility depends only on `y` and the point set, so the cache is exact; it is reset
/// whenever the point set changes.
pub type VisibilityCache = Vec<std::sync::OnceLock<Box<[u32]>>>;

/// Everything the energy needs besides the parameters.
pub struct Problem<'a, const D: usize> {
    pub domain: &'a Domain<D>,
    pub points: &'a PointSet<D>,
    pub cons: &'a Constraints<D>,
    /// Finite-difference step `h` of eq. 13.
    pub h: f64,
    /// Radius of the zero-Neumann reparameterisation (eq. 9), `None` for natural conditions.
    pub neumann: Option<f64>,
    /// Visibility-aware kernel (eq. 4); false gives the plain Gaussian (eq. 3).
    pub visibility: bool,
    /// Visibility cache over the sample pool, if enabled.
    pub cache: Option<&'a VisibilityCache>,
}

/// Reused per-chunk memory.
#[derive(Default)]
struct Scratch {
    cand: Vec<u32>,
    vals: [FieldValue; 6],
    wn: [f64; 3],
    se: [f64; 3],
    alpha: Vec<f64>,
    e: Vec<f64>,
    g: Vec<f64>,
    u: Vec<f64>,
    near: Vec<usize>,
}

impl<const D: usize> Problem<'_, D>
where
    Boundary<D>: BoundaryQueries<D>,
{
    fn k(&self) -> usize {
        self.cons.k
    }

    /// Weights `alpha(z)` (eq. 7, with eq. 9 if enabled) of evaluation point `m` (0: y, 1: y+,
    /// 2: y-) into `sc.alpha[m*K..]` from `alpha_hat(z)` in `sc.vals[m]` ([`eval3`]).
    #[allow(clippy::needless_range_loop)]
    fn forward(&self, m: usize, z: &[f64; D], f: &[f64], sc: &mut Scratch) {
        let nk = self.k();
        let (first, rest) = sc.vals.split_at_mut(3);
        sc.wn[m] = 0.0;
        if let (Some(eps), Some(b)) = (self.neumann, &self.domain.boundary) {
            let c = b.closest(z);
            if c.dist < eps && rest[m].eval(self.points, &c.point, &sc.cand, f, nk) {
                sc.wn[m] = bump(c.dist, eps);
            }
        }
        sc.e.resize(nk, 0.0);
        sc.se[m] = self.cons.eval(z, &mut sc.e, &mut sc.near);
        let w = sc.wn[m];
        let out = &mut sc.alpha[m * nk..(m + 1) * nk];
        for kk in 0..nk {
            let mut a = first[m].alpha[kk];
            if w > 0.0 {
                a = (1.0 - w) * a + w * rest[m].alpha[kk];
            }
            out[kk] = sc.e[kk] + (1.0 - sc.se[m]) * a;
        }
    }

    /// Energy term of one sample (already scaled by `scale`), gradient added to `grad`.
    #[allow(clippy::needless_range_loop)]
    fn term(
        &self,
        s: &McSample<D>,
        f: &[f64],
        scale_e: f64,
        grad: &mut [f64],
        sc: &mut Scratch,
        stats: &mut RayStats,
    ) -> f64 {
        let nk = self.k();
        let ps = self.points;
        let r = ps.support() + self.h + self.neumann.unwrap_or(0.0);
        sc.cand.clear();
        let hv = scale(&s.v, self.h);
        let z = [s.y, add(&s.y, &hv), sub(&s.y, &hv)];
        // With Neumann conditions the closest boundary points are evaluated too: keep the ball.
        let centres: &[[f64; D]] = if self.neumann.is_some() { &[] } else { &z };
        match self.cache.and_then(|c| c.get(s.pool)) {
            Some(cell) => {
                let all = cell.get_or_init(|| {
                    let mut v = Vec::new();
                    let d_y = self.domain.dist(&s.y);
                    ps.visible_within(
                        self.domain,
                        &s.y,
                        d_y,
                        r,
                        &[],
                        self.visibility,
                        &mut v,
                        stats,
                    );
                    v.into_boxed_slice()
                });
                ps.keep_near(all, centres, &mut sc.cand);
            }
            None => {
                let d_y = self.domain.dist(&s.y);
                ps.visible_within(
                    self.domain,
                    &s.y,
                    d_y,
                    r,
                    centres,
                    self.visibility,
                    &mut sc.cand,
                    stats,
                );
            }
        }
        sc.alpha.resize(3 * nk, 0.0);
        if !eval3(&mut sc.vals[..3], ps, &z, &sc.cand, f, nk) {
            return 0.0;
        }
        for (m, zm) in z.iter().enumerate() {
            self.forward(m, zm, f, sc);
        }
        let ih2 = 1.0 / (self.h * self.h);
        let coef = [-2.0, 1.0, 1.0];
        let mut e = 0.0;
        sc.g.resize(3 * nk, 0.0);
        for kk in 0..nk {
            let lap = (sc.alpha[nk + kk] + sc.alpha[2 * nk + kk] - 2.0 * sc.alpha[kk]) * ih2;
            e += lap * lap;
            let d = scale_e * s.weight * 2.0 * lap * ih2;
            for m in 0..3 {
                sc.g[m * nk + kk] = d * coef[m];
            }
        }
        // Backward: alpha = e~ + (1 - sum e~) ((1 - w) alpha_hat(z) + w alpha_hat(p)).
        let mut g3 = vec![0.0; 3 * nk];
        for m in 0..3 {
            let a = (1.0 - sc.se[m]) * (1.0 - sc.wn[m]);
            for kk in 0..nk {
                g3[m * nk + kk] = a * sc.g[m * nk + kk];
            }
        }
        backward3(&sc.vals[..3], &sc.cand, &g3, grad, &mut sc.u);
        let mut gm = vec![0.0; nk];
        for m in 0..3 {
            let w = sc.wn[m];
            if w > 0.0 {
                let a = (1.0 - sc.se[m]) * w;
                for kk in 0..nk {
                    gm[kk] = a * sc.g[m * nk + kk];
                }
                sc.vals[3 + m].backward(&sc.cand, &gm, grad, &mut sc.u);
            }
        }
        scale_e * s.weight * e
    }

    /// Energy (eq. 11) over `samples` and its gradient with respect to `f` (N by K row-major),
    /// written to `grad`; `bufs` holds [`CHUNKS`] reusable buffers.
    pub fn energy(
        &self,
        samples: &[McSample<D>],
        f: &[f64],
        grad: &mut [f64],
        bufs: &mut Vec<Vec<f64>>,
    ) -> (f64, RayStats) {
        let n = f.len();
        bufs.resize_with(CHUNKS, Vec::new);
        let scale_e = self.domain.volume / samples.len().max(1) as f64;
        let per = samples.len().div_ceil(CHUNKS).max(1);
        let parts: Vec<(f64, RayStats)> = bufs
            .par_iter_mut()
            .enumerate()
            .map(|(c, buf)| {
                buf.clear();
                buf.resize(n, 0.0);
                let mut sc = Scratch::default();
                let mut stats = RayStats::default();
                let lo = (c * per).min(samples.len());
                let hi = ((c + 1) * per).min(samples.len());
                let mut e = 0.0;
                for s in &samples[lo..hi] {
                    e += self.term(s, f, scale_e, buf, &mut sc, &mut stats);
                }
                (e, stats)
            })
            .collect();
        let bufs = &*bufs;
        grad.par_chunks_mut(4096).enumerate().for_each(|(b, out)| {
            let o = b * 4096;
            for (j, g) in out.iter_mut().enumerate() {
                let mut s = 0.0;
                for buf in bufs {
                    s += buf[o + j];
                }
                *g = s;
            }
        });
        let mut stats = RayStats::default();
        let mut e = 0.0;
        for (pe, ps) in &parts {
            e += pe;
            stats.add(ps);
        }
        (e, stats)
    }
}
