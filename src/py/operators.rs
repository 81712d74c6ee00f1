//! Bindings for `crate::operators`: cotangent Laplacian, mass matrix, biharmonic matrix and
//! connected components. Arguments arrive already shaped by `skinrs.operators`; indices are
//! re-checked here so no Rust code ever sees an out-of-range index.

use numpy::{IntoPyArray, PyArray1, PyReadonlyArray2};
use pyo3::prelude::*;

use super::{index_array, released, sparse_out, Choices, SparseParts};
use crate::operators::{self, MassKind};

const MASS_KINDS: Choices<MassKind> = Choices(&[
    ("voronoi", MassKind::Voronoi),
    ("barycentric", MassKind::Barycentric),
]);

#[pyfunction]
fn _cotan_laplacian<'py>(
    py: Python<'py>,
    v: PyReadonlyArray2<'py, f64>,
    f: PyReadonlyArray2<'py, i64>,
) -> PyResult<SparseParts<'py>> {
    let vv = v.as_array();
    let ff = index_array(&f, vv.nrows(), "F")?;
    let l = released(py, || operators::cotan_laplacian(vv, ff.view()))?;
    Ok(sparse_out(py, &l))
}

#[pyfunction]
fn _massmatrix<'py>(
    py: Python<'py>,
    v: PyReadonlyArray2<'py, f64>,
    f: PyReadonlyArray2<'py, i64>,
    kind: &str,
) -> PyResult<Bound<'py, PyArray1<f64>>> {
    let kind = MASS_KINDS.parse("mass kind", kind)?;
    let vv = v.as_array();
    let ff = index_array(&f, vv.nrows(), "F")?;
    let m = released(py, || operators::massmatrix(vv, ff.view(), kind))?;
    Ok(m.into_pyarray(py))
}

#[pyfunction]
fn _biharmonic_matrix<'py>(
    py: Python<'py>,
    v: PyReadonlyArray2<'py, f64>,
    f: PyReadonlyArray2<'py, i64>,
    kind: &str,
) -> PyResult<SparseParts<'py>> {
    let kind = MASS_KINDS.parse("mass kind", kind)?;
    let vv = v.as_array();
    let ff = index_array(&f, vv.nrows(), "F")?;
    let b = released(py, || operators::biharmonic_matrix(vv, ff.view(), kind))?;
    Ok(sparse_out(py, &b))
}

#[pyfunction]
fn _connected_components<'py>(
    py: Python<'py>,
    n: usize,
    f: PyReadonlyArray2<'py, i64>,
) -> PyResult<(usize, Bound<'py, PyArray1<i64>>)> {
    let ff = index_array(&f, n, "F")?;
    let (count, labels) = released(py, || Ok(operators::connected_components(n, ff.view())))?;
    let labels: Vec<i64> = labels.into_iter().map(|x| x as i64).collect();
    Ok((count, labels.into_pyarray(py)))
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(_cotan_laplacian, m)?)?;
    m.add_function(wrap_pyfunction!(_massmatrix, m)?)?;
    m.add_function(wrap_pyfunction!(_biharmonic_matrix, m)?)?;
    m.add_function(wrap_pyfunction!(_connected_components, m)?)?;
    MASS_KINDS.register(m, "MASS_KINDS")
}
