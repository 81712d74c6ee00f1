"""Calls into the optional meshers: TetGen (3D), Triangle (2D) and fTetWild (3D fallback).

They are reached through the Python packages ``tetgen``, ``triangle`` and ``pytetwild``
(``pip install skinrs[mesh]``), never linked into skinrs's compiled core.
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import subprocess
import sys
import tempfile
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


# Unit-box coordinates below this (but not 0) are refused: the fourth-degree incircle test of
# Triangle underflowed (and crashed) with 1e-75.
_TINY = 1e-50


def _to_unit_box(
    pts: NDArray[np.float64], n_input: int
) -> tuple[NDArray[np.float64], NDArray[np.float64], float]:
    """``pts`` moved and scaled into the unit box, with the shift and scale.

    Triangle's and TetGen's exact predicates assume products of coordinates neither overflow nor
    underflow: Triangle gets unit-box coordinates, and a coordinate that is nonzero but below
    ``_TINY`` of the extent (whose products would underflow) is refused instead of crashing
    the C code.
    """
    lo = pts.min(axis=0)
    ext = float((pts.max(axis=0) - lo).max()) or 1.0
    U = (pts - lo) / ext
    tiny = (U != 0) & (np.abs(U) < _TINY)
    if tiny.any():
        r = int(np.argwhere(tiny)[0][0])
        what = f"V row {r}" if r < n_input else "a bone sample (from C)"
        raise ValueError(
            f"{what} lies within {np.abs(U[tiny]).min() * ext:.3g} of another coordinate, below "
            f"{_TINY:g} of the shape's extent {ext:.3g}: the mesher's predicates would underflow; "
            "round such coordinates"
        )
    return U, lo, ext


def _from_unit_box(
    VV: NDArray[np.float64],
    pts: NDArray[np.float64],
    U: NDArray[np.float64],
    lo: NDArray[np.float64],
    ext: float,
) -> NDArray[np.float64]:
    """Mesher output back in input units; the input points' rows are restored exactly."""
    out = VV * ext + lo
    k = len(pts)
    if len(VV) >= k and np.array_equal(VV[:k], U):
        out[:k] = pts
    return out


def _unit_switches(flags: str, measure: float) -> str:
    """``flags`` for unit-box input: a maximum area ``a<x>`` is divided by ``measure`` (the
    extent squared)."""
    return re.sub(
        r"a(\d+(?:\.\d*)?|\.\d+)", lambda m: f"a{float(m.group(1)) / measure:.17g}", flags
    )


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
    _to_unit_box(pts, len(V))  # refuses coordinates whose products underflow
    # TetGen gets the input units: its tolerances are relative, and unit-box input changed its
    # results on self-intersecting surfaces (an abort instead of an error)
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

    _to_unit_box(np.asarray(V, float), len(V))
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
    oriented (fTetWild's own order is the opposite one).

    fTetWild runs in a child Python process: on some folded surfaces it segfaults, which then
    raises ``ValueError`` here instead of killing the caller (Ctrl-C stops the child)."""
    import pytetwild  # noqa: F401 - ImportError when missing (or its pyvista dependency is)

    try:
        opts = json.dumps(options)
    except (TypeError, ValueError):
        raise ValueError(f"tetwild_options must map names to numbers, got {options!r}") from None
    with tempfile.TemporaryDirectory(prefix="skinrs-tetwild-") as tmp:
        inp, out = os.path.join(tmp, "in.npz"), os.path.join(tmp, "out.npz")
        np.savez(inp, V=np.asarray(V, float), F=np.asarray(F, np.int32))
        code = "from skinrs._external_meshers import _tetwild_main; _tetwild_main()"
        args = [sys.executable, "-c", code, inp, out, opts, str(int(verbose))]
        child = subprocess.Popen(args, cwd=tmp)  # scratch files land in tmp
        try:
            rc = child.wait()
        except BaseException:
            child.kill()
            child.wait()
            raise
        if rc != 0 or not os.path.exists(out):
            raise ValueError(
                f"V, F: TetGen rejected this surface and fTetWild failed on it (exit code {rc}); "
                "repair the surface (self-intersections, folds, holes) and try again"
            )
        with np.load(out) as r:
            VV, TT = np.array(r["V"], dtype=np.float64), np.array(r["T"], dtype=np.int64)
    flip = _tet_volumes(VV, TT) < 0
    TT[flip] = TT[flip][:, [0, 1, 3, 2]]
    return VV, TT


def _tetwild_main() -> None:
    """Entry point of the fTetWild child process: ``in.npz out.npz options-json verbose``."""
    import pytetwild

    inp, out, options, verbose = sys.argv[1:5]
    with np.load(inp) as d:
        V, F = d["V"], d["F"]
    VV, TT = pytetwild.tetrahedralize(  # type: ignore[attr-defined]
        V, F, quiet=verbose != "1", **json.loads(options)
    )
    np.savez(out, V=np.asarray(VV, float), T=np.asarray(TT, np.int64))


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
    U, lo, ext = _to_unit_box(pts, len(V))
    segs = np.vstack([E, seg_S + len(V)]) if len(seg_S) else E
    try:
        out = triangle.triangulate(
            {"vertices": U, "segments": segs.astype(np.int32)}, _unit_switches(flags, ext**2)
        )
    except RuntimeError as e:  # "Triangulation failed -- probably because of invalid geometry"
        raise ValueError(f"V, F: Triangle could not mesh this domain: {e}") from None
    VV = _from_unit_box(np.asarray(out["vertices"], float), pts, U, lo, ext)
    return VV, np.asarray(out["triangles"], np.int64)
