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
//! The rows are swept run by run ([`SweepPlan`]): `A`'s rows are renumbered in
//! breadth-first order, cut into runs of consecutive rows, and the runs coloured so that no two
//! of one colour are coupled by `A`. Runs of one colour are swept in parallel, each in its own
//! row order, so the sweep is still Gauss-Seidel and gives the same result on any number of
//! threads. Breadth-first order keeps a row's neighbours near it in memory: colouring single
//! rows instead scatters each colour over the whole mesh, and its two threads then swept
//! hand-403 no faster than one thread in row order, the 85k armadillo 1.3x faster
//! (docs/solver.md's smoother row).

use std::ops::Range;

use rayon::prelude::*;

use crate::sparse::{greedy_colouring, Csc};

/// Rows per run of [`SweepPlan`]. Longer runs sweep a little faster, but each pass along one
/// propagates further in one direction: runs of 256 rows took the 7.7k armadillo of `bench
/// scale` 11 rounds against 7 (seeds 0-2, tol 1e-9), runs of 16-64 rows 7 (seed 0), as single
/// rows do.
const RUN_ROWS: usize = 64;

/// How the sweeps visit `A`'s rows (see the module docs): `A` renumbered in breadth-first
/// order (`order[p]` is the row at position `p`), its off-diagonal entries by row and its
/// diagonal, and runs of [`RUN_ROWS`] consecutive positions grouped by colour. The renumbered
/// copy of `A` takes 12 bytes an entry, less than `A` itself (and a few percent of `B_ff`'s
/// factor).
pub(super) struct SweepPlan {
    order: Vec<usize>,
    starts: Vec<usize>,
    /// Where a row's entries in its own run begin: its entries in other runs come first, so
    /// that a run's sweep reads each from its own buffer or the shared one without a branch.
    own_from: Vec<usize>,
    cols: Vec<u32>,
    vals: Vec<f64>,
    diag: Vec<f64>,
    colours: Vec<Vec<Range<usize>>>,
}

impl SweepPlan {
    pub fn new(a: &Csc) -> Self {
        let n = a.nrows();
        let order = breadth_first_order(a);
        let mut position = vec![0usize; n];
        for (p, &i) in order.iter().enumerate() {
            position[i] = p;
        }
        let (mut starts, mut own_from) = (vec![0], Vec::with_capacity(n));
        let (mut cols, mut vals) = (Vec::new(), Vec::new());
        let mut diag = vec![0.0; n];
        let mut own = Vec::new();
        for (p, &i) in order.iter().enumerate() {
            let nbrs = a.symbolic().row_idx_of_col_raw(i);
            own.clear();
            for (&k, &v) in nbrs.iter().zip(a.val_of_col(i)) {
                // Positions fit u32: a mesh of 4G vertices would not fit in memory anyway.
                let q = position[k] as u32;
                if k == i {
                    diag[p] += v;
                } else if position[k] / RUN_ROWS == p / RUN_ROWS {
                    own.push((q, v));
                } else {
                    cols.push(q);
                    vals.push(v);
                }
            }
            own_from.push(cols.len());
            cols.extend(own.iter().map(|e| e.0));
            vals.extend(own.iter().map(|e| e.1));
            starts.push(cols.len());
        }
        let runs: Vec<Range<usize>> = (0..n)
            .step_by(RUN_ROWS)
            .map(|s| s..(s + RUN_ROWS).min(n))
            .collect();
        let colours = colour_runs(runs, &starts, &cols);
        SweepPlan {
            order,
            starts,
            own_from,
            cols,
            vals,
            diag,
            colours,
        }
    }
}

/// `A`'s rows in breadth-first order, each connected component from the last row reached by
/// a search from its first row (a far row, so that the search's levels are narrow).
fn breadth_first_order(a: &Csc) -> Vec<usize> {
    let n = a.nrows();
    let mut seen = vec![false; n];
    let mut order = Vec::with_capacity(n);
    let mut scratch = vec![false; n];
    for root in 0..n {
        if seen[root] {
            continue;
        }
        let far = *breadth_first(a, root, &mut scratch).last().unwrap_or(&root);
        order.extend(breadth_first(a, far, &mut seen));
    }
    order
}

