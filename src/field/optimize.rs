//! The geometric field of Dodik et al. 2024 for bounded biharmonic weights: set-up, the
//! multiscale Adam optimisation of App. A, painting and resuming.
//!
//! [`GeometricField::new`] inputs (any units; everything is rescaled into the unit box, App. A):
//!   v          #V by D vertices (D = 2 or 3)
//!   f          #F by D boundary elements (triangles / segments) or `None` for a point cloud
//!   simplices  #S by D + 1 interior mesh for sampling (tets / triangles) or `None`
//!   handles    (a, b, column) segments in input units (`a == b` for point handles), K columns
//!   opts       [`FieldOptions`]
//! Schedule: `opts.steps` Adam steps; the point set (`n_init` points) doubles `upsamples` times
//! at steps `steps * l / (upsamples + 1)`, with `f` and both Adam moments interpolated onto the
//! new points by the field itself (eq. 2) and the learning rate divided by 3 (Sec. 5.4, App. A).
//! After the schedule, `optimize` runs further steps at the final resolution (used to resume
//! after [`GeometricField::paint`]).

//!
//! Layout: this module holds the field, its set-up and the optimisation loop (steps,
//! upsampling, painting); [`options`] the options, their App. A defaults and their checks;
//! [`setup`] the input checks and helpers of the set-up (unit box, handles, point cloud
//! radius, spatial order of points).

mod options;
mod setup;

use super::adam::Adam;
use super::energy::{McSample, Problem};
use super::kernel::{FieldValue, PointSet, RayStats};
use super::mollifier::Constraints;
use super::sampling::{Domain, Sample};
use super::{Boundary, BoundaryQueries};
use crate::error::SkinResult;
use crate::invalid;
use crate::progress::{Event, Progress};
use crate::rng::Rng;
use options::check_options;
pub use options::{FieldOptions, MAX_POINTS};
pub use setup::unit_box;
use setup::{check_handles, check_solid, cloud_radius, permute, spatial_order, to_unit};

/// Totals for reporting.
#[derive(Clone, Debug, Default)]
pub struct FieldStats {
    pub rays: RayStats,
    pub seconds_energy: f64,
    pub seconds_total: f64,
    pub last_energy: f64,
}

/// The field, its parameters and optimiser state.
pub struct GeometricField<const D: usize> {
    pub opts: FieldOptions,
    pub domain: Domain<D>,
    pub cons: Constraints<D>,
    pub points: PointSet<D>,
    /// Parameters, N by K row-major.
    pub f: Vec<f64>,
    pub adam: Adam,
    pub step: usize,
    pub level: usize,
    pub lr: f64,
    /// sigma of the initial point set (sets the Neumann radius, App. A).
    pub sigma0: f64,
    /// Interior pool for the Monte-Carlo samples.
    pub pool: Vec<Sample<D>>,
    /// Unit-box map: `unit = (x - offset) * scale`.
    pub offset: [f64; D],
    pub scale: f64,
    pub stats: FieldStats,
    bufs: Vec<Vec<f64>>,
    cache: super::energy::VisibilityCache,
}

