"""Wavefront ``.obj`` surfaces."""

from __future__ import annotations

import itertools
import os
import re
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
    _pad_z,
    _Source,
    _to_int,
    _write_lines,
)

# Keywords whose lines carry nothing we return (normals, texture coordinates, grouping,
# materials, polylines and points).
_OBJ_IGNORED = frozenset(
    ["vn", "vt", "vp", "g", "s", "o", "usemtl", "mtllib", "usemap", "maplib", "l", "p"]
)
_SLASH_TAIL = re.compile(r"/\S*")


def read_obj(
    path: str | os.PathLike[str], *, return_polygons: bool = False, dim: int | None = None
) -> Any:
    """Read the vertices and faces of a Wavefront ``.obj`` file.

    Faces may be written ``i``, ``i/t``, ``i//n`` or ``i/t/n`` (only the vertex index is
    used), with 1-based or negative (relative) indices. Polygons are split into a triangle fan
    ``(p0, p_i, p_i+1)``. ``vn``, ``vt``, ``g``, ``s``, ``o``, ``usemtl``, ``mtllib``, ``l``,
    ``p`` and ``#`` lines are ignored; any other keyword raises. Vertex lines ``v x y z [w]``
    (or with colours ``v x y z r g b``) keep ``x y z``; ``v x y`` gets ``z = 0``.

    Parameters
    ----------
    path : str or pathlib.Path
    return_polygons : bool
        Also return the faces as read, a list of 0-based int64 index arrays.
    dim : None, 2 or 3
        ``2`` returns ``V[:, :2]`` after checking every z is exactly 0 (``ValueError``
        otherwise), for the 2D meshes stored as OBJ with z = 0.

    Returns
    -------
    V : (n, 3) float64, or (n, 2) with ``dim=2``
    F : (m, 3) int64
        0-based triangles (``(0, 3)`` if the file has no face).
    polygons : list of (s,) int64 arrays, only if ``return_polygons``

    Examples
    --------
    >>> V, F = read_obj("woody.obj", dim=2)               # doctest: +SKIP
    >>> V.shape, F.shape                                  # doctest: +SKIP
    ((2863, 2), (5478, 3))
    """
    if dim not in (None, 2, 3):
        raise ValueError(f"dim must be None, 2 or 3, got {dim!r}")
    src = _Source(path)
    # The fast path gives up (None) on anything unusual; the checked path then reads the file
    # line by line and raises with the line number, or handles the unusual-but-valid case.
    parsed = _obj_parse_fast(src)
    V, idx, sizes = parsed if parsed is not None else _obj_parse_checked(src)
    if not sizes.size and _OBJ_PER_CORNER.search(src.text):
        raise src.eof_error(
            "the file has vertex normals or texture coordinates (vn/vt) but no face: it looks "
            "cut before its 'f' lines"
        )
    F = _fan_triangulate(idx, sizes)
    if dim == 2:
        off = np.flatnonzero(V[:, 2] != 0)
        if off.size:
            i = int(off[0])
            raise src.error(
                _obj_vertex_line(src, i),
                f"dim=2 needs z = 0 for every vertex, vertex {i + 1} has z = {float(V[i, 2])!r}",
            )
        V = np.ascontiguousarray(V[:, :2])
    if not return_polygons:
        return V, F
    polys = np.split(idx, np.cumsum(sizes)[:-1]) if sizes.size else []
    return V, F, polys


_OBJ_KNOWN = _OBJ_IGNORED | {"v", "f"}
_OBJ_PER_CORNER = re.compile(r"^[ \t]*(vn|vt)[ \t]", re.MULTILINE)
_OBJ_KEYWORD = re.compile(r"^[ \t]*(\S+)", re.MULTILINE)
_OBJ_V3 = re.compile(r"^[ \t]*v[ \t]+(\S+)[ \t]+(\S+)[ \t]+(\S+)[ \t\r]*$", re.MULTILINE)
_OBJ_F = re.compile(r"^[ \t]*f[ \t]+(.*)$", re.MULTILINE)


