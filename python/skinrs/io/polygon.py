"""poly2tri ``.dat`` polygon outlines: an outer ring and holes."""

from __future__ import annotations

import os
from typing import cast

import numpy as np
from numpy.typing import NDArray

from ._text import _Source, _to_float


def read_polygon_dat(
    path: str | os.PathLike[str],
) -> tuple[NDArray[np.float64], list[NDArray[np.float64]]]:
    """Read a poly2tri ``.dat`` polygon: an outer ring, then rings after each ``HOLE`` line.

    Each point is a line ``x y``; the last point of a ring is not repeated. Blank lines and
    CRLF line ends are fine; a last line without a newline is a cut file and raises. Every ring needs at least 3 points.

    Parameters
    ----------
    path : str or pathlib.Path

    Returns
    -------
    outer : (k, 2) float64
        The outer ring, in file order.
    holes : list of (j, 2) float64
        The hole rings, in file order.

    Examples
    --------
    >>> outer, holes = read_polygon_dat("dude.dat")       # doctest: +SKIP
    >>> outer.shape, [h.shape for h in holes]             # doctest: +SKIP
    ((94, 2), [(4, 2), (6, 2)])
    """
    src = _Source(path)
    rings: list[list[list[float]]] = [[]]
    starts = [1]
    for lineno, raw in enumerate(src.lines, 1):
        s = raw.split()
        if not s or s[0].startswith("#"):
            continue
        if len(s) == 1 and s[0].upper() == "HOLE":
            rings.append([])
            starts.append(lineno)
            continue
        xy = [_to_float(t) for t in s]
        if len(s) != 2 or any(v is None or not np.isfinite(v) for v in xy):
            raise src.error(lineno, f"expected a point 'x y' or 'HOLE', got {raw.strip()!r}")
        rings[-1].append(cast("list[float]", xy))
    if src.last_line_unterminated:
        raise src.eof_error("the last line has no newline: the file looks cut inside it")
    for ring, lineno in zip(rings, starts):
        if len(ring) < 3:
            what = "outer ring" if lineno == 1 else "hole"
            raise src.error(lineno, f"{what} starting here has {len(ring)} points, expected >= 3")
    arrays = [np.array(r, dtype=np.float64) for r in rings]
    return arrays[0], arrays[1:]
