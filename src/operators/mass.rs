//! Lumped (diagonal) mass matrices, equal to `igl::massmatrix` with
//! `MASSMATRIX_TYPE_BARYCENTRIC` or `MASSMATRIX_TYPE_VORONOI`.

use ndarray::ArrayView2;
use rayon::prelude::*;

use super::elements::{check_elements, corners, point, Simplex, P3};
use crate::error::SkinResult;
use crate::geometry::{add, cross, dot, norm, scale, sub, triple};

/// How an element's measure is shared among its corners.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MassKind {
    /// Equal shares: area / 3 per triangle corner, volume / 4 per tet corner.
    Barycentric,
    /// Voronoi shares (Meyer et al. 2003 "hybrid" rule, as in libigl): for triangles the
    /// circumcentric dual area, with an obtuse triangle giving half its area to the obtuse corner
    /// and a quarter to the others; for tets the circumcentric dual volume with circumcentres
    /// outside their simplex snapped to the facet (libigl's `voronoi_mass`).
    Voronoi,
}

/// Diagonal of the lumped mass matrix.
///
/// Inputs:
///   v     #V by dim vertex positions (dim 2 or 3; 3 for tets)
///   f     #F by 3 triangles or #F by 4 tetrahedra
///   kind  [`MassKind::Barycentric`] or [`MassKind::Voronoi`]
/// Output:
///   #V masses, `diag(igl::massmatrix(V, F, type))`; 0 for vertices referenced by no element.
///   The masses sum to the total area/volume.
/// Errors: see [`check_elements`].
pub fn massmatrix(
    v: ArrayView2<f64>,
    f: ArrayView2<usize>,
    kind: MassKind,
) -> SkinResult<Vec<f64>> {
    check_elements(v, f)?;
    let simplex = Simplex::of(&v, &f)?;
    let local: Vec<[f64; 4]> = (0..f.nrows())
        .into_par_iter()
        .with_min_len(512)
        .map(|t| {
            let e = corners(&f, t);
            match (simplex, kind) {
                (Simplex::Tet, MassKind::Barycentric) => tet_barycentric(&v, &e),
                (Simplex::Tet, MassKind::Voronoi) => tet_voronoi(&v, &e),
                (_, MassKind::Barycentric) => triangle_barycentric(&v, &e),
                (_, MassKind::Voronoi) => triangle_voronoi(&v, &e),
            }
        })
        .collect();
    let mut m = vec![0.0; v.nrows()];
    let s = f.ncols();
    for (t, shares) in local.iter().enumerate() {
        for (k, &x) in shares.iter().enumerate().take(s) {
            m[f[[t, k]]] += x;
        }
    }
    Ok(m)
}

fn triangle_points(v: &ArrayView2<f64>, e: &[usize; 4]) -> [P3; 3] {
    [point(v, e[0]), point(v, e[1]), point(v, e[2])]
}

fn triangle_area(p: &[P3; 3]) -> f64 {
    0.5 * norm(&cross(&sub(&p[1], &p[0]), &sub(&p[2], &p[0])))
}

fn triangle_barycentric(v: &ArrayView2<f64>, e: &[usize; 4]) -> [f64; 4] {
    let a = triangle_area(&triangle_points(v, e)) / 3.0;
    [a, a, a, 0.0]
}

/// `d_i = (p_j - p_i) . (p_k - p_i)` (the sign of the angle's cosine at corner i) and
/// `w_i = d_i |p_j - p_k|^2`, proportional to the barycentric coordinates of the circumcentre.
fn circumcentre_weights(p: &[P3; 3]) -> ([f64; 3], [f64; 3]) {
    let mut d = [0.0; 3];
    let mut w = [0.0; 3];
    for i in 0..3 {
        let (a, b, c) = (p[i], p[(i + 1) % 3], p[(i + 2) % 3]);
        d[i] = dot(&sub(&b, &a), &sub(&c, &a));
        let opp = sub(&c, &b);
        w[i] = d[i] * dot(&opp, &opp);
    }
    (d, w)
}

/// Index of the first smallest entry (Eigen's `minCoeff(&j)`).
fn argmin<const N: usize>(x: &[f64; N]) -> usize {
    (1..N).fold(0, |j, i| if x[i] < x[j] { i } else { j })
}