def _obj_parse_fast(src: _Source) -> tuple[NDArray[Any], NDArray[Any], NDArray[Any]] | None:
    """(V, flat face indices, face sizes) with regexes over the whole text, or None."""
    text = _COMMENT.sub("", src.text) if "#" in src.text else src.text
    kws = _OBJ_KEYWORD.findall(text)
    if not set(kws) <= _OBJ_KNOWN:
        return None
    is_v = np.fromiter((k == "v" for k in kws), dtype=bool, count=len(kws))
    is_f = np.fromiter((k == "f" for k in kws), dtype=bool, count=len(kws))
    vm = _OBJ_V3.findall(text)
    fl = _OBJ_F.findall(text)
    if len(vm) != is_v.sum() or len(fl) != is_f.sum():
        return None  # 2 or 4+ coordinates, empty face lines, odd line ends: go the slow way
    V = _bulk(list(itertools.chain.from_iterable(vm)), np.float64)
    if V is None or not np.all(np.isfinite(V)):
        return None
    V = V.reshape(-1, 3)
    tok_lists = list(map(str.split, fl))
    sizes = np.fromiter(map(len, tok_lists), dtype=np.int64, count=len(tok_lists))
    if sizes.size and sizes.min() < 3:
        return None
    ftoks = list(itertools.chain.from_iterable(tok_lists))
    raw = _face_index_values(ftoks)
    if raw is None:
        return None
    fnv = np.cumsum(is_v)[is_f]
    idx, bad = _resolve_face_indices(raw, sizes, fnv, V.shape[0])
    if bad.any():
        return None
    return V, idx, sizes


