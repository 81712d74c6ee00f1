//! The point-based field and its visibility-aware kernel (Sec. 4.1-4.2, eqs. 2-4, 14).
//!
//! [`PointSet`] holds the field's points `x_i` (N of them) with
//!   sigma  median distance to the 9th nearest neighbour (Sec. 6.1); kernel support `3 sigma`
//!   dist   each point's distance to the boundary (infinite without a boundary)
//!   grid   hash grid for radius queries
//! The parameters `f` are a separate row-major N by K buffer (one row per point).
//!
//! Visibility (eq. 4) between an origin `o` and a point `x_i` needs a ray only when the two
//! boundary-free balls `B(o, d_o)` and `B(x_i, d_i)` (`d` = distance to the boundary) do not
//! cover the segment: if `|o - x_i| < d_o + d_i`, every point of the segment lies in one of the
//! balls, so it cannot cross the boundary. This skips most interior pairs.
//!
//! Field value at `z` (eqs. 2, 14): `f(z) = sum_i k_i f_i / sum_i k_i`, `s = softplus(f(z))`,
//! `alpha_hat = s / sum(s)`.

use ndarray::ArrayView2;

use super::sampling::{dist2, to_array, Domain};
use super::{Boundary, BoundaryQueries, HashGrid};
use crate::error::SkinResult;
use crate::invalid;

/// Counters of the visibility work (for the benchmark).
#[derive(Clone, Copy, Debug, Default)]
pub struct RayStats {
    /// Candidate pairs within the kernel support.
    pub pairs: u64,
    /// Pairs that needed a ray (the two-ball test did not settle them).
    pub rays: u64,
    /// Seconds spent in neighbour search and visibility.
    pub seconds: f64,
}

impl RayStats {
    /// Adds the counters of `o`.
    pub fn add(&mut self, o: &RayStats) {
        self.pairs += o.pairs;
        self.rays += o.rays;
        self.seconds += o.seconds;
    }
}

/// The field's points with their search structures.
#[derive(Clone, Debug)]
pub struct PointSet<const D: usize> {
    pub x: Vec<[f64; D]>,
    pub dist: Vec<f64>,
    pub sigma: f64,
    pub grid: HashGrid<D>,
    /// Use the boundary-free balls to skip rays (see the module doc); false traces every pair.
    pub skip_rays: bool,
}

/// Deepest neighbours whose boundary-free balls are tried before tracing a ray.
pub const ANCHORS: usize = 4;

/// Number of the neighbour whose median distance is `sigma` (Sec. 6.1).
pub const SIGMA_KNN: usize = 9;

/// Stable `log(1 + exp(t))` (eq. 14).
#[inline]
pub fn softplus(t: f64) -> f64 {
    t.max(0.0) + (-t.abs()).exp().ln_1p()
}

/// Derivative of softplus: the logistic function.
#[inline]
pub fn sigmoid(t: f64) -> f64 {
    if t >= 0.0 {
        1.0 / (1.0 + (-t).exp())
    } else {
        let e = t.exp();
        e / (1.0 + e)
    }
}

