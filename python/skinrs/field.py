"""Geometric queries for mesh-free skinning weights (Dodik et al. 2024).

The boundary is either a triangle mesh or soup in 3D (``V`` (n, 3), ``F`` (m, 3)) or a set of
segments in 2D (``V`` (n, 2), ``F`` (m, 2)); it need not be closed, manifold or consistently
connected. Normals follow libigl: outward for counter-clockwise triangles seen from outside and
for counter-clockwise outer polygons in 2D.

* :func:`winding_number`: generalized winding number, hierarchical (Barill et al. 2018) in 2D
  and 3D; 1 inside, 0 outside, in between for open shapes.
* :func:`segment_visible`: the visibility indicator of the kernel ``k_RT`` (eq. 4).
* :func:`closest_point`: closest boundary point, its primitive and normal (eq. 9).
* :func:`knn_distance`: distance to the k-th nearest neighbour (``sigma`` heuristic).
* :class:`GeometricField`, :func:`bbw_field`: mesh-free bounded biharmonic weights on the
  visibility-aware point field (Secs. 4-5, App. A).

Each call builds its acceleration structure in Rust (in parallel, with the GIL released).
"""

from __future__ import annotations

import sys
import time
from typing import TYPE_CHECKING, Any, Literal, TypedDict, overload

import numpy as np
from numpy.typing import ArrayLike, NDArray

from . import _checks, _skinrs
from ._checks import Callback
from ._info import Info

if TYPE_CHECKING:
    from typing_extensions import Unpack


def _boundary(V: ArrayLike, F: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    V = _checks.as_points(V, "V")
    d = V.shape[1]
    F = _checks.as_index_array(F, V.shape[0], "F", cols=d, allow_empty=False)
    return V, F


def _queries(Q: ArrayLike, d: int, name: str) -> NDArray[np.float64]:
    Q = _checks.as_points(Q, name, dims=(d,), min_rows=0)
    return Q


def winding_number(
    V: ArrayLike, F: ArrayLike, Q: ArrayLike, *, beta: float | None = None
) -> NDArray[np.float64]:
    """Generalized winding number of a boundary at query points.

    Parameters
    ----------
    V : (n, 3) or (n, 2) float array
        Vertex positions.
    F : (m, 3) or (m, 2) int array
        Triangles in 3D, segments in 2D (rows index ``V``). Degenerate elements are allowed and
        contribute nothing.
    Q : (nq, d) float array
        Query points, same dimension as ``V``.
    beta : float, optional
        Accuracy of the far-field expansion (Barill et al. 2018): a tree node is replaced by its
        order-2 expansion for queries farther than ``beta`` times its radius. Larger is more
        accurate and slower; ``np.inf`` gives the exact sum. Default: 2 in 3D (Barill et al.'s
        and libigl's choice), 4 in 2D, where the angle kernel decays only like ``1/d`` and
        ``beta=2`` would be ~10x less accurate than in 3D.

    Returns
    -------
    w : (nq,) float array
        1 inside a closed outward-oriented shape (counter-clockwise polygon in 2D), 0 outside,
        as ``igl.winding_number``. With the default ``beta`` the largest deviation from the
        exact value, reached next to the boundary, is a few 1e-3 (in 3D like
        ``igl.fast_winding_number``), the median a few 1e-4; ``beta=3`` brings the 3D maximum
        under 1e-3.

    Examples
    --------
    >>> import numpy as np, skinrs
    >>> V = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    >>> E = np.array([[0, 1], [1, 2], [2, 3], [3, 0]])
    >>> w = skinrs.winding_number(V, E, np.array([[0.5, 0.5], [2.0, 0.5]]))
    >>> np.abs(w).round(12)
    array([1., 0.])
    """
    V, F = _boundary(V, F)
    Q = _queries(Q, V.shape[1], "Q")
    if beta is None:
        beta = 2.0 if V.shape[1] == 3 else 4.0
    try:
        beta = float(beta)
    except (TypeError, ValueError):
        raise ValueError(f"beta must be a positive number, got {beta!r}") from None
    if not beta > 0:
        raise ValueError(f"beta must be positive, got {beta!r}")
    return _skinrs._winding_number(V, F, Q, beta)


def segment_visible(V: ArrayLike, F: ArrayLike, P: ArrayLike, Q: ArrayLike) -> NDArray[np.bool_]:
    """Whether each segment ``P[i] -> Q[i]`` avoids the boundary (``V``, ``F``).

    The segment is open: touching the boundary at ``P[i]`` or ``Q[i]`` does not block it, and
    a boundary element lying in the same plane (3D) or line (2D) as the segment does not block
    it either. Element edges and vertices do block.

    Parameters
    ----------
    V, F : boundary as in :func:`winding_number`
    P, Q : (nq, d) float arrays
        Segment end points.

    Returns
    -------
    visible : (nq,) bool array
        True where the open segment crosses no element.

    Examples
    --------
    >>> import numpy as np, skinrs
    >>> V = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    >>> E = np.array([[0, 1], [1, 2], [2, 3], [3, 0]])
    >>> skinrs.segment_visible(V, E, [[0.5, 0.5], [0.5, 0.5]], [[0.2, 0.8], [1.5, 0.5]])
    array([ True, False])
    """
    V, F = _boundary(V, F)
    P = _queries(P, V.shape[1], "P")
    Q = _queries(Q, V.shape[1], "Q")
    if P.shape[0] != Q.shape[0]:
        raise ValueError(f"P and Q must have the same number of rows, got {P.shape} and {Q.shape}")
    return ~_skinrs._segment_hits(V, F, P, Q)


def closest_point(
    V: ArrayLike, F: ArrayLike, Q: ArrayLike
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.int64], NDArray[np.float64]]:
    """Closest point of the boundary (``V``, ``F``) to each query point.

    Parameters
    ----------
    V, F : boundary as in :func:`winding_number`
    Q : (nq, d) float array

    Returns
    -------
    dist : (nq,) float array
        Euclidean distance to the boundary.
    point : (nq, d) float array
        The closest point.
    face : (nq,) int64 array
        Row of ``F`` holding it (on exact ties, the lowest tied row).
    normal : (nq, d) float array
        Unit normal of that element: ``(b - a) x (c - a)`` normalised for triangles, the segment
        direction turned clockwise by 90 degrees in 2D; zero for degenerate elements.

    Examples
    --------
    >>> import numpy as np, skinrs
    >>> V = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    >>> E = np.array([[0, 1], [1, 2], [2, 3], [3, 0]])
    >>> d, p, f, n = skinrs.closest_point(V, E, [[0.5, -0.5]])
    >>> d, p, f, n
    (array([0.5]), array([[0.5, 0. ]]), array([0]), array([[ 0., -1.]]))
    """
    V, F = _boundary(V, F)
    Q = _queries(Q, V.shape[1], "Q")
    return _skinrs._closest_point(V, F, Q)


