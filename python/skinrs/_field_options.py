"""Options and argument checks of the geometric field (:mod:`skinrs.field`)."""

from __future__ import annotations

from typing import Any, TypedDict

import numpy as np
from numpy.typing import ArrayLike, NDArray

from . import _checks, _skinrs
from ._checks import Callback


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
