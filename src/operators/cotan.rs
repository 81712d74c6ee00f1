//! Cotangent Laplacian for triangle and tetrahedral meshes, in libigl's convention
//! (`igl::cotmatrix`): symmetric, negative semidefinite, zero row sums.

use faer::sparse::SymbolicSparseColMat;
use ndarray::ArrayView2;
use rayon::prelude::*;

use super::elements::{check_elements, corners, point, Simplex, P3};
use crate::error::SkinResult;
use crate::geometry::{cross, dot, sub, triple};
use crate::sparse::Csc;

/// Local vertex pairs of a triangle; pair `k` is the edge opposite corner `k`.
const TRI_EDGES: [(usize, usize); 3] = [(1, 2), (2, 0), (0, 1)];
/// All six local vertex pairs of a tetrahedron.
const TET_EDGES: [(usize, usize); 6] = [(1, 2), (2, 0), (0, 1), (3, 0), (3, 1), (3, 2)];

/// Cotangent Laplacian `L` of a triangle mesh (2D or 3D) or a tetrahedral mesh.
///
/// Inputs:
///   v  #V by dim vertex positions (dim 2 or 3; 3 for tets)
///   f  #F by 3 triangles or #F by 4 tetrahedra
/// Output:
///   L  #V by #V sparse matrix, exactly symmetric, negative semidefinite: for triangles
///      L_ij = (cot a_ij + cot b_ij) / 2 summed over the triangles sharing edge ij; for tets
///      L_ij = sum over the tets sharing edge ij of l_kl cot(theta_kl) / 6 (l_kl the length of
///      the opposite edge, theta_kl its dihedral angle); L_ii = -sum_j L_ij. This is
///      `igl::cotmatrix`. Vertices referenced by no element have an empty row and column.
/// Errors: see [`check_elements`].
pub fn cotan_laplacian(v: ArrayView2<f64>, f: ArrayView2<usize>) -> SkinResult<Csc> {
    check_elements(v, f)?;
    let kind = Simplex::of(&v, &f)?;
    let pairs: &[(usize, usize)] = match kind {
        Simplex::Tet => &TET_EDGES,
        _ => &TRI_EDGES,
    };
    let k = pairs.len();
    let mut w = vec![0.0; f.nrows() * k];
    w.par_chunks_mut(k)
        .with_min_len(512)
        .enumerate()
        .for_each(|(t, out)| {
            let e = corners(&f, t);
            match kind {
                Simplex::Tet => tet_weights(&v, &e, out),
                _ => triangle_weights(&v, &e, out),
            }
        });
    Ok(assemble_edge_weights(v.nrows(), f, pairs, &w))
}

/// Off-diagonal entries of one triangle, in `TRI_EDGES` order: half the cotangent of the
/// angle opposite each edge, cot = (u . w) / |u x w| with u, w the two edges at that corner.
fn triangle_weights(v: &ArrayView2<f64>, e: &[usize; 4], out: &mut [f64]) {
    let p: [P3; 3] = [point(v, e[0]), point(v, e[1]), point(v, e[2])];
    // |u x w| is twice the area for every corner; compute it once.
    let dbl_area = {
        let c = cross(&sub(&p[1], &p[0]), &sub(&p[2], &p[0]));
        dot(&c, &c).sqrt()
    };
    for (corner, o) in out.iter_mut().enumerate() {
        let a = p[corner];
        let u = sub(&p[(corner + 1) % 3], &a);
        let w = sub(&p[(corner + 2) % 3], &a);
        *o = 0.5 * dot(&u, &w) / dbl_area;
    }
}

