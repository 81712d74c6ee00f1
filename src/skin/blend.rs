//! Shared machinery of the skinning kernels: blending per-handle coefficient blocks with one
//! vertex's weights (dense or packed), and running a per-chunk kernel over all vertices in
//! parallel.
//!
//! A handle's coefficients are stored as `G` groups of 4 lanes ([`Lanes`]): for LBS one group
//! per row of `[R | t]` (padded with zeros in 2D), for DQS the two quaternions of a dual
//! quaternion. The blend `sum_j w_j table[j]` is then `G` 4-wide multiply-adds per influence.
//! On x86_64 with AVX2 + FMA it runs on explicit 256-bit registers with fused multiply-adds
//! (LLVM's auto-vectoriser shuffles the plain loop between registers); elsewhere a scalar loop
//! with the same summation order runs (results then differ from the FMA path only by rounding).

use rayon::prelude::*;

use super::{slice_of, standard2, Weights, CHUNK};
use crate::error::{SkinError, SkinResult};

/// `G` groups of 4 coefficients.
pub(crate) type Lanes<const G: usize> = [[f64; 4]; G];

/// What can go wrong inside a chunk; turned into a [`SkinError`] by the caller, which knows
/// the inputs well enough to say which one is wrong.
#[derive(Debug, Clone, Copy)]
pub(crate) enum ChunkError {
    /// A packed index outside `0..m`: `(vertex, slot, value)`.
    BadIndex(usize, usize, i64),
    /// The output of this vertex is NaN or infinite.
    NonFinite(usize),
    /// The blended quaternion of this vertex vanished (DQS only).
    Vanished(usize),
}

/// Influences of each vertex, as contiguous slices.
pub(crate) enum Influences<'a> {
    Dense {
        w: &'a [f64],
        m: usize,
    },
    Packed {
        idx: &'a [i64],
        w: &'a [f64],
        k: usize,
    },
}

/// Keeps the (possibly copied) contiguous weight arrays alive while kernels borrow them.
pub(crate) enum Held<'a> {
    Dense(ndarray::CowArray<'a, f64, ndarray::Ix2>),
    Packed(
        ndarray::CowArray<'a, i64, ndarray::Ix2>,
        ndarray::CowArray<'a, f64, ndarray::Ix2>,
    ),
}

impl<'a> Held<'a> {
    pub(crate) fn new(w: &Weights<'a>) -> Self {
        match w {
            Weights::Dense(w) => Held::Dense(standard2(*w)),
            Weights::Packed { index, weight } => {
                Held::Packed(standard2(*index), standard2(*weight))
            }
        }
    }

    pub(crate) fn influences(&self) -> SkinResult<Influences<'_>> {
        Ok(match self {
            Held::Dense(w) => Influences::Dense {
                w: slice_of(w)?,
                m: w.ncols(),
            },
            Held::Packed(i, w) => Influences::Packed {
                idx: slice_of(i)?,
                w: slice_of(w)?,
                k: w.ncols(),
            },
        })
    }
}

impl Influences<'_> {
    /// Number of weight entries per vertex (`m` dense, `k` packed).
    pub(crate) fn width(&self) -> usize {
        match *self {
            Influences::Dense { m, .. } => m,
            Influences::Packed { k, .. } => k,
        }
    }

    /// Asks the CPU to start loading the weights of vertices `i..i + rows` (a few vertices
    /// ahead of the ones being blended): the hardware prefetcher alone left the dense kernel
    /// waiting on memory about half of the time.
    #[inline(always)]
    pub(crate) fn prefetch(&self, i: usize, rows: usize) {
        #[cfg(target_arch = "x86_64")]
        {
            use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
            let lines = |s: &[f64], start: usize, len: usize| {
                let base = s.as_ptr().wrapping_add(start) as *const i8;
                let mut off = 0;
                while off < len * 8 {
                    // SAFETY: a prefetch never faults, even past the end of the slice.
                    unsafe { _mm_prefetch::<_MM_HINT_T0>(base.wrapping_add(off)) };
                    off += 64;
                }
            };
            // Packed rows are short and read in step with V and U: the hardware handles them.
            if let Influences::Dense { w, m } = *self {
                lines(w, i * m, rows * m);
            }
        }
        #[cfg(not(target_arch = "x86_64"))]
        let _ = (i, rows);
    }

    /// The weights of vertex `i` and, when packed, their handle indices (checked against
    /// `0..m`).
    #[inline(always)]
    pub(crate) fn row(&self, i: usize, m: usize) -> Result<(&[f64], Option<&[i64]>), ChunkError> {
        match *self {
            Influences::Dense { w, m } => Ok((&w[i * m..(i + 1) * m], None)),
            Influences::Packed { idx, w, k } => {
                let irow = &idx[i * k..(i + 1) * k];
                // `as usize` maps negative indices far out of range, so one compare catches both.
                if let Some(s) = irow.iter().position(|&j| j as usize >= m) {
                    return Err(ChunkError::BadIndex(i, s, irow[s]));
                }
                Ok((&w[i * k..(i + 1) * k], Some(irow)))
            }
        }
    }
}