def knn_distance(X: ArrayLike, *, k: int = 9) -> NDArray[np.float64]:
    """Distance from each point to its ``k``-th nearest other point (hash-grid search).

    ``np.median(knn_distance(X, k=9))`` is the kernel width ``sigma`` of Dodik et al. (Sec. 6.2).
    Coincident points count as neighbours at distance 0.

    Parameters
    ----------
    X : (n, 2) or (n, 3) float array
    k : int, 1 <= k < n

    Returns
    -------
    d : (n,) float array

    Examples
    --------
    >>> import numpy as np, skinrs
    >>> skinrs.knn_distance(np.array([[0.0, 0.0], [1.0, 0.0], [3.0, 0.0]]), k=1)
    array([1., 1., 2.])
    """
    X = _checks.as_points(X, "X")
    k = _checks.positive_int(k, "k")
    if k >= X.shape[0]:
        raise ValueError(f"k must be smaller than the number of points ({X.shape[0]}), got {k}")
    return _skinrs._knn_distance(X, k)


# --- the geometric field (Dodik et al. 2024, Secs. 4-5, App. A) ------------------------------


class FieldOptions(TypedDict, total=False):
    """The keyword options of :func:`bbw_field` besides ``return_info`` (for type checkers)."""

    tets: ArrayLike | None
    neumann: bool
    seed: int
    verbose: bool
    callback: Callback | None
    n_points: int | None
    samples: int | None
    steps: int | None
    upsamples: int | None
    lr: float | None
    lr_decay: float | None
    beta1: float | None
    beta2: float | None
    adam_eps: float | None
    h: float | None
    eps: float | None
    visibility: bool | None
    wn_l: float | None
    wn_h: float | None
    pool: int | None
    cache_visibility: bool | None
    skip_rays: bool | None


