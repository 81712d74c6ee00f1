"""Readers and writers for the file formats skinning data comes in.

Pure Python + numpy. Every reader takes a ``str`` or ``pathlib.Path`` and returns numpy arrays
with libigl names and conventions: float64 coordinates, int64 **0-based** indices, 2D arrays
even when there is a single column or no row at all.

Formats: libigl ``.tgf`` skeletons, libigl ``.dmat`` matrices (ASCII and binary), MEDIT ``.mesh``
tet meshes, Wavefront ``.obj`` surfaces, poly2tri ``.dat`` outlines and RigNet ``*_rig.txt`` rigs.

A malformed file raises ``ValueError("<path>: line <n>: <what was expected>")``; a missing file
raises the usual ``FileNotFoundError``. Nothing is silently dropped: an index out of range, a
count that does not match the data, or an unknown keyword is an error.

>>> import skinrs.io as sio                                   # doctest: +SKIP
>>> V, T, F = sio.read_mesh("hand.mesh")                       # doctest: +SKIP
>>> C, BE = sio.read_tgf("hand.tgf")                           # doctest: +SKIP
>>> V.shape, T.shape, F.shape, C.shape, BE.shape               # doctest: +SKIP
((7234, 3), (29998, 4), (9556, 3), (21, 3), (20, 2))
"""

from __future__ import annotations

import functools
import itertools
import os
import re

import numpy as np

from ._checks import as_index_array, as_points

__all__ = [
    "read_dmat",
    "read_mesh",
    "read_obj",
    "read_polygon_dat",
    "read_rignet_rig",
    "read_tgf",
    "write_dmat",
    "write_mesh",
    "write_obj",
    "write_tgf",
]


# --------------------------------------------------------------------------------------------
# shared helpers


class _Source:
    """A text file, able to build ``ValueError``s that name file and line."""

    def __init__(self, path):
        self.name = os.fspath(path)
        with open(self.name, "rb") as fh:
            data = fh.read()
        self.text = _decode(data)

    @functools.cached_property
    def lines(self) -> list[str]:
        return self.text.splitlines()

    def error(self, lineno: int, what: str) -> ValueError:
        return ValueError(f"{self.name}: line {lineno}: {what}")

    def eof_error(self, what: str) -> ValueError:
        return ValueError(f"{self.name}: line {len(self.lines)} (end of file): {what}")


_COMMENT = re.compile(r"#[^\r\n]*")


def _decode(data: bytes) -> str:
    # The formats are ASCII; names (RigNet joints) may be UTF-8. latin-1 never fails, so a
    # stray byte in a comment never stops a read.
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError:
        return data.decode("latin-1")


def _to_float(tok: str) -> float | None:
    try:
        return float(tok)
    except ValueError:
        return None


def _to_int(tok: str) -> int | None:
    try:
        return int(tok)
    except ValueError:
        return None


def _bulk(tokens, dtype):
    """Convert a list of strings to an array, or return None when any token is not a number."""
    try:
        return np.array(tokens, dtype=dtype)
    except (ValueError, OverflowError):
        return None


def _first_bad(tokens, dtype) -> int:
    """Position of the first token that is not a number (or an integer outside int64)."""
    for k, t in enumerate(tokens):
        if dtype == np.int64:
            v = _to_int(t)
            if v is None or not -(2**63) <= v < 2**63:
                return k
        elif _to_float(t) is None:
            return k
    return len(tokens)


def _kind(dtype) -> str:
    return "an integer" if dtype == np.int64 else "a number"


def _write_lines(path, lines) -> None:
    with open(os.fspath(path), "w", encoding="utf-8", newline="\n") as fh:
        fh.write("\n".join(lines))
        fh.write("\n")


def _float_rows(A: np.ndarray, prefix: str = "") -> list[str]:
    """Rows of ``A`` as text, each value written as the shortest string that reads back exactly."""
    return [prefix + " ".join(map(repr, row)) for row in A.tolist()]