/// The rows reached from `root` in breadth-first order, marking them in `seen`.
fn breadth_first(a: &Csc, root: usize, seen: &mut [bool]) -> Vec<usize> {
    let mut queue = vec![root];
    seen[root] = true;
    let mut head = 0;
    while head < queue.len() {
        let i = queue[head];
        head += 1;
        for &k in a.symbolic().row_idx_of_col_raw(i) {
            if !seen[k] {
                seen[k] = true;
                queue.push(k);
            }
        }
    }
    queue
}

/// `runs` (run `r` the positions `r * RUN_ROWS..`) grouped by colour: a greedy colouring of the
/// runs in order ([`greedy_colouring`]), two runs coupled when an entry (`starts`, `cols`)
/// couples their rows.
fn colour_runs(runs: Vec<Range<usize>>, starts: &[usize], cols: &[u32]) -> Vec<Vec<Range<usize>>> {
    let (colour, count) = greedy_colouring(runs.len(), |r, visit| {
        let entries = starts[runs[r].start]..starts[runs[r].end];
        cols[entries]
            .iter()
            .for_each(|&k| visit(k as usize / RUN_ROWS));
    });
    let mut colours = vec![Vec::new(); count];
    for (run, c) in runs.into_iter().zip(colour) {
        colours[c].push(run);
    }
    colours
}

/// Columns a vector register holds (AVX2's four doubles).
const LANES: usize = 4;

/// Most registers [`accumulate`] holds for one block of columns.
const MAX_VECTORS: usize = 8;

/// `sweeps` Gauss-Seidel sweeps over the rows of `w`, run by run (see the module docs).
pub(super) fn gauss_seidel_pou(
    plan: &SweepPlan,
    g: &[f64],
    w: &[f64],
    nf: usize,
    m: usize,
    sweeps: usize,
) -> Vec<f64> {
    if m == 0 || nf == 0 {
        return w.to_vec();
    }
    // Row-major in the plan's order, so that a row's update reads its neighbours' rows and its
    // own row of G contiguously and nearby; each row padded with zeros to whole registers.
    let stride = m.next_multiple_of(LANES);
    let mut rows = gather_rows(w, &plan.order, m, stride);
    let g = gather_rows(g, &plan.order, m, stride);
    // One buffer per run, reused by every sweep.
    let mut bufs: Vec<Vec<Vec<f64>>> = plan
        .colours
        .iter()
        .map(|c| c.iter().map(|run| vec![0.0; run.len() * stride]).collect())
        .collect();
    let rows_of = |run: &Range<usize>| run.start * stride..run.end * stride;
    for _ in 0..sweeps {
        for (colour, bufs) in plan.colours.iter().zip(&mut bufs) {
            colour
                .par_iter()
                .zip(bufs.par_iter_mut())
                .for_each(|(run, own)| {
                    let pass = RunPass {
                        plan,
                        g: &g,
                        rows: &rows,
                        run: run.clone(),
                        m,
                        stride,
                    };
                    sweep_run(&pass, own)
                });
            for (run, own) in colour.iter().zip(bufs.iter()) {
                rows[rows_of(run)].copy_from_slice(own);
            }
        }
    }
    // Back to column-major in the original row order.
    let mut out = vec![0.0; nf * m];
    for (p, &i) in plan.order.iter().enumerate() {
        for j in 0..m {
            out[j * nf + i] = rows[p * stride + j];
        }
    }
    out
}

/// Row `order[p]` of the column-major `nrows x m` matrix `x` at `p * stride..`, each row
/// followed by `stride - m` zeros.
fn gather_rows(x: &[f64], order: &[usize], m: usize, stride: usize) -> Vec<f64> {
    let nrows = order.len();
    let mut rows = vec![0.0; nrows * stride];
    rows.par_chunks_mut(stride).zip(order).for_each(|(r, &i)| {
        r[..m]
            .iter_mut()
            .enumerate()
            .for_each(|(j, v)| *v = x[j * nrows + i]);
    });
    rows
}

/// One run's pass: the plan, `G` and the rows of the other runs (`rows`), each row `m`
/// weights padded to `stride`.
struct RunPass<'a> {
    plan: &'a SweepPlan,
    g: &'a [f64],
    rows: &'a [f64],
    run: Range<usize>,
    m: usize,
    stride: usize,
}

