//! Tests of the fast winding numbers against the exact sums, and of the expansion order.

use super::*;
use ndarray::array;

use crate::field::P3;

fn exact(b: &Boundary<3>, q: &P3) -> f64 {
    b.elems
        .iter()
        .map(|&[i, j, k]| solid_angle(q, &b.verts[i], &b.verts[j], &b.verts[k]))
        .sum::<f64>()
        / FOUR_PI
}

/// UV sphere with outward triangles.
fn sphere(nu: usize, nv: usize) -> (ndarray::Array2<f64>, ndarray::Array2<usize>) {
    let mut v = vec![[0.0, 0.0, 1.0]];
    for i in 1..nv {
        let th = std::f64::consts::PI * i as f64 / nv as f64;
        for j in 0..nu {
            let ph = TWO_PI * j as f64 / nu as f64;
            v.push([th.sin() * ph.cos(), th.sin() * ph.sin(), th.cos()]);
        }
    }
    v.push([0.0, 0.0, -1.0]);
    let south = v.len() - 1;
    let id = |i: usize, j: usize| 1 + (i - 1) * nu + (j % nu);
    let mut f = Vec::new();
    for j in 0..nu {
        f.push([0, id(1, j), id(1, j + 1)]);
        f.push([south, id(nv - 1, j + 1), id(nv - 1, j)]);
    }
    for i in 1..nv - 1 {
        for j in 0..nu {
            f.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
            f.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
        }
    }
    let va = ndarray::Array2::from_shape_fn((v.len(), 3), |(i, k)| v[i][k]);
    let fa = ndarray::Array2::from_shape_fn((f.len(), 3), |(i, k)| f[i][k]);
    (va, fa)
}

#[test]
fn sphere_inside_outside_and_far_field_accuracy() {
    let (v, f) = sphere(40, 20);
    // The centre of a sphere is the worst case for the expansion: every node is seen from
    // about the same distance, so the truncation errors add up coherently.
    for (beta, tol) in [(2.0, 3e-3), (4.0, 3e-4)] {
        let fw = FastWinding::<3>::new(v.view(), f.view(), beta).unwrap();
        for q in [
            [0.1, -0.2, 0.3],
            [0.3, 0.2, 0.8],
            [1.1, 0.0, 0.0],
            [-2.0, 1.0, 0.5],
        ] {
            let (a, e) = (fw.eval(&q), exact(fw.boundary(), &q));
            assert!(
                (a - e).abs() < tol,
                "beta {beta} at {q:?}: fast {a} exact {e}"
            );
        }
    }
    let fw = FastWinding::<3>::new(v.view(), f.view(), f64::INFINITY).unwrap();
    assert!((fw.eval(&[0.1, -0.2, 0.3]) - 1.0).abs() < 1e-12);
    assert!(fw.eval(&[3.0, 0.0, 0.0]).abs() < 1e-12);
}

#[test]
fn expansion_error_is_third_order() {
    // Two triangles seen from farther and farther away: the order-2 expansion's error falls
    // like d^-5 (solid angle d^-2 times (R / d)^3), i.e. ~32x per doubling.
    let v = array![
        [0.0, 0.0, 0.0],
        [1.0, 0.2, 0.0],
        [0.3, 1.0, 0.1],
        [0.5, 0.5, 0.8]
    ];
    let f = array![[0usize, 1, 2], [0, 3, 1]];
    let fw = FastWinding::<3>::new(v.view(), f.view(), 2.0).unwrap();
    let err = |s: f64| {
        let q = [0.3 + 0.4 * s, 0.2 - 0.5 * s, 0.1 + 0.7 * s];
        (fw.exp[0].eval(&q) - exact(fw.boundary(), &q) * FOUR_PI).abs()
    };
    let (e8, e16, e32) = (err(8.0), err(16.0), err(32.0));
    assert!(e8 / e16 > 30.0 && e16 / e32 > 30.0, "{e8} {e16} {e32}");
}

#[test]
fn single_triangle_expansion_matches_exact_far_away() {
    let v = array![[0.0, 0.0, 0.0], [1.0, 0.2, 0.0], [0.3, 1.0, 0.1]];
    let f = array![[0usize, 1, 2]];
    let fw = FastWinding::<3>::new(v.view(), f.view(), 2.0).unwrap();
    let q = [3.0, -2.0, 4.0];
    let e = solid_angle(&q, &[0.0, 0.0, 0.0], &[1.0, 0.2, 0.0], &[0.3, 1.0, 0.1]);
    let a = fw.exp[0].eval(&q);
    // Third-order truncation: relative error ~ (R / d)^3 ~ 1e-2 at d / R ~ 5.
    assert!((a - e).abs() < 1e-3 * e.abs().max(1e-3), "{a} vs {e}");
}

