//! Queries on a [`HashGrid`]: points within a radius, the k nearest points (a ring search
//! over cells, with a linear scan as fallback far from the points), and [`knn_distance`], the
//! distance from every point to its k-th nearest other point.

use ndarray::ArrayView2;
use rayon::prelude::*;

use super::HashGrid;
use crate::error::SkinResult;
use crate::field::{norm2, sub};
use crate::invalid;
use crate::progress::{Event, Progress};

impl<const D: usize> HashGrid<D> {
    /// Calls `visit(i, |x_i - q|^2)` for every point in the cells overlapping the box
    /// `q +- r`; the caller filters by distance.
    fn for_cells_in_box(&self, q: &[f64; D], r: f64, mut visit: impl FnMut(u32, f64)) {
        let lo: [i64; D] = std::array::from_fn(|k| {
            (((q[k] - r - self.origin[k]) / self.cell).floor() as i64).max(self.key_lo[k])
        });
        let hi: [i64; D] = std::array::from_fn(|k| {
            (((q[k] + r - self.origin[k]) / self.cell).floor() as i64).min(self.key_hi[k])
        });
        if (0..D).any(|k| lo[k] > hi[k]) {
            return;
        }
        let mut c = lo;
        loop {
            if let Some((s, e)) = self.cell_range(&c) {
                for &i in &self.order[s as usize..e as usize] {
                    visit(i, norm2(&sub(&self.points[i as usize], q)));
                }
            }
            // Odometer increment over the box of cells.
            let mut a = 0;
            loop {
                if a == D {
                    return;
                }
                if c[a] < hi[a] {
                    c[a] += 1;
                    break;
                }
                c[a] = lo[a];
                a += 1;
            }
        }
    }

    /// Indices of all points within distance `r` of `q` (boundary included), appended to `out`.
    pub fn radius(&self, q: &[f64; D], r: f64, out: &mut Vec<usize>) {
        let r2 = r * r;
        self.for_cells_in_box(q, r, |i, d2| {
            if d2 <= r2 {
                out.push(i as usize);
            }
        });
    }

    /// The `k` nearest points to `q` as `(distance, index)`, nearest first (ties by index),
    /// never returning `skip`. Fewer than `k` only if the grid holds fewer points.
    pub fn knn(&self, q: &[f64; D], k: usize, skip: Option<usize>) -> Vec<(f64, usize)> {
        let mut best: Vec<(f64, u32)> = Vec::with_capacity(k + 1);
        if k == 0 {
            return Vec::new();
        }
        let skip = skip.map(|s| s as u32);
        let c = self.key(q);
        // Rings of cells at Chebyshev distance s around q's cell. Every point not yet seen lies
        // outside the cube of searched cells, so stop once the k-th best distance is within the
        // distance from q to that cube's boundary (at least s * cell).
        let max_ring = (0..D)
            .map(|a| {
                c[a].saturating_sub(self.key_lo[a])
                    .max(self.key_hi[a].saturating_sub(c[a]))
                    .max(0)
            })
            .max()
            .unwrap_or(0);
        // Far from the points (an outlier, a query far outside) the rings would visit more
        // cells than there are points: past this many cells, one linear scan is cheaper.
        let cell_budget = 8.0 * self.points.len() as f64 + 64.0;
        let mut s: i64 = 0;
        loop {
            if ((2 * s + 1) as f64).powi(D as i32) > cell_budget {
                return self.knn_scan(q, k, skip);
            }
            self.ring(&c, s, |i| {
                if Some(i) == skip {
                    return;
                }
                let d2 = norm2(&sub(&self.points[i as usize], q));
                if best.len() == k {
                    let w = best[k - 1];
                    if d2 > w.0 || (d2 == w.0 && i > w.1) {
                        return;
                    }
                }
                let pos = best.partition_point(|&(bd, bi)| bd < d2 || (bd == d2 && bi < i));
                best.insert(pos, (d2, i));
                best.truncate(k);
            });
            if s >= max_ring {
                break;
            }
            if best.len() == k {
                // Distance from q to the outside of the cube of cells searched so far.
                let mut reach = f64::INFINITY;
                for a in 0..D {
                    let lo = self.origin[a] + (c[a] - s) as f64 * self.cell;
                    let hi = self.origin[a] + (c[a] + s + 1) as f64 * self.cell;
                    reach = reach.min(q[a] - lo).min(hi - q[a]);
                }
                if best[k - 1].0 <= reach * reach {
                    break;
                }
            }
            s += 1;
        }
        best.into_iter()
            .map(|(d2, i)| (d2.sqrt(), i as usize))
            .collect()
    }

