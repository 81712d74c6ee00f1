//! A sparse Cholesky factor whose triangular solves run disjoint subtrees of the elimination
//! tree on different threads.
//!
//! Input: an SPD matrix (its lower triangle). Output: `L L^T = P A P^T` (faer's supernodal
//! factor, minimum-degree order) and `A^{-1} X` for an `n x k` block `X`.
//!
//! Why not faer's solve: its right-hand sides are column-major, so below every supernode the
//! rows are gathered and scattered one column at a time; here the block is row-major (a row's
//! `k` entries share a cache line). And splitting the right-hand sides over the threads
//! makes every thread stream the whole factor, while splitting the *tree* makes each
//! stream only its part, for all columns at once. Supernodes in disjoint subtrees never update
//! each other, only their common ancestors, which are solved afterwards on one thread. Each
//! part works on its own copy of the block (`n k` doubles per thread of extra memory).
//! `docs/solver.md` has the measurement.

use faer::linalg::matmul::matmul;
use faer::linalg::triangular_solve::{
    solve_lower_triangular_in_place, solve_upper_triangular_in_place,
};
use faer::sparse::linalg::cholesky::SymbolicCholeskyRaw;
#[cfg(test)]
use faer::sparse::linalg::SupernodalThreshold;
use faer::{Accum, MatMut, Par};
use rayon::prelude::*;

use super::llt_plan::{LltPlan, SparseLlt};
use super::Csc;

/// Cholesky factor with a partition of its supernodal elimination tree over the rayon threads.
pub struct TreeLlt {
    llt: SparseLlt,
    /// Supernodes of each thread's subtrees (ascending: children before parents), and the
    /// common ancestors solved on one thread (ascending; all supernodes when one thread runs).
    /// Both empty for a simplicial factor (small matrices), which faer's own solve handles.
    parts: Vec<Vec<usize>>,
    top: Vec<usize>,
}

impl TreeLlt {
    /// Factors the SPD `a` (lower triangle read) by its symbolic analysis `plan` (which says the
    /// factor's size beforehand), or says why it failed.
    pub fn from_plan(plan: LltPlan, a: &Csc) -> Result<Self, String> {
        Self::split(plan.factor(a)?, rayon::current_num_threads())
    }

    /// `new` with faer's choice between simplicial and supernodal made by `threshold` and the
    /// tree split over `threads` parts (tests force small factors to be supernodal).
    #[cfg(test)]
    fn with_params(
        a: &Csc,
        threshold: SupernodalThreshold,
        threads: usize,
    ) -> Result<Self, String> {
        Self::split(LltPlan::with_threshold(a, threshold)?.factor(a)?, threads)
    }

    /// The factor `llt` with its supernodal tree split over `threads` parts.
    fn split(llt: SparseLlt, threads: usize) -> Result<Self, String> {
        let (parts, top) = match llt.symbolic.raw() {
            SymbolicCholeskyRaw::Supernodal(sn) if threads > 1 => split_tree(sn, threads),
            SymbolicCholeskyRaw::Supernodal(sn) => (Vec::new(), (0..sn.n_supernodes()).collect()),
            SymbolicCholeskyRaw::Simplicial(_) => (Vec::new(), Vec::new()),
        };
        Ok(TreeLlt { llt, parts, top })
    }

    /// Number of rows (and columns) of the factored matrix.
    pub fn nrows(&self) -> usize {
        self.llt.symbolic.nrows()
    }

    /// Overwrites the `n x k` column-major `x` with `A^{-1} x`.
    pub fn solve_in_place(&self, x: &mut [f64]) {
        let n = self.nrows();
        if n == 0 || x.is_empty() {
            return;
        }
        let k = x.len() / n;
        let SymbolicCholeskyRaw::Supernodal(sn) = self.llt.symbolic.raw() else {
            return self.llt.solve_in_place(x);
        };
        // The factor is of `P A P^T`: permute in (to row-major), solve, permute out.
        let identity: Vec<usize>;
        let fwd: &[usize] = match self.llt.symbolic.perm() {
            Some(p) => p.arrays().0,
            None => {
                identity = (0..n).collect();
                &identity
            }
        };
        let mut y = vec![0.0; n * k];
        y.par_chunks_mut(k).zip(fwd).for_each(|(row, &f)| {
            for (j, r) in row.iter_mut().enumerate() {
                *r = x[j * n + f];
            }
        });
        let ln = Supernodes {
            sn,
            values: &self.llt.values,
        };
        self.forward(&ln, &mut y, k);
        self.backward(&ln, &mut y, k);
        x.par_chunks_mut(n).enumerate().for_each(|(j, col)| {
            for (i, &f) in fwd.iter().enumerate() {
                col[f] = y[i * k + j];
            }
        });
    }

