"""Weight reduction: k influences per vertex that still deform like the full weights.

Landreneau & Schaefer 2010, "Poisson-based weight reduction of animated meshes" (paper 002).
Every vertex keeps the ``k`` handles with its largest original weights (the paper's heuristic)
and the kept weights are set by one of four methods:

- ``"k-largest"``: the k largest weights renormalised (what exporters do);
- ``"smooth"`` (Sec. 3.1): the Laplacian of every reduced weight function matches the original's;
  with the rest cage ``C`` also linear precision ``sum_i a_i c_i = v``. Skeletal weights (no ``C``)
  get only sum-to-one (and non-negativity): bones have no point to be precise about;
- ``"geometric"`` (Sec. 3.2, eq. 3): the example-pose positions are matched;
- ``"poisson"`` (Sec. 3.3, eq. 5; Sec. 4 for skeletons): the Laplacian of the deformed positions
  over the example poses is matched, which keeps normals continuous.

Example poses are either ``control_points`` ``(p, m, d)`` (cages / barycentric coordinates) or
``bone_transforms`` ``(p, m, d, d+1)`` affine ``[A | t]`` per bone (skeletons, linear blend
skinning). Results come in packed fixed-k form ``(indices (n, k), weights (n, k))``.

>>> import numpy as np, skinrs
>>> V = np.array([[0., 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
>>> F = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
>>> W = np.array([[.7, .2, .1], [.2, .7, .1], [.1, .2, .7], [.4, .3, .3]])
>>> Cj = [[0, 0, 0], [0, 1, 0], [0, 2, 0], [0, 3, 0]]      # joints of a 3-bone chain
>>> P = skinrs.random_skeleton_poses(Cj, [[0, 1], [1, 2], [2, 3]], 3, seed=0)
>>> I, A = skinrs.reduce_weights(W, 2, method="poisson", V=V, F=F, bone_transforms=P)
>>> I.shape, bool(np.allclose(A.sum(1), 1))
((4, 2), True)
"""

from __future__ import annotations

import time
from typing import TYPE_CHECKING, Any, Literal, TypedDict, overload

import numpy as np
from numpy.typing import ArrayLike, NDArray

from . import _checks, _skinrs
from ._checks import (
    Callback,
    as_elements,
    as_points,
    as_weights,
    positive_float,
    positive_int,
)
from ._info import Info
from ._reduce_deform import (
    ReductionError,
    deform,
    reduction_error,
    transform_normals,
    unpack_weights,
)
from ._reduce_poses import (  # noqa: F401
    Packed,
    _bones,
    _handle_count,
    _packed,
    _poses,
    _rotation,
    random_skeleton_poses,
)

if TYPE_CHECKING:
    from typing_extensions import Unpack

#: Choice lists and defaults of :func:`reduce_weights` (from the Rust core).
METHODS: tuple[str, ...] = _skinrs.REDUCE_METHODS
ENERGIES: tuple[str, ...] = _skinrs.REDUCE_ENERGIES
SOLVERS: tuple[str, ...] = _skinrs.REDUCE_SOLVERS
_DEFAULTS: dict[str, Any] = _skinrs.REDUCE_DEFAULTS


class ReduceOptions(TypedDict, total=False):
    """The keyword options of :func:`reduce_weights` (for type checkers)."""

    method: str
    V: ArrayLike | None
    F: ArrayLike | None
    control_points: ArrayLike | None
    bone_transforms: ArrayLike | None
    C: ArrayLike | None
    nonnegative: bool | None
    max_sweeps: int
    tol: float
    relaxation: float
    energy: str
    solver: str
    callback: Callback | None


__all__ = [
    "ENERGIES",
    "METHODS",
    "SOLVERS",
    "ReduceOptions",
    "ReductionError",
    "deform",
    "random_skeleton_poses",
    "reduce_weights",
    "reduction_error",
    "transform_normals",
    "unpack_weights",
]


