//! The default BBW solver: a primal-dual active-set method on the eliminated QP.
//!
//! Inputs: an [`EliminatedProblem`] (`A = B_ff` factored once, `G`, `W0`) and [`BbwOptions`].
//! Output: the best certified feasible weights, written into [`Best`], and diagnostics.
//!
//! With partition of unity the KKT conditions of eq. 3 on the free rows are, per column `j`,
//!
//! ```text
//!   A w_j + g_j + mu - y_j = 0,   w_j >= 0,  y_j >= 0,  w_j o y_j = 0,   sum_j w_j = 1,
//! ```
//!
//! where `y_j` is the dual variable `Y` of eq. 12 and `mu` the multiplier of partition of unity
//! (so `Y P_m = A W + G`, eq. 15). Given a guess of each column's support `F_j` (`y_j = 0` there,
//! `w_j = 0` off it) the system is linear: `w_j = -A_{F_j F_j}^{-1} (g_j + mu)` on `F_j`, and
//! `mu` solves the `nf x nf` SPD system `S mu = rowsum(W(0)) - 1` with
//! `S = sum_j E_j A_{F_j F_j}^{-1} E_j^T`. `S` is never formed: conjugate gradients apply it
//! with one sparse Cholesky factor per column support, preconditioned by `A / m` (exact when
//! every support is the whole mesh, where `S = m A^{-1}`); on real rigs that takes 10-20
//! iterations per round, warm-started at the last round's `mu`, to a residual tied to the
//! last gap ([`GAP_POU`]). (A preconditioner averaging the support blocks instead is exact
//! for disjoint supports too, but `S` is a harmonic mean of them and it took 200-500.)
//! Entries of the support whose weight came out negative
//! leave it, entries off it whose multiplier `y` came out negative join it (damped and
//! dilated as [`next_support`] explains), and the round repeats until no sign is violated (the
//! KKT conditions then hold to round-off).
//!
//! The first support comes from a short run of the paper's L-BFGS on the dual (a duality gap of
//! `WARM_GAP`). Every round is certified like the L-BFGS iterates: the projected weights give
//! an upper bound on the optimal energy, the dual (eq. 12) at `y` made non-negative by
//! [`spread_negative`] a lower bound, and the solve stops once their relative gap is below
//! `tol`. Without partition of unity (App. A) the columns decouple and each one is a
//! box-constrained QP solved the same way with two bounds and no `mu`. Primal-dual active sets
//! are not guaranteed to converge when `A` is not an M-matrix (the biharmonic one is not): if
//! the gap stalls, L-BFGS warm-started from the last multipliers runs for at most
//! `INTERMISSION` iterations, then the rounds resume until neither of their own bounds moves
//! any more, and L-BFGS finishes.

use std::time::Instant;

use faer::linalg::solvers::Solve;
use faer::sparse::linalg::solvers::Llt;
use faer::sparse::SymbolicSparseColMat;
use faer::MatMut;
use rayon::prelude::*;

use super::dual::{box_eval, pou_eval, project_box, project_pou};
use super::problem::{cholesky, EliminatedProblem};
use super::solve::{blocks, random_start, run_lbfgs, BbwInfo, BbwOptions, Best};
use super::vector::dot;
use crate::error::{SkinError, SkinResult};
use crate::progress::{Event, Progress};
use crate::sparse::Csc;

/// Relative duality gap of the L-BFGS warm start that guesses the first support, and the
/// weight below which its entries are left out of that support. Rounds / L-BFGS iterations on
/// hand-403 at tol 1e-6: 1e-3 -> 15 / 90, 2e-3 -> 9 / 65, 3e-3 -> 9 / 50, 5e-3 -> 13 / 35,
/// 1e-2 -> 16 / 20 (the small fixtures change by +-2 rounds). With the round rules of
/// [`next_support`] and [`spread_negative`], 3e-3 -> 8 / 50 there and 8 / 110 on big2d; 6e-3
/// -> 23 / 75 and 11 / 90.
pub const WARM_GAP: f64 = 3e-3;
/// Loosest partition-of-unity residual accepted from CG at the end, relative to `tol`. Rows are
/// renormalised afterwards; on hand-403 1e-3 changed no support decision and cost an eighth more
/// CG iterations.
const POU_FLOOR: f64 = 1e-2;
/// Partition-of-unity residual accepted from CG, relative to `tol`, while KKT signs still flip
/// (once they hold, `POU_FLOOR` applies). Only the support decisions depend on it, and the
/// certificate is computed on the renormalised weights either way. CG iterations with
/// `POU_FLOOR` throughout / with this: hand-403 tol 1e-6 245 / 183 (9 rounds both), tol 1e-9
/// 522 / 429 (16 rounds both); big2d tol 1e-6 293 / 214 (13 rounds both). 3 saved more at
/// tol 1e-6 but cost hand-403 two rounds at 1e-9.
const SIGN_POU: f64 = 1.0;
/// Above `SIGN_POU * tol`, the partition-of-unity residual accepted from CG while signs flip
/// is this fraction of the last round's relative gap (and never rises): a decision that CG
/// noise of a tenth of the gap could flip does not move the bounds. Before, it fell tenfold
/// per round from 1e-4. CG iterations old / new at tol 1e-6: big2d 147 / 129, hand-403
/// 164 / 138, knight 144 / 99 (rounds unchanged); at tol 1e-9: big2d 437 / 288 (19 / 17
/// rounds), hand-403 386 / 283 (14 / 14), woody 173 / 156 (10 / 11).
const GAP_POU: f64 = 0.1;
/// A round whose gap fell by less than this factor crawls, and the next one dilates its joins
/// ([`next_support`]). It was 2 until one join per row ([`row_joiners`]) kept the supports
/// small; then, over seeds 0-6 at tol 1e-6, big2d took 63 rounds and 44.9 s in all with 2,
/// 52 and 39.3 s with 4, and 49 and 39.0 s when every round dilated. hand-403 took 12.1,
/// 12.4 and 13.0 s. Dilating every round from the start made hand-403 cycle before that
/// rule.
const CRAWL: f64 = 4.0;
/// Rounds after which a gap that has not halved counts as stalled.
const STALL_ROUNDS: usize = 12;
/// Hard cap on the rounds (each one is cheap; real rigs need 10-40).
const MAX_ROUNDS: usize = 300;