def _int_rows(A: np.ndarray, prefix: str = "", suffix: str = "") -> list[str]:
    return [prefix + " ".join(map(str, row)) + suffix for row in A.tolist()]


# --------------------------------------------------------------------------------------------
# TGF (libigl skeleton graph)


def read_tgf(path, return_point_handles: bool = False):
    """Read a libigl ``.tgf`` skeleton: joint positions and directed bone edges.

    The file holds joint lines ``index x y z [extra columns]`` (index 1-based, in order), a
    ``#`` line, bone lines ``i j [is_bone is_pseudo is_cage]`` (1-based, parent -> child) and
    a closing ``#``; anything after it is ignored, as libigl does. Extra joint columns (often
    uninitialised garbage such as ``6.95e-310``) are ignored. A joint line with only ``x y``
    gets ``z = 0``. Blank lines, a missing final newline and a missing bone section are fine.
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
    return xyz


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
    return vals[0], vals[1], lineno


def write_tgf(path, C, BE) -> None:
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


def _pad_z(V: np.ndarray) -> np.ndarray:
    if V.shape[1] == 3:
        return V
    return np.hstack([V, np.zeros((V.shape[0], 1))])


# --------------------------------------------------------------------------------------------
# DMAT (libigl dense matrix)


def read_dmat(path) -> np.ndarray:
    """Read a libigl ``.dmat`` matrix, ASCII or binary.

    ASCII: a line ``cols rows`` then ``cols*rows`` numbers in column-major order.
    Binary: a line ``0 0``, a line ``cols rows``, then ``cols*rows`` little-endian float64 in
    column-major order. A ``0 0`` header with nothing after it is an empty ASCII matrix.

    Parameters
    ----------
    path : str or pathlib.Path

    Returns
    -------
    W : (rows, cols) float64
        Always 2D: a single column stays ``(rows, 1)``.

    Examples
    --------
    >>> W = read_dmat("armadillo-weights.dmat")           # doctest: +SKIP
    >>> W.shape                                           # doctest: +SKIP
    (43243, 5)
    """
    name = os.fspath(path)
    with open(name, "rb") as fh:
        data = fh.read()
    first, rest = _split_line(data)
    cols, rows = _dmat_header(name, 1, first)
    if cols == 0 and rows == 0 and rest.strip():
        second, payload = _split_line(rest)
        cols, rows = _dmat_header(name, 2, second)
        return _dmat_binary(name, payload, rows, cols)
    return _dmat_ascii(name, _decode(rest), rows, cols)


def _split_line(data: bytes) -> tuple[bytes, bytes]:
    i = data.find(b"\n")
    return (data, b"") if i < 0 else (data[:i], data[i + 1 :])


def _dmat_header(name: str, lineno: int, line: bytes) -> tuple[int, int]:
    s = _decode(line).split()
    vals = [_to_int(t) for t in s]
    if len(s) != 2 or any(v is None or v < 0 for v in vals):
        raise ValueError(
            f"{name}: line {lineno}: expected a header 'cols rows' of two non-negative "
            f"integers, got {_decode(line)[:60]!r}"
        )
    return vals[0], vals[1]


def _dmat_binary(name: str, payload: bytes, rows: int, cols: int) -> np.ndarray:
    need = 8 * rows * cols
    if len(payload) != need:
        what = "truncated" if len(payload) < need else "has trailing bytes"
        raise ValueError(
            f"{name}: line 3 (binary data): {what}: expected {need} bytes for "
            f"{rows}x{cols} float64 values, found {len(payload)}"
        )
    flat = np.frombuffer(payload, dtype="<f8")
    return np.ascontiguousarray(flat.reshape(cols, rows).T, dtype=np.float64)


def _dmat_ascii(name: str, text: str, rows: int, cols: int) -> np.ndarray:
    toks = text.split()
    need = rows * cols
    lines = None
    if len(toks) != need:
        lines = text.splitlines()
        if len(toks) < need:
            raise ValueError(
                f"{name}: line {len(lines) + 1} (end of file): truncated: expected {need} "
                f"values for {rows}x{cols}, found {len(toks)}"
            )
        lineno = _line_of_token(lines, need) + 1
        raise ValueError(
            f"{name}: line {lineno}: unexpected value {toks[need]!r}: the header announces "
            f"{rows}x{cols} = {need} values, the file holds {len(toks)}"
        )
    flat = _bulk(toks, np.float64)
    if flat is None:
        k = _first_bad(toks, np.float64)
        lineno = _line_of_token(text.splitlines(), k) + 1
        raise ValueError(f"{name}: line {lineno}: expected a number, got {toks[k]!r}")
    return np.ascontiguousarray(flat.reshape(cols, rows).T)


def _line_of_token(lines: list[str], k: int) -> int:
    """1-based line (counting the header as line 1) of the k-th whitespace token of ``lines``."""
    seen = 0
    for i, line in enumerate(lines):
        seen += len(line.split())
        if seen > k:
            return i + 1
    return len(lines)


def write_dmat(path, W, binary: bool = False) -> None:
    """Write a matrix as a libigl ``.dmat`` file (column-major, values read back exactly).

    Parameters
    ----------
    path : str or pathlib.Path
    W : (rows, cols) or (rows,) float
        A 1D array is written as one column.
    binary : bool
        Binary form (``0 0`` line, ``cols rows`` line, little-endian float64) instead of ASCII.

    Examples
    --------
    >>> import numpy as np
    >>> write_dmat("w.dmat", np.eye(3), binary=True)              # doctest: +SKIP
    >>> read_dmat("w.dmat")                                       # doctest: +SKIP
    array([[1., 0., 0.], [0., 1., 0.], [0., 0., 1.]])
    """
    A = np.asarray(W)
    if A.dtype == object or not (np.issubdtype(A.dtype, np.number) or A.dtype == bool):
        raise ValueError(f"W must hold numbers, got dtype {A.dtype}")
    if np.iscomplexobj(A):
        raise ValueError(f"W must be real, got dtype {A.dtype}")
    if A.ndim == 1:
        A = A[:, None]
    if A.ndim != 2:
        raise ValueError(f"W must be a 1D or 2D array, got shape {A.shape}")
    A = A.astype(np.float64)
    rows, cols = A.shape
    flat = A.ravel(order="F")
    with open(os.fspath(path), "wb") as fh:
        if binary:
            fh.write(f"0 0\n{cols} {rows}\n".encode())
            fh.write(flat.astype("<f8").tobytes())
        else:
            body = "".join(v + "\n" for v in map(repr, flat.tolist()))
            fh.write(f"{cols} {rows}\n{body}".encode())


# --------------------------------------------------------------------------------------------
# MEDIT .mesh


# Sections we understand but do not return: tokens per entry (given the dimension d).
_MESH_SKIPPED = {
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

    def block(self, n: int, width: int, dtype, keyword: str) -> np.ndarray:
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


def read_mesh(path):
    """Read a MEDIT ASCII ``.mesh`` tet mesh (as written by libigl, TetGen, TetWild).

    Reads ``Vertices`` (dropping the reference column), ``Tetrahedra`` and ``Triangles``
    (1-based, reference column dropped). Accepts keywords and counts on the same or the next
    line, ``#`` comments, ``Edges``/``Corners``/``Ridges``/... sections (skipped), a trailing
    ``Edges 0``, a missing ``End`` and a missing final newline. Non-empty quad/hex/prism
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
    while True:
        k = tk.pos
        word = tk.next()
        if word is None:
            break
        key = word.lower()
        if key == "end":
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


