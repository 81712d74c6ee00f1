//! The domain of the field and uniform samples of its interior (Sec. 5.1-5.2, App. A).
//!
//! [`Domain`] holds what the optimisation asks of the shape, in unit-box coordinates:
//!   boundary   triangles (3D) / segments (2D) with their BVH: visibility (eq. 4), closest points
//!   winding    fast generalized winding number: rejection of outside samples, weights (eq. 11)
//!   interior   how to draw uniform interior points:
//!              * `Simplices`: a tet mesh (3D) or triangle mesh (2D) given by the user, sampled
//!                by volume (it need not be a good FEM mesh, only cover the interior);
//!              * `Winding`: uniform in the bounding box, rejected where `wn < wn_l`;
//!              * `Cloud`: no boundary at all (a point cloud): a random input point plus a
//!                uniform offset in a ball of radius `r` (our choice, the paper has no such case).
//! Every sample carries the weight of eq. 11, `clip((wn - wn_l) / (wn_h - wn_l), 0, 1)` (1 for
//! simplex and cloud samples).

use ndarray::{Array2, ArrayView2};
use rayon::prelude::*;

use super::{norm2, scale, sub, Boundary, BoundaryQueries, FastWinding};
use crate::error::SkinResult;
use crate::invalid;
use crate::rng::Rng;

/// One interior sample: position and energy weight (eq. 11).
#[derive(Clone, Copy, Debug)]
pub struct Sample<const D: usize> {
    pub x: [f64; D],
    pub weight: f64,
}

/// How interior points are drawn.
#[derive(Clone, Debug)]
pub enum Interior<const D: usize> {
    /// Rejection sampling in the box `[lo, hi]` with the winding number.
    Winding { lo: [f64; D], hi: [f64; D] },
    /// Simplices (D + 1 corners each, unused corners ignored) with cumulative volumes.
    Simplices {
        verts: Vec<[f64; D]>,
        elems: Vec<[usize; 4]>,
        cdf: Vec<f64>,
    },
    /// Balls of radius `radius` around `points`.
    Cloud { points: Vec<[f64; D]>, radius: f64 },
}

/// Shape of the field's domain (unit-box coordinates).
#[derive(Clone, Debug)]
pub struct Domain<const D: usize> {
    pub boundary: Option<Boundary<D>>,
    pub winding: Option<FastWinding<D>>,
    pub interior: Interior<D>,
    pub wn_l: f64,
    pub wn_h: f64,
    /// Estimated volume (area in 2D) of the domain: the `V(P)` of eq. 10.
    pub volume: f64,
}

/// Draws before giving up on finding one interior point by rejection.
const MAX_ATTEMPTS: usize = 100_000;

/// Volume of the simplex with corners `p[0..=D]`.
fn simplex_volume<const D: usize>(p: &[[f64; D]]) -> f64 {
    let a = sub(&p[1], &p[0]);
    let b = sub(&p[2], &p[0]);
    if D == 2 {
        0.5 * (a[0] * b[1 % D] - a[1 % D] * b[0]).abs()
    } else {
        let c = sub(&p[3], &p[0]);
        let (a, b, c) = (pad(&a), pad(&b), pad(&c));
        (super::dot(&a, &super::cross(&b, &c)) / 6.0).abs()
    }
}

#[inline]
fn pad<const D: usize>(p: &[f64; D]) -> [f64; 3] {
    std::array::from_fn(|k| if k < D { p[k] } else { 0.0 })
}