def _obj_parse_checked(src: _Source) -> tuple[NDArray[Any], NDArray[Any], NDArray[Any]]:
    """Line-by-line OBJ reader that reports the first problem with its line number."""
    vtoks: list[str] = []
    vlines: list[int] = []
    ftoks: list[str] = []
    fsizes: list[int] = []
    fnv: list[int] = []  # number of vertices read before each face (for negative indices)
    flines: list[int] = []
    for lineno, raw in enumerate(src.lines, 1):
        if "#" in raw:
            raw = raw[: raw.index("#")]
        s = raw.split()
        if not s:
            continue
        key = s[0]
        if key == "v":
            c = len(s) - 1
            if c in (3, 4, 6, 7):
                vtoks += s[1:4]
            elif c == 2:
                vtoks += [s[1], s[2], "0"]
            else:
                raise src.error(
                    lineno, f"expected a vertex line 'v x y z [w]', got {raw.strip()!r}"
                )
            vlines.append(lineno)
        elif key == "f":
            if len(s) < 4:
                raise src.error(
                    lineno, f"expected a face with at least 3 vertices, got {raw.strip()!r}"
                )
            ftoks += s[1:]
            fsizes.append(len(s) - 1)
            fnv.append(len(vlines))
            flines.append(lineno)
        elif key not in _OBJ_IGNORED:
            raise src.error(
                lineno, f"expected an OBJ statement (v, f, vn, vt, g, ...), got {key!r}"
            )
    V = _bulk(vtoks, np.float64)
    if V is None:
        k = _first_bad(vtoks, np.float64)
        raise src.error(vlines[k // 3], f"expected a number in a vertex line, got {vtoks[k]!r}")
    V = V.reshape(-1, 3)
    bad = ~np.isfinite(V)
    if bad.any():
        r = int(np.argwhere(bad)[0][0])
        raise src.error(vlines[r], "non-finite vertex coordinate")
    sizes = np.asarray(fsizes, dtype=np.int64)
    values = _face_index_values(ftoks)
    if values is None:
        k = 0
        for f, size in enumerate(fsizes):
            for t in ftoks[k : k + size]:
                v = _to_int(t.split("/", 1)[0])
                if v is None or abs(v) >= 2**62:
                    raise src.error(flines[f], f"expected a vertex index in a face, got {t!r}")
            k += size
    assert values is not None  # the loop above raised on the token that is not an index
    n = V.shape[0]
    idx, bad = _resolve_face_indices(values, sizes, np.asarray(fnv, dtype=np.int64), n)
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        f = int(np.searchsorted(np.cumsum(sizes), k, side="right"))
        raise src.error(
            flines[f],
            f"face vertex {ftoks[k]!r} is out of range: {fnv[f]} vertices read so far, "
            f"{n} in the file (1-based, or negative relative indices)",
        )
    return V, idx, sizes


def _face_index_values(ftoks: list[str]) -> np.ndarray | None:
    """The vertex part of every face token ("7", "7/2", "7//3", "7/2/3") as int64, or None."""
    joined = " ".join(ftoks)
    if "/" in joined:
        joined = _SLASH_TAIL.sub("", joined)
    flat = joined.split()
    if len(flat) != len(ftoks):
        return None  # a token such as "/3" has no vertex part
    return _bulk(flat, np.int64)


def _resolve_face_indices(
    raw: NDArray[Any], sizes: NDArray[Any], fnv: NDArray[Any], n: int
) -> tuple[NDArray[Any], NDArray[Any]]:
    """0-based indices from 1-based / negative (relative) ones, and a mask of invalid ones."""
    nv = np.repeat(np.asarray(fnv, dtype=np.int64), sizes)
    # 1-based: i -> i-1; relative: -1 is the last vertex read so far; 0 is invalid.
    idx = np.where(raw > 0, raw - 1, nv + raw)
    bad = (raw == 0) | (idx < 0) | (idx >= n)
    return idx.astype(np.int64), bad


def _obj_vertex_line(src: _Source, i: int) -> int:
    """Line number of the (i+1)-th vertex line."""
    seen = 0
    for lineno, raw in enumerate(src.lines, 1):
        s = raw.split()
        if s and s[0] == "v":
            if seen == i:
                return lineno
            seen += 1
    return len(src.lines)


def _fan_triangulate(idx: np.ndarray, sizes: np.ndarray) -> np.ndarray:
    if sizes.size == 0:
        return np.zeros((0, 3), dtype=np.int64)
    if np.all(sizes == 3):
        return idx.reshape(-1, 3).copy()
    starts = np.cumsum(sizes) - sizes
    ntri = sizes - 2
    face = np.repeat(np.arange(sizes.size), ntri)
    # corner i of the fan in its polygon: 1 .. size-2
    i = np.arange(int(ntri.sum())) - np.repeat(np.cumsum(ntri) - ntri, ntri) + 1
    s = starts[face]
    return np.stack([idx[s], idx[s + i], idx[s + i + 1]], axis=1)


def write_obj(path: str | os.PathLike[str], V: ArrayLike, F: ArrayLike) -> None:
    """Write a Wavefront ``.obj`` surface (``v x y z`` and 1-based ``f`` lines).

    Parameters
    ----------
    path : str or pathlib.Path
    V : (n, 2) or (n, 3) float
        Vertex positions; 2D vertices are written with ``z = 0``.
    F : (m, s) int, s >= 3
        0-based faces (triangles, quads, ...); may be empty.

    Examples
    --------
    >>> import numpy as np
    >>> V = np.array([[0., 0], [1, 0], [0, 1]])
    >>> write_obj("tri.obj", V, np.array([[0, 1, 2]]))            # doctest: +SKIP
    """
    V = _pad_z(as_points(V, "V", min_rows=0))
    F = np.asarray(F)
    if F.size == 0:
        F = np.zeros((0, 3), dtype=np.int64)
    elif F.ndim != 2 or F.shape[1] < 3:
        raise ValueError(f"F must have shape (m, s) with s >= 3, got {F.shape}")
    F = as_index_array(F, V.shape[0], "F")
    _write_lines(path, _float_rows(V, "v ") + _int_rows(F + 1, "f "))
