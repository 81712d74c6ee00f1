//! Uniform hash grid over points: radius queries and k nearest neighbours.
//!
//! Inputs (to [`HashGrid::new`]):
//!   x     #X by D point positions (D = 2 or 3), finite
//!   cell  edge length of the cubic cells (> 0); [`HashGrid::auto`] picks one
//! Queries:
//!   radius(q, r) -> indices of all points with |x_i - q| <= r (unordered)
//!   knn(q, k, skip) -> the k nearest points as (distance, index), nearest first, optionally
//!                      skipping one index (the query point itself)
//!   [`knn_distance`] (x, k) -> #X distances from each point to its k-th nearest other point
//!
//! Why a hash grid and not a tree: the field method (Dodik et al. 2024, Sec. 4.1) truncates its
//! kernel at `r = 3 sigma` with `sigma` about the 9th-neighbour spacing, so every radius query
//! touches a bounded number of cells of that size, and a grid answers it with no traversal.
//! Only occupied cells are stored (a hash map), so shapes with large empty bounding boxes
//! (thin limbs, surfaces sampled in 3D) cost memory proportional to the points, not the box;
//! when the occupied box has at most ~4 cells per point a dense array replaces the hash map.
//! Points are sorted by cell so each cell is a contiguous range of `order`.

use std::collections::HashMap;
use std::hash::{BuildHasherDefault, Hasher};

use ndarray::ArrayView2;
use rayon::prelude::*;

use super::{norm2, row, sub};
use crate::error::SkinResult;
use crate::invalid;
use crate::progress::{Event, Progress};

/// Multiplicative hash for integer cell keys. The default SipHash is built to resist
/// adversarial keys, which cell coordinates are not, and costs more than the distance tests a
/// lookup guards; this one (the Fx hash of rustc) is a rotate, xor and multiply per word.
#[derive(Default, Clone, Copy)]
pub struct CellHasher(u64);

impl Hasher for CellHasher {
    #[inline]
    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.write_u64(b as u64);
        }
    }

    #[inline]
    fn write_u64(&mut self, x: u64) {
        self.0 = (self.0.rotate_left(5) ^ x).wrapping_mul(0x51_7c_c1_b7_27_22_0a_95);
    }

    #[inline]
    fn write_i64(&mut self, x: i64) {
        self.write_u64(x as u64);
    }

    #[inline]
    fn write_usize(&mut self, x: usize) {
        self.write_u64(x as u64);
    }

    #[inline]
    fn finish(&self) -> u64 {
        self.0
    }
}

type CellMap<const D: usize> = HashMap<[i64; D], (u32, u32), BuildHasherDefault<CellHasher>>;

#[derive(Clone, Debug)]
pub struct HashGrid<const D: usize> {
    points: Vec<[f64; D]>,
    origin: [f64; D],
    cell: f64,
    /// Cell key -> range of `order`.
    cells: CellMap<D>,
    /// The same ranges as a dense array over the occupied key box, when that box has at most a
    /// few cells per point (then `cells` is left empty): an index computation instead of a
    /// hash lookup, which matters because searches mostly visit empty or nearly empty cells.
    dense: Option<Vec<(u32, u32)>>,
    strides: [usize; D],
    order: Vec<u32>,
    /// Smallest and largest occupied cell key per axis (bounds the kNN ring search).
    key_lo: [i64; D],
    key_hi: [i64; D],
}

