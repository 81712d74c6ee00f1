//! Elimination of the constrained vertices: `A = B_ff`, `G = B_fb bc`, and one Cholesky factor.

use std::time::Instant;

use faer::sparse::Triplet;
use ndarray::ArrayView2;
use rayon::prelude::*;

use super::energy::LaplacianEnergy;
use super::options::BbwOptions;
use crate::error::{SkinError, SkinResult};
use crate::invalid;
use crate::sparse::{from_triplets, Csc, LltPlan, TreeLlt};

/// The BBW quadratic restricted to the free vertices.
///
/// With `W = [W_f; bc]` the energy is `sum_j 1/2 w_j^T A w_j + g_j^T w_j + c0`, where
/// `A = B_ff`, `G = B_fb bc` and `c0 = 1/2 tr(bc^T B_bb bc)`. Dense matrices are stored
/// column-major, `nf x m`.
pub struct EliminatedProblem {
    /// Number of vertices of the full mesh.
    pub n: usize,
    /// Number of weight functions (handles + bones).
    pub m: usize,
    /// Constrained vertices (sorted) and their values (`b.len() x m`, row-major as given).
    pub b: Vec<usize>,
    pub bc: Vec<f64>,
    /// Free vertices, in increasing order.
    pub free: Vec<usize>,
    /// `B_ff`, symmetric positive definite.
    pub a: Csc,
    /// `G = B_fb bc`, `nf x m` column-major.
    pub g: Vec<f64>,
    /// Constant energy of the constrained rows.
    pub c0: f64,
    /// Unconstrained biharmonic weights `W0 = -A^{-1} G` (`= R` of eq. 14, since `W0 1 = 1`).
    pub w0: Vec<f64>,
    llt: TreeLlt,
    /// Bytes of `llt`'s values (and row indices).
    pub factor_bytes: usize,
    /// The factors of `B` when known: the energy is then evaluated from them (see [`energy`]).
    ///
    /// [`energy`]: super::energy
    laplacian: Option<LaplacianEnergy>,
    /// Seconds spent in assembly + factorisation.
    pub time_factor: f64,
}

impl EliminatedProblem {
    /// Eliminates the rows `b` of the `n x n` symmetric PSD matrix `bmat` and factors `B_ff`.
    ///
    /// Errors: `b` unsorted/duplicated/out of range, `bc` of the wrong shape or not finite, a
    /// connected component of `bmat`'s graph with no constrained vertex (which makes `B_ff`
    /// singular), or a failed factorisation.
    pub fn new(bmat: &Csc, b: &[usize], bc: ArrayView2<f64>) -> SkinResult<Self> {
        Self::within(bmat, b, bc, &BbwOptions::default())
    }

