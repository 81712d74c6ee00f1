//! Bindings of weight reduction (`crate::reduce`). The Python layer (`skinrs/reduce.py`) checks
//! dtypes and shapes first; every check is repeated in Rust, so nothing here can panic on bad data.

use ndarray::Array2;
use numpy::{
    IntoPyArray, PyArray1, PyArray2, PyArray3, PyReadonlyArray1, PyReadonlyArray2,
    PyReadonlyArray3, PyReadonlyArray4,
};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

use pyo3::types::PyDict;

use super::{index_array, released, weights_view, Choices, PyProgress};
use crate::reduce::{self, qp, Energy, Method, Poses, ReduceOptions, Solver};

const METHODS: Choices<Method> = Choices(&[
    ("k-largest", Method::KLargest),
    ("smooth", Method::Smooth),
    ("geometric", Method::Geometric),
    ("poisson", Method::Poisson),
]);
const ENERGIES: Choices<Energy> = Choices(&[
    ("gradient", Energy::Gradient),
    ("laplacian", Energy::SquaredLaplacian),
]);
const SOLVERS: Choices<Solver> = Choices(&[
    ("auto", Solver::Auto),
    ("local", Solver::Local),
    ("cg", Solver::Cg),
]);

fn poses<'a>(
    control_points: &'a Option<PyReadonlyArray3<'_, f64>>,
    bone_transforms: &'a Option<PyReadonlyArray4<'_, f64>>,
) -> PyResult<Option<Poses<'a>>> {
    match (control_points, bone_transforms) {
        (Some(_), Some(_)) => Err(PyValueError::new_err(
            "pass either control_points or bone_transforms, not both",
        )),
        (Some(c), None) => Ok(Some(Poses::ControlPoints(c.as_array()))),
        (None, Some(t)) => Ok(Some(Poses::Bones(t.as_array()))),
        (None, None) => Ok(None),
    }
}

fn required_poses<'a>(
    control_points: &'a Option<PyReadonlyArray3<'_, f64>>,
    bone_transforms: &'a Option<PyReadonlyArray4<'_, f64>>,
) -> PyResult<Poses<'a>> {
    poses(control_points, bone_transforms)?
        .ok_or_else(|| PyValueError::new_err("pass control_points or bone_transforms"))
}

fn usize_to_i64(a: Array2<usize>) -> Array2<i64> {
    a.mapv(|x| x as i64)
}

type ReduceOut<'py> = (
    Bound<'py, PyArray2<i64>>,
    Bound<'py, PyArray2<f64>>,
    Vec<f64>,
    bool,
    usize,
    usize,
);

/// Weight reduction; returns (indices, weights, objective per sweep, converged, colours, qp_capped).
#[pyfunction]
#[pyo3(signature = (w, k, method, *, v, f, control_points, bone_transforms, c, nonnegative,
                    max_sweeps, tol, relaxation, energy, solver, callback))]
#[allow(clippy::too_many_arguments)]
fn reduce_weights<'py>(
    py: Python<'py>,
    w: PyReadonlyArray2<'py, f64>,
    k: usize,
    method: &str,
    v: Option<PyReadonlyArray2<'py, f64>>,
    f: Option<PyReadonlyArray2<'py, i64>>,
    control_points: Option<PyReadonlyArray3<'py, f64>>,
    bone_transforms: Option<PyReadonlyArray4<'py, f64>>,
    c: Option<PyReadonlyArray2<'py, f64>>,
    nonnegative: bool,
    max_sweeps: usize,
    tol: f64,
    relaxation: f64,
    energy: &str,
    solver: &str,
    callback: Option<Py<PyAny>>,
) -> PyResult<ReduceOut<'py>> {
    let method = METHODS.parse("method", method)?;
    let energy = ENERGIES.parse("energy", energy)?;
    let solver = SOLVERS.parse("solver", solver)?;
    let nv = v.as_ref().map_or(0, |v| v.as_array().nrows());
    let f = match &f {
        Some(f) => Some(index_array(f, nv, "F")?),
        None => None,
    };
    let p = poses(&control_points, &bone_transforms)?;
    let w = w.as_array();
    let v = v.as_ref().map(|v| v.as_array());
    let c = c.as_ref().map(|c| c.as_array());
    let opts = ReduceOptions {
        nonnegative,
        rest_control_points: c,
        max_sweeps,
        tol,
        relaxation,
        energy,
        solver,
    };
    let mut progress = PyProgress::new(callback);
    let r = released(py, || {
        reduce::reduce_weights(
            w,
            k,
            method,
            v,
            f.as_ref().map(|f| f.view()),
            p.as_ref(),
            &opts,
            &mut progress,
        )
    })?;
    Ok((
        usize_to_i64(r.indices).into_pyarray(py),
        r.weights.into_pyarray(py),
        r.objective,
        r.converged,
        r.colours,
        r.qp_capped,
    ))
}

/// Deformed positions `(p, n, d)` from dense weights, or packed ones when `indices` is given.
#[pyfunction]
#[pyo3(signature = (v, weights, indices=None, control_points=None, bone_transforms=None))]
fn reduce_deform<'py>(
    py: Python<'py>,
    v: PyReadonlyArray2<'py, f64>,
    weights: PyReadonlyArray2<'py, f64>,
    indices: Option<PyReadonlyArray2<'py, i64>>,
    control_points: Option<PyReadonlyArray3<'py, f64>>,
    bone_transforms: Option<PyReadonlyArray4<'py, f64>>,
) -> PyResult<Bound<'py, PyArray3<f64>>> {
    let p = required_poses(&control_points, &bone_transforms)?;
    let w = weights_view(&weights, &indices);
    let v = v.as_array();
    let x = released(py, || reduce::deform(v, &w, &p))?;
    Ok(x.into_pyarray(py))
}

