"""Bounded biharmonic weights (BBW) through the convex dual (Solomon & Stein 2025).

``bbw_dual`` solves the classic BBW quadratic program *with* partition of unity exactly::

    min_W  1/2 tr(W^T B W)   s.t.  W 1 = 1,  W >= 0,  W[b] = bc          (paper eq. 3)

with ``B = L^T M^-1 L`` (cotangent Laplacian, lumped mass divided by its largest entry). The
constrained rows are eliminated, so one sparse Cholesky factor of ``B_ff`` serves the whole solve;
the dual (eq. 12) is a non-negative least-squares problem whose gradient is the recovered weights
(eq. 15-16). Iterations stop on a measured duality gap, so the returned energy is certified to be
within ``tol`` (relative) of the optimum. ``partition_of_unity=False`` solves the relaxation with
``0 <= W <= 1`` instead (App. A-B), which is what ``igl.bbw`` computes.
"""

from __future__ import annotations

import sys
import time
import warnings
from typing import TYPE_CHECKING, Any, Literal, TypedDict, overload

import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike, NDArray

from . import _checks, _skinrs
from ._checks import Callback

if TYPE_CHECKING:
    from typing_extensions import Unpack
from ._info import Info
from .operators import cotan_laplacian, massmatrix

#: Distance tolerance of ``boundary_conditions``, relative to the bounding-box diagonal. On
#: unit-size meshes it equals libigl's test ``squared distance <= 1e-7``.
DEFAULT_BC_TOL: float = _skinrs.BOUNDARY_TOL

#: The solvers of ``bbw_dual_constrained`` and the defaults of its options (from the Rust core).
SOLVERS: tuple[str, ...] = _skinrs.BBW_SOLVERS
_DEFAULTS: dict[str, Any] = _skinrs.BBW_DEFAULTS


class BbwOptions(TypedDict, total=False):
    """The keyword options of :func:`bbw_dual_constrained` (for type checkers)."""

    partition_of_unity: bool
    normalize: bool
    mass: str
    solver: str
    tol: float
    max_iter: int
    seed: int
    lbfgs_memory: int
    memory_limit: float | None
    verbose: bool
    callback: Callback | None


def boundary_conditions(
    V: ArrayLike,
    C: ArrayLike,
    BE: ArrayLike | None = None,
    P: ArrayLike | None = None,
    *,
    tol: float = DEFAULT_BC_TOL,
) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
    """Constrained vertices and their values from point handles and bones.

    A vertex within ``tol * bbox_diagonal(V)`` of point handle ``C[P[k]]`` is held at 1 in
    column ``k``; a vertex on bone ``BE[e]`` (segment ``C[BE[e,0]] -> C[BE[e,1]]``) at 1 in
    column ``len(P) + e`` (libigl's order: points first, then bones). A vertex on several bones (a
    joint) is shared equally between them, as libigl's ``boundary_conditions`` does.

    Parameters
    ----------
    V : (n, d) float array, d = 2 or 3
    C : (h, d) float array of control points / joints (a 3-column ``C`` with z = 0 is accepted
        for 2D ``V``)
    BE : (k, 2) int array of bone edges into ``C``, optional
    P : (p,) int array of point-handle indices into ``C``, optional
    tol : float
        Distance tolerance relative to the bounding-box diagonal of ``V``.

    Returns
    -------
    b : (q,) int64 array, sorted constrained vertex indices
    bc : (q, p + k) float array, rows sum to 1

    Raises
    ------
    ValueError
        A handle or bone with no vertex on it (libigl silently returns all-zero weights then),
        duplicate point handles, duplicate or zero-length bones, bad shapes or indices.

    Examples
    --------
    >>> import numpy as np, skinrs
    >>> V = np.array([[0., 0.], [1., 0.], [2., 0.], [1., 1.]])
    >>> b, bc = skinrs.boundary_conditions(V, V[:3], BE=[[0, 1], [1, 2]])
    >>> b.tolist(), bc[1].tolist()
    ([0, 1, 2], [0.5, 0.5])
    """
    V = _checks.as_points(V, "V")
    C = _checks.as_points(C, "C", min_rows=1)
    if V.shape[1] == 2 and C.shape[1] == 3:
        if np.any(C[:, 2] != 0):
            raise ValueError("V is 2D but C has non-zero z coordinates")
        C = np.ascontiguousarray(C[:, :2])
    if C.shape[1] != V.shape[1]:
        raise ValueError(f"C must have {V.shape[1]} columns like V, got {C.shape}")
    h = C.shape[0]
    P = _checks.as_index_array([] if P is None else P, h, "P", ndim=1).reshape(-1, 1)
    BE = _checks.as_index_array(np.zeros((0, 2)) if BE is None else BE, h, "BE", cols=2)
    if len(P) + len(BE) == 0:
        raise ValueError("no handles: give point handles P and/or bone edges BE")
    tol = _checks.positive_float(tol, "tol")
    return _skinrs._boundary_conditions(V, C, P, BE, tol)