    /// [`EliminatedProblem::new`] for a solve with `opts`: errors with
    /// [`SkinError::OutOfMemory`] before factoring `B_ff` when its factor and the solve's
    /// vectors would exceed `opts.memory_limit`.
    pub fn within(
        bmat: &Csc,
        b: &[usize],
        bc: ArrayView2<f64>,
        opts: &BbwOptions,
    ) -> SkinResult<Self> {
        let t0 = Instant::now();
        let n = bmat.nrows();
        let m = bc.ncols();
        if bc.nrows() != b.len() {
            return invalid!("bc has {} rows but b has {} entries", bc.nrows(), b.len());
        }
        if m == 0 {
            return invalid!("bc has no columns: there are no handles");
        }
        if bc.iter().any(|x| !x.is_finite()) {
            return invalid!("bc has a NaN or infinite entry");
        }
        let mut is_b = vec![usize::MAX; n];
        for (r, &i) in b.iter().enumerate() {
            if i >= n {
                return invalid!("b holds vertex {i}, outside 0..{n}");
            }
            if is_b[i] != usize::MAX {
                return invalid!("b holds vertex {i} twice");
            }
            is_b[i] = r;
        }
        check_components(bmat, &is_b)?;

        let free: Vec<usize> = (0..n).filter(|&i| is_b[i] == usize::MAX).collect();
        let nf = free.len();
        let mut new_index = vec![usize::MAX; n];
        for (k, &i) in free.iter().enumerate() {
            new_index[i] = k;
        }

        let mut trip = Vec::with_capacity(bmat.compute_nnz());
        let mut g = vec![0.0; nf * m];
        let mut c0 = 0.0;
        for j in 0..n {
            let rows = bmat.symbolic().row_idx_of_col_raw(j);
            let vals = bmat.val_of_col(j);
            for (&i, &val) in rows.iter().zip(vals) {
                match (new_index[i] != usize::MAX, is_b[j] != usize::MAX) {
                    (true, false) => trip.push(Triplet::new(new_index[i], new_index[j], val)),
                    (true, true) => {
                        let rj = is_b[j];
                        for col in 0..m {
                            g[col * nf + new_index[i]] += val * bc[[rj, col]];
                        }
                    }
                    (false, true) => {
                        let (ri, rj) = (is_b[i], is_b[j]);
                        for col in 0..m {
                            c0 += 0.5 * bc[[ri, col]] * val * bc[[rj, col]];
                        }
                    }
                    (false, false) => {}
                }
            }
        }
        let a = from_triplets(nf, nf, &trip)?;
        let not_spd = |e: String| {
            SkinError::Numerical(format!(
                "B_ff is not positive definite ({e}); check for degenerate elements or a \
                 component without constrained vertices"
            ))
        };
        let plan = LltPlan::new(&a).map_err(not_spd)?;
        let factor_bytes = plan.factor_bytes();
        let vectors = opts.vector_bytes(nf, m);
        if factor_bytes.saturating_add(vectors) > opts.memory_limit {
            return Err(SkinError::OutOfMemory(format!(
                "memory_limit: the Cholesky factor of B_ff ({nf} free vertices) needs {} and the \
                 solver's vectors ({m} columns) {}, more than memory_limit = {}",
                bytes_text(factor_bytes),
                bytes_text(vectors),
                bytes_text(opts.memory_limit)
            )));
        }
        let llt = TreeLlt::from_plan(plan, &a).map_err(not_spd)?;

        let mut w0: Vec<f64> = g.iter().map(|x| -x).collect();
        let mut prob = EliminatedProblem {
            n,
            m,
            b: b.to_vec(),
            bc: bc.iter().copied().collect(),
            free,
            a,
            g,
            c0,
            w0: Vec::new(),
            llt,
            factor_bytes,
            laplacian: None,
            time_factor: 0.0,
        };
        prob.solve_in_place(&mut w0);
        prob.w0 = w0;
        prob.time_factor = t0.elapsed().as_secs_f64();
        Ok(prob)
    }

    /// Evaluates energies from the factors `B = L^T D L` of the matrix this problem was built
    /// from, which keeps the duality gap accurate on meshes with sliver elements.
    pub fn with_laplacian(mut self, laplacian: LaplacianEnergy) -> SkinResult<Self> {
        if laplacian.n() != self.n {
            return invalid!(
                "the Laplacian has {} vertices, the problem {}",
                laplacian.n(),
                self.n
            );
        }
        self.laplacian = Some(laplacian);
        Ok(self)
    }

    /// Number of free vertices.
    pub fn nf(&self) -> usize {
        self.free.len()
    }

    /// Overwrites the `nf x m` column-major `x` with `A^{-1} x` (all columns in one pass).
    pub fn solve_in_place(&self, x: &mut [f64]) {
        let nf = self.nf();
        if nf == 0 {
            return;
        }
        // The tree split runs the factor's independent subtrees on the rayon threads.
        self.llt.solve_in_place(x);
    }

    /// `A x` for an `nf x k` column-major block (parallel over columns).
    pub fn apply_a(&self, x: &[f64]) -> Vec<f64> {
        let nf = self.nf();
        let mut y = vec![0.0; x.len()];
        if nf == 0 {
            return y;
        }
        y.par_chunks_mut(nf)
            .zip(x.par_chunks(nf))
            .for_each(|(yc, xc)| {
                for (j, &xj) in xc.iter().enumerate() {
                    if xj == 0.0 {
                        continue;
                    }
                    let rows = self.a.symbolic().row_idx_of_col_raw(j);
                    for (&i, &v) in rows.iter().zip(self.a.val_of_col(j)) {
                        yc[i] += v * xj;
                    }
                }
            });
        y
    }