/// Approximate normal transform of paper 002 Sec. 5: `(p, n, 3)`.
#[pyfunction]
#[pyo3(signature = (normals, indices, weights, control_points=None, bone_transforms=None, c=None))]
fn reduce_transform_normals<'py>(
    py: Python<'py>,
    normals: PyReadonlyArray2<'py, f64>,
    indices: PyReadonlyArray2<'py, i64>,
    weights: PyReadonlyArray2<'py, f64>,
    control_points: Option<PyReadonlyArray3<'py, f64>>,
    bone_transforms: Option<PyReadonlyArray4<'py, f64>>,
    c: Option<PyReadonlyArray2<'py, f64>>,
) -> PyResult<Bound<'py, PyArray3<f64>>> {
    let p = required_poses(&control_points, &bone_transforms)?;
    let idx = index_array(&indices, p.handles(), "indices")?;
    let (nrm, w) = (normals.as_array(), weights.as_array());
    let c = c.as_ref().map(|c| c.as_array());
    let x = released(py, || reduce::transform_normals(nrm, idx.view(), w, &p, c))?;
    Ok(x.into_pyarray(py))
}

type ErrorsOut<'py> = (Bound<'py, PyArray2<f64>>, Vec<f64>, Vec<f64>);

/// Sec. 6 metrics: (per-vertex normal angle (p, n), normal RMS (p,), position RMS % (p,)).
#[pyfunction]
fn reduce_deformation_errors<'py>(
    py: Python<'py>,
    f: PyReadonlyArray2<'py, i64>,
    full: PyReadonlyArray3<'py, f64>,
    approx: PyReadonlyArray3<'py, f64>,
) -> PyResult<ErrorsOut<'py>> {
    let (full, approx) = (full.as_array(), approx.as_array());
    let f = index_array(&f, full.shape()[1], "F")?;
    let e = released(py, || reduce::deformation_errors(f.view(), full, approx))?;
    Ok((
        e.normal_angle.into_pyarray(py),
        e.normal_rms,
        e.position_rms,
    ))
}

type QpOut<'py> = (
    Bound<'py, PyArray1<f64>>,
    Bound<'py, PyArray1<f64>>,
    Bound<'py, PyArray1<f64>>,
    usize,
    bool,
);

/// Test hook: one local QP `min 1/2 x'Hx + g'x, Ex = e, x >= 0 (optional)` from start `x0`;
/// returns (x, lambda, mu, iterations, converged).
#[pyfunction]
fn _reduce_local_qp<'py>(
    py: Python<'py>,
    h: PyReadonlyArray2<'py, f64>,
    g: PyReadonlyArray1<'py, f64>,
    e_mat: PyReadonlyArray2<'py, f64>,
    e_rhs: PyReadonlyArray1<'py, f64>,
    nonneg: bool,
    x0: PyReadonlyArray1<'py, f64>,
) -> PyResult<QpOut<'py>> {
    let (h, g, e_mat, e_rhs, x0) = (
        h.as_array(),
        g.as_array(),
        e_mat.as_array(),
        e_rhs.as_array(),
        x0.as_array(),
    );
    let k = g.len();
    let r = e_rhs.len();
    if h.dim() != (k, k) || e_mat.dim() != (r, k) || x0.len() != k || r == 0 {
        return Err(PyValueError::new_err("inconsistent local QP shapes"));
    }
    let (h, g, em, er) = (
        h.iter().copied().collect::<Vec<_>>(),
        g.to_vec(),
        e_mat.iter().copied().collect::<Vec<_>>(),
        e_rhs.to_vec(),
    );
    let mut x = x0.to_vec();
    let (mut lambda, mut mu) = (vec![0.0; r], vec![0.0; k]);
    let qp = qp::LocalQp {
        h: &h,
        g: &g,
        e_mat: &em,
        e_rhs: &er,
        nonneg,
    };
    let st = qp::solve(
        &qp,
        &mut x,
        &mut lambda,
        &mut mu,
        &mut qp::QpWork::default(),
    )
    .map_err(|e| PyValueError::new_err(format!("local QP failed: {e:?}")))?;
    Ok((
        x.into_pyarray(py),
        lambda.into_pyarray(py),
        mu.into_pyarray(py),
        st.iterations,
        st.converged,
    ))
}

/// The defaults of `reduce_weights`' options, keyed by their Python names.
fn reduce_defaults(py: Python<'_>) -> PyResult<Bound<'_, PyDict>> {
    let o = ReduceOptions::default();
    let d = PyDict::new(py);
    d.set_item("max_sweeps", o.max_sweeps)?;
    d.set_item("tol", o.tol)?;
    d.set_item("relaxation", o.relaxation)?;
    d.set_item("energy", ENERGIES.name(o.energy))?;
    d.set_item("solver", SOLVERS.name(o.solver))?;
    Ok(d)
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    METHODS.register(m, "REDUCE_METHODS")?;
    ENERGIES.register(m, "REDUCE_ENERGIES")?;
    SOLVERS.register(m, "REDUCE_SOLVERS")?;
    m.add("REDUCE_DEFAULTS", reduce_defaults(m.py())?)?;
    m.add_function(wrap_pyfunction!(reduce_weights, m)?)?;
    m.add_function(wrap_pyfunction!(reduce_deform, m)?)?;
    m.add_function(wrap_pyfunction!(reduce_transform_normals, m)?)?;
    m.add_function(wrap_pyfunction!(reduce_deformation_errors, m)?)?;
    m.add_function(wrap_pyfunction!(_reduce_local_qp, m)?)?;
    Ok(())
}