def biharmonic_energy(W: ArrayLike, B: sp.spmatrix | sp.sparray) -> float:
    """``1/2 tr(W^T B W)``, the BBW objective (paper eq. 3), for ``W (n, m)`` and sparse ``B``.

    Summed through ``B``, so on a mesh with sliver elements (``B``'s entries many orders above
    the energy) it loses digits; ``bbw_dual``'s ``info["energy"]`` is evaluated from ``L`` and
    ``M`` and keeps them.
    """
    import scipy.sparse as sp

    if not (sp.issparse(B) or isinstance(B, np.ndarray)) or B.ndim != 2 or B.shape[0] != B.shape[1]:
        raise ValueError(f"B must be a square (n, n) matrix, got {type(B).__name__} {np.shape(B)}")
    W = _checks.as_points(W, "W", dims=None, min_rows=0, coordinates=False)
    if W.shape[0] != B.shape[0]:
        raise ValueError(f"W must have {B.shape[0]} rows like B, got shape {W.shape}")
    with np.errstate(over="ignore", invalid="ignore"):
        e = 0.5 * float(np.einsum("ij,ij->", W, np.asarray(B @ W)))
    if not np.isfinite(e):
        raise ValueError("the energy overflows: W or B has entries too large for double precision")
    return e


def _memory_limit_bytes(memory_limit: float | None) -> int:
    """``memory_limit`` as whole bytes: half of this machine's memory when None."""
    if memory_limit is None:
        return _checks.physical_memory() // 2
    limit = _checks.positive_float(memory_limit, "memory_limit")
    return min(int(limit), 2**64 - 1)


def _bytes_text(n: int) -> str:
    """``n`` bytes in the largest binary unit it reaches (``"1.50 GiB"``)."""
    if n < 1024:
        return f"{n} B"
    x, unit = n / 1024, "KiB"
    for bigger in ("MiB", "GiB"):
        if x < 1024:
            break
        x, unit = x / 1024, bigger
    return f"{x:.2f} {unit}"