/// `sum_l w[l] table[index[l]]` (or `sum_j w[j] table[j]` without `index`): two accumulators,
/// even and odd influences, added at the end (two independent chains of multiply-adds; see
/// `docs/skinning.md`). Indices must have been checked by [`Influences::row`].
#[inline(always)]
pub(crate) fn blend<const G: usize, const AVX: bool>(
    w: &[f64],
    index: Option<&[i64]>,
    table: &[Lanes<G>],
) -> Lanes<G> {
    #[cfg(target_arch = "x86_64")]
    {
        if AVX {
            // SAFETY: `AVX` is true only on the AVX2/FMA path, after runtime detection.
            return unsafe { avx::blend(w, index, table) };
        }
    }
    scalar_blend(w, index, table)
}

#[inline(always)]
fn axpy<const G: usize>(acc: &mut Lanes<G>, w: f64, t: &Lanes<G>) {
    for g in 0..G {
        for l in 0..4 {
            acc[g][l] += w * t[g][l];
        }
    }
}

#[inline(always)]
fn scalar_blend<const G: usize>(w: &[f64], index: Option<&[i64]>, table: &[Lanes<G>]) -> Lanes<G> {
    let mut a0 = [[0.0; 4]; G];
    let mut a1 = [[0.0; 4]; G];
    let handle = |l: usize| match index {
        Some(ix) => ix[l] as usize,
        None => l,
    };
    let pairs = w.len() / 2;
    for p in 0..pairs {
        axpy(&mut a0, w[2 * p], &table[handle(2 * p)]);
        axpy(&mut a1, w[2 * p + 1], &table[handle(2 * p + 1)]);
    }
    if w.len() % 2 == 1 {
        let l = w.len() - 1;
        axpy(&mut a0, w[l], &table[handle(l)]);
    }
    for g in 0..G {
        for l in 0..4 {
            a0[g][l] += a1[g][l];
        }
    }
    a0
}

#[cfg(target_arch = "x86_64")]
pub(crate) mod avx {
    use super::Lanes;
    use std::arch::x86_64::*;

    /// AVX2/FMA version of `scalar_blend`, same summation order: the two accumulators (even
    /// and odd influences) live in `__m256d` registers, one per group, and are added at the end.
    #[target_feature(enable = "avx2,fma")]
    #[inline]
    unsafe fn accumulate<const G: usize>(
        w: &[f64],
        index: Option<&[i64]>,
        table: &[Lanes<G>],
    ) -> [__m256d; G] {
        let mut a0 = [_mm256_setzero_pd(); G];
        let mut a1 = [_mm256_setzero_pd(); G];
        let n = w.len();
        let step = |acc: &mut [__m256d; G], wl: f64, t: &Lanes<G>| {
            let wv = _mm256_set1_pd(wl);
            for g in 0..G {
                // SAFETY: `t[g]` is 4 contiguous f64.
                let tv = unsafe { _mm256_loadu_pd(t[g].as_ptr()) };
                acc[g] = _mm256_fmadd_pd(wv, tv, acc[g]);
            }
        };
        match index {
            None => {
                let (tw, tt) = (w.chunks_exact(2), table.chunks_exact(2));
                let (rw, rt) = (tw.remainder(), tt.remainder());
                for (wp, tp) in tw.zip(tt) {
                    step(&mut a0, wp[0], &tp[0]);
                    step(&mut a1, wp[1], &tp[1]);
                }
                if let (Some(&wl), Some(t)) = (rw.first(), rt.first()) {
                    step(&mut a0, wl, t);
                }
            }
            Some(ix) => {
                let pairs = n / 2;
                for p in 0..pairs {
                    step(&mut a0, w[2 * p], &table[ix[2 * p] as usize]);
                    step(&mut a1, w[2 * p + 1], &table[ix[2 * p + 1] as usize]);
                }
                if n % 2 == 1 {
                    step(&mut a0, w[n - 1], &table[ix[n - 1] as usize]);
                }
            }
        }
        for g in 0..G {
            a0[g] = _mm256_add_pd(a0[g], a1[g]);
        }
        a0
    }

