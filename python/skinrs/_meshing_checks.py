"""Argument checks of :func:`skinrs.mesh_with_skeleton`: the domain, the mesher switches,
the number of bone samples.
"""

from __future__ import annotations

import re

import numpy as np
from numpy.typing import ArrayLike

from . import _checks
from ._checks import as_index_array, as_points
from ._meshing_geometry import Arr

# Bone samples a call may insert: each costs the mesher a few kB; far more is a unit mistake.
_MAX_SAMPLES = 10**6

# Switches passed on to Triangle / TetGen: the ones that only tune quality, size, verbosity or
# checks. Others change what the mesher reads or returns (refinement of an existing mesh, point
# files, second-order elements, zero-based output ...) and can crash the C code.
_MESHER_SWITCHES = {True: set("pqaYADjSCQVuO"), False: set("pqaYAOSTVQCMd")}
_SWITCH_SYNTAX = re.compile(r"(?:[A-Za-z](?:\d+(?:\.\d*)?|\.\d+)?(?:/\d+(?:\.\d*)?)?)*")


def _checked_flags(flags: object, planar: bool) -> str | None:
    """``flags`` (None or a Triangle / TetGen switch string) after checking it."""
    if flags is None:
        return None
    tool = "Triangle" if planar else "TetGen"
    if not isinstance(flags, str) or len(flags) > 100 or not _SWITCH_SYNTAX.fullmatch(flags):
        raise ValueError(f"flags {str(flags)[:40]!r} is not a {tool} switch string (e.g. 'pq30Y')")
    bad = sorted({c for c in flags if c.isalpha()} - _MESHER_SWITCHES[planar])
    if bad:
        allowed = "".join(sorted(_MESHER_SWITCHES[planar]))
        raise ValueError(
            f"flags: {tool} switch(es) {''.join(bad)!r} are not supported here (allowed: {allowed})"
        )
    if "p" not in flags:
        raise ValueError(
            f"flags must contain 'p' ({tool} meshes the given boundary), got {flags!r}"
        )
    return flags


def _check_sample_count(
    C: Arr,
    BE: Arr | None,
    nP: int,
    spacing: float,
    min_samples: int,
    samples_per_edge: float,
) -> None:
    """ValueError before sampling when the bones would get more than ``_MAX_SAMPLES`` samples."""
    if BE is None or not len(BE):
        return
    L = np.linalg.norm(C[BE[:, 1]] - C[BE[:, 0]], axis=1)
    with np.errstate(over="ignore", divide="ignore", invalid="ignore"):
        count = nP + float(np.maximum(min_samples, np.ceil(L / spacing) + 1).sum())
    if not count <= _MAX_SAMPLES:
        raise ValueError(
            f"samples_per_edge={samples_per_edge:g} would put {count:.3g} samples on the bones "
            f"(at most {_MAX_SAMPLES:,}); lower samples_per_edge or min_samples"
        )


def _first_duplicate_row(A: Arr) -> tuple[int, int] | None:
    """``(i, j)``, two rows of ``A`` that are equal, or None."""
    _, first, inverse = np.unique(A, axis=0, return_index=True, return_inverse=True)
    inverse = inverse.reshape(-1)
    dup = np.flatnonzero(first[inverse] != np.arange(len(A)))
    if not len(dup):
        return None
    j = int(dup[0])
    return int(first[inverse[j]]), j


def _checked_domain(
    V: ArrayLike, F: ArrayLike | None, C: ArrayLike, BE: ArrayLike | None, P: ArrayLike | None
) -> tuple[Arr, Arr | None, Arr, Arr | None, Arr | None, bool]:
    """The arguments of :func:`mesh_with_skeleton` as checked arrays, and whether it is 2D."""
    V = _checks.spans(as_points(V, "V", dims=(2, 3), min_rows=3))
    n = len(V)
    # Triangle and TetGen crash or silently merge on repeated input vertices
    dup = _first_duplicate_row(V)
    if dup is not None:
        raise ValueError(
            f"V rows {dup[0]} and {dup[1]} are the same point {V[dup[0]].tolist()}: remove the "
            "duplicate vertex (and renumber F)"
        )
    # 2D: 2 columns, or 3 with z = 0 (2D OBJ files); a closed 3D surface is never flat
    planar = V.shape[1] == 2 or not np.any(V[:, 2])
    if F is None and not planar:
        raise ValueError("a 3D surface needs its triangles F")
    if F is not None:
        F = as_index_array(F, n, "F", cols=(2, 3) if planar else 3, allow_empty=False)
        srt = np.sort(F, axis=1)
        rep = np.flatnonzero(np.any(srt[:, 1:] == srt[:, :-1], axis=1))
        if len(rep):
            raise ValueError(f"F row {int(rep[0])} repeats a vertex: {F[rep[0]].tolist()}")
    dim = 2 if planar else 3
    C = as_points(C, "C", dims=(2, 3))
    if C.shape[1] != dim:
        if C.shape[1] == 3 and dim == 2 and not np.any(C[:, 2]):
            C = np.ascontiguousarray(C[:, :2])
        else:
            raise ValueError(f"C must have {dim} columns like the domain, got {C.shape}")
    BE = None if BE is None else as_index_array(BE, len(C), "BE", cols=2)
    P = None if P is None else as_index_array(P, len(C), "P", ndim=1)
    if (0 if P is None else len(P)) + (0 if BE is None else len(BE)) == 0:
        raise ValueError("no handles: give bones BE and/or point handles P")
    if BE is not None and np.any(BE[:, 0] == BE[:, 1]):
        raise ValueError(f"bone {int(np.flatnonzero(BE[:, 0] == BE[:, 1])[0])} has zero length")
    _check_skeleton_span(V, C, BE, P)
    return V, F, C, BE, P, planar


# A skeleton spanning less than this fraction of the shape is a unit mistake (V in mm, C in m):
# the mesh around it is all needles, and the solve on it crawls (minutes at 1e-5) or is wrong.
_SKELETON_SPAN_MIN = 1e-4


def _check_skeleton_span(V: Arr, C: Arr, BE: Arr | None, P: Arr | None) -> None:
    """ValueError when the joints in use span less than ``_SKELETON_SPAN_MIN`` of ``V``."""
    used = np.unique(np.concatenate([np.ravel([] if X is None else X) for X in (BE, P)]))
    J = C[used.astype(np.int64)]
    if len(np.unique(J, axis=0)) < 2:  # a single point handle
        return
    span = float(np.linalg.norm(J.max(0) - J.min(0)))
    shape = float(np.linalg.norm(V.max(0) - V.min(0)))
    if span < _SKELETON_SPAN_MIN * shape:
        raise ValueError(
            f"C: the handles span {span:.3g} (bounding-box diagonal), only {span / shape:.2g} of "
            f"the shape V ({shape:.3g}); are C and V in the same units? (the skeleton must "
            f"span at least {_SKELETON_SPAN_MIN:g} of the shape)"
        )
