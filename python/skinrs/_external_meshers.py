"""Calls into the optional meshers: TetGen (3D), Triangle (2D) and fTetWild (3D fallback).

They are reached through the Python packages ``tetgen``, ``triangle`` and ``pytetwild``
(``pip install skinrs[mesh]``), never linked into skinrs's compiled core, and run in a child
process: each of them crashes or loops on some inputs, which then is an exception here (and
Ctrl-C stops the child). Their scratch files land in the child's temporary directory.
"""

from __future__ import annotations

import importlib.util
import json
import os
import re
import subprocess
import sys
import tempfile
from typing import Any

import numpy as np
from numpy.typing import NDArray

from . import _checks
from ._tet_edit import _tet_volumes

_INSTALL = "install the optional meshing packages with `pip install skinrs[mesh]`"


# Unit-box coordinates below this (but not 0) are refused: the fourth-degree incircle test of
# Triangle underflowed (and crashed) with 1e-75.
_TINY = 1e-50
# Two mesher input points closer than this (relative to the extent) are refused: normalising
# merges them into one, and Triangle segfaults on a segment between duplicate vertices (an
# outline with one vertex at 4.7e16 among unit-scale ones).
RESOLUTION = 1e-12


def _describe_row(r: int, n_input: int) -> str:
    return f"V row {r}" if r < n_input else "a bone sample (from C)"


def _check_resolution(
    U: NDArray[np.float64], pts: NDArray[np.float64], n_input: int, ext: float
) -> None:
    """ValueError when two rows of the unit-box points ``U`` (``pts`` normalised) lie within
    ``RESOLUTION``."""
    from scipy.spatial import cKDTree

    d, nn = cKDTree(U).query(U, k=2)
    close = np.flatnonzero(d[:, 1] <= RESOLUTION)
    if not len(close):
        return
    r = int(close[0])
    # with duplicates the row itself may come second
    i, j = sorted((r, int(nn[r, 1] if nn[r, 0] == r else nn[r, 0])))
    what = (
        f"V rows {i} and {j}"
        if j < n_input
        else f"{_describe_row(i, n_input)} and a bone sample (from C)"
    )
    raise ValueError(
        f"{what} lie {np.linalg.norm(pts[i] - pts[j]):.3g} apart, below {RESOLUTION:g} of the extent {ext:.3g} "
        "of the shape and its handles: double precision cannot keep them apart in the mesher; "
        "look for a stray coordinate in V or C, or merge the points"
    )


def _to_unit_box(
    pts: NDArray[np.float64], n_input: int
) -> tuple[NDArray[np.float64], NDArray[np.float64], float]:
    """``pts`` moved and scaled into the unit box, with the shift and scale.

    Triangle's and TetGen's exact predicates assume products of coordinates neither overflow nor
    underflow: Triangle gets unit-box coordinates, and a coordinate that is nonzero but below
    ``_TINY`` of the extent (whose products would underflow), or two points closer than
    ``RESOLUTION`` of it, are refused instead of crashing the C code.
    """
    lo = pts.min(axis=0)
    ext = float((pts.max(axis=0) - lo).max()) or 1.0
    U = (pts - lo) / ext
    tiny = (U != 0) & (np.abs(U) < _TINY)
    if tiny.any():
        r = int(np.argwhere(tiny)[0][0])
        what = _describe_row(r, n_input)
        raise ValueError(
            f"{what} lies within {np.abs(U[tiny]).min() * ext:.3g} of another coordinate, below "
            f"{_TINY:g} of the shape's extent {ext:.3g}: the mesher's predicates would underflow; "
            "round such coordinates"
        )
    _check_resolution(U, pts, n_input, ext)
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


_AREA = r"a(\d+(?:\.\d*)?|\.\d+)"


def _unit_switches(flags: str, measure: float) -> str:
    """``flags`` for unit-box input: a maximum area ``a<x>`` is divided by ``measure`` (the
    extent squared)."""

    def unit(m: re.Match[str]) -> str:
        # positional: Triangle reads no exponent ("1e-05" would be the switches e, 0, 5)
        return "a" + np.format_float_positional(float(m.group(1)) / measure, trim="-")

    return re.sub(_AREA, unit, flags)


