"""MEDIT ASCII ``.mesh`` tetrahedral meshes."""

from __future__ import annotations

import os
from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._checks import as_index_array, as_points
from ._text import (
    _COMMENT,
    _bulk,
    _first_bad,
    _float_rows,
    _int_rows,
    _kind,
    _line_of_token,
    _Source,
    _to_int,
    _write_lines,
)

# Sections we understand but do not return: tokens per entry (given the dimension d).
_MESH_SKIPPED: dict[str, Callable[[int], int]] = {
    "edges": lambda d: 3,
    "corners": lambda d: 1,
    "ridges": lambda d: 1,
    "requiredvertices": lambda d: 1,
    "requirededges": lambda d: 1,
    "requiredtriangles": lambda d: 1,
    "normals": lambda d: d,
    "normalatvertices": lambda d: 2,
    "tangents": lambda d: d,
    "tangentatvertices": lambda d: 2,
}
# Element sections we cannot represent as (V, T, F): non-empty ones raise.
_MESH_UNSUPPORTED = {"quadrilaterals": 5, "hexahedra": 9, "prisms": 7, "pyramids": 6}


class _MeshTokens:
    """Whitespace tokens of a MEDIT file (``#`` comments removed), each traceable to its line."""

    def __init__(self, src: _Source):
        self.src = src
        self.text = _COMMENT.sub("", src.text)
        self.toks = self.text.split()
        self.pos = 0

    def line_of(self, k: int) -> int:
        # Only called to report an error, so a linear scan is fine.
        return _line_of_token(self.text.splitlines(), k) if self.toks else 1

    def error_at(self, k: int, what: str) -> ValueError:
        if k >= len(self.toks):
            return self.src.eof_error(what)
        return self.src.error(self.line_of(k), what)

    def next(self) -> str | None:
        if self.pos >= len(self.toks):
            return None
        self.pos += 1
        return self.toks[self.pos - 1]

    def count(self, keyword: str) -> int:
        k = self.pos
        t = self.next()
        v = None if t is None else _to_int(t)
        if v is None or v < 0:
            raise self.error_at(k, f"expected the number of entries after {keyword!r}, got {t!r}")
        return v

    def block(self, n: int, width: int, dtype: type, keyword: str) -> NDArray[Any]:
        """The next ``n`` entries of ``width`` numbers each, as an (n, width) array."""
        start, stop = self.pos, self.pos + n * width
        chunk = self.toks[start:stop]
        A = _bulk(chunk, dtype)
        if A is None or len(chunk) < n * width:
            k = start + (_first_bad(chunk, dtype) if A is None else len(chunk))
            got = "end of file" if k >= len(self.toks) else repr(self.toks[k])
            entry = (k - start) // width + 1
            raise self.error_at(
                k,
                f"expected {_kind(dtype)} in entry {entry} of {n} of section {keyword!r} "
                f"({width} values per entry), got {got}",
            )
        self.pos = stop
        return A.reshape(n, width)

    def entry_error(self, start: int, width: int, row: int, what: str) -> ValueError:
        return self.error_at(start + row * width, what)


