"""From a surface and a skeleton to a volume mesh with the handles as vertices, and weights.

Paper 000, Sec. 7: sample each bone (about two samples per average edge length of the input,
at least two per bone, endpoints included) and mesh the interior so that the point handles and
bone samples are vertices that can be constrained -- TetGen in 3D, Triangle in 2D.

TetGen (AGPL) and Triangle (non-commercial licence) are *not* part of skinrs's compiled core:
they are called through the optional Python packages ``tetgen``, ``triangle`` and, as a fallback
for surfaces TetGen rejects, ``pytetwild``: ``pip install skinrs[mesh]``.
"""

from __future__ import annotations

import contextlib
import itertools
import os
import sys
import warnings

import numpy as np

from ._checks import as_index_array, as_points

__all__ = [
    "MeshingWarning",
    "mesh_with_skeleton",
    "sample_skeleton",
    "skin_weights",
    "winding_number",
]

_INSTALL = "install the optional meshing packages with `pip install skinrs[mesh]`"


class MeshingWarning(UserWarning):
    """Something in the meshing needed a compromise (bone partly outside, snapped samples)."""


# ---------------------------------------------------------------------------------------------
# Generalised winding numbers (Jacobson et al. 2013), exact, in numpy


def winding_number(V, F, Q, chunk: int = 256) -> np.ndarray:
    """Winding number of closed (or nearly closed) boundary ``(V, F)`` at the points ``Q``.

    3D: ``F (k, 3)`` triangles, sum of signed solid angles / 4 pi (Van Oosterom & Strackee).
    2D: ``F (k, 2)`` oriented edges, sum of signed angles / 2 pi. About 1 inside a
    counter-clockwise (2D) or outward-oriented (3D) boundary, 0 outside.
    """
    V, Q = np.asarray(V, float), np.asarray(Q, float)
    out = np.empty(len(Q))
    for s in range(0, len(Q), chunk):
        q = Q[s : s + chunk, None, :]
        if F.shape[1] == 2:
            a, b = V[F[:, 0]][None] - q, V[F[:, 1]][None] - q
            cr = a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]
            out[s : s + chunk] = np.arctan2(cr, (a * b).sum(-1)).sum(1) / (2 * np.pi)
        else:
            a, b, c = (V[F[:, i]][None] - q for i in range(3))
            la, lb, lc = (np.linalg.norm(x, axis=-1) for x in (a, b, c))
            det = np.einsum("qki,qki->qk", a, np.cross(b, c))
            den = la * lb * lc + (a * b).sum(-1) * lc + (b * c).sum(-1) * la + (c * a).sum(-1) * lb
            out[s : s + chunk] = 2 * np.arctan2(det, den).sum(1) / (4 * np.pi)
    return out


# ---------------------------------------------------------------------------------------------
# Sampling


def _mean_edge_length(V, F) -> float:
    E = (
        np.vstack([F[:, [i, (i + 1) % F.shape[1]]] for i in range(F.shape[1])])
        if F.shape[1] > 2
        else F
    )
    E = np.unique(np.sort(E, axis=1), axis=0)
    return float(np.linalg.norm(V[E[:, 0]] - V[E[:, 1]], axis=1).mean())


def sample_skeleton(C, BE=None, P=None, spacing: float = 1.0, min_samples: int = 2):
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
    handles = [sorted(set(col[inv == u].tolist())) for u in range(len(uniq))]
    return uniq, handles


def _bc_matrix(handles, m: int) -> np.ndarray:
    bc = np.zeros((len(handles), m))
    for r, hs in enumerate(handles):
        bc[r, hs] = 1.0 / len(hs)  # a joint is shared equally by the bones meeting there
    return bc