/// Cholesky factor of `A` restricted to one column's support `idx` (sorted free-row indices).
struct SupportFactor {
    idx: Vec<usize>,
    llt: Option<Llt<usize, f64>>,
}

impl SupportFactor {
    fn new(a: &Csc, idx: Vec<usize>) -> SkinResult<Self> {
        if idx.is_empty() {
            return Ok(SupportFactor { idx, llt: None });
        }
        let mut pos = vec![usize::MAX; a.nrows()];
        for (k, &i) in idx.iter().enumerate() {
            pos[i] = k;
        }
        // Only the lower triangle is read by the factorisation. `A`'s rows are sorted and `pos`
        // is increasing on `idx`, so the submatrix is built column by column in CSC order
        // (through triplets this was a quarter of the factor time on big2d).
        let k = idx.len();
        let (mut col_ptr, mut row_idx, mut val) = (Vec::with_capacity(k + 1), vec![], vec![]);
        col_ptr.push(0);
        for &j in &idx {
            let rows = a.symbolic().row_idx_of_col_raw(j);
            for (&i, &v) in rows.iter().zip(a.val_of_col(j)) {
                if i >= j && pos[i] != usize::MAX {
                    row_idx.push(pos[i]);
                    val.push(v);
                }
            }
            col_ptr.push(row_idx.len());
        }
        let sub = Csc::new(
            SymbolicSparseColMat::new_checked(k, k, col_ptr, None, row_idx),
            val,
        );
        // A principal submatrix of the SPD `A` is SPD, so this fails only on round-off.
        let llt = cholesky(&sub)
            .map_err(|e| SkinError::Numerical(format!("Cholesky of a support block: {e}")))?;
        Ok(SupportFactor {
            idx,
            llt: Some(llt),
        })
    }

    /// `A_FF^{-1} x[F]`, as a vector over `F`.
    fn solve_gathered(&self, x: &[f64]) -> Vec<f64> {
        let mut r: Vec<f64> = self.idx.iter().map(|&i| x[i]).collect();
        if let Some(llt) = &self.llt {
            let k = r.len();
            llt.solve_in_place(MatMut::from_column_major_slice_mut(&mut r, k, 1));
        }
        r
    }
}

/// Factors `A` on every column's support (`support[j * nf + i]`), in parallel over columns,
/// largest support first.
fn factor_supports(a: &Csc, support: &[bool], nf: usize) -> SkinResult<Vec<SupportFactor>> {
    let columns: Vec<&[bool]> = support.chunks(nf).collect();
    let sizes: Vec<usize> = columns
        .par_iter()
        .map(|col| col.iter().filter(|&&s| s).count())
        .collect();
    longest_first(&sizes, |j| {
        let idx = (0..nf).filter(|&i| columns[j][i]).collect();
        SupportFactor::new(a, idx)
    })
    .into_iter()
    .collect()
}

/// `[f(0), ..., f(n - 1)]`, computed on the rayon pool longest job first: each worker takes the
/// next index in decreasing `cost` (greedy list scheduling). The columns' supports differ in
/// size by 2-3x; rayon's even split of big2d's 8 columns over 2 threads left one idle for
/// 10-15 % of each round's factorisations.
fn longest_first<T: Send>(cost: &[usize], f: impl Fn(usize) -> T + Sync) -> Vec<T> {
    use std::sync::atomic::{AtomicUsize, Ordering};
    use std::sync::Mutex;
    let mut order: Vec<usize> = (0..cost.len()).collect();
    order.sort_by_key(|&i| std::cmp::Reverse(cost[i]));
    let next = AtomicUsize::new(0);
    let slots: Vec<Mutex<Option<T>>> = (0..cost.len()).map(|_| Mutex::new(None)).collect();
    let workers = rayon::current_num_threads().min(cost.len());
    rayon::scope(|s| {
        for _ in 0..workers {
            s.spawn(|_| {
                while let Some(&i) = order.get(next.fetch_add(1, Ordering::Relaxed)) {
                    let out = f(i);
                    if let Ok(mut slot) = slots[i].lock() {
                        *slot = Some(out);
                    }
                }
            });
        }
    });
    // The workers take every index once (a panic in `f` propagates out of the scope).
    slots
        .into_iter()
        .map(|s| {
            s.into_inner()
                .ok()
                .flatten()
                .expect("every index is computed")
        })
        .collect()
}

/// Runs the active-set solver (see the module docs), writing into `best` and `info`.
pub(crate) fn solve(
    prob: &EliminatedProblem,
    opts: &BbwOptions,
    best: &mut Best,
    info: &mut BbwInfo,
    progress: &mut dyn Progress,
) -> SkinResult<()> {
    solve_with_stall(prob, opts, STALL_ROUNDS, best, info, progress)
}

