//! Projected Gauss-Seidel on the partition-of-unity QP: the smoother of a round.
//!
//! Inputs: `A` (`nf x nf`, symmetric, positive diagonal), `G` and feasible weights `W`
//! (`nf x m`, column-major, rows on the simplex). Output: weights with rows on the simplex
//! whose energy `1/2 tr(W^T A W) + tr(G^T W)` is no higher.
//!
//! Row `i` of the QP (eq. 3 with partition of unity) with every other row held fixed is
//! `min a_ii/2 |x|^2 + x.(g_i + sum_{k != i} a_ik w_k)` over the simplex: the projection of
//! `-(g_i + sum_{k != i} a_ik w_k) / a_ii` onto the simplex. Sweeping the rows in turn is
//! nonlinear Gauss-Seidel, which never raises the energy; as the smoother of truncated
//! nonsmooth Newton multigrid (Graeser & Kornhuber 2009) it settles the zero set locally,
//! where a round's exact solve on a support guess corrects it globally.
//!
//! The rows are swept colour by colour ([`Colouring`]): rows of one colour are not coupled by
//! `A`, so their updates are independent and run in parallel, and the sweep is still
//! Gauss-Seidel (in the order of the colours), with the same result on any number of threads.

use rayon::prelude::*;

use crate::sparse::Csc;

/// A partition of `A`'s rows into classes of rows no two of which are coupled (`a_ik = 0`):
/// greedy colouring in row order, each row taking the smallest colour none of its neighbours
/// holds.
pub(super) struct Colouring {
    classes: Vec<Vec<usize>>,
}

impl Colouring {
    pub fn new(a: &Csc) -> Self {
        let n = a.nrows();
        let mut colour = vec![usize::MAX; n];
        // taken[c] == i: a neighbour of row i holds colour c.
        let mut taken: Vec<usize> = Vec::new();
        let mut classes: Vec<Vec<usize>> = Vec::new();
        for i in 0..n {
            for &k in a.symbolic().row_idx_of_col_raw(i) {
                if colour[k] != usize::MAX {
                    taken[colour[k]] = i;
                }
            }
            let c = (0..classes.len())
                .find(|&c| taken[c] != i)
                .unwrap_or(classes.len());
            if c == classes.len() {
                classes.push(Vec::new());
                taken.push(usize::MAX);
            }
            colour[i] = c;
            classes[c].push(i);
        }
        Colouring { classes }
    }
}

/// `sweeps` Gauss-Seidel sweeps over the rows of `w`, colour by colour (see the module docs).
pub(super) fn gauss_seidel_pou(
    a: &Csc,
    colouring: &Colouring,
    g: &[f64],
    w: &[f64],
    nf: usize,
    m: usize,
    sweeps: usize,
) -> Vec<f64> {
    if m == 0 || nf == 0 {
        return w.to_vec();
    }
    // Row-major, so that a row's update reads its neighbours' rows and its own row of G
    // contiguously.
    let mut rows = row_major(w, nf, m);
    let g = row_major(g, nf, m);
    let mut updates = Vec::new();
    for _ in 0..sweeps {
        for class in &colouring.classes {
            updates.resize(class.len() * m, 0.0);
            updates
                .par_chunks_mut(m)
                .zip(class.par_iter())
                .for_each_init(Vec::new, |scratch, (target, &i)| {
                    row_update(a, &g[i * m..(i + 1) * m], &rows, i, target, scratch);
                });
            for (&i, target) in class.iter().zip(updates.chunks(m)) {
                rows[i * m..(i + 1) * m].copy_from_slice(target);
            }
        }
    }
    // Back to column-major: `rows` is the column-major storage of the `m x nf` transpose.
    row_major(&rows, m, nf)
}

/// The column-major `nrows x ncols` matrix `x` stored row by row (which is the column-major
/// storage of its transpose).
fn row_major(x: &[f64], nrows: usize, ncols: usize) -> Vec<f64> {
    let mut rows = vec![0.0; nrows * ncols];
    rows.par_chunks_mut(ncols).enumerate().for_each(|(i, r)| {
        r.iter_mut()
            .enumerate()
            .for_each(|(j, v)| *v = x[j * nrows + i]);
    });
    rows
}

/// Row `i`'s minimiser with the other rows of `rows` fixed, into `target`, given its row
/// `g_i` of `G`; row `i` itself when `a_ii` is not positive.
fn row_update(
    a: &Csc,
    g_i: &[f64],
    rows: &[f64],
    i: usize,
    target: &mut [f64],
    scratch: &mut Vec<f64>,
) {
    let m = target.len();
    target.copy_from_slice(g_i);
    let mut diag = 0.0;
    let nbrs = a.symbolic().row_idx_of_col_raw(i);
    for (&k, &v) in nbrs.iter().zip(a.val_of_col(i)) {
        if k == i {
            diag = v;
            continue;
        }
        let wk = &rows[k * m..(k + 1) * m];
        target.iter_mut().zip(wk).for_each(|(t, x)| *t += v * x);
    }
    if diag <= 0.0 {
        target.copy_from_slice(&rows[i * m..(i + 1) * m]);
        return;
    }
    target.iter_mut().for_each(|t| *t /= -diag);
    project_simplex(target, scratch);
}