def _keep_inside(S, handles, inside, n_points: int, n_bones: int):
    """Drops outside samples; warns for a partly outside bone, raises for a wholly outside one."""
    for k in range(n_points):
        rows = [r for r, hs in enumerate(handles) if k in hs]
        if not inside[rows].any():
            raise ValueError(f"point handle {k} lies outside the surface")
    for e in range(n_bones):
        c = n_points + e
        rows = np.array([r for r, hs in enumerate(handles) if c in hs])
        frac_out = 1.0 - inside[rows].mean()
        if frac_out == 1.0:
            raise ValueError(
                f"bone {e} lies wholly outside the surface: none of its "
                f"{len(rows)} samples is inside; fix the skeleton or the mesh"
            )
        if frac_out > 0:
            warnings.warn(
                f"bone {e} is partly outside the surface ({100 * frac_out:.0f}% of its "
                f"samples); its inside samples are kept",
                MeshingWarning,
                stacklevel=3,
            )
    keep = np.flatnonzero(inside)
    return S[keep], [handles[r] for r in keep]


# ---------------------------------------------------------------------------------------------
# Meshers


@contextlib.contextmanager
def _quiet_fd1(quiet: bool):
    """Silences C-level prints to stdout (the tetgen wrapper prints even with "Q")."""
    if not quiet:
        yield
        return
    sys.stdout.flush()
    try:
        saved = os.dup(1)
    except OSError:  # no real stdout
        yield
        return
    try:
        with open(os.devnull, "w") as null:
            os.dup2(null.fileno(), 1)
            yield
    finally:
        os.dup2(saved, 1)
        os.close(saved)


# Files TetGen (on a self-intersecting surface) and fTetWild write into the working directory.
_LITTER = ("tetgen-tmpfile_skipped.face", "tetgen-tmpfile_skipped.node", "__tracked_surface.stl")


@contextlib.contextmanager
def _no_litter():
    """Removes the scratch files the meshers leave in the working directory (only those the
    call created: a file of that name that was there before is left alone)."""
    before = {f for f in _LITTER if os.path.exists(f)}
    try:
        yield
    finally:
        for f in set(_LITTER) - before:
            with contextlib.suppress(OSError):
                os.remove(f)


def _import_tetgen():
    try:
        import tetgen
    except ImportError:
        raise ImportError(f"mesh_with_skeleton needs TetGen in 3D: {_INSTALL}") from None
    return tetgen


def _tetgen(V, F, S, flags: str, verbose: bool):
    tetgen = _import_tetgen()
    if not verbose and "Q" not in flags:
        flags += "Q"
    pts = np.vstack([V, S])
    with _quiet_fd1(not verbose), _no_litter():
        tg = tetgen.TetGen(pts, F.astype(np.int32))
        VV, TT = tg.tetrahedralize(switches=flags)[:2]
    # copies: the arrays may view memory owned by `tg`, freed when it goes away
    return np.array(VV, dtype=np.float64, copy=True), np.array(TT, dtype=np.int64, copy=True)


def _self_intersects(V, F) -> bool:
    """Whether TetGen finds intersecting faces in the surface alone (switch ``d``).

    Checked before the real TetGen run because TetGen, given a self-intersecting surface *and*
    extra points to insert, can corrupt its heap and abort the whole Python process (seen with
    two overlapping tubes) instead of raising; on the bare surface the check raises cleanly."""
    tetgen = _import_tetgen()

    with _quiet_fd1(True), _no_litter():
        try:
            tetgen.TetGen(V, F.astype(np.int32)).tetrahedralize(switches="dQ")
        except RuntimeError as e:  # "The input surface mesh contain self-intersections."
            return "self-intersect" in str(e)
    return False


def _tetwild(V, F, S, verbose: bool, **options):
    """Fallback mesher: fTetWild (robust to self-intersections and holes). Does not keep the
    input vertices or insert points, so the caller meshes its boundary again or snaps vertices
    onto the samples. ``options`` go to ``pytetwild.tetrahedralize``. Tets come back positively
    oriented (fTetWild's own order is the opposite one)."""
    import pytetwild  # ImportError when missing (also raised when its pyvista dependency is)

    with _no_litter():
        VV, TT = pytetwild.tetrahedralize(
            np.asarray(V, float), np.asarray(F, np.int32), quiet=not verbose, **options
        )
    VV, TT = np.array(VV, dtype=np.float64), np.array(TT, dtype=np.int64)
    flip = _tet_volumes(VV, TT) < 0
    TT[flip] = TT[flip][:, [0, 1, 3, 2]]
    return VV, TT


