//! PyO3 bindings: argument conversion, GIL release, progress and error mapping. No numerics here;
//! each capability has one file that wraps its Rust functions.

use std::cell::RefCell;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::time::{Duration, Instant};

use ndarray::Array2;
use numpy::{IntoPyArray, PyArray1, PyReadonlyArray2};
use pyo3::create_exception;
use pyo3::exceptions::{PyKeyboardInterrupt, PyMemoryError, PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyTuple;

use crate::error::{SkinError, SkinResult};
use crate::progress::{Event, Progress};
use crate::skin::Weights;
use crate::sparse::Csc;

mod bbw;
mod field;
mod operators;
mod reduce;
mod skin;

create_exception!(
    skinrs,
    InternalError,
    PyRuntimeError,
    "A bug in skinrs (a Rust panic caught at the binding layer), not a problem with the inputs."
);

thread_local! {
    /// The exception a progress callback raised, re-raised unchanged once the computation has
    /// stopped (so a `KeyboardInterrupt` or the user's own exception type reaches the caller).
    /// Thread-local is right because `report` runs on the thread that called the binding: the
    /// numerics get `&mut dyn Progress`, which is not `Send`, so no rayon task can capture it
    /// (tests/test_robustness.py checks the thread, also for calls from Python threads).
    static CALLBACK_ERROR: RefCell<Option<PyErr>> = const { RefCell::new(None) };
}

/// The names of a string option and the values they stand for. The bindings parse with it and
/// register the names in the module, where the Python layer reads its choice lists.
pub(crate) struct Choices<T: 'static>(pub(crate) &'static [(&'static str, T)]);

impl<T: Copy + PartialEq> Choices<T> {
    pub(crate) fn parse(&self, what: &str, s: &str) -> PyResult<T> {
        match self.0.iter().find(|(name, _)| *name == s) {
            Some(&(_, v)) => Ok(v),
            None => Err(PyValueError::new_err(format!(
                "{what} must be one of {:?}, got {s:?}",
                self.names()
            ))),
        }
    }

    pub(crate) fn name(&self, v: T) -> &'static str {
        self.0.iter().find(|(_, x)| *x == v).map_or("", |&(n, _)| n)
    }

    pub(crate) fn names(&self) -> Vec<&'static str> {
        self.0.iter().map(|&(n, _)| n).collect()
    }

    /// Adds the names to the module as the tuple `key`.
    pub(crate) fn register(&self, m: &Bound<'_, PyModule>, key: &str) -> PyResult<()> {
        m.add(key, PyTuple::new(m.py(), self.names())?)
    }
}

/// Maps the crate's error to the Python exception the user should see.
pub(crate) fn to_pyerr(e: SkinError) -> PyErr {
    match e {
        SkinError::InvalidInput(s) => PyValueError::new_err(s),
        SkinError::Interrupted => CALLBACK_ERROR
            .with(|c| c.borrow_mut().take())
            .unwrap_or_else(|| PyKeyboardInterrupt::new_err("skinrs computation interrupted")),
        SkinError::Numerical(s) => PyRuntimeError::new_err(s),
        SkinError::OutOfMemory(s) => PyMemoryError::new_err(s),
    }
}

/// The exception for a Rust panic: a bug in skinrs, with what to report.
fn panic_to_pyerr(p: Box<dyn std::any::Any + Send>) -> PyErr {
    let msg = p
        .downcast_ref::<String>()
        .cloned()
        .or_else(|| p.downcast_ref::<&str>().map(|s| s.to_string()))
        .unwrap_or_else(|| "unknown panic".into());
    InternalError::new_err(format!(
        "internal error in skinrs: {msg}. This is a bug in skinrs, not in your data; please \
         report it on the skinrs issue tracker with the skinrs version and a script (or the \
         arrays saved with numpy.save) that reproduces it. The Python process is unaffected."
    ))
}

/// Runs `f` with the GIL released: the crate's errors become Python exceptions and a panic
/// becomes [`InternalError`] instead of unwinding into Python. Every binding's work goes
/// through here.
pub(crate) fn released<T, F>(py: Python<'_>, f: F) -> PyResult<T>
where
    F: FnOnce() -> SkinResult<T> + Send,
    T: Send,
{
    match py.detach(|| catch_unwind(AssertUnwindSafe(f))) {
        Ok(r) => r.map_err(to_pyerr),
        Err(p) => Err(panic_to_pyerr(p)),
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
        CALLBACK_ERROR.with(|c| c.borrow_mut().take());
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
            py.check_signals().map_err(|e| {
                CALLBACK_ERROR.with(|c| *c.borrow_mut() = Some(e));
                SkinError::Interrupted
            })?;
            if let Some(cb) = &self.callback {
                let r = cb
                    .call1(py, (event.stage, event.iteration, event.value))
                    .map_err(|e| {
                        CALLBACK_ERROR.with(|c| *c.borrow_mut() = Some(e));
                        SkinError::Interrupted
                    })?;
                if let Ok(false) = r.extract::<bool>(py) {
                    return Err(SkinError::Interrupted);
                }
            }
            Ok(())
        })
    }
}

/// Panics inside [`released`] (for the tests: a panic must become `InternalError`).
#[pyfunction]
fn _panic_for_tests(py: Python<'_>, message: String) -> PyResult<()> {
    released(py, || -> SkinResult<()> { panic!("{message}") })
}

#[pymodule]
fn _skinrs(m: &Bound<'_, PyModule>) -> PyResult<()> {
    // Sparse factorisations run single-threaded (faster on small machines, see
    // docs/benchmarks.md); rayon parallelism is used for assembly and independent work instead.
    faer::set_global_parallelism(faer::Par::Seq);
    m.add("InternalError", m.py().get_type::<InternalError>())?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add_function(wrap_pyfunction!(_panic_for_tests, m)?)?;
    operators::register(m)?;
    bbw::register(m)?;
    skin::register(m)?;
    reduce::register(m)?;
    field::register(m)?;
    Ok(())
}