impl<const D: usize> HashGrid<D> {
    /// Grid with cells of edge `cell` over the rows of `x` (#X by D, at least one row).
    pub fn new(x: ArrayView2<f64>, cell: f64) -> SkinResult<Self> {
        if x.ncols() != D {
            return invalid!("points must have {D} columns, got shape {:?}", x.dim());
        }
        if x.nrows() == 0 {
            return invalid!("the point set is empty");
        }
        if x.nrows() > u32::MAX as usize {
            return invalid!("too many points ({})", x.nrows());
        }
        if !(cell > 0.0 && cell.is_finite()) {
            return invalid!("cell size must be positive and finite, got {cell}");
        }
        crate::limits::check_coordinates("X", &x)?;
        let points: Vec<[f64; D]> = (0..x.nrows()).map(|i| row(&x, i)).collect();
        let mut origin = [f64::INFINITY; D];
        for p in &points {
            for k in 0..D {
                origin[k] = origin[k].min(p[k]);
            }
        }
        let key = |p: &[f64; D]| -> [i64; D] {
            std::array::from_fn(|k| ((p[k] - origin[k]) / cell).floor() as i64)
        };
        let keys: Vec<[i64; D]> = points.iter().map(key).collect();
        let mut order: Vec<u32> = (0..points.len() as u32).collect();
        order.sort_unstable_by(|&a, &b| keys[a as usize].cmp(&keys[b as usize]));
        let mut cells = CellMap::<D>::default();
        let (mut key_lo, mut key_hi) = ([i64::MAX; D], [i64::MIN; D]);
        let mut s = 0;
        while s < order.len() {
            let k = keys[order[s] as usize];
            let mut e = s + 1;
            while e < order.len() && keys[order[e] as usize] == k {
                e += 1;
            }
            cells.insert(k, (s as u32, e as u32));
            for a in 0..D {
                key_lo[a] = key_lo[a].min(k[a]);
                key_hi[a] = key_hi[a].max(k[a]);
            }
            s = e;
        }
        let mut strides = [0usize; D];
        let mut total: Option<usize> = Some(1);
        for a in (0..D).rev() {
            strides[a] = total.unwrap_or(0);
            let span = key_hi[a]
                .checked_sub(key_lo[a])
                .and_then(|w| w.checked_add(1))
                .and_then(|w| usize::try_from(w).ok());
            total = total.zip(span).and_then(|(t, w)| t.checked_mul(w));
        }
        let dense = match total {
            Some(t) if t <= 4 * points.len() + 4096 => {
                let mut d = vec![(0u32, 0u32); t];
                for (k, r) in cells.drain() {
                    let idx: usize = (0..D)
                        .map(|a| (k[a] - key_lo[a]) as usize * strides[a])
                        .sum();
                    d[idx] = r;
                }
                Some(d)
            }
            _ => None,
        };
        Ok(HashGrid {
            points,
            origin,
            cell,
            cells,
            dense,
            strides,
            order,
            key_lo,
            key_hi,
        })
    }

    /// Grid whose cells hold about `per_cell` points if the points filled their bounding box;
    /// axes with (near) zero extent count as 1e-3 of the largest one.
    pub fn auto(x: ArrayView2<f64>, per_cell: f64) -> SkinResult<Self> {
        let mut ext = [0.0f64; D];
        if x.ncols() == D && x.nrows() > 0 {
            for (k, e) in ext.iter_mut().enumerate() {
                let c = x.column(k);
                let lo = c.iter().cloned().fold(f64::INFINITY, f64::min);
                let hi = c.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
                *e = hi - lo;
            }
        }
        let big = ext.iter().cloned().fold(0.0, f64::max);
        // The box volume relative to `big^D` (each factor in [1e-3, 1]), so that neither the
        // volume nor the cell size overflows or underflows for any finite coordinates.
        let rel: f64 = ext.iter().map(|&e| (e / big).max(1e-3)).product();
        let cell = big * (rel * per_cell.max(1.0) / x.nrows().max(1) as f64).powf(1.0 / D as f64);
        let cell = if cell > 0.0 && cell.is_finite() {
            cell
        } else if big > 0.0 && big.is_finite() {
            big
        } else {
            1.0
        };
        Self::new(x, cell)
    }

    pub fn cell_size(&self) -> f64 {
        self.cell
    }