def _tet_volumes(V, T):
    X = V[T]
    a, b, c = X[:, 1] - X[:, 0], X[:, 2] - X[:, 0], X[:, 3] - X[:, 0]
    return np.einsum("ij,ij->i", a, np.cross(b, c)) / 6.0


def _triangle(V, E, S, seg_S, flags: str, verbose: bool):
    try:
        import triangle
    except ImportError:
        raise ImportError(f"mesh_with_skeleton needs Triangle in 2D: {_INSTALL}") from None
    if not verbose and "Q" not in flags:
        flags += "Q"
    pts = np.vstack([V, S])
    segs = np.vstack([E, seg_S + len(V)]) if len(seg_S) else E
    out = triangle.triangulate({"vertices": pts, "segments": segs.astype(np.int32)}, flags)
    return np.asarray(out["vertices"], float), np.asarray(out["triangles"], np.int64)


def _as_2d(V, F):
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


def mesh_with_skeleton(
    V,
    F,
    C,
    BE=None,
    P=None,
    *,
    samples_per_edge: float = 2.0,
    min_samples: int = 2,
    flags: str | None = None,
    tetwild_options: dict | None = None,
    verbose: bool = False,
):
    """Volume mesh of a closed surface (3D) or a 2D domain whose vertices include the handles.

    Bones are sampled about ``samples_per_edge`` times per average edge length of the input
    (at least ``min_samples`` per bone, endpoints included); the samples and point handles
    ``C[P]`` are inserted as interior vertices: TetGen in 3D (flags ``"pq2Y"``: quality, surface
    kept), Triangle in 2D (bones as segments; flags ``"pq30Y"`` for an outline, ``"pY"`` for a
    given triangle mesh, whose vertices are all kept and which is not refined). The input vertices keep their
    indices: ``V_vol[:len(V)] == V``. If TetGen rejects the surface (self-intersections,
    holes) and ``pytetwild`` is installed, fTetWild meshes it instead (target edge length: the
    input's mean edge length), then TetGen meshes fTetWild's repaired boundary with the samples
    inserted exactly; if that fails too, the nearest interior fTetWild vertices are moved onto
    the samples (a move that would invert a tet is not made; the next nearest vertex is tried),
    and a sample none of whose nearby vertices can move is inserted as a new vertex. Either way
    a :class:`MeshingWarning` says so (the snapping one reports the largest move), and the
    surface rows no longer match ``V`` (:func:`skin_weights` then interpolates).

    Parameters
    ----------
    V : (n, 3) float array, or (n, 2) (or (n, 3) with z = 0) for 2D
        Surface vertices (3D) or 2D domain vertices.
    F : (f, 3) int array, or in 2D (f, 3) triangles, (f, 2) outline edges or None
        Closed surface triangles (3D); in 2D a triangle mesh (its boundary is used), the edges of
        the outline, or ``None`` when ``V`` is one closed polygon in order.
    C : (h, d) float array
        Joint / handle positions.
    BE : (k, 2) int array, optional
        Bones (directed edges into ``C``).
    P : (p,) int array, optional
        Point handles (indices into ``C``).
    samples_per_edge, min_samples : bone sampling density, see above.
    flags : str, optional
        TetGen / Triangle switches (``Q``, quiet, is added unless ``verbose``).
    tetwild_options : dict, optional
        Keyword arguments of ``pytetwild.tetrahedralize`` for the fallback (e.g.
        ``edge_length_abs``, ``stop_energy``; larger ``stop_energy`` is faster, lower quality).

    Returns
    -------
    V_vol : (N, d) float array
        Volume vertices; the first ``n`` rows are ``V`` (unless the fallback ran).
    T : (t, 4) or (t, 3) int array
        Tetrahedra (3D) or triangles (2D).
    b : (q,) int array
        The vertices holding a handle sample.
    bc : (q, p + k) float array
        Their weights: one-hot per handle, point handles first, then bones; a joint shared by
        several bones has ``1 / (number of bones)`` in each.

    Raises
    ------
    ValueError
        A bone or point handle wholly outside the surface, bad shapes or indices.
    ImportError
        The meshing package is missing (``pip install skinrs[mesh]``), or TetGen failed and
        ``pytetwild`` is not installed.

    Warns
    -----
    MeshingWarning
        A bone partly outside (its outside samples are dropped), or snapped samples.

    Examples
    --------
    >>> import numpy as np, skinrs
    >>> V = np.array([[0.0, 0], [4, 0], [4, 1], [0, 1]])                 # a 4 x 1 rectangle
    >>> C = np.array([[0.5, 0.5], [2, 0.5], [3.5, 0.5]])
    >>> Vv, T, b, bc = skinrs.mesh_with_skeleton(V, None, C, [[0, 1], [1, 2]])
    >>> bool(np.array_equal(Vv[:4], V)), bc.shape[1]
    (True, 2)
    """
    V = as_points(V, "V", dims=(2, 3))
    n = len(V)
    # 2D: 2 columns, or 3 with z = 0 (2D OBJ files); a closed 3D surface is never flat
    planar = V.shape[1] == 2 or not np.any(V[:, 2])
    if F is None and not planar:
        raise ValueError("a 3D surface needs its triangles F")
    if F is not None:
        F = as_index_array(F, n, "F", cols=(2, 3) if planar else 3, allow_empty=False)
    dim = 2 if planar else 3
    C = as_points(C, "C", dims=(2, 3))
    if C.shape[1] != dim:
        if C.shape[1] == 3 and dim == 2 and not np.any(C[:, 2]):
            C = np.ascontiguousarray(C[:, :2])
        else:
            raise ValueError(f"C must have {dim} columns like the domain, got {C.shape}")
    BE = None if BE is None else as_index_array(BE, len(C), "BE", cols=2)
    P = None if P is None else as_index_array(P, len(C), "P", ndim=1)
    nP = 0 if P is None else len(P)
    nB = 0 if BE is None else len(BE)
    if nP + nB == 0:
        raise ValueError("no handles: give bones BE and/or point handles P")
    if BE is not None and np.any(BE[:, 0] == BE[:, 1]):
        raise ValueError(f"bone {int(np.flatnonzero(BE[:, 0] == BE[:, 1])[0])} has zero length")

    if planar:
        Vd, E = _as_2d(V, F)
        rho = _mean_edge_length(Vd, F if F is not None and F.shape[1] == 3 else E)
        boundary = E
    else:
        Vd, E = V, None
        rho = _mean_edge_length(V, F)
        boundary = F
    S, handles = sample_skeleton(C, BE, P, spacing=rho / samples_per_edge, min_samples=min_samples)
    w = winding_number(Vd, boundary, S)
    inside = np.abs(w) > 0.5
    S, handles = _keep_inside(S, handles, inside, nP, nB)

    # a sample sitting on an input vertex is that vertex (inserting it again would be dropped
    # by the mesher as a duplicate and shift every index after it)
    scale = float(np.linalg.norm(Vd.max(0) - Vd.min(0)))
    from scipy.spatial import cKDTree

    d, nearest = cKDTree(Vd).query(S)
    on_vertex = d <= 1e-12 * scale
    insert = np.flatnonzero(~on_vertex)
    Si = S[insert]

    if planar:
        seg = _bone_segments(S, handles, insert, nP, nB)
        # An outline is refined to quality triangles; a given triangle mesh keeps its resolution
        # (refining around its interior vertices next to bone segments cascades to slivers).
        default = "pq30Y" if F is None or F.shape[1] == 2 else "pY"
        Vv, T = _triangle(Vd, E, Si, seg, flags or default, verbose)
        exact = _rows_match(Vv, Vd, Si)
        if not exact:
            raise RuntimeError("Triangle did not keep the input vertices and samples in order")
        # Triangle keeps triangles inside the outer segments only: drop those in holes
        cent = Vv[T].mean(axis=1)
        T = T[np.abs(winding_number(Vd, E, cent)) > 0.5]
    else:
        Vv = T = None
        err = None
        try:
            if _self_intersects(V, F):
                raise RuntimeError("the input surface has self-intersections")
            Vv, T = _tetgen(V, F, Si, flags or "pq2Y", verbose)
            exact = _rows_match(Vv, V, Si)
        except ImportError:
            raise
        except Exception as e:  # noqa: BLE001 - TetGen raises RuntimeError and others
            err, exact = e, False
        if not exact:
            user = dict(tetwild_options or {})
            opts = {"edge_length_abs": rho, **user}
            # for snapping, vertices must be at least as dense as the samples
            fine = {**opts, "edge_length_abs": user.get("edge_length_abs", rho / samples_per_edge)}

            def finer():
                return _tetwild(V, F, Si, verbose, **fine)

            try:
                Vw, Tw = _tetwild(V, F, Si, verbose, **opts)
            except ImportError as e:
                why = f"TetGen failed ({err})" if err else "TetGen did not keep the input vertices"
                raise ImportError(
                    f"{why}; the fallback mesher pytetwild is not available ({e}): "
                    f"{_INSTALL} (or repair the surface)"
                ) from None
            return _fallback(Vw, Tw, S, handles, nP + nB, scale, flags or "pq2Y", verbose, finer)

    b = np.where(on_vertex, nearest, 0)
    b[insert] = n + np.arange(len(insert))
    bc = _bc_matrix(handles, nP + nB)
    if V.shape[1] == 3 and Vv.shape[1] == 2:
        Vv = np.c_[Vv, np.zeros(len(Vv))]
    order = np.argsort(b, kind="stable")
    return Vv, T, b[order].astype(np.int64), bc[order]


