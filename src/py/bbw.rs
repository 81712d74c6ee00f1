//! Bindings for boundary conditions and the BBW solvers.

use ndarray::Array2;
use numpy::{IntoPyArray, PyArray1, PyArray2, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use super::{index_array, released, to_pyerr, Choices, PyProgress};
use crate::bbw::{bbw_dual, BbwOptions, EliminatedProblem, LaplacianEnergy, Solver};
use crate::constraints::{boundary_conditions, DEFAULT_TOL};
use crate::operators::biharmonic_from_parts;
use crate::sparse::Csc;

const SOLVERS: Choices<Solver> = Choices(&[
    ("active-set", Solver::ActiveSet),
    ("lbfgs-squared", Solver::LbfgsSquared),
]);

type BoundaryConditionsOut<'py> = (Bound<'py, PyArray1<i64>>, Bound<'py, PyArray2<f64>>);

#[pyfunction]
#[pyo3(name = "_boundary_conditions")]
fn py_boundary_conditions<'py>(
    py: Python<'py>,
    v: PyReadonlyArray2<'py, f64>,
    c: PyReadonlyArray2<'py, f64>,
    p: PyReadonlyArray2<'py, i64>,
    be: PyReadonlyArray2<'py, i64>,
    tol: f64,
) -> PyResult<BoundaryConditionsOut<'py>> {
    let nc = c.as_array().nrows();
    let p = index_array(&p, nc, "P")?;
    let be = index_array(&be, nc, "BE")?;
    let p: Vec<usize> = p.iter().copied().collect();
    let (v, c) = (v.as_array(), c.as_array());
    let r = released(py, || boundary_conditions(v, c, &p, be.view(), tol))?;
    let b: Vec<i64> = r.b.iter().map(|&i| i as i64).collect();
    Ok((b.into_pyarray(py), r.bc.into_pyarray(py)))
}

/// Rebuilds the square CSC matrix `name` from scipy's arrays (validated: sorted indices are not
/// required).
pub(crate) fn csc_from_parts(
    name: &str,
    data: &[f64],
    indices: &[i64],
    indptr: &[i64],
    n: usize,
) -> PyResult<Csc> {
    use pyo3::exceptions::PyValueError;
    if indptr.len() != n + 1
        || indices.len() != data.len()
        || *indptr.last().unwrap_or(&0) as usize != data.len()
    {
        return Err(PyValueError::new_err(format!(
            "{name} is not a valid square CSC matrix"
        )));
    }
    let mut trip = Vec::with_capacity(data.len());
    for j in 0..n {
        let (s, e) = (indptr[j], indptr[j + 1]);
        if s < 0 || e < s || e as usize > data.len() {
            return Err(PyValueError::new_err(format!(
                "{name} has an invalid column pointer"
            )));
        }
        for k in s as usize..e as usize {
            let i = indices[k];
            if i < 0 || i as usize >= n {
                return Err(PyValueError::new_err(format!(
                    "{name} has row index {i} outside 0..{n}"
                )));
            }
            if !data[k].is_finite() {
                return Err(PyValueError::new_err(format!(
                    "{name} has a NaN or infinite entry"
                )));
            }
            trip.push(faer::sparse::Triplet::new(i as usize, j, data[k]));
        }
    }
    crate::sparse::from_triplets(n, n, &trip).map_err(to_pyerr)
}

#[pyfunction]
#[pyo3(name = "_bbw_dual", signature = (l_data, l_indices, l_indptr, masses, b, bc, *, solver, tol,
                                        max_iter, partition_of_unity, seed, lbfgs_memory,
                                        memory_limit, callback))]