/// [`solve`] with the stall window of the first rounds as a parameter (tests force the
/// L-BFGS hand-over with a window of 0).
fn solve_with_stall(
    prob: &EliminatedProblem,
    opts: &BbwOptions,
    stall_rounds: usize,
    best: &mut Best,
    info: &mut BbwInfo,
    progress: &mut dyn Progress,
) -> SkinResult<()> {
    let (nf, m) = (prob.nf(), prob.m);
    let t = Instant::now();
    let start = random_start(nf, m, blocks(opts), opts.seed);
    let warm = WARM_GAP.max(opts.tol);
    run_lbfgs(prob, opts, warm, start, best, info, progress)?;
    info.time_lbfgs = t.elapsed().as_secs_f64();
    if best.relative_gap() <= opts.tol {
        return Ok(());
    }
    let t = Instant::now();
    // The warm start's projected weights name the first support.
    let w = best.w.clone();
    if !opts.partition_of_unity {
        let outcome = box_rounds(prob, opts, &w, best, info, progress)?;
        info.time_active_set = t.elapsed().as_secs_f64();
        if let Outcome::Stalled(y) = outcome {
            fallback_lbfgs(prob, opts, opts.max_iter, &y, best, info, progress)?;
        }
        return Ok(());
    }
    let mut state = PouState::from_warm_start(&w, nf, m);
    let watch = Watch::Gap(stall_rounds);
    let mut outcome = pou_rounds(prob, opts, &mut state, watch, best, info, progress)?;
    info.time_active_set = t.elapsed().as_secs_f64();
    if let Outcome::Stalled(y) = outcome {
        // The rounds cycle or their lower bound lags (before `spread_negative`, big2d's rounds
        // stalled at a gap of 7e-4 with the upper bound within 1e-6; now none of the fixtures
        // comes here). A short L-BFGS intermission from their multipliers lifts the lower
        // bound; if that does not close the gap the rounds resume (their upper bound still
        // falls, where L-BFGS alone crawls for minutes).
        fallback_lbfgs(prob, opts, INTERMISSION, &y, best, info, progress)?;
        if best.relative_gap() <= opts.tol {
            return Ok(());
        }
        let t = Instant::now();
        outcome = pou_rounds(prob, opts, &mut state, Watch::Bounds, best, info, progress)?;
        info.time_active_set += t.elapsed().as_secs_f64();
        if let Outcome::Stalled(y) = outcome {
            fallback_lbfgs(prob, opts, opts.max_iter, &y, best, info, progress)?;
        }
    }
    Ok(())
}

/// L-BFGS iterations of the first fallback before the rounds resume (big2d with clamped
/// multipliers: 35-80 lifted the lower bound from a gap of 7e-4 to 1e-6).
const INTERMISSION: usize = 150;

/// L-BFGS on the dual (at most `max_iter` iterations) warm-started from multipliers `y`.
fn fallback_lbfgs(
    prob: &EliminatedProblem,
    opts: &BbwOptions,
    max_iter: usize,
    y: &[f64],
    best: &mut Best,
    info: &mut BbwInfo,
    progress: &mut dyn Progress,
) -> SkinResult<()> {
    // Adding a constant to every entry leaves W(Y) unchanged (P_m removes row means) and
    // moves every entry off 0, where the squared parameterisation has no gradient.
    let delta = 1e-9 * y.iter().copied().fold(0.0, f64::max) + 1e-300;
    let u: Vec<f64> = y.iter().map(|v| (v + delta).sqrt()).collect();
    info.fallbacks += 1;
    let capped = BbwOptions {
        max_iter: max_iter.min(opts.max_iter),
        ..opts.clone()
    };
    let t = Instant::now();
    run_lbfgs(prob, &capped, opts.tol, u, best, info, progress)?;
    info.time_lbfgs += t.elapsed().as_secs_f64();
    Ok(())
}

enum Outcome {
    Done,
    /// The gap stopped shrinking; carries the last dual variables (`Y`, or `(Y, U)` stacked)
    /// for the fallback.
    Stalled(Vec<f64>),
}

/// Tracks whether the certified gap still shrinks.
struct StallWatch {
    best_gap: f64,
    since: usize,
}

impl StallWatch {
    fn stalled(&mut self, gap: f64, window: usize) -> bool {
        if gap < 0.5 * self.best_gap {
            self.best_gap = gap;
            self.since = 0;
        } else {
            self.since += 1;
        }
        self.since >= window
    }
}

/// When the partition-of-unity rounds hand over to L-BFGS.
#[derive(Clone, Copy)]
enum Watch {
    /// The certified gap has not halved in this many rounds.
    Gap(usize),
    /// Neither of the rounds' own bounds improved on its best by `tol / 2` (relative) in each of
    /// two rounds ([`OwnBounds`]).
    /// Their lower bound keeps rising after the weights have settled (big2d: by 1e-6..1e-5 per
    /// round up to round 50), and more rounds beat L-BFGS's crawl there.
    Bounds,
}

/// The best upper and lower bound the rounds have found themselves, and for how many rounds in
/// a row neither has improved by more than a relative step.
struct OwnBounds {
    upper: f64,
    lower: f64,
    quiet: usize,
}

impl OwnBounds {
    fn new() -> Self {
        OwnBounds {
            upper: f64::INFINITY,
            lower: f64::NEG_INFINITY,
            quiet: 0,
        }
    }

    /// Records a round's bounds; returns the number of quiet rounds so far. Bounds are compared
    /// with the best so far, so bounds that oscillate (a cycling support) count as quiet
    /// instead of keeping the rounds alive until `MAX_ROUNDS`.
    fn quiet_rounds(&mut self, upper: f64, lower: f64, step: f64) -> usize {
        let size = upper.abs().max(1e-300);
        let moved = (self.upper - upper).max(lower - self.lower) / size;
        self.upper = self.upper.min(upper);
        self.lower = self.lower.max(lower);
        self.quiet = if moved < step { self.quiet + 1 } else { 0 };
        self.quiet
    }
}

