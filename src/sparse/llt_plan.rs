//! A sparse Cholesky factor computed in two steps, so that its size is known before it is
//! allocated: the symbolic analysis (minimum-degree order, elimination structure) counts the
//! entries of the numeric factor, and a caller with a memory budget can stop there.
//!
//! Input: an SPD matrix (its lower triangle is read). Output: [`SparseLlt`], `L L^T = P A P^T`
//! with faer's choice of a simplicial or supernodal factor, and `A^{-1} x`.

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::sparse::linalg::cholesky::{
    factorize_symbolic_cholesky, CholeskySymbolicParams, LltRef, SymbolicCholesky,
    SymbolicCholeskyRaw, SymmetricOrdering,
};
use faer::sparse::linalg::SupernodalThreshold;
use faer::{Conj, MatMut, Par, Side};

use super::Csc;

/// The symbolic analysis of a Cholesky factor, before its numeric values exist.
pub(crate) struct LltPlan {
    symbolic: SymbolicCholesky<usize>,
}

impl LltPlan {
    /// Analyses the SPD `a` (faer's default choice between simplicial and supernodal).
    pub fn new(a: &Csc) -> Result<Self, String> {
        Self::with_threshold(a, SupernodalThreshold::AUTO)
    }

    /// [`LltPlan::new`] with faer's choice between simplicial and supernodal made by `threshold`.
    pub fn with_threshold(a: &Csc, threshold: SupernodalThreshold) -> Result<Self, String> {
        let params = CholeskySymbolicParams {
            supernodal_flop_ratio_threshold: threshold,
            ..Default::default()
        };
        let symbolic =
            factorize_symbolic_cholesky(a.symbolic(), Side::Lower, SymmetricOrdering::Amd, params)
                .map_err(|e| format!("symbolic analysis: {e:?}"))?;
        Ok(LltPlan { symbolic })
    }

    /// Bytes the numeric factor will take: its values, and in a simplicial factor one row index
    /// per value (a supernodal one stores its row indices per supernode, a small fraction).
    pub fn factor_bytes(&self) -> usize {
        let per_value = match self.symbolic.raw() {
            SymbolicCholeskyRaw::Simplicial(_) => 16,
            SymbolicCholeskyRaw::Supernodal(_) => 8,
        };
        per_value * self.symbolic.len_val()
    }

    /// The numeric factor of `a`, the matrix this plan analysed (single-threaded: on two cores
    /// a second thread makes faer's factorisation slower; callers factor blocks in parallel).
    pub fn factor(self, a: &Csc) -> Result<SparseLlt, String> {
        self.factor_with(a, Par::Seq)
    }

    /// [`LltPlan::factor`] with the parallelism `par`.
    pub fn factor_with(self, a: &Csc, par: Par) -> Result<SparseLlt, String> {
        let symbolic = self.symbolic;
        // Reserved fallibly: a refused allocation (an address-space limit) is an error, not an
        // abort of the process.
        let mut values = Vec::new();
        values
            .try_reserve_exact(symbolic.len_val())
            .map_err(|_| "out of memory for the factor's values".to_string())?;
        values.resize(symbolic.len_val(), 0.0);
        let mut mem = MemBuffer::try_new(
            symbolic.factorize_numeric_llt_scratch::<f64>(par, Default::default()),
        )
        .map_err(|e| format!("{e:?}"))?;
        symbolic
            .factorize_numeric_llt(
                &mut values,
                a.as_ref(),
                Side::Lower,
                Default::default(),
                par,
                MemStack::new(&mut mem),
                Default::default(),
            )
            .map_err(|e| format!("{e:?}"))?;
        Ok(SparseLlt { symbolic, values })
    }
}

/// A numeric Cholesky factor and its symbolic structure.
pub(crate) struct SparseLlt {
    pub(super) symbolic: SymbolicCholesky<usize>,
    pub(super) values: Vec<f64>,
}

impl SparseLlt {
    /// Number of rows (and columns) of the factored matrix.
    pub fn nrows(&self) -> usize {
        self.symbolic.nrows()
    }

    /// Overwrites the `n x k` column-major `x` with `A^{-1} x` (faer's solve, one thread).
    pub fn solve_in_place(&self, x: &mut [f64]) {
        let n = self.nrows();
        if n == 0 || x.is_empty() {
            return;
        }
        let k = x.len() / n;
        let par = Par::Seq;
        let mut mem = MemBuffer::new(self.symbolic.solve_in_place_scratch::<f64>(k, par));
        LltRef::new(&self.symbolic, &self.values).solve_in_place_with_conj(
            Conj::No,
            MatMut::from_column_major_slice_mut(x, n, k),
            par,
            MemStack::new(&mut mem),
        );
    }
}
