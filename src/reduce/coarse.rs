//! Coarse space of the two-level preconditioner of the conjugate-gradient solver
//! ([`super::cg`]).
//!
//! The block preconditioner of the local iteration removes the error inside each vertex's `k`
//! weights but not the smooth (low-frequency) error over the surface, which a Laplacian energy
//! barely penalises: block-Jacobi conjugate gradients need `O(sqrt(n))` iterations. The coarse
//! space adds one unknown per (aggregate `A`, handle `i`): "handle `i` gains weight on the
//! vertices of `A`" (where it is in the influence set, with the other `k - 1` weights giving it
//! up evenly so every row still sums to one),
//!
//! ```text
//!   z_{A,i}(v) = e_t - 1/k   for v in A with S_vt = i,   0 elsewhere,
//! ```
//!
//! and the preconditioner becomes `P + Z H_c^-1 Z^T` with `H_c = Z^T H Z` (additive two-level
//! Schwarz with an aggregation coarse space, e.g. Toselli & Widlund 2005, Ch. 3). `Z` only
//! applies when the equality rows are the sums alone (no linear precision).
//!
//! `H_c` is assembled from the coupling entries: `(Z^T H Z)` gets
//! `Q_vu (B_v^T B_u)'_ts` at (`(A(v), S_vt)`, `(A(u), S_us)`), where `C'` is `B_v^T B_u` with
//! row and column means removed (the `- 1/k` parts of `z`).

use faer::sparse::Triplet;
use rayon::prelude::*;

use crate::error::{SkinError, SkinResult};
use crate::sparse::{from_triplets, LltPlan, SparseLlt};

use super::problem::Problem;

/// Target number of vertices per aggregate.
const AGGREGATE: usize = 64;

/// The coarse space and the Cholesky factor of `H_c`.
pub(crate) struct Coarse {
    /// Coarse unknown of every (vertex, slot): `(n, k)` flat.
    dof: Vec<usize>,
    llt: SparseLlt,
    nc: usize,
    k: usize,
}