/// The rounds' state, kept across an L-BFGS intermission: the support guess
/// (`support[j * nf + i]`), the partition-of-unity multiplier, the CG tolerance and what
/// decides the dilation of joins ([`next_support`]).
struct PouState {
    support: Vec<bool>,
    mu: Vec<f64>,
    pou_tol: f64,
    dilation: Dilation,
}

/// The last round's own bounds, whether its joins were dilated, and whether dilation is still
/// allowed.
#[derive(Clone, Copy)]
struct Dilation {
    allowed: bool,
    last_dilated: bool,
    last_gap: f64,
    last_upper: f64,
}

impl PouState {
    fn from_warm_start(w: &[f64], nf: usize, m: usize) -> Self {
        // The warm start is only accurate to its gap: weights below WARM_GAP are mostly the
        // smooth tails of W(Y) (eq. 15) over regions that are zero at the optimum. Leaving them
        // out of the first support saves rounds (hand-403: 9 instead of 18).
        let mut support: Vec<bool> = w.iter().map(|&x| x > WARM_GAP).collect();
        for i in 0..nf {
            // Every row needs a support entry; its largest weight is the safest.
            let jmax = (0..m)
                .max_by(|&a, &b| w[a * nf + i].total_cmp(&w[b * nf + i]))
                .unwrap_or(0);
            support[jmax * nf + i] = true;
        }
        // Partition-of-unity residual accepted from CG: loose while the support is still wrong.
        PouState {
            support,
            mu: vec![0.0; nf],
            pou_tol: 1e-4,
            dilation: Dilation {
                allowed: true,
                last_dilated: false,
                last_gap: f64::INFINITY,
                last_upper: f64::INFINITY,
            },
        }
    }
}

/// Rounds of the partition-of-unity active-set method from `state`, until the gap is below
/// `tol`, the KKT signs hold, or `watch` says the rounds have stopped paying.
fn pou_rounds(
    prob: &EliminatedProblem,
    opts: &BbwOptions,
    state: &mut PouState,
    watch: Watch,
    best: &mut Best,
    info: &mut BbwInfo,
    progress: &mut dyn Progress,
) -> SkinResult<Outcome> {
    let (nf, m) = (prob.nf(), prob.m);
    let mut gap_watch = StallWatch {
        best_gap: best.relative_gap(),
        since: 0,
    };
    let mut own_bounds = OwnBounds::new();
    let budget = opts.max_iter.min(MAX_ROUNDS).saturating_sub(info.rounds);
    for _ in 0..budget {
        let round = info.rounds;
        info.rounds += 1;
        let PouState {
            support,
            mu,
            pou_tol,
            dilation,
        } = &mut *state;
        let t = Instant::now();
        let factors = factor_supports(&prob.a, support, nf)?;
        info.time_support_factor += t.elapsed().as_secs_f64();
        let sizes: Vec<usize> = factors.iter().map(|f| f.idx.len()).collect();
        let weights = |mu: &[f64]| -> Vec<f64> {
            let cols = longest_first(&sizes, |j| {
                let gj = &prob.g[j * nf..(j + 1) * nf];
                let rhs: Vec<f64> = gj.iter().zip(mu).map(|(g, u)| g + u).collect();
                factors[j].solve_gathered(&rhs)
            });
            let mut w = vec![0.0; nf * m];
            for (j, (f, col)) in factors.iter().zip(&cols).enumerate() {
                for (&i, &v) in f.idx.iter().zip(col) {
                    w[j * nf + i] = -v;
                }
            }
            w
        };
        // `S x` and, per column, `A_FF^{-1} x[F]`.
        let apply_s = |x: &[f64]| -> (Vec<f64>, Vec<Vec<f64>>) {
            let cols = longest_first(&sizes, |j| factors[j].solve_gathered(x));
            let mut out = vec![0.0; nf];
            for (f, col) in factors.iter().zip(&cols) {
                for (&i, &v) in f.idx.iter().zip(col) {
                    out[i] += v;
                }
            }
            (out, cols)
        };
        // S delta = rowsum(W(mu)) - 1, warm-started at the previous round's mu. W is linear in
        // mu, so W(mu + delta) = W(mu) - sum_k alpha_k A_FF^{-1} p_k is accumulated from the
        // solves CG makes anyway (recomputing it cost one more solve per column).
        let mut w = weights(mu);
        let residual = row_sums_minus_one(&w, nf, m);
        let t = Instant::now();
        let step = |alpha: f64, cols: &Vec<Vec<f64>>| {
            w.par_chunks_mut(nf)
                .zip(factors.par_iter().zip(cols))
                .for_each(|(wc, (f, col))| {
                    for (&i, &v) in f.idx.iter().zip(col) {
                        wc[i] -= alpha * v;
                    }
                });
        };
        let (delta, iters) = pcg(prob, apply_s, step, &residual, *pou_tol, progress)?;
        info.time_cg += t.elapsed().as_secs_f64();
        info.cg_iterations += iters;
        mu.iter_mut().zip(&delta).for_each(|(u, d)| *u += d);

        // Multipliers y = A w + g + mu on the zero set (eq. 15 read backwards).
        let aw = prob.apply_a(&w);
        let mut y = vec![0.0; nf * m];
        let mut scale: f64 = 1.0;
        for k in 0..nf * m {
            let grad = aw[k] + prob.g[k];
            scale = scale.max(grad.abs());
            if !support[k] {
                y[k] = grad + mu[k % nf];
            }
        }
        // Certificate: projected w (upper bound), dual at y spread to >= 0 (lower bound).
        let feasible = project_pou(&w, nf, m);
        let upper = prob.energy(&feasible);
        best.offer(&w, feasible, upper);
        // The dual's own recovered W(Y) is not offered as a primal candidate: it is
        // smooth but nowhere exactly zero, and once projected can win on energy by a hair
        // while sitting 1e-4 off the optimum in flat directions.
        let mut y_plus = y.clone();
        spread_negative(&mut y_plus, &prob.a, nf);
        let own = pou_eval(prob, &y_plus);
        let own_lower = own.lower_bound;
        let own_gap = (upper - own_lower) / upper.abs().max(1e-300);
        best.bound(&own);
        progress.report(Event {
            stage: "active-set",
            iteration: round,
            value: best.relative_gap(),
        })?;
        // Certified: the next support (two graph searches per column) is not needed.
        if best.relative_gap() <= opts.tol {
            return Ok(Outcome::Done);
        }
        // A gap that fell by less than a factor CRAWL in a round means the supports' edges
        // crawl: the joins then bring their neighbourhoods along. If a dilated round raised
        // the upper bound, dilation overshoots on this problem (it made the knight cycle):
        // never again.
        if dilation.last_dilated && upper > dilation.last_upper {
            dilation.allowed = false;
        }
        let dilate = dilation.allowed && own_gap > dilation.last_gap / CRAWL;
        dilation.last_dilated = dilate;
        dilation.last_gap = own_gap;
        dilation.last_upper = upper;
        let thresholds = SignThresholds::new(opts.tol, scale);
        let (next, n_w, n_y) = next_support(&prob.a, support, &w, &y, thresholds, dilate, nf);
        let exact = n_w == 0 && n_y == 0;
        if exact && *pou_tol <= POU_FLOOR * opts.tol {
            // Every KKT sign holds and PoU to round-off: this is the optimum; the gap is as
            // small as floating point allows.
            return Ok(Outcome::Done);
        }
        // The rounds' own bounds (best may hold an L-BFGS point from the intermission).
        let quiet = own_bounds.quiet_rounds(upper, own_lower, 0.5 * opts.tol);
        let stalled = match watch {
            Watch::Gap(window) => gap_watch.stalled(best.relative_gap(), window),
            Watch::Bounds => quiet >= 2,
        };
        if stalled {
            return Ok(Outcome::Stalled(y_plus));
        }
        // Rows are renormalised at the end, so a PoU residual far below tol changes nothing;
        // while signs still flip, one of a tenth of the gap, down to SIGN_POU * tol, decides
        // them as well.
        *pou_tol = if exact {
            POU_FLOOR * opts.tol
        } else {
            (GAP_POU * own_gap).max(SIGN_POU * opts.tol).min(*pou_tol)
        }
        .max(1e-13);
        *support = next;
    }
    Ok(Outcome::Done)
}