def default_options(dim: int) -> dict[str, Any]:
    """The defaults of :class:`GeometricField`'s options in ``dim`` dimensions (paper App. A).

    An option left at ``None`` takes this value. The values are defined in the Rust core.

    Examples
    --------
    >>> import skinrs
    >>> o = skinrs.field.default_options(3)
    >>> o["n_points"], o["samples"], o["steps"], o["upsamples"], o["lr"], o["pool"]
    (8192, 2048, 6000, 3, 0.2, 65536)
    """
    if dim not in (2, 3):
        raise ValueError(f"dim must be 2 or 3, got {dim!r}")
    return dict(_skinrs._field_defaults(dim))


def _boundary_edges_2d(V: NDArray[np.float64], T: NDArray[np.int64]) -> NDArray[np.int64]:
    """Boundary segments of a 2D triangle mesh, oriented so the interior has winding number 1."""
    a, b, c = (V[T[:, i]] for i in range(3))
    u, v = b - a, c - a
    area = u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0]
    T = np.where((area < 0)[:, None], T[:, [0, 2, 1]], T)
    E = np.concatenate([T[:, [0, 1]], T[:, [1, 2]], T[:, [2, 0]]])
    key = np.sort(E, axis=1)
    _, inv, cnt = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    return np.ascontiguousarray(E[cnt[inv.ravel()] == 1])


def _handles(
    C: ArrayLike, P: ArrayLike | None, BE: ArrayLike | None, d: int
) -> tuple[NDArray[np.float64], NDArray[np.int64], NDArray[np.int64]]:
    C = _checks.as_points(C, "C", min_rows=1)
    if d == 2 and C.shape[1] == 3:
        if np.any(C[:, 2] != 0):
            raise ValueError("V is 2D but C has non-zero z coordinates")
        C = np.ascontiguousarray(C[:, :2])
    if C.shape[1] != d:
        raise ValueError(f"C must have {d} columns like V, got {C.shape}")
    h = C.shape[0]
    P = _checks.as_index_array([] if P is None else P, h, "P", ndim=1)
    BE = _checks.as_index_array(np.zeros((0, 2)) if BE is None else BE, h, "BE", cols=2)
    if len(P) + len(BE) == 0:
        raise ValueError("no handles: give point handles P and/or bone edges BE")
    if len(np.unique(P)) != len(P):
        raise ValueError("P holds a point handle more than once")
    if len(BE) and np.any(np.all(C[BE[:, 0]] == C[BE[:, 1]], axis=1)):
        raise ValueError("BE has a zero-length bone")
    return C, P, BE


def _check_field_memory(d: int, k: int, options: dict[str, Any]) -> None:
    """ValueError before anything is allocated when the point set, samples or pool of a field
    would not fit in memory (defaults as in the Rust core)."""
    three = d == 3
    points = options.get("n_points", 1 << 13 if three else 1 << 11) << options.get("upsamples", 3)
    samples = options.get("samples", 1 << 11 if three else 1 << 12)
    pool = options.get("pool", 1 << 16 if three else 1 << 17)
    cache = options.get("cache_visibility", True)
    # per point: position, parameters and two Adam moments per handle, grid entry; per pool
    # sample: position, winding weight and (cached) up to 64 visible points x 9 neighbours
    nbytes = (
        points * (8 * d + 32 * k + 16)
        + samples * (64 + 8 * k)
        + pool * (8 * d + 16 + (64 * 9 * 4 if cache else 0))
    )
    _checks.fits_in_memory(
        float(nbytes),
        f"a field with n_points * 2^upsamples = {points}, samples = {samples}, pool = {pool}",
    )


