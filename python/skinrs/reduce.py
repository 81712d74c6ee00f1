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
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Literal, TypedDict, overload

import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike, NDArray

from . import _checks, _skinrs
from ._checks import (
    Callback,
    as_elements,
    as_index_array,
    as_points,
    as_weights,
    positive_float,
    positive_int,
)
from ._info import Info

if TYPE_CHECKING:
    from typing_extensions import Unpack
from .skinning import forward_kinematics

#: Choice lists and defaults of :func:`reduce_weights` (from the Rust core).
METHODS: tuple[str, ...] = _skinrs.REDUCE_METHODS
ENERGIES: tuple[str, ...] = _skinrs.REDUCE_ENERGIES
SOLVERS: tuple[str, ...] = _skinrs.REDUCE_SOLVERS
_DEFAULTS: dict[str, Any] = _skinrs.REDUCE_DEFAULTS

#: Packed weights ``(indices (n, k) int, weights (n, k) float)``.
Packed = tuple[NDArray[np.int64], NDArray[np.float64]]


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


@dataclass
class ReductionError:
    """Paper 002 Sec. 6 errors of a reduced animation against the full-weight one.

    normal_angle : (p, n) angle (radians) between area-weighted vertex normals.
    normal_rms : (p,) RMS normal deviation per pose (radians).
    position_rms : (p,) RMS vertex distance per pose, in percent of the bounding-box diagonal
        of the full-weight pose.
    normal_rms_all, position_rms_all : the same over all poses.
    """

    normal_angle: np.ndarray
    normal_rms: np.ndarray
    position_rms: np.ndarray
    normal_rms_all: float
    position_rms_all: float


def _poses(
    control_points: ArrayLike | None,
    bone_transforms: ArrayLike | None,
    m: int,
    d: int | None,
    *,
    required: bool,
) -> tuple[NDArray[np.float64] | None, NDArray[np.float64] | None, bool]:
    """Checks the example poses; a single pose may be given without the leading axis.

    Returns ``(control_points, bone_transforms, single)``, batched, one of them ``None``.
    """
    if control_points is not None and bone_transforms is not None:
        raise ValueError("pass either control_points or bone_transforms, not both")
    if control_points is None and bone_transforms is None:
        if required:
            raise ValueError("example poses are needed: pass control_points or bone_transforms")
        return None, None, False
    if control_points is not None:
        P = _checks.as_real_array(control_points, "control_points")
        single = P.ndim == 2
        P = _checks.as_array(P[None] if single else P, "control_points", 3)
        dd = P.shape[2] if d is None else d
        if P.shape[0] < 1 or P.shape[1:] != (m, dd):
            raise ValueError(
                f"control_points must have shape (p, {m}, {dd}) (p poses of the {m} handles), "
                f"got {np.shape(control_points)}"
            )
        return P, None, single
    assert bone_transforms is not None
    T = _checks.as_real_array(bone_transforms, "bone_transforms")
    single = T.ndim == 3
    T = _checks.as_array(T[None] if single else T, "bone_transforms", 4)
    dd = 3 if d is None else d
    if T.shape[0] < 1 or T.shape[1:] != (m, dd, dd + 1):
        raise ValueError(
            f"bone_transforms must have shape (p, {m}, {dd}, {dd + 1}) (affine [A | t] per pose "
            f"and bone), got {np.shape(bone_transforms)}"
        )
    return None, T, single


def _packed(
    reduced: Packed | ArrayLike, n: int | None = None
) -> tuple[NDArray[np.int64], NDArray[np.float64], int]:
    """``(indices, weights)`` or a dense ``(n, m)`` matrix -> int64 indices, float weights, m."""
    if isinstance(reduced, tuple) and len(reduced) == 2:
        Wr = as_points(reduced[1], "weights", dims=None, coordinates=False)
        I = _checks.as_real_array(reduced[0], "indices")
        if I.shape != Wr.shape:
            raise ValueError(
                f"indices and weights must have the same shape, got {I.shape} and {Wr.shape}"
            )
        I = as_index_array(I, 1 << 62, "indices")
        if n is not None and I.shape[0] != n:
            raise ValueError(f"weights must have {n} rows (one per vertex), got {I.shape[0]}")
        return I, Wr, int(I.max()) + 1 if I.size else 0
    W = as_weights(reduced, n)
    n_, m = W.shape
    I = np.ascontiguousarray(np.broadcast_to(np.arange(m, dtype=np.int64), (n_, m)))
    return I, W, m


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