/// libigl `massmatrix_intrinsic` VORONOI: acute/right triangles split their area at the
/// circumcentre (corner i gets the halves of the sub-triangles on its two edges); an obtuse
/// triangle gives area/2 to the obtuse corner and area/4 to the others.
fn triangle_voronoi(v: &ArrayView2<f64>, e: &[usize; 4]) -> [f64; 4] {
    let p = triangle_points(v, e);
    let area = triangle_area(&p);
    let (d, w) = circumcentre_weights(&p);
    if let Some(obtuse) = (0..3).find(|&i| d[i] < 0.0) {
        let mut m = [0.25 * area; 4];
        m[obtuse] = 0.5 * area;
        m[3] = 0.0;
        return m;
    }
    let sum = w[0] + w[1] + w[2];
    // Area of the sub-triangle (circumcentre, edge opposite i) is bary_i * area.
    let part = [w[0] / sum * area, w[1] / sum * area, w[2] / sum * area];
    [
        0.5 * (part[1] + part[2]),
        0.5 * (part[2] + part[0]),
        0.5 * (part[0] + part[1]),
        0.0,
    ]
}

fn tet_barycentric(v: &ArrayView2<f64>, e: &[usize; 4]) -> [f64; 4] {
    let p0 = point(v, e[0]);
    let vol = triple(
        &sub(&point(v, e[1]), &p0),
        &sub(&point(v, e[2]), &p0),
        &sub(&point(v, e[3]), &p0),
    )
    .abs()
        / 6.0;
    [vol / 4.0; 4]
}

/// Circumcentre of a triangle, snapped to the midpoint of the edge opposite the obtuse corner
/// when it lies outside (libigl `voronoi_mass`).
fn snapped_face_centre(p: &[P3; 3]) -> P3 {
    let (_, w) = circumcentre_weights(p);
    let j = argmin(&w);
    if w[j] < 0.0 {
        return scale(&add(&p[(j + 1) % 3], &p[(j + 2) % 3]), 0.5);
    }
    let sum = w[0] + w[1] + w[2];
    let off = add(
        &scale(&sub(&p[1], &p[0]), w[1] / sum),
        &scale(&sub(&p[2], &p[0]), w[2] / sum),
    );
    add(&p[0], &off)
}

