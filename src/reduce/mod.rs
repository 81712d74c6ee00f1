//! Weight reduction (Landreneau & Schaefer 2010, "Poisson-based weight reduction of animated
//! meshes", paper 002): keep `k` influences per vertex that still deform like the full weights.
//!
//! - [`reduce_weights`]: the k-largest baseline, smooth (Sec. 3.1), geometric (3.2, eq. 3) and
//!   Poisson (3.3, eq. 5) reductions for cages (control points) and skeletons (Sec. 4), solved by
//!   the parallel local iteration of Sec. 3.1 ([`local`]) with exact per-vertex QPs ([`qp`]),
//!   or without bounds by preconditioned conjugate gradients ([`cg`], [`coarse`]); [`solver`]
//!   describes the method and chooses the iteration.
//! - [`deform`] (the shared linear blend skinning over all example poses),
//!   [`transform_normals`] (Sec. 5) and [`deformation_errors`] (Sec. 6).

#![allow(clippy::needless_range_loop)] // index loops mirror the formulas

mod basis;
mod blocks;
mod cg;
mod coarse;
mod coupling;
mod deform;
mod iteration;
mod local;
mod problem;
pub(crate) mod qp;
mod solver;

use ndarray::{Array2, ArrayView2, Axis, CowArray, Ix2};
use rayon::prelude::*;

use crate::error::SkinResult;
use crate::invalid;
use crate::operators::{self, MassKind};
use crate::progress::Progress;

use basis::Basis;
use coupling::Coupling;
pub use deform::{deform, deformation_errors, transform_normals, DeformationErrors, Poses};
use iteration::SolveOptions;
use problem::{LinearPrecision, Problem};
pub use solver::Solver;

/// Which weights to keep and how to set them.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Method {
    /// The k largest weights, renormalised to sum to one (what exporters do).
    KLargest,
    /// Sec. 3.1: match the Laplacian of every reduced weight function to the original's.
    Smooth,
    /// Sec. 3.2, eq. (3): match the example-pose positions.
    Geometric,
    /// Sec. 3.3, eq. (5) (and Sec. 4 for skeletons): match the Laplacian of the deformed positions.
    Poisson,
}

impl Method {
    /// Parses `"k-largest"`, `"smooth"`, `"geometric"` or `"poisson"`.
    pub fn parse(s: &str) -> SkinResult<Self> {
        match s {
            "k-largest" => Ok(Method::KLargest),
            "smooth" => Ok(Method::Smooth),
            "geometric" => Ok(Method::Geometric),
            "poisson" => Ok(Method::Poisson),
            _ => invalid!(
                "unknown reduction method {s:?}: use 'k-largest', 'smooth', 'geometric' or 'poisson'"
            ),
        }
    }
}

/// How the smooth and Poisson methods measure the difference of two functions on the surface.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Energy {
    /// `int |grad (phi - psi)|^2 dA = e^T (-L) e`: the Poisson problem of Sec. 3.3 in its
    /// gradient form `min int |grad phi - w|^2`, `w = grad psi`.
    Gradient,
    /// `int (lap (phi - psi))^2 dA ~ e^T L M^-1 L e`: eqs. (4)-(5) as printed.
    SquaredLaplacian,
}

impl Energy {
    /// Parses `"gradient"` or `"laplacian"`.
    pub fn parse(s: &str) -> SkinResult<Self> {
        match s {
            "gradient" => Ok(Energy::Gradient),
            "laplacian" => Ok(Energy::SquaredLaplacian),
            _ => invalid!("unknown energy {s:?}: use 'gradient' or 'laplacian'"),
        }
    }
}

