//! The biharmonic energy from the factors of `B = L^T D L`, accurate on meshes with slivers.
//!
//! `1/2 w^T B w` summed entry by entry is the difference of terms as large as `B`'s entries. A
//! sliver element puts a cotangent of 1e6-1e7 on the edge between two nearly coincident
//! vertices, `B` then holds entries near 1e13, and an energy of 100 keeps no correct digit of the
//! 1e-6 the duality gap is measured to. Written as `1/2 sum_i d_i ((L w)_i)^2` with each row of
//! `L w` a sum of differences `L_ik (w_k - w_i)` (the rows of `L` sum to zero), every term is
//! non-negative and the large cotangent multiplies a small difference: the sum is accurate to a
//! few ulps of the energy itself.

use rayon::prelude::*;

use crate::error::SkinResult;
use crate::operators::scaled_inverse_masses;
use crate::sparse::Csc;

/// The factors of `B = L^T D L`: a symmetric Laplacian `L` whose rows sum to zero (as built by
/// [`cotan_laplacian`](crate::operators::cotan_laplacian)) and the diagonal `D`.
pub struct LaplacianEnergy {
    l: Csc,
    d: Vec<f64>,
}

impl LaplacianEnergy {
    /// The energy of [`biharmonic_from_parts(l, masses)`](crate::operators::biharmonic_from_parts).
    ///
    /// Errors: `l` not square, `masses` of the wrong length, or a used vertex with a
    /// non-positive mass.
    pub fn new(l: Csc, masses: &[f64]) -> SkinResult<Self> {
        let d = scaled_inverse_masses(&l, masses)?;
        Ok(LaplacianEnergy { l, d })
    }

    /// Number of vertices.
    pub fn n(&self) -> usize {
        self.l.ncols()
    }