@overload
def bbw_dual_constrained(
    V: ArrayLike,
    T: ArrayLike,
    b: ArrayLike,
    bc: ArrayLike,
    *,
    return_info: Literal[False] = False,
    **options: Unpack[BbwOptions],
) -> NDArray[np.float64]: ...
@overload
def bbw_dual_constrained(
    V: ArrayLike,
    T: ArrayLike,
    b: ArrayLike,
    bc: ArrayLike,
    *,
    return_info: Literal[True],
    **options: Unpack[BbwOptions],
) -> tuple[NDArray[np.float64], Info]: ...
@overload
def bbw_dual_constrained(
    V: ArrayLike,
    T: ArrayLike,
    b: ArrayLike,
    bc: ArrayLike,
    *,
    return_info: bool,
    **options: Unpack[BbwOptions],
) -> NDArray[np.float64] | tuple[NDArray[np.float64], Info]: ...
def bbw_dual_constrained(
    V: ArrayLike,
    T: ArrayLike,
    b: ArrayLike,
    bc: ArrayLike,
    *,
    partition_of_unity: bool = _DEFAULTS["partition_of_unity"],
    normalize: bool = True,
    mass: str = "voronoi",
    solver: str = _DEFAULTS["solver"],
    tol: float = _DEFAULTS["tol"],
    max_iter: int = _DEFAULTS["max_iter"],
    seed: int = _DEFAULTS["seed"],
    lbfgs_memory: int = _DEFAULTS["lbfgs_memory"],
    memory_limit: float | None = None,
    verbose: bool = False,
    callback: Callback | None = None,
    return_info: bool = False,
) -> NDArray[np.float64] | tuple[NDArray[np.float64], Info]:
    """Exact BBW for user-given constraints ``W[b] = bc``.

    Parameters
    ----------
    V : (n, d) float array
        Vertices of a 2D triangle mesh, a 3D tet mesh (or a 3D surface).
    T : (k, 3) or (k, 4) int array
        Triangles or tetrahedra.
    b : (q,) int array
        Constrained vertices (distinct).
    bc : (q, m) float array
        Their prescribed weights, one column per handle. With partition of unity each row must
        be non-negative and sum to 1.
    partition_of_unity : bool
        True (default): the classic BBW with ``W 1 = 1`` (eq. 3). False: the relaxation with
        ``0 <= W <= 1`` and independent columns (App. A), as ``igl.bbw`` solves it.
    normalize : bool
        Without partition of unity, divide rows by their sums afterwards (default, what skinning
        needs); ``False`` returns the raw box-constrained weights. Ignored with partition of unity.
    mass : {"voronoi", "barycentric"}
        Lumped mass in ``B = L^T M^-1 L``. The paper uses Voronoi; libigl's ``bbw`` uses its
        default, which is barycentric for tets.
    solver : str
        ``"active-set"`` (default): a short L-BFGS run guesses the supports, then a primal-dual
        active set solves the problem on them exactly (one Cholesky per column support, CG on
        the partition-of-unity multiplier) and swaps KKT violators. ``"lbfgs-squared"``: the
        paper's L-BFGS on ``Y = U o U`` (Sec. 6, 8).
    tol : float
        Stop when the duality gap is at most ``tol`` times the energy: the returned energy is then
        certified within ``tol`` (relative) of the optimum.
    max_iter : int
        Iteration cap; a warning is issued if the gap is still above ``tol`` then.
    seed : int
        Seed of the random start (the paper's), for reproducible results.
    lbfgs_memory : int
        Number of L-BFGS correction pairs (SciPy's default, 10, is the paper's setting).
    memory_limit : float, optional
        Bytes the solve may take for its factors and dense vectors (default: half of this
        machine's memory). Each factor's size is known from its symbolic analysis before it is
        allocated. If the Cholesky factor of ``B_ff`` would not fit, ``MemoryError`` is raised
        before it is computed. If the active set's support factors would not fit (it holds one
        per column), L-BFGS on the dual, which needs only the factor of ``B_ff``, finishes the
        solve to the same certified ``tol`` (slower), with a ``RuntimeWarning``.
    verbose : bool
        Print progress (gap per iteration, throttled) and a summary to stderr.
    callback : callable, optional
        ``callback(stage, iteration, value)`` is called about every 0.1 s with the relative gap
        (stages ``"dual"``, ``"active-set"``) or the partition-of-unity residual of the inner
        conjugate gradients (``"active-set cg"``);
        returning ``False`` stops the solve (raises ``KeyboardInterrupt``). Ctrl-C also stops it.
    return_info : bool
        Also return an :class:`skinrs.Info` of diagnostics: solver, iterations and evaluations
        (L-BFGS), rounds, cg_iterations and fallbacks (active set: rounds, CG iterations in
        them, and hand-overs to L-BFGS when the rounds stall), energy, lower_bound, gap,
        relative_gap, dual_objective, min_raw_weight, max_raw_weight, converged, seconds (the
        whole call) and seconds per phase: time_operators, time_factor, time_solve and within it
        time_lbfgs, time_active_set (of which time_support_factor, time_cg and time_smooth);
        factor_bytes, vector_bytes and support_factor_bytes (the factor of ``B_ff``, the dense
        vectors, and the most the support factors of one round took or would have taken), and
        memory_fallback (those did not fit ``memory_limit``).

    Returns
    -------
    W : (n, m) float array
        Weights: ``W >= 0``, ``W[b] == bc`` exactly, rows sum to 1 (to rounding) with partition
        of unity or ``normalize``.

    Examples
    --------
    >>> import numpy as np, skinrs
    >>> x, y = np.meshgrid(np.linspace(0, 1, 6), np.linspace(0, 1, 6))
    >>> V = np.c_[x.ravel(), y.ravel()]
    >>> T = np.array([[i + 6 * j, i + 1 + 6 * j, i + 7 + 6 * j] for j in range(5) for i in range(5)]
    ...              + [[i + 6 * j, i + 7 + 6 * j, i + 6 + 6 * j] for j in range(5) for i in range(5)])
    >>> W = skinrs.bbw_dual_constrained(V, T, [0, 35], np.eye(2))
    >>> bool(np.allclose(W.sum(1), 1) and W.min() >= 0)
    True
    """
    V = _checks.as_points(V, "V")
    T = _checks.as_elements(T, V, "T")
    n = V.shape[0]
    b = _checks.as_index_array(b, n, "b", ndim=1, allow_empty=False)
    if len(np.unique(b)) != len(b):
        raise ValueError("b holds a vertex more than once")
    bc = _checks.as_real_array(bc, "bc")
    if bc.ndim == 1 and len(b) == 1:
        bc = bc.reshape(1, -1)
    bc = _checks.as_points(bc, "bc", dims=None, coordinates=False)
    if bc.shape[0] != len(b):
        raise ValueError(f"bc must have one row per entry of b ({len(b)}), got {bc.shape}")
    if partition_of_unity:
        if bc.min() < 0:
            raise ValueError("bc has negative entries: infeasible with W >= 0")
        bad = np.abs(bc.sum(1) - 1) > 1e-9
        if bad.any():
            r = int(np.flatnonzero(bad)[0])
            raise ValueError(
                f"bc row {r} (vertex {b[r]}) sums to {bc[r].sum():.6g}, not 1: infeasible with "
                "partition of unity"
            )
    elif bc.min() < 0 or bc.max() > 1:
        raise ValueError("bc must lie in [0, 1] for the box-constrained variant")
    if not isinstance(solver, str) or solver not in SOLVERS:
        raise ValueError(f"solver must be one of {SOLVERS}, got {solver!r}")
    tol = _checks.positive_float(tol, "tol")
    max_iter = _checks.positive_int(max_iter, "max_iter", hi=2**63 - 1)
    lbfgs_memory = _checks.positive_int(lbfgs_memory, "lbfgs_memory", hi=10_000)
    seed = _checks.integer(seed, "seed", 0, 2**64 - 1)
    limit = _memory_limit_bytes(memory_limit)
    _checks.as_callback(callback)

    t0 = time.perf_counter()
    # B = L^T M^-1 L is assembled in Rust from its factors, which also evaluate the energies of
    # the certificate accurately on meshes with sliver elements.
    L = cotan_laplacian(V, T)
    masses = np.asarray(massmatrix(V, T, kind=mass).diagonal(), dtype=np.float64)
    t_ops = time.perf_counter() - t0
    cb = _checks.progress_printer(verbose, callback, _describe)
    W, raw = _skinrs._bbw_dual(
        L.data,
        L.indices.astype(np.int64),
        L.indptr.astype(np.int64),
        masses,
        b,
        bc,
        solver=solver,
        tol=tol,
        max_iter=max_iter,
        partition_of_unity=bool(partition_of_unity),
        seed=int(seed),
        lbfgs_memory=int(lbfgs_memory),
        memory_limit=limit,
        callback=cb,
    )
    info = Info(raw, time_operators=t_ops)
    if info["memory_fallback"]:
        warnings.warn(
            f"bbw_dual: the active set's support factors need "
            f"{_bytes_text(info['support_factor_bytes'])}, more than memory_limit = "
            f"{_bytes_text(limit)} leaves besides B_ff's factor "
            f"({_bytes_text(info['factor_bytes'])}) and the vectors "
            f"({_bytes_text(info['vector_bytes'])}); L-BFGS on the dual solved the rest",
            RuntimeWarning,
            stacklevel=2,
        )
    if not info["converged"]:
        warnings.warn(
            f"bbw_dual stopped after {info['iterations']} iterations with relative duality gap "
            f"{info['relative_gap']:.2e} > tol {tol:.1e}; raise max_iter for a tighter result",
            RuntimeWarning,
            stacklevel=2,
        )
    if not partition_of_unity and normalize:
        s = W.sum(1, keepdims=True)
        if np.any(s <= 0):
            r = int(np.flatnonzero(s[:, 0] <= 0)[0])
            raise ValueError(f"vertex {r} has all-zero weights and cannot be normalised")
        W = W / s
    info["seconds"] = time.perf_counter() - t0
    if verbose:
        print(
            f"skinrs.bbw_dual: {info['solver']}, {info['iterations']} iterations, energy "
            f"{info['energy']:.10g}, relative gap {info['relative_gap']:.1e}, "
            f"{info['time_operators'] + info['time_solve']:.2f} s",
            file=sys.stderr,
        )
    return (W, info) if return_info else W


