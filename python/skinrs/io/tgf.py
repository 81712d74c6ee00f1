"""libigl ``.tgf`` skeleton graphs: joint positions and directed bone edges."""

from __future__ import annotations

import os
from typing import Any, cast

import numpy as np
from numpy.typing import ArrayLike

from .._checks import as_index_array, as_points
from ._text import _int_rows, _pad_z, _Source, _to_float, _to_int, _write_lines


def read_tgf(path: str | os.PathLike[str], *, return_point_handles: bool = False) -> Any:
    """Read a libigl ``.tgf`` skeleton: joint positions and directed bone edges.

    The file holds joint lines ``index x y z [extra columns]`` (index 1-based, in order), a
    ``#`` line, bone lines ``i j [is_bone is_pseudo is_cage]`` (1-based, parent -> child) and
    a closing ``#``; anything after it is ignored, as libigl does. Extra joint columns (often
    uninitialised garbage such as ``6.95e-310``) are ignored. A joint line with only ``x y``
    gets ``z = 0``. Blank lines and a missing bone section are fine; a last data line without a
    newline and no closing ``#`` after it is a cut file and raises.
    Pseudo edges and cage edges are not supported and raise.

    Parameters
    ----------
    path : str or pathlib.Path
    return_point_handles : bool
        Also return ``P``, the joints that no bone references (libigl's point handles).

    Returns
    -------
    C : (n, 3) float64
        Joint positions (2D skeletons have ``z = 0``; drop it with ``C[:, :2]``).
    BE : (k, 2) int64
        0-based bone edges, parent -> child.
    P : (p,) int64, only if ``return_point_handles``

    Examples
    --------
    >>> C, BE = read_tgf("hand.tgf")                      # doctest: +SKIP
    >>> C.shape, BE.shape                                 # doctest: +SKIP
    ((21, 3), (20, 2))
    """
    src = _Source(path)
    joints: list[list[float]] = []
    bones: list[tuple[int, int, int]] = []  # (parent, child, line)
    section = 0  # 0: joints, 1: bones, 2: ignored tail
    for lineno, raw in enumerate(src.lines, 1):
        s = raw.split()
        if not s:
            continue
        if s[0].startswith("#"):
            section += 1
            if section == 2:
                break
            continue
        if section == 0:
            joints.append(_tgf_joint(src, lineno, s, len(joints) + 1))
        else:
            bones.append(_tgf_bone(src, lineno, s))
    if not joints:
        raise src.eof_error("expected at least one joint line 'index x y z'")
    if section < 2 and src.last_line_unterminated and not src.lines[-1].lstrip().startswith("#"):
        # a data line without newline and no closing '#': the file was cut inside that line
        raise src.eof_error(
            "the file ends inside a line (no newline, no closing '#'): it looks cut; libigl "
            "writes '#' after the joints and after the bones"
        )
    n = len(joints)
    for a, b, lineno in bones:
        for j in (a, b):
            if not 1 <= j <= n:
                raise src.error(lineno, f"bone references joint {j}, expected 1..{n} (1-based)")
        if a == b:
            raise src.error(lineno, f"bone from joint {a} to itself")
    C = np.array(joints, dtype=np.float64).reshape(n, 3)
    BE = np.array([(a - 1, b - 1) for a, b, _ in bones], dtype=np.int64).reshape(-1, 2)
    if not return_point_handles:
        return C, BE
    used = np.zeros(n, dtype=bool)
    used[BE.ravel()] = True
    return C, BE, np.flatnonzero(~used).astype(np.int64)


def _tgf_joint(src: _Source, lineno: int, s: list[str], expected_index: int) -> list[float]:
    if len(s) < 3:
        raise src.error(lineno, f"expected a joint line 'index x y z', got {' '.join(s)!r}")
    idx = _to_int(s[0])
    if idx is None:
        raise src.error(lineno, f"expected an integer joint index, got {s[0]!r}")
    if idx != expected_index:
        raise src.error(
            lineno, f"expected joint index {expected_index} (joints in order), got {idx}"
        )
    xyz = [_to_float(t) for t in s[1:4]]
    if len(s) == 3:
        xyz.append(0.0)
    for t, v in zip(s[1:4], xyz):
        if v is None or not np.isfinite(v):
            raise src.error(lineno, f"expected a finite joint coordinate, got {t!r}")
    return cast("list[float]", xyz)


def _tgf_bone(src: _Source, lineno: int, s: list[str]) -> tuple[int, int, int]:
    vals = [_to_int(t) for t in s[:5]]
    if len(s) < 2 or any(v is None for v in vals):
        raise src.error(
            lineno, f"expected a bone line 'i j' of 1-based joints, got {' '.join(s)!r}"
        )
    flags = vals[2:] + [0] * (5 - len(vals))
    if flags[1] == 1 or flags[2] == 1:
        kind = "pseudo" if flags[1] == 1 else "cage"
        raise src.error(lineno, f"{kind} edges are not supported (only bone edges)")
    return cast(int, vals[0]), cast(int, vals[1]), lineno


def write_tgf(path: str | os.PathLike[str], C: ArrayLike, BE: ArrayLike) -> None:
    """Write a libigl ``.tgf`` skeleton (1-based indices, 2D joints get ``z = 0``).

    Parameters
    ----------
    path : str or pathlib.Path
    C : (n, 2) or (n, 3) float
        Joint positions.
    BE : (k, 2) int
        0-based bone edges, parent -> child.

    Examples
    --------
    >>> import numpy as np
    >>> write_tgf("chain.tgf", np.eye(3), np.array([[0, 1], [1, 2]]))   # doctest: +SKIP
    """
    C = _pad_z(as_points(C, "C"))
    BE = as_index_array(BE, C.shape[0], "BE", cols=2)
    lines = [f"{i + 1} " + " ".join(map(repr, row)) for i, row in enumerate(C.tolist())]
    lines.append("#")
    lines += _int_rows(BE + 1)
    lines.append("#")
    _write_lines(path, lines)
