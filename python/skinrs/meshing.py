"""From a surface and a skeleton to a volume mesh with the handles as vertices, and weights.

Paper 000, Sec. 7: sample each bone (about two samples per average edge length of the input,
at least two per bone, endpoints included) and mesh the interior so that the point handles and
bone samples are vertices that can be constrained -- TetGen in 3D, Triangle in 2D.

TetGen (AGPL) and Triangle (non-commercial licence) are *not* part of skinrs's compiled core:
they are called through the optional Python packages ``tetgen``, ``triangle`` and, as a fallback
for surfaces TetGen rejects, ``pytetwild``: ``pip install skinrs[mesh]``.
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from . import _checks, _skinrs
from ._checks import Callback, as_points
from ._external_meshers import (
    _INSTALL,
    _self_intersects,  # noqa: F401 - tests reach it here
    _tetgen,
    _tetwild,
    _triangle,
)
from ._meshing_checks import (  # noqa: F401
    _MAX_SAMPLES,
    _MESHER_SWITCHES,
    _SWITCH_SYNTAX,
    _check_sample_count,
    _checked_domain,
    _checked_flags,
    _first_duplicate_row,
)
from ._meshing_geometry import (
    Arr,
    Handles,
    _as_2d,
    _bone_segments,
    _interpolate,
    _points_on_bones,
    _rows_match,
    _snap_to_vertices,
    _winding_number,
)
from ._skeleton_sampling import _bc_matrix, _mean_edge_length, sample_skeleton
from ._tet_edit import (  # noqa: F401 - tests reach the last two as meshing._*
    _barycentric,
    _boundary_faces,
    _insert_vertex,
    _snap,
    _tet_volumes,
)

__all__ = [
    "MeshingWarning",
    "mesh_with_skeleton",
    "sample_skeleton",
    "skin_weights",
]


_BBW_DEFAULTS: dict[str, Any] = _skinrs.BBW_DEFAULTS
#: A sample this close to an input vertex (relative to the sample spacing) is that vertex, and an
#: input vertex this close to a bone is one of its samples.
_SNAP = 1e-3


class MeshingWarning(UserWarning):
    """Something in the meshing needed a compromise (bone partly outside, snapped samples)."""


def _keep_inside(
    S: Arr, handles: Handles, inside: Arr, n_points: int, n_bones: int
) -> tuple[Arr, Handles]:
    """Drops outside samples; warns for a partly outside bone, raises for a wholly outside one."""
    for k in range(n_points):
        rows = [r for r, hs in enumerate(handles) if k in hs]
        if not inside[rows].any():
            raise ValueError(f"point handle {k} lies outside the surface")
    for e in range(n_bones):
        c = n_points + e
        bone_rows = np.array([r for r, hs in enumerate(handles) if c in hs])
        frac_out = 1.0 - inside[bone_rows].mean()
        if frac_out == 1.0:
            raise ValueError(
                f"bone {e} lies wholly outside the surface: none of its "
                f"{len(bone_rows)} samples is inside; fix the skeleton or the mesh"
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


def mesh_with_skeleton(
    V: ArrayLike,
    F: ArrayLike | None,
    C: ArrayLike,
    BE: ArrayLike | None = None,
    P: ArrayLike | None = None,
    *,
    samples_per_edge: float = 2.0,
    min_samples: int = 2,
    flags: str | None = None,
    tetwild_options: dict[str, Any] | None = None,
    verbose: bool = False,
) -> tuple[NDArray[np.float64], NDArray[np.int64], NDArray[np.int64], NDArray[np.float64]]:
    """Volume mesh of a closed surface (3D) or a 2D domain whose vertices include the handles.

    Bones are sampled about ``samples_per_edge`` times per average edge length of the input
    (at least ``min_samples`` per bone, endpoints included); the samples and point handles
    ``C[P]`` are inserted as interior vertices: TetGen in 3D (flags ``"pq2Y"``: quality, surface
    kept), Triangle in 2D (bones as segments; flags ``"pq30Y"`` for an outline, ``"pY"`` for a
    given triangle mesh, whose vertices are all kept and which is not refined). A sample within
    1e-3 of the sample spacing of an input vertex is that vertex, and an input vertex that close
    to a bone is one of its samples (a mesh drawn around its skeleton has vertices on the bones;
    kept apart, each such pair would be a sliver). A vertex Triangle adds on a bone segment (it
    splits segments to meet its quality and area bounds) is held like the bone's samples. The
    input vertices keep their indices: ``V_vol[:len(V)] == V``. If TetGen rejects the surface
    (self-intersections, holes) and ``pytetwild`` is installed, fTetWild meshes it instead
    (target edge length: the input's mean edge length), then TetGen meshes fTetWild's repaired
    boundary with the samples inserted exactly; if that fails too, the nearest interior
    fTetWild vertices are moved onto the samples (a move that would invert a tet is not made;
    the next nearest vertex is tried), and a sample none of whose nearby vertices can move is
    inserted as a new vertex. Either way a :class:`MeshingWarning` says so (the snapping one
    reports the largest move), and the surface rows no longer match ``V`` (:func:`skin_weights`
    then interpolates).

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
        A bone or point handle wholly outside the surface; handles spanning less than 1e-4 of
        the shape (C and V in different units); two points closer than 1e-12 of the extent
        (double precision cannot keep them apart); a 2D domain Triangle fails on; bad shapes
        or indices. (Triangle, TetGen and fTetWild run in a child process: a crash of theirs
        is this error, or in 3D the fallback.)
    ImportError
        The meshing package is missing (``pip install skinrs[mesh]``), or TetGen failed and
        ``pytetwild`` is not installed.

    Warns
    -----
    MeshingWarning
        A bone partly outside (its outside samples are dropped), snapped samples, or Triangle
        stopped refining at its bound on added vertices (switch ``S``; by default 200 per input
        point, at least 50,000).

    Examples
    --------
    >>> import numpy as np, skinrs
    >>> V = np.array([[0.0, 0], [4, 0], [4, 1], [0, 1]])                 # a 4 x 1 rectangle
    >>> C = np.array([[0.5, 0.5], [2, 0.5], [3.5, 0.5]])
    >>> Vv, T, b, bc = skinrs.mesh_with_skeleton(V, None, C, [[0, 1], [1, 2]])
    >>> bool(np.array_equal(Vv[:4], V)), bc.shape[1]
    (True, 2)
    """
    V, F, C, BE, P, planar = _checked_domain(V, F, C, BE, P)
    samples_per_edge = _checks.positive_float(samples_per_edge, "samples_per_edge")
    min_samples = _checks.integer(min_samples, "min_samples", 2, _MAX_SAMPLES)
    flags = _checked_flags(flags, planar)
    nP = 0 if P is None else len(P)
    nB = 0 if BE is None else len(BE)
    if planar:
        Vd, boundary = _as_2d(V, F)  # the outline's edges
        rho = _mean_edge_length(Vd, F if F is not None and F.shape[1] == 3 else boundary)
    else:
        assert F is not None  # _checked_domain asks a 3D surface for its triangles
        Vd, boundary = V, F
        rho = _mean_edge_length(V, F)
    _check_sample_count(C, BE, nP, rho / samples_per_edge, min_samples, samples_per_edge)
    S, handles = sample_skeleton(C, BE, P, spacing=rho / samples_per_edge, min_samples=min_samples)
    inside = np.abs(_winding_number(Vd, boundary, S)) > 0.5
    S, handles = _keep_inside(S, handles, inside, nP, nB)

    # A sample on an input vertex is that vertex (inserting it again would be dropped by the
    # mesher as a duplicate and shift every index after it); nearly on one, or an input vertex
    # nearly on a bone, would make a sliver.
    scale = float(np.linalg.norm(Vd.max(0) - Vd.min(0)))
    spacing = rho / samples_per_edge
    snap = max(_SNAP * spacing, 1e-12 * scale)
    S, handles, vertex_of = _snap_to_vertices(Vd, S, handles, C, BE, nP, snap)
    on_vertex = vertex_of >= 0
    insert = np.flatnonzero(~on_vertex)
    Si = S[insert]
    vertex_of[insert] = len(Vd) + np.arange(len(insert))

    if planar:
        Vv, T = _mesh_planar(Vd, F, boundary, S, handles, vertex_of, Si, nP, nB, flags, verbose)
        # Triangle splits bone segments to meet its quality and area bounds: the vertices it
        # adds there lie on the bone and are held like its samples.
        added = len(Vd) + len(Si)
        on_bone, bones = _points_on_bones(Vv[added:], C, BE, nP, snap)
        vertex_of = np.concatenate([vertex_of, added + on_bone])
        handles = handles + bones
    else:
        Vt, Tt, err = _tetgen_keeping_rows(V, boundary, Si, flags or "pq2Y", verbose)
        if Vt is None or Tt is None:
            fallback = _TetWildFallback(rho, samples_per_edge, tetwild_options, flags, verbose)
            return fallback.mesh(V, boundary, S, Si, handles, nP + nB, scale, err)
        Vv, T = Vt, Tt

    b = vertex_of
    bc = _bc_matrix(handles, nP + nB)
    if V.shape[1] == 3 and Vv.shape[1] == 2:
        Vv = np.c_[Vv, np.zeros(len(Vv))]
    order = np.argsort(b, kind="stable")
    return Vv, T, b[order].astype(np.int64), bc[order]


def _mesh_planar(
    Vd: Arr,
    F: Arr | None,
    E: Arr,
    S: Arr,
    handles: Handles,
    vertex_of: Arr,
    Si: Arr,
    nP: int,
    nB: int,
    flags: str | None,
    verbose: bool,
) -> tuple[Arr, Arr]:
    """Triangle mesh of the 2D domain with the inserted samples ``Si`` as vertices, bones as
    segments (``vertex_of``: each sample's vertex in ``[Vd; Si]``)."""
    seg = _bone_segments(S, handles, vertex_of, nP, nB)
    # An outline is refined to quality triangles; a given triangle mesh keeps its resolution
    # (refining around its interior vertices next to bone segments cascades to slivers).
    default = "pq30Y" if F is None or F.shape[1] == 2 else "pY"
    Vv, T, budget = _triangle(Vd, E, Si, seg, flags or default, verbose)
    if budget is not None:
        warnings.warn(
            f"Triangle stopped refining after adding {budget:,} vertices: the quality switch "
            "is not met everywhere (crossing edges or features far below the extent of V?)",
            MeshingWarning,
            stacklevel=3,
        )
    if not _rows_match(Vv, Vd, Si):
        raise RuntimeError("Triangle did not keep the input vertices and samples in order")
    # Triangle keeps triangles inside the outer segments only: drop those in holes
    cent = Vv[T].mean(axis=1)
    return Vv, T[np.abs(_winding_number(Vd, E, cent)) > 0.5]


def _tetgen_keeping_rows(
    V: Arr, F: Arr, Si: Arr, flags: str, verbose: bool
) -> tuple[Arr | None, Arr | None, Exception | None]:
    """TetGen's ``(V_vol, T, None)`` when it keeps the surface vertices and the samples as the
    first rows, else ``(None, None, the error TetGen raised or None)``."""
    try:
        Vv, T = _tetgen(V, F, Si, flags, verbose, check=True)
    except ImportError:
        raise
    except Exception as e:  # noqa: BLE001 - TetGen raises RuntimeError and others
        return None, None, e
    if not _rows_match(Vv, V, Si):
        return None, None, None
    return Vv, T, None


class _TetWildFallback:
    """The 3D mesh when TetGen rejects the surface: fTetWild, then TetGen on fTetWild's repaired
    boundary, then snapping (see :func:`mesh_with_skeleton`)."""

    def __init__(
        self,
        rho: float,
        samples_per_edge: float,
        tetwild_options: dict[str, Any] | None,
        flags: str | None,
        verbose: bool,
    ) -> None:
        user = dict(tetwild_options or {})
        self.options = {"edge_length_abs": rho, **user}
        # for snapping, vertices must be at least as dense as the samples
        fine = user.get("edge_length_abs", rho / samples_per_edge)
        self.fine_options = {**self.options, "edge_length_abs": fine}
        self.flags = flags or "pq2Y"
        self.verbose = verbose

    def mesh(
        self,
        V: Arr,
        F: Arr,
        S: Arr,
        Si: Arr,
        handles: Handles,
        m: int,
        scale: float,
        err: Exception | None,
    ) -> tuple[Arr, Arr, Arr, Arr]:
        """``(V_vol, T, b, bc)`` for the samples ``S`` (``Si``: those not on a surface vertex)."""
        try:
            Vw, Tw = _tetwild(V, F, Si, self.verbose, **self.options)
        except ImportError as e:
            why = f"TetGen failed ({err})" if err else "TetGen did not keep the input vertices"
            raise ImportError(
                f"{why}; the fallback mesher pytetwild is not available ({e}): "
                f"{_INSTALL} (or repair the surface)"
            ) from None

        def finer() -> tuple[Arr, Arr]:
            return _tetwild(V, F, Si, self.verbose, **self.fine_options)

        return _fallback(Vw, Tw, S, handles, m, scale, self.flags, self.verbose, finer)


def _fallback(
    Vw: Arr,
    Tw: Arr,
    S: Arr,
    handles: Handles,
    m: int,
    scale: float,
    flags: str,
    verbose: bool,
    finer: Callable[[], tuple[Arr, Arr]],
) -> tuple[Arr, Arr, Arr, Arr]:
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
            stacklevel=4,
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
        stacklevel=4,
    )
    order = np.argsort(idx)
    return Vv, Tw, idx[order].astype(np.int64), bc[order]


# ---------------------------------------------------------------------------------------------


def skin_weights(
    V: ArrayLike,
    F: ArrayLike | None,
    C: ArrayLike,
    BE: ArrayLike | None = None,
    P: ArrayLike | None = None,
    *,
    mesh_options: dict[str, Any] | None = None,
    partition_of_unity: bool = _BBW_DEFAULTS["partition_of_unity"],
    normalize: bool = True,
    mass: str = "voronoi",
    solver: str = _BBW_DEFAULTS["solver"],
    tol: float = _BBW_DEFAULTS["tol"],
    max_iter: int = _BBW_DEFAULTS["max_iter"],
    seed: int = _BBW_DEFAULTS["seed"],
    lbfgs_memory: int = _BBW_DEFAULTS["lbfgs_memory"],
    memory_limit: float | None = None,
    verbose: bool = False,
    callback: Callback | None = None,
    return_mesh: bool = False,
    return_info: bool = False,
) -> Any:
    """Bounded biharmonic weights on the vertices of a surface (3D) or 2D domain.

    Meshes the interior with the handles as vertices (:func:`mesh_with_skeleton`), solves
    :func:`skinrs.bbw_dual_constrained` there and returns the rows of the input vertices.

    Parameters
    ----------
    V, F, C, BE, P
        As in :func:`mesh_with_skeleton`.
    mesh_options : dict, optional
        Extra keyword arguments of :func:`mesh_with_skeleton`.
    partition_of_unity, normalize, mass, solver, tol, max_iter, seed, lbfgs_memory, memory_limit,
        verbose and callback as in :func:`skinrs.bbw_dual_constrained`.
    return_mesh : bool
        Also return a dict with the volume mesh and its weights: ``V``, ``T``, ``b``, ``bc``,
        ``W`` (all volume vertices).
    return_info : bool
        Also return an :class:`skinrs.Info`: that of :func:`skinrs.bbw_dual_constrained` plus
        ``volume_vertices``, ``volume_elements``, ``time_meshing`` and ``interpolated`` (the
        fallback mesher moved the surface, so the weights were interpolated), and ``seconds``
        for the whole call.

    Returns
    -------
    W : (n, p + k) float array
        Weights of the input vertices: point handles first, then bones; ``W >= 0``, rows sum to
        1, and 1 in a bone's column on that bone. Followed by the mesh dict and the info, when
        asked for, in that order.

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

    t0 = time.perf_counter()
    Vin = as_points(V, "V", dims=(2, 3))
    Vv, T, b, bc = mesh_with_skeleton(V, F, C, BE, P, **(mesh_options or {}))
    t_mesh = time.perf_counter() - t0
    W, info = bbw_dual_constrained(
        Vv,
        T,
        b,
        bc,
        partition_of_unity=partition_of_unity,
        normalize=normalize,
        mass=mass,
        solver=solver,
        tol=tol,
        max_iter=max_iter,
        seed=seed,
        lbfgs_memory=lbfgs_memory,
        memory_limit=memory_limit,
        verbose=verbose,
        callback=callback,
        return_info=True,
    )
    n = len(Vin)
    # The meshers keep the input vertices as the first rows; only the fallback does not.
    inputs_first = Vv.shape[1] == Vin.shape[1] and np.array_equal(Vv[:n], Vin)
    Ws = np.ascontiguousarray(W[:n]) if inputs_first else _interpolate(Vin, Vv, T, W)
    out: list[Any] = [Ws]
    if return_mesh:
        out.append({"V": Vv, "T": T, "b": b, "bc": bc, "W": W})
    if return_info:
        info.update(
            volume_vertices=len(Vv),
            volume_elements=len(T),
            time_meshing=t_mesh,
            interpolated=not inputs_first,
            seconds=time.perf_counter() - t0,
        )
        out.append(info)
    return out[0] if len(out) == 1 else tuple(out)
