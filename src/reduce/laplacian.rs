//! Cotangent Laplacian and lumped (barycentric) mass of a triangle surface.
//!
//! Private to weight reduction for now: the shared operator (`crate::operators::cotan_laplacian`)
//! is written concurrently on another branch; the lead switches [`super`] to it when merging.
//! Conventions follow libigl: `L` is symmetric negative semi-definite with
//! `L_ij = (cot a_ij + cot b_ij) / 2` on edges and zero row sums, `M_ii = sum(area_f) / 3`.

use faer::sparse::Triplet;
use ndarray::ArrayView2;

use crate::error::SkinResult;
use crate::invalid;
use crate::sparse::{from_triplets, Csc};

/// Row `i` of `v`, zero-padded to 3D.
pub(crate) fn point(v: ArrayView2<f64>, i: usize) -> [f64; 3] {
    let mut x = [0.0; 3];
    for (c, xc) in x.iter_mut().enumerate().take(v.ncols()) {
        *xc = v[[i, c]];
    }
    x
}

fn sub(a: &[f64; 3], b: &[f64; 3], out: &mut [f64; 3]) {
    for c in 0..3 {
        out[c] = a[c] - b[c];
    }
}

pub(crate) fn dot(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// Twice the area of the triangle spanned by edge vectors `a`, `b` (3D, zero-padded for 2D).
pub(crate) fn double_area(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    let x = a[1] * b[2] - a[2] * b[1];
    let y = a[2] * b[0] - a[0] * b[2];
    let z = a[0] * b[1] - a[1] * b[0];
    (x * x + y * y + z * z).sqrt()
}

/// Checks `V (n, 2|3)` and `F (f, 3)`: indices in range, no repeated vertex, no zero-area triangle,
/// every vertex used by some triangle. Returns twice the area of each triangle.
pub(crate) fn check_surface(v: ArrayView2<f64>, f: ArrayView2<usize>) -> SkinResult<Vec<f64>> {
    let n = v.nrows();
    if !(2..=3).contains(&v.ncols()) {
        return invalid!("V must have 2 or 3 columns, got {}", v.ncols());
    }
    if f.ncols() != 3 {
        return invalid!(
            "F must hold triangles (3 columns), got {} columns",
            f.ncols()
        );
    }
    if f.nrows() == 0 {
        return invalid!("F has no triangles");
    }
    if v.iter().any(|x| !x.is_finite()) {
        return invalid!("V has a NaN or infinite entry");
    }
    let mut used = vec![false; n];
    let mut areas = Vec::with_capacity(f.nrows());
    let (mut e1, mut e2, mut e3) = ([0.0; 3], [0.0; 3], [0.0; 3]);
    for (t, tri) in f.rows().into_iter().enumerate() {
        let (i, j, k) = (tri[0], tri[1], tri[2]);
        if i >= n || j >= n || k >= n {
            return invalid!("F row {t} holds an index outside 0..{n}");
        }
        if i == j || j == k || i == k {
            return invalid!("F row {t} repeats a vertex: [{i}, {j}, {k}]");
        }
        let (pi, pj, pk) = (point(v, i), point(v, j), point(v, k));
        sub(&pj, &pi, &mut e1);
        sub(&pk, &pi, &mut e2);
        sub(&pk, &pj, &mut e3);
        let a2 = double_area(&e1, &e2);
        let scale = dot(&e1, &e1).max(dot(&e2, &e2)).max(dot(&e3, &e3));
        if a2.is_nan() || a2 <= 1e-12 * scale {
            return invalid!("F row {t} is a degenerate (zero-area) triangle [{i}, {j}, {k}]");
        }
        areas.push(a2);
        used[i] = true;
        used[j] = true;
        used[k] = true;
    }
    if let Some(u) = used.iter().position(|&x| !x) {
        return invalid!(
            "V row {u} is not used by any triangle of F; the Laplacian-based methods need every \
             vertex on the surface (drop unreferenced vertices and reindex F)"
        );
    }
    Ok(areas)
}

/// Cotangent Laplacian `L (n, n)` of a triangle surface (libigl sign convention, negative
/// semi-definite, exactly symmetric).
///
/// Inputs: `v (n, d)` vertex positions, d = 2 or 3; `f (t, 3)` triangles.
/// Output: `L` as CSC.
pub(crate) fn cotan_laplacian(v: ArrayView2<f64>, f: ArrayView2<usize>) -> SkinResult<Csc> {
    let n = v.nrows();
    check_surface(v, f)?;
    let mut trip = Vec::with_capacity(f.nrows() * 12);
    for tri in f.rows() {
        let ids = [tri[0], tri[1], tri[2]];
        let pts = [point(v, ids[0]), point(v, ids[1]), point(v, ids[2])];
        // Corner c is opposite edge (c+1, c+2): contributes cot(c)/2 to that edge.
        for c in 0..3 {
            let (a, b) = ((c + 1) % 3, (c + 2) % 3);
            let ea: [f64; 3] = std::array::from_fn(|x| pts[a][x] - pts[c][x]);
            let eb: [f64; 3] = std::array::from_fn(|x| pts[b][x] - pts[c][x]);
            let w = 0.5 * dot(&ea, &eb) / double_area(&ea, &eb);
            let (i, j) = (ids[a], ids[b]);
            // Same value pushed to (i, j) and (j, i) in the same order: L is exactly symmetric.
            trip.push(Triplet::new(i, j, w));
            trip.push(Triplet::new(j, i, w));
            trip.push(Triplet::new(i, i, -w));
            trip.push(Triplet::new(j, j, -w));
        }
    }
    from_triplets(n, n, &trip)
}

/// Lumped barycentric mass: one third of the area of the triangles around each vertex.
pub(crate) fn barycentric_mass(v: ArrayView2<f64>, f: ArrayView2<usize>) -> SkinResult<Vec<f64>> {
    let areas = check_surface(v, f)?;
    let mut m = vec![0.0; v.nrows()];
    for (tri, a2) in f.rows().into_iter().zip(areas) {
        for c in 0..3 {
            m[tri[c]] += a2 / 6.0;
        }
    }
    Ok(m)
}