    /// The blended coefficient groups, stored.
    #[target_feature(enable = "avx2,fma")]
    #[inline]
    pub(super) unsafe fn blend<const G: usize>(
        w: &[f64],
        index: Option<&[i64]>,
        table: &[Lanes<G>],
    ) -> Lanes<G> {
        // SAFETY: same target features as the caller's.
        let a = unsafe { accumulate(w, index, table) };
        let mut out = [[0.0; 4]; G];
        for g in 0..G {
            // SAFETY: `out[g]` is 4 contiguous f64.
            unsafe { _mm256_storeu_pd(out[g].as_mut_ptr(), a[g]) };
        }
        out
    }

    /// One LBS point in registers: blend the rows `[R_p | t_p]` (G = d = 2 or 3, see
    /// `transform_blocks`), then `u_p = row_p . [x; 1]` with horizontal adds; writes `o[..d]`.
    #[target_feature(enable = "avx2,fma")]
    #[inline]
    pub(crate) unsafe fn lbs_point<const G: usize>(
        w: &[f64],
        index: Option<&[i64]>,
        table: &[Lanes<G>],
        x: &[f64],
        o: &mut [f64],
    ) {
        // SAFETY: same target features as the caller's.
        let a = unsafe { accumulate(w, index, table) };
        // SAFETY: same target features as the caller's.
        unsafe { apply(&a, x, o) };
    }

    /// `B` consecutive vertices with dense weights `w (B, m)`, blended like a small GEMM
    /// micro-kernel: each handle's `G` rows are loaded once into registers and shared by the `B`
    /// vertices, and each vertex's weight is broadcast once and shared by its `G` rows, so one
    /// handle costs `G` loads + `B` broadcasts for `B G` fused multiply-adds.
    ///
    /// Why `B G <= 9`: AVX2 has 16 `ymm` registers. The accumulators (`B G`), the handle's rows
    /// (`G`) and the broadcast weights (`B`) must all fit, or LLVM spills accumulators to the
    /// stack and the loop becomes a chain of store-to-load forwards (a 4-vertex block needs
    /// 12 + 3 + 4 = 19 registers; see `docs/skinning.md`). `B = 3, G = 3` uses 9 + 3 + 3 = 15
    /// registers (2D: `B = 4`,
    /// 8 + 2 + 4 = 14), and the 8 or 9 independent accumulator chains cover the FMA latency
    /// (4 cycles x 2 FMA pipes = 8 chains needed).
    #[target_feature(enable = "avx2,fma")]
    #[inline]
    pub(crate) unsafe fn lbs_dense_block<const G: usize, const B: usize>(
        w: &[f64],
        table: &[Lanes<G>],
        x: &[f64],
        o: &mut [f64],
    ) {
        let m = table.len();
        // `[..m]` tells LLVM every row has exactly `m` entries: no bounds check in the loop
        // (a loop, not `array::from_fn`, which LLVM left as an out-of-line call per block)
        let mut rows: [&[f64]; B] = [&[]; B];
        for (b, row) in rows.iter_mut().enumerate() {
            *row = &w[b * m..][..m];
        }
        let mut acc = [[_mm256_setzero_pd(); G]; B];
        for (j, t) in table.iter().enumerate() {
            let mut tv = [_mm256_setzero_pd(); G];
            for g in 0..G {
                // SAFETY: `t[g]` is 4 contiguous f64.
                tv[g] = unsafe { _mm256_loadu_pd(t[g].as_ptr()) };
            }
            for b in 0..B {
                let wb = _mm256_set1_pd(rows[b][j]);
                for g in 0..G {
                    acc[b][g] = _mm256_fmadd_pd(wb, tv[g], acc[b][g]);
                }
            }
        }
        for b in 0..B {
            // SAFETY: same target features as the caller's.
            unsafe { apply(&acc[b], &x[b * G..(b + 1) * G], &mut o[b * G..(b + 1) * G]) };
        }
    }