/// Makes the multipliers `y` (`nf x m`) non-negative, for the dual lower bound, by moving each
/// negative entry's mass onto the nearest positive entries of its column, ring by ring of the
/// graph of `A`.
///
/// Any `Y >= 0` gives a lower bound, and its gap to `y`'s (tight but infeasible) Lagrangian is
/// `1/2 <D, A^{-1} D P_m>` with `D = Y - y`. `A^{-1}` is a smoothing operator (the biharmonic
/// Green's function), so clamping, whose `D` is a positive bump of every negative entry, loses
/// a lot, and a `D` that is locally zero-sum almost nothing. On big2d at tol 1e-6 after 12
/// rounds: relative gap 6.6e-4 clamped, 1.0e-6 spread. The first-order term `<D, w>` is zero
/// either way (`y` is only non-zero off the support, where `w = 0`).
///
/// Entries above `-NOISE max |y|` are round-off on the optimum's weakly active zeros (where
/// `y* = 0` too) and are clamped: on big2d 60-70k of each round's ~90k negative entries, whose
/// ring searches took most of the 40-80 ms this spent per round (now 10-35 ms); the lower
/// bounds moved by 1e-13 relative.
fn spread_negative(y: &mut [f64], a: &Csc, nf: usize) {
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
            stamp[k] = k;
            ring.clear();
            ring.push(k);
            for _ in 0..REACH {
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

/// The sign tests of a round. Weights and multipliers below these in magnitude are CG and
/// round-off noise: testing them against 0 (as before) flipped ~20k such entries per round on
/// big2d and doubled the supports, without changing the bounds.
#[derive(Clone, Copy)]
struct SignThresholds {
    /// A support entry whose weight is below this leaves.
    leave_below: f64,
    /// An off-support entry whose multiplier is below this joins.
    join_below: f64,
}

impl SignThresholds {
    fn new(tol: f64, scale: f64) -> Self {
        SignThresholds {
            leave_below: 1e-3 * tol,
            join_below: -0.1 * tol * scale,
        }
    }
}

/// The next support guess from a round's weights `w` and multipliers `y` (all `nf x m`):
/// returns it with the numbers of sign violations: support entries below `leave_below` (not
/// all of which leave) and off-support entries below `join_below` (at most one per row joins,
/// below).
///
/// Two rules keep the supports' edges from crawling, as plain primal-dual active sets do on
/// the biharmonic operator (not an M-matrix; on big2d they took 15 rounds at tol 1e-6), and a
/// third keeps the supports from overgrowing:
/// - A support that reaches too far overshoots: its weights dip negative over a band wider than
///   the excess, and dropping the whole band cuts into the optimal support, which then creeps
///   back one neighbourhood per round. So only the outer half of a negative band leaves (entries
///   no farther, in steps of the graph of `A`, from the support's edge than from its
///   non-negative part), plus the most negative entry of each neighbourhood, which opens holes.
///   big2d: 15 -> 12 rounds; hand-403 unchanged at 8.
/// - A support that falls short only sees negative multipliers right at its edge, so it grows by
///   one neighbourhood per round. When `dilate` (the rounds crawl, [`CRAWL`]), the off-support
///   neighbours of each joining entry whose multiplier is below the joiner's violation join
///   too. big2d: 12 -> 8 rounds. Always dilating made hand-403 cycle, hence the switch.
/// - A row joins one column per round: the one whose multiplier is most negative
///   ([`row_joiners`]).
fn next_support(
    a: &Csc,
    support: &[bool],
    w: &[f64],
    y: &[f64],
    th: SignThresholds,
    dilate: bool,
    nf: usize,
) -> (Vec<bool>, usize, usize) {
    let mut next = support.to_vec();
    let joiner = row_joiners(support, y, th.join_below, nf);
    let counts: Vec<(usize, usize)> = next
        .par_chunks_mut(nf)
        .zip(support.par_chunks(nf))
        .zip(w.par_chunks(nf).zip(y.par_chunks(nf)))
        .enumerate()
        .with_max_len(1)
        .map(|(col, ((nx, sup), (wc, yc)))| {
            let leaving = |i: usize| sup[i] && wc[i] < th.leave_below;
            let d_edge = graph_distance(a, sup, |i| !sup[i]);
            let d_kept = graph_distance(a, sup, |i| sup[i] && !leaving(i));
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
                    if joiner[i] != col {
                        continue;
                    }
                    nx[i] = true;
                    if dilate {
                        for &j in a.symbolic().row_idx_of_col_raw(i) {
                            if !sup[j] && yc[j] < -yc[i] {
                                nx[j] = true;
                            }
                        }
                    }
                }
            }
            (negative, joined)
        })
        .collect();
    let (n_w, n_y) = counts.iter().fold((0, 0), |(a, b), &(l, j)| (a + l, b + j));
    (next, n_w, n_y)
}

