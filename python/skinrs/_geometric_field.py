""":class:`GeometricField`: mesh-free bounded biharmonic weights (Dodik et al. 2024)."""

from __future__ import annotations

import sys
from typing import Any, Literal, overload

import numpy as np
from numpy.typing import ArrayLike, NDArray

from . import _checks, _skinrs
from ._checks import Callback
from ._field_options import (
    _boundary_edges_2d,
    _check_field_memory,
    _handles,
)
from ._info import Info


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


def _describe(stage: str, iteration: int, value: float) -> str:
    return f"{stage} step {iteration}: energy {value:.4g}"