/// libigl `voronoi_mass`: each corner gets the volume of its part of the tet cut by the
/// perpendicular bisector planes of its three edges. The cell of corner j is bounded by the
/// corner, the three edge midpoints, the three (snapped) face circumcentres and the (snapped)
/// tet circumcentre; its volume is computed by the divergence theorem over its boundary.
fn tet_voronoi(v: &ArrayView2<f64>, e: &[usize; 4]) -> [f64; 4] {
    let p: [P3; 4] = [
        point(v, e[0]),
        point(v, e[1]),
        point(v, e[2]),
        point(v, e[3]),
    ];
    // Circumcentre of the face opposite corner q.
    let face: [P3; 4] = std::array::from_fn(|q| {
        snapped_face_centre(&[p[(q + 1) % 4], p[(q + 2) % 4], p[(q + 3) % 4]])
    });
    let centre = {
        let e1 = sub(&p[1], &p[0]);
        let e2 = sub(&p[2], &p[0]);
        let e3 = sub(&p[3], &p[0]);
        let g = [cross(&e2, &e3), cross(&e3, &e1), cross(&e1, &e2)];
        let det = dot(&e1, &g[0]);
        // 2 [e1 e2 e3]^T x = (|e1|^2, |e2|^2, |e3|^2), x = circumcentre - p0.
        let x = scale(
            &add(
                &add(&scale(&g[0], dot(&e1, &e1)), &scale(&g[1], dot(&e2, &e2))),
                &scale(&g[2], dot(&e3, &e3)),
            ),
            0.5 / det,
        );
        let l = [
            dot(&x, &g[0]) / det,
            dot(&x, &g[1]) / det,
            dot(&x, &g[2]) / det,
        ];
        let bary = [1.0 - l[0] - l[1] - l[2], l[0], l[1], l[2]];
        let j = argmin(&bary);
        if bary[j] < 0.0 {
            face[j]
        } else {
            add(&p[0], &x)
        }
    };
    std::array::from_fn(|j| {
        let o = p[j];
        let c = sub(&centre, &o);
        // m[k], f[k] for k = 1..3: midpoint of edge (j, j+k), centre of face opposite j+k.
        let m: [P3; 4] = std::array::from_fn(|k| scale(&sub(&p[(j + k) % 4], &o), 0.5));
        let f: [P3; 4] = std::array::from_fn(|k| sub(&face[(j + k) % 4], &o));
        // Boundary triangles not through the corner: (c, m_{k+1}, f_k) and (c, f_k, m_{k+2});
        // those through the corner contribute nothing with the corner as origin.
        let vol: f64 = (1..4)
            .map(|k| {
                let (k1, k2) = (k % 3 + 1, (k + 1) % 3 + 1);
                triple(&c, &m[k1], &f[k]) + triple(&c, &f[k], &m[k2])
            })
            .sum();
        // Odd corners see the tet with the opposite orientation.
        if j % 2 == 1 {
            -vol / 6.0
        } else {
            vol / 6.0
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::array;

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() <= 1e-14 * (1.0 + b.abs())
    }

    #[test]
    fn right_triangle_voronoi_and_barycentric() {
        // Circumcentre at the hypotenuse midpoint (0.5, 0.5): the right-angle corner gets 1/4
        // (the square [0,.5]^2), the others 1/8 each.
        let v = array![[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]];
        let f = array![[0usize, 1, 2]];
        let m = massmatrix(v.view(), f.view(), MassKind::Voronoi).unwrap();
        assert!(
            close(m[0], 0.25) && close(m[1], 0.125) && close(m[2], 0.125),
            "{m:?}"
        );
        let m = massmatrix(v.view(), f.view(), MassKind::Barycentric).unwrap();
        assert!(m.iter().all(|&x| close(x, 1.0 / 6.0)), "{m:?}");
    }

    #[test]
    fn obtuse_triangle_voronoi() {
        let v = array![
            [0.0, 0.0, 0.0],
            [4.0, 0.0, 0.0],
            [-1.0, 1.0, 0.0],
            [9.0, 9.0, 9.0]
        ];
        let f = array![[1usize, 2, 0]];
        let m = massmatrix(v.view(), f.view(), MassKind::Voronoi).unwrap();
        // area 2, obtuse at vertex 0
        assert!(
            close(m[0], 1.0) && close(m[1], 0.5) && close(m[2], 0.5) && m[3] == 0.0,
            "{m:?}"
        );
    }

    #[test]
    fn equilateral_triangle_voronoi_is_barycentric() {
        let h = 3f64.sqrt() / 2.0;
        let v = array![[0.0, 0.0], [1.0, 0.0], [0.5, h]];
        let f = array![[0usize, 1, 2]];
        let m = massmatrix(v.view(), f.view(), MassKind::Voronoi).unwrap();
        assert!(m.iter().all(|&x| close(x, h / 6.0)), "{m:?}");
    }

    #[test]
    fn regular_tet_voronoi() {
        let v = array![
            [1.0, 1.0, 1.0],
            [-1.0, 1.0, -1.0],
            [1.0, -1.0, -1.0],
            [-1.0, -1.0, 1.0]
        ];
        let f = array![[0usize, 1, 2, 3]];
        let vol = 8.0 / 3.0;
        for kind in [MassKind::Voronoi, MassKind::Barycentric] {
            let m = massmatrix(v.view(), f.view(), kind).unwrap();
            assert!(m.iter().all(|&x| close(x, vol / 4.0)), "{kind:?} {m:?}");
        }
    }

    #[test]
    fn corner_tet_voronoi() {
        // Tet (0, e1, e2, e3): the circumcentre (1/2, 1/2, 1/2) is outside (its barycentric
        // coordinate for corner 0 is -1/2), so it snaps to the circumcentre of the opposite face,
        // c = (1/3, 1/3, 1/3). The faces at the origin are right triangles with circumcentres at
        // their hypotenuse midpoints, so corner 0's cell is bounded by three squares of area 1/4
        // on the coordinate planes plus faces through c: 3 pyramids of apex c and height 1/3,
        // volume 3 * (1/3) * (1/4) * (1/3) = 1/12. The other corners share the rest equally.
        let v = array![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 1.0]
        ];
        let f = array![[0usize, 1, 2, 3]];
        let m = massmatrix(v.view(), f.view(), MassKind::Voronoi).unwrap();
        assert!(close(m.iter().sum::<f64>(), 1.0 / 6.0), "{m:?}");
        assert!(close(m[0], 1.0 / 12.0), "{m:?}");
        assert!((1..4).all(|i| close(m[i], 1.0 / 36.0)), "{m:?}");
    }
}