#[allow(clippy::too_many_arguments)]
fn py_bbw_dual<'py>(
    py: Python<'py>,
    l_data: PyReadonlyArray1<'py, f64>,
    l_indices: PyReadonlyArray1<'py, i64>,
    l_indptr: PyReadonlyArray1<'py, i64>,
    masses: PyReadonlyArray1<'py, f64>,
    b: PyReadonlyArray1<'py, i64>,
    bc: PyReadonlyArray2<'py, f64>,
    solver: &str,
    tol: f64,
    max_iter: usize,
    partition_of_unity: bool,
    seed: u64,
    lbfgs_memory: usize,
    memory_limit: u64,
    callback: Option<Py<PyAny>>,
) -> PyResult<(Bound<'py, PyArray2<f64>>, Bound<'py, PyDict>)> {
    let masses = masses.as_slice()?.to_vec();
    let n = masses.len();
    let l = csc_from_parts(
        "L",
        l_data.as_slice()?,
        l_indices.as_slice()?,
        l_indptr.as_slice()?,
        n,
    )?;
    let b_idx: Vec<usize> = b
        .as_array()
        .iter()
        .map(|&i| {
            if i < 0 || i as u64 >= n as u64 {
                Err(pyo3::exceptions::PyValueError::new_err(format!(
                    "b holds index {i}, outside 0..{n}"
                )))
            } else {
                Ok(i as usize)
            }
        })
        .collect::<PyResult<_>>()?;
    let bc = bc.as_array().to_owned();
    let opts = BbwOptions {
        solver: SOLVERS.parse("solver", solver)?,
        tol,
        max_iter,
        partition_of_unity,
        seed,
        memory: lbfgs_memory.max(1),
        memory_limit: usize::try_from(memory_limit).unwrap_or(usize::MAX),
    };
    let mut progress = PyProgress::new(callback);
    let (w, info): (Array2<f64>, _) = released(py, || {
        let bmat = biharmonic_from_parts(&l, &masses)?;
        let prob = EliminatedProblem::within(&bmat, &b_idx, bc.view(), &opts)?
            .with_laplacian(LaplacianEnergy::new(l, &masses)?)?;
        bbw_dual(&prob, &opts, &mut progress)
    })?;
    let d = PyDict::new(py);
    d.set_item("solver", info.solver)?;
    d.set_item("iterations", info.iterations)?;
    d.set_item("evaluations", info.evaluations)?;
    d.set_item("rounds", info.rounds)?;
    d.set_item("cg_iterations", info.cg_iterations)?;
    d.set_item("energy", info.energy)?;
    d.set_item("lower_bound", info.lower_bound)?;
    d.set_item("dual_objective", info.dual_objective)?;
    d.set_item("gap", info.gap)?;
    d.set_item("relative_gap", info.relative_gap)?;
    d.set_item("min_raw_weight", info.min_raw_weight)?;
    d.set_item("max_raw_weight", info.max_raw_weight)?;
    d.set_item("converged", info.converged)?;
    d.set_item("time_factor", info.time_factor)?;
    d.set_item("time_solve", info.time_solve)?;
    d.set_item("time_lbfgs", info.time_lbfgs)?;
    d.set_item("time_active_set", info.time_active_set)?;
    d.set_item("time_support_factor", info.time_support_factor)?;
    d.set_item("fallbacks", info.fallbacks)?;
    d.set_item("time_cg", info.time_cg)?;
    d.set_item("time_smooth", info.time_smooth)?;
    d.set_item("factor_bytes", info.factor_bytes)?;
    d.set_item("vector_bytes", info.vector_bytes)?;
    d.set_item("support_factor_bytes", info.support_factor_bytes)?;
    d.set_item("memory_fallback", info.memory_fallback)?;
    Ok((w.into_pyarray(py), d))
}

/// The defaults of `bbw_dual_constrained`'s options, keyed by their Python names.
fn bbw_defaults(py: Python<'_>) -> PyResult<Bound<'_, PyDict>> {
    let o = BbwOptions::default();
    let d = PyDict::new(py);
    d.set_item("solver", SOLVERS.name(o.solver))?;
    d.set_item("tol", o.tol)?;
    d.set_item("max_iter", o.max_iter)?;
    d.set_item("partition_of_unity", o.partition_of_unity)?;
    d.set_item("seed", o.seed)?;
    d.set_item("lbfgs_memory", o.memory)?;
    Ok(d)
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(py_boundary_conditions, m)?)?;
    m.add_function(wrap_pyfunction!(py_bbw_dual, m)?)?;
    SOLVERS.register(m, "BBW_SOLVERS")?;
    m.add("BBW_DEFAULTS", bbw_defaults(m.py())?)?;
    m.add("BOUNDARY_TOL", DEFAULT_TOL)
}