    /// [`HashGrid::knn`] by one pass over every point (linear time, no ring search).
    fn knn_scan(&self, q: &[f64; D], k: usize, skip: Option<u32>) -> Vec<(f64, usize)> {
        let mut all: Vec<(f64, u32)> = (0..self.points.len() as u32)
            .filter(|&i| Some(i) != skip)
            .map(|i| (norm2(&sub(&self.points[i as usize], q)), i))
            .collect();
        let by = |a: &(f64, u32), b: &(f64, u32)| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1));
        if k < all.len() {
            all.select_nth_unstable_by(k, by);
            all.truncate(k);
        }
        all.sort_unstable_by(by);
        all.into_iter()
            .map(|(d2, i)| (d2.sqrt(), i as usize))
            .collect()
    }

    /// Calls `visit` for every point in the cells at Chebyshev distance exactly `s` from `c`.
    fn ring(&self, c: &[i64; D], s: i64, mut visit: impl FnMut(u32)) {
        let lo: [i64; D] = std::array::from_fn(|k| c[k].saturating_sub(s));
        let hi: [i64; D] = std::array::from_fn(|k| c[k].saturating_add(s));
        let mut x = lo;
        loop {
            let on_ring = (0..D).any(|k| x[k] == lo[k] || x[k] == hi[k]);
            if on_ring {
                if let Some((a, b)) = self.cell_range(&x) {
                    for &i in &self.order[a as usize..b as usize] {
                        visit(i);
                    }
                }
            }
            // Odometer; on interior rows jump straight from lo to hi along axis 0.
            let mut a = 0;
            loop {
                if a == D {
                    return;
                }
                if x[a] < hi[a] {
                    let interior = a == 0 && (1..D).all(|k| x[k] != lo[k] && x[k] != hi[k]);
                    x[a] = if interior && x[a] == lo[a] {
                        hi[a]
                    } else {
                        x[a] + 1
                    };
                    break;
                }
                x[a] = lo[a];
                a += 1;
            }
        }
    }

    /// For every point, the distance to its `k`-th nearest other point, in parallel; blocks of
    /// points report to `progress` in between (Ctrl-C stops the computation there).
    pub fn knn_distance_self(&self, k: usize, progress: &mut dyn Progress) -> SkinResult<Vec<f64>> {
        if k == 0 || k >= self.points.len() {
            return invalid!(
                "k must be in 1..{} (fewer than the number of points), got {k}",
                self.points.len()
            );
        }
        let n = self.points.len();
        let mut out = Vec::with_capacity(n);
        for start in (0..n).step_by(PROGRESS_BLOCK) {
            let end = (start + PROGRESS_BLOCK).min(n);
            out.par_extend(
                (start..end)
                    .into_par_iter()
                    .map(|i| self.knn(&self.points[i], k, Some(i))[k - 1].0),
            );
            progress.report(Event {
                stage: "knn",
                iteration: end,
                value: f64::NAN,
            })?;
        }
        Ok(out)
    }
}

/// Points per block between two progress reports of a parallel loop.
pub(crate) const PROGRESS_BLOCK: usize = 1 << 14;

/// Distance from each row of `x` (#X by D, D = 2 or 3) to its `k`-th nearest other row.
/// Coincident points count (distance 0). Needs `1 <= k < #X`.
pub fn knn_distance(
    x: ArrayView2<f64>,
    k: usize,
    progress: &mut dyn Progress,
) -> SkinResult<Vec<f64>> {
    match x.ncols() {
        // About k / 2 points per cell: the k-th neighbour then usually lies within one ring of
        // cells, and a ring visits half the points it would with k per cell.
        2 => HashGrid::<2>::auto(x, 0.5 * k as f64)?.knn_distance_self(k, progress),
        3 => HashGrid::<3>::auto(x, 0.5 * k as f64)?.knn_distance_self(k, progress),
        c => invalid!("X must have 2 or 3 columns, got {c}"),
    }
}