/// Settings of [`reduce_weights`].
#[derive(Debug, Clone)]
pub struct ReduceOptions<'a> {
    /// Keep every weight `>= 0` (skeletal rigs, harmonic and BBW weights).
    pub nonnegative: bool,
    /// Rest control points `C (m, d)` of a cage: the smooth method then enforces linear precision
    /// `sum_i alpha_i c_i = v`. Only the smooth method uses them.
    pub rest_control_points: Option<ArrayView2<'a, f64>>,
    /// Upper bound on the sweeps of the local iteration.
    pub max_sweeps: usize,
    /// Stop when the mean decrease of the objective over the last (up to 4) sweeps is at most
    /// `tol` times its decrease since the start (see `iteration::should_stop`).
    pub tol: f64,
    /// Over-relaxation factor of each block step, in (0, 2); 1 is plain block Gauss-Seidel.
    pub relaxation: f64,
    /// Energy of the smooth and Poisson methods.
    pub energy: Energy,
    /// Iteration for coupled problems (smooth, Poisson).
    pub solver: Solver,
}

impl Default for ReduceOptions<'_> {
    fn default() -> Self {
        ReduceOptions {
            nonnegative: false,
            rest_control_points: None,
            max_sweeps: 1000,
            tol: 1e-4,
            relaxation: 1.9,
            energy: Energy::Gradient,
            solver: Solver::Auto,
        }
    }
}

/// Reduced weights in packed fixed-k form plus how the iteration went.
#[derive(Debug, Clone)]
pub struct Reduction {
    /// `(n, k)` handle indices, per row in decreasing order of the original weight.
    pub indices: Array2<usize>,
    /// `(n, k)` weights of those handles; each row sums to one.
    pub weights: Array2<f64>,
    /// The global objective before the first sweep and after every sweep (empty for k-largest).
    pub objective: Vec<f64>,
    /// Whether the stopping rule was met before `max_sweeps`.
    pub converged: bool,
    /// Number of colour classes (parallel batches per sweep); 0 when conjugate gradients ran.
    pub colours: usize,
    /// Local QPs that hit their iteration cap (left feasible, not optimal); normally 0.
    pub qp_capped: usize,
}

/// Tolerance on `|sum_i W_vi - 1|` for the methods that need partition of unity.
const POU_TOL: f64 = 1e-6;

/// Influence sets: the `k` largest weights of every row (ties to the lower index), in decreasing
/// order, and those weights renormalised to sum to one (the k-largest reduction). One pass per
/// row keeping the best `k` in a sorted buffer: most entries are rejected by one comparison
/// with the current k-th largest.
fn influence_sets(w: ArrayView2<f64>, k: usize) -> SkinResult<(Array2<usize>, Array2<f64>)> {
    let (n, m) = w.dim();
    let ws = crate::skin::standard2(w);
    let ws = ws.as_slice().expect("standard layout");
    let mut sets = Array2::<usize>::zeros((n, k));
    let mut alpha = Array2::<f64>::zeros((n, k));
    let bad = sets
        .as_slice_mut()
        .expect("fresh array is contiguous")
        .par_chunks_mut(k)
        .zip(
            alpha
                .as_slice_mut()
                .expect("fresh array is contiguous")
                .par_chunks_mut(k),
        )
        .enumerate()
        .find_map_first(|(v, (idx, val))| {
            let row = &ws[v * m..(v + 1) * m];
            if !row.iter().fold(true, |ok, x| ok & x.is_finite()) {
                return Some((v, f64::NAN));
            }
            // Insert `x` (handle `i`) into the sorted best `len` (shifting out the last when full);
            // equal values stay behind the earlier, lower index.
            let insert = |val: &mut [f64], idx: &mut [usize], len: usize, x: f64, i: usize| {
                let mut p = len.min(k - 1);
                while p > 0 && val[p - 1] < x {
                    val[p] = val[p - 1];
                    idx[p] = idx[p - 1];
                    p -= 1;
                }
                val[p] = x;
                idx[p] = i;
            };
            for (i, &x) in row[..k].iter().enumerate() {
                insert(val, idx, i, x, i);
            }
            let mut threshold = val[k - 1];
            for (i, &x) in row.iter().enumerate().skip(k) {
                if x > threshold {
                    insert(val, idx, k, x, i);
                    threshold = val[k - 1];
                }
            }
            let s: f64 = val.iter().sum();
            if s.is_nan() || s <= 0.0 {
                return Some((v, s));
            }
            val.iter_mut().for_each(|x| *x /= s);
            None
        });
    match bad {
        Some((v, s)) if s.is_nan() => invalid!("W has a NaN or infinite entry (row {v})"),
        Some((v, s)) => {
            invalid!("the k largest weights of W row {v} sum to {s}: cannot renormalise")
        }
        None => Ok((sets, alpha)),
    }
}