@overload
def bbw_dual(
    V: ArrayLike,
    T: ArrayLike,
    C: ArrayLike,
    BE: ArrayLike | None = None,
    P: ArrayLike | None = None,
    *,
    bc_tol: float = DEFAULT_BC_TOL,
    return_info: Literal[False] = False,
    **options: Unpack[BbwOptions],
) -> NDArray[np.float64]: ...
@overload
def bbw_dual(
    V: ArrayLike,
    T: ArrayLike,
    C: ArrayLike,
    BE: ArrayLike | None = None,
    P: ArrayLike | None = None,
    *,
    bc_tol: float = DEFAULT_BC_TOL,
    return_info: Literal[True],
    **options: Unpack[BbwOptions],
) -> tuple[NDArray[np.float64], Info]: ...
@overload
def bbw_dual(
    V: ArrayLike,
    T: ArrayLike,
    C: ArrayLike,
    BE: ArrayLike | None = None,
    P: ArrayLike | None = None,
    *,
    bc_tol: float = DEFAULT_BC_TOL,
    return_info: bool,
    **options: Unpack[BbwOptions],
) -> NDArray[np.float64] | tuple[NDArray[np.float64], Info]: ...
def bbw_dual(
    V: ArrayLike,
    T: ArrayLike,
    C: ArrayLike,
    BE: ArrayLike | None = None,
    P: ArrayLike | None = None,
    *,
    bc_tol: float = DEFAULT_BC_TOL,
    partition_of_unity: bool = _DEFAULTS["partition_of_unity"],
    normalize: bool = True,
    mass: str = "voronoi",
    solver: str = _DEFAULTS["solver"],
    tol: float = _DEFAULTS["tol"],
    max_iter: int = _DEFAULTS["max_iter"],
    seed: int = _DEFAULTS["seed"],
    lbfgs_memory: int = _DEFAULTS["lbfgs_memory"],
    memory_limit: float | None = None,
    verbose: bool = False,
    callback: Callback | None = None,
    return_info: bool = False,
) -> NDArray[np.float64] | tuple[NDArray[np.float64], Info]:
    """Exact bounded biharmonic weights for bones ``BE`` and point handles ``P``.

    The mesh must contain the handles and bone samples as vertices (see
    ``skinrs.mesh_with_skeleton``); :func:`boundary_conditions` finds them (within ``bc_tol``
    of the bounding-box diagonal). Columns are ordered as in libigl: point handles first, then
    bones. The other keywords are those of :func:`bbw_dual_constrained`.

    Returns
    -------
    W : (n, #P + #BE) float array (or ``(W, info)`` with ``return_info=True``)

    Examples
    --------
    >>> import skinrs                                                     # doctest: +SKIP
    >>> V, T, _ = skinrs.io.read_mesh("hand.mesh")                        # doctest: +SKIP
    >>> C, BE = skinrs.io.read_tgf("hand.tgf")                            # doctest: +SKIP
    >>> W = skinrs.bbw_dual(V, T, C, BE=BE)                               # doctest: +SKIP
    """
    bc_tol = _checks.positive_float(bc_tol, "bc_tol")
    b, bc = boundary_conditions(V, C, BE=BE, P=P, tol=bc_tol)
    return bbw_dual_constrained(
        V,
        T,
        b,
        bc,
        partition_of_unity=partition_of_unity,
        normalize=normalize,
        mass=mass,
        solver=solver,
        tol=tol,
        max_iter=max_iter,
        seed=seed,
        lbfgs_memory=lbfgs_memory,
        memory_limit=memory_limit,
        verbose=verbose,
        callback=callback,
        return_info=return_info,
    )


def _describe(stage: str, iteration: int, value: float) -> str:
    what = "partition-of-unity residual" if stage.endswith("cg") else "relative gap"
    return f"{stage} iteration {iteration}: {what} {value:.2e}"
