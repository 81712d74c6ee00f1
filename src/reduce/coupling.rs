//! The coupling matrix `Q` of the reduction objective `tr(E^T Q E)` and its colouring.

use rayon::prelude::*;

use crate::sparse::Csc;

/// The symmetric positive semi-definite `n x n` matrix `Q` of the objective `sum tr(E^T Q E)`,
/// `E = X(alpha) - Xbar`, stored by columns (= rows).
pub(crate) struct Coupling {
    pub(super) ptr: Vec<usize>,
    pub(super) rows: Vec<usize>,
    pub(super) val: Vec<f64>,
    /// `Q_vv`.
    pub(super) diag: Vec<f64>,
}

impl Coupling {
    /// `Q = I` (geometric reduction, eq. 3).
    pub(crate) fn identity(n: usize) -> Self {
        Coupling {
            ptr: (0..=n).collect(),
            rows: (0..n).collect(),
            val: vec![1.0; n],
            diag: vec![1.0; n],
        }
    }

    fn from_parts(ptr: Vec<usize>, rows: Vec<usize>, val: Vec<f64>) -> Self {
        let n = ptr.len() - 1;
        let diag = (0..n)
            .map(|v| {
                (ptr[v]..ptr[v + 1])
                    .find(|&p| rows[p] == v)
                    .map_or(0.0, |p| val[p])
            })
            .collect();
        Coupling {
            ptr,
            rows,
            val,
            diag,
        }
    }

    /// `Q = -L`: the Dirichlet energy `int |grad e|^2 dA` of the error.
    pub(crate) fn dirichlet(l: &Csc) -> Self {
        let sym = l.symbolic();
        Self::from_parts(
            sym.col_ptr().to_vec(),
            sym.row_idx().to_vec(),
            l.val().iter().map(|x| -x).collect(),
        )
    }

    /// `Q = L M^-1 L`: the squared-Laplacian energy `int (lap e)^2 dA` of eqs. (4)-(5).
    /// `L` must be exactly symmetric; then so is `Q` (terms are summed in the same order).
    pub(crate) fn squared_laplacian(l: &Csc, mass: &[f64]) -> Self {
        let sym = l.symbolic();
        let (lp, lr, lv) = (sym.col_ptr(), sym.row_idx(), l.val());
        let n = mass.len();
        let mut ptr = Vec::with_capacity(n + 1);
        let mut rows = Vec::new();
        let mut val = Vec::new();
        let mut acc = vec![0.0; n];
        let mut seen = vec![usize::MAX; n];
        let mut touched = Vec::new();
        ptr.push(0);
        for v in 0..n {
            touched.clear();
            // Column v of Q = sum_w L[:, w] L_wv / M_w, w ascending.
            for p in lp[v]..lp[v + 1] {
                let (w, lwv) = (lr[p], lv[p]);
                let f = lwv / mass[w];
                for p2 in lp[w]..lp[w + 1] {
                    let u = lr[p2];
                    if seen[u] != v {
                        seen[u] = v;
                        acc[u] = 0.0;
                        touched.push(u);
                    }
                    acc[u] += lv[p2] * f;
                }
            }
            touched.sort_unstable();
            for &u in &touched {
                rows.push(u);
                val.push(acc[u]);
            }
            ptr.push(rows.len());
        }
        Self::from_parts(ptr, rows, val)
    }

    pub(super) fn n(&self) -> usize {
        self.diag.len()
    }

    /// No two vertices interact (geometric reduction): one exact sweep solves the problem.
    pub(super) fn is_diagonal(&self) -> bool {
        (0..self.n()).all(|v| self.col(v).all(|p| self.rows[p] == v))
    }

    pub(super) fn col(&self, v: usize) -> std::ops::Range<usize> {
        self.ptr[v]..self.ptr[v + 1]
    }

    /// The entries `(u, Q_vu)` of row (= column) `v`.
    pub(crate) fn entries(&self, v: usize) -> impl Iterator<Item = (usize, f64)> + '_ {
        self.col(v).map(move |p| (self.rows[p], self.val[p]))
    }

    /// `out = Q x` for `x (n, q)` flat, in parallel over rows (`Q` is symmetric: columns = rows).
    pub(super) fn apply(&self, x: &[f64], q: usize, out: &mut [f64]) {
        out.par_chunks_mut(q).enumerate().for_each(|(v, o)| {
            o.iter_mut().for_each(|y| *y = 0.0);
            for p in self.col(v) {
                let (u, w) = (self.rows[p], self.val[p]);
                for (y, xu) in o.iter_mut().zip(&x[u * q..(u + 1) * q]) {
                    *y += w * xu;
                }
            }
        });
    }

    /// Greedy colouring such that no two vertices of one class are coupled by `Q`. Returns the
    /// vertices ordered class by class and the class boundaries (`ptr`, length classes + 1).
    pub(crate) fn colour_order(&self) -> (Vec<usize>, Vec<usize>) {
        let n = self.n();
        let (colour, classes) = crate::sparse::greedy_colouring(n, |v, visit| {
            self.col(v).for_each(|p| visit(self.rows[p]));
        });
        let mut counts = vec![0; classes];
        colour.iter().for_each(|&c| counts[c] += 1);
        let mut ptr = vec![0; counts.len() + 1];
        for c in 0..counts.len() {
            ptr[c + 1] = ptr[c] + counts[c];
        }
        let mut next = ptr.clone();
        let mut order = vec![0; n];
        for v in 0..n {
            order[next[colour[v]]] = v;
            next[colour[v]] += 1;
        }
        (order, ptr)
    }

    /// `Q[order, order]`: the coupling of the renumbered vertices `i -> order[i]`.
    pub(crate) fn permuted(&self, order: &[usize]) -> Self {
        let n = self.n();
        let mut inv = vec![0; n];
        for (i, &v) in order.iter().enumerate() {
            inv[v] = i;
        }
        let mut ptr = Vec::with_capacity(n + 1);
        let mut rows = Vec::with_capacity(self.rows.len());
        let mut val = Vec::with_capacity(self.val.len());
        let mut entries = Vec::new();
        ptr.push(0);
        for &v in order {
            entries.clear();
            entries.extend(self.col(v).map(|p| (inv[self.rows[p]], self.val[p])));
            entries.sort_unstable_by_key(|e| e.0);
            for &(r, x) in &entries {
                rows.push(r);
                val.push(x);
            }
            ptr.push(rows.len());
        }
        Self::from_parts(ptr, rows, val)
    }
}