@overload
def reduce_weights(
    W: ArrayLike, k: int, *, return_info: Literal[False] = False, **options: Unpack[ReduceOptions]
) -> Packed: ...
@overload
def reduce_weights(
    W: ArrayLike, k: int, *, return_info: Literal[True], **options: Unpack[ReduceOptions]
) -> tuple[NDArray[np.int64], NDArray[np.float64], Info]: ...
@overload
def reduce_weights(
    W: ArrayLike, k: int, *, return_info: bool, **options: Unpack[ReduceOptions]
) -> Packed | tuple[NDArray[np.int64], NDArray[np.float64], Info]: ...
def reduce_weights(
    W: ArrayLike,
    k: int,
    *,
    method: str = "poisson",
    V: ArrayLike | None = None,
    F: ArrayLike | None = None,
    control_points: ArrayLike | None = None,
    bone_transforms: ArrayLike | None = None,
    C: ArrayLike | None = None,
    nonnegative: bool | None = None,
    max_sweeps: int = _DEFAULTS["max_sweeps"],
    tol: float = _DEFAULTS["tol"],
    relaxation: float = _DEFAULTS["relaxation"],
    energy: str = _DEFAULTS["energy"],
    solver: str = _DEFAULTS["solver"],
    return_info: bool = False,
    callback: Callback | None = None,
) -> Packed | tuple[NDArray[np.int64], NDArray[np.float64], Info]:
    """Reduce skinning weights to ``k`` influences per vertex (paper 002).

    Parameters
    ----------
    W : (n, m) float
        Original weights, one column per handle. Rows must sum to 1 (within 1e-6) for every
        method except ``"k-largest"``.
    k : int
        Influences kept per vertex, ``1 <= k <= m``.
    method : {"k-largest", "smooth", "geometric", "poisson"}
    V : (n, d) float, optional
        Rest vertices (d = 2 or 3); needed by smooth and Poisson, by skeletons and by ``C``.
    F : (f, 3) int, optional
        Triangles of the surface; needed by smooth and Poisson (cotangent Laplacian). Every vertex
        must be used by a triangle.
    control_points : (p, m, d) float, optional
        Example poses of a cage: the position of every control point in every pose.
    bone_transforms : (p, m, d, d+1) float, optional
        Example poses of a skeleton: affine bone transforms ``[A | t]`` (rest pose = identity).
        Geometric and Poisson need one of the two; k-largest and smooth do not use them.
    C : (m, d) float, optional
        Rest control points of a cage. Smooth reduction then enforces linear precision
        ``sum_i a_i C_i = v`` (needs ``k >= d + 1``). Only the smooth method takes ``C``.
    nonnegative : bool, optional
        Keep every weight >= 0. Default: True for skeletons (``bone_transforms``) and whenever
        ``W`` has no negative entry (harmonic, BBW), False otherwise (e.g. mean value coordinates).
    max_sweeps : int
        Upper bound on the sweeps of the local iteration (or the iterations of conjugate
        gradients).
    tol : float
        Stopping rule, measured on the global objective ``h`` (``h[0]`` at the k-largest start,
        ``h[s]`` after sweep ``s``) and independent of its units: stop at the first sweep where
        the mean decrease over the last (up to) 4 sweeps is at most ``tol * (h[0] - h[s])``,
        i.e. the iteration has stopped making progress relative to what it has achieved.
    relaxation : float in (0, 2)
        Over-relaxation of each per-vertex step of the local iteration (1 = plain block
        Gauss-Seidel as in the paper; larger values need fewer sweeps to the same minimum).
    energy : {"gradient", "laplacian"}
        How smooth and Poisson compare functions on the surface. ``"gradient"`` (default):
        ``int |grad(phi - psi)|^2 dA``, the Poisson problem of Sec. 3.3 in its gradient form
        ``min int |grad phi - w|^2``; ``"laplacian"``: ``int (lap(phi - psi))^2 dA``, eqs. (4)-(5)
        as printed. The squared Laplacian barely penalises smooth (low-frequency) errors, so its
        minimiser drifts away from the example poses and converges slowly; held-out errors of
        both are compared in ``docs/reduce.md``.
    solver : {"auto", "local", "cg"}
        How coupled problems (smooth, Poisson) are minimised. ``"local"``: the local iteration
        of Sec. 3.1 (per-vertex QPs over graph-colour classes in parallel, over-relaxed);
        ``"cg"``: projected conjugate gradients preconditioned by the same per-vertex blocks plus
        a coarse space (handle weight shifts on ~64-vertex aggregates), for ``nonnegative=False``
        only; ``"auto"`` (default): ``"cg"`` without bounds, ``"local"`` with them. Both report the
        objective after every sweep / iteration and reach the same minimiser.
    return_info : bool
        Also return an :class:`skinrs.Info` with ``objective`` ((s+1,) global objective before
        the first sweep and after each sweep or conjugate-gradient iteration, empty for
        k-largest; never increases), ``sweeps`` (sweeps or iterations run), ``converged``
        (the stopping rule was met before ``max_sweeps``), ``colours`` (colour classes, the
        parallel batches of one sweep; 0 when conjugate gradients ran), ``qp_capped`` (local
        QPs that hit their active-set iteration cap, normally 0), ``nonnegative`` (the setting
        used) and ``seconds``.
    callback : callable(stage, iteration, value) -> bool | None, optional
        Called about every 0.1 s with the sweep and objective; returning False stops.

    Returns
    -------
    indices : (n, k) int64
        Kept handles per vertex, in decreasing order of the original weight.
    weights : (n, k) float
        Their weights; rows sum to 1.
    info : Info, only with ``return_info=True``.

    Examples
    --------
    >>> import numpy as np, skinrs
    >>> W = np.array([[.6, .3, .1], [.1, .5, .4]])
    >>> I, A = skinrs.reduce_weights(W, 2, method="k-largest")
    >>> I.tolist(), np.round(A, 3).tolist()
    ([[0, 1], [1, 2]], [[0.667, 0.333], [0.556, 0.444]])
    """
    t0 = time.perf_counter()
    if not isinstance(method, str) or method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}, got {method!r}")
    W = as_weights(W)
    n, m = W.shape
    k = positive_int(k, "k")
    if k > m:
        raise ValueError(f"k must be between 1 and the number of handles m = {m}, got {k}")
    if V is not None:
        V = as_points(V, "V")
        if V.shape[0] != n:
            raise ValueError(f"V must have one row per row of W ({n}), got {V.shape[0]}")
    if F is not None:
        if V is None:
            raise ValueError("F needs the vertices V")
        F = as_elements(F, V, "F", cols=3)
    d = None if V is None else V.shape[1]
    P, T, _ = _poses(
        control_points, bone_transforms, m, d, required=method in ("geometric", "poisson")
    )
    if T is not None and V is None:
        raise ValueError("bone_transforms need the rest vertices V")
    if C is not None:
        C = as_points(C, "C")
    if nonnegative is None:
        nonnegative = bool(T is not None or W.min() >= 0)
    max_sweeps = positive_int(max_sweeps, "max_sweeps", hi=2**63 - 1)
    tol = _checks.non_negative_float(tol, "tol")
    relaxation = positive_float(relaxation, "relaxation")
    if not isinstance(energy, str) or energy not in ENERGIES:
        raise ValueError(f"energy must be one of {ENERGIES}, got {energy!r}")
    if not isinstance(solver, str) or solver not in SOLVERS:
        raise ValueError(f"solver must be one of {SOLVERS}, got {solver!r}")
    callback = _checks.as_callback(callback)
    I, A, obj, converged, colours, capped = _skinrs.reduce_weights(
        W,
        k,
        method,
        v=V,
        f=F,
        control_points=P,
        bone_transforms=T,
        c=C,
        nonnegative=bool(nonnegative),
        max_sweeps=max_sweeps,
        tol=tol,
        relaxation=relaxation,
        energy=energy,
        solver=solver,
        callback=callback,
    )
    if not return_info:
        return I, A
    objective = np.asarray(obj)
    info = Info(
        objective=objective,
        sweeps=max(len(objective) - 1, 0),
        converged=converged,
        colours=colours,
        qp_capped=capped,
        nonnegative=bool(nonnegative),
        seconds=time.perf_counter() - t0,
    )
    return I, A, info
