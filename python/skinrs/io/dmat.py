"""libigl ``.dmat`` dense matrices, ASCII and binary."""

from __future__ import annotations

import os
from typing import cast

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ._text import _bulk, _decode, _first_bad, _line_of_token, _to_int


def read_dmat(path: str | os.PathLike[str]) -> NDArray[np.float64]:
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
    return cast(int, vals[0]), cast(int, vals[1])


def _dmat_binary(name: str, payload: bytes, rows: int, cols: int) -> np.ndarray:
    need = 8 * rows * cols
    if len(payload) != need:
        what = "truncated" if len(payload) < need else "has trailing bytes"
        raise ValueError(
            f"{name}: line 3 (binary data): {what}: expected {need} bytes for "
            f"{rows}x{cols} float64 values, found {len(payload)}"
        )
    flat = np.frombuffer(payload, dtype="<f8")
    bad = np.flatnonzero(~np.isfinite(flat))
    if bad.size:
        k = int(bad[0])
        raise ValueError(
            f"{name}: line 3 (binary data): value {k} (row {k % rows}, column {k // rows}) is "
            f"{flat[k]!r}: NaN and infinite entries are not accepted"
        )
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
    bad = np.flatnonzero(~np.isfinite(flat))
    if bad.size:
        k = int(bad[0])
        lineno = _line_of_token(text.splitlines(), k) + 1
        raise ValueError(
            f"{name}: line {lineno}: {toks[k]!r} (row {k % rows}, column {k // rows}): NaN and "
            "infinite entries are not accepted"
        )
    return np.ascontiguousarray(flat.reshape(cols, rows).T)


def write_dmat(path: str | os.PathLike[str], W: ArrayLike, *, binary: bool = False) -> None:
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
