//! Bindings for `crate::field`: winding numbers, segment visibility, closest points and
//! k-nearest-neighbour distances. Arguments arrive already checked and shaped by
//! `skinrs.field`; indices are re-checked here and the dimension (2 or 3) picks the Rust type.
//! The tree is built and queried with the GIL released.

use ndarray::{Array2, ArrayView2};
use numpy::{IntoPyArray, PyArray1, PyArray2, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;

use super::{index_array, released, PyProgress};
use crate::error::SkinResult;
use crate::field::{self, Boundary, BoundaryQueries, Closest, FastWinding};
use crate::field::{FieldOptions, GeometricField};

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
    let w = released(py, || -> SkinResult<Vec<f64>> {
        if d == 3 {
            FastWinding::<3>::new(vv, ff.view(), beta)?.eval_batch(qq)
        } else {
            FastWinding::<2>::new(vv, ff.view(), beta)?.eval_batch(qq)
        }
    })?;
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
    let hits = released(py, || -> SkinResult<Vec<bool>> {
        if d == 3 {
            Boundary::<3>::new(vv, ff.view())?.segment_hits_batch(pp, qq)
        } else {
            Boundary::<2>::new(vv, ff.view())?.segment_hits_batch(pp, qq)
        }
    })?;
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
    let r = released(py, || -> SkinResult<ClosestArrays> {
        Ok(if d == 3 {
            unpack(Boundary::<3>::new(vv, ff.view())?.closest_batch(qq)?)
        } else {
            unpack(Boundary::<2>::new(vv, ff.view())?.closest_batch(qq)?)
        })
    })?;
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
    let mut progress = PyProgress::new(None);
    let d = released(py, || field::knn_distance(xx, k, &mut progress))?;
    Ok(d.into_pyarray(py))
}

/// A geometric field in 2D or 3D.
enum Inner {
    D2(Box<GeometricField<2>>),
    D3(Box<GeometricField<3>>),
}

/// Calls `$body` with `$g` bound to the field of either dimension (`$d` its dimension).
macro_rules! with_field {
    ($inner:expr, $g:ident, $body:expr) => {
        match $inner {
            Inner::D2($g) => $body,
            Inner::D3($g) => $body,
        }
    };
}

/// The field state behind `skinrs.GeometricField` (argument checks live in Python).
#[pyclass(name = "_GeometricField", module = "skinrs._skinrs")]
pub struct PyGeometricField {
    inner: Inner,
}

fn opt<'py, T: for<'a> FromPyObject<'a, 'py>>(
    d: &Bound<'py, PyDict>,
    key: &str,
    default: T,
) -> PyResult<T> {
    match d.get_item(key)? {
        Some(v) if !v.is_none() => v
            .extract::<T>()
            .map_err(|_| PyValueError::new_err(format!("option {key} has the wrong type"))),
        _ => Ok(default),
    }
}