    pub fn len(&self) -> usize {
        self.points.len()
    }

    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }

    /// Range of `order` holding the points of cell `key`, if any.
    #[inline]
    fn cell_range(&self, key: &[i64; D]) -> Option<(u32, u32)> {
        match &self.dense {
            Some(d) => {
                let mut idx = 0;
                for (a, &k) in key.iter().enumerate() {
                    if k < self.key_lo[a] || k > self.key_hi[a] {
                        return None;
                    }
                    idx += (k - self.key_lo[a]) as usize * self.strides[a];
                }
                let r = d[idx];
                (r.0 < r.1).then_some(r)
            }
            None => self.cells.get(key).copied(),
        }
    }

    fn key(&self, p: &[f64; D]) -> [i64; D] {
        std::array::from_fn(|k| ((p[k] - self.origin[k]) / self.cell).floor() as i64)
    }

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

#[cfg(test)]
mod tests {
    use super::*;

    fn cloud(n: usize, seed: u64) -> ndarray::Array2<f64> {
        let mut s = seed;
        ndarray::Array2::from_shape_fn((n, 3), |(_, k)| {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let u = (s >> 11) as f64 / (1u64 << 53) as f64;
            if k == 2 {
                0.1 * u
            } else {
                u
            }
        })
    }

    fn check_against_brute_force(x: &ndarray::Array2<f64>, g: &HashGrid<3>, r: f64) {
        let n = x.nrows();
        let pts: Vec<[f64; 3]> = (0..n).map(|i| row(&x.view(), i)).collect();
        for qi in [0usize, 17, 123, n - 1] {
            let q = pts[qi];
            let mut d: Vec<(f64, usize)> = pts
                .iter()
                .enumerate()
                .filter(|&(i, _)| i != qi)
                .map(|(i, p)| (norm2(&sub(p, &q)).sqrt(), i))
                .collect();
            d.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
            let got = g.knn(&q, 9, Some(qi));
            assert_eq!(got.len(), 9);
            for (a, b) in got.iter().zip(&d) {
                assert_eq!(a.1, b.1);
                assert!((a.0 - b.0).abs() < 1e-15);
            }
            let mut got = Vec::new();
            g.radius(&q, r, &mut got);
            got.sort();
            let want: Vec<usize> = (0..n)
                .filter(|&i| norm2(&sub(&pts[i], &q)) <= r * r)
                .collect();
            assert_eq!(got, want);
        }
    }

    #[test]
    fn radius_and_knn_match_brute_force() {
        // Dense cell array.
        let x = cloud(500, 7);
        let g = HashGrid::<3>::auto(x.view(), 3.0).unwrap();
        assert!(g.dense.is_some());
        check_against_brute_force(&x, &g, 0.12);
        // Two clusters far apart: the occupied key box is huge, so the hash map is used.
        let mut y = cloud(400, 11);
        for i in 200..400 {
            for k in 0..3 {
                y[[i, k]] += 1000.0;
            }
        }
        let g = HashGrid::<3>::new(y.view(), 0.05).unwrap();
        assert!(g.dense.is_none());
        check_against_brute_force(&y, &g, 0.12);
        let g = HashGrid::<3>::auto(y.view(), 4.0).unwrap();
        check_against_brute_force(&y, &g, 30.0);
        let kd = knn_distance(x.view(), 9, &mut crate::Silent).unwrap();
        assert_eq!(kd.len(), 500);
        assert!(kd.iter().all(|&v| v > 0.0));
        assert!(knn_distance(x.view(), 500, &mut crate::Silent).is_err());
    }

    #[test]
    fn far_outlier_falls_back_to_a_linear_scan() {
        let mut x = cloud(400, 7);
        x[[0, 0]] = 1e6;
        let g = HashGrid::<3>::auto(x.view(), 4.5).unwrap();
        check_against_brute_force(&x, &g, 0.3);
        let q = [1e9, 0.5, 0.5];
        let near = g.knn(&q, 3, None);
        assert_eq!(near[0].1, 0);
        assert_eq!(near.len(), 3);
    }
}