/// Checks `W (n, m)` and `k`.
fn check_weights(w: ArrayView2<f64>, k: usize, method: Method) -> SkinResult<()> {
    let (n, m) = w.dim();
    if n == 0 || m == 0 {
        return invalid!("W must have at least one row and one column, got shape ({n}, {m})");
    }
    if k < 1 || k > m {
        return invalid!("k must be between 1 and the number of handles m = {m}, got {k}");
    }
    if method == Method::KLargest {
        return Ok(()); // `influence_sets` rejects non-finite entries in its single pass
    }
    let ws = crate::skin::standard2(w);
    let ws = ws.as_slice().expect("standard layout");
    let bad = ws.par_chunks(m).enumerate().find_map_first(|(v, r)| {
        let s: f64 = r.iter().sum();
        (!s.is_finite() || (s - 1.0).abs() > POU_TOL).then_some((v, s))
    });
    match bad {
        Some((v, _)) if ws[v * m..(v + 1) * m].iter().any(|x| !x.is_finite()) => {
            invalid!("W has a NaN or infinite entry (row {v})")
        }
        Some((v, s)) => invalid!(
            "W row {v} sums to {s}, not 1 (tolerance {POU_TOL}); {method:?} reduction needs \
             partition-of-unity weights: normalise the rows first"
        ),
        None => Ok(()),
    }
}

/// What the Laplacian methods need of `F (t, 3)` beyond [`operators::check_elements`]:
/// triangles, no repeated vertex in a triangle, every vertex used by some triangle (a vertex
/// off the surface would have an empty Laplacian row and an undetermined weight).
fn check_surface(n: usize, f: ArrayView2<usize>) -> SkinResult<()> {
    if f.ncols() != 3 || f.nrows() == 0 {
        return invalid!(
            "F must hold at least one triangle (t, 3), got shape {:?}",
            f.dim()
        );
    }
    let mut used = vec![false; n];
    for (t, tri) in f.rows().into_iter().enumerate() {
        let (i, j, k) = (tri[0], tri[1], tri[2]);
        if i >= n || j >= n || k >= n {
            return invalid!("F row {t} holds an index outside 0..{n}");
        }
        if i == j || j == k || i == k {
            return invalid!("F row {t} repeats a vertex: [{i}, {j}, {k}]");
        }
        used[i] = true;
        used[j] = true;
        used[k] = true;
    }
    if let Some(u) = used.iter().position(|&x| !x) {
        return invalid!(
            "V row {u} is not used by any triangle of F; the Laplacian-based methods need every \
             vertex on the surface (drop unreferenced vertices and reindex F)"
        );
    }
    Ok(())
}

fn need<T>(x: Option<T>, what: &str, method: Method) -> SkinResult<T> {
    match x {
        Some(x) => Ok(x),
        None => invalid!("{method:?} reduction needs {what}"),
    }
}