def _rows_match(Vv, V, S) -> bool:
    n, s = len(V), len(S)
    return len(Vv) >= n + s and np.array_equal(Vv[:n], V) and np.array_equal(Vv[n : n + s], S)


def _bone_segments(S, handles, insert, nP, nB):
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


# The faces of a positively oriented tet, each opposite one corner and oriented outward.
_TET_FACES = [[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]]


def _boundary_faces(T):
    faces = T[:, _TET_FACES].reshape(-1, 3)
    _, inv, cnt = np.unique(np.sort(faces, axis=1), axis=0, return_inverse=True, return_counts=True)
    return faces[cnt[inv.reshape(-1)] == 1]


def _fallback(Vw, Tw, S, handles, m, scale, flags, verbose, finer):
    """After fTetWild: mesh its clean boundary again with TetGen and the samples inserted; if
    that fails too, mesh again with fTetWild at the sample spacing (``finer()``) and move the
    nearest interior vertices onto the samples."""
    Fb = _boundary_faces(Tw)
    used, Fs = np.unique(Fb, return_inverse=True)
    Vs, Fs = Vw[used], Fs.reshape(-1, 3)
    bc = _bc_matrix(handles, m)
    try:
        Vv, T = _tetgen(Vs, Fs, S, flags, verbose)
        exact = _rows_match(Vv, Vs, S)
    except Exception:  # noqa: BLE001 - any TetGen failure sends us to snapping
        exact = False
    if exact:
        warnings.warn(
            "TetGen could not mesh the input surface; meshed fTetWild's repaired "
            "surface instead (samples inserted exactly). The input surface vertices are "
            "not rows of V_vol.",
            MeshingWarning,
            stacklevel=3,
        )
        return Vv, T, len(Vs) + np.arange(len(S), dtype=np.int64), bc
    Vw, Tw = finer()
    Vv, Tw, idx, d = _snap(Vw, Tw, S)
    added = int((idx >= len(Vw)).sum())
    warnings.warn(
        f"TetGen could not mesh the surface; used fTetWild and moved {len(idx) - added} volume "
        f"vertices onto the handle samples (snapping distance: largest {d.max():.3g}, mean "
        f"{d.mean():.3g}; largest = {d.max() / scale:.2%} of the bounding-box diagonal)"
        + (f" and inserted {added} more as new vertices" if added else "")
        + ". The input surface vertices are not rows of V_vol.",
        MeshingWarning,
        stacklevel=3,
    )
    order = np.argsort(idx)
    return Vv, Tw, idx[order].astype(np.int64), bc[order]