/// Off-diagonal entries of one tet, in `TET_EDGES` order: L_ab = -|T| grad(phi_a) . grad(phi_b),
/// which equals l_cd cot(theta_cd) / 6 for the edge cd opposite ab. With J = [e1 e2 e3]
/// (edges from corner 0), grad(phi_k) = g_k / det J for g_1 = e2 x e3, g_2 = e3 x e1,
/// g_3 = e1 x e2 and g_0 = -(g_1 + g_2 + g_3), so L_ab = -(g_a . g_b) / (6 |det J|).
fn tet_weights(v: &ArrayView2<f64>, e: &[usize; 4], out: &mut [f64]) {
    let p0 = point(v, e[0]);
    let e1 = sub(&point(v, e[1]), &p0);
    let e2 = sub(&point(v, e[2]), &p0);
    let e3 = sub(&point(v, e[3]), &p0);
    let det = triple(&e1, &e2, &e3).abs();
    let g1 = cross(&e2, &e3);
    let g2 = cross(&e3, &e1);
    let g3 = cross(&e1, &e2);
    let g0 = [
        -(g1[0] + g2[0] + g3[0]),
        -(g1[1] + g2[1] + g3[1]),
        -(g1[2] + g2[2] + g3[2]),
    ];
    let g = [g0, g1, g2, g3];
    for (o, &(a, b)) in out.iter_mut().zip(TET_EDGES.iter()) {
        *o = -dot(&g[a], &g[b]) / (6.0 * det);
    }
}