    /// Full energy `1/2 tr(W^T B W)` of the weights whose free rows are `wf` (`nf x m`).
    pub fn energy(&self, wf: &[f64]) -> f64 {
        match &self.laplacian {
            Some(l) => l.energy(&self.full_rows(wf), self.m),
            None => self.matrix_energy(wf),
        }
    }

    /// The full weights, `n x m` row by row: `wf`'s rows on the free vertices, `bc`'s on `b`.
    fn full_rows(&self, wf: &[f64]) -> Vec<f64> {
        let (nf, m) = (self.nf(), self.m);
        let mut w = vec![0.0; self.n * m];
        for (k, &i) in self.free.iter().enumerate() {
            for c in 0..m {
                w[i * m + c] = wf[c * nf + k];
            }
        }
        for (r, &i) in self.b.iter().enumerate() {
            w[i * m..(i + 1) * m].copy_from_slice(&self.bc[r * m..(r + 1) * m]);
        }
        w
    }

    /// `1/2 w^T A w + g^T w + c0`, the energy summed through the eliminated matrix.
    fn matrix_energy(&self, wf: &[f64]) -> f64 {
        let aw = self.apply_a(wf);
        let quad: f64 = wf.iter().zip(&aw).map(|(w, a)| 0.5 * w * a).sum();
        let lin: f64 = wf.iter().zip(&self.g).map(|(w, g)| w * g).sum();
        quad + lin + self.c0
    }

    /// Scatters free rows `wf` (`nf x m` column-major) and `bc` into a full row-major `n x m`.
    pub fn full_weights(&self, wf: &[f64]) -> ndarray::Array2<f64> {
        let (n, m, nf) = (self.n, self.m, self.nf());
        let mut w = ndarray::Array2::<f64>::zeros((n, m));
        for (k, &i) in self.free.iter().enumerate() {
            for col in 0..m {
                w[[i, col]] = wf[col * nf + k];
            }
        }
        for (r, &i) in self.b.iter().enumerate() {
            for col in 0..m {
                w[[i, col]] = self.bc[r * m + col];
            }
        }
        w
    }
}

/// Every connected component of the matrix graph must hold a constrained vertex, otherwise
/// `B_ff` is singular (its constant vector on that component is in the null space).
fn check_components(bmat: &Csc, is_b: &[usize]) -> SkinResult<()> {
    let n = bmat.nrows();
    let mut parent: Vec<usize> = (0..n).collect();
    fn find(p: &mut [usize], mut x: usize) -> usize {
        while p[x] != x {
            p[x] = p[p[x]];
            x = p[x];
        }
        x
    }
    for j in 0..n {
        for &i in bmat.symbolic().row_idx_of_col_raw(j) {
            let (ri, rj) = (find(&mut parent, i), find(&mut parent, j));
            if ri != rj {
                parent[ri.max(rj)] = ri.min(rj);
            }
        }
    }
    let mut has_b = vec![false; n];
    for (i, &bi) in is_b.iter().enumerate() {
        if bi != usize::MAX {
            let r = find(&mut parent, i);
            has_b[r] = true;
        }
    }
    let mut size = vec![0usize; n];
    for i in 0..n {
        let r = find(&mut parent, i);
        size[r] += 1;
    }
    for i in 0..n {
        let r = find(&mut parent, i);
        if !has_b[r] {
            return invalid!(
                "the connected component containing vertex {i} ({} vertices) has no constrained \
                 vertex: every component needs a handle or bone on it (or remove it from the mesh)",
                size[r]
            );
        }
    }
    Ok(())
}

/// `bytes` for a message, in the largest binary unit it reaches (`"1.50 GiB"`, `"312 B"`).
fn bytes_text(bytes: usize) -> String {
    let units = ["B", "KiB", "MiB", "GiB", "TiB"];
    let mut x = bytes as f64;
    let mut unit = 0;
    while x >= 1024.0 && unit + 1 < units.len() {
        x /= 1024.0;
        unit += 1;
    }
    if unit == 0 {
        format!("{bytes} B")
    } else {
        format!("{x:.2} {}", units[unit])
    }
}