impl<const D: usize> PointSet<D>
where
    Boundary<D>: BoundaryQueries<D>,
{
    /// Point set over `x` (N > SIGMA_KNN points) in `domain`: sigma, distances and grid.
    pub fn new(x: Vec<[f64; D]>, domain: &Domain<D>) -> SkinResult<Self> {
        if x.len() <= SIGMA_KNN {
            return invalid!(
                "the field needs more than {SIGMA_KNN} points, got {}",
                x.len()
            );
        }
        let a = to_array(&x);
        let kd = super::knn_distance(a.view(), SIGMA_KNN, &mut crate::Silent)?;
        let mut s = kd.clone();
        s.sort_by(f64::total_cmp);
        let sigma = s[s.len() / 2];
        if sigma.is_nan() || sigma <= 0.0 {
            return invalid!("the field's points coincide (sigma = 0)");
        }
        let dist = point_distances(&x, domain);
        // Cells of 2 sigma: a query of radius 3-4 sigma visits 3-5 cells per axis.
        let grid = HashGrid::<D>::new(a.view(), 2.0 * sigma)?;
        Ok(PointSet {
            x,
            dist,
            sigma,
            grid,
            skip_rays: true,
        })
    }

    /// Number of points N.
    pub fn len(&self) -> usize {
        self.x.len()
    }

    /// True if there is no point (never, after [`PointSet::new`]).
    pub fn is_empty(&self) -> bool {
        self.x.is_empty()
    }

    /// Kernel support radius `3 sigma` (Sec. 4.1).
    #[inline]
    pub fn support(&self) -> f64 {
        3.0 * self.sigma
    }

    /// Points within `r` of `o` that are visible from `o` (eq. 4), appended to `out`.
    ///
    /// Inputs: domain (its boundary blocks), o origin, d_o its distance to the boundary,
    /// r radius, centres (if not empty, only points within `3 sigma` of one of them are kept:
    /// the others have zero kernel weight at every evaluation point), visibility (false: plain
    /// Gaussian kernel k_E, eq. 3).
    #[allow(clippy::too_many_arguments)]
    pub fn visible_within(
        &self,
        domain: &Domain<D>,
        o: &[f64; D],
        d_o: f64,
        r: f64,
        centres: &[[f64; D]],
        visibility: bool,
        out: &mut Vec<u32>,
        stats: &mut RayStats,
    ) {
        let t = std::time::Instant::now();
        let mut near = Vec::new();
        self.grid.radius(o, r, &mut near);
        if !centres.is_empty() {
            let r2 = self.support() * self.support();
            near.retain(|&i| centres.iter().any(|c| dist2(c, &self.x[i]) <= r2));
        }
        stats.pairs += near.len() as u64;
        match (&domain.boundary, visibility) {
            (Some(b), true) => {
                let anchors = if self.skip_rays {
                    self.anchors(o, &near)
                } else {
                    Vec::new()
                };
                for i in near {
                    if self.skip_rays && self.covered(o, d_o, i, &anchors) {
                        out.push(i as u32);
                        continue;
                    }
                    stats.rays += 1;
                    if !b.segment_hits(o, &self.x[i]) {
                        out.push(i as u32);
                    }
                }
            }
            _ => out.extend(near.into_iter().map(|i| i as u32)),
        }
        stats.seconds += t.elapsed().as_secs_f64();
    }

    /// Appends to `out` the points of `all` within `3 sigma` of one of `centres` (all of them
    /// if `centres` is empty).
    pub fn keep_near(&self, all: &[u32], centres: &[[f64; D]], out: &mut Vec<u32>) {
        if centres.is_empty() {
            out.extend_from_slice(all);
            return;
        }
        let r2 = self.support() * self.support();
        out.extend(
            all.iter()
                .copied()
                .filter(|&i| centres.iter().any(|c| dist2(c, &self.x[i as usize]) <= r2)),
        );
    }

    /// The [`ANCHORS`] deepest points among `near` (largest distance to the boundary) that lie
    /// within `3 sigma` of `o`: their boundary-free balls help cover segments from `o`.
    fn anchors(&self, o: &[f64; D], near: &[usize]) -> Vec<([f64; D], f64)> {
        let r2 = self.support() * self.support();
        let mut best: Vec<(f64, usize)> = Vec::with_capacity(ANCHORS + 1);
        for &i in near {
            let d = self.dist[i];
            if best.len() == ANCHORS && d <= best[ANCHORS - 1].0 {
                continue;
            }
            if dist2(o, &self.x[i]) > r2 {
                continue;
            }
            let pos = best.partition_point(|b| b.0 >= d);
            best.insert(pos, (d, i));
            best.truncate(ANCHORS);
        }
        best.into_iter().map(|(d, i)| (self.x[i], d)).collect()
    }

    /// True if the segment `o -> x_i` lies in the union of the boundary-free open balls
    /// `B(o, d_o)`, `B(x_i, d_i)` and those of the anchors, so that it cannot cross the
    /// boundary (exact, conservative: `false` only means a ray is needed).
    #[inline]
    fn covered(&self, o: &[f64; D], d_o: f64, i: usize, anchors: &[([f64; D], f64)]) -> bool {
        let x = &self.x[i];
        let l = dist2(o, x).sqrt();
        let d_i = self.dist[i];
        if l < d_o + d_i {
            return true;
        }
        // Sweep the balls' intervals along the segment (parameter t in [0, l]).
        let u: [f64; D] = std::array::from_fn(|k| (x[k] - o[k]) / l);
        let mut iv: [(f64, f64); ANCHORS] = [(f64::INFINITY, f64::INFINITY); ANCHORS];
        let mut m = 0;
        for (c, r) in anchors {
            let w: [f64; D] = std::array::from_fn(|k| c[k] - o[k]);
            let b = super::dot(&w, &u);
            let disc = r * r - (super::norm2(&w) - b * b);
            if disc > 0.0 {
                let s = disc.sqrt();
                iv[m] = (b - s, b + s);
                m += 1;
            }
        }
        iv[..m].sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
        // Reach of the covered prefix, starting with B(o, d_o); 0.999 keeps the open-ball
        // intervals strictly overlapping under rounding.
        let mut reach = 0.999 * d_o;
        let goal = l - 0.999 * d_i;
        for &(a, b) in &iv[..m] {
            if reach >= goal {
                break;
            }
            if a < reach {
                reach = reach.max(b - 1e-3 * (b - a));
            }
        }
        reach >= goal
    }

    /// Truncated Gaussian weights (eq. 3) at `z` of the candidates `cand`, into `k`
    /// (zero outside `3 sigma`); returns their sum.
    pub fn weights(&self, z: &[f64; D], cand: &[u32], k: &mut Vec<f64>) -> f64 {
        let r2 = self.support() * self.support();
        let c = -0.5 / (self.sigma * self.sigma);
        k.clear();
        let mut s = 0.0;
        for &i in cand {
            let d2 = dist2(z, &self.x[i as usize]);
            let w = if d2 <= r2 { (c * d2).exp() } else { 0.0 };
            k.push(w);
            s += w;
        }
        s
    }
}