def _import_tetgen() -> Any:
    try:
        import tetgen
    except ImportError:
        raise ImportError(f"mesh_with_skeleton needs TetGen in 3D: {_INSTALL}") from None
    return tetgen


def _tetgen(
    V: NDArray[Any],
    F: NDArray[Any],
    S: NDArray[Any],
    flags: str,
    verbose: bool,
    check: bool = False,
) -> tuple[NDArray[Any], NDArray[Any]]:
    """TetGen's ``(V_vol, T)`` for the surface ``(V, F)`` with the points ``S`` inserted, run in
    a child process. RuntimeError when TetGen fails (its message), crashes (it corrupts its heap
    on some slightly bent planar faces), or, with ``check``, when the surface intersects itself
    (checked first: TetGen given such a surface *and* points to insert can abort)."""
    if not verbose and "Q" not in flags:
        flags += "Q"
    out = _tetgen_child(V, F, S, flags, verbose, check, check_only=False)
    if "self_intersects" in out:
        raise RuntimeError("the input surface has self-intersections")
    return out["vertices"].astype(np.float64), out["elements"].astype(np.int64)


def _self_intersects(V: NDArray[Any], F: NDArray[Any]) -> bool:
    """Whether TetGen finds intersecting faces in the surface alone (switch ``d``)."""
    out = _tetgen_child(V, F, np.zeros((0, np.shape(V)[1])), "", False, True, check_only=True)
    return bool(out["self_intersects"])


def _tetgen_child(
    V: NDArray[Any],
    F: NDArray[Any],
    S: NDArray[Any],
    flags: str,
    verbose: bool,
    check: bool,
    check_only: bool,
) -> dict[str, NDArray[Any]]:
    _import_tetgen()
    pts = np.vstack([V, S])
    _to_unit_box(pts, len(V))  # refuses coordinates whose products underflow
    # TetGen gets the input units: its tolerances are relative, and unit-box input changed its
    # results on self-intersecting surfaces (an abort instead of an error)
    inputs = {
        "points": pts.astype(np.float64),
        "faces": np.asarray(F, np.int32),
        "n_surface": np.array(len(V)),
        "switches": np.array(flags),
        "check": np.array(check),
        "check_only": np.array(check_only),
    }
    why, out = _in_child([_MESHER_CHILD, "tetgen"], inputs, [str(_memory_limit())], verbose)
    if out is None:
        raise RuntimeError(f"TetGen failed on this surface ({why})")
    return out


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
    code = "from skinrs._external_meshers import _tetwild_main; _tetwild_main()"
    inputs = {"V": np.asarray(V, float), "F": np.asarray(F, np.int32)}
    why, r = _in_child(["-c", code], inputs, [opts, str(int(verbose))], verbose)
    if r is None:
        raise ValueError(
            f"V, F: TetGen rejected this surface and fTetWild failed on it ({why}); "
            "repair the surface (self-intersections, folds, holes) and try again"
        )
    VV, TT = r["V"].astype(np.float64), r["T"].astype(np.int64)
    flip = _tet_volumes(VV, TT) < 0
    TT[flip] = TT[flip][:, [0, 1, 3, 2]]
    return VV, TT


def _in_child(
    command: list[str], inputs: dict[str, Any], args: list[str], verbose: bool
) -> tuple[str, dict[str, NDArray[Any]] | None]:
    """Runs ``python <command> in.npz out.npz <args>`` in a scratch directory with ``inputs``
    saved to ``in.npz``: the arrays of ``out.npz``, or None when the child failed (e.g. a
    segfault), with its exit code and last line of stderr. Ctrl-C (or any exception) while
    waiting kills the child. Its stdout is dropped unless ``verbose``."""
    with tempfile.TemporaryDirectory(prefix="skinrs-mesher-") as tmp:
        inp, out = os.path.join(tmp, "in.npz"), os.path.join(tmp, "out.npz")
        np.savez(inp, **inputs)
        # scratch files land in tmp; one BLAS thread (the child does no linear algebra)
        env = {**os.environ, "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"}
        argv = [sys.executable, *command, inp, out, *args]
        quiet = None if verbose else subprocess.DEVNULL
        child = subprocess.Popen(
            argv, cwd=tmp, env=env, stdout=quiet, stderr=subprocess.PIPE, text=True
        )
        try:
            _, err = child.communicate()
        except BaseException:
            child.kill()
            child.wait()
            raise
        lines = [ln.strip() for ln in err.splitlines() if ln.strip()]
        why = f"exit code {child.returncode}" + (f": {lines[-1][:200]}" if lines else "")
        if child.returncode != 0 or not os.path.exists(out):
            return why, None
        with np.load(out) as r:
            return why, {k: np.array(r[k]) for k in r.files}


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


