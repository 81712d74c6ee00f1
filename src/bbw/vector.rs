//! Dense vector kernels for the `nf x m` blocks of the dual solvers, run on the rayon threads.
//!
//! At 40k vertices and 8 handles these vectors are 2.6 MB each and L-BFGS keeps 20 of them, so
//! its bookkeeping streams from memory and, done serially, costs more wall time than the sparse
//! solves (which run on all cores). Each kernel does its work in one pass, and sums are reduced
//! per chunk and then added in chunk order, so results do not depend on scheduling.

use std::ops::Range;

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

/// Which entries of `w` are above `threshold` (a support read off weights).
pub fn above(w: &[f64], threshold: f64) -> Vec<bool> {
    w.par_iter().map(|&x| x > threshold).collect()
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

/// Partial sums per inner product in the many-vector kernels: one running sum waits on each
/// addition's latency, which with a few dozen products per entry would bound the pass.
const LANES: usize = 8;

/// Entries per block of the many-vector kernels (a multiple of `LANES`): the block of the
/// vectors every product uses (the columns, or `out`) stays in cache while the others stream
/// past it, so each vector comes from memory once however many products use it.
const BLOCK: usize = 2048;

/// `acc[l] += sum of a[i] b[i]` over the entries `i = l mod LANES` (the last, fewer than
/// `LANES`, into `acc[0]`).
#[inline(always)]
fn accumulate_lanes<A: Copy + Into<f64>>(acc: &mut [f64; LANES], a: &[A], b: &[f64]) {
    let (a8, a_tail) = a.as_chunks::<LANES>();
    let (b8, b_tail) = b.as_chunks::<LANES>();
    for (x, y) in a8.iter().zip(b8) {
        for l in 0..LANES {
            acc[l] += x[l].into() * y[l];
        }
    }
    acc[0] += a_tail
        .iter()
        .zip(b_tail)
        .map(|(p, q)| (*p).into() * q)
        .sum::<f64>();
}

/// All inner products `<rows[i], cols[j]>`, row-major `rows.len() x cols.len()`, in one pass
/// over the vectors. The rows are single precision (stored L-BFGS pairs), the products
/// double.
pub fn inner_products(rows: &[&[f32]], cols: &[&[f64]]) -> Vec<f64> {
    let n = cols.first().map_or(0, |c| c.len());
    let nc = rows.len() * cols.len();
    let parts: Vec<Vec<f64>> = (0..n.div_ceil(CHUNK))
        .into_par_iter()
        .map(|c| {
            let r = c * CHUNK..(c * CHUNK + CHUNK).min(n);
            #[cfg(target_arch = "x86_64")]
            if crate::cpu::has_avx2() {
                // SAFETY: the CPU has AVX2 and FMA (checked at run time).
                return unsafe { products_chunk_avx2(rows, cols, r) };
            }
            products_chunk(rows, cols, r)
        })
        .collect();
    parts.iter().fold(vec![0.0; nc], |mut acc, p| {
        acc.iter_mut().zip(p).for_each(|(a, b)| *a += b);
        acc
    })
}

/// [`products_chunk`] compiled for AVX2: the same operations in the same order (no fused
/// multiply-adds), four doubles to a register instead of two.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn products_chunk_avx2(rows: &[&[f32]], cols: &[&[f64]], r: Range<usize>) -> Vec<f64> {
    products_chunk(rows, cols, r)
}

/// `inner_products` over the entries `r`.
#[inline(always)]
fn products_chunk(rows: &[&[f32]], cols: &[&[f64]], r: Range<usize>) -> Vec<f64> {
    let nc = cols.len();
    let mut acc = vec![[0.0; LANES]; rows.len() * nc];
    for b0 in r.clone().step_by(BLOCK) {
        let b = b0..(b0 + BLOCK).min(r.end);
        for (i, row) in rows.iter().enumerate() {
            for (j, col) in cols.iter().enumerate() {
                accumulate_lanes(&mut acc[i * nc + j], &row[b.clone()], &col[b.clone()]);
            }
        }
    }
    acc.iter().map(|a| a.iter().sum()).collect()
}

