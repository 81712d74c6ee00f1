"""Points on the handles: point handles and bones sampled at a given spacing (paper 000, Sec. 7)."""

from __future__ import annotations

import itertools
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray


def _mean_edge_length(V: NDArray[Any], F: NDArray[Any]) -> float:
    E = (
        np.vstack([F[:, [i, (i + 1) % F.shape[1]]] for i in range(F.shape[1])])
        if F.shape[1] > 2
        else F
    )
    E = np.unique(np.sort(E, axis=1), axis=0)
    return float(np.linalg.norm(V[E[:, 0]] - V[E[:, 1]], axis=1).mean())


def sample_skeleton(
    C: ArrayLike,
    BE: ArrayLike | None = None,
    P: ArrayLike | None = None,
    *,
    spacing: float = 1.0,
    min_samples: int = 2,
) -> tuple[NDArray[np.float64], list[list[int]]]:
    """Points on the handles: each point handle, and each bone sampled every ``spacing``.

    Returns ``S (s, d)`` sample positions and ``handles``: a list (one per sample) of the
    columns it belongs to (point handles first, then bones), so joints shared by several bones
    list all of them. Coincident samples (e.g. a joint) are merged.
    """
    C = np.asarray(C, float)
    BE = np.zeros((0, 2), np.int64) if BE is None else np.asarray(BE, np.int64).reshape(-1, 2)
    P = np.zeros(0, np.int64) if P is None else np.asarray(P, np.int64).reshape(-1)
    pts, cols = [], []
    for k, p in enumerate(P):
        pts.append(C[p][None])
        cols.append(np.array([k]))
    for e, (i, j) in enumerate(BE):
        L = np.linalg.norm(C[j] - C[i])
        # ~2 samples per average edge length (spacing = rho / 2), endpoints included
        count = max(min_samples, int(np.ceil(L / spacing)) + 1)
        t = np.linspace(0.0, 1.0, count)
        seg = C[i] + t[:, None] * (C[j] - C[i])
        seg[0], seg[-1] = C[i], C[j]  # exact joints, so shared joints merge below
        pts.append(seg)
        cols.append(np.full(count, len(P) + e))
    if not pts:
        raise ValueError("no handles: give bones BE and/or point handles P")
    S = np.vstack(pts)
    col = np.concatenate(cols)
    # merge exactly coincident samples (shared joints, coincident joints)
    uniq, inv = np.unique(S, axis=0, return_inverse=True)
    inv = inv.reshape(-1)
    # group the columns by unique sample in one sort (a mask per sample is quadratic)
    order = np.argsort(inv, kind="stable")
    bounds = np.searchsorted(inv[order], np.arange(len(uniq) + 1))
    handles = [sorted(set(col[order[a:b]].tolist())) for a, b in itertools.pairwise(bounds)]
    return uniq, handles


def _bc_matrix(handles: list[list[int]], m: int) -> NDArray[np.float64]:
    bc = np.zeros((len(handles), m))
    for r, hs in enumerate(handles):
        bc[r, hs] = 1.0 / len(hs)  # a joint is shared equally by the bones meeting there
    return bc