/// Distance of each point to the boundary, in parallel (infinite without a boundary).
fn point_distances<const D: usize>(x: &[[f64; D]], domain: &Domain<D>) -> Vec<f64>
where
    Boundary<D>: BoundaryQueries<D>,
{
    use rayon::prelude::*;
    x.par_iter().map(|p| domain.dist(p)).collect()
}

/// The field at one point: interpolated parameters and normalised softplus (eqs. 2, 14).
#[derive(Clone, Debug, Default)]
pub struct FieldValue {
    /// `f(z)`, K values.
    pub f: Vec<f64>,
    /// `alpha_hat(z) = softplus(f) / sum softplus(f)`, K values.
    pub alpha: Vec<f64>,
    /// `sum softplus(f(z))`.
    pub sp_sum: f64,
    /// Normalised kernel weights `k_i / sum k`, one per candidate.
    pub k: Vec<f64>,
}

impl FieldValue {
    /// Evaluates the field at `z` from candidates `cand` and parameters `f` (N by K,
    /// row-major). Returns false (and leaves garbage) when no candidate has weight.
    pub fn eval<const D: usize>(
        &mut self,
        ps: &PointSet<D>,
        z: &[f64; D],
        cand: &[u32],
        f: &[f64],
        nk: usize,
    ) -> bool
    where
        Boundary<D>: BoundaryQueries<D>,
    {
        let s = ps.weights(z, cand, &mut self.k);
        if s.is_nan() || s <= 0.0 {
            return false;
        }
        let inv = 1.0 / s;
        self.f.clear();
        self.f.resize(nk, 0.0);
        for (j, &i) in cand.iter().enumerate() {
            let w = self.k[j] * inv;
            self.k[j] = w;
            if w == 0.0 {
                continue;
            }
            let row = &f[i as usize * nk..(i as usize + 1) * nk];
            for (a, &b) in self.f.iter_mut().zip(row) {
                *a += w * b;
            }
        }
        self.finish_softplus();
        true
    }

    /// `alpha = softplus(f) / sum softplus(f)` from `self.f` (eq. 14, Sec. 4.2).
    fn finish_softplus(&mut self) {
        self.alpha.clear();
        self.alpha.extend(self.f.iter().map(|&t| softplus(t)));
        self.sp_sum = self.alpha.iter().sum();
        let inv = 1.0 / self.sp_sum;
        for a in self.alpha.iter_mut() {
            *a *= inv;
        }
    }

    /// Back-propagates `g = dE / d alpha_hat(z)` (K values) into `grad` (N by K, row-major):
    /// through the normalisation, the softplus and eq. 2.
    pub fn backward(&self, cand: &[u32], g: &[f64], grad: &mut [f64], u: &mut Vec<f64>) {
        let nk = g.len();
        let ga: f64 = g.iter().zip(&self.alpha).map(|(a, b)| a * b).sum();
        u.clear();
        u.extend((0..nk).map(|m| (g[m] - ga) / self.sp_sum * sigmoid(self.f[m])));
        for (j, &i) in cand.iter().enumerate() {
            let w = self.k[j];
            if w == 0.0 {
                continue;
            }
            let row = &mut grad[i as usize * nk..(i as usize + 1) * nk];
            for (a, &b) in row.iter_mut().zip(u.iter()) {
                *a += w * b;
            }
        }
    }
}