#[test]
fn merged_expansions_equal_direct_sums() {
    let (v, f) = sphere(30, 15);
    let fw = FastWinding::<3>::new(v.view(), f.view(), 2.0).unwrap();
    let b = fw.boundary();
    for (node, e) in b.bvh.nodes.iter().zip(&fw.exp) {
        let s = node.start as usize;
        let d = expansion(b, &b.bvh.order[s..s + node.count as usize], &node.bbox, 2.0);
        let close = |x: f64, y: f64| (x - y).abs() < 1e-12;
        assert!((0..3).all(|k| close(e.center[k], d.center[k]) && close(e.n[k], d.n[k])));
        assert!((0..3).all(|i| (0..3).all(|j| close(e.m[i][j], d.m[i][j]))));
        assert!((0..3).all(|i| (0..3).all(|j| (0..3).all(|k| close(e.c[i][j][k], d.c[i][j][k])))));
        assert!(close(e.reach2, d.reach2));
    }
}

#[test]
fn fast_2d_matches_exact_sum() {
    // In 2D the kernel decays like 1/d only, so at equal beta the far field is less accurate
    // than in 3D (see docs/field.md for the errors at beta = 2, 3, 4).
    // A wiggly star polygon (counter-clockwise), 600 segments.
    let n = 600;
    let v = ndarray::Array2::from_shape_fn((n, 2), |(i, k)| {
        let t = TWO_PI * i as f64 / n as f64;
        let r = 1.0 + 0.3 * (7.0 * t).sin();
        if k == 0 {
            r * t.cos()
        } else {
            r * t.sin()
        }
    });
    let f = ndarray::Array2::from_shape_fn((n, 2), |(i, k)| (i + k) % n);
    let q = ndarray::Array2::from_shape_fn((400, 2), |(i, k)| {
        let x = ((i * 7919 + k * 104729) % 1000) as f64 / 1000.0;
        3.0 * x - 1.5
    });
    let exact = winding_number_2d(v.view(), f.view(), q.view()).unwrap();
    for (beta, tol) in [
        (2.0, 1.5e-2),
        (3.0, 3e-3),
        (4.0, 1e-3),
        (f64::INFINITY, 1e-12),
    ] {
        let fw = FastWinding::<2>::new(v.view(), f.view(), beta).unwrap();
        let w = fw.eval_batch(q.view()).unwrap();
        let err = w
            .iter()
            .zip(&exact)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        assert!(err < tol, "beta {beta}: max error {err}");
    }
    assert!(exact.iter().any(|&w| (w - 1.0).abs() < 1e-9));
    assert!(exact.iter().any(|&w| w.abs() < 1e-9));
}

#[test]
fn expansion_error_is_third_order_2d() {
    let v = array![[0.0, 0.0], [1.0, 0.3], [1.5, 1.0]];
    let f = array![[0usize, 1], [1, 2]];
    let fw = FastWinding::<2>::new(v.view(), f.view(), 2.0).unwrap();
    let b = fw.boundary();
    let err = |s: f64| {
        let q = [0.3 + 0.6 * s, 0.2 - 0.8 * s];
        let e: f64 = (0..2).map(|t| b.exact(&q, t)).sum();
        (fw.exp[0].eval(&q) - e).abs()
    };
    // Angle ~ d^-1 times (R / d)^3: ~16x per doubling.
    let (e8, e16, e32) = (err(8.0), err(16.0), err(32.0));
    assert!(e8 / e16 > 14.0 && e16 / e32 > 14.0, "{e8} {e16} {e32}");
}

#[test]
fn square_2d_winding() {
    let v = array![[0., 0.], [1., 0.], [1., 1.], [0., 1.]];
    let f = array![[0usize, 1], [1, 2], [2, 3], [3, 0]];
    let q = array![[0.5, 0.5], [2.0, 0.3]];
    let w = winding_number_2d(v.view(), f.view(), q.view()).unwrap();
    assert!((w[0] - 1.0).abs() < 1e-14 && w[1].abs() < 1e-14);
}
