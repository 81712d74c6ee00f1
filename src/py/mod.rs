//! PyO3 bindings: argument conversion, GIL release, progress and error mapping. No numerics here;
//! each capability has one file that wraps its Rust functions.

use std::time::{Duration, Instant};

use ndarray::Array2;
use numpy::{IntoPyArray, PyArray1, PyReadonlyArray2};
use pyo3::exceptions::{PyKeyboardInterrupt, PyRuntimeError, PyValueError};
use pyo3::prelude::*;

use crate::error::{SkinError, SkinResult};
use crate::progress::{Event, Progress};
use crate::skin::Weights;
use crate::sparse::Csc;

mod bbw;
mod field;
mod operators;
mod reduce;
mod skin;

/// Maps the crate's error to the Python exception the user should see.
pub(crate) fn to_pyerr(e: SkinError) -> PyErr {
    match e {
        SkinError::InvalidInput(s) => PyValueError::new_err(s),
        SkinError::Interrupted => PyKeyboardInterrupt::new_err("skinrs computation interrupted"),
        SkinError::Numerical(s) => PyRuntimeError::new_err(s),
    }
}

/// Converts integer element/index arrays to `usize`, checking every entry lies in `0..n`.
pub(crate) fn index_array(
    a: &PyReadonlyArray2<'_, i64>,
    n: usize,
    what: &str,
) -> PyResult<Array2<usize>> {
    let a = a.as_array();
    let mut out = Array2::<usize>::zeros(a.dim());
    for (o, &x) in out.iter_mut().zip(a.iter()) {
        if x < 0 || x as u64 >= n as u64 {
            return Err(PyValueError::new_err(format!(
                "{what} holds index {x}, outside 0..{n}"
            )));
        }
        *o = x as usize;
    }
    Ok(out)
}

/// Skinning weights from the arrays of a binding: dense `w (n, m)`, or packed when the handle
/// indices `index (n, k)` come with `w (n, k)` (their range is checked by the skinning code).
pub(crate) fn weights_view<'a>(
    w: &'a PyReadonlyArray2<'_, f64>,
    index: &'a Option<PyReadonlyArray2<'_, i64>>,
) -> Weights<'a> {
    match index {
        Some(i) => Weights::Packed {
            index: i.as_array(),
            weight: w.as_array(),
        },
        None => Weights::Dense(w.as_array()),
    }
}

/// CSC parts `(data, indices, indptr, shape)` that the Python layer wraps in `scipy.sparse.csc_matrix`.
pub(crate) type SparseParts<'py> = (
    Bound<'py, PyArray1<f64>>,
    Bound<'py, PyArray1<i64>>,
    Bound<'py, PyArray1<i64>>,
    (usize, usize),
);

pub(crate) fn sparse_out<'py>(py: Python<'py>, m: &Csc) -> SparseParts<'py> {
    let sym = m.symbolic();
    let indptr: Vec<i64> = sym.col_ptr().iter().map(|&x| x as i64).collect();
    let indices: Vec<i64> = sym.row_idx().iter().map(|&x| x as i64).collect();
    let data: Vec<f64> = m.val().to_vec();
    (
        data.into_pyarray(py),
        indices.into_pyarray(py),
        indptr.into_pyarray(py),
        (m.nrows(), m.ncols()),
    )
}

/// Progress sink used while the GIL is released: every ~100 ms it takes the GIL, checks for
/// Ctrl-C and calls the user's `callback(stage, iteration, value)`; a callback returning
/// `False` stops the computation.
pub(crate) struct PyProgress {
    callback: Option<Py<PyAny>>,
    last: Instant,
    every: Duration,
}

impl PyProgress {
    pub(crate) fn new(callback: Option<Py<PyAny>>) -> Self {
        let every = Duration::from_millis(100);
        PyProgress {
            callback,
            last: Instant::now() - every,
            every,
        }
    }
}

impl Progress for PyProgress {
    fn report(&mut self, event: Event<'_>) -> SkinResult<()> {
        if self.last.elapsed() < self.every {
            return Ok(());
        }
        self.last = Instant::now();
        Python::attach(|py| {
            py.check_signals().map_err(|_| SkinError::Interrupted)?;
            if let Some(cb) = &self.callback {
                let r = cb
                    .call1(py, (event.stage, event.iteration, event.value))
                    .map_err(|e| {
                        SkinError::InvalidInput(format!("progress callback raised: {e}"))
                    })?;
                if let Ok(false) = r.extract::<bool>(py) {
                    return Err(SkinError::Interrupted);
                }
            }
            Ok(())
        })
    }
}

#[pymodule]
fn _skinrs(m: &Bound<'_, PyModule>) -> PyResult<()> {
    // Sparse factorisations run single-threaded: on small machines two threads were slower;
    // rayon parallelism is used for assembly and independent work instead.
    faer::set_global_parallelism(faer::Par::Seq);
    operators::register(m)?;
    bbw::register(m)?;
    skin::register(m)?;
    reduce::register(m)?;
    field::register(m)?;
    Ok(())
}
