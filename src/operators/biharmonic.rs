//! Biharmonic energy matrix B = L^T M^-1 L (Solomon & Stein 2025, Sec. 7).

use faer::sparse::SymbolicSparseColMat;
use ndarray::ArrayView2;
use rayon::prelude::*;

use super::cotan::cotan_laplacian;
use super::mass::{massmatrix, MassKind};
use crate::error::{SkinError, SkinResult};
use crate::sparse::Csc;

/// Biharmonic energy matrix of a mesh: `B = L^T M^-1 L` with `L` the cotangent Laplacian and
/// `M` the lumped mass matrix divided by its largest entry (paper Sec. 7, "for numerical
/// stability"); the energy of weights `w` is `w^T B w`.
///
/// Inputs:
///   v     #V by dim vertex positions
///   f     #F by 3 triangles or #F by 4 tetrahedra
///   kind  mass matrix lumping (the paper uses [`MassKind::Voronoi`])
/// Output:
///   B  #V by #V sparse, exactly symmetric, positive semidefinite.
/// Errors: see [`check_elements`](super::check_elements); `Numerical` if a vertex used by an
/// element has a non-positive mass.
pub fn biharmonic_matrix(
    v: ArrayView2<f64>,
    f: ArrayView2<usize>,
    kind: MassKind,
) -> SkinResult<Csc> {
    let l = cotan_laplacian(v, f)?;
    let m = massmatrix(v, f, kind)?;
    biharmonic_from_parts(&l, &m)
}

/// The diagonal `max(m) / m` of `B = L^T diag(max(m) / m) L` (the masses rescaled by their
/// largest entry first), zero for the vertices with an empty column in `L` (unused, whose mass may
/// be zero).
///
/// Errors: `l` not square or `m` of another length; `Numerical` if a used vertex has a mass that
/// is not positive and finite.
pub fn scaled_inverse_masses(l: &Csc, m: &[f64]) -> SkinResult<Vec<f64>> {
    let n = l.ncols();
    if l.nrows() != n || m.len() != n {
        return Err(SkinError::InvalidInput(format!(
            "biharmonic: L is {}x{} but there are {} masses",
            l.nrows(),
            n,
            m.len()
        )));
    }
    let col_ptr = l.symbolic().col_ptr();
    let max_m = m.iter().copied().fold(0.0, f64::max);
    let mut inv = vec![0.0; n];
    for k in 0..n {
        if col_ptr[k + 1] > col_ptr[k] {
            let positive = m[k].is_finite() && m[k] > 0.0;
            if !positive {
                return Err(SkinError::Numerical(format!(
                    "vertex {k} has mass {:e}; the mass matrix must be positive (try the \
                     barycentric mass matrix)",
                    m[k]
                )));
            }
            // 1 / (m_k / max m): M is rescaled by its largest entry first.
            inv[k] = 1.0 / (m[k] / max_m);
        }
    }
    Ok(inv)
}

/// `B = L^T diag(max(m) / m) L` for a symmetric `L` (as built by
/// [`cotan_laplacian`]) and the lumped masses `m` (as from [`massmatrix`]).
///
/// The upper triangle is computed column by column (in parallel) as
/// `B_ij = sum_k (max m / m_k) (L_ik L_kj)` and mirrored, so `B` is exactly symmetric. Vertices
/// with an empty column in `L` (unused) may have zero mass.
pub fn biharmonic_from_parts(l: &Csc, m: &[f64]) -> SkinResult<Csc> {
    let n = l.ncols();
    let inv = scaled_inverse_masses(l, m)?;
    let sym = l.symbolic();
    let (col_ptr, row_idx, val) = (sym.col_ptr(), sym.row_idx(), l.val());

    // Upper triangle (rows i <= j) of every column, in parallel (Gustavson's algorithm with a
    // branch-free "first visit" marker: every visit writes its row to `seen[count]`, and only a
    // first visit advances `count`, hence one spare slot). Rows of L are sorted, so each inner
    // scan stops at j.
    let upper: Vec<(Vec<usize>, Vec<f64>)> = (0..n)
        .into_par_iter()
        .with_min_len(64)
        .map_init(
            || (vec![0.0; n], vec![usize::MAX; n], vec![0usize; n + 1]),
            |(acc, mark, seen), j| {
                let mut count = 0;
                for q in col_ptr[j]..col_ptr[j + 1] {
                    let (k, l_kj) = (row_idx[q], val[q]);
                    for p in col_ptr[k]..col_ptr[k + 1] {
                        let i = row_idx[p];
                        if i > j {
                            break;
                        }
                        seen[count] = i;
                        count += usize::from(mark[i] != j);
                        mark[i] = j;
                        acc[i] += inv[k] * (val[p] * l_kj);
                    }
                }
                let mut rows = seen[..count].to_vec();
                rows.sort_unstable();
                let vals = rows
                    .iter()
                    .map(|&i| std::mem::replace(&mut acc[i], 0.0))
                    .collect();
                (rows, vals)
            },
        )
        .collect();
    Ok(mirror_upper(n, &upper))
}

