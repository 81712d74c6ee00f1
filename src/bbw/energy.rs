//! The biharmonic energy from the factors of `B = L^T D L`, accurate on meshes with slivers.
//!
//! `1/2 w^T B w` summed entry by entry is the difference of terms as large as `B`'s entries. A
//! sliver element puts a cotangent of 1e6-1e7 on the edge between two nearly coincident
//! vertices, `B` then holds entries near 1e13, and an energy of 100 keeps no correct digit of the
//! 1e-6 the duality gap is measured to. Written as `1/2 sum_i d_i ((L w)_i)^2` with each row of
//! `L w` a sum of differences `L_ik (w_k - w_i)` (the rows of `L` sum to zero), every term is
//! non-negative and the large cotangent multiplies a small difference: the sum is accurate to a
//! few ulps of the energy itself.

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

    /// `1/2 w^T B w` for one full column `w` (length `n`).
    pub fn column_energy(&self, w: &[f64]) -> f64 {
        let sym = self.l.symbolic();
        let (col_ptr, row_idx, val) = (sym.col_ptr(), sym.row_idx(), self.l.val());
        let mut sum = 0.0;
        for (i, &wi) in w.iter().enumerate() {
            // Column i of the symmetric L is row i; its diagonal is implied by the zero row sum.
            let mut lw = 0.0;
            for q in col_ptr[i]..col_ptr[i + 1] {
                if row_idx[q] != i {
                    lw += val[q] * (w[row_idx[q]] - wi);
                }
            }
            sum += self.d[i] * lw * lw;
        }
        0.5 * sum
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
        let (a, ref_) = (e.column_energy(&w), matrix_energy(&b, &w));
        assert!((a - ref_).abs() <= 1e-12 * ref_, "{a} vs {ref_}");
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
        assert_eq!(e.column_energy(&[0.75; 5]), 0.0);
        let w = [0.0, 0.25, 0.5, 0.125, 0.25];
        let shifted: Vec<f64> = w.iter().map(|x| x + 1.0).collect();
        let (a, b) = (e.column_energy(&w), e.column_energy(&shifted));
        assert!(a > 0.0);
        assert_eq!(a, b);
    }
}