    /// `L y = b` (`y` row-major): each part on a private copy (its updates reach only its own
    /// rows and the common ancestors'), then the ancestors' updates are summed and the
    /// ancestors solved.
    fn forward(&self, ln: &Supernodes, y: &mut [f64], k: usize) {
        let copies = self.on_copies(y, |part, z, tmp| {
            part.iter().for_each(|&s| ln.forward_step(s, z, k, tmp));
        });
        if !copies.is_empty() {
            let base: Vec<f64> = self
                .top
                .iter()
                .flat_map(|&s| ln.rows(s, y, k))
                .copied()
                .collect();
            self.take_own_rows(ln, &copies, y, k);
            for z in &copies {
                // Ancestors' rows: add this part's change.
                let mut t = 0;
                for &s in &self.top {
                    let (c0, c1) = ln.cols(s);
                    for i in c0 * k..c1 * k {
                        y[i] += z[i] - base[t];
                        t += 1;
                    }
                }
            }
        }
        let mut tmp = Vec::new();
        for &s in &self.top {
            ln.forward_step(s, y, k, &mut tmp);
        }
    }

    /// `L^T x = y`: the ancestors first (descending), then the parts, each reading the rows
    /// above it and writing only its own.
    fn backward(&self, ln: &Supernodes, y: &mut [f64], k: usize) {
        let mut tmp = Vec::new();
        for &s in self.top.iter().rev() {
            ln.backward_step(s, y, k, &mut tmp);
        }
        let copies = self.on_copies(y, |part, z, tmp| {
            part.iter()
                .rev()
                .for_each(|&s| ln.backward_step(s, z, k, tmp));
        });
        self.take_own_rows(ln, &copies, y, k);
    }

    /// Runs `f(part, copy of y, scratch)` for every part in parallel; returns the copies.
    fn on_copies(
        &self,
        y: &[f64],
        f: impl Fn(&[usize], &mut [f64], &mut Vec<f64>) + Sync,
    ) -> Vec<Vec<f64>> {
        self.parts
            .par_iter()
            .with_max_len(1)
            .map(|part| {
                let (mut z, mut tmp) = (y.to_vec(), Vec::new());
                f(part, &mut z, &mut tmp);
                z
            })
            .collect()
    }

    /// Copies each part's own rows from its copy into `y`.
    fn take_own_rows(&self, ln: &Supernodes, copies: &[Vec<f64>], y: &mut [f64], k: usize) {
        for (part, z) in self.parts.iter().zip(copies) {
            for &s in part {
                let (c0, c1) = ln.cols(s);
                y[c0 * k..c1 * k].copy_from_slice(&z[c0 * k..c1 * k]);
            }
        }
    }
}

/// The supernodes of a factor with their values.
struct Supernodes<'a> {
    sn: &'a faer::sparse::linalg::cholesky::supernodal::SymbolicSupernodalCholesky<usize>,
    values: &'a [f64],
}