/// Into `own`: the rows of the run after one Gauss-Seidel pass over them in order, the other
/// rows held at `rows`: each row the simplex projection of `-(g_p + sum_{k != p} a_pk w_k) /
/// a_pp`, or kept when `a_pp` is not positive.
fn sweep_run(pass: &RunPass, own: &mut [f64]) {
    #[cfg(target_arch = "x86_64")]
    if crate::cpu::has_avx2() {
        // SAFETY: the CPU has AVX2 and FMA (checked at run time).
        return unsafe { sweep_run_avx2(pass, own) };
    }
    sweep_run_body(pass, own)
}

/// [`sweep_run_body`] compiled for AVX2: the same operations in the same order (no fused
/// multiply-adds), four doubles to a register instead of two.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn sweep_run_avx2(pass: &RunPass, own: &mut [f64]) {
    sweep_run_body(pass, own)
}

#[inline(always)]
fn sweep_run_body(pass: &RunPass, own: &mut [f64]) {
    let RunPass {
        plan,
        g,
        rows,
        ref run,
        m,
        stride,
    } = *pass;
    own.copy_from_slice(&rows[run.start * stride..run.end * stride]);
    let mut target = vec![0.0; stride];
    for p in run.clone() {
        let diag = plan.diag[p];
        if diag <= 0.0 {
            continue;
        }
        // Columns in blocks of up to MAX_VECTORS registers, each block's sums held in
        // registers across the row's entries.
        let row = RowInputs {
            plan,
            g,
            rows,
            own,
            p,
            run_start: run.start,
            stride,
        };
        let mut col = 0;
        while col < stride {
            let vectors = ((stride - col) / LANES).min(MAX_VECTORS);
            // Called, not taken as a function pointer, so that it inlines into the AVX2 body.
            let block = &mut target[col..col + vectors * LANES];
            match vectors {
                1 => accumulate::<1>(&row, col, block),
                2 => accumulate::<2>(&row, col, block),
                3 => accumulate::<3>(&row, col, block),
                4 => accumulate::<4>(&row, col, block),
                5 => accumulate::<5>(&row, col, block),
                6 => accumulate::<6>(&row, col, block),
                7 => accumulate::<7>(&row, col, block),
                _ => accumulate::<MAX_VECTORS>(&row, col, block),
            }
            col += vectors * LANES;
        }
        let target = &mut target[..m];
        target.iter_mut().for_each(|t| *t /= -diag);
        project_simplex(target);
        let at = (p - run.start) * stride;
        own[at..at + m].copy_from_slice(target);
    }
}

/// What row `p`'s update reads: its entries in the plan, `G`, the rows of other runs
/// (`rows`) and those of its own run (`own`, from position `run_start`), each `stride` long.
struct RowInputs<'a> {
    plan: &'a SweepPlan,
    g: &'a [f64],
    rows: &'a [f64],
    own: &'a [f64],
    p: usize,
    run_start: usize,
    stride: usize,
}

/// Columns `col..col + NV * LANES` of `g_p + sum_{k != p} a_pk w_k` into `target`, in the
/// plan's entry order. The sums stay in `NV` registers over all the row's entries; summing
/// into memory instead made each entry wait for the previous one's store.
#[inline(always)]
fn accumulate<const NV: usize>(row: &RowInputs, col: usize, target: &mut [f64]) {
    let (plan, p, stride) = (row.plan, row.p, row.stride);
    let block = |x: &[f64], at: usize| -> [[f64; LANES]; NV] {
        let x = &x[at + col..at + col + NV * LANES];
        std::array::from_fn(|l| std::array::from_fn(|q| x[l * LANES + q]))
    };
    let mut acc = block(row.g, p * stride);
    let mut add = |v: f64, wk: [[f64; LANES]; NV]| {
        for (a, w) in acc.iter_mut().zip(&wk) {
            for (a, w) in a.iter_mut().zip(w) {
                *a += v * w;
            }
        }
    };
    let (start, split, end) = (plan.starts[p], plan.own_from[p], plan.starts[p + 1]);
    for (&k, &v) in plan.cols[start..split].iter().zip(&plan.vals[start..split]) {
        add(v, block(row.rows, k as usize * stride));
    }
    for (&k, &v) in plan.cols[split..end].iter().zip(&plan.vals[split..end]) {
        add(v, block(row.own, (k as usize - row.run_start) * stride));
    }
    for (t, a) in target.chunks_exact_mut(LANES).zip(&acc) {
        t.copy_from_slice(a);
    }
}