def _check_indices(tk, E: np.ndarray, n: int, start: int, width: int, word: str) -> np.ndarray:
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


def write_mesh(path, V, T, F=None) -> None:
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


# --------------------------------------------------------------------------------------------
# Wavefront OBJ

# Keywords whose lines carry nothing we return (normals, texture coordinates, grouping,
# materials, polylines and points).
_OBJ_IGNORED = frozenset(
    ["vn", "vt", "vp", "g", "s", "o", "usemtl", "mtllib", "usemap", "maplib", "l", "p"]
)
_SLASH_TAIL = re.compile(r"/\S*")


def read_obj(path, return_polygons: bool = False, dim: int | None = None):
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
_OBJ_KEYWORD = re.compile(r"^[ \t]*(\S+)", re.MULTILINE)
_OBJ_V3 = re.compile(r"^[ \t]*v[ \t]+(\S+)[ \t]+(\S+)[ \t]+(\S+)[ \t\r]*$", re.MULTILINE)
_OBJ_F = re.compile(r"^[ \t]*f[ \t]+(.*)$", re.MULTILINE)


def _obj_parse_fast(src: _Source):
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


def _obj_parse_checked(src: _Source):
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
    raw = _face_index_values(ftoks)
    if raw is None:
        k = 0
        for f, size in enumerate(fsizes):
            for t in ftoks[k : k + size]:
                v = _to_int(t.split("/", 1)[0])
                if v is None or abs(v) >= 2**62:
                    raise src.error(flines[f], f"expected a vertex index in a face, got {t!r}")
            k += size
    n = V.shape[0]
    idx, bad = _resolve_face_indices(raw, sizes, np.asarray(fnv, dtype=np.int64), n)
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