def _snap(Vw, Tw, S, k: int = 32):
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


def _insert_vertex(V, T, p, vmin: float, max_tets: int = 64):
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
    tets_of_face = {}
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


def _barycentric(V, T, p):
    """Barycentric coordinates ``(m, 4)`` of the point ``p`` in each tet of ``(V, T)``; rows of
    flat tets are ``-inf``."""
    X = V[T]
    A = np.transpose(X[:, 1:] - X[:, :1], (0, 2, 1))  # (m, 3, 3): columns are edges from corner 0
    ok = np.abs(np.linalg.det(A)) > 0
    lam = np.full((len(T), 4), -np.inf)
    lam[ok, 1:] = np.linalg.solve(A[ok], (p - X[ok, 0])[..., None])[..., 0]
    lam[ok, 0] = 1 - lam[ok, 1:].sum(axis=1)
    return lam


def _containing_tet(V, T, p) -> int:
    """The tet of ``(V, T)`` whose smallest barycentric coordinate of ``p`` is largest."""
    lam = _barycentric(V, T, p)
    t = int(np.argmax(lam.min(axis=1)))
    if lam[t].min() < -1e-9:
        raise ValueError(f"the handle sample {p.tolist()} lies outside the fallback mesh")
    return t


# ---------------------------------------------------------------------------------------------