impl<const D: usize> Domain<D>
where
    Boundary<D>: BoundaryQueries<D>,
{
    /// Domain bounded by `v` (#V by D) and `f` (#F by D boundary elements), optionally with an
    /// interior mesh `simplices` (#S by D + 1, rows index `v`); `f` may be empty only for a
    /// point cloud (then `v` are the cloud's points and `cloud_radius` the ball radius).
    pub fn new(
        v: ArrayView2<f64>,
        f: Option<ArrayView2<usize>>,
        simplices: Option<ArrayView2<usize>>,
        cloud_radius: f64,
        wn_l: f64,
        wn_h: f64,
    ) -> SkinResult<Self> {
        if wn_l.is_nan() || wn_h.is_nan() || wn_l >= wn_h {
            return invalid!("wn_l must be smaller than wn_h, got {wn_l} and {wn_h}");
        }
        let verts: Vec<[f64; D]> = (0..v.nrows()).map(|i| super::row(&v, i)).collect();
        let (boundary, winding) = match f {
            Some(f) => (
                Some(Boundary::<D>::new(v, f)?),
                Some(FastWinding::<D>::new(v, f, if D == 3 { 2.0 } else { 4.0 })?),
            ),
            None => (None, None),
        };
        let interior = if let Some(s) = simplices {
            simplex_interior(&verts, s)?
        } else if boundary.is_some() {
            let mut lo = [f64::INFINITY; D];
            let mut hi = [f64::NEG_INFINITY; D];
            for p in &verts {
                for k in 0..D {
                    lo[k] = lo[k].min(p[k]);
                    hi[k] = hi[k].max(p[k]);
                }
            }
            Interior::Winding { lo, hi }
        } else {
            if !(cloud_radius > 0.0 && cloud_radius.is_finite()) {
                return invalid!("point cloud ball radius must be positive, got {cloud_radius}");
            }
            Interior::Cloud {
                points: verts,
                radius: cloud_radius,
            }
        };
        let volume = match &interior {
            Interior::Simplices { cdf, .. } => *cdf.last().unwrap_or(&0.0),
            _ => 1.0, // replaced by the acceptance-rate estimate in `estimate_volume`
        };
        Ok(Domain {
            boundary,
            winding,
            interior,
            wn_l,
            wn_h,
            volume,
        })
    }

    /// Energy weight of eq. 11 for winding number `wn`.
    #[inline]
    pub fn wn_weight(&self, wn: f64) -> f64 {
        ((wn - self.wn_l) / (self.wn_h - self.wn_l)).clamp(0.0, 1.0)
    }

    /// Winding number at `x` (1 without a boundary).
    #[inline]
    pub fn wn(&self, x: &[f64; D]) -> f64 {
        self.winding.as_ref().map_or(1.0, |w| w.eval(x))
    }

    /// Distance from `x` to the boundary (infinite without one).
    #[inline]
    pub fn dist(&self, x: &[f64; D]) -> f64 {
        self.boundary
            .as_ref()
            .map_or(f64::INFINITY, |b| b.closest(x).dist)
    }

    /// One uniform interior sample from `rng`, or `None` after [`MAX_ATTEMPTS`] rejections.
    /// Also returns the number of candidates drawn.
    pub fn draw(&self, rng: &mut Rng) -> (Option<Sample<D>>, usize) {
        match &self.interior {
            Interior::Winding { lo, hi } => {
                for a in 1..=MAX_ATTEMPTS {
                    let x: [f64; D] =
                        std::array::from_fn(|k| lo[k] + (hi[k] - lo[k]) * rng.uniform());
                    let wn = self.wn(&x);
                    if wn >= self.wn_l {
                        let weight = self.wn_weight(wn);
                        return (Some(Sample { x, weight }), a);
                    }
                }
                (None, MAX_ATTEMPTS)
            }
            Interior::Simplices { verts, elems, cdf } => {
                let total = *cdf.last().unwrap_or(&0.0);
                let t = rng.uniform() * total;
                let e = cdf.partition_point(|&c| c <= t).min(elems.len() - 1);
                // Uniform barycentric coordinates: sorted uniforms' gaps.
                let mut u: Vec<f64> = (0..D).map(|_| rng.uniform()).collect();
                u.sort_by(f64::total_cmp);
                let mut x = [0.0; D];
                let mut prev = 0.0;
                for c in 0..=D {
                    let next = if c < D { u[c] } else { 1.0 };
                    let b = next - prev;
                    prev = next;
                    let p = &verts[elems[e][c]];
                    for k in 0..D {
                        x[k] += b * p[k];
                    }
                }
                (Some(Sample { x, weight: 1.0 }), 1)
            }
            Interior::Cloud { points, radius } => {
                let p = points[rng.below(points.len())];
                let o: [f64; D] = rng.in_ball();
                let x = super::add(&p, &scale(&o, *radius));
                (Some(Sample { x, weight: 1.0 }), 1)
            }
        }
    }

    /// `n` samples, sample `i` drawn from stream `(seed, tag, i)`, in parallel; also the total
    /// number of candidates drawn (for the volume estimate).
    pub fn sample(&self, n: usize, seed: u64, tag: u64) -> SkinResult<(Vec<Sample<D>>, usize)> {
        let r: Vec<(Option<Sample<D>>, usize)> = (0..n)
            .into_par_iter()
            .map(|i| self.draw(&mut Rng::stream(seed, tag, i as u64)))
            .collect();
        let tries = r.iter().map(|x| x.1).sum();
        let out: Option<Vec<Sample<D>>> = r.into_iter().map(|x| x.0).collect();
        match out {
            Some(s) => Ok((s, tries)),
            None => invalid!(
                "could not find points inside the shape: the generalized winding number stays \
                 below wn_l = {} in {MAX_ATTEMPTS} random points of the bounding box (is the \
                 boundary empty, flat, or oriented inward?)",
                self.wn_l
            ),
        }
    }

    /// Sets `volume` from an acceptance rate `accepted / tries` (rejection sampling only).
    pub fn estimate_volume(&mut self, accepted: usize, tries: usize) {
        if let Interior::Winding { lo, hi } = &self.interior {
            let box_vol: f64 = (0..D).map(|k| hi[k] - lo[k]).product();
            self.volume = box_vol * accepted as f64 / tries.max(1) as f64;
        }
    }
}