    /// `1/2 tr(W^T B W)` for the full `n x m` weights `w`, stored row by row.
    ///
    /// Row by row, the differences `w_k - w_i` of all `m` columns are contiguous; the rows are
    /// summed in fixed chunks, so the result does not depend on the scheduling.
    pub fn energy(&self, w: &[f64], m: usize) -> f64 {
        const ROWS_PER_CHUNK: usize = 512;
        let n = self.n();
        debug_assert_eq!(w.len(), n * m);
        let sym = self.l.symbolic();
        let (col_ptr, row_idx, val) = (sym.col_ptr(), sym.row_idx(), self.l.val());
        let chunk_sums: Vec<f64> = (0..n.div_ceil(ROWS_PER_CHUNK))
            .into_par_iter()
            .map(|chunk| {
                let (mut sum, mut lw) = (0.0, vec![0.0; m]);
                for i in chunk * ROWS_PER_CHUNK..((chunk + 1) * ROWS_PER_CHUNK).min(n) {
                    let wi = &w[i * m..(i + 1) * m];
                    lw.fill(0.0);
                    // Column i of the symmetric L is row i; its diagonal is implied by the
                    // zero row sum.
                    for q in col_ptr[i]..col_ptr[i + 1] {
                        let k = row_idx[q];
                        if k != i {
                            let (v, wk) = (val[q], &w[k * m..(k + 1) * m]);
                            for ((l, a), b) in lw.iter_mut().zip(wk).zip(wi) {
                                *l += v * (a - b);
                            }
                        }
                    }
                    sum += self.d[i] * lw.iter().map(|l| l * l).sum::<f64>();
                }
                sum
            })
            .collect();
        0.5 * chunk_sums.iter().sum::<f64>()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::operators::{biharmonic_from_parts, cotan_laplacian, massmatrix, MassKind};
    use ndarray::array;

    /// `w^T B w` by the matrix, for comparison.
    fn matrix_energy(b: &Csc, w: &[f64]) -> f64 {
        let mut e = 0.0;
        for j in 0..b.ncols() {
            let rows = b.symbolic().row_idx_of_col_raw(j);
            for (&i, &v) in rows.iter().zip(b.val_of_col(j)) {
                e += w[i] * v * w[j];
            }
        }
        0.5 * e
    }

    #[test]
    fn equals_the_matrix_energy_on_a_well_shaped_mesh() {
        let v = array![[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0], [0.4, 0.6]];
        let f = array![[0usize, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4]];
        let l = cotan_laplacian(v.view(), f.view()).unwrap();
        let m = massmatrix(v.view(), f.view(), MassKind::Voronoi).unwrap();
        let b = biharmonic_from_parts(&l, &m).unwrap();
        let e = LaplacianEnergy::new(l, &m).unwrap();
        let w = vec![0.3, -0.2, 0.9, 0.1, 0.5];
        let (a, ref_) = (e.energy(&w, 1), matrix_energy(&b, &w));
        assert!((a - ref_).abs() <= 1e-12 * ref_, "{a} vs {ref_}");
    }

    #[test]
    fn sums_the_columns_of_a_row_major_block() {
        // A 30 x 30 grid: more rows than one chunk, three columns side by side in each row.
        let k = 30;
        let v = ndarray::Array2::from_shape_fn((k * k, 2), |(i, d)| {
            let (r, c) = (i / k, i % k);
            (if d == 0 { c } else { r }) as f64 + 0.1 * ((i * 7) % 5) as f64 / 5.0
        });
        let mut f = Vec::new();
        for r in 0..k - 1 {
            for c in 0..k - 1 {
                let i = r * k + c;
                f.extend_from_slice(&[i, i + 1, i + k + 1, i, i + k + 1, i + k]);
            }
        }
        let f = ndarray::Array2::from_shape_vec((f.len() / 3, 3), f).unwrap();
        let l = cotan_laplacian(v.view(), f.view()).unwrap();
        let mass = massmatrix(v.view(), f.view(), MassKind::Voronoi).unwrap();
        let b = biharmonic_from_parts(&l, &mass).unwrap();
        let e = LaplacianEnergy::new(l, &mass).unwrap();
        let (n, m) = (k * k, 3);
        let col = |c: usize| -> Vec<f64> {
            (0..n)
                .map(|i| ((i * (c + 3) * 31 + 7 * c) % 97) as f64 / 97.0 - 0.3)
                .collect()
        };
        let mut rows = vec![0.0; n * m];
        for c in 0..m {
            for (i, x) in col(c).into_iter().enumerate() {
                rows[i * m + c] = x;
            }
        }
        let ref_: f64 = (0..m).map(|c| matrix_energy(&b, &col(c))).sum();
        let a = e.energy(&rows, m);
        assert!((a - ref_).abs() <= 1e-10 * ref_, "{a} vs {ref_}");
    }

    #[test]
    fn is_blind_to_constants_next_to_a_sliver() {
        // Vertex 4 sits 1e-7 from vertex 1: the sliver (4, 1, 2) has a cotangent near 1e7 on
        // the edge (1, 4) and B entries near 1e14, so `w^T B w` summed through the matrix is off
        // by about 1e-2 for any w of size 1, even a constant one. The difference form gives a
        // constant exactly zero energy, and the same energy to w and w + 1 (the weights below
        // are dyadic, so w + 1 is exact).
        let v = array![
            [0.0, 0.0],
            [1.0, 0.0],
            [1.0, 1.0],
            [0.0, 1.0],
            [1.0 - 1e-7, 1e-7]
        ];
        let f = array![[0usize, 4, 3], [4, 1, 2], [4, 2, 3], [0, 1, 4]];
        let l = cotan_laplacian(v.view(), f.view()).unwrap();
        let m = massmatrix(v.view(), f.view(), MassKind::Barycentric).unwrap();
        let e = LaplacianEnergy::new(l, &m).unwrap();
        assert_eq!(e.energy(&[0.75; 5], 1), 0.0);
        let w = [0.0, 0.25, 0.5, 0.125, 0.25];
        let shifted: Vec<f64> = w.iter().map(|x| x + 1.0).collect();
        let (a, b) = (e.energy(&w, 1), e.energy(&shifted, 1));
        assert!(a > 0.0);
        assert_eq!(a, b);
    }
}
