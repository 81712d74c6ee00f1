//! Bindings for `crate::field`: winding numbers, segment visibility, closest points and
//! k-nearest-neighbour distances. Arguments arrive already checked and shaped by
//! `skinrs.field`; indices are re-checked here and the dimension (2 or 3) picks the Rust type.
//! The tree is built and queried with the GIL released.

use ndarray::{Array2, ArrayView2};
use numpy::{IntoPyArray, PyArray1, PyArray2, PyReadonlyArray2};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

use super::{index_array, to_pyerr};
use crate::error::SkinResult;
use crate::field::{self, Boundary, BoundaryQueries, Closest, FastWinding};

fn dim(v: &ArrayView2<f64>, f: &Array2<usize>) -> PyResult<usize> {
    match (v.ncols(), f.ncols()) {
        (3, 3) => Ok(3),
        (2, 2) => Ok(2),
        (a, b) => Err(PyValueError::new_err(format!(
            "V with {a} columns needs F with {a} columns (triangles in 3D, segments in 2D), got {b}"
        ))),
    }
}

#[pyfunction]
fn _winding_number<'py>(
    py: Python<'py>,
    v: PyReadonlyArray2<'py, f64>,
    f: PyReadonlyArray2<'py, i64>,
    q: PyReadonlyArray2<'py, f64>,
    beta: f64,
) -> PyResult<Bound<'py, PyArray1<f64>>> {
    let (vv, qq) = (v.as_array(), q.as_array());
    let ff = index_array(&f, vv.nrows(), "F")?;
    let d = dim(&vv, &ff)?;
    let w = py
        .detach(|| -> SkinResult<Vec<f64>> {
            if d == 3 {
                FastWinding::<3>::new(vv, ff.view(), beta)?.eval_batch(qq)
            } else {
                FastWinding::<2>::new(vv, ff.view(), beta)?.eval_batch(qq)
            }
        })
        .map_err(to_pyerr)?;
    Ok(w.into_pyarray(py))
}

#[pyfunction]
fn _segment_hits<'py>(
    py: Python<'py>,
    v: PyReadonlyArray2<'py, f64>,
    f: PyReadonlyArray2<'py, i64>,
    p: PyReadonlyArray2<'py, f64>,
    q: PyReadonlyArray2<'py, f64>,
) -> PyResult<Bound<'py, PyArray1<bool>>> {
    let (vv, pp, qq) = (v.as_array(), p.as_array(), q.as_array());
    let ff = index_array(&f, vv.nrows(), "F")?;
    let d = dim(&vv, &ff)?;
    let hits = py
        .detach(|| -> SkinResult<Vec<bool>> {
            if d == 3 {
                Boundary::<3>::new(vv, ff.view())?.segment_hits_batch(pp, qq)
            } else {
                Boundary::<2>::new(vv, ff.view())?.segment_hits_batch(pp, qq)
            }
        })
        .map_err(to_pyerr)?;
    Ok(hits.into_pyarray(py))
}

type ClosestOut<'py> = (
    Bound<'py, PyArray1<f64>>,
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyArray1<i64>>,
    Bound<'py, PyArray2<f64>>,
);

struct ClosestArrays {
    dist: Vec<f64>,
    point: Array2<f64>,
    face: Vec<i64>,
    normal: Array2<f64>,
}

fn unpack<const D: usize>(c: Vec<Closest<D>>) -> ClosestArrays {
    let n = c.len();
    ClosestArrays {
        dist: c.iter().map(|x| x.dist).collect(),
        point: Array2::from_shape_fn((n, D), |(i, k)| c[i].point[k]),
        face: c.iter().map(|x| x.prim as i64).collect(),
        normal: Array2::from_shape_fn((n, D), |(i, k)| c[i].normal[k]),
    }
}

#[pyfunction]
fn _closest_point<'py>(
    py: Python<'py>,
    v: PyReadonlyArray2<'py, f64>,
    f: PyReadonlyArray2<'py, i64>,
    q: PyReadonlyArray2<'py, f64>,
) -> PyResult<ClosestOut<'py>> {
    let (vv, qq) = (v.as_array(), q.as_array());
    let ff = index_array(&f, vv.nrows(), "F")?;
    let d = dim(&vv, &ff)?;
    let r = py
        .detach(|| -> SkinResult<ClosestArrays> {
            Ok(if d == 3 {
                unpack(Boundary::<3>::new(vv, ff.view())?.closest_batch(qq)?)
            } else {
                unpack(Boundary::<2>::new(vv, ff.view())?.closest_batch(qq)?)
            })
        })
        .map_err(to_pyerr)?;
    Ok((
        r.dist.into_pyarray(py),
        r.point.into_pyarray(py),
        r.face.into_pyarray(py),
        r.normal.into_pyarray(py),
    ))
}

#[pyfunction]
fn _knn_distance<'py>(
    py: Python<'py>,
    x: PyReadonlyArray2<'py, f64>,
    k: usize,
) -> PyResult<Bound<'py, PyArray1<f64>>> {
    let xx = x.as_array();
    let d = py.detach(|| field::knn_distance(xx, k)).map_err(to_pyerr)?;
    Ok(d.into_pyarray(py))
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(_winding_number, m)?)?;
    m.add_function(wrap_pyfunction!(_segment_hits, m)?)?;
    m.add_function(wrap_pyfunction!(_closest_point, m)?)?;
    m.add_function(wrap_pyfunction!(_knn_distance, m)?)?;
    Ok(())
}
