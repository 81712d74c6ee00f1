"""Geometric helpers of :mod:`skinrs.meshing`: winding numbers, outlines, bone segments,
interpolation of weights onto other points.
"""

from __future__ import annotations

import itertools
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ._tet_edit import _barycentric
from .field import winding_number as _fast_winding_number

Arr = NDArray[Any]
#: Per sample, the handle columns it belongs to.
Handles = list[list[int]]


def _winding_number(V: Arr, F: Arr, Q: Arr) -> Arr:
    """Exact generalised winding numbers (the hierarchical sum with no far-field expansion)."""
    return _fast_winding_number(V, F, Q, beta=np.inf)


def _as_2d(V: Arr, F: Arr | None) -> tuple[Arr, Arr]:
    """2D input: ``V (n, 2)`` (or ``(n, 3)`` with z = 0) with triangles, edges or nothing."""
    V2 = V[:, :2]
    if F is None:
        n = len(V2)
        return V2, np.c_[np.arange(n), (np.arange(n) + 1) % n]
    if F.shape[1] == 2:
        return V2, F
    # boundary edges of a triangle mesh, oriented like its triangles
    E = np.vstack([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    key = np.sort(E, axis=1)
    _, inv, cnt = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    return V2, E[cnt[inv.reshape(-1)] == 1]


def _rows_match(Vv: Arr, V: Arr, S: Arr) -> bool:
    n, s = len(V), len(S)
    return len(Vv) >= n + s and np.array_equal(Vv[:n], V) and np.array_equal(Vv[n : n + s], S)


def _bone_segments(S: Arr, handles: Handles, insert: Arr, nP: int, nB: int) -> Arr:
    """Segments between consecutive inserted samples of each bone (for Triangle)."""
    pos = {int(r): k for k, r in enumerate(insert)}
    segs = []
    for e in range(nB):
        rows = [r for r, hs in enumerate(handles) if nP + e in hs and r in pos]
        if len(rows) < 2:
            continue
        pts = S[rows]
        d = pts - pts[0]
        far = pts[np.argmax(np.linalg.norm(d, axis=1))] - pts[0]
        order = np.argsort(d @ far)
        ids = [pos[rows[o]] for o in order]
        segs += list(itertools.pairwise(ids))
    return np.array(segs, np.int64).reshape(-1, 2)


def _interpolate(Q: Arr, Vv: Arr, T: Arr, W: Arr) -> Arr:
    """Weights at points ``Q`` by barycentric interpolation in the best tet around the nearest
    vertex (for the fallback mesh, whose surface only approximates the input)."""
    from scipy.spatial import cKDTree

    _, near = cKDTree(Vv).query(Q)
    inc: list[list[int]] = [[] for _ in range(len(Vv))]
    for t, row in enumerate(T):
        for v in row:
            inc[v].append(t)
    out = np.empty((len(Q), W.shape[1]))
    for i, (q, v) in enumerate(zip(Q, near, strict=True)):
        around = T[inc[v]]
        lam = _barycentric(Vv, around, q)
        best = int(np.argmax(lam.min(axis=1)))
        lam = np.clip(lam[best], 0, None)
        lam /= lam.sum()
        out[i] = lam @ W[around[best]]
    return out
