//! Input checks and helpers of [`GeometricField::new`](super::GeometricField::new): the map
//! into the unit box, the checks that the shape has an interior and that every handle reaches
//! into it, the sampling radius of a point cloud, and the spatial (Morton) order of points.

use crate::error::SkinResult;
use crate::field::kernel::SIGMA_KNN;
use crate::field::sampling::Domain;
use crate::field::{knn_distance, Boundary, BoundaryQueries};
use crate::invalid;

/// `(x - offset) * scale` mapping the rows of `v` into the unit box (largest side 1).
pub fn unit_box<const D: usize>(v: &ndarray::ArrayView2<f64>) -> SkinResult<([f64; D], f64)> {
    let mut lo = [f64::INFINITY; D];
    let mut hi = [f64::NEG_INFINITY; D];
    for r in v.rows() {
        for k in 0..D {
            lo[k] = lo[k].min(r[k]);
            hi[k] = hi[k].max(r[k]);
        }
    }
    let ext = (0..D).map(|k| hi[k] - lo[k]).fold(0.0, f64::max);
    if !(ext > 0.0 && ext.is_finite()) {
        return invalid!("the vertices span no extent (all coincide, or V is empty)");
    }
    crate::limits::check_coordinates("V", v)?;
    crate::limits::check_extent("V", ext)?;
    Ok((lo, 1.0 / ext))
}

/// A field lives in a solid (3D) or a region (2D): vertices that span no extent along some axis
/// bound nothing, and every sample would sit on the boundary.
pub(super) fn check_solid<const D: usize>(
    v: &ndarray::ArrayView2<f64>,
    scale: f64,
) -> SkinResult<()> {
    for k in 0..D {
        let c = v.column(k);
        let lo = c.iter().cloned().fold(f64::INFINITY, f64::min);
        let hi = c.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
        if (hi - lo) * scale <= 1e-9 {
            return invalid!(
                "V is flat: it spans no extent along axis {k} ({:e} against {:e} along its \
                 longest axis), so it encloses no {}; a field needs a shape with an interior",
                hi - lo,
                1.0 / scale,
                if D == 3 { "volume" } else { "area" }
            );
        }
    }
    Ok(())
}

/// Morton order of points (see [`crate::field::coherent_order`]).
pub(super) fn spatial_order<const D: usize>(x: &[[f64; D]]) -> Vec<usize> {
    let a = crate::field::sampling::to_array(x);
    crate::field::coherent_order::<D>(&a.view())
}

/// Rows `order[0], order[1], ...` of `v` seen as rows of `width` entries.
pub(super) fn permute<T: Copy>(v: &[T], order: &[usize], width: usize) -> Vec<T> {
    let mut out = Vec::with_capacity(v.len());
    for &i in order {
        out.extend_from_slice(&v[i * width..(i + 1) * width]);
    }
    out
}

pub(super) fn to_unit<const D: usize>(x: &[f64; D], offset: &[f64; D], scale: f64) -> [f64; D] {
    std::array::from_fn(|k| (x[k] - offset[k]) * scale)
}

/// Ball radius for point-cloud sampling: the median distance to the 9th neighbour of the cloud.
pub(super) fn cloud_radius(v: &ndarray::Array2<f64>) -> SkinResult<f64> {
    if v.nrows() <= SIGMA_KNN {
        return invalid!(
            "a point cloud needs more than {} points, got {}",
            SIGMA_KNN,
            v.nrows()
        );
    }
    let mut d = knn_distance(v.view(), SIGMA_KNN, &mut crate::Silent)?;
    d.sort_by(f64::total_cmp);
    Ok(d[d.len() / 2])
}

/// Every handle must reach inside the shape: some point along it (ends and 7 interior points)
/// has winding number >= wn_l.
pub(super) fn check_handles<const D: usize>(
    domain: &Domain<D>,
    handles: &[([f64; D], [f64; D], usize)],
    k: usize,
) -> SkinResult<()>
where
    Boundary<D>: BoundaryQueries<D>,
{
    let mut seen = vec![false; k];
    for (a, b, c) in handles {
        if *c >= k {
            return invalid!("handle column {c} outside 0..{k}");
        }
        seen[*c] = true;
        if domain.winding.is_none() {
            continue;
        }
        let best = (0..=8)
            .map(|s| {
                let t = s as f64 / 8.0;
                let p: [f64; D] = std::array::from_fn(|q| a[q] + t * (b[q] - a[q]));
                domain.wn(&p)
            })
            .fold(f64::NEG_INFINITY, f64::max);
        if best < domain.wn_l {
            return invalid!(
                "handle {c} lies outside the shape: its generalized winding number is at most \
                 {best:.3} < wn_l = {} everywhere along it",
                domain.wn_l
            );
        }
    }
    if let Some(c) = seen.iter().position(|s| !s) {
        return invalid!("handle column {c} has no primitive");
    }
    Ok(())
}
