//! Dense vector kernels for the `nf x m` blocks of the dual solvers, run on the rayon threads.
//!
//! At 40k vertices and 8 handles these vectors are 2.6 MB each and L-BFGS keeps 20 of them, so
//! its bookkeeping streams from memory and, done serially, costs more wall time than the sparse
//! solves (which run on all cores). Each kernel does its work in one pass, and sums are reduced
//! per chunk and then added in chunk order, so results do not depend on scheduling.

use rayon::prelude::*;

/// Entries per rayon task: large enough to amortise scheduling, small enough to share a
/// 330k-entry block evenly between the threads.
const CHUNK: usize = 1 << 14;

/// Adds per-chunk partial sums in order (deterministic, unlike a rayon `sum`).
fn ordered_sum<const K: usize>(parts: Vec<[f64; K]>) -> [f64; K] {
    parts.iter().fold([0.0; K], |mut acc, p| {
        acc.iter_mut().zip(p).for_each(|(a, b)| *a += b);
        acc
    })
}

/// `<a, b>`.
pub fn dot(a: &[f64], b: &[f64]) -> f64 {
    let parts: Vec<[f64; 1]> = a
        .par_chunks(CHUNK)
        .zip(b.par_chunks(CHUNK))
        .map(|(x, y)| [x.iter().zip(y).map(|(p, q)| p * q).sum()])
        .collect();
    ordered_sum(parts)[0]
}

/// `y <- beta y + alpha x` (`y`'s old entries are not read when `beta` is 0), then returns
/// `<z, y>` of the updated `y` (0 without `z`).
pub fn update_dot(beta: f64, y: &mut [f64], alpha: f64, x: &[f64], z: Option<&[f64]>) -> f64 {
    let parts: Vec<[f64; 1]> = y
        .par_chunks_mut(CHUNK)
        .zip(x.par_chunks(CHUNK))
        .enumerate()
        .map(|(c, (yc, xc))| {
            if beta == 0.0 {
                yc.iter_mut().zip(xc).for_each(|(yi, xi)| *yi = alpha * xi);
            } else {
                yc.iter_mut()
                    .zip(xc)
                    .for_each(|(yi, xi)| *yi = beta * *yi + alpha * xi);
            }
            let zc = z.map(|z| &z[c * CHUNK..c * CHUNK + yc.len()]);
            [zc.map_or(0.0, |zc| zc.iter().zip(yc.iter()).map(|(p, q)| p * q).sum())]
        })
        .collect();
    ordered_sum(parts)[0]
}

/// `out <- a + t b`.
pub fn add_scaled(out: &mut [f64], a: &[f64], t: f64, b: &[f64]) {
    out.par_chunks_mut(CHUNK)
        .zip(a.par_chunks(CHUNK).zip(b.par_chunks(CHUNK)))
        .for_each(|(o, (a, b))| {
            o.iter_mut()
                .zip(a.iter().zip(b))
                .for_each(|(o, (a, b))| *o = a + t * b);
        });
}

/// `s <- x1 - x0`, `y <- g1 - g0`; returns `[<s, s>, <y, y>, <s, y>]` (an L-BFGS correction
/// pair and what its curvature test needs).
pub fn correction_pair(
    s: &mut [f64],
    y: &mut [f64],
    (x1, x0): (&[f64], &[f64]),
    (g1, g0): (&[f64], &[f64]),
) -> [f64; 3] {
    let parts: Vec<[f64; 3]> = s
        .par_chunks_mut(CHUNK)
        .zip(y.par_chunks_mut(CHUNK))
        .enumerate()
        .map(|(c, (sc, yc))| {
            let r = c * CHUNK..c * CHUNK + sc.len();
            let (x1, x0, g1, g0) = (&x1[r.clone()], &x0[r.clone()], &g1[r.clone()], &g0[r]);
            let mut acc = [0.0; 3];
            for i in 0..sc.len() {
                sc[i] = x1[i] - x0[i];
                yc[i] = g1[i] - g0[i];
                acc[0] += sc[i] * sc[i];
                acc[1] += yc[i] * yc[i];
                acc[2] += sc[i] * yc[i];
            }
            acc
        })
        .collect();
    ordered_sum(parts)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn serial_dot(a: &[f64], b: &[f64]) -> f64 {
        a.iter().zip(b).map(|(x, y)| x * y).sum()
    }

    #[test]
    fn kernels_match_their_serial_definitions_across_chunks() {
        let n = 3 * CHUNK + 17;
        let a: Vec<f64> = (0..n)
            .map(|i| ((i * 7919) % 1000) as f64 / 1000.0 - 0.5)
            .collect();
        let b: Vec<f64> = (0..n)
            .map(|i| ((i * 104_729) % 997) as f64 / 997.0)
            .collect();
        let rel = |x: f64, y: f64| (x - y).abs() / y.abs().max(1e-300);
        assert!(rel(dot(&a, &b), serial_dot(&a, &b)) < 1e-12);

        let mut y = a.clone();
        let d = update_dot(2.0, &mut y, -3.0, &b, Some(&a));
        let expect: Vec<f64> = a.iter().zip(&b).map(|(p, q)| 2.0 * p - 3.0 * q).collect();
        assert_eq!(y, expect);
        assert!(rel(d, serial_dot(&a, &expect)) < 1e-12);
        assert_eq!(update_dot(1.0, &mut y, 0.0, &b, None), 0.0);

        let mut out = vec![0.0; n];
        add_scaled(&mut out, &a, 0.5, &b);
        assert!(out
            .iter()
            .zip(a.iter().zip(&b))
            .all(|(o, (p, q))| *o == p + 0.5 * q));

        let (mut s, mut yv) = (vec![0.0; n], vec![0.0; n]);
        let [ss, yy, sy] = correction_pair(&mut s, &mut yv, (&b, &a), (&a, &b));
        let ds: Vec<f64> = b.iter().zip(&a).map(|(p, q)| p - q).collect();
        let dy: Vec<f64> = ds.iter().map(|v| -v).collect();
        assert_eq!((s.clone(), yv.clone()), (ds.clone(), dy.clone()));
        assert!(rel(ss, serial_dot(&ds, &ds)) < 1e-12);
        assert!(rel(yy, serial_dot(&dy, &dy)) < 1e-12);
        assert!(rel(sy, serial_dot(&ds, &dy)) < 1e-12);
    }
}
