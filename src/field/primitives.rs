//! Exact tests and closest points on the boundary primitives: triangles in 3D, segments in 2D.

use super::{add, cross, cross2, dot, norm2, scale, sub, P2, P3};

/// Möller–Trumbore: does `p + t d`, `0 < t < 1`, cross triangle `abc` (edges included)?
/// Coplanar segments (zero determinant) never hit: they cannot separate the two sides.
#[inline]
pub fn segment_triangle(p: &P3, d: &P3, a: &P3, b: &P3, c: &P3) -> bool {
    let e1 = sub(b, a);
    let e2 = sub(c, a);
    let h = cross(d, &e2);
    let det = dot(&e1, &h);
    if det == 0.0 {
        return false;
    }
    let inv = 1.0 / det;
    let s = sub(p, a);
    let u = inv * dot(&s, &h);
    if !(0.0..=1.0).contains(&u) {
        return false;
    }
    let qv = cross(&s, &e1);
    let v = inv * dot(d, &qv);
    if v < 0.0 || u + v > 1.0 {
        return false;
    }
    let t = inv * dot(&e2, &qv);
    t > 0.0 && t < 1.0
}

/// Does `p + t d`, `0 < t < 1`, cross segment `ab` (endpoints included)? Parallel: never.
#[inline]
pub fn segment_segment(p: &P2, d: &P2, a: &P2, b: &P2) -> bool {
    let e = sub(b, a);
    let den = cross2(d, &e);
    if den == 0.0 {
        return false;
    }
    let w = sub(a, p);
    let t = cross2(&w, &e) / den;
    let s = cross2(&w, d) / den;
    t > 0.0 && t < 1.0 && (0.0..=1.0).contains(&s)
}

/// Closest point on triangle `abc` to `x` (Ericson, Real-Time Collision Detection 5.1.5): the
/// Voronoi regions of the vertices, edges and face are tested in turn, no square roots, and
/// degenerate triangles fall through to an edge or vertex.
pub fn closest_on_triangle(x: &P3, a: &P3, b: &P3, c: &P3) -> P3 {
    let p = closest_on_triangle_regions(x, a, b, c);
    if p.iter().all(|v| v.is_finite()) {
        return p;
    }
    // A degenerate triangle (two equal corners) can make a region's ratio 0 / 0.
    closest_on_edges(x, a, b, c)
}

/// The closest of the three edges' closest points (for degenerate triangles).
fn closest_on_edges(x: &P3, a: &P3, b: &P3, c: &P3) -> P3 {
    [(a, b), (b, c), (c, a)]
        .iter()
        .map(|(s, t)| closest_on_segment(x, s, t))
        .min_by(|p, q| norm2(&sub(x, p)).total_cmp(&norm2(&sub(x, q))))
        .unwrap_or(*a)
}

/// Ericson's region test for [`closest_on_triangle`].
fn closest_on_triangle_regions(x: &P3, a: &P3, b: &P3, c: &P3) -> P3 {
    let ab = sub(b, a);
    let ac = sub(c, a);
    let ap = sub(x, a);
    let d1 = dot(&ab, &ap);
    let d2 = dot(&ac, &ap);
    if d1 <= 0.0 && d2 <= 0.0 {
        return *a;
    }
    let bp = sub(x, b);
    let d3 = dot(&ab, &bp);
    let d4 = dot(&ac, &bp);
    if d3 >= 0.0 && d4 <= d3 {
        return *b;
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let v = d1 / (d1 - d3);
        return add(a, &scale(&ab, v));
    }
    let cp = sub(x, c);
    let d5 = dot(&ab, &cp);
    let d6 = dot(&ac, &cp);
    if d6 >= 0.0 && d5 <= d6 {
        return *c;
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let w = d2 / (d2 - d6);
        return add(a, &scale(&ac, w));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return add(b, &scale(&sub(c, b), w));
    }
    let den = va + vb + vc;
    if den == 0.0 || !den.is_finite() {
        // Degenerate (collinear) triangle that slipped through: best of the three edges.
        return closest_on_edges(x, a, b, c);
    }
    let v = vb / den;
    let w = vc / den;
    add(&add(a, &scale(&ab, v)), &scale(&ac, w))
}

/// Closest point on segment `ab` to `x` (a point for `a == b`).
pub fn closest_on_segment<const D: usize>(x: &[f64; D], a: &[f64; D], b: &[f64; D]) -> [f64; D] {
    let e = sub(b, a);
    let l2 = norm2(&e);
    if l2 == 0.0 {
        return *a;
    }
    let t = (dot(&sub(x, a), &e) / l2).clamp(0.0, 1.0);
    add(a, &scale(&e, t))
}

/// Unit normal of a triangle, zero if degenerate.
pub fn triangle_normal(a: &P3, b: &P3, c: &P3) -> P3 {
    let n = cross(&sub(b, a), &sub(c, a));
    // Divide by the largest entry first: the squared length neither overflows nor underflows.
    let big = n.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    if !(big > 0.0 && big.is_finite()) {
        return [0.0; 3];
    }
    let n = scale(&n, 1.0 / big);
    let l = norm2(&n).sqrt();
    if l > 0.0 {
        scale(&n, 1.0 / l)
    } else {
        [0.0; 3]
    }
}

/// Unit normal of segment `ab`: its direction turned clockwise (outward for a CCW polygon).
pub fn segment_normal(a: &P2, b: &P2) -> P2 {
    let e = sub(b, a);
    let l = norm2(&e).sqrt();
    if l > 0.0 {
        [e[1] / l, -e[0] / l]
    } else {
        [0.0; 2]
    }
}