/// The symmetric matrix whose upper triangle (diagonal included) is given column by column.
/// Column c of the result: the upper column c, then the rows j > c where column j has row c.
fn mirror_upper(n: usize, upper: &[(Vec<usize>, Vec<f64>)]) -> Csc {
    let mut below = vec![0usize; n];
    for (j, (rows, _)) in upper.iter().enumerate() {
        for &i in rows.iter().filter(|&&i| i < j) {
            below[i] += 1;
        }
    }
    let mut ptr = vec![0usize; n + 1];
    for c in 0..n {
        ptr[c + 1] = ptr[c] + upper[c].0.len() + below[c];
    }
    let nnz = ptr[n];
    let mut rows_all = vec![0usize; nnz];
    let mut vals_all = vec![0.0; nnz];
    let mut cursor = vec![0usize; n];
    for (c, (rows, vals)) in upper.iter().enumerate() {
        let s = ptr[c];
        rows_all[s..s + rows.len()].copy_from_slice(rows);
        vals_all[s..s + rows.len()].copy_from_slice(vals);
        cursor[c] = s + rows.len();
    }
    // Columns j in increasing order, so the rows j land sorted in each column i.
    for (j, (rows, vals)) in upper.iter().enumerate() {
        for (&i, &x) in rows.iter().zip(vals).filter(|(&i, _)| i < j) {
            rows_all[cursor[i]] = j;
            vals_all[cursor[i]] = x;
            cursor[i] += 1;
        }
    }
    let symbolic = SymbolicSparseColMat::new_checked(n, n, ptr, None, rows_all);
    Csc::new(symbolic, vals_all)
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::array;

    #[test]
    fn right_triangle_biharmonic() {
        // L = [[-1, .5, .5], [.5, -.5, 0], [.5, 0, -.5]], Voronoi masses (1/4, 1/8, 1/8)
        // rescaled to (1, 1/2, 1/2): B = L diag(1, 2, 2) L.
        let v = array![[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]];
        let b =
            biharmonic_matrix(v.view(), array![[0usize, 1, 2]].view(), MassKind::Voronoi).unwrap();
        let l = [[-1.0, 0.5, 0.5], [0.5, -0.5, 0.0], [0.5, 0.0, -0.5]];
        let d = [1.0, 2.0, 2.0];
        let mut dense = [[0.0; 3]; 3];
        for t in b.triplet_iter() {
            dense[t.row][t.col] = *t.val;
        }
        for i in 0..3 {
            for j in 0..3 {
                let expect: f64 = (0..3).map(|k| l[k][i] * d[k] * l[k][j]).sum();
                assert!((dense[i][j] - expect).abs() < 1e-14, "{i} {j} {dense:?}");
                assert_eq!(dense[i][j], dense[j][i]);
            }
        }
        // Constant functions have zero energy.
        assert!(dense.iter().all(|r| r.iter().sum::<f64>().abs() < 1e-14));
    }
}