impl<const D: usize> GeometricField<D>
where
    Boundary<D>: BoundaryQueries<D>,
{
    /// Sets up the domain, handles and initial point set (see the module doc).
    pub fn new(
        v: ndarray::ArrayView2<f64>,
        f: Option<ndarray::ArrayView2<usize>>,
        simplices: Option<ndarray::ArrayView2<usize>>,
        handles: Vec<([f64; D], [f64; D], usize)>,
        k: usize,
        opts: FieldOptions,
    ) -> SkinResult<Self> {
        check_options(&opts)?;
        if k == 0 || handles.is_empty() {
            return invalid!("no handles: give point handles P and/or bone edges BE");
        }
        let (offset, scale) = unit_box::<D>(&v)?;
        check_solid::<D>(&v, scale)?;
        let vu = v.map(|x| *x); // copy, then rescale column-wise
        let mut vu = vu;
        for mut r in vu.rows_mut() {
            for kk in 0..D {
                r[kk] = (r[kk] - offset[kk]) * scale;
            }
        }
        let handles: Vec<_> = handles
            .into_iter()
            .map(|(a, b, c)| (to_unit(&a, &offset, scale), to_unit(&b, &offset, scale), c))
            .collect();
        let cloud_r = if f.is_none() { cloud_radius(&vu)? } else { 0.0 };
        let mut domain = Domain::<D>::new(vu.view(), f, simplices, cloud_r, opts.wn_l, opts.wn_h)?;
        check_handles(&domain, &handles, k)?;
        let (pool, tries) = domain.sample(opts.pool, opts.seed, u64::MAX)?;
        domain.estimate_volume(pool.len(), tries);
        let (x0, _) = domain.sample(opts.n_init, opts.seed, 1_000_000)?;
        let x0: Vec<[f64; D]> = x0.iter().map(|s| s.x).collect();
        let x0 = permute(&x0, &spatial_order(&x0), 1);
        let points = PointSet::new(x0, &domain)?;
        let sigma0 = points.sigma;
        let cons = Constraints::new(k, handles, opts.eps_sigma * sigma0);
        let n = points.len() * k;
        Ok(GeometricField {
            adam: Adam::new(n, opts.beta1, opts.beta2, opts.adam_eps),
            lr: opts.lr,
            opts,
            domain,
            cons,
            points,
            f: vec![0.0; n],
            step: 0,
            level: 0,
            sigma0,
            pool,
            offset,
            scale,
            stats: FieldStats::default(),
            bufs: Vec::new(),
            cache: Vec::new(),
        }
        .with_fresh_cache())
    }

    /// Empties the visibility cache (after the point set changed).
    fn with_fresh_cache(mut self) -> Self {
        self.reset_cache();
        self
    }

    fn reset_cache(&mut self) {
        self.points.skip_rays = self.opts.skip_rays;
        self.cache = if self.opts.cache_visibility {
            (0..self.pool.len())
                .map(|_| std::sync::OnceLock::new())
                .collect()
        } else {
            Vec::new()
        };
    }

    /// Number of weight columns K.
    pub fn k(&self) -> usize {
        self.cons.k
    }

    /// Input units -> unit box.
    pub fn to_unit(&self, x: &[f64; D]) -> [f64; D] {
        to_unit(x, &self.offset, self.scale)
    }

    /// The energy problem at the current resolution.
    pub fn problem(&self) -> Problem<'_, D> {
        Problem {
            domain: &self.domain,
            points: &self.points,
            cons: &self.cons,
            h: self.opts.h_sigma * self.points.sigma,
            neumann: self
                .opts
                .neumann
                .then_some(self.opts.eps_sigma * self.sigma0),
            visibility: self.opts.visibility,
            cache: (!self.cache.is_empty()).then_some(&self.cache),
        }
    }

    /// The M Monte-Carlo samples of step `step`: pool entries and directions from the
    /// per-sample streams `(seed, step, j)`.
    pub fn samples(&self, step: u64) -> Vec<McSample<D>> {
        let samples = (0..self.opts.samples)
            .map(|j| {
                let mut r = Rng::stream(self.opts.seed, step, j as u64);
                let pool = r.below(self.pool.len());
                let s = self.pool[pool];
                McSample {
                    y: s.x,
                    v: r.direction(),
                    weight: s.weight,
                    pool,
                }
            })
            .collect::<Vec<_>>();
        // Spatially coherent order: consecutive samples (and each gradient chunk) touch
        // neighbouring parameter rows, which the spatial order of the points keeps close in
        // memory.
        let ys: Vec<[f64; D]> = samples.iter().map(|s| s.y).collect();
        permute(&samples, &spatial_order(&ys), 1)
    }

    /// Energy and gradient at parameters `f` (N by K row-major) with the samples of `step`.
    pub fn energy_at(&mut self, f: &[f64], step: u64) -> SkinResult<(f64, Vec<f64>)> {
        if f.len() != self.f.len() {
            return invalid!("f must have {} entries, got {}", self.f.len(), f.len());
        }
        let samples = self.samples(step);
        let mut grad = vec![0.0; f.len()];
        let mut bufs = std::mem::take(&mut self.bufs);
        let (e, _) = self.problem().energy(&samples, f, &mut grad, &mut bufs);
        self.bufs = bufs;
        Ok((e, grad))
    }

    /// Step at which upsampling number `l` (1-based) happens.
    fn upsample_at(&self, l: usize) -> usize {
        self.opts.steps * l / (self.opts.upsamples + 1)
    }

    /// Runs `steps` Adam steps (`None`: to the end of the schedule, or `resume` steps when it is
    /// already complete), reporting `("optimize", step, energy)`.
    pub fn optimize(
        &mut self,
        steps: Option<usize>,
        resume: usize,
        progress: &mut dyn Progress,
    ) -> SkinResult<()> {
        let t0 = std::time::Instant::now();
        let n = match steps {
            Some(s) => s,
            None if self.step < self.opts.steps => self.opts.steps - self.step,
            None => resume,
        };
        let mut grad = vec![0.0; self.f.len()];
        for _ in 0..n {
            while self.level < self.opts.upsamples && self.step >= self.upsample_at(self.level + 1)
            {
                self.upsample()?;
                grad = vec![0.0; self.f.len()];
            }
            let t = std::time::Instant::now();
            let samples = self.samples(self.step as u64);
            let mut bufs = std::mem::take(&mut self.bufs);
            let (e, rs) = self
                .problem()
                .energy(&samples, &self.f, &mut grad, &mut bufs);
            self.bufs = bufs;
            self.stats.seconds_energy += t.elapsed().as_secs_f64();
            self.stats.rays.add(&rs);
            self.stats.last_energy = e;
            if !e.is_finite() {
                return Err(crate::error::SkinError::Numerical(format!(
                    "the energy became {e} at step {}",
                    self.step
                )));
            }
            self.adam.step(&mut self.f, &grad, self.lr);
            self.step += 1;
            progress.report(Event {
                stage: "optimize",
                iteration: self.step,
                value: e,
            })?;
        }
        self.stats.seconds_total += t0.elapsed().as_secs_f64();
        Ok(())
    }

    /// Doubles the point set (Sec. 5.4): new interior points get `f` and the Adam moments
    /// interpolated by eq. 2 (visibility from the new point; the nearest old point when none
    /// is visible); sigma, h and the mollifier radius shrink with the new spacing and the
    /// learning rate is divided by `lr_decay`.
    pub fn upsample(&mut self) -> SkinResult<()> {
        self.level += 1;
        let n_new = self.points.len();
        let (news, _) = self
            .domain
            .sample(n_new, self.opts.seed, 1_000_000 + self.level as u64)?;
        let xs: Vec<[f64; D]> = news.iter().map(|s| s.x).collect();
        let k = self.k();
        let mut f = self.f.clone();
        let mut m = self.adam.m.clone();
        let mut v = self.adam.v.clone();
        let cols = [&self.f, &self.adam.m, &self.adam.v];
        let rows = self.interpolate_rows(&xs, &cols);
        for (i, r) in rows.iter().enumerate() {
            let _ = i;
            f.extend_from_slice(&r[0..k]);
            m.extend_from_slice(&r[k..2 * k]);
            v.extend_from_slice(&r[2 * k..3 * k]);
        }
        let mut x = self.points.x.clone();
        x.extend(xs);
        let order = spatial_order(&x);
        self.points = PointSet::new(permute(&x, &order, 1), &self.domain)?;
        self.reset_cache();
        self.f = permute(&f, &order, k);
        self.adam.m = permute(&m, &order, k);
        self.adam.v = permute(&v, &order, k);
        self.lr /= self.opts.lr_decay;
        self.cons.set_eps(self.opts.eps_sigma * self.points.sigma)?;
        Ok(())
    }

    /// Kernel interpolation (eq. 2, before the softplus) of each buffer in `cols` (N by K) at
    /// `xs`; returns per point the concatenated K-rows.
    fn interpolate_rows(&self, xs: &[[f64; D]], cols: &[&Vec<f64>]) -> Vec<Vec<f64>> {
        use rayon::prelude::*;
        let k = self.k();
        let ps = &self.points;
        xs.par_iter()
            .map(|x| {
                let mut cand = Vec::new();
                let mut st = RayStats::default();
                let d = self.domain.dist(x);
                ps.visible_within(
                    &self.domain,
                    x,
                    d,
                    ps.support(),
                    &[],
                    self.opts.visibility,
                    &mut cand,
                    &mut st,
                );
                let mut kw = Vec::new();
                let s = ps.weights(x, &cand, &mut kw);
                if s.is_nan() || s <= 0.0 {
                    cand = vec![ps.grid.knn(x, 1, None)[0].1 as u32];
                    kw = vec![1.0];
                }
                let s: f64 = kw.iter().sum();
                let mut out = vec![0.0; cols.len() * k];
                for (j, &i) in cand.iter().enumerate() {
                    let w = kw[j] / s;
                    for (c, buf) in cols.iter().enumerate() {
                        for kk in 0..k {
                            out[c * k + kk] += w * buf[i as usize * k + kk];
                        }
                    }
                }
                out
            })
            .collect()
    }

    /// Adds painted Dirichlet conditions: points `p` (input units) with weight rows `w`
    /// (row-major, K each, >= 0, summing to 1). Resume with [`GeometricField::optimize`].
    pub fn paint(&mut self, p: &[[f64; D]], w: &[f64]) -> SkinResult<()> {
        let pu: Vec<[f64; D]> = p.iter().map(|x| self.to_unit(x)).collect();
        self.cons.paint(&pu, w)
    }

    /// Field value `alpha_hat` of the visible points around `o` at `z`, or `None`.
    pub(crate) fn alpha_hat(
        &self,
        z: &[f64; D],
        o: &[f64; D],
        visibility: bool,
        val: &mut FieldValue,
    ) -> bool {
        let ps = &self.points;
        let mut cand = Vec::new();
        let mut st = RayStats::default();
        let d = if visibility {
            self.domain.dist(o)
        } else {
            f64::INFINITY
        };
        let r = ps.support() + super::sampling::dist2(z, o).sqrt();
        ps.visible_within(&self.domain, o, d, r, &[], visibility, &mut cand, &mut st);
        val.eval(ps, z, &cand, &self.f, self.k())
    }
}