/// For each row, the off-support column whose multiplier is most negative below `join_below`
/// (`usize::MAX` where none is): the only entry of the row that joins this round.
///
/// Partition of unity couples a row's columns through its multiplier `mu_i`: where a row's
/// support is wrong, `mu_i` is off and `y_ij = (A w + g)_ij + mu_i` comes out negative in
/// most of its columns at once. On hand-403 at seed 6 (traced with dilation off), 1,000-1,900
/// rows per round had 5-19 columns with `y < 0`, only a tenth of those columns belong to the
/// optimal support (weight above 1e-7), and the most negative one is a right one 43-69 % of
/// the time (the second most negative 12-17 %). Joining them all grew the supports to
/// 50-60k entries against 29k weights above 1e-7 at the optimum, and the next ten rounds
/// peeled them off again; joining one per row keeps them at 22-38k, which makes every round
/// cheaper, for about as many rounds. Seeds 0-6 at tol 1e-6: hand-403 16.96 -> 12.56 s in
/// all (72 -> 78 rounds), big2d 52.3 -> 47.0 s (68 -> 65 rounds). Letting two or four join
/// per row, or every column within a factor of 0.5 or 0.8 of the row's most negative, fell
/// in between.
///
/// The neighbours a dilated join brings along ([`next_support`]) are not limited per row:
/// limiting them to rows whose own choice is the same column cost big2d 5 more rounds and 6 %
/// more time over seeds 0-6.
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

/// Steps in the graph of `A`, moving only through `inside` vertices, from the nearest vertex
/// where `source` holds (`usize::MAX` where none is reachable).
fn graph_distance(a: &Csc, inside: &[bool], source: impl Fn(usize) -> bool) -> Vec<usize> {
    let n = inside.len();
    let mut d = vec![usize::MAX; n];
    let mut queue = std::collections::VecDeque::new();
    for i in (0..n).filter(|&i| source(i)) {
        d[i] = 0;
        queue.push_back(i);
    }
    while let Some(i) = queue.pop_front() {
        for &j in a.symbolic().row_idx_of_col_raw(i) {
            if inside[j] && d[j] == usize::MAX {
                d[j] = d[i] + 1;
                queue.push_back(j);
            }
        }
    }
    d
}

/// `rowsum(W) - 1` for the `nf x m` column-major `w`.
fn row_sums_minus_one(w: &[f64], nf: usize, m: usize) -> Vec<f64> {
    let mut r = vec![-1.0; nf];
    for col in w.chunks(nf).take(m) {
        r.iter_mut().zip(col).for_each(|(ri, wi)| *ri += wi);
    }
    r
}

/// Preconditioned conjugate gradients for `S x = b` from `x = 0`, preconditioner `A / m`; stops
/// when `max |b - S x| <= tol` (a partition-of-unity violation, so an absolute weight error).
/// `apply_s(p)` returns `S p` and what its caller keeps of the product (`T`), handed back as
/// `step(alpha, &T)` when `x` moves by `alpha p`.
fn pcg<T>(
    prob: &EliminatedProblem,
    apply_s: impl Fn(&[f64]) -> (Vec<f64>, T),
    mut step: impl FnMut(f64, &T),
    b: &[f64],
    tol: f64,
    progress: &mut dyn Progress,
) -> SkinResult<(Vec<f64>, usize)> {
    let n = b.len();
    // Scaling a preconditioner does not change CG's iterates; `A / m` keeps `z` at the scale
    // of `x`.
    let inv_m = 1.0 / prob.m as f64;
    let precondition = |r: &[f64]| -> Vec<f64> {
        let mut z = prob.apply_a(r);
        z.iter_mut().for_each(|v| *v *= inv_m);
        z
    };
    let max_abs = |v: &[f64]| v.iter().fold(0.0f64, |a, x| a.max(x.abs()));
    let mut x = vec![0.0; n];
    let mut r = b.to_vec();
    if max_abs(&r) <= tol {
        return Ok((x, 0));
    }
    let mut z = precondition(&r);
    let mut p = z.clone();
    let mut rz = dot(&r, &z);
    // CG on an SPD system of size n converges in n steps in exact arithmetic; far fewer here.
    for it in 1..=n.max(1) {
        let (q, aux) = apply_s(&p);
        let pq = dot(&p, &q);
        if pq.is_nan() || pq <= 0.0 {
            return Ok((x, it)); // round-off has taken over: keep what we have
        }
        let alpha = rz / pq;
        x.iter_mut().zip(&p).for_each(|(xi, pi)| *xi += alpha * pi);
        step(alpha, &aux);
        r.iter_mut().zip(&q).for_each(|(ri, qi)| *ri -= alpha * qi);
        progress.report(Event {
            stage: "active-set cg",
            iteration: it,
            value: max_abs(&r),
        })?;
        if max_abs(&r) <= tol {
            return Ok((x, it));
        }
        z = precondition(&r);
        let rz_new = dot(&r, &z);
        let beta = rz_new / rz;
        rz = rz_new;
        p.iter_mut()
            .zip(&z)
            .for_each(|(pi, zi)| *pi = zi + beta * *pi);
    }
    Ok((x, n))
}

