//! Small fixed-size vector helpers shared by the operators, the field queries and skinning.
//!
//! Points and vectors are plain arrays (`[f64; D]`, passed by reference); the generic helpers
//! work in any dimension, `cross`/`triple` in 3D and `cross2` in 2D.

/// A point or vector in 3D (2D points are embedded with z = 0 where a 3D formula is used).
pub(crate) type P3 = [f64; 3];
/// A point or vector in 2D.
pub(crate) type P2 = [f64; 2];

/// `a - b`.
#[inline]
pub(crate) fn sub<const D: usize>(a: &[f64; D], b: &[f64; D]) -> [f64; D] {
    std::array::from_fn(|i| a[i] - b[i])
}

/// `a + b`.
#[inline]
pub(crate) fn add<const D: usize>(a: &[f64; D], b: &[f64; D]) -> [f64; D] {
    std::array::from_fn(|i| a[i] + b[i])
}

/// `s a`.
#[inline]
pub(crate) fn scale<const D: usize>(a: &[f64; D], s: f64) -> [f64; D] {
    std::array::from_fn(|i| a[i] * s)
}

/// `a . b`.
#[inline]
pub(crate) fn dot<const D: usize>(a: &[f64; D], b: &[f64; D]) -> f64 {
    let mut s = 0.0;
    for i in 0..D {
        s += a[i] * b[i];
    }
    s
}

/// `|a|^2`.
#[inline]
pub(crate) fn norm2<const D: usize>(a: &[f64; D]) -> f64 {
    dot(a, a)
}

/// `|a|`.
#[inline]
pub(crate) fn norm<const D: usize>(a: &[f64; D]) -> f64 {
    dot(a, a).sqrt()
}

/// `a x b`.
#[inline(always)]
pub(crate) fn cross(a: &P3, b: &P3) -> P3 {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// z-component of `a x b` for 2D vectors (twice the signed area of the triangle 0, a, b).
#[inline]
pub(crate) fn cross2(a: &P2, b: &P2) -> f64 {
    a[0] * b[1] - a[1] * b[0]
}

/// Triple product `a . (b x c)` = det[a, b, c].
#[inline]
pub(crate) fn triple(a: &P3, b: &P3, c: &P3) -> f64 {
    dot(a, &cross(b, c))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn helpers_agree_with_hand_computed_values() {
        let (a, b) = ([1.0, 2.0, 3.0], [4.0, 5.0, 6.0]);
        assert_eq!(sub(&b, &a), [3.0, 3.0, 3.0]);
        assert_eq!(add(&a, &b), [5.0, 7.0, 9.0]);
        assert_eq!(scale(&a, 2.0), [2.0, 4.0, 6.0]);
        assert_eq!(dot(&a, &b), 32.0);
        assert_eq!(norm2(&a), 14.0);
        assert_eq!(norm(&[3.0, 4.0]), 5.0);
        assert_eq!(cross(&a, &b), [-3.0, 6.0, -3.0]);
        assert_eq!(cross2(&[1.0, 0.0], &[0.0, 1.0]), 1.0);
        assert_eq!(
            triple(&[1.0, 0.0, 0.0], &[0.0, 1.0, 0.0], &[0.0, 0.0, 1.0]),
            1.0
        );
    }
}