/// Reduces weights to `k` influences per vertex (paper 002).
///
/// Inputs:
/// - `w (n, m)` original weights (rows summing to one except for k-largest);
/// - `k` influences to keep, `1 <= k <= m`;
/// - `method`;
/// - `v (n, d)` rest vertices (d = 2 or 3) and `f (t, 3)` triangles: `v` for skeletons, linear
///   precision and the Laplacian methods, `f` for smooth and Poisson;
/// - `poses` example poses: required by geometric and Poisson, unused by k-largest and smooth;
/// - `opts`, `progress` (one event per sweep, value = objective).
///
/// Output: [`Reduction`] with `indices (n, k)` and `weights (n, k)`.
///
/// The influence set of each vertex is its `k` largest original weights (Sec. 3). Smooth
/// reduction of skeletal weights (no rest control points given) has no linear precision: it only
/// matches the weight Laplacians under sum-to-one (and non-negativity).
#[allow(clippy::too_many_arguments)]
pub fn reduce_weights<'a>(
    w: ArrayView2<'a, f64>,
    k: usize,
    method: Method,
    v: Option<ArrayView2<'a, f64>>,
    f: Option<ArrayView2<'a, usize>>,
    poses: Option<&Poses<'a>>,
    opts: &ReduceOptions<'a>,
    progress: &mut dyn Progress,
) -> SkinResult<Reduction> {
    check_weights(w, k, method)?;
    let (n, m) = w.dim();
    if let Some(v) = v {
        if v.nrows() != n {
            return invalid!("V must have one row per row of W ({n}), got {}", v.nrows());
        }
        if !(2..=3).contains(&v.ncols()) {
            return invalid!("V must have 2 or 3 columns, got {}", v.ncols());
        }
        if v.iter().any(|x| !x.is_finite()) {
            return invalid!("V has a NaN or infinite entry");
        }
    }
    if let Some(p) = poses {
        let d = match (p, v) {
            (_, Some(v)) => v.ncols(),
            (Poses::ControlPoints(c), None) => c.shape()[2],
            (Poses::Bones(_), None) => return invalid!("bone_transforms need the rest vertices V"),
        };
        p.check(m, d)?;
    }
    if !(opts.relaxation > 0.0 && opts.relaxation < 2.0) {
        return invalid!("relaxation must lie in (0, 2), got {}", opts.relaxation);
    }
    if opts.tol.is_nan() || opts.tol < 0.0 {
        return invalid!("tol must be >= 0, got {}", opts.tol);
    }
    if opts.rest_control_points.is_some() && method != Method::Smooth {
        return invalid!(
            "the rest control points C (linear precision) are used by the smooth method only"
        );
    }

    let (sets, mut alpha) = influence_sets(w, k)?;
    if method == Method::KLargest {
        if opts.nonnegative {
            if let Some(i) = alpha.iter().position(|&a| a < 0.0) {
                return invalid!(
                    "k-largest keeps a negative weight in row {}; it cannot enforce \
                     nonnegative=True (use another method, or make W non-negative first)",
                    i / k
                );
            }
        }
        return Ok(Reduction {
            indices: sets,
            weights: alpha,
            objective: Vec::new(),
            converged: true,
            colours: 0,
            qp_capped: 0,
        });
    }

    if let Some(c) = opts.rest_control_points {
        let v = need(v, "the rest vertices V for linear precision", method)?;
        let d = v.ncols();
        if c.dim() != (m, d) {
            return invalid!("C must have shape ({m}, {d}), got {:?}", c.dim());
        }
        if c.iter().any(|x| !x.is_finite()) {
            return invalid!("C has a NaN or infinite entry");
        }
        if k < d + 1 {
            return invalid!("linear precision in {d}D needs k >= {}, got k = {k}", d + 1);
        }
    }
    let coupling = match method {
        Method::Geometric => Coupling::identity(n),
        _ => {
            let v = need(v, "the rest vertices V", method)?;
            let f = need(f, "the triangles F", method)?;
            check_surface(v.nrows(), f)?;
            let l = operators::cotan_laplacian(v, f)?;
            match opts.energy {
                Energy::Gradient => Coupling::dirichlet(&l),
                Energy::SquaredLaplacian => {
                    let mass = operators::massmatrix(v, f, MassKind::Barycentric)?;
                    Coupling::squared_laplacian(&l, &mass)
                }
            }
        }
    };
    // The local iteration renumbers the vertices colour class by colour class (see `solver`);
    // conjugate gradients keep the input order (better locality) and one class.
    let use_cg = opts.solver != Solver::Local
        && !opts.nonnegative
        && method != Method::Geometric
        && (method != Method::Smooth || k < u8::MAX as usize)
        && (opts.solver == Solver::Cg || n.saturating_mul(k * k) <= blocks::FAST_LIMIT);
    if opts.solver == Solver::Cg && !use_cg {
        return invalid!(
            "solver='cg' needs nonnegative=False and a coupled method (smooth or poisson); \
             use solver='local' or 'auto'"
        );
    }
    // Conjugate gradients and decoupled vertices (geometric) need no colouring: input order.
    let in_order = use_cg || method == Method::Geometric;
    let (order, classes) = if in_order {
        ((0..n).collect(), vec![0, n])
    } else {
        coupling.colour_order()
    };
    let (coupling, sets_p, mut alpha_p, v_p) = if in_order {
        (
            coupling,
            sets.clone(),
            alpha.clone(),
            v.map(|v| v.to_owned()),
        )
    } else {
        let rows = |a: ArrayView2<f64>| a.select(Axis(0), &order);
        (
            coupling.permuted(&order),
            sets.select(Axis(0), &order),
            alpha.select(Axis(0), &order),
            v.map(rows),
        )
    };
    let w_p = |w: ArrayView2<'a, f64>| -> CowArray<'a, f64, Ix2> {
        if in_order {
            CowArray::from(w)
        } else {
            CowArray::from(w.select(Axis(0), &order))
        }
    };
    let (basis, target) = match method {
        Method::Smooth => (
            Basis::Select { m },
            w_p(w).as_standard_layout().into_owned(),
        ),
        _ => {
            let p = *need(
                poses,
                "example poses (control_points or bone_transforms)",
                method,
            )?;
            pose_basis(w_p(w).view(), v_p.as_ref().map(|v| v.view()), p, &sets_p)?
        }
    };
    let lp = match (opts.rest_control_points, v_p) {
        (Some(c), Some(v)) => Some(LinearPrecision { rest_points: c, v }),
        _ => None,
    };
    let problem = Problem {
        sets: sets_p,
        basis,
        coupling,
        target,
        lp,
        nonneg: opts.nonnegative,
        classes,
        order,
    };
    problem.make_feasible(&mut alpha_p)?;
    let report = problem.solve(
        &mut alpha_p,
        &SolveOptions {
            max_sweeps: opts.max_sweeps,
            tol: opts.tol,
            relaxation: opts.relaxation,
            cg: use_cg,
        },
        progress,
    )?;
    for (i, &vi) in problem.order.iter().enumerate() {
        alpha.row_mut(vi).assign(&alpha_p.row(i));
    }
    Ok(Reduction {
        indices: sets,
        weights: alpha,
        objective: report.objective,
        converged: report.converged,
        colours: if use_cg { 0 } else { problem.classes.len() - 1 },
        qp_capped: report.qp_capped,
    })
}