/// The `Simplices` interior from #S by D + 1 element rows.
fn simplex_interior<const D: usize>(
    verts: &[[f64; D]],
    s: ArrayView2<usize>,
) -> SkinResult<Interior<D>> {
    if s.ncols() != D + 1 {
        return invalid!(
            "interior elements in {D}D need {} columns, got {}",
            D + 1,
            s.ncols()
        );
    }
    if s.nrows() == 0 {
        return invalid!("the interior mesh has no elements");
    }
    let mut elems = Vec::with_capacity(s.nrows());
    let mut cdf = Vec::with_capacity(s.nrows());
    let mut acc = 0.0;
    for r in s.rows() {
        let mut e = [0usize; 4];
        for c in 0..=D {
            if r[c] >= verts.len() {
                return invalid!("interior element index {} outside 0..{}", r[c], verts.len());
            }
            e[c] = r[c];
        }
        let p: Vec<[f64; D]> = (0..=D).map(|c| verts[e[c]]).collect();
        acc += simplex_volume(&p);
        elems.push(e);
        cdf.push(acc);
    }
    if acc.is_nan() || acc <= 0.0 {
        return invalid!("the interior mesh has zero volume");
    }
    Ok(Interior::Simplices {
        verts: verts.to_vec(),
        elems,
        cdf,
    })
}

/// Rows of a list of points as an #X by D array.
pub fn to_array<const D: usize>(x: &[[f64; D]]) -> Array2<f64> {
    Array2::from_shape_fn((x.len(), D), |(i, k)| x[i][k])
}

/// Squared distance (helper shared by the field modules).
#[inline]
pub fn dist2<const D: usize>(a: &[f64; D], b: &[f64; D]) -> f64 {
    norm2(&sub(a, b))
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::array;

    #[test]
    fn square_rejection_and_simplices() {
        let v = array![[0., 0.], [1., 0.], [1., 1.], [0., 1.], [2.0, 2.0]];
        let f = array![[0usize, 1], [1, 2], [2, 3], [3, 0]];
        let mut d = Domain::<2>::new(v.view(), Some(f.view()), None, 0.0, 0.1, 0.25).unwrap();
        let (s, tries) = d.sample(4000, 3, 0).unwrap();
        d.estimate_volume(s.len(), tries);
        // Box [0,2]^2 (vertex 4 enlarges it), unit square inside: volume ~ 1.
        assert!((d.volume - 1.0).abs() < 0.08, "{}", d.volume);
        assert!(s.iter().all(|p| p.x[0] <= 1.0 && p.x[1] <= 1.0));
        let t = array![[0usize, 1, 2], [0, 2, 3]];
        let d = Domain::<2>::new(v.view(), Some(f.view()), Some(t.view()), 0.0, 0.1, 0.25).unwrap();
        assert!((d.volume - 1.0).abs() < 1e-12);
        let (s, _) = d.sample(1000, 3, 0).unwrap();
        assert!(s
            .iter()
            .all(|p| (0.0..=1.0).contains(&p.x[0]) && p.weight == 1.0));
    }
}