impl Supernodes<'_> {
    fn cols(&self, s: usize) -> (usize, usize) {
        (self.sn.supernode_begin()[s], self.sn.supernode_end()[s])
    }

    /// Supernode `s`'s rows of the row-major `n x k` block `x`.
    fn rows<'x>(&self, s: usize, x: &'x [f64], k: usize) -> &'x [f64] {
        let (c0, c1) = self.cols(s);
        &x[c0 * k..c1 * k]
    }

    /// Supernode `s`'s dense block: `(ncols + pattern) x ncols`, column-major, and its pattern.
    fn block(&self, s: usize) -> (faer::MatRef<'_, f64>, &[usize]) {
        let (c0, c1) = self.cols(s);
        let pattern = self.sn.supernode(s).pattern();
        let ptr = self.sn.col_ptr_for_val();
        let l = faer::MatRef::from_column_major_slice(
            &self.values[ptr[s]..ptr[s + 1]],
            c1 - c0 + pattern.len(),
            c1 - c0,
        );
        (l, pattern)
    }

    /// `x_s <- L_ss^{-1} x_s`, then `x_pattern -= L_ps x_s`. `x` is `n x k` row-major (each
    /// row's `k` entries adjacent, so the pattern's rows are gathered a cache line at a time);
    /// `tmp` is scratch.
    fn forward_step(&self, s: usize, x: &mut [f64], k: usize, tmp: &mut Vec<f64>) {
        let (c0, c1) = self.cols(s);
        let (l, pattern) = self.block(s);
        let (top, bot) = l.split_at_row(c1 - c0);
        let (head, tail) = x.split_at_mut(c1 * k);
        let mut xs = MatMut::from_row_major_slice_mut(&mut head[c0 * k..], c1 - c0, k);
        solve_lower_triangular_in_place(top, xs.as_mut(), Par::Seq);
        if pattern.is_empty() {
            return;
        }
        tmp.resize(pattern.len() * k, 0.0);
        let t = MatMut::from_row_major_slice_mut(&mut tmp[..], pattern.len(), k);
        matmul(t, Accum::Replace, bot, xs.as_ref(), 1.0, Par::Seq);
        for (&i, d) in pattern.iter().zip(tmp.chunks_exact(k)) {
            let row = &mut tail[(i - c1) * k..(i - c1 + 1) * k];
            row.iter_mut().zip(d).for_each(|(r, d)| *r -= d);
        }
    }

    /// `x_s -= L_ps^T x_pattern`, then `x_s <- L_ss^{-T} x_s` (layout as in `forward_step`).
    fn backward_step(&self, s: usize, x: &mut [f64], k: usize, tmp: &mut Vec<f64>) {
        let (c0, c1) = self.cols(s);
        let (l, pattern) = self.block(s);
        let (top, bot) = l.split_at_row(c1 - c0);
        let (head, tail) = x.split_at_mut(c1 * k);
        let mut xs = MatMut::from_row_major_slice_mut(&mut head[c0 * k..], c1 - c0, k);
        if !pattern.is_empty() {
            tmp.clear();
            for &i in pattern {
                tmp.extend_from_slice(&tail[(i - c1) * k..(i - c1 + 1) * k]);
            }
            let t = faer::MatRef::from_row_major_slice(&tmp[..], pattern.len(), k);
            matmul(xs.as_mut(), Accum::Add, bot.transpose(), t, -1.0, Par::Seq);
        }
        solve_upper_triangular_in_place(top.transpose(), xs, Par::Seq);
    }
}

/// Splits the supernodal elimination tree into `p` groups of disjoint subtrees of similar work
/// plus their common ancestors, minimising (largest group + ancestors), the solve's critical
/// path (Geist & Ng's subtree-to-processor mapping: expand the heaviest subtree while that
/// helps). Work of a supernode = its number of factor entries (a solve reads each once).
fn split_tree(
    sn: &faer::sparse::linalg::cholesky::supernodal::SymbolicSupernodalCholesky<usize>,
    p: usize,
) -> (Vec<Vec<usize>>, Vec<usize>) {
    let ns = sn.n_supernodes();
    let (begin, end) = (sn.supernode_begin(), sn.supernode_end());
    let mut owner = vec![0; sn.nrows()];
    for s in 0..ns {
        owner[begin[s]..end[s]].fill(s);
    }
    let ptr = sn.col_ptr_for_val();
    let own: Vec<usize> = (0..ns).map(|s| ptr[s + 1] - ptr[s]).collect();
    let mut children = vec![Vec::new(); ns];
    let mut roots = Vec::new();
    let mut subtree = own.clone();
    // Supernodes are numbered children first, so one ascending pass sums the subtrees.
    for s in 0..ns {
        match sn.supernode(s).pattern().iter().min() {
            Some(&r) => {
                let parent = owner[r];
                children[parent].push(s);
                subtree[parent] += subtree[s];
            }
            None => roots.push(s),
        }
    }
    let mut frontier = roots;
    let mut top: Vec<usize> = Vec::new();
    let mut top_work = 0;
    let mut best: Option<(usize, Vec<usize>, Vec<Vec<usize>>)> = None;
    for _ in 0..ns.min(512) {
        let (span, bins) = pack(&frontier, &subtree, p);
        if best.as_ref().is_none_or(|b| span + top_work < b.0) {
            best = Some((span + top_work, top.clone(), bins));
        }
        // Expand the heaviest subtree that has children.
        let Some(pos) = (0..frontier.len())
            .filter(|&i| !children[frontier[i]].is_empty())
            .max_by_key(|&i| subtree[frontier[i]])
        else {
            break;
        };
        let s = frontier.swap_remove(pos);
        top.push(s);
        top_work += own[s];
        frontier.extend_from_slice(&children[s]);
        if top_work >= best.as_ref().map_or(usize::MAX, |b| b.0) {
            break;
        }
    }
    let (_, mut top, bins) = best.unwrap_or_default();
    top.sort_unstable();
    let parts = bins
        .into_iter()
        .map(|roots| {
            let mut nodes = Vec::new();
            let mut stack = roots;
            while let Some(s) = stack.pop() {
                nodes.push(s);
                stack.extend_from_slice(&children[s]);
            }
            nodes.sort_unstable();
            nodes
        })
        .collect();
    (parts, top)
}