def read_mesh(
    path: str | os.PathLike[str],
) -> tuple[NDArray[np.float64], NDArray[np.int64], NDArray[np.int64]]:
    """Read a MEDIT ASCII ``.mesh`` tet mesh (as written by libigl, TetGen, TetWild).

    Reads ``Vertices`` (dropping the reference column), ``Tetrahedra`` and ``Triangles``
    (1-based, reference column dropped). Accepts keywords and counts on the same or the next
    line, ``#`` comments, ``Edges``/``Corners``/``Ridges``/... sections (skipped), a trailing
    ``Edges 0``, and a missing ``End`` or a missing final newline (not both: that is a file cut
    inside its last line). Non-empty quad/hex/prism
    sections raise, as they cannot be returned.

    Parameters
    ----------
    path : str or pathlib.Path

    Returns
    -------
    V : (n, 3) float64 (``(n, 2)`` for a ``Dimension 2`` file)
    T : (k, 4) int64
        0-based tetrahedra; ``(0, 4)`` if the file has none.
    F : (j, 3) int64
        0-based triangles; ``(0, 3)`` if the file has none.

    Examples
    --------
    >>> V, T, F = read_mesh("hand.mesh")                  # doctest: +SKIP
    >>> V.shape, T.shape, F.shape                         # doctest: +SKIP
    ((7234, 3), (29998, 4), (9556, 3))
    """
    tk = _MeshTokens(_Source(path))
    first = tk.next()
    if first is None or first.lower() != "meshversionformatted":
        raise tk.error_at(0, f"expected 'MeshVersionFormatted' (MEDIT ASCII .mesh), got {first!r}")
    version = tk.count("MeshVersionFormatted")
    if version not in (1, 2, 3, 4):
        raise tk.error_at(tk.pos - 1, f"unknown MeshVersionFormatted {version}, expected 1..4")
    dim = None
    seen: set[str] = set()
    V = T = F = None
    ended = False
    while True:
        k = tk.pos
        word = tk.next()
        if word is None:
            break
        key = word.lower()
        if key == "end":
            ended = True
            break
        if key in seen:
            raise tk.error_at(k, f"section {word!r} appears twice")
        seen.add(key)
        if key == "dimension":
            if V is not None:
                raise tk.error_at(k, "'Dimension' must come before 'Vertices'")
            dim = tk.count(word)
            if dim not in (2, 3):
                raise tk.error_at(tk.pos - 1, f"expected Dimension 2 or 3, got {dim}")
        elif key == "vertices":
            dim = dim or 3
            n = tk.count(word)
            start = tk.pos
            V = tk.block(n, dim + 1, np.float64, word)[:, :dim]
            _check_finite(tk, V, start, dim + 1, word)
        elif key in ("tetrahedra", "triangles"):
            width = 4 if key == "tetrahedra" else 3
            n = tk.count(word)
            start = tk.pos
            E = tk.block(n, width + 1, np.int64, word)[:, :width]
            if V is None:
                raise tk.error_at(k, f"section {word!r} comes before 'Vertices'")
            E = _check_indices(tk, E, V.shape[0], start, width + 1, word)
            if key == "tetrahedra":
                T = E
            else:
                F = E
        elif key in _MESH_SKIPPED:
            n = tk.count(word)
            tk.block(n, _MESH_SKIPPED[key](dim or 3), np.float64, word)
        elif key in _MESH_UNSUPPORTED:
            n = tk.count(word)
            if n:
                raise tk.error_at(k, f"{n} {word} are not supported (only tets and triangles)")
        else:
            raise tk.error_at(k, f"expected a MEDIT section keyword, got {word!r}")
    if not ended and tk.src.last_line_unterminated:
        raise tk.src.eof_error(
            "the file ends inside a line (no newline, no 'End'): it looks cut in its last number"
        )
    if V is None:
        raise tk.src.eof_error("no 'Vertices' section")
    if T is None:
        T = np.zeros((0, 4), dtype=np.int64)
    if F is None:
        F = np.zeros((0, 3), dtype=np.int64)
    return np.ascontiguousarray(V), T, F


def _check_finite(tk: _MeshTokens, V: np.ndarray, start: int, width: int, word: str) -> None:
    bad = ~np.isfinite(V)
    if bad.any():
        r = int(np.argwhere(bad)[0][0])
        raise tk.entry_error(start, width, r, f"non-finite coordinate in {word} entry {r + 1}")


def _check_indices(
    tk: _MeshTokens, E: NDArray[Any], n: int, start: int, width: int, word: str
) -> NDArray[Any]:
    bad = (E < 1) | (E > n)
    if bad.any():
        r, c = (int(x) for x in np.argwhere(bad)[0])
        raise tk.entry_error(
            start,
            width,
            r,
            f"{word} entry {r + 1} references vertex {int(E[r, c])}, expected 1..{n} (1-based)",
        )
    return np.ascontiguousarray(E - 1)


def write_mesh(
    path: str | os.PathLike[str], V: ArrayLike, T: ArrayLike, F: ArrayLike | None = None
) -> None:
    """Write a MEDIT ASCII ``.mesh`` file (1-based indices, reference 0 everywhere).

    Parameters
    ----------
    path : str or pathlib.Path
    V : (n, 3) float
        Vertex positions (``(n, 2)`` writes ``Dimension 2``).
    T : (k, 4) int
        0-based tetrahedra (may be empty).
    F : (j, 3) int, optional
        0-based triangles, typically the boundary of ``T``.

    Examples
    --------
    >>> import numpy as np
    >>> V = np.array([[0., 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    >>> write_mesh("tet.mesh", V, np.array([[0, 1, 2, 3]]))       # doctest: +SKIP
    """
    V = as_points(V, "V", min_rows=0)
    n = V.shape[0]
    T = as_index_array(T, n, "T", cols=4)
    F = as_index_array(np.zeros((0, 3)) if F is None else F, n, "F", cols=3)
    lines = ["MeshVersionFormatted 1", f"Dimension {V.shape[1]}", "Vertices", str(n)]
    lines += [s + " 0" for s in _float_rows(V)]
    lines += ["Triangles", str(F.shape[0])] + _int_rows(F + 1, suffix=" 0")
    lines += ["Tetrahedra", str(T.shape[0])] + _int_rows(T + 1, suffix=" 0")
    lines.append("End")
    _write_lines(path, lines)