/// Euclidean projection of `u` onto the simplex `{x >= 0, sum x = 1}`, in place: `x = max(u -
/// theta, 0)`, `theta` found by Michelot's (1986) iteration: the mean excess over 1 of the
/// entries above the last `theta`, from all of them, rises until that set stops shrinking
/// (at most `u.len()` passes; on a round's rows cheaper than sorting them, docs/solver.md).
#[inline(always)]
pub(super) fn project_simplex(u: &mut [f64]) {
    // Without a branch per entry: whether an entry is above `theta` is a coin toss the
    // processor mispredicts.
    let excess = |theta: f64| {
        // Four partial sums, one register: a single running sum waits on each addition.
        let (mut sum, mut count) = ([0.0; LANES], [0.0; LANES]);
        let mut add = |q: usize, x: f64| {
            let above = x > theta;
            sum[q] += if above { x } else { 0.0 };
            count[q] += if above { 1.0 } else { 0.0 };
        };
        let chunks = u.chunks_exact(LANES);
        let tail = chunks.remainder();
        for c in chunks {
            (0..LANES).for_each(|q| add(q, c[q]));
        }
        tail.iter().enumerate().for_each(|(q, &x)| add(q, x));
        let total = (sum[0] + sum[1]) + (sum[2] + sum[3]);
        (total - 1.0) / ((count[0] + count[1]) + (count[2] + count[3]))
    };
    let mut theta = excess(f64::NEG_INFINITY);
    loop {
        let next = excess(theta);
        // Not above: the set is stable (or a NaN entry made `next` NaN, which stops it too).
        if next.partial_cmp(&theta) != Some(std::cmp::Ordering::Greater) {
            break;
        }
        theta = next;
    }
    u.iter_mut().for_each(|x| *x = (*x - theta).max(0.0));
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn simplex_projection_is_the_nearest_point() {
        let mut u = vec![0.5, 0.2, -0.3, 0.9];
        project_simplex(&mut u);
        // theta = (0.9 + 0.5 - 1) / 2 = 0.2: (0.3, 0, 0, 0.7).
        let want = [0.3, 0.0, 0.0, 0.7];
        for (x, w) in u.iter().zip(want) {
            assert!((x - w).abs() < 1e-15, "{u:?}");
        }
        let mut inside = vec![0.25, 0.75];
        project_simplex(&mut inside);
        assert_eq!(inside, vec![0.25, 0.75]);
    }

    #[test]
    fn simplex_projection_meets_its_optimality_conditions() {
        // x = P(u) iff x is on the simplex and u - x is one constant `theta` on x's positive
        // entries and at least u on its zeros (u_i <= theta there).
        for len in 1..=25 {
            for trial in 0..40 {
                let u: Vec<f64> = (0..len)
                    .map(|i| 3.0 * (1.7 * (i * 31 + trial * 7 + len) as f64).sin() - 0.5)
                    .collect();
                let mut x = u.clone();
                project_simplex(&mut x);
                assert!(x.iter().all(|&v| v >= 0.0), "{u:?} -> {x:?}");
                assert!(
                    (x.iter().sum::<f64>() - 1.0).abs() < 1e-13,
                    "{u:?} -> {x:?}"
                );
                let top = (0..len).max_by(|&a, &b| x[a].total_cmp(&x[b])).unwrap();
                let theta = u[top] - x[top];
                for i in 0..len {
                    if x[i] > 0.0 {
                        assert!((u[i] - x[i] - theta).abs() < 1e-13, "{u:?} -> {x:?}");
                    } else {
                        assert!(u[i] <= theta + 1e-13, "{u:?} -> {x:?}");
                    }
                }
            }
        }
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
    fn runs_cover_every_row_once_and_never_couple_two_of_a_colour() {
        let a = nine_point_grid(40);
        let plan = SweepPlan::new(&a);
        let n = a.nrows();
        // The order is a permutation, and a breadth-first one: a row's neighbours lie within
        // two grid lines (80 positions) of it.
        let mut sorted = plan.order.clone();
        sorted.sort_unstable();
        assert_eq!(sorted, (0..n).collect::<Vec<_>>());
        let max_reach = (0..n)
            .flat_map(|p| {
                plan.cols[plan.starts[p]..plan.starts[p + 1]]
                    .iter()
                    .map(move |&k| (k as usize).abs_diff(p))
            })
            .max()
            .unwrap();
        assert!(max_reach <= 2 * 40 + 1, "{max_reach}");
        // 1,600 rows in runs of RUN_ROWS: more than one colour, more than one run per colour.
        assert!(
            plan.colours.len() > 1 && plan.colours.len() < 13,
            "{}",
            plan.colours.len()
        );
        let mut seen = vec![0; n];
        for colour in &plan.colours {
            let mut in_colour = vec![false; n];
            for run in colour {
                run.clone().for_each(|p| in_colour[p] = true);
            }
            for run in colour {
                for p in run.clone() {
                    seen[p] += 1;
                    for &k in &plan.cols[plan.starts[p]..plan.starts[p + 1]] {
                        let k = k as usize;
                        assert!(
                            run.contains(&k) || !in_colour[k],
                            "positions {p} and {k} in two runs of one colour"
                        );
                    }
                }
            }
        }
        assert!(seen.iter().all(|&s| s == 1));
    }

    #[test]
    fn sweeps_give_the_same_weights_on_one_thread_and_on_two() {
        let (k, m) = (40, 4);
        let a = nine_point_grid(k);
        let nf = k * k;
        let plan = SweepPlan::new(&a);
        let g: Vec<f64> = (0..nf * m).map(|i| (0.37 * i as f64).sin()).collect();
        let w = vec![1.0 / m as f64; nf * m];
        let run = |threads: usize| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap()
                .install(|| gauss_seidel_pou(&plan, &g, &w, nf, m, 5))
        };
        let one = run(1);
        assert_eq!(one, run(2));
        assert_ne!(one, w);
    }

    #[test]
    fn a_sweep_is_gauss_seidel_in_the_plans_order_for_any_number_of_columns() {
        // A row-by-row scalar sweep, colour by colour and run by run, against the blocked
        // sweep: m = 3 and 6 pad to whole registers, m = 37 takes two blocks of columns.
        let k = 20;
        let a = nine_point_grid(k);
        let nf = k * k;
        let plan = SweepPlan::new(&a);
        for m in [1, 3, 6, 37] {
            let g: Vec<f64> = (0..nf * m).map(|i| (0.37 * i as f64).sin()).collect();
            let w0: Vec<f64> = (0..nf * m).map(|i| (1.3 * i as f64).cos().abs()).collect();
            let w0 = crate::bbw::dual::project_pou(&w0, nf, m);
            let mut want = w0.clone();
            for colour in &plan.colours {
                for p in colour.iter().flat_map(|run| run.clone()) {
                    let i = plan.order[p];
                    let mut u: Vec<f64> = (0..m).map(|j| g[j * nf + i]).collect();
                    for (&q, &v) in plan.cols[plan.starts[p]..plan.starts[p + 1]]
                        .iter()
                        .zip(&plan.vals[plan.starts[p]..plan.starts[p + 1]])
                    {
                        let r = plan.order[q as usize];
                        u.iter_mut()
                            .enumerate()
                            .for_each(|(j, t)| *t += v * want[j * nf + r]);
                    }
                    u.iter_mut().for_each(|t| *t /= -plan.diag[p]);
                    project_simplex(&mut u);
                    (0..m).for_each(|j| want[j * nf + i] = u[j]);
                }
            }
            let got = gauss_seidel_pou(&plan, &g, &w0, nf, m, 1);
            let err = got
                .iter()
                .zip(&want)
                .map(|(x, y)| (x - y).abs())
                .fold(0.0, f64::max);
            assert!(err < 1e-14, "m = {m}: {err}");
        }
    }

    #[test]
    fn sweeps_descend_to_the_constrained_minimum() {
        let (nf, m) = (30, 3);
        let a = crate::sparse::path_matrix(nf);
        let g: Vec<f64> = (0..nf * m).map(|k| (0.7 * k as f64).sin()).collect();
        let plan = SweepPlan::new(&a);
        let mut w = vec![1.0 / m as f64; nf * m];
        let (mut last, _) = energy_and_gradient(&a, &g, &w, nf);
        for _ in 0..3000 {
            w = gauss_seidel_pou(&plan, &g, &w, nf, m, 1);
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