class GeometricField:
    """Mesh-free bounded biharmonic weights on a geometric field (Dodik et al. 2024).

    The weights are a kernel field over points sampled inside the shape (eq. 2) whose kernel
    ignores points hidden behind the boundary (eq. 4), made non-negative and partition-of-unity
    by a normalised softplus (Sec. 4.2), exactly one-hot on the handles by a mollifier (eqs. 7,
    15, 16) and optionally zero-Neumann on the boundary (eq. 9). Its parameters minimise a
    Monte-Carlo biharmonic energy (eqs. 10-13) with Adam on a multiscale schedule (App. A). No
    volume mesh is needed: the boundary may be open, self-intersecting or a triangle soup
    (inside/outside by the generalized winding number, eq. 11).

    Parameters
    ----------
    V : (n, 3) or (n, 2) float array
        Vertices (any units; the shape is rescaled into the unit box internally).
    F : (m, 3) int array, (m, 2) int array, or None
        3D: boundary triangles (a mesh, an open mesh or a soup). 2D: boundary segments, or a
        triangle mesh whose boundary is used (and whose triangles are sampled). ``None``: ``V``
        is a point cloud; the domain is the union of balls of the cloud's median 9-NN spacing
        around its points, with no visibility.
    C : (h, d) float array
        Joint / handle positions (a 3-column ``C`` with z = 0 is accepted in 2D).
    BE : (b, 2) int array, optional
        Bone edges into ``C``.
    P : (p,) int array, optional
        Point handles (indices into ``C``). Columns: point handles first, then bones (libigl).
    tets : (t, 4) int array, optional
        A tet mesh of the interior over ``V`` (3D), used only to sample interior points.
    neumann : bool
        Zero-Neumann boundary conditions (eq. 9) instead of natural ones.
    seed : int
        Seed of every random draw; results are bitwise reproducible for a seed.
    verbose : bool
        Print progress of :meth:`optimize` to stderr about every second.
    n_points, samples, steps, upsamples, lr, lr_decay, beta1, beta2, adam_eps, h, eps
        and visibility, wn_l, wn_h, pool, cache_visibility, skip_rays: optional settings of
        the optimisation; ``None`` takes :func:`default_options` for the dimension (paper
        App. A). ``n_points``: initial number of field points; ``samples``: Monte-Carlo
        samples per step M; ``steps``: steps of the full schedule; ``upsamples``: doublings of
        the point set at regular intervals; ``lr``: initial Adam learning rate, divided by
        ``lr_decay`` at each doubling; ``beta1``, ``beta2``, ``adam_eps``: Adam's constants;
        ``h``: finite-difference step of eq. 13 in units of sigma; ``eps``: radius of the
        handle / paint / Neumann neighbourhoods in units of sigma; ``visibility``: the
        visibility-aware kernel k_RT (False: the plain Gaussian k_E); ``wn_l``, ``wn_h``:
        winding-number rejection and full-weight thresholds; ``pool``: interior samples drawn
        once, from which every step draws its M samples; ``cache_visibility``: cache the
        visible points of each pool sample (exact); ``skip_rays``: skip rays covered by
        boundary-free balls (exact; False only to measure).
    resume_steps : int
        Steps of :meth:`optimize` once the schedule is complete, e.g. after :meth:`paint`.

    Examples
    --------
    >>> import numpy as np, skinrs
    >>> V = np.array([[0, 0], [2, 0], [2, 1], [0, 1]], dtype=float)
    >>> E = np.array([[0, 1], [1, 2], [2, 3], [3, 0]])
    >>> C = np.array([[0.3, 0.5], [1.7, 0.5]])
    >>> fld = skinrs.GeometricField(V, E, C, P=[0, 1], steps=40, n_points=256, samples=256,
    ...                             upsamples=1, pool=4096)
    >>> fld.optimize()
    >>> W = fld.evaluate([[0.3, 0.5], [1.0, 0.5], [1.7, 0.5]])
    >>> W.round(2)[[0, 2]].tolist(), bool(np.allclose(W.sum(1), 1))
    ([[1.0, 0.0], [0.0, 1.0]], True)
    """

    def __init__(
        self,
        V: ArrayLike,
        F: ArrayLike | None,
        C: ArrayLike,
        BE: ArrayLike | None = None,
        P: ArrayLike | None = None,
        *,
        tets: ArrayLike | None = None,
        neumann: bool = False,
        seed: int = 0,
        verbose: bool = False,
        n_points: int | None = None,
        samples: int | None = None,
        steps: int | None = None,
        upsamples: int | None = None,
        lr: float | None = None,
        lr_decay: float | None = None,
        beta1: float | None = None,
        beta2: float | None = None,
        adam_eps: float | None = None,
        h: float | None = None,
        eps: float | None = None,
        visibility: bool | None = None,
        wn_l: float | None = None,
        wn_h: float | None = None,
        pool: int | None = None,
        cache_visibility: bool | None = None,
        skip_rays: bool | None = None,
        resume_steps: int = 1500,
    ) -> None:
        given = {
            "n_points": n_points,
            "samples": samples,
            "steps": steps,
            "upsamples": upsamples,
            "lr": lr,
            "lr_decay": lr_decay,
            "beta1": beta1,
            "beta2": beta2,
            "adam_eps": adam_eps,
            "h": h,
            "eps": eps,
            "visibility": visibility,
            "wn_l": wn_l,
            "wn_h": wn_h,
            "pool": pool,
            "cache_visibility": cache_visibility,
            "skip_rays": skip_rays,
        }
        options: dict[str, Any] = {k: v for k, v in given.items() if v is not None}
        V = _checks.as_points(V, "V")
        d = V.shape[1]
        n = V.shape[0]
        self._V = V
        self._adj = np.zeros((0, 2), dtype=np.int64)
        simplices = None
        if F is None:
            if n <= 9:
                raise ValueError(f"V: a point cloud (F=None) needs more than 9 points, got {n}")
            Fb = None
            self._normal_elems = np.zeros((0, d), dtype=np.int64)
        else:
            F = _checks.as_index_array(F, n, "F", cols=(2, 3), allow_empty=False)
            if d == 3 and F.shape[1] != 3:
                raise ValueError(f"in 3D, F must hold triangles (m, 3), got {F.shape}")
            if d == 2 and F.shape[1] == 3:
                simplices = F
                Fb = _boundary_edges_2d(V, F)
                if len(Fb) == 0:
                    raise ValueError("the 2D triangle mesh F has no boundary edges")
            else:
                Fb = F
            self._adj = F
            self._normal_elems = Fb
        if tets is not None:
            if d != 3:
                raise ValueError("tets are for 3D shapes; in 2D pass the triangles as F")
            simplices = _checks.as_index_array(tets, n, "tets", cols=4, allow_empty=False)
        C, P, BE = _handles(C, P, BE, d)
        self._resume = _checks.positive_int(resume_steps, "resume_steps")
        for key in ("n_points", "samples", "steps", "pool"):
            if key in options:
                options[key] = _checks.positive_int(options[key], key, hi=2**62)
        if "upsamples" in options:
            options["upsamples"] = _checks.integer(options["upsamples"], "upsamples", 0, 8)
        for key in ("lr", "lr_decay", "h", "eps", "adam_eps"):
            if key in options:
                options[key] = _checks.positive_float(options[key], key)
        for key in ("beta1", "beta2", "wn_l", "wn_h"):
            if key in options:
                options[key] = _checks.finite_float(options[key], key)
        for key in ("visibility", "cache_visibility", "skip_rays"):
            if key in options:
                options[key] = bool(options[key])
        seed = _checks.integer(seed, "seed", 0, 2**64 - 1)
        _check_field_memory(d, len(P) + len(BE), options)
        options.update(neumann=bool(neumann), seed=int(seed))
        self.k = len(P) + len(BE)
        self.dim = d
        self.verbose = bool(verbose)
        self._f = _skinrs._GeometricField(V, Fb, simplices, C, P, BE, options)

    def optimize(self, *, steps: int | None = None, callback: Callback | None = None) -> None:
        """Run Adam on the Monte-Carlo biharmonic energy.

        Parameters
        ----------
        steps : int, optional
            Number of steps. Default: to the end of the schedule (``steps`` option, with the
            point set doubled ``upsamples`` times on the way); once the schedule is complete
            (e.g. after :meth:`paint`), ``resume_steps`` more steps at the final resolution.
        callback : callable, optional
            ``callback(stage, step, energy)`` about every 0.1 s (stage ``"optimize"``);
            returning ``False`` stops (raises ``KeyboardInterrupt``); Ctrl-C also stops, and
            the field keeps the steps done so far.
        """
        if steps is not None:
            steps = _checks.positive_int(steps, "steps", hi=2**62)
        cb = _checks.progress_printer(self.verbose, callback, _describe)
        self._f.optimize(steps, self._resume, cb)
        if self.verbose:
            i = self.info()
            print(
                f"skinrs.GeometricField: step {i['step']}, {i['n_points']} points, energy "
                f"{i['energy']:.4g}, {i['time_optimize']:.1f} s",
                file=sys.stderr,
            )

    def paint(self, points: ArrayLike, weights: ArrayLike) -> None:
        """Add painted Dirichlet conditions (Sec. 4.3, Fig. 6); then :meth:`optimize` resumes.

        Parameters
        ----------
        points : (q, d) float array
            Painted positions (usually boundary points or vertices), in the input's units.
        weights : (q, K) float array or (K,) array
            Prescribed weights there: rows >= 0 summing to 1. A single row applies to every
            point. Points painted again get the new value.
        """
        Q = _checks.as_points(points, "points", dims=(self.dim,))
        W = _checks.as_real_array(weights, "weights")
        if W.ndim == 1:
            W = np.tile(W, (Q.shape[0], 1))
        W = _checks.as_weights(W, Q.shape[0], "weights")
        if W.shape[1] != self.k:
            raise ValueError(f"weights must have {self.k} columns (one per handle), got {W.shape}")
        if W.min() < 0 or np.any(np.abs(W.sum(1) - 1) > 1e-9):
            raise ValueError("painted weights must be >= 0 with rows summing to 1")
        self._f.paint(Q, np.ascontiguousarray(W))

    @overload
    def evaluate(
        self, Q: ArrayLike, *, return_status: Literal[False] = False
    ) -> NDArray[np.float64]: ...
    @overload
    def evaluate(
        self, Q: ArrayLike, *, return_status: Literal[True]
    ) -> tuple[NDArray[np.float64], NDArray[np.uint8]]: ...
    @overload
    def evaluate(
        self, Q: ArrayLike, *, return_status: bool
    ) -> NDArray[np.float64] | tuple[NDArray[np.float64], NDArray[np.uint8]]: ...
    def evaluate(
        self, Q: ArrayLike, *, return_status: bool = False
    ) -> NDArray[np.float64] | tuple[NDArray[np.float64], NDArray[np.uint8]]:
        """Weights at arbitrary points (eq. 7).

        Parameters
        ----------
        Q : (q, d) float array in the input's units
        return_status : bool
            Also return per row 0 (visible points found), 1 (none visible: plain Gaussian
            kernel), 2 (no point within the kernel: nearest point's value).

        Returns
        -------
        W : (q, K) float array, rows >= 0 summing to 1, one-hot on handles
        """
        Q = _checks.as_points(Q, "Q", dims=(self.dim,), min_rows=0)
        W, s = self._f.evaluate(Q)
        return (W, s) if return_status else W

    @overload
    def vertex_weights(self, *, return_status: Literal[False] = False) -> NDArray[np.float64]: ...
    @overload
    def vertex_weights(
        self, *, return_status: Literal[True]
    ) -> tuple[NDArray[np.float64], NDArray[np.uint8]]: ...
    @overload
    def vertex_weights(
        self, *, return_status: bool
    ) -> NDArray[np.float64] | tuple[NDArray[np.float64], NDArray[np.uint8]]: ...
    def vertex_weights(
        self, *, return_status: bool = False
    ) -> NDArray[np.float64] | tuple[NDArray[np.float64], NDArray[np.uint8]]:
        """Weights at the input vertices ``V`` (App. A, "Evaluation on the boundary").

        Rays start 1e-5 (unit-box units) inside along the vertex normal; vertices outside the
        shape or occluded from every point take the average of their neighbours (flood fill);
        the rest falls back to the kernel without visibility. ``return_status`` also returns
        per vertex 0 (direct), 3 (flood-filled), 1 (no visibility), 2 (nearest point).

        Returns
        -------
        W : (n, K) float array
        """
        W, s = self._f.vertex_weights(self._V, self._normal_elems, self._adj)
        return (W, s) if return_status else W

    def info(self) -> Info:
        """Diagnostics: n_points, sigma, step, schedule_steps, lr, energy, rays, timings, and
        ``converged`` (the schedule is complete) and ``seconds`` (time spent optimising)."""
        i = Info(self._f.info())
        i["converged"] = i["step"] >= i["schedule_steps"]
        i["seconds"] = i["time_optimize"]
        return i

    @property
    def points(self) -> NDArray[np.float64]:
        """The field's points ``x_i`` (N, d), in the input's units."""
        return self._f.points()

    @property
    def params(self) -> NDArray[np.float64]:
        """The parameters ``f_i`` (N, K)."""
        return self._f.params()

    def energy(self, f: ArrayLike, *, step: int = 0) -> tuple[float, NDArray[np.float64]]:
        """Monte-Carlo energy (eq. 11) and its hand-derived gradient at parameters ``f`` (N, K),
        with the samples of optimisation step ``step`` (for checks)."""
        f = _checks.as_points(f, "f", dims=(self.k,), coordinates=False)
        step = _checks.integer(step, "step", 0, 2**64 - 1)
        return self._f.energy(f, step)


