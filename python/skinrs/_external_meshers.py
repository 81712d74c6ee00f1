"""Calls into the optional meshers: TetGen (3D), Triangle (2D) and fTetWild (3D fallback).

They are reached through the Python packages ``tetgen``, ``triangle`` and ``pytetwild``
(``pip install skinrs[mesh]``), never linked into skinrs's compiled core.
"""

from __future__ import annotations

import contextlib
import os
import sys
from collections.abc import Iterator
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ._tet_edit import _tet_volumes

_INSTALL = "install the optional meshing packages with `pip install skinrs[mesh]`"


@contextlib.contextmanager
def _quiet_fd1(quiet: bool) -> Iterator[None]:
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
def _no_litter() -> Iterator[None]:
    """Removes the scratch files the meshers leave in the working directory (only those the
    call created: a file of that name that was there before is left alone)."""
    before = {f for f in _LITTER if os.path.exists(f)}
    try:
        yield
    finally:
        for f in set(_LITTER) - before:
            with contextlib.suppress(OSError):
                os.remove(f)


def _import_tetgen() -> Any:
    try:
        import tetgen
    except ImportError:
        raise ImportError(f"mesh_with_skeleton needs TetGen in 3D: {_INSTALL}") from None
    return tetgen


def _tetgen(
    V: NDArray[Any], F: NDArray[Any], S: NDArray[Any], flags: str, verbose: bool
) -> tuple[NDArray[Any], NDArray[Any]]:
    tetgen = _import_tetgen()
    if not verbose and "Q" not in flags:
        flags += "Q"
    pts = np.vstack([V, S])
    with _quiet_fd1(not verbose), _no_litter():
        tg = tetgen.TetGen(pts, F.astype(np.int32))
        VV, TT = tg.tetrahedralize(switches=flags)[:2]
    # copies: the arrays may view memory owned by `tg`, freed when it goes away
    return np.array(VV, dtype=np.float64, copy=True), np.array(TT, dtype=np.int64, copy=True)


def _self_intersects(V: NDArray[Any], F: NDArray[Any]) -> bool:
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


def _tetwild(
    V: NDArray[Any], F: NDArray[Any], S: NDArray[Any], verbose: bool, **options: Any
) -> tuple[NDArray[Any], NDArray[Any]]:
    """Fallback mesher: fTetWild (robust to self-intersections and holes). Does not keep the
    input vertices or insert points, so the caller meshes its boundary again or snaps vertices
    onto the samples. ``options`` go to ``pytetwild.tetrahedralize``. Tets come back positively
    oriented (fTetWild's own order is the opposite one)."""
    import pytetwild  # ImportError when missing (also raised when its pyvista dependency is)

    with _no_litter():
        VV, TT = pytetwild.tetrahedralize(  # type: ignore[attr-defined]
            np.asarray(V, float), np.asarray(F, np.int32), quiet=not verbose, **options
        )
    VV, TT = np.array(VV, dtype=np.float64), np.array(TT, dtype=np.int64)
    flip = _tet_volumes(VV, TT) < 0
    TT[flip] = TT[flip][:, [0, 1, 3, 2]]
    return VV, TT


def _triangle(
    V: NDArray[Any],
    E: NDArray[Any],
    S: NDArray[Any],
    seg_S: NDArray[Any],
    flags: str,
    verbose: bool,
) -> tuple[NDArray[Any], NDArray[Any]]:
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