/// [`FieldValue::eval`] at the three points `z` of one Laplacian stencil (eq. 13), which share
/// their candidates: one pass over the candidates reads each parameter row once. Returns false
/// if some point has no candidate with weight.
pub fn eval3<const D: usize>(
    vals: &mut [FieldValue],
    ps: &PointSet<D>,
    z: &[[f64; D]; 3],
    cand: &[u32],
    f: &[f64],
    nk: usize,
) -> bool
where
    Boundary<D>: BoundaryQueries<D>,
{
    let r2 = ps.support() * ps.support();
    let c = -0.5 / (ps.sigma * ps.sigma);
    let mut sum = [0.0f64; 3];
    for v in vals.iter_mut().take(3) {
        v.k.clear();
        v.f.clear();
        v.f.resize(nk, 0.0);
    }
    let (v0, rest) = vals.split_at_mut(1);
    let (v1, v2) = rest.split_at_mut(1);
    let (v0, v1, v2) = (&mut v0[0], &mut v1[0], &mut v2[0]);
    for &i in cand {
        let x = &ps.x[i as usize];
        let w: [f64; 3] = std::array::from_fn(|m| {
            let d2 = dist2(&z[m], x);
            if d2 <= r2 {
                (c * d2).exp()
            } else {
                0.0
            }
        });
        v0.k.push(w[0]);
        v1.k.push(w[1]);
        v2.k.push(w[2]);
        if w[0] == 0.0 && w[1] == 0.0 && w[2] == 0.0 {
            continue;
        }
        for m in 0..3 {
            sum[m] += w[m];
        }
        let row = &f[i as usize * nk..(i as usize + 1) * nk];
        let f12 = v1.f.iter_mut().zip(v2.f.iter_mut());
        for ((a0, (a1, a2)), &a) in v0.f.iter_mut().zip(f12).zip(row) {
            *a0 += w[0] * a;
            *a1 += w[1] * a;
            *a2 += w[2] * a;
        }
    }
    for (m, v) in [v0, v1, v2].into_iter().enumerate() {
        if sum[m].is_nan() || sum[m] <= 0.0 {
            return false;
        }
        let inv = 1.0 / sum[m];
        v.k.iter_mut().for_each(|w| *w *= inv);
        v.f.iter_mut().for_each(|a| *a *= inv);
        v.finish_softplus();
    }
    true
}

/// [`FieldValue::backward`] of the three stencil points at once: `g` holds their three
/// K-vectors `dE / d alpha_hat(z_m)` back to back; each gradient row is touched once.
pub fn backward3(vals: &[FieldValue], cand: &[u32], g: &[f64], grad: &mut [f64], u: &mut Vec<f64>) {
    let nk = g.len() / 3;
    u.clear();
    for (m, v) in vals.iter().take(3).enumerate() {
        let gm = &g[m * nk..(m + 1) * nk];
        let ga: f64 = gm.iter().zip(&v.alpha).map(|(a, b)| a * b).sum();
        u.extend((0..nk).map(|kk| (gm[kk] - ga) / v.sp_sum * sigmoid(v.f[kk])));
    }
    let (u0, rest) = u.split_at(nk);
    let (u1, u2) = rest.split_at(nk);
    for (j, &i) in cand.iter().enumerate() {
        let w = [vals[0].k[j], vals[1].k[j], vals[2].k[j]];
        if w[0] == 0.0 && w[1] == 0.0 && w[2] == 0.0 {
            continue;
        }
        let row = &mut grad[i as usize * nk..(i as usize + 1) * nk];
        let u12 = u1.iter().zip(u2);
        for ((r, a0), (a1, a2)) in row.iter_mut().zip(u0).zip(u12) {
            *r += w[0] * a0 + w[1] * a1 + w[2] * a2;
        }
    }
}

/// Rows of an N by K view as a row-major buffer.
pub fn flat(f: ArrayView2<f64>) -> Vec<f64> {
    f.iter().copied().collect()
}