/// App. A defaults of the field options for dimension `d`, keyed by their Python names (those
/// [`options`] reads).
#[pyfunction]
fn _field_defaults(py: Python<'_>, d: usize) -> PyResult<Bound<'_, PyDict>> {
    let x = FieldOptions::defaults(d);
    let o = PyDict::new(py);
    o.set_item("n_points", x.n_init)?;
    o.set_item("samples", x.samples)?;
    o.set_item("steps", x.steps)?;
    o.set_item("upsamples", x.upsamples)?;
    o.set_item("lr", x.lr)?;
    o.set_item("lr_decay", x.lr_decay)?;
    o.set_item("beta1", x.beta1)?;
    o.set_item("beta2", x.beta2)?;
    o.set_item("adam_eps", x.adam_eps)?;
    o.set_item("h", x.h_sigma)?;
    o.set_item("eps", x.eps_sigma)?;
    o.set_item("neumann", x.neumann)?;
    o.set_item("visibility", x.visibility)?;
    o.set_item("wn_l", x.wn_l)?;
    o.set_item("wn_h", x.wn_h)?;
    o.set_item("seed", x.seed)?;
    o.set_item("pool", x.pool)?;
    o.set_item("cache_visibility", x.cache_visibility)?;
    o.set_item("skip_rays", x.skip_rays)?;
    Ok(o)
}

fn options(d: usize, o: &Bound<'_, PyDict>) -> PyResult<FieldOptions> {
    let x = FieldOptions::defaults(d);
    Ok(FieldOptions {
        n_init: opt(o, "n_points", x.n_init)?,
        samples: opt(o, "samples", x.samples)?,
        steps: opt(o, "steps", x.steps)?,
        upsamples: opt(o, "upsamples", x.upsamples)?,
        lr: opt(o, "lr", x.lr)?,
        lr_decay: opt(o, "lr_decay", x.lr_decay)?,
        beta1: opt(o, "beta1", x.beta1)?,
        beta2: opt(o, "beta2", x.beta2)?,
        adam_eps: opt(o, "adam_eps", x.adam_eps)?,
        h_sigma: opt(o, "h", x.h_sigma)?,
        eps_sigma: opt(o, "eps", x.eps_sigma)?,
        neumann: opt(o, "neumann", x.neumann)?,
        visibility: opt(o, "visibility", x.visibility)?,
        wn_l: opt(o, "wn_l", x.wn_l)?,
        wn_h: opt(o, "wn_h", x.wn_h)?,
        seed: opt(o, "seed", x.seed)?,
        pool: opt(o, "pool", x.pool)?,
        cache_visibility: opt(o, "cache_visibility", x.cache_visibility)?,
        skip_rays: opt(o, "skip_rays", x.skip_rays)?,
    })
}

/// Handle primitives `(a, b, column)`: point handles first, then bones (libigl's order).
fn handles<const D: usize>(
    c: &ArrayView2<f64>,
    p: &[usize],
    be: &Array2<usize>,
) -> Vec<([f64; D], [f64; D], usize)> {
    let pt = |i: usize| -> [f64; D] { std::array::from_fn(|k| c[[i, k]]) };
    let mut h: Vec<_> = p
        .iter()
        .enumerate()
        .map(|(j, &i)| (pt(i), pt(i), j))
        .collect();
    for (e, r) in be.rows().into_iter().enumerate() {
        h.push((pt(r[0]), pt(r[1]), p.len() + e));
    }
    h
}

fn points<const D: usize>(q: &ArrayView2<f64>) -> Vec<[f64; D]> {
    (0..q.nrows())
        .map(|i| std::array::from_fn(|k| q[[i, k]]))
        .collect()
}

type WeightsOut<'py> = (Bound<'py, PyArray2<f64>>, Bound<'py, PyArray1<u8>>);

#[pymethods]
impl PyGeometricField {
    #[new]
    #[pyo3(signature = (v, f, simplices, c, p, be, opts))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        py: Python<'_>,
        v: PyReadonlyArray2<'_, f64>,
        f: Option<PyReadonlyArray2<'_, i64>>,
        simplices: Option<PyReadonlyArray2<'_, i64>>,
        c: PyReadonlyArray2<'_, f64>,
        p: PyReadonlyArray1<'_, i64>,
        be: PyReadonlyArray2<'_, i64>,
        opts: &Bound<'_, PyDict>,
    ) -> PyResult<Self> {
        let vv = v.as_array();
        let n = vv.nrows();
        let d = vv.ncols();
        if d != 2 && d != 3 {
            return Err(PyValueError::new_err("V must have 2 or 3 columns"));
        }
        let ff = f.map(|f| index_array(&f, n, "F")).transpose()?;
        let ss = simplices.map(|s| index_array(&s, n, "tets")).transpose()?;
        let cc = c.as_array();
        let pp: Vec<usize> = p
            .as_array()
            .iter()
            .map(|&i| {
                if i < 0 || i as usize >= cc.nrows() {
                    Err(PyValueError::new_err(format!(
                        "P holds index {i} outside C"
                    )))
                } else {
                    Ok(i as usize)
                }
            })
            .collect::<PyResult<_>>()?;
        let bb = index_array(&be, cc.nrows(), "BE")?;
        let k = pp.len() + bb.nrows();
        let o = options(d, opts)?;
        let inner = released(py, || {
            let fv = ff.as_ref().map(|x| x.view());
            let sv = ss.as_ref().map(|x| x.view());
            Ok(if d == 2 {
                let h = handles::<2>(&cc, &pp, &bb);
                Inner::D2(Box::new(GeometricField::new(vv, fv, sv, h, k, o)?))
            } else {
                let h = handles::<3>(&cc, &pp, &bb);
                Inner::D3(Box::new(GeometricField::new(vv, fv, sv, h, k, o)?))
            })
        })?;
        Ok(PyGeometricField { inner })
    }

    /// Runs Adam steps (see `GeometricField::optimize`).
    #[pyo3(signature = (steps, resume, callback=None))]
    fn optimize(
        &mut self,
        py: Python<'_>,
        steps: Option<usize>,
        resume: usize,
        callback: Option<Py<PyAny>>,
    ) -> PyResult<()> {
        let mut progress = PyProgress::new(callback);
        let inner = &mut self.inner;
        released(py, || {
            with_field!(inner, g, g.optimize(steps, resume, &mut progress))
        })
    }

    /// Adds painted Dirichlet points (input units) with weight rows.
    fn paint(
        &mut self,
        py: Python<'_>,
        q: PyReadonlyArray2<'_, f64>,
        w: PyReadonlyArray2<'_, f64>,
    ) -> PyResult<()> {
        let (q, w) = (q.as_array(), w.as_array());
        let wf: Vec<f64> = w.iter().copied().collect();
        let inner = &mut self.inner;
        released(py, || {
            with_field!(inner, g, {
                let pts = points(&q);
                g.paint(&pts, &wf)
            })
        })
    }

    /// Weights and status at query points (input units).
    fn evaluate<'py>(
        &self,
        py: Python<'py>,
        q: PyReadonlyArray2<'py, f64>,
    ) -> PyResult<WeightsOut<'py>> {
        let q = q.as_array();
        let inner = &self.inner;
        let mut progress = PyProgress::new(None);
        let (w, s) = released(py, || with_field!(inner, g, g.evaluate(q, &mut progress)))?;
        Ok((w.into_pyarray(py), s.into_pyarray(py)))
    }

    /// Weights and status at vertices, with normal elements and adjacency elements.
    fn vertex_weights<'py>(
        &self,
        py: Python<'py>,
        v: PyReadonlyArray2<'py, f64>,
        normal_elems: PyReadonlyArray2<'py, i64>,
        adj: PyReadonlyArray2<'py, i64>,
    ) -> PyResult<WeightsOut<'py>> {
        let v = v.as_array();
        let n = v.nrows();
        let ne = index_array(&normal_elems, n, "F")?;
        let ad = index_array(&adj, n, "F")?;
        let inner = &self.inner;
        let (w, s) = released(py, || {
            Ok(with_field!(
                inner,
                g,
                g.vertex_weights(v, ne.view(), ad.view())
            ))
        })?;
        Ok((w.into_pyarray(py), s.into_pyarray(py)))
    }

    /// Energy and gradient at parameters `f` (N by K) with the Monte-Carlo samples of `step`.
    fn energy<'py>(
        &mut self,
        py: Python<'py>,
        f: PyReadonlyArray2<'py, f64>,
        step: u64,
    ) -> PyResult<(f64, Bound<'py, PyArray2<f64>>)> {
        let fa = f.as_array();
        let (n, k) = fa.dim();
        let flat: Vec<f64> = fa.iter().copied().collect();
        let inner = &mut self.inner;
        let (e, g) = released(py, || with_field!(inner, g, g.energy_at(&flat, step)))?;
        let g =
            Array2::from_shape_vec((n, k), g).map_err(|e| PyValueError::new_err(e.to_string()))?;
        Ok((e, g.into_pyarray(py)))
    }

    /// Parameters f (N by K).
    fn params<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        let (f, k) = with_field!(&self.inner, g, (g.f.clone(), g.k()));
        let n = f.len() / k;
        Array2::from_shape_vec((n, k), f)
            .expect("N by K")
            .into_pyarray(py)
    }

    /// The field's points in input units (N by D).
    fn points<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        with_field!(&self.inner, g, {
            let d = g.points.x[0].len();
            let x = &g.points.x;
            Array2::from_shape_fn((x.len(), d), |(i, c)| x[i][c] / g.scale + g.offset[c])
                .into_pyarray(py)
        })
    }

    /// Diagnostics as a dict.
    fn info<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        with_field!(&self.inner, g, {
            d.set_item("n_points", g.points.len())?;
            d.set_item("sigma", g.points.sigma / g.scale)?;
            d.set_item("sigma_unit", g.points.sigma)?;
            d.set_item("step", g.step)?;
            d.set_item("level", g.level)?;
            d.set_item("lr", g.lr)?;
            d.set_item("volume_unit", g.domain.volume)?;
            d.set_item("energy", g.stats.last_energy)?;
            d.set_item("pairs", g.stats.rays.pairs)?;
            d.set_item("rays", g.stats.rays.rays)?;
            d.set_item("time_visibility", g.stats.rays.seconds)?;
            d.set_item("time_energy", g.stats.seconds_energy)?;
            d.set_item("time_optimize", g.stats.seconds_total)?;
            d.set_item("n_painted", g.cons.painted.len())?;
            d.set_item("pool", g.pool.len())?;
            d.set_item("schedule_steps", g.opts.steps)?;
        });
        Ok(d)
    }
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyGeometricField>()?;
    m.add_function(wrap_pyfunction!(_winding_number, m)?)?;
    m.add_function(wrap_pyfunction!(_segment_hits, m)?)?;
    m.add_function(wrap_pyfunction!(_closest_point, m)?)?;
    m.add_function(wrap_pyfunction!(_knn_distance, m)?)?;
    m.add_function(wrap_pyfunction!(_field_defaults, m)?)?;
    Ok(())
}
