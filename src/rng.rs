//! The crate's one random number generator: SplitMix64 (Steele et al. 2014), small and
//! deterministic.
//!
//! The geometric field draws from streams keyed by `(seed, purpose, index)`, e.g.
//! `(seed, step, sample)`: each Monte-Carlo sample owns its stream, so results do not depend on
//! how rayon schedules the work or on the thread count. The BBW solvers draw their random start
//! from one generator ([`Rng::unmixed`]).

/// A SplitMix64 generator.
#[derive(Clone, Debug)]
pub struct Rng(u64);

const GOLDEN: u64 = 0x9E37_79B9_7F4A_7C15;

/// The SplitMix64 output function (a bijective 64-bit mixer).
#[inline]
pub fn mix(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

impl Rng {
    /// Generator seeded with `seed`.
    pub fn new(seed: u64) -> Self {
        Rng(mix(seed ^ GOLDEN))
    }

    /// Generator whose first state is `seed ^ GOLDEN`, without the mixing of [`Rng::new`]: the
    /// seeding of the BBW random start, kept so that a seed gives the same start as before.
    pub fn unmixed(seed: u64) -> Self {
        Rng(seed ^ GOLDEN)
    }

    /// Independent stream number `(a, b)` of `seed`.
    ///
    /// Inputs: seed, a (purpose / step), b (item index). Output: a generator whose sequence
    /// depends only on the three keys.
    pub fn stream(seed: u64, a: u64, b: u64) -> Self {
        let k = mix(mix(seed ^ GOLDEN).wrapping_add(a.wrapping_mul(0xD1B5_4A32_D192_ED03)));
        Rng(mix(k.wrapping_add(b.wrapping_mul(0xABC9_8388_FB8F_AC03))))
    }

    /// Next 64 random bits.
    #[inline]
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(GOLDEN);
        mix(self.0)
    }

    /// Uniform in `[0, 1)` with 53 random bits.
    #[inline]
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }

    /// Uniform integer in `0..n` (`n >= 1`), by multiply-shift.
    #[inline]
    pub fn below(&mut self, n: usize) -> usize {
        ((self.next_u64() as u128 * n as u128) >> 64) as usize
    }

    /// Uniform direction on the unit circle (D = 2) or sphere (D = 3): the `v` of eq. 13.
    pub fn direction<const D: usize>(&mut self) -> [f64; D] {
        let phi = std::f64::consts::TAU * self.uniform();
        let mut out = [0.0; D];
        if D == 2 {
            out[0] = phi.cos();
            out[1 % D] = phi.sin();
        } else {
            let z = 2.0 * self.uniform() - 1.0;
            let r = (1.0 - z * z).max(0.0).sqrt();
            out[0] = r * phi.cos();
            out[1 % D] = r * phi.sin();
            out[2 % D] = z;
        }
        out
    }

    /// Uniform point in the unit ball of dimension D (rejection from the cube).
    pub fn in_ball<const D: usize>(&mut self) -> [f64; D] {
        loop {
            let p: [f64; D] = std::array::from_fn(|_| 2.0 * self.uniform() - 1.0);
            if p.iter().map(|x| x * x).sum::<f64>() <= 1.0 {
                return p;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::norm;

    #[test]
    fn streams_are_reproducible_and_distinct() {
        let a: Vec<u64> = (0..4).map(|_| Rng::stream(1, 2, 3).next_u64()).collect();
        assert!(a.windows(2).all(|w| w[0] == w[1]));
        assert_ne!(
            Rng::stream(1, 2, 3).next_u64(),
            Rng::stream(1, 2, 4).next_u64()
        );
        assert_ne!(
            Rng::stream(1, 2, 3).next_u64(),
            Rng::stream(1, 3, 3).next_u64()
        );
        let mut r = Rng::new(5);
        let m: f64 = (0..20000).map(|_| r.uniform()).sum::<f64>() / 20000.0;
        assert!((m - 0.5).abs() < 0.01);
        let d: [f64; 3] = r.direction();
        assert!((norm(&d) - 1.0).abs() < 1e-12);
    }
}
