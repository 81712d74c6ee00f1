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
//!
//! Layout: this module builds the grid (cell keys, the sorted point order, the hash map or
//! dense array of cell ranges); [`query`] answers radius and k-nearest-neighbour queries on it
//! and holds [`knn_distance`].

mod query;
#[cfg(test)]
mod tests;

use std::collections::HashMap;
use std::hash::{BuildHasherDefault, Hasher};

use ndarray::ArrayView2;

use super::row;
use crate::error::SkinResult;
use crate::invalid;
pub use query::knn_distance;

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
}