    /// All rows of a chunk with packed weights (`k` influences per vertex), in one function so
    /// that nothing in the loop is a call (a per-vertex call would return its `G` registers
    /// through the stack). Each handle index is checked once (`table.get`, no separate validation pass);
    /// returns the first `(row, slot)` holding an index outside `0..m`, having written the rows
    /// before it.
    #[target_feature(enable = "avx2,fma")]
    pub(crate) unsafe fn lbs_packed_rows<const G: usize, const K: usize>(
        idx: &[i64],
        w: &[f64],
        k: usize,
        table: &[Lanes<G>],
        x: &[f64],
        o: &mut [f64],
    ) -> Option<(usize, usize)> {
        // `K > 0` fixes `k` at compile time (the common widths are instantiated by the caller):
        // the slot loop is then unrolled and the row slices need no bounds checks.
        let k = if K > 0 { K } else { k };
        let load = |t: &Lanes<G>, g: usize| {
            // SAFETY: `t[g]` is 4 contiguous f64.
            unsafe { _mm256_loadu_pd(t[g].as_ptr()) }
        };
        let rows = idx
            .chunks_exact(k)
            .zip(w.chunks_exact(k))
            .zip(x.chunks_exact(G))
            .zip(o.chunks_exact_mut(G));
        for (r, (((ir, wr), xr), or)) in rows.enumerate() {
            // Two accumulators (even and odd slots), as in `scalar_blend`: two independent
            // chains of multiply-adds per row.
            let mut a0 = [_mm256_setzero_pd(); G];
            let mut a1 = [_mm256_setzero_pd(); G];
            let mut l = 0;
            while l + 2 <= k {
                // `as usize` maps negative indices far out of range: `get` catches both.
                let Some(t0) = table.get(ir[l] as usize) else {
                    return Some((r, l));
                };
                let Some(t1) = table.get(ir[l + 1] as usize) else {
                    return Some((r, l + 1));
                };
                let (b0, b1) = (_mm256_set1_pd(wr[l]), _mm256_set1_pd(wr[l + 1]));
                for g in 0..G {
                    a0[g] = _mm256_fmadd_pd(b0, load(t0, g), a0[g]);
                    a1[g] = _mm256_fmadd_pd(b1, load(t1, g), a1[g]);
                }
                l += 2;
            }
            if l < k {
                let Some(t0) = table.get(ir[l] as usize) else {
                    return Some((r, l));
                };
                let b0 = _mm256_set1_pd(wr[l]);
                for (g, a) in a0.iter_mut().enumerate() {
                    *a = _mm256_fmadd_pd(b0, load(t0, g), *a);
                }
            }
            for g in 0..G {
                a0[g] = _mm256_add_pd(a0[g], a1[g]);
            }
            // SAFETY: same target features as this function's.
            unsafe { apply(&a0, xr, or) };
        }
        None
    }