impl Coarse {
    /// Builds aggregates on the coupling graph and factors `H_c`.
    pub(crate) fn new(pb: &Problem) -> SkinResult<Self> {
        let (n, k) = pb.sets.dim();
        let (agg, na) = aggregates(pb, n);
        // Vertices of every aggregate (counting sort).
        let mut vstart = vec![0usize; na + 1];
        for &a in &agg {
            vstart[a + 1] += 1;
        }
        for a in 0..na {
            vstart[a + 1] += vstart[a];
        }
        let mut verts = vec![0usize; n];
        let mut next = vstart.clone();
        for (v, &a) in agg.iter().enumerate() {
            verts[next[a]] = v;
            next[a] += 1;
        }
        // Coarse unknowns: the distinct handles of every aggregate, numbered aggregate by
        // aggregate (`dstart[a]..dstart[a + 1]`).
        let m = pb.sets.iter().max().map_or(0, |&i| i + 1);
        let mut local = vec![(usize::MAX, 0usize); m];
        let mut dof = vec![0usize; n * k];
        let mut dstart = vec![0usize; na + 1];
        for a in 0..na {
            let base = dstart[a];
            let mut count = 0;
            for &v in &verts[vstart[a]..vstart[a + 1]] {
                for t in 0..k {
                    let i = pb.sets[[v, t]];
                    if local[i].0 != a {
                        local[i] = (a, count);
                        count += 1;
                    }
                    dof[v * k + t] = base + local[i].1;
                }
            }
            dstart[a + 1] = base + count;
        }
        let nc = dstart[na];
        // Lower triangle of H_c, aggregate by aggregate: a dense block of its rows times the
        // coarse columns its vertices reach through Q.
        let cp = &pb.coupling;
        let kf = k as f64;
        let blocks: Vec<Vec<Triplet<usize, usize, f64>>> = (0..na)
            .into_par_iter()
            .map_init(
                || {
                    (
                        vec![usize::MAX; nc],
                        vec![0.0; 3 * k + k * k],
                        Vec::new(),
                        Vec::new(),
                    )
                },
                |(pos, c, cols, acc), a| {
                    let (base, rows) = (dstart[a], dstart[a + 1] - dstart[a]);
                    cols.clear();
                    acc.clear();
                    let mut lrow = vec![0usize; k];
                    for &v in &verts[vstart[a]..vstart[a + 1]] {
                        for (t, l) in lrow.iter_mut().enumerate() {
                            *l = dof[v * k + t] - base;
                        }
                        for (u, w) in cp.entries(v) {
                            let (cg, rest) = c.split_at_mut(k * k);
                            let (rm, rest) = rest.split_at_mut(k);
                            let (cm, _) = rest.split_at_mut(k);
                            pb.cross_gram(v, u, cg);
                            for t in 0..k {
                                rm[t] = cg[t * k..(t + 1) * k].iter().sum::<f64>() / kf;
                                cm[t] = (0..k).map(|x| cg[x * k + t]).sum::<f64>() / kf;
                            }
                            let mu = rm.iter().sum::<f64>() / kf;
                            for s in 0..k {
                                let j = dof[u * k + s];
                                if pos[j] == usize::MAX {
                                    pos[j] = cols.len();
                                    cols.push(j);
                                    acc.resize(acc.len() + rows, 0.0);
                                }
                                let col = &mut acc[pos[j] * rows..(pos[j] + 1) * rows];
                                let shift = mu - cm[s];
                                for t in 0..k {
                                    col[lrow[t]] += w * (cg[t * k + s] - rm[t] + shift);
                                }
                            }
                        }
                    }
                    let mut out = Vec::with_capacity(acc.len() / 2 + rows * rows);
                    for (x, &j) in cols.iter().enumerate() {
                        pos[j] = usize::MAX;
                        for r in 0..rows {
                            if base + r >= j {
                                out.push(Triplet::new(base + r, j, acc[x * rows + r]));
                            }
                        }
                    }
                    out
                },
            )
            .collect();
        let mut trip: Vec<Triplet<usize, usize, f64>> = blocks.into_iter().flatten().collect();
        // The unknowns of one aggregate sum to the zero correction (every z row sums to zero):
        // `delta 1 1^T` on each aggregate's block makes H_c definite without changing
        // `Z H_c^-1 Z^T`; a tiny ridge guards against other dependencies.
        let mut diag = vec![0.0; nc];
        for t in &trip {
            if t.row == t.col {
                diag[t.row] += t.val;
            }
        }
        let dmax = diag.iter().fold(0.0f64, |a, &b| a.max(b));
        if !(dmax > 0.0 && dmax.is_finite()) {
            return Err(SkinError::Numerical(
                "coarse matrix has no positive diagonal".into(),
            ));
        }
        for a in 0..na {
            let d = dstart[a]..dstart[a + 1];
            let delta = diag[d.clone()].iter().sum::<f64>() / d.len().max(1) as f64;
            for i in d.clone() {
                for j in dstart[a]..=i {
                    trip.push(Triplet::new(i, j, delta));
                }
            }
        }
        for (c, &d) in diag.iter().enumerate() {
            trip.push(Triplet::new(c, c, 1e-10 * dmax + 1e-12 * d));
        }
        let hc = from_triplets(nc, nc, &trip)?;
        let llt = LltPlan::new(&hc)
            .and_then(|plan| plan.factor(&hc))
            .map_err(|e| SkinError::Numerical(format!("coarse Cholesky failed: {e}")))?;
        Ok(Coarse { dof, llt, nc, k })
    }

    /// `z += Z H_c^-1 Z^T g` for `g, z (n, k)` flat.
    pub(crate) fn add_correction(&self, g: &[f64], z: &mut [f64]) {
        let k = self.k;
        let mut rc = vec![0.0; self.nc];
        for (v, gv) in g.chunks(k).enumerate() {
            let mean = gv.iter().sum::<f64>() / k as f64;
            for (t, x) in gv.iter().enumerate() {
                rc[self.dof[v * k + t]] += x - mean;
            }
        }
        self.llt.solve_in_place(&mut rc);
        z.par_chunks_mut(k).enumerate().for_each(|(v, zv)| {
            let d = &self.dof[v * k..(v + 1) * k];
            let mean = d.iter().map(|&c| rc[c]).sum::<f64>() / k as f64;
            for (x, &c) in zv.iter_mut().zip(d) {
                *x += rc[c] - mean;
            }
        });
    }
}

/// Greedy breadth-first aggregation of the coupling graph into pieces of about
/// [`AGGREGATE`] vertices.
fn aggregates(pb: &Problem, n: usize) -> (Vec<usize>, usize) {
    let mut agg = vec![usize::MAX; n];
    let mut count = 0;
    let mut queue = std::collections::VecDeque::new();
    for s in 0..n {
        if agg[s] != usize::MAX {
            continue;
        }
        agg[s] = count;
        queue.clear();
        queue.push_back(s);
        let mut size = 1;
        'grow: while let Some(v) = queue.pop_front() {
            for (u, _) in pb.coupling.entries(v) {
                if agg[u] == usize::MAX {
                    agg[u] = count;
                    size += 1;
                    queue.push_back(u);
                    if size >= AGGREGATE {
                        break 'grow;
                    }
                }
            }
        }
        count += 1;
    }
    (agg, count)
}