/// Longest-processing-time packing of the subtrees `roots` into `p` bins: (largest bin, bins).
fn pack(roots: &[usize], work: &[usize], p: usize) -> (usize, Vec<Vec<usize>>) {
    let mut sorted = roots.to_vec();
    sorted.sort_by_key(|&s| std::cmp::Reverse(work[s]));
    let mut bins = vec![Vec::new(); p];
    let mut load = vec![0usize; p];
    for s in sorted {
        let b = (0..p).min_by_key(|&b| load[b]).unwrap_or(0);
        bins[b].push(s);
        load[b] += work[s];
    }
    (load.into_iter().max().unwrap_or(0), bins)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sparse::from_triplets;
    use faer::linalg::solvers::Solve;
    use faer::sparse::linalg::solvers::{Llt, SymbolicLlt};
    use faer::sparse::Triplet;
    use faer::Side;

    /// 2D grid Laplacian plus identity: SPD, supernodal at this size.
    fn grid(k: usize) -> Csc {
        let id = |i: usize, j: usize| i * k + j;
        let mut t = Vec::new();
        for i in 0..k {
            for j in 0..k {
                t.push(Triplet::new(id(i, j), id(i, j), 5.0));
                for (di, dj) in [(1usize, 0usize), (0, 1)] {
                    if i + di < k && j + dj < k {
                        let (a, b) = (id(i, j), id(i + di, j + dj));
                        t.push(Triplet::new(a, b, -1.0));
                        t.push(Triplet::new(b, a, -1.0));
                    }
                }
            }
        }
        from_triplets(k * k, k * k, &t).unwrap()
    }

    #[test]
    fn tree_solve_matches_faer() {
        let a = grid(60);
        let n = a.nrows();
        let llt = Llt::try_new_with_symbolic(
            SymbolicLlt::try_new(a.symbolic(), Side::Lower).unwrap(),
            a.as_ref(),
            Side::Lower,
        )
        .unwrap();
        for threads in [1, 2, 3] {
            let f =
                TreeLlt::with_params(&a, SupernodalThreshold::FORCE_SUPERNODAL, threads).unwrap();
            assert_eq!(f.parts.len(), if threads > 1 { threads } else { 0 });
            for k in [1, 3, 8] {
                let b: Vec<f64> = (0..n * k)
                    .map(|i| ((i * 7919) % 113) as f64 - 56.0)
                    .collect();
                let mut x = b.clone();
                f.solve_in_place(&mut x);
                let mut r = b.clone();
                llt.solve_in_place(MatMut::from_column_major_slice_mut(&mut r, n, k));
                let err = x
                    .iter()
                    .zip(&r)
                    .map(|(a, b)| (a - b).abs())
                    .fold(0.0, f64::max);
                let scale = r.iter().map(|v| v.abs()).fold(0.0, f64::max);
                assert!(
                    err <= 1e-12 * scale,
                    "{threads} threads, k {k}: {err} vs {scale}"
                );
            }
        }
    }

    #[test]
    fn parts_are_closed_subtrees_of_similar_work() {
        let f = TreeLlt::with_params(&grid(60), SupernodalThreshold::FORCE_SUPERNODAL, 1).unwrap();
        let SymbolicCholeskyRaw::Supernodal(sn) = f.llt.symbolic.raw() else {
            panic!("expected a supernodal factor");
        };
        let ns = sn.n_supernodes();
        let mut owner = vec![0; sn.nrows()];
        for s in 0..ns {
            owner[sn.supernode_begin()[s]..sn.supernode_end()[s]].fill(s);
        }
        let ptr = sn.col_ptr_for_val();
        let work = |v: &[usize]| v.iter().map(|&s| ptr[s + 1] - ptr[s]).sum::<usize>();
        for p in [2, 3] {
            let (parts, top) = split_tree(sn, p);
            let mut group = vec![usize::MAX; ns];
            for (g, part) in parts.iter().enumerate() {
                part.iter().for_each(|&s| group[s] = g);
            }
            top.iter().for_each(|&s| group[s] = p);
            assert!(
                group.iter().all(|&g| g != usize::MAX),
                "every supernode placed"
            );
            assert_eq!(parts.iter().map(Vec::len).sum::<usize>() + top.len(), ns);
            // A part's supernodes update only their own part or the common ancestors.
            for s in 0..ns {
                if let (Some(&r), true) = (sn.supernode(s).pattern().iter().min(), group[s] < p) {
                    assert!([group[s], p].contains(&group[owner[r]]), "supernode {s}");
                }
            }
            let total = work(&(0..ns).collect::<Vec<_>>());
            let span = parts.iter().map(|q| work(q)).max().unwrap() + work(&top);
            assert!(span * 10 <= total * 7, "{p} parts: span {span} of {total}");
        }
    }
}
