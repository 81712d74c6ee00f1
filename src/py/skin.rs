//! Bindings of `crate::skin`: LBS, DQS, forward kinematics, vertex normals.
//!
//! Arrays come in as read-only numpy views (no copy when the Python layer passes C-contiguous
//! float64 / int64); results are moved into numpy without a copy.
#![allow(non_snake_case)]

use ndarray::Array2;
use numpy::{
    IntoPyArray, PyArray1, PyArray2, PyArray3, PyArrayMethods, PyReadonlyArray2, PyReadonlyArray3,
    PyUntypedArrayMethods,
};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

use super::{index_array, released, weights_view};
use crate::skin;

type Deformed<'py> = (Bound<'py, PyArray2<f64>>, Option<Bound<'py, PyArray2<f64>>>);

#[derive(Clone, Copy)]
enum Method {
    Lbs,
    Dqs,
}

#[allow(clippy::too_many_arguments)]
fn skin_any<'py>(
    py: Python<'py>,
    method: Method,
    V: PyReadonlyArray2<'py, f64>,
    W: PyReadonlyArray2<'py, f64>,
    T: PyReadonlyArray3<'py, f64>,
    index: Option<PyReadonlyArray2<'py, i64>>,
    N: Option<PyReadonlyArray2<'py, f64>>,
    out: Option<Bound<'py, PyArray2<f64>>>,
) -> PyResult<Deformed<'py>> {
    let (v, t) = (V.as_array(), T.as_array());
    let n = N.as_ref().map(|a| a.as_array());
    let weights = weights_view(&W, &index);
    let fresh = out.is_none();
    let out = match out {
        Some(o) => o,
        None => PyArray2::<f64>::zeros(py, v.dim(), false),
    };
    let mut nout = n.map(|_| Array2::<f64>::zeros(v.dim()));
    {
        let mut guard = out.try_readwrite().map_err(|_| {
            PyValueError::new_err("out must be a writeable array that does not overlap the inputs")
        })?;
        if !fresh && !guard.is_c_contiguous() {
            return Err(PyValueError::new_err(
                "out must be a C-contiguous float64 array",
            ));
        }
        let o = guard.as_array_mut();
        let no = nout.as_mut().map(|a| a.view_mut());
        released(py, || match method {
            Method::Lbs => skin::lbs_into(v, &weights, t, n, o, no),
            Method::Dqs => skin::dqs_into(v, &weights, t, n, o, no),
        })?;
    }
    Ok((out, nout.map(|a| a.into_pyarray(py))))
}

/// Linear blend skinning; packed weights when `index` is given. Returns `(U, N_out or None)`;
/// `U` is `out` when given.
#[pyfunction]
#[pyo3(signature = (V, W, T, index=None, N=None, out=None))]
#[allow(clippy::too_many_arguments)]
fn lbs<'py>(
    py: Python<'py>,
    V: PyReadonlyArray2<'py, f64>,
    W: PyReadonlyArray2<'py, f64>,
    T: PyReadonlyArray3<'py, f64>,
    index: Option<PyReadonlyArray2<'py, i64>>,
    N: Option<PyReadonlyArray2<'py, f64>>,
    out: Option<Bound<'py, PyArray2<f64>>>,
) -> PyResult<Deformed<'py>> {
    skin_any(py, Method::Lbs, V, W, T, index, N, out)
}

/// Dual-quaternion skinning; packed weights when `index` is given. Returns `(U, N_out or None)`;
/// `U` is `out` when given.
#[pyfunction]
#[pyo3(signature = (V, W, T, index=None, N=None, out=None))]
#[allow(clippy::too_many_arguments)]
fn dqs<'py>(
    py: Python<'py>,
    V: PyReadonlyArray2<'py, f64>,
    W: PyReadonlyArray2<'py, f64>,
    T: PyReadonlyArray3<'py, f64>,
    index: Option<PyReadonlyArray2<'py, i64>>,
    N: Option<PyReadonlyArray2<'py, f64>>,
    out: Option<Bound<'py, PyArray2<f64>>>,
) -> PyResult<Deformed<'py>> {
    skin_any(py, Method::Dqs, V, W, T, index, N, out)
}

/// Absolute `(m, 3, 4)` bone transforms from relative `(w, x, y, z)` rotations.
#[pyfunction]
fn forward_kinematics<'py>(
    py: Python<'py>,
    C: PyReadonlyArray2<'py, f64>,
    BE: PyReadonlyArray2<'py, i64>,
    Q: PyReadonlyArray2<'py, f64>,
) -> PyResult<Bound<'py, PyArray3<f64>>> {
    let c = C.as_array();
    let be = index_array(&BE, c.nrows(), "BE")?;
    let q = Q.as_array();
    let t = released(py, || skin::forward_kinematics(c, be.view(), q))?;
    Ok(t.into_pyarray(py))
}

/// Parent bone of each bone (-1 for roots).
#[pyfunction]
fn bone_parents<'py>(
    py: Python<'py>,
    BE: PyReadonlyArray2<'py, i64>,
    n_joints: usize,
) -> PyResult<Bound<'py, PyArray1<i64>>> {
    let be = index_array(&BE, n_joints, "BE")?;
    let p = released(py, || skin::bone_parents(be.view(), n_joints))?;
    let p: Vec<i64> = p.iter().map(|q| q.map_or(-1, |b| b as i64)).collect();
    Ok(p.into_pyarray(py))
}

/// Area-weighted vertex normals of a triangle mesh.
#[pyfunction]
fn per_vertex_normals<'py>(
    py: Python<'py>,
    V: PyReadonlyArray2<'py, f64>,
    F: PyReadonlyArray2<'py, i64>,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let v = V.as_array();
    let f = index_array(&F, v.nrows(), "F")?;
    let n = released(py, || skin::per_vertex_normals(v, f.view()))?;
    Ok(n.into_pyarray(py))
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(lbs, m)?)?;
    m.add_function(wrap_pyfunction!(dqs, m)?)?;
    m.add_function(wrap_pyfunction!(forward_kinematics, m)?)?;
    m.add_function(wrap_pyfunction!(bone_parents, m)?)?;
    m.add_function(wrap_pyfunction!(per_vertex_normals, m)?)?;
    Ok(())
}
