//! Unit quaternions stored `[w, x, y, z]` (scalar first), as plain arrays.

use crate::geometry::cross;

/// Quaternion `[w, x, y, z]`.
pub type Quat = [f64; 4];

/// Hamilton product `a b` (rotation `b` first, then `a`).
#[inline(always)]
pub fn mul(a: &Quat, b: &Quat) -> Quat {
    [
        a[0] * b[0] - a[1] * b[1] - a[2] * b[2] - a[3] * b[3],
        a[0] * b[1] + a[1] * b[0] + a[2] * b[3] - a[3] * b[2],
        a[0] * b[2] - a[1] * b[3] + a[2] * b[0] + a[3] * b[1],
        a[0] * b[3] + a[1] * b[2] - a[2] * b[1] + a[3] * b[0],
    ]
}

/// Rotates `v` by the unit quaternion `q`: `v + 2 d x (d x v + w v)` with `d = (x, y, z)`.
#[inline(always)]
pub fn rotate(q: &Quat, v: &[f64; 3]) -> [f64; 3] {
    let d = [q[1], q[2], q[3]];
    let c = cross(&d, v);
    let inner = [c[0] + q[0] * v[0], c[1] + q[0] * v[1], c[2] + q[0] * v[2]];
    let c2 = cross(&d, &inner);
    [v[0] + 2.0 * c2[0], v[1] + 2.0 * c2[1], v[2] + 2.0 * c2[2]]
}

/// Rotation matrix (row-major) of the unit quaternion `q`.
pub fn to_matrix(q: &Quat) -> [[f64; 3]; 3] {
    let [w, x, y, z] = *q;
    [
        [
            1.0 - 2.0 * (y * y + z * z),
            2.0 * (x * y - w * z),
            2.0 * (x * z + w * y),
        ],
        [
            2.0 * (x * y + w * z),
            1.0 - 2.0 * (x * x + z * z),
            2.0 * (y * z - w * x),
        ],
        [
            2.0 * (x * z - w * y),
            2.0 * (y * z + w * x),
            1.0 - 2.0 * (x * x + y * y),
        ],
    ]
}

/// Unit quaternion of a rotation matrix (Shepperd's method: divide by the largest of
/// `4w^2, 4x^2, 4y^2, 4z^2` for accuracy). The sign is chosen with `w >= 0`.
pub fn from_matrix(r: &[[f64; 3]; 3]) -> Quat {
    let tr = r[0][0] + r[1][1] + r[2][2];
    let q = if tr >= r[0][0].max(r[1][1]).max(r[2][2]) {
        let s = (1.0 + tr).max(0.0).sqrt() * 2.0; // 4w
        [
            0.25 * s,
            (r[2][1] - r[1][2]) / s,
            (r[0][2] - r[2][0]) / s,
            (r[1][0] - r[0][1]) / s,
        ]
    } else if r[0][0] >= r[1][1] && r[0][0] >= r[2][2] {
        let s = (1.0 + r[0][0] - r[1][1] - r[2][2]).max(0.0).sqrt() * 2.0; // 4x
        [
            (r[2][1] - r[1][2]) / s,
            0.25 * s,
            (r[0][1] + r[1][0]) / s,
            (r[0][2] + r[2][0]) / s,
        ]
    } else if r[1][1] >= r[2][2] {
        let s = (1.0 - r[0][0] + r[1][1] - r[2][2]).max(0.0).sqrt() * 2.0; // 4y
        [
            (r[0][2] - r[2][0]) / s,
            (r[0][1] + r[1][0]) / s,
            0.25 * s,
            (r[1][2] + r[2][1]) / s,
        ]
    } else {
        let s = (1.0 - r[0][0] - r[1][1] + r[2][2]).max(0.0).sqrt() * 2.0; // 4z
        [
            (r[1][0] - r[0][1]) / s,
            (r[0][2] + r[2][0]) / s,
            (r[1][2] + r[2][1]) / s,
            0.25 * s,
        ]
    };
    let n = norm(&q);
    let sgn = if q[0] < 0.0 { -1.0 } else { 1.0 };
    [
        sgn * q[0] / n,
        sgn * q[1] / n,
        sgn * q[2] / n,
        sgn * q[3] / n,
    ]
}

#[inline(always)]
pub fn norm(q: &Quat) -> f64 {
    (q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn matrix_round_trip() {
        let qs: [Quat; 4] = [
            [1.0, 0.0, 0.0, 0.0],
            [0.0, 1.0, 0.0, 0.0],
            [0.5, 0.5, -0.5, 0.5],
            [0.1, -0.7, 0.2, 0.3],
        ];
        for q in qs {
            let n = norm(&q);
            let q = [q[0] / n, q[1] / n, q[2] / n, q[3] / n];
            let back = from_matrix(&to_matrix(&q));
            let s = if q[0] < 0.0 { -1.0 } else { 1.0 };
            for k in 0..4 {
                assert!((back[k] - s * q[k]).abs() < 1e-14, "{q:?} -> {back:?}");
            }
            let v = [0.3, -1.2, 2.5];
            let r = to_matrix(&q);
            let a = rotate(&q, &v);
            for i in 0..3 {
                let b = r[i][0] * v[0] + r[i][1] * v[1] + r[i][2] * v[2];
                assert!((a[i] - b).abs() < 1e-14);
            }
        }
    }

    #[test]
    fn product_composes_rotations() {
        let a = [0.8f64.cos(), 0.8f64.sin(), 0.0, 0.0];
        let b = [0.3f64.cos(), 0.0, 0.0, 0.3f64.sin()];
        let v = [1.0, 2.0, 3.0];
        let ab = rotate(&mul(&a, &b), &v);
        let seq = rotate(&a, &rotate(&b, &v));
        for i in 0..3 {
            assert!((ab[i] - seq[i]).abs() < 1e-14);
        }
    }
}