/// `out <- t0 v0 + sum_i t_i v_i` (`v0` double, the `v_i` single precision) in one pass over
/// the vectors, then returns `<z, out>`.
pub fn combine_dot(out: &mut [f64], v0: (f64, &[f64]), terms: &[(f64, &[f32])], z: &[f64]) -> f64 {
    let parts: Vec<[f64; 1]> = out
        .par_chunks_mut(CHUNK)
        .enumerate()
        .map(|(c, oc)| {
            let at = c * CHUNK;
            #[cfg(target_arch = "x86_64")]
            if crate::cpu::has_avx2() {
                // SAFETY: the CPU has AVX2 and FMA (checked at run time).
                return [unsafe { combine_chunk_avx2(oc, at, v0, terms, z) }];
            }
            [combine_chunk(oc, at, v0, terms, z)]
        })
        .collect();
    ordered_sum(parts)[0]
}

/// [`combine_chunk`] compiled for AVX2 (as [`products_chunk_avx2`]).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn combine_chunk_avx2(
    out: &mut [f64],
    at: usize,
    v0: (f64, &[f64]),
    terms: &[(f64, &[f32])],
    z: &[f64],
) -> f64 {
    combine_chunk(out, at, v0, terms, z)
}

/// `combine_dot` on the entries `at..at + out.len()`, returning this part of `<z, out>`.
#[inline(always)]
fn combine_chunk(
    out: &mut [f64],
    at: usize,
    (t0, v0): (f64, &[f64]),
    terms: &[(f64, &[f32])],
    z: &[f64],
) -> f64 {
    let mut acc = [0.0; LANES];
    for (b, ob) in out.chunks_mut(BLOCK).enumerate() {
        let r = at + b * BLOCK..at + b * BLOCK + ob.len();
        ob.iter_mut()
            .zip(&v0[r.clone()])
            .for_each(|(o, v)| *o = t0 * v);
        for (t, v) in terms {
            ob.iter_mut()
                .zip(&v[r.clone()])
                .for_each(|(o, v)| *o += t * f64::from(*v));
        }
        accumulate_lanes(&mut acc, ob, &z[r]);
    }
    acc.iter().sum()
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

        // Without further terms: `out <- t0 v0` and `<z, out>`.
        let mut y = a.clone();
        let d = combine_dot(&mut y, (-3.0, &b), &[], &a);
        let expect: Vec<f64> = b.iter().map(|q| -3.0 * q).collect();
        assert_eq!(y, expect);
        assert!(rel(d, serial_dot(&a, &expect)) < 1e-12);

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

        let single = |v: &[f64]| -> Vec<f32> { v.iter().map(|x| *x as f32).collect() };
        let wide = |v: &[f32]| -> Vec<f64> { v.iter().map(|x| f64::from(*x)).collect() };
        let (a32, b32, ds32) = (single(&a), single(&b), single(&ds));
        let g = inner_products(&[&a32, &b32, &ds32], &[&b, &a]);
        let (aw, bw, dsw) = (wide(&a32), wide(&b32), wide(&ds32));
        let expect = [
            (&aw, &b),
            (&aw, &a),
            (&bw, &b),
            (&bw, &a),
            (&dsw, &b),
            (&dsw, &a),
        ];
        for (got, (p, q)) in g.iter().zip(expect) {
            assert!(rel(*got, serial_dot(p, q)) < 1e-12);
        }

        let mut out = vec![1.0; n];
        let d = combine_dot(&mut out, (2.0, &a), &[(-0.5, &b32), (3.0, &ds32)], &b);
        let expect: Vec<f64> = (0..n)
            .map(|i| 2.0 * a[i] - 0.5 * bw[i] + 3.0 * dsw[i])
            .collect();
        assert!(out
            .iter()
            .zip(&expect)
            .all(|(o, e)| (o - e).abs() <= 1e-15 * e.abs().max(1.0)));
        assert!(rel(d, serial_dot(&expect, &b)) < 1e-12);
    }
}
