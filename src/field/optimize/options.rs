//! Options of the geometric field ([`FieldOptions`]), their defaults (Dodik et al. 2024,
//! App. A) and the check that refuses invalid or unaffordable ones before any work.

use crate::error::SkinResult;
use crate::field::kernel::SIGMA_KNN;
use crate::invalid;

/// Options of the field (defaults: App. A).
#[derive(Clone, Debug)]
pub struct FieldOptions {
    /// Initial number of points: 2^11 (2D) / 2^13 (3D).
    pub n_init: usize,
    /// Monte-Carlo samples per step M: 2^12 (2D) / 2^11 (3D).
    pub samples: usize,
    /// Total steps of the schedule (6000).
    pub steps: usize,
    /// Number of doublings of the point set (3).
    pub upsamples: usize,
    /// Initial learning rate (0.2) and its divisor at each upsampling (3).
    pub lr: f64,
    pub lr_decay: f64,
    pub beta1: f64,
    pub beta2: f64,
    pub adam_eps: f64,
    /// Finite-difference step `h` in units of sigma (1; the paper ties h to the spacing).
    pub h_sigma: f64,
    /// Mollifier / Neumann radius in units of sigma (0.5, App. A).
    pub eps_sigma: f64,
    /// Zero-Neumann reparameterisation (eq. 9).
    pub neumann: bool,
    /// Visibility-aware kernel (false: plain Gaussian, for comparisons).
    pub visibility: bool,
    pub wn_l: f64,
    pub wn_h: f64,
    pub seed: u64,
    /// Interior samples drawn once by rejection; each step takes its M samples from this pool.
    pub pool: usize,
    /// Cache each pool sample's visible points (exact; memory ~ pool x 64 x 9 x 4 bytes in 3D).
    pub cache_visibility: bool,
    /// Skip rays whose segment is covered by boundary-free balls (exact; off only to measure).
    pub skip_rays: bool,
}

impl FieldOptions {
    /// App. A defaults for dimension `d`.
    pub fn defaults(d: usize) -> Self {
        let three = d == 3;
        FieldOptions {
            n_init: if three { 1 << 13 } else { 1 << 11 },
            samples: if three { 1 << 11 } else { 1 << 12 },
            steps: 6000,
            upsamples: 3,
            lr: 0.2,
            lr_decay: 3.0,
            beta1: 0.9,
            beta2: 0.8,
            adam_eps: 1e-10,
            h_sigma: 1.0,
            eps_sigma: 0.5,
            neumann: false,
            visibility: true,
            wn_l: 0.1,
            wn_h: 0.25,
            seed: 0,
            pool: if three { 1 << 16 } else { 1 << 17 },
            cache_visibility: true,
            skip_rays: true,
        }
    }
}

/// Largest point set, sample count or pool a field accepts (each costs tens of bytes per entry
/// and per handle).
pub const MAX_POINTS: usize = 1 << 24;

pub(super) fn check_options(o: &FieldOptions) -> SkinResult<()> {
    if o.n_init <= SIGMA_KNN || o.samples == 0 || o.pool == 0 {
        return invalid!(
            "n_init must exceed {} and samples, pool must be positive",
            SIGMA_KNN
        );
    }
    let pos = [o.lr, o.lr_decay, o.h_sigma, o.eps_sigma, o.adam_eps];
    if pos.iter().any(|x| !(*x > 0.0 && x.is_finite())) {
        return invalid!("lr, lr_decay, h, eps and adam_eps must be positive and finite");
    }
    if !(0.0..1.0).contains(&o.beta1) || !(0.0..1.0).contains(&o.beta2) {
        return invalid!("Adam's beta1 and beta2 must lie in [0, 1)");
    }
    if o.upsamples > 8 {
        return invalid!("at most 8 upsamplings (the point set doubles each time)");
    }
    // Each of these sizes one allocation before any other work: refuse sizes no machine holds.
    let most_points = o
        .n_init
        .checked_shl(o.upsamples as u32)
        .unwrap_or(usize::MAX);
    for (name, x) in [
        ("n_points * 2^upsamples", most_points),
        ("samples", o.samples),
        ("pool", o.pool),
    ] {
        if x > MAX_POINTS {
            return invalid!("{name} must be at most {MAX_POINTS}, got {x}");
        }
    }
    Ok(())
}
