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


def _bone_segments(S: Arr, handles: Handles, vertex_of: Arr, nP: int, nB: int) -> Arr:
    """Segments between consecutive samples of each bone (for Triangle), as pairs of vertices:
    ``vertex_of[r]`` is the mesher's vertex of sample ``r`` (an input vertex it sits on, or its
    inserted copy)."""
    segs = []
    for e in range(nB):
        rows = [r for r, hs in enumerate(handles) if nP + e in hs]
        if len(rows) < 2:
            continue
        pts = S[rows]
        d = pts - pts[0]
        far = pts[np.argmax(np.linalg.norm(d, axis=1))] - pts[0]
        order = np.argsort(d @ far)
        ids = [int(vertex_of[rows[o]]) for o in order]
        segs += [(a, b) for a, b in itertools.pairwise(ids) if a != b]
    return np.array(segs, np.int64).reshape(-1, 2)


def _points_on_bones(Q: Arr, C: Arr, BE: Arr | None, nP: int, tol: float) -> tuple[Arr, Handles]:
    """The points of ``Q`` within ``tol`` of a bone's inside (its end joints excluded), in
    increasing order, and per point the columns of the bones it lies on (``nP + bone``)."""
    bones: dict[int, list[int]] = {}
    for e, (i, j) in enumerate(np.zeros((0, 2), np.int64) if BE is None else BE):
        a, u = C[i], C[j] - C[i]
        t = (Q - a) @ u / max(float(u @ u), 1e-300)
        dist = np.linalg.norm(Q - (a + np.clip(t, 0, 1)[:, None] * u), axis=1)
        for k in np.flatnonzero((dist <= tol) & (t > 0) & (t < 1)).tolist():
            bones.setdefault(k, []).append(nP + e)
    rows = sorted(bones)
    return np.array(rows, np.int64), [bones[k] for k in rows]


def _snap_to_vertices(
    V: Arr, S: Arr, handles: Handles, C: Arr, BE: Arr | None, nP: int, tol: float
) -> tuple[Arr, Handles, Arr]:
    """The samples that sit on input vertices, and the input vertices that sit on bones.

    A sample within ``tol`` of an input vertex is that vertex; an input vertex within ``tol`` of
    a bone's inside becomes a sample of that bone. Left apart, either pair makes a sliver
    whose cotangent is about ``spacing / tol`` (1e7 for a vertex 1e-7 from a bone): the
    biharmonic matrix then holds entries 1e14 times its energy, and the solve slows down by
    orders of magnitude.

    Returns the samples (extended by the vertices on bones), their handles, and per sample the
    input vertex it is (-1 for a sample to insert). Samples on one vertex share it (their
    handle lists are merged).
    """
    from scipy.spatial import cKDTree

    on_bone, bones = _points_on_bones(V, C, BE, nP, tol)
    if len(on_bone):
        S = np.vstack([S, V[on_bone]])
        handles = handles + bones
    d, nearest = cKDTree(V).query(S)
    vertex = np.where(d <= tol, nearest, -1)
    on_vertex: dict[int, list[int]] = {}
    for q in np.flatnonzero(vertex >= 0).tolist():
        on_vertex.setdefault(int(vertex[q]), []).extend(handles[q])
    S_out, h_out, v_out = [], [], []
    for r, k in enumerate(vertex.tolist()):
        if k < 0:
            S_out.append(S[r])
            h_out.append(handles[r])
        elif k in on_vertex:  # the first sample on vertex k stands for all of them
            S_out.append(V[k])
            h_out.append(sorted(set(on_vertex.pop(k))))
        else:
            continue
        v_out.append(k)
    return np.array(S_out, np.float64).reshape(-1, S.shape[1]), h_out, np.array(v_out, np.int64)


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