/// The basis of the pose-matching methods and the full-weight deformation `Xbar (n, q)`.
fn pose_basis(
    w: ArrayView2<f64>,
    v: Option<ArrayView2<f64>>,
    poses: Poses,
    sets: &Array2<usize>,
) -> SkinResult<(Basis, Array2<f64>)> {
    let (n, m) = w.dim();
    let p = poses.count();
    match poses {
        Poses::ControlPoints(c) => {
            let d = c.shape()[2];
            // cq row i = c_i over all poses; Xbar = W cq.
            let mut cq = Array2::<f64>::zeros((m, p * d));
            for i in 0..m {
                for j in 0..p {
                    for a in 0..d {
                        cq[[i, j * d + a]] = c[[j, i, a]];
                    }
                }
            }
            let gram = cq.dot(&cq.t());
            let target = w.dot(&cq);
            Ok((Basis::Cage { cq, gram }, target))
        }
        Poses::Bones(_) => {
            let v = match v {
                Some(v) => v,
                None => return invalid!("bone_transforms need the rest vertices V"),
            };
            let x = deform(v, &crate::skin::Weights::Dense(w), &poses)?;
            let d = v.ncols();
            // (p, n, d) -> (n, p * d)
            let target = Array2::from_shape_fn((n, p * d), |(vi, c)| x[[c / d, vi, c % d]]);
            Ok((Basis::bones(&poses, v, sets), target))
        }
    }
}