    /// `u_p = row_p . [x; 1]` for the blended rows in registers; writes `o[..G]`.
    #[target_feature(enable = "avx2,fma")]
    #[inline]
    unsafe fn apply<const G: usize>(a: &[__m256d; G], x: &[f64], o: &mut [f64]) {
        if G == 3 {
            let xv = _mm256_set_pd(1.0, x[2], x[1], x[0]);
            let (p0, p1, p2) = (
                _mm256_mul_pd(a[0], xv),
                _mm256_mul_pd(a[1], xv),
                _mm256_mul_pd(a[2], xv),
            );
            let h01 = _mm256_hadd_pd(p0, p1); // [p0_01, p1_01, p0_23, p1_23]
            let h22 = _mm256_hadd_pd(p2, p2); // [p2_01, p2_01, p2_23, p2_23]
            let lo = _mm256_permute2f128_pd(h01, h22, 0x20); // [p0_01, p1_01, p2_01, p2_01]
            let hi = _mm256_permute2f128_pd(h01, h22, 0x31); // [p0_23, p1_23, p2_23, p2_23]
            let u = _mm256_add_pd(lo, hi);
            let o3 = &mut o[..3];
            // SAFETY: `o3` holds 3 numbers; the 128-bit store writes the first two.
            unsafe { _mm_storeu_pd(o3.as_mut_ptr(), _mm256_castpd256_pd128(u)) };
            o3[2] = _mm_cvtsd_f64(_mm256_extractf128_pd(u, 1));
        } else {
            // rows [r_p0, r_p1, t_p, 0]
            let xv = _mm256_set_pd(0.0, 1.0, x[1], x[0]);
            let h01 = _mm256_hadd_pd(_mm256_mul_pd(a[0], xv), _mm256_mul_pd(a[1], xv));
            let u = _mm_add_pd(_mm256_castpd256_pd128(h01), _mm256_extractf128_pd(h01, 1));
            let o2 = &mut o[..2];
            // SAFETY: `o2` holds 2 numbers.
            unsafe { _mm_storeu_pd(o2.as_mut_ptr(), u) };
        }
    }
}

/// Runs `kernel(first_vertex, out_chunk, normals_chunk)` over chunks of [`CHUNK`] vertices in
/// parallel; `out` (and `nout` when given) hold `d` numbers per vertex.
pub(crate) fn par_chunks<K>(
    d: usize,
    out: &mut [f64],
    nout: Option<&mut [f64]>,
    kernel: K,
) -> Result<(), ChunkError>
where
    K: Fn(usize, &mut [f64], Option<&mut [f64]>) -> Result<(), ChunkError> + Sync,
{
    let step = CHUNK * d;
    match nout {
        None => out
            .par_chunks_mut(step)
            .enumerate()
            .try_for_each(|(c, o)| kernel(c * CHUNK, o, None)),
        Some(nout) => out
            .par_chunks_mut(step)
            .zip(nout.par_chunks_mut(step))
            .enumerate()
            .try_for_each(|(c, (o, no))| kernel(c * CHUNK, o, Some(no))),
    }
}

/// Error for the first vertex of a chunk holding a non-finite number, if any.
#[inline(always)]
pub(crate) fn first_nonfinite(first: usize, d: usize, chunk: &[f64]) -> Result<(), ChunkError> {
    // A float is NaN or infinite exactly when its 11 exponent bits are all ones. Testing the bits
    // and OR-ing the answers is an integer reduction, which LLVM vectorises (compare + or on
    // 4 lanes per instruction). The previous `sum of x * 0` was a single chain of dependent f64
    // additions (3-4 cycles each, float addition is not reassociated), about 10 cycles per
    // vertex: as much time as the whole packed blend.
    const EXP: u64 = 0x7ff0_0000_0000_0000;
    let bad = chunk
        .iter()
        .fold(0u64, |acc, x| acc | u64::from(x.to_bits() & EXP == EXP));
    if bad == 0 {
        return Ok(());
    }
    let p = chunk.iter().position(|x| !x.is_finite()).unwrap_or(0);
    Err(ChunkError::NonFinite(first + p / d))
}

/// Turns a kernel error into the user-facing message.
pub(crate) fn to_skin_error(
    e: ChunkError,
    m: usize,
    explain: impl Fn(usize) -> SkinError,
) -> SkinError {
    match e {
        ChunkError::BadIndex(i, s, j) => SkinError::InvalidInput(format!(
            "packed weight indices: entry ({i}, {s}) is {j}, outside the valid range 0..{}",
            m.saturating_sub(1)
        )),
        ChunkError::NonFinite(i) => explain(i),
        ChunkError::Vanished(i) => SkinError::InvalidInput(format!(
            "dqs: the blended rotation of vertex {i} vanishes (its weights sum to zero or cancel)"
        )),
    }
}