/// Rounds of the box-constrained active-set method (no partition of unity, App. A): each column
/// is an independent QP with `0 <= w_j <= 1`, solved exactly on its free set.
fn box_rounds(
    prob: &EliminatedProblem,
    opts: &BbwOptions,
    w: &[f64],
    best: &mut Best,
    info: &mut BbwInfo,
    progress: &mut dyn Progress,
) -> SkinResult<Outcome> {
    let (nf, m) = (prob.nf(), prob.m);
    // state: 0 free, 1 at the lower bound, 2 at the upper bound.
    let mut state: Vec<u8> = w
        .iter()
        .map(|&x| {
            if x <= 0.0 {
                1
            } else if x >= 1.0 {
                2
            } else {
                0
            }
        })
        .collect();
    let mut watch = StallWatch {
        best_gap: best.relative_gap(),
        since: 0,
    };
    for round in 0..opts.max_iter.min(MAX_ROUNDS) {
        info.rounds += 1;
        let free: Vec<bool> = state.iter().map(|&s| s == 0).collect();
        let t = Instant::now();
        let factors = factor_supports(&prob.a, &free, nf)?;
        info.time_support_factor += t.elapsed().as_secs_f64();
        // w_j: 1 on the upper set, A_FF^{-1}(-g - A_FU 1) on the free set, 0 elsewhere.
        let upper_ind: Vec<f64> = state.iter().map(|&s| f64::from(s == 2)).collect();
        let a_upper = prob.apply_a(&upper_ind);
        let cols: Vec<Vec<f64>> = factors
            .par_iter()
            .enumerate()
            .map(|(j, f)| {
                let rhs: Vec<f64> = (0..nf)
                    .map(|i| -prob.g[j * nf + i] - a_upper[j * nf + i])
                    .collect();
                f.solve_gathered(&rhs)
            })
            .collect();
        let mut w = upper_ind;
        for (j, (f, col)) in factors.iter().zip(&cols).enumerate() {
            for (&i, &v) in f.idx.iter().zip(col) {
                w[j * nf + i] = v;
            }
        }
        let aw = prob.apply_a(&w);
        let mut y = vec![0.0; nf * m]; // multipliers of w >= 0
        let mut u = vec![0.0; nf * m]; // multipliers of w <= 1
        let mut scale: f64 = 1.0;
        let mut changes = 0usize;
        for k in 0..nf * m {
            let grad = aw[k] + prob.g[k];
            scale = scale.max(grad.abs());
            match state[k] {
                1 => y[k] = grad,
                2 => u[k] = -grad,
                _ => {}
            }
        }
        for k in 0..nf * m {
            let new = match state[k] {
                0 if w[k] < -1e-12 => 1,
                0 if w[k] > 1.0 + 1e-12 => 2,
                1 | 2 if y[k] < -1e-12 * scale || u[k] < -1e-12 * scale => 0,
                s => s,
            };
            if new != state[k] {
                changes += 1;
                state[k] = new;
            }
        }
        let feasible = project_box(&w);
        let upper = prob.energy(&feasible);
        best.offer(&w, feasible, upper);
        // Spread, not clamped (see `spread_negative`): knight at tol 1e-9 then reaches the exact
        // optimum in its rounds alone (63 rounds, 2.8 s); clamped, its gap stalled and an
        // L-BFGS fallback of 580 iterations finished it (32 rounds, 3.0 s).
        spread_negative(&mut y, &prob.a, nf);
        spread_negative(&mut u, &prob.a, nf);
        best.bound(&box_eval(prob, &y, &u));
        progress.report(Event {
            stage: "active-set",
            iteration: round,
            value: best.relative_gap(),
        })?;
        // The columns are cheap to solve exactly, so iterate to the exact optimum: a small gap
        // alone does not pin down weights where the energy is flat.
        if changes == 0 {
            return Ok(Outcome::Done);
        }
        if watch.stalled(best.relative_gap(), STALL_ROUNDS) {
            if best.relative_gap() <= opts.tol {
                return Ok(Outcome::Done); // certified; the last swaps only cycle at round-off
            }
            y.extend_from_slice(&u);
            return Ok(Outcome::Stalled(y));
        }
    }
    Ok(Outcome::Done)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bbw::solve::Solver;
    use crate::operators::{biharmonic_matrix, MassKind};
    use crate::progress::Silent;
    use crate::sparse::from_triplets;
    use faer::sparse::Triplet;
    use ndarray::Array2;

    #[test]
    fn oscillating_bounds_count_as_quiet() {
        let mut own = OwnBounds::new();
        assert_eq!(own.quiet_rounds(10.0, 5.0, 1e-6), 0);
        assert_eq!(own.quiet_rounds(9.0, 6.0, 1e-6), 0);
        // A cycling support: the bounds jump back and forth without beating their best.
        assert_eq!(own.quiet_rounds(9.5, 5.5, 1e-6), 1);
        assert_eq!(own.quiet_rounds(9.0, 6.0, 1e-6), 2);
        assert_eq!(own.quiet_rounds(9.5, 5.5, 1e-6), 3);
        // A real improvement of either bound resets the count.
        assert_eq!(own.quiet_rounds(9.5, 6.5, 1e-6), 0);
        assert_eq!(own.quiet_rounds(8.0, 5.0, 1e-6), 0);
        assert_eq!(own.quiet_rounds(8.0 - 1e-7, 6.5, 1e-6), 1);
    }

    /// The pattern of a path graph 0 - 1 - ... - (n-1) (a tridiagonal matrix).
    fn path(n: usize) -> Csc {
        let mut trip = Vec::new();
        for i in 0..n {
            trip.push(Triplet::new(i, i, 2.0));
            if i + 1 < n {
                trip.push(Triplet::new(i, i + 1, -1.0));
                trip.push(Triplet::new(i + 1, i, -1.0));
            }
        }
        from_triplets(n, n, &trip).unwrap()
    }

    #[test]
    fn graph_distance_stays_inside() {
        let a = path(6);
        let inside = [true, true, false, true, true, true];
        let d = graph_distance(&a, &inside, |i| i == 0 || i == 5);
        assert_eq!(d, vec![0, 1, usize::MAX, 2, 1, 0]);
    }

    #[test]
    fn spread_negative_moves_mass_to_the_nearest_positive_entries() {
        let a = path(7);
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

    #[test]
    fn only_the_outer_half_of_a_negative_band_leaves() {
        let a = path(14);
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
        y[11] = 0.5; // below the joiner's violation: joins too when dilating
        y[12] = 2.0;
        let th = SignThresholds::new(1e-6, 1.0);
        let (next, negative, joined) = next_support(&a, &support, &w, &y, th, false, 14);
        assert_eq!((negative, joined), (4, 1));
        let kept: Vec<usize> = (0..14).filter(|&i| next[i]).collect();
        // 8 and 9 are no farther from the edge than from the positive part; 6 and 7 stay.
        assert_eq!(kept, vec![0, 1, 2, 3, 4, 5, 6, 7, 10]);
        let (next, _, _) = next_support(&a, &support, &w, &y, th, true, 14);
        assert!(next[10] && next[11] && !next[12]);
    }

    #[test]
    fn a_row_joins_only_its_most_negative_column() {
        // Two columns on a path of 4 vertices: column 0 holds row 0, column 1 holds row 3.
        let a = path(4);
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
        let (next, negative, joined) = next_support(&a, &support, &w, &y, th, false, 4);
        // Every violation counts (the KKT test), but each row takes one column.
        assert_eq!((negative, joined), (0, 4));
        assert_eq!(
            next,
            vec![true, true, false, false, false, false, true, true]
        );
    }

    /// A `k x k` grid of the unit square with handles at three corners and the centre.
    fn grid_problem(k: usize) -> EliminatedProblem {
        let h = 1.0 / (k - 1) as f64;
        let v = Array2::from_shape_fn((k * k, 2), |(i, c)| {
            h * if c == 0 { i % k } else { i / k } as f64
        });
        let mut f = Vec::new();
        for r in 0..k - 1 {
            for c in 0..k - 1 {
                let i = r * k + c;
                f.extend([i, i + 1, i + k + 1, i, i + k + 1, i + k]);
            }
        }
        let f = Array2::from_shape_vec((f.len() / 3, 3), f).unwrap();
        let bmat = biharmonic_matrix(v.view(), f.view(), MassKind::Voronoi).unwrap();
        let b = vec![0, k - 1, (k / 2) * k + k / 2, k * k - 1];
        let bc = Array2::from_shape_fn((4, 4), |(i, j)| f64::from(i == j));
        EliminatedProblem::new(&bmat, &b, bc.view()).unwrap()
    }

    fn run(prob: &EliminatedProblem, stall_rounds: usize) -> (Best, BbwInfo) {
        let opts = BbwOptions {
            solver: Solver::ActiveSet,
            tol: 1e-11,
            ..Default::default()
        };
        let (mut best, mut info) = (Best::new(), BbwInfo::default());
        solve_with_stall(prob, &opts, stall_rounds, &mut best, &mut info, &mut Silent).unwrap();
        (best, info)
    }

    #[test]
    fn rounds_resume_after_the_lbfgs_intermission() {
        let prob = grid_problem(25);
        let (plain, plain_info) = run(&prob, STALL_ROUNDS);
        assert_eq!(
            plain_info.fallbacks, 0,
            "the plain rounds should not stall here"
        );
        assert!(plain.relative_gap() <= 1e-11);
        // A window of 0 hands over to L-BFGS after the first round; 150 L-BFGS iterations do
        // not reach 1e-11, so the rounds must resume and finish the job.
        let (forced, info) = run(&prob, 0);
        assert!(info.fallbacks >= 1, "no hand-over: {info:?}");
        assert!(info.rounds > 1, "the rounds did not resume: {info:?}");
        assert!(
            forced.relative_gap() <= 1e-11,
            "gap {} {info:?} plain {plain_info:?}",
            forced.relative_gap()
        );
        let dw = plain
            .w
            .iter()
            .zip(&forced.w)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        assert!(dw < 1e-6, "max |dW| {dw}");
    }
}