# Vertices Triangle may add beyond the input when the flags set no bound (switch S), per input
# point and in all: its quality refinement ("q") does not terminate on some outlines (crossing
# segments, features far below the extent) and fills the memory.
_STEINER_PER_POINT = 200
_STEINER_MIN = 50_000
# Address space of the Triangle child before meshing (Python, numpy, Triangle), in bytes.
_CHILD_BASE_MEMORY = 1 << 30
# The script the meshers run in (a child process, see its docstring).
_MESHER_CHILD = os.path.join(os.path.dirname(__file__), "_mesher_child.py")


def _memory_limit() -> int:
    """Address space a mesher child may take: half of the machine's memory."""
    return _checks.physical_memory() // 2


def _steiner_budget(flags: str, n_points: int, given: str) -> tuple[str, int | None]:
    """``flags`` with a bound ``S<n>`` on the added vertices, and that bound (None when the
    caller gave one). An area bound ``a<x>`` (unit box) raises the budget to what it asks;
    ``given`` are the flags as the caller wrote them (for the error message)."""
    if "S" in flags:
        return flags, None
    budget = max(_STEINER_MIN, _STEINER_PER_POINT * n_points)
    for m in re.finditer(_AREA, flags):
        area = float(m.group(1))
        budget = max(budget, int(min(4.0 / area, 1e12)) if area > 0 else budget)
    # a triangle record of Triangle's takes ~100 bytes, and there are ~2 per vertex
    _checks.fits_in_memory(300.0 * budget, f"flags {given!r}: the area bound")
    return f"{flags}S{budget}", budget


def _triangle(
    V: NDArray[Any],
    E: NDArray[Any],
    S: NDArray[Any],
    seg: NDArray[Any],
    flags: str,
    verbose: bool,
) -> tuple[NDArray[Any], NDArray[Any], int | None]:
    """Triangle's ``(V_vol, T, budget)`` of the outline ``V, E`` with the points ``S`` and the
    segments ``seg`` (indices into ``[V; S]``) inside: ``budget`` is the bound on added
    vertices that it reached (the quality switch was then not met everywhere), else None."""
    if importlib.util.find_spec("triangle") is None:
        raise ImportError(f"mesh_with_skeleton needs Triangle in 2D: {_INSTALL}")
    given = flags
    if not verbose and "Q" not in flags:
        flags += "Q"
    pts = np.vstack([V, S])
    U, lo, ext = _to_unit_box(pts, len(V))
    segs = np.vstack([E, seg]) if len(seg) else E
    switches, budget = _steiner_budget(_unit_switches(flags, ext**2), len(pts), given)
    # Triangle runs in a child process: crossing or nearly touching edges can make its quality
    # refinement loop (filling the memory) or crash; that becomes a ValueError here
    limit = _memory_limit()
    if budget is not None:  # room for the budget of vertices (~1 kB each in Triangle)
        limit = min(limit, _CHILD_BASE_MEMORY + 1000 * (len(pts) + budget))
    inputs = {"vertices": U, "segments": segs.astype(np.int32), "switches": np.array(switches)}
    why, out = _in_child([_MESHER_CHILD, "triangle"], inputs, [str(limit)], verbose)
    if out is None:
        raise ValueError(
            f"V, F: Triangle failed on this domain ({why}); check the outline for "
            "crossing or overlapping edges, and bones crossing it"
        )
    VV = _from_unit_box(out["vertices"].astype(np.float64), pts, U, lo, ext)
    reached = budget if budget is not None and len(VV) >= len(pts) + budget else None
    return VV, out["elements"].astype(np.int64), reached
