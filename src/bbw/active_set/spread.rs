//! The lower bound of a round: multipliers made non-negative by spreading, not clamping.

use rayon::prelude::*;

use crate::sparse::Csc;

/// Makes the multipliers `y` (`nf x m`) non-negative, for the dual lower bound, by moving each
/// negative entry's mass onto the nearest positive entries of its column, ring by ring of the
/// graph of `A`.
///
/// Any `Y >= 0` gives a lower bound, and its gap to `y`'s (tight but infeasible) Lagrangian is
/// `1/2 <D, A^{-1} D P_m>` with `D = Y - y`. `A^{-1}` is a smoothing operator (the biharmonic
/// Green's function), so clamping, whose `D` is a positive bump of every negative entry, loses
/// a lot, and a `D` that is locally zero-sum almost nothing. The first-order term `<D, w>` is
/// zero either way (`y` is only non-zero off the support, where `w = 0`).
///
/// Entries above `-NOISE max |y|` are round-off on the optimum's weakly active zeros (where
/// `y* = 0` too) and are clamped without a search: they are most of the negative entries, and
/// clamping them moves the lower bound by round-off only.
pub(super) fn spread_negative(y: &mut [f64], a: &Csc, nf: usize) {
    /// Rings searched per negative entry before its remaining mass is dropped (a clamp).
    const REACH: usize = 3;
    /// Multipliers this far below 0, relative to the largest, are clamped without a search.
    const NOISE: f64 = 1e-14;
    let floor = -NOISE * y.iter().fold(0.0f64, |a, v| a.max(v.abs()));
    // One column per task: the columns' negative entries differ in number several-fold.
    y.par_chunks_mut(nf).with_max_len(1).for_each(|col| {
        let mut stamp = vec![usize::MAX; nf];
        let (mut ring, mut next) = (Vec::new(), Vec::new());
        for k in 0..nf {
            if col[k] >= 0.0 {
                continue;
            }
            if col[k] > floor {
                col[k] = 0.0;
                continue;
            }
            let mut deficit = -col[k];
            col[k] = 0.0;
            // The first ring is `k`'s row of `A` without `k`: most deficits are paid there,
            // so it is scanned in place, and marked for the outer rings only when some remains.
            let first = a.symbolic().row_idx_of_col_raw(k);
            let pos: f64 = first
                .iter()
                .filter(|&&i| i != k)
                .map(|&i| col[i].max(0.0))
                .sum();
            if pos > 0.0 {
                let take = deficit.min(pos);
                let keep = 1.0 - take / pos;
                for &i in first {
                    if i != k && col[i] > 0.0 {
                        col[i] *= keep;
                    }
                }
                deficit -= take;
            }
            if deficit <= 0.0 {
                continue;
            }
            stamp[k] = k;
            ring.clear();
            for &i in first {
                if i != k {
                    stamp[i] = k;
                    ring.push(i);
                }
            }
            for _ in 1..REACH {
                if deficit <= 0.0 || ring.is_empty() {
                    break;
                }
                next.clear();
                for &r in &ring {
                    for &i in a.symbolic().row_idx_of_col_raw(r) {
                        if stamp[i] != k {
                            stamp[i] = k;
                            next.push(i);
                        }
                    }
                }
                let pos: f64 = next.iter().map(|&i| col[i].max(0.0)).sum();
                if pos > 0.0 {
                    let take = deficit.min(pos);
                    let keep = 1.0 - take / pos;
                    for &i in &next {
                        if col[i] > 0.0 {
                            col[i] *= keep;
                        }
                    }
                    deficit -= take;
                }
                std::mem::swap(&mut ring, &mut next);
            }
        }
    });
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sparse::path_matrix;

    #[test]
    fn spread_negative_moves_mass_to_the_nearest_positive_entries() {
        let a = path_matrix(7);
        // A negative entry at 3; positive mass one step away (2) and two steps away (5).
        let mut y = vec![0.0, 0.0, 0.5, -1.0, 0.0, 2.0, 4.0];
        spread_negative(&mut y, &a, 7);
        assert!(y.iter().all(|&v| v >= 0.0), "{y:?}");
        // Ring 1 {2, 4} holds 0.5: all of it goes; ring 2 {1, 5} pays the remaining 0.5.
        let want = [0.0, 0.0, 0.0, 0.0, 0.0, 1.5, 4.0];
        for (got, want) in y.iter().zip(want) {
            assert!((got - want).abs() < 1e-15, "{y:?}");
        }
        // Mass four rings away is out of reach: the deficit is dropped (a clamp) and the
        // mass stays.
        let mut y = vec![-1.0, 0.0, 0.0, 0.0, 0.5, 0.0, 0.0];
        spread_negative(&mut y, &a, 7);
        assert_eq!(y, vec![0.0, 0.0, 0.0, 0.0, 0.5, 0.0, 0.0]);
    }
}