def _resolve_face_indices(raw, sizes, fnv, n: int):
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


def write_obj(path, V, F) -> None:
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


# --------------------------------------------------------------------------------------------
# poly2tri .dat outlines


def read_polygon_dat(path):
    """Read a poly2tri ``.dat`` polygon: an outer ring, then rings after each ``HOLE`` line.

    Each point is a line ``x y``; the last point of a ring is not repeated. Blank lines and
    CRLF line ends are fine. Every ring needs at least 3 points.

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
        rings[-1].append(xy)
    for ring, lineno in zip(rings, starts):
        if len(ring) < 3:
            what = "outer ring" if lineno == 1 else "hole"
            raise src.error(lineno, f"{what} starting here has {len(ring)} points, expected >= 3")
    arrays = [np.array(r, dtype=np.float64) for r in rings]
    return arrays[0], arrays[1:]


# --------------------------------------------------------------------------------------------
# RigNet rig .txt


def read_rignet_rig(path) -> dict:
    """Read a RigNet rig (``*_rig.txt``): joints, hierarchy, root and per-vertex skin weights.

    Lines: ``joints <name> x y z``, ``root <name>``, ``hier <parent> <child>`` and
    ``skin <vertex> <joint> <w> [<joint> <w> ...]`` (vertex 0-based, one line per vertex).

    Parameters
    ----------
    path : str or pathlib.Path

    Returns
    -------
    rig : dict with
        ``names`` : list of str, joint names in file order;
        ``C`` : (n, 3) float64 joint positions;
        ``BE`` : (k, 2) int64 0-based ``(parent, child)`` joint pairs, in ``hier`` order;
        ``root`` : int, index of the root joint;
        ``W`` : (nverts, n) float64 dense skin weights, one column per **joint** (ordered as
        ``names``), ``nverts`` = the number of ``skin`` lines (ids ``0..nverts-1``, each once).

    Examples
    --------
    >>> rig = read_rignet_rig("smith_ori_rig.txt")        # doctest: +SKIP
    >>> rig["C"].shape, rig["BE"].shape, rig["W"].shape   # doctest: +SKIP
    ((25, 3), (24, 2), (518, 25))
    """
    src = _Source(path)
    names: list[str] = []
    index: dict[str, int] = {}
    C: list[list[float]] = []
    roots: list[tuple[str, int]] = []
    hier: list[tuple[str, str, int]] = []
    skins: list[tuple[int, list[str], int]] = []
    for lineno, raw in enumerate(src.lines, 1):
        s = raw.split()
        if not s or s[0].startswith("#"):
            continue
        key = s[0]
        if key == "joints":
            xyz = [_to_float(t) for t in s[2:]]
            if len(s) != 5 or any(v is None or not np.isfinite(v) for v in xyz):
                raise src.error(lineno, f"expected 'joints <name> x y z', got {raw.strip()!r}")
            if s[1] in index:
                raise src.error(lineno, f"joint {s[1]!r} is defined twice")
            index[s[1]] = len(names)
            names.append(s[1])
            C.append(xyz)
        elif key == "root":
            if len(s) != 2:
                raise src.error(lineno, f"expected 'root <name>', got {raw.strip()!r}")
            roots.append((s[1], lineno))
        elif key == "hier":
            if len(s) != 3:
                raise src.error(lineno, f"expected 'hier <parent> <child>', got {raw.strip()!r}")
            hier.append((s[1], s[2], lineno))
        elif key == "skin":
            vid = _to_int(s[1]) if len(s) > 1 else None
            if vid is None or vid < 0 or len(s) < 4 or len(s) % 2 != 0:
                raise src.error(
                    lineno,
                    f"expected 'skin <vertex> <joint> <w> [<joint> <w> ...]', got {raw.strip()!r}",
                )
            skins.append((vid, s[2:], lineno))
        else:
            raise src.error(lineno, f"expected joints/root/hier/skin, got {key!r}")
    if not names:
        raise src.eof_error("no 'joints' line")

    def joint(name: str, lineno: int) -> int:
        if name not in index:
            raise src.error(lineno, f"unknown joint {name!r}")
        return index[name]

    if len(roots) != 1:
        where = roots[1][1] if len(roots) > 1 else len(src.lines)
        raise src.error(where, f"expected exactly one 'root' line, found {len(roots)}")
    root = joint(*roots[0])
    BE = np.array([(joint(p, ln), joint(c, ln)) for p, c, ln in hier], dtype=np.int64).reshape(
        -1, 2
    )
    parent_line: dict[int, int] = {}
    for (_, _, ln), (p, c) in zip(hier, BE.tolist()):
        if p == c:
            raise src.error(ln, f"'hier' makes {names[c]!r} its own parent")
        if c == root or c in parent_line:
            why = "the root" if c == root else f"already a child (line {parent_line[c]})"
            raise src.error(ln, f"'hier' makes {names[c]!r} a child, but it is {why}")
        parent_line[c] = ln
    W = _rignet_skin(src, skins, joint, len(names))
    return {"names": names, "C": np.array(C, dtype=np.float64), "BE": BE, "root": root, "W": W}


def _rignet_skin(src: _Source, skins, joint, n: int) -> np.ndarray:
    nverts = len(skins)  # one line per vertex, ids 0..nverts-1 in any order
    W = np.zeros((nverts, n), dtype=np.float64)
    seen = np.zeros(nverts, dtype=bool)
    for vid, pairs, lineno in skins:
        if vid >= nverts:
            raise src.error(
                lineno,
                f"vertex id {vid} is out of range: {nverts} 'skin' lines (one per vertex) "
                f"need ids 0..{nverts - 1}",
            )
        if seen[vid]:
            raise src.error(lineno, f"vertex {vid} has a second 'skin' line")
        seen[vid] = True
        used: set[int] = set()
        for name, wtok in zip(pairs[::2], pairs[1::2]):
            j = joint(name, lineno)
            w = _to_float(wtok)
            if w is None or not np.isfinite(w):
                raise src.error(lineno, f"expected a weight after joint {name!r}, got {wtok!r}")
            if j in used:
                raise src.error(lineno, f"joint {name!r} appears twice for vertex {vid}")
            used.add(j)
            W[vid, j] = w
    return W
