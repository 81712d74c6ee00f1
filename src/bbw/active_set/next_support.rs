//! The next support guess of a round, from its weights and multipliers.

use rayon::prelude::*;

use crate::sparse::Csc;

/// The sign tests of a round. Weights and multipliers below these in magnitude are CG and
/// round-off noise: testing them against 0 flips many such entries per round and grows the
/// supports without changing the bounds.
#[derive(Clone, Copy)]
pub(super) struct SignThresholds {
    /// A support entry whose weight is below this leaves.
    pub leave_below: f64,
    /// An off-support entry whose multiplier is below this joins.
    pub join_below: f64,
}

impl SignThresholds {
    /// Thresholds for a solve to relative gap `tol` whose gradient entries reach `scale`.
    pub fn new(tol: f64, scale: f64) -> Self {
        SignThresholds {
            leave_below: 1e-3 * tol,
            join_below: -0.1 * tol * scale,
        }
    }
}

/// A round's next support guess ([`next_support`]).
pub(super) struct NextSupport {
    /// The support after the sign rules (`support[j * nf + i]`).
    pub next: Vec<bool>,
    /// Sign violations: support entries below `leave_below` (not all of which leave) and
    /// off-support entries below `join_below` (at most one per row joins).
    pub negative: usize,
    pub joined: usize,
}

/// The next support guess from a round's weights `w` and multipliers `y` (all `nf x m`).
///
/// One rule keeps the supports' edges from crawling, as plain primal-dual active sets do on
/// the biharmonic operator (not an M-matrix), and another keeps the supports from
/// overgrowing (the smoother of the rounds settles the rest of the edges, `pou_rounds`):
/// - A support that reaches too far overshoots: its weights dip negative over a band wider than
///   the excess, and dropping the whole band cuts into the optimal support, which then creeps
///   back one neighbourhood per round. So only the outer half of a negative band leaves (entries
///   no farther, in steps of the graph of `A`, from the support's edge than from its
///   non-negative part), plus the most negative entry of each neighbourhood, which opens holes.
/// - A row joins one column per round: the one whose multiplier is most negative
///   ([`row_joiners`]).
pub(super) fn next_support(
    a: &Csc,
    support: &[bool],
    w: &[f64],
    y: &[f64],
    th: SignThresholds,
    nf: usize,
) -> NextSupport {
    let mut next = support.to_vec();
    let joiner = row_joiners(support, y, th.join_below, nf);
    let per_column: Vec<(usize, usize)> = next
        .par_chunks_mut(nf)
        .zip(support.par_chunks(nf))
        .zip(w.par_chunks(nf).zip(y.par_chunks(nf)))
        .enumerate()
        .with_max_len(1)
        .map(|(col, ((nx, sup), (wc, yc)))| {
            let leaving = |i: usize| sup[i] && wc[i] < th.leave_below;
            let band: Vec<usize> = (0..nf).filter(|&i| leaving(i)).collect();
            let d_edge = band_distance(a, &band, leaving, |i| !sup[i], nf);
            let d_kept = band_distance(a, &band, leaving, |i| sup[i] && !leaving(i), nf);
            let (mut negative, mut joined) = (0, 0);
            for i in 0..nf {
                if leaving(i) {
                    negative += 1;
                    let nb = a.symbolic().row_idx_of_col_raw(i);
                    let local_min = nb.iter().all(|&j| !sup[j] || wc[j] >= wc[i]);
                    if d_edge[i] <= d_kept[i] || local_min {
                        nx[i] = false;
                    }
                } else if !sup[i] && yc[i] < th.join_below {
                    joined += 1;
                    nx[i] |= joiner[i] == col;
                }
            }
            (negative, joined)
        })
        .collect();
    NextSupport {
        next,
        negative: per_column.iter().map(|c| c.0).sum(),
        joined: per_column.iter().map(|c| c.1).sum(),
    }
}

/// For each row, the off-support column whose multiplier is most negative below `join_below`
/// (`usize::MAX` where none is): the only entry of the row that joins this round.
///
/// Partition of unity couples a row's columns through its multiplier `mu_i`: where a row's
/// support is wrong, `mu_i` is off and `y_ij = (A w + g)_ij + mu_i` comes out negative in
/// most of its columns at once, though only a few of them belong to the optimal support. The
/// most negative one is the likeliest; joining them all overgrows the supports, and the next
/// rounds peel them off again at the cost of a larger factor each.
fn row_joiners(support: &[bool], y: &[f64], join_below: f64, nf: usize) -> Vec<usize> {
    let m = support.len() / nf.max(1);
    (0..nf)
        .into_par_iter()
        .with_min_len(1024)
        .map(|i| {
            let mut pick = (usize::MAX, join_below);
            for j in 0..m {
                let k = j * nf + i;
                if !support[k] && y[k] < pick.1 {
                    pick = (j, y[k]);
                }
            }
            pick.0
        })
        .collect()
}