@overload
def bbw_field(
    V: ArrayLike,
    F: ArrayLike | None,
    C: ArrayLike,
    BE: ArrayLike | None = None,
    P: ArrayLike | None = None,
    *,
    return_info: Literal[False] = False,
    **options: Unpack[FieldOptions],
) -> NDArray[np.float64]: ...
@overload
def bbw_field(
    V: ArrayLike,
    F: ArrayLike | None,
    C: ArrayLike,
    BE: ArrayLike | None = None,
    P: ArrayLike | None = None,
    *,
    return_info: Literal[True],
    **options: Unpack[FieldOptions],
) -> tuple[NDArray[np.float64], Info]: ...
@overload
def bbw_field(
    V: ArrayLike,
    F: ArrayLike | None,
    C: ArrayLike,
    BE: ArrayLike | None = None,
    P: ArrayLike | None = None,
    *,
    return_info: bool,
    **options: Unpack[FieldOptions],
) -> NDArray[np.float64] | tuple[NDArray[np.float64], Info]: ...
def bbw_field(
    V: ArrayLike,
    F: ArrayLike | None,
    C: ArrayLike,
    BE: ArrayLike | None = None,
    P: ArrayLike | None = None,
    *,
    tets: ArrayLike | None = None,
    neumann: bool = False,
    seed: int = 0,
    verbose: bool = False,
    callback: Callback | None = None,
    return_info: bool = False,
    n_points: int | None = None,
    samples: int | None = None,
    steps: int | None = None,
    upsamples: int | None = None,
    lr: float | None = None,
    lr_decay: float | None = None,
    beta1: float | None = None,
    beta2: float | None = None,
    adam_eps: float | None = None,
    h: float | None = None,
    eps: float | None = None,
    visibility: bool | None = None,
    wn_l: float | None = None,
    wn_h: float | None = None,
    pool: int | None = None,
    cache_visibility: bool | None = None,
    skip_rays: bool | None = None,
) -> NDArray[np.float64] | tuple[NDArray[np.float64], Info]:
    """Bounded biharmonic weights at the vertices of ``V`` without a volume mesh.

    One-shot :class:`GeometricField` (same arguments and options): optimise with the full
    schedule, return :meth:`GeometricField.vertex_weights`. ``callback`` is that of
    :meth:`GeometricField.optimize`; ``return_info`` also returns
    :meth:`GeometricField.info`.

    Examples
    --------
    >>> import numpy as np, skinrs
    >>> V = np.array([[0, 0], [2, 0], [2, 1], [0, 1]], dtype=float)
    >>> E = np.array([[0, 1], [1, 2], [2, 3], [3, 0]])
    >>> W = skinrs.bbw_field(V, E, [[0.3, 0.5], [1.7, 0.5]], P=[0, 1], steps=40,
    ...                      n_points=256, samples=256, upsamples=1, pool=4096)
    >>> W.shape, bool(np.allclose(W.sum(1), 1))
    ((4, 2), True)
    """
    t0 = time.perf_counter()
    fld = GeometricField(
        V,
        F,
        C,
        BE=BE,
        P=P,
        tets=tets,
        neumann=neumann,
        seed=seed,
        verbose=verbose,
        n_points=n_points,
        samples=samples,
        steps=steps,
        upsamples=upsamples,
        lr=lr,
        lr_decay=lr_decay,
        beta1=beta1,
        beta2=beta2,
        adam_eps=adam_eps,
        h=h,
        eps=eps,
        visibility=visibility,
        wn_l=wn_l,
        wn_h=wn_h,
        pool=pool,
        cache_visibility=cache_visibility,
        skip_rays=skip_rays,
    )
    fld.optimize(callback=callback)
    W = fld.vertex_weights()
    if not return_info:
        return W
    info = fld.info()
    info["seconds"] = time.perf_counter() - t0
    return W, info


def _describe(stage: str, iteration: int, value: float) -> str:
    return f"{stage} step {iteration}: energy {value:.4g}"
