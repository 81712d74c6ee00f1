"""Argument checks shared by every public function.

Each helper returns a clean, contiguous array of the dtype the Rust core expects, or raises a
``ValueError`` that names the argument and says what is wrong. Nothing is silently clamped,
dropped or reinterpreted.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable, Iterable, Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

#: ``callback(stage, iteration, value)`` of a long job; returning ``False`` stops it.
Callback = Callable[[str, int, float], "bool | None"]


def as_points(
    X: ArrayLike, name: str = "V", dims: Iterable[int] = (2, 3), min_rows: int = 1
) -> NDArray[np.float64]:
    """Float64 C-contiguous ``(n, d)`` array with ``d`` in ``dims`` and only finite entries."""
    try:
        A = np.asarray(X)
    except (TypeError, ValueError) as e:  # ragged lists and the like
        raise ValueError(f"{name} must be an (n, d) array of numbers: {e}") from None
    if A.dtype == object or not (np.issubdtype(A.dtype, np.number) or A.dtype == bool):
        raise ValueError(f"{name} must hold numbers, got dtype {A.dtype}")
    if np.iscomplexobj(A):
        raise ValueError(f"{name} must be real, got dtype {A.dtype}")
    if A.ndim != 2 or A.shape[1] not in dims:
        raise ValueError(f"{name} must have shape (n, d) with d in {tuple(dims)}, got {A.shape}")
    if A.shape[0] < min_rows:
        raise ValueError(f"{name} must have at least {min_rows} rows, got {A.shape[0]}")
    A = np.ascontiguousarray(A, dtype=np.float64)
    bad = ~np.isfinite(A)
    if bad.any():
        r = int(np.argwhere(bad)[0][0])
        raise ValueError(f"{name} has a NaN or infinite entry (row {r})")
    return A


def as_index_array(
    X: ArrayLike,
    n: int,
    name: str,
    cols: int | Sequence[int] | None = None,
    ndim: int = 2,
    allow_empty: bool = True,
) -> NDArray[np.int64]:
    """Int64 C-contiguous index array with every entry in ``0..n``.

    ``cols`` (an int or tuple of ints) restricts the number of columns of a 2D array.
    Floating arrays are accepted only when every entry is integral (like ``igl`` outputs).
    """
    A = np.asarray(X)
    if A.size == 0:
        if not allow_empty:
            raise ValueError(f"{name} must not be empty")
        shape = (0,) if ndim == 1 else (0, cols if isinstance(cols, int) else (cols or (0,))[0])
        return np.zeros(shape, dtype=np.int64)
    if A.dtype == bool or not np.issubdtype(A.dtype, np.number) or np.iscomplexobj(A):
        raise ValueError(f"{name} must hold integer indices, got dtype {A.dtype}")
    if not np.issubdtype(A.dtype, np.integer) and (
        not np.all(np.isfinite(A)) or np.any(A != np.round(A))
    ):
        raise ValueError(f"{name} must hold integer indices, got non-integral values")
    if A.ndim != ndim:
        raise ValueError(f"{name} must be {ndim}-dimensional, got shape {A.shape}")
    if ndim == 2 and cols is not None:
        allowed = (cols,) if isinstance(cols, int) else tuple(cols)
        if A.shape[1] not in allowed:
            raise ValueError(
                f"{name} must have {' or '.join(map(str, allowed))} columns, got {A.shape}"
            )
    A = np.ascontiguousarray(A, dtype=np.int64)
    lo, hi = int(A.min()), int(A.max())
    if lo < 0 or hi >= n:
        bad = lo if lo < 0 else hi
        raise ValueError(f"{name} holds index {bad}, outside the valid range 0..{n - 1}")
    return A


def as_elements(
    F: ArrayLike, V: NDArray[np.float64], name: str = "F", cols: int | Sequence[int] = (3, 4)
) -> NDArray[np.int64]:
    """Int64 ``(k, s)`` element array referencing rows of ``V``; no repeated vertex in an element."""
    A = as_index_array(F, V.shape[0], name, cols=cols, allow_empty=False)
    s = np.sort(A, axis=1)
    rep = np.any(s[:, 1:] == s[:, :-1], axis=1)
    if rep.any():
        e = int(np.flatnonzero(rep)[0])
        raise ValueError(f"{name} row {e} repeats a vertex: {A[e].tolist()}")
    if A.shape[1] == 4 and V.shape[1] != 3:
        raise ValueError(f"tetrahedra need 3D vertices, V has shape {V.shape}")
    return A


def as_weights(W: ArrayLike, n: int | None = None, name: str = "W") -> NDArray[np.float64]:
    """Float64 ``(n, m)`` finite weight matrix."""
    A = as_points(W, name=name, dims=range(1, 1 << 30))
    if n is not None and A.shape[0] != n:
        raise ValueError(f"{name} must have {n} rows (one per vertex), got {A.shape[0]}")
    return A


def positive_int(x: Any, name: str) -> int:
    if isinstance(x, bool) or not isinstance(x, (int, np.integer)) or x < 1:
        raise ValueError(f"{name} must be a positive integer, got {x!r}")
    return int(x)


def positive_float(x: Any, name: str) -> float:
    try:
        f = float(x)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a positive number, got {x!r}") from None
    if not np.isfinite(f) or f <= 0:
        raise ValueError(f"{name} must be a positive finite number, got {x!r}")
    return f


def progress_printer(
    verbose: bool,
    callback: Callback | None,
    describe: Callable[[str, int, float], str],
    every: float = 1.0,
) -> Callback | None:
    """The ``callback(stage, iteration, value)`` a long Rust job reports to: with ``verbose``,
    print ``describe(stage, iteration, value)`` to stderr at most every ``every`` seconds, then
    forward to the user's ``callback`` (whose ``False`` stops the job)."""
    if not verbose:
        return callback
    last = [0.0]

    def cb(stage: str, iteration: int, value: float) -> bool | None:
        now = time.perf_counter()
        if now - last[0] > every:
            last[0] = now
            print(f"  {describe(stage, iteration, value)}", file=sys.stderr)
        return None if callback is None else callback(stage, iteration, value)

    return cb