/// Euclidean projection of `u` onto the simplex `{x >= 0, sum x = 1}`, in place: `x = max(u -
/// theta, 0)` with `theta` found by sorting (Held, Wolfe & Crowder 1974). `scratch` is reused
/// across calls.
pub(super) fn project_simplex(u: &mut [f64], scratch: &mut Vec<f64>) {
    scratch.clear();
    scratch.extend_from_slice(u);
    scratch.sort_unstable_by(|a, b| b.total_cmp(a));
    let (mut sum, mut theta) = (0.0, 0.0);
    for (r, &x) in scratch.iter().enumerate() {
        sum += x;
        let t = (sum - 1.0) / (r + 1) as f64;
        if x - t > 0.0 {
            theta = t;
        } else {
            break;
        }
    }
    u.iter_mut().for_each(|x| *x = (*x - theta).max(0.0));
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn simplex_projection_is_the_nearest_point() {
        let mut scratch = Vec::new();
        let mut u = vec![0.5, 0.2, -0.3, 0.9];
        project_simplex(&mut u, &mut scratch);
        // theta = (0.9 + 0.5 - 1) / 2 = 0.2: (0.3, 0, 0, 0.7).
        let want = [0.3, 0.0, 0.0, 0.7];
        for (x, w) in u.iter().zip(want) {
            assert!((x - w).abs() < 1e-15, "{u:?}");
        }
        let mut inside = vec![0.25, 0.75];
        project_simplex(&mut inside, &mut scratch);
        assert_eq!(inside, vec![0.25, 0.75]);
    }

    /// `1/2 tr(W^T A W) + tr(G^T W)` and the gradient `A W + G`, column-major.
    fn energy_and_gradient(
        a: &crate::sparse::Csc,
        g: &[f64],
        w: &[f64],
        nf: usize,
    ) -> (f64, Vec<f64>) {
        let mut grad = g.to_vec();
        for (wc, gc) in w.chunks(nf).zip(grad.chunks_mut(nf)) {
            for (i, &x) in wc.iter().enumerate() {
                let rows = a.symbolic().row_idx_of_col_raw(i);
                for (&k, &v) in rows.iter().zip(a.val_of_col(i)) {
                    gc[k] += v * x;
                }
            }
        }
        let e = w
            .iter()
            .zip(g.iter().zip(&grad))
            .map(|(x, (g, d))| 0.5 * x * (d + g))
            .sum();
        (e, grad)
    }

    /// A `k x k` grid's rows coupled to their 8 neighbours (diagonally dominant).
    fn nine_point_grid(k: usize) -> crate::sparse::Csc {
        let mut t = Vec::new();
        for i in 0..k * k {
            for r in i / k..(i / k + 2).min(k) {
                for c in (i % k).saturating_sub(1)..(i % k + 2).min(k) {
                    let j = r * k + c;
                    if j > i {
                        t.push(faer::sparse::Triplet::new(i, j, -1.0));
                        t.push(faer::sparse::Triplet::new(j, i, -1.0));
                    }
                }
            }
            t.push(faer::sparse::Triplet::new(i, i, 9.0));
        }
        crate::sparse::from_triplets(k * k, k * k, &t).unwrap()
    }

    #[test]
    fn colours_cover_every_row_once_and_never_couple_two() {
        let a = crate::sparse::path_matrix(9);
        let classes = Colouring::new(&a).classes;
        // A path's rows alternate between two colours.
        assert_eq!(classes, vec![vec![0, 2, 4, 6, 8], vec![1, 3, 5, 7]]);
        let a = nine_point_grid(7);
        let classes = Colouring::new(&a).classes;
        // The 9-point stencil's rows in row order take 4 colours, 2 x 2 blocks of the grid.
        assert_eq!(classes.len(), 4);
        let mut seen = vec![0; a.nrows()];
        for class in &classes {
            for &i in class {
                seen[i] += 1;
                for &k in a.symbolic().row_idx_of_col_raw(i) {
                    assert!(
                        k == i || !class.contains(&k),
                        "rows {i} and {k} share a colour"
                    );
                }
            }
        }
        assert!(seen.iter().all(|&s| s == 1));
    }

    #[test]
    fn sweeps_descend_to_the_constrained_minimum() {
        let (nf, m) = (30, 3);
        let a = crate::sparse::path_matrix(nf);
        let g: Vec<f64> = (0..nf * m).map(|k| (0.7 * k as f64).sin()).collect();
        let colouring = Colouring::new(&a);
        let mut w = vec![1.0 / m as f64; nf * m];
        let (mut last, _) = energy_and_gradient(&a, &g, &w, nf);
        for _ in 0..3000 {
            w = gauss_seidel_pou(&a, &colouring, &g, &w, nf, m, 1);
            let (e, _) = energy_and_gradient(&a, &g, &w, nf);
            assert!(
                e <= last + 1e-13,
                "a sweep raised the energy: {last} -> {e}"
            );
            last = e;
        }
        // KKT of the simplex-constrained QP: per row, the gradient is smallest (= -mu_i) on
        // every positive entry and no smaller elsewhere.
        let (_, grad) = energy_and_gradient(&a, &g, &w, nf);
        for i in 0..nf {
            let row: Vec<(f64, f64)> = (0..m).map(|j| (w[j * nf + i], grad[j * nf + i])).collect();
            assert!((row.iter().map(|r| r.0).sum::<f64>() - 1.0).abs() < 1e-14);
            assert!(row.iter().all(|r| r.0 >= 0.0));
            let low = row.iter().map(|r| r.1).fold(f64::INFINITY, f64::min);
            for &(x, d) in &row {
                assert!(
                    d - low >= -1e-9 && (x == 0.0 || d - low < 1e-9),
                    "row {i}: {row:?}"
                );
            }
        }
    }
}
