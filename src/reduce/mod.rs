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
mod input;
mod iteration;
mod local;
mod problem;
pub(crate) mod qp;
mod solver;

use ndarray::{Array2, ArrayView2, Axis};

use crate::error::SkinResult;
use crate::invalid;
use crate::operators::{self, MassKind};
use crate::progress::Progress;

use basis::{pose_basis, Basis};
use coupling::Coupling;
pub use deform::{deform, deformation_errors, transform_normals, DeformationErrors, Poses};
use input::{
    check_inputs, check_linear_precision, check_surface, check_weights, influence_sets, need,
};
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
    check_inputs((n, m), method, v, poses, opts)?;
    let (sets, mut alpha) = influence_sets(w, k)?;
    if method == Method::KLargest {
        return k_largest(sets, alpha, opts.nonnegative);
    }
    if let Some(c) = opts.rest_control_points {
        check_linear_precision(c, v, (m, k), method)?;
    }
    let coupling = coupling_of(method, n, v, f, opts.energy)?;
    let use_cg = uses_cg(method, opts, n, k)?;
    let problem = problem_of(method, w, v, poses, opts, coupling, &sets, use_cg)?;
    let mut alpha_p = alpha.select(Axis(0), &problem.order);
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

/// The k-largest reduction: the influence sets and their renormalised weights.
fn k_largest(sets: Array2<usize>, alpha: Array2<f64>, nonnegative: bool) -> SkinResult<Reduction> {
    if nonnegative {
        if let Some(i) = alpha.iter().position(|&a| a < 0.0) {
            return invalid!(
                "k-largest keeps a negative weight in row {}; it cannot enforce \
                 nonnegative=True (use another method, or make W non-negative first)",
                i / sets.ncols()
            );
        }
    }
    Ok(Reduction {
        indices: sets,
        weights: alpha,
        objective: Vec::new(),
        converged: true,
        colours: 0,
        qp_capped: 0,
    })
}

/// `Q` of the method: the identity (geometric), `-L` or `L M^-1 L` on the surface.
fn coupling_of(
    method: Method,
    n: usize,
    v: Option<ArrayView2<f64>>,
    f: Option<ArrayView2<usize>>,
    energy: Energy,
) -> SkinResult<Coupling> {
    if method == Method::Geometric {
        return Ok(Coupling::identity(n));
    }
    let v = need(v, "the rest vertices V", method)?;
    let f = need(f, "the triangles F", method)?;
    check_surface(v.nrows(), f)?;
    let l = operators::cotan_laplacian(v, f)?;
    Ok(match energy {
        Energy::Gradient => Coupling::dirichlet(&l),
        Energy::SquaredLaplacian => {
            let mass = operators::massmatrix(v, f, MassKind::Barycentric)?;
            Coupling::squared_laplacian(&l, &mass)
        }
    })
}

/// Whether conjugate gradients minimise (no bounds, a coupled method, blocks that fit in
/// memory) instead of the local iteration; an error if `solver='cg'` cannot.
fn uses_cg(method: Method, opts: &ReduceOptions, n: usize, k: usize) -> SkinResult<bool> {
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
    Ok(use_cg)
}

/// The problem in the iteration's vertex order. The local iteration renumbers the vertices
/// colour class by colour class (see `solver`); conjugate gradients and decoupled vertices
/// (geometric) keep the input order (better locality) and one class.
#[allow(clippy::too_many_arguments)]
fn problem_of<'a>(
    method: Method,
    w: ArrayView2<'a, f64>,
    v: Option<ArrayView2<'a, f64>>,
    poses: Option<&Poses<'a>>,
    opts: &ReduceOptions<'a>,
    coupling: Coupling,
    sets: &Array2<usize>,
    use_cg: bool,
) -> SkinResult<Problem<'a>> {
    let n = w.nrows();
    let in_order = use_cg || method == Method::Geometric;
    let (order, classes) = if in_order {
        ((0..n).collect(), vec![0, n])
    } else {
        coupling.colour_order()
    };
    let rows_f = |a: ArrayView2<f64>| a.select(Axis(0), &order);
    let coupling = if in_order {
        coupling
    } else {
        coupling.permuted(&order)
    };
    let sets_p = sets.select(Axis(0), &order);
    let v_p = v.map(rows_f);
    let w_p = rows_f(w);
    let (basis, target) = match method {
        Method::Smooth => (Basis::Select { m: w.ncols() }, w_p),
        _ => {
            let p = *need(
                poses,
                "example poses (control_points or bone_transforms)",
                method,
            )?;
            pose_basis(w_p.view(), v_p.as_ref().map(|v| v.view()), p, &sets_p)?
        }
    };
    let lp = match (opts.rest_control_points, v_p) {
        (Some(c), Some(v)) => Some(LinearPrecision { rest_points: c, v }),
        _ => None,
    };
    Ok(Problem {
        sets: sets_p,
        basis,
        coupling,
        target,
        lp,
        nonneg: opts.nonnegative,
        classes,
        order,
    })
}