def unpack_weights(
    indices: ArrayLike, weights: ArrayLike, m: int, *, sparse: bool = False
) -> NDArray[np.float64] | sp.csr_matrix:
    """Dense ``(n, m)`` (or ``scipy.sparse.csr_matrix`` with ``sparse=True``) view of packed weights.

    >>> import numpy as np, skinrs
    >>> skinrs.unpack_weights(np.array([[2, 0]]), np.array([[.75, .25]]), 3).tolist()
    [[0.25, 0.0, 0.75]]
    """
    m = positive_int(m, "m")
    Wr = as_points(weights, "weights", dims=None, coordinates=False)
    if not sparse:
        _checks.fits_in_memory(
            8.0 * Wr.shape[0] * m, f"a dense ({Wr.shape[0]}, {m}) matrix (m={m})"
        )
    I = _checks.as_real_array(indices, "indices")
    if I.shape != Wr.shape:
        raise ValueError(
            f"indices and weights must have the same shape, got {I.shape} and {Wr.shape}"
        )
    I = as_index_array(I, m, "indices")
    n, k = I.shape
    rows = np.repeat(np.arange(n), k)
    S = sp.csr_matrix((Wr.ravel(), (rows, I.ravel())), shape=(n, m))
    return S if sparse else S.toarray()


def deform(
    V: ArrayLike,
    W: Packed | ArrayLike,
    *,
    control_points: ArrayLike | None = None,
    bone_transforms: ArrayLike | None = None,
) -> NDArray[np.float64]:
    """Deform rest vertices with full or packed weights (linear blend skinning / cage blending).

    ``x_v = sum_i W_vi c_i`` (cages) or ``x_v = sum_i W_vi A_i [v; 1]`` (bones).

    Parameters
    ----------
    V : (n, d) rest vertices.
    W : (n, m) dense weights, or ``(indices, weights)`` packed ``(n, k)``.
    control_points : (p, m, d) or (m, d); bone_transforms : (p, m, d, d+1) or (m, d, d+1).

    Returns
    -------
    (p, n, d) deformed positions, or (n, d) when a single pose was given.
    """
    V = as_points(V, "V")
    packed = isinstance(W, tuple)
    I, A, m = _packed(W, V.shape[0])
    m = _handle_count(control_points, bone_transforms, m, packed)
    P, T, single = _poses(control_points, bone_transforms, m, V.shape[1], required=True)
    X = _skinrs.reduce_deform(V, A, I if packed else None, P, T)
    return X[0] if single else X


def _handle_count(
    control_points: ArrayLike | None, bone_transforms: ArrayLike | None, m: int, packed: bool
) -> int:
    """Handle count of the poses: dense weights fix it, packed weights bound it from below."""
    X = control_points if control_points is not None else bone_transforms
    if X is None or not packed:
        return m
    name = "control_points" if control_points is not None else "bone_transforms"
    shape = _checks.as_real_array(X, name).shape
    single = len(shape) == (2 if control_points is not None else 3)
    mp = shape[0] if single else (shape[1] if len(shape) > 1 else 0)
    if mp < m:
        raise ValueError(f"the weights refer to handle {m - 1}, but {name} has {mp} handles")
    return mp


def transform_normals(
    N: ArrayLike,
    reduced: Packed | ArrayLike,
    *,
    control_points: ArrayLike | None = None,
    bone_transforms: ArrayLike | None = None,
    C: ArrayLike | None = None,
) -> NDArray[np.float64]:
    """Deform rest normals from (packed) weights without mesh adjacency (paper 002 Sec. 5).

    Skeletons: ``n' ~ (sum_i a_i A_i)^-T n``. Cages: the affine map fitted per vertex by weighted
    least squares to its control points (weights ``a_i^2``), whose inverse transpose is
    ``adj(sum a_i^2 d_i d^_i^T) (sum a_i^2 d_i d_i^T)`` with ``d_i``, ``d^_i`` the rest and
    deformed control points relative to their weighted centroids; exact when the cage moves
    affinely or ``k = 4`` points are affinely independent.

    Parameters
    ----------
    N : (n, 3) rest unit normals.
    reduced : ``(indices, weights)`` packed or (n, m) dense weights.
    control_points : (p, m, 3) or (m, 3), with ``C`` (m, 3) the rest control points;
    bone_transforms : (p, m, 3, 4) or (m, 3, 4).

    Returns
    -------
    (p, n, 3) unit normals, or (n, 3) for a single pose.
    """
    N = as_points(N, "N", dims=(3,))
    I, A, m = _packed(reduced, N.shape[0])
    m = _handle_count(control_points, bone_transforms, m, isinstance(reduced, tuple))
    P, T, single = _poses(control_points, bone_transforms, m, 3, required=True)
    if P is not None:
        if C is None:
            raise ValueError("normals of a cage deformation need the rest control points C")
        C = as_points(C, "C", dims=(3,))
        if C.shape[0] != m:
            raise ValueError(f"C must have {m} rows (one per control point), got {C.shape[0]}")
    elif C is not None:
        raise ValueError("C (rest control points) is only used with control_points")
    X = _skinrs.reduce_transform_normals(N, I, A, P, T, C)
    return X[0] if single else X