/// Steps in the graph of `A` from the nearest vertex where `source` holds to each vertex of
/// `band` (where `in_band` holds), moving through `band` only; `usize::MAX` elsewhere and where
/// none is reachable.
///
/// A negative band's entries compare their distances to the support's edge and to its kept
/// part, each measured inside the support. Paths through the band alone give the same
/// comparison at a fraction of the cost (the band is a few entries of a support): a shortest
/// path from the kept part has only its source outside the band, and one from the edge that
/// crosses the kept part is longer than the distance from the kept part, as is its band-only
/// counterpart.
fn band_distance(
    a: &Csc,
    band: &[usize],
    in_band: impl Fn(usize) -> bool,
    source: impl Fn(usize) -> bool,
    n: usize,
) -> Vec<usize> {
    let mut d = vec![usize::MAX; n];
    let mut queue = std::collections::VecDeque::new();
    for &i in band {
        if a.symbolic()
            .row_idx_of_col_raw(i)
            .iter()
            .any(|&j| source(j))
        {
            d[i] = 1;
            queue.push_back(i);
        }
    }
    while let Some(i) = queue.pop_front() {
        for &j in a.symbolic().row_idx_of_col_raw(i) {
            if d[j] == usize::MAX && in_band(j) {
                d[j] = d[i] + 1;
                queue.push_back(j);
            }
        }
    }
    d
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sparse::path_matrix;

    #[test]
    fn band_distance_moves_through_the_band_only() {
        let a = path_matrix(6);
        let in_band = |i: usize| (1..=3).contains(&i);
        let band = [1, 2, 3];
        let none = usize::MAX;
        let d = band_distance(&a, &band, in_band, |i| i == 0, 6);
        assert_eq!(d, vec![none, 1, 2, 3, none, none]);
        let d = band_distance(&a, &band, in_band, |i| i == 4, 6);
        assert_eq!(d, vec![none, 3, 2, 1, none, none]);
        // Vertex 4 is neither in the band nor a source: 5 does not reach the band.
        let d = band_distance(&a, &band, in_band, |i| i == 5, 6);
        assert_eq!(d, vec![none; 6]);
    }

    #[test]
    fn only_the_outer_half_of_a_negative_band_leaves() {
        let a = path_matrix(14);
        // Support 0..=9, positive on 0..=5, a negative band 6..=9 deepening outwards.
        let support: Vec<bool> = (0..14).map(|i| i <= 9).collect();
        let w: Vec<f64> = (0..14)
            .map(|i| match i {
                0..=5 => 1.0 - 0.1 * i as f64,
                6..=9 => -0.1 * (i - 5) as f64,
                _ => 0.0,
            })
            .collect();
        let mut y = vec![0.0; 14];
        y[10] = -1.0; // wants to join
        y[11] = 0.5; // no violation: stays out
        let th = SignThresholds::new(1e-6, 1.0);
        let step = next_support(&a, &support, &w, &y, th, 14);
        assert_eq!((step.negative, step.joined), (4, 1));
        let kept: Vec<usize> = (0..14).filter(|&i| step.next[i]).collect();
        // 8 and 9 are no farther from the edge than from the positive part; 6 and 7 stay.
        assert_eq!(kept, vec![0, 1, 2, 3, 4, 5, 6, 7, 10]);
    }

    #[test]
    fn a_row_joins_only_its_most_negative_column() {
        // Two columns on a path of 4 vertices: column 0 holds row 0, column 1 holds row 3.
        let a = path_matrix(4);
        let support = vec![true, false, false, false, false, false, false, true];
        let w = vec![1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0];
        // Rows 1 and 2 violate in both columns: row 1 most in column 0, row 2 in column 1.
        let y = vec![0.0, -1.0, -0.2, 0.5, 0.4, -0.5, -3.0, 0.0];
        let th = SignThresholds::new(1e-6, 1.0);
        let none = usize::MAX;
        assert_eq!(
            row_joiners(&support, &y, th.join_below, 4),
            vec![none, 0, 1, none]
        );
        let step = next_support(&a, &support, &w, &y, th, 4);
        // Every violation counts (the KKT test), but each row takes one column.
        assert_eq!((step.negative, step.joined), (0, 4));
        assert_eq!(
            step.next,
            vec![true, true, false, false, false, false, true, true]
        );
    }
}
