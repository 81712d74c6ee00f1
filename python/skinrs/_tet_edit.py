"""Local edits of a tet mesh: boundary faces, moving vertices onto points, inserting a vertex.

Used after fTetWild, whose meshes keep neither the input vertices nor the handle samples.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray


def _tet_volumes(V: NDArray[Any], T: NDArray[Any]) -> NDArray[Any]:
    X = V[T]
    a, b, c = X[:, 1] - X[:, 0], X[:, 2] - X[:, 0], X[:, 3] - X[:, 0]
    volumes: NDArray[Any] = np.einsum("ij,ij->i", a, np.cross(b, c)) / 6.0
    return volumes


# The faces of a positively oriented tet, each opposite one corner and oriented outward.
_TET_FACES = [[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]]


def _boundary_faces(T: NDArray[Any]) -> NDArray[Any]:
    faces = T[:, _TET_FACES].reshape(-1, 3)
    _, inv, cnt = np.unique(np.sort(faces, axis=1), axis=0, return_inverse=True, return_counts=True)
    boundary: NDArray[Any] = faces[cnt[inv.reshape(-1)] == 1]
    return boundary


def _snap(
    Vw: NDArray[Any], Tw: NDArray[Any], S: NDArray[Any], k: int = 32
) -> tuple[NDArray[Any], NDArray[Any], NDArray[Any], NDArray[Any]]:
    """Puts a vertex of ``(Vw, Tw)`` exactly on each sample.

    First, greedily by distance, a distinct interior vertex is moved onto each sample, nearest
    first. A move that would leave an incident tet inverted or nearly flat (volume below 1e-3 of
    the mean) is not made; the next nearest free vertex is tried. Boundary vertices stay put, so
    the surface does not change. A sample for which none of its ``k`` nearest vertices can move
    (its good neighbours went to nearby samples) is inserted as a new vertex instead
    (:func:`_insert_vertex`); fTetWild is randomised, so this happens on some runs only.

    Returns the vertices, the tets, the vertex of each sample and the distance moved (0 for an
    inserted vertex)."""
    from scipy.spatial import cKDTree

    Vv = np.array(Vw, dtype=np.float64, copy=True)
    nv = len(Vv)
    boundary = np.zeros(nv, bool)
    boundary[_boundary_faces(Tw).ravel()] = True
    # tets around each vertex (CSR)
    flat = Tw.ravel()
    order = np.argsort(flat, kind="stable")
    start = np.searchsorted(flat[order], np.arange(nv + 1))
    tets_of = order // 4
    vmin = 1e-3 * np.abs(_tet_volumes(Vv, Tw)).mean()
    k = min(k, nv)
    d, nn = cKDTree(Vv).query(S, k=k)
    d, nn = d.reshape(len(S), k), nn.reshape(len(S), k)
    taken = boundary.copy()
    idx, dist = np.full(len(S), -1, np.int64), np.zeros(len(S))
    for s in np.argsort(d[:, 0]):
        for c in range(k):
            v = nn[s, c]
            if taken[v]:
                continue
            inc = tets_of[start[v] : start[v + 1]]
            old = Vv[v].copy()
            Vv[v] = S[s]
            if _tet_volumes(Vv, Tw[inc]).min() > vmin:
                idx[s], dist[s] = v, np.linalg.norm(S[s] - old)
                taken[v] = True
                break
            Vv[v] = old
    T = Tw
    for s in np.flatnonzero(idx < 0):
        Vv, T, idx[s] = _insert_vertex(Vv, T, S[s], vmin)
    return Vv, T, idx, dist


def _insert_vertex(
    V: NDArray[Any], T: NDArray[Any], p: NDArray[Any], vmin: float, max_tets: int = 64
) -> tuple[NDArray[Any], NDArray[Any], int]:
    """Inserts the point ``p`` as a new vertex of the tet mesh ``(V, T)`` (positively oriented).

    The tets of a cavity around ``p`` are replaced by the fan from ``p`` to the cavity's
    boundary faces, so the mesh stays conforming and its boundary does not change. The cavity
    starts as the tet containing ``p``; while a fan tet would be flatter than ``vmin`` (``p``
    lies on or behind that face), the tet across the face joins the cavity.

    Returns the new vertices, the new tets and the index of the new vertex."""
    faces = T[:, _TET_FACES]  # (m, 4, 3)
    key = np.sort(faces, axis=2).reshape(-1, 3)
    _, face_id = np.unique(key, axis=0, return_inverse=True)
    face_id = face_id.reshape(-1, 4)
    tets_of_face: dict[int, list[int]] = {}
    for t, f in zip(np.repeat(np.arange(len(T)), 4), face_id.ravel(), strict=True):
        tets_of_face.setdefault(int(f), []).append(int(t))
    cavity = {_containing_tet(V, T, p)}
    q = len(V)
    Vn = np.vstack([V, p])
    while True:
        fid = face_id[list(cavity)].ravel()
        tri = faces[list(cavity)].reshape(-1, 3)
        _, first, cnt = np.unique(fid, return_index=True, return_counts=True)
        outer = tri[first[cnt == 1]]
        fan = np.c_[np.full(len(outer), q), outer]
        bad = _tet_volumes(Vn, fan) <= vmin
        if not bad.any():
            break
        grow = {t for f in fid[first[cnt == 1]][bad] for t in tets_of_face[int(f)]} - cavity
        if not grow or len(cavity) + len(grow) > max_tets:
            raise ValueError(
                f"could not insert the handle sample {p.tolist()} into the fallback mesh "
                "(it lies on or next to the surface); move the skeleton inside the surface or "
                "pass a smaller tetwild_options['edge_length_abs']"
            )
        cavity |= grow
    keep = np.ones(len(T), bool)
    keep[list(cavity)] = False
    return Vn, np.vstack([T[keep], fan]).astype(T.dtype), q


def _barycentric(V: NDArray[Any], T: NDArray[Any], p: NDArray[Any]) -> NDArray[Any]:
    """Barycentric coordinates ``(m, 4)`` of the point ``p`` in each tet of ``(V, T)``; rows of
    flat tets are ``-inf``."""
    X = V[T]
    A = np.transpose(X[:, 1:] - X[:, :1], (0, 2, 1))  # (m, 3, 3): columns are edges from corner 0
    ok = np.abs(np.linalg.det(A)) > 0
    lam = np.full((len(T), 4), -np.inf)
    lam[ok, 1:] = np.linalg.solve(A[ok], (p - X[ok, 0])[..., None])[..., 0]
    lam[ok, 0] = 1 - lam[ok, 1:].sum(axis=1)
    return lam


def _containing_tet(V: NDArray[Any], T: NDArray[Any], p: NDArray[Any]) -> int:
    """The tet of ``(V, T)`` whose smallest barycentric coordinate of ``p`` is largest."""
    lam = _barycentric(V, T, p)
    t = int(np.argmax(lam.min(axis=1)))
    if lam[t].min() < -1e-9:
        raise ValueError(f"the handle sample {p.tolist()} lies outside the fallback mesh")
    return t