def reduction_error(
    V: ArrayLike,
    F: ArrayLike,
    W: ArrayLike,
    reduced: Packed | ArrayLike,
    *,
    control_points: ArrayLike | None = None,
    bone_transforms: ArrayLike | None = None,
) -> ReductionError:
    """Paper 002 Sec. 6 metrics of reduced weights against the full weights over some poses.

    Both weight sets deform ``V``; normals are recomputed from each deformed mesh
    (area-weighted vertex normals) and compared by angle; positions by distance, in percent of
    the bounding-box diagonal of the full-weight pose. Use poses that were *not* used for fitting.

    Parameters
    ----------
    V : (n, 3), F : (f, 3) rest mesh.
    W : (n, m) full weights.
    reduced : ``(indices, weights)`` packed ``(n, k)`` (or dense (n, m)).
    control_points : (p, m, 3) or bone_transforms : (p, m, 3, 4) evaluation poses.

    Returns
    -------
    ReductionError
    """
    V = as_points(V, "V", dims=(3,))
    F = as_elements(F, V, "F", cols=3)
    W = as_weights(W, V.shape[0])
    full = deform(V, W, control_points=control_points, bone_transforms=bone_transforms)
    red = deform(V, reduced, control_points=control_points, bone_transforms=bone_transforms)
    if full.ndim == 2:
        full, red = full[None], red[None]
    ang, normal_rms, position_rms = _skinrs.reduce_deformation_errors(F, full, red)
    nrms, prms = np.asarray(normal_rms), np.asarray(position_rms)
    return ReductionError(
        normal_angle=ang,
        normal_rms=nrms,
        position_rms=prms,
        normal_rms_all=float(np.sqrt(np.mean(nrms**2))),
        position_rms_all=float(np.sqrt(np.mean(prms**2))),
    )


def _bones(C: ArrayLike, BE: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    C = as_points(C, "C", dims=(3,))
    BE = as_index_array(BE, C.shape[0], "BE", cols=2, allow_empty=False)
    return C, BE


def _rotation(axis: NDArray[np.float64], angle: float) -> NDArray[np.float64]:
    """Rodrigues' formula for a unit axis."""
    x, y, z = axis
    K = np.array([[0, -z, y], [z, 0, -x], [-y, x, 0]])
    R: NDArray[np.float64] = np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * (K @ K)
    return R


def random_skeleton_poses(
    C: ArrayLike,
    BE: ArrayLike,
    n_poses: int,
    *,
    max_angle: float = np.pi / 6,
    max_twist: float | None = None,
    seed: int | np.random.Generator | None = None,
) -> NDArray[np.float64]:
    """Random plausible skeleton poses: bounded bends and twists of every bone about its head.

    Relative to its parent, each bone bends about a uniformly random axis perpendicular to the
    bone by an angle drawn uniformly from ``[-max_angle, max_angle]``, then twists about its own
    axis by at most ``max_twist``; forward kinematics chains them. The relative rotation of a bone
    is therefore at most ``max_angle + max_twist``.

    Parameters
    ----------
    C : (j, 3) rest joint positions. BE : (m, 2) bones (head, tail) as joint indices; a forest.
    n_poses : int. max_angle : float, radians. max_twist : float, radians (default
    ``max_angle / 3``; 0 for none). seed : int or numpy Generator.

    Returns
    -------
    (n_poses, m, 3, 4) bone transforms ``[A | t]``, ready for ``bone_transforms=``.

    >>> import numpy as np, skinrs
    >>> T = skinrs.random_skeleton_poses([[0, 0, 0], [0, 1, 0]], [[0, 1]], 2, seed=1)
    >>> T.shape
    (2, 1, 3, 4)
    """
    C, BE = _bones(C, BE)
    n_poses = positive_int(n_poses, "n_poses")
    max_angle = positive_float(max_angle, "max_angle")
    if max_angle > np.pi:
        raise ValueError(f"max_angle must be at most pi (radians), got {max_angle!r}")
    max_twist = (
        max_angle / 3 if max_twist is None else _checks.non_negative_float(max_twist, "max_twist")
    )
    if max_twist > np.pi:
        raise ValueError(f"max_twist must be at most pi (radians), got {max_twist!r}")
    if not isinstance(seed, np.random.Generator):
        seed = _checks.seed(seed)
    rng = np.random.default_rng(seed)
    m = BE.shape[0]
    _checks.fits_in_memory(96.0 * n_poses * m, f"n_poses={n_poses} poses of {m} bones")
    axis = C[BE[:, 1]] - C[BE[:, 0]]
    length = np.linalg.norm(axis, axis=1, keepdims=True)
    if np.any(length == 0):
        raise ValueError(f"bone {int(np.flatnonzero(length == 0)[0])} has zero length")
    axis /= length
    out = np.empty((n_poses, m, 3, 4))
    for p in range(n_poses):
        bend = rng.normal(size=(m, 3))
        bend -= (bend * axis).sum(1, keepdims=True) * axis  # perpendicular to the bone
        bend /= np.linalg.norm(bend, axis=1, keepdims=True)
        angles = np.asarray(rng.uniform(-max_angle, max_angle, size=m))
        twists = np.asarray(rng.uniform(-max_twist, max_twist, size=m))
        R = np.stack(
            [_rotation(b, a) @ _rotation(d, t) for b, a, d, t in zip(bend, angles, axis, twists)]
        )
        out[p] = forward_kinematics(C, BE, R)
    return out