/// Assembles the symmetric matrix with off-diagonal entries `L_ij = L_ji = sum of w` over the
/// element pairs `(i, j)` and `L_ii = -sum_j L_ij`.
///
/// Duplicates are merged in element order (stable sorts only), and both triangles of the matrix
/// take the same merged value, so the result is exactly symmetric and deterministic.
pub(crate) fn assemble_edge_weights(
    n: usize,
    f: ArrayView2<usize>,
    pairs: &[(usize, usize)],
    w: &[f64],
) -> Csc {
    let k = pairs.len();
    // Bucket the element pairs by their smaller vertex (a stable counting sort, in element
    // order), then sort each small bucket by the larger vertex and merge duplicates.
    let mut start = vec![0usize; n + 1];
    for row in f.rows() {
        for &(p, q) in pairs {
            start[row[p].min(row[q]) + 1] += 1;
        }
    }
    for i in 0..n {
        start[i + 1] += start[i];
    }
    let mut bucket = vec![(0usize, 0.0f64); start[n]];
    let mut cursor = start.clone();
    for (t, row) in f.rows().into_iter().enumerate() {
        for (e, &(p, q)) in pairs.iter().enumerate() {
            let (a, b) = (row[p].min(row[q]), row[p].max(row[q]));
            bucket[cursor[a]] = (b, w[t * k + e]);
            cursor[a] += 1;
        }
    }
    // Unique undirected edges (i < j) in lexicographic order, duplicates summed in element order.
    let mut edges: Vec<(usize, usize, f64)> = Vec::with_capacity(start[n] / 2 + 1);
    for i in 0..n {
        let b = &mut bucket[start[i]..start[i + 1]];
        b.sort_by_key(|&(j, _)| j);
        for &(j, x) in b.iter() {
            match edges.last_mut() {
                Some(last) if last.0 == i && last.1 == j => last.2 += x,
                _ => edges.push((i, j, x)),
            }
        }
    }
    drop(bucket);

    // Column c holds rows i < c (edges (i, c)), the diagonal, then rows j > c (edges (c, j)).
    let mut lower = vec![0usize; n];
    let mut upper = vec![0usize; n];
    for &(i, j, _) in &edges {
        upper[i] += 1;
        lower[j] += 1;
    }
    let mut col_ptr = vec![0usize; n + 1];
    for c in 0..n {
        let diag = usize::from(lower[c] + upper[c] > 0);
        col_ptr[c + 1] = col_ptr[c] + lower[c] + diag + upper[c];
    }
    let nnz = col_ptr[n];
    let mut row_idx = vec![0usize; nnz];
    let mut val = vec![0.0; nnz];
    let mut cursor: Vec<usize> = col_ptr[..n].to_vec();
    // Sorted by (i, j): for a fixed column j the rows i arrive increasing.
    for &(i, j, x) in &edges {
        row_idx[cursor[j]] = i;
        val[cursor[j]] = x;
        cursor[j] += 1;
    }
    let diag_pos: Vec<Option<usize>> = (0..n)
        .map(|c| {
            (lower[c] + upper[c] > 0).then(|| {
                let p = cursor[c];
                row_idx[p] = c;
                cursor[c] += 1;
                p
            })
        })
        .collect();
    // For a fixed column i the rows j > i arrive increasing.
    for &(i, j, x) in &edges {
        row_idx[cursor[i]] = j;
        val[cursor[i]] = x;
        cursor[i] += 1;
    }
    for (c, p) in diag_pos.iter().enumerate() {
        if let Some(p) = *p {
            let s: f64 = (col_ptr[c]..col_ptr[c + 1])
                .filter(|&q| q != p)
                .map(|q| val[q])
                .sum();
            val[p] = -s;
        }
    }
    let symbolic = SymbolicSparseColMat::new_checked(n, n, col_ptr, None, row_idx);
    Csc::new(symbolic, val)
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::array;

    fn dense(m: &Csc) -> Vec<Vec<f64>> {
        let mut d = vec![vec![0.0; m.ncols()]; m.nrows()];
        for t in m.triplet_iter() {
            d[t.row][t.col] += *t.val;
        }
        d
    }

    fn assert_close(a: f64, b: f64) {
        assert!((a - b).abs() <= 1e-14 * (1.0 + b.abs()), "{a} vs {b}");
    }

    #[test]
    fn right_triangle() {
        // Right angle at vertex 0, 45 degrees at 1 and 2: cot 0 = 0, cot 45 = 1.
        let v = array![[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]];
        for f in [array![[0usize, 1, 2]], array![[0usize, 2, 1]]] {
            let l = dense(&cotan_laplacian(v.view(), f.view()).unwrap());
            let expect = [[-1.0, 0.5, 0.5], [0.5, -0.5, 0.0], [0.5, 0.0, -0.5]];
            for i in 0..3 {
                for j in 0..3 {
                    assert_close(l[i][j], expect[i][j]);
                }
            }
        }
    }

    #[test]
    fn regular_tet() {
        // All dihedral angles are acos(1/3): cot = 1/(2 sqrt 2); every edge has length s.
        let s = 2f64.sqrt() * 2.0;
        let v = array![
            [1.0, 1.0, 1.0],
            [-1.0, 1.0, -1.0],
            [1.0, -1.0, -1.0],
            [-1.0, -1.0, 1.0]
        ];
        let l = dense(&cotan_laplacian(v.view(), array![[0usize, 1, 2, 3]].view()).unwrap());
        let off = s / (2.0 * 2f64.sqrt()) / 6.0;
        for (i, row) in l.iter().enumerate() {
            for (j, &x) in row.iter().enumerate() {
                assert_close(x, if i == j { -3.0 * off } else { off });
            }
        }
    }

    #[test]
    fn corner_tet_matches_dihedral_formula() {
        // Tet (0, e1, e2, e3): edge (0,1) is opposite edge (2,3), length sqrt 2, whose dihedral
        // angle is the angle between faces (0,2,3) and (1,2,3): cos = 1/sqrt 3 -> cot = 1/sqrt 2.
        // So L_01 = sqrt 2 * (1/sqrt 2) / 6 = 1/6. Edge (2,3) is opposite edge (0,1) whose
        // dihedral angle is 90 degrees -> L_23 = 0.
        let v = array![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 1.0]
        ];
        let l = dense(&cotan_laplacian(v.view(), array![[0usize, 1, 2, 3]].view()).unwrap());
        assert_close(l[0][1], 1.0 / 6.0);
        assert_close(l[2][3], 0.0);
        assert_close(l[0][0], -0.5);
        assert_close(l[1][1], -1.0 / 6.0);
    }

    #[test]
    fn shared_edges_are_summed_and_symmetric() {
        let v = array![[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0], [5.0, 5.0]];
        let f = array![[0usize, 1, 2], [0, 2, 3]];
        let m = cotan_laplacian(v.view(), f.view()).unwrap();
        let l = dense(&m);
        // The shared diagonal 0-2 faces two right angles -> 0; edge 0-1 faces 45 degrees.
        assert_close(l[0][2], 0.0);
        assert_close(l[0][1], 0.5);
        for (i, row) in l.iter().enumerate() {
            for (j, &x) in row.iter().enumerate() {
                assert_eq!(x, l[j][i]);
            }
            assert!(row.iter().sum::<f64>().abs() < 1e-15);
        }
        // Unreferenced vertex 4: empty column.
        assert_eq!(m.symbolic().col_ptr()[4], m.symbolic().col_ptr()[5]);
    }
}