def skin_weights(V, F, C, BE=None, P=None, *, mesh_options=None, return_mesh=False, **bbw_options):
    """Bounded biharmonic weights on the vertices of a surface (3D) or 2D domain.

    Meshes the interior with the handles as vertices (:func:`mesh_with_skeleton`), solves
    :func:`skinrs.bbw_dual_constrained` there and returns the rows of the input vertices.

    Parameters
    ----------
    V, F, C, BE, P
        As in :func:`mesh_with_skeleton`.
    mesh_options : dict, optional
        Extra keyword arguments of :func:`mesh_with_skeleton`.
    return_mesh : bool
        Also return a dict with the volume mesh and its weights: ``V``, ``T``, ``b``, ``bc``,
        ``W`` (all volume vertices).
    **bbw_options
        Passed to :func:`skinrs.bbw_dual_constrained` (``tol``, ``max_iter``, ...).

    Returns
    -------
    W : (n, p + k) float array
        Weights of the input vertices: point handles first, then bones; ``W >= 0``, rows sum to
        1, and 1 in a bone's column on that bone.

    Examples
    --------
    >>> import numpy as np, skinrs
    >>> V = np.array([[0.0, 0], [4, 0], [4, 1], [0, 1]])
    >>> C = np.array([[0.5, 0.5], [2, 0.5], [3.5, 0.5]])
    >>> W = skinrs.skin_weights(V, None, C, [[0, 1], [1, 2]])
    >>> W.shape, bool(np.allclose(W.sum(1), 1))
    ((4, 2), True)
    """
    from .bbw import bbw_dual_constrained

    n = len(np.asarray(V))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        Vv, T, b, bc = mesh_with_skeleton(V, F, C, BE, P, **(mesh_options or {}))
    snapped = False
    for w in caught:
        snapped |= issubclass(w.category, MeshingWarning) and "fTetWild" in str(w.message)
        warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    W = bbw_dual_constrained(Vv, T, b, bc, **bbw_options)
    if isinstance(W, tuple):  # return_info=True
        W = W[0]
    if not snapped:
        Ws = np.ascontiguousarray(W[:n])
    else:
        Ws = _interpolate(np.asarray(V, float), Vv, T, W)
    if return_mesh:
        return Ws, {"V": Vv, "T": T, "b": b, "bc": bc, "W": W}
    return Ws


def _interpolate(Q, Vv, T, W):
    """Weights at points ``Q`` by barycentric interpolation in the best tet around the nearest
    vertex (for the fallback mesh, whose surface only approximates the input)."""
    from scipy.spatial import cKDTree

    _, near = cKDTree(Vv).query(Q)
    inc = [[] for _ in range(len(Vv))]
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
