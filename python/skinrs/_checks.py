"""Argument checks shared by every public function.

Each helper returns a clean, contiguous array of the dtype the Rust core expects, or raises a
``ValueError`` that names the argument and says what is wrong. Nothing is silently clamped, dropped or reinterpreted.

Coordinates must be finite and at most ``COORD_MAX`` in magnitude, and a mesh must span at least
``EXTENT_MIN``: beyond that, squared distances, areas and volumes overflow or underflow double
precision (the same limits as the Rust core, ``src/limits.rs``). Sizes that decide an allocation
are checked against the machine's memory before anything is allocated.
"""

from __future__ import annotations

import os
import sys
import time
from collections.abc import Callable, Iterable, Sequence
from typing import Any, cast

import numpy as np
from numpy.typing import ArrayLike, NDArray

#: ``callback(stage, iteration, value)`` of a long job; returning ``False`` stops it.
Callback = Callable[[str, int, float], "bool | None"]

COORD_MAX = 1e75
EXTENT_MIN = 1e-75


def as_real_array(X: ArrayLike, name: str) -> NDArray[Any]:
    """``np.asarray(X)`` holding real numbers (bool, integer or float dtype), else ValueError."""
    try:
        A = np.asarray(X)
    except (TypeError, ValueError, OverflowError) as e:  # ragged lists and the like
        raise ValueError(f"{name} must be an array of numbers: {e}") from None
    if np.iscomplexobj(A):
        raise ValueError(f"{name} must be real, got dtype {A.dtype}")
    if A.dtype == object or not (np.issubdtype(A.dtype, np.number) or A.dtype == bool):
        raise ValueError(f"{name} must hold numbers, got dtype {A.dtype}")
    return A


def as_array(X: ArrayLike, name: str, ndim: int, coordinates: bool = True) -> NDArray[np.float64]:
    """Float64 C-contiguous array with ``ndim`` dimensions and finite entries (at most
    ``COORD_MAX`` in magnitude with ``coordinates``)."""
    A = as_real_array(X, name)
    if A.ndim != ndim:
        raise ValueError(f"{name} must be {ndim}-dimensional, got shape {A.shape}")
    A = finite(np.ascontiguousarray(A, dtype=np.float64), name)
    return representable(A, name) if coordinates else A


def _describe_dims(dims: Iterable[int] | None) -> str:
    if dims is None:
        return "(n, m) with m >= 1"
    dims = tuple(dims)
    return f"(n, d) with d in {dims}" if len(dims) > 1 else f"(n, {dims[0]})"


def as_points(
    X: ArrayLike,
    name: str = "V",
    dims: Iterable[int] | None = (2, 3),
    min_rows: int = 1,
    coordinates: bool = True,
) -> NDArray[np.float64]:
    """Float64 C-contiguous ``(n, d)`` array with ``d`` in ``dims`` (any ``d >= 1`` when
    ``dims`` is None) and only finite entries; with ``coordinates``, entries are at most
    ``COORD_MAX`` in magnitude."""
    A = as_real_array(X, name)
    if (
        A.ndim != 2
        or (dims is None and A.shape[1] < 1)
        or (dims is not None and A.shape[1] not in dims)
    ):
        raise ValueError(f"{name} must have shape {_describe_dims(dims)}, got {A.shape}")
    if A.shape[0] < min_rows:
        raise ValueError(f"{name} must have at least {min_rows} rows, got {A.shape[0]}")
    A = np.ascontiguousarray(A, dtype=np.float64)
    finite(A, name)
    if coordinates:
        representable(A, name)
    return A


def finite(A: NDArray[Any], name: str) -> NDArray[Any]:
    """``A`` itself, or ValueError naming the first row with a NaN or infinite entry."""
    bad = ~np.isfinite(A)
    if bad.any():
        where = np.argwhere(bad)[0]
        at = f"row {int(where[0])}" if A.ndim >= 2 else f"entry {int(where[0])}"
        raise ValueError(f"{name} has a NaN or infinite entry ({at})")
    return A


def representable(A: NDArray[np.float64], name: str) -> NDArray[np.float64]:
    """``A`` itself, or ValueError when an entry exceeds ``COORD_MAX`` in magnitude."""
    if A.size and float(np.abs(A).max()) > COORD_MAX:
        r = int(np.argwhere(np.abs(A) > COORD_MAX)[0][0])
        raise ValueError(
            f"{name} row {r} has an entry of magnitude {float(np.abs(A).max()):.3g}, beyond "
            f"{COORD_MAX:g}: distances and areas would overflow double precision; rescale the data"
        )
    return A


def spans(V: NDArray[np.float64], name: str = "V") -> NDArray[np.float64]:
    """``V`` itself, or ValueError when its bounding box is non-zero but below ``EXTENT_MIN``."""
    if len(V):
        diag = float(np.linalg.norm((V.max(axis=0) - V.min(axis=0)) / COORD_MAX)) * COORD_MAX
        if 0.0 < diag < EXTENT_MIN:
            raise ValueError(
                f"{name} spans only {diag:.3g} (bounding-box diagonal), below {EXTENT_MIN:g}: its "
                f"lengths, areas and volumes would underflow double precision; rescale the data"
            )
    return V


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
    A = as_real_array(X, name)
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
    # range first, in the input's own dtype (a uint64 2**64-1 must not wrap to -1)
    lo, hi = A.min(), A.max()
    if lo < 0 or hi >= n:
        bad = lo if lo < 0 else hi
        bad = int(bad) if np.issubdtype(A.dtype, np.integer) or bad == int(bad) else float(bad)
        raise ValueError(f"{name} holds index {bad}, outside the valid range 0..{n - 1}")
    return np.ascontiguousarray(A, dtype=np.int64)


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
    A = as_points(W, name=name, dims=None, coordinates=False)
    if n is not None and A.shape[0] != n:
        raise ValueError(f"{name} must have {n} rows (one per vertex), got {A.shape[0]}")
    return A


_NOT_NUMBERS = (bool, np.bool_, str, bytes, complex, np.complexfloating)


def _as_float(x: Any, name: str, what: str) -> float:
    """``float(x)`` for a finite real number (never bool, str or complex), else ValueError."""
    f = None
    if not isinstance(x, _NOT_NUMBERS):
        try:
            f = float(x)
        except (TypeError, ValueError, OverflowError):
            f = None
    if f is None or not np.isfinite(f):
        raise ValueError(f"{name} must be {what}, got {x!r}")
    return f


def finite_float(x: Any, name: str) -> float:
    return _as_float(x, name, "a finite number")


def non_negative_float(x: Any, name: str) -> float:
    f = _as_float(x, name, "a finite number >= 0")
    if f < 0:
        raise ValueError(f"{name} must be a finite number >= 0, got {x!r}")
    return f


def positive_float(x: Any, name: str) -> float:
    f = _as_float(x, name, "a positive finite number")
    if f <= 0:
        raise ValueError(f"{name} must be a positive finite number, got {x!r}")
    return f


def integer(x: Any, name: str, lo: int | None = None, hi: int | None = None) -> int:
    """A Python int (integral numpy scalars too, never bool or float) in ``lo..=hi``."""
    is_int = isinstance(x, (int, np.integer)) and not isinstance(x, (bool, np.bool_))
    if not is_int:
        raise ValueError(f"{name} must be an integer, got {x!r}")
    v = int(x)
    if lo is not None and v < lo:
        what = "a non-negative integer" if lo == 0 else f"an integer >= {lo}"
        raise ValueError(f"{name} must be {what}, got {v}")
    if hi is not None and v > hi:
        raise ValueError(f"{name} must be at most {hi}, got {v}")
    return v


def positive_int(x: Any, name: str, hi: int = 2**62) -> int:
    if isinstance(x, (bool, np.bool_)) or not isinstance(x, (int, np.integer)) or x < 1:
        raise ValueError(f"{name} must be a positive integer, got {x!r}")
    if x > hi:
        raise ValueError(f"{name} must be at most {hi}, got {x}")
    return int(x)


def seed(x: Any, name: str = "seed") -> int | None:
    """A seed: an integer in ``0..2**64-1`` (or None, kept as None)."""
    return None if x is None else integer(x, name, 0, 2**64 - 1)


def physical_memory() -> int:
    """Bytes of RAM of this machine (a large default where the OS does not say)."""
    try:
        return int(os.sysconf("SC_PAGE_SIZE")) * int(os.sysconf("SC_PHYS_PAGES"))
    except (AttributeError, ValueError, OSError):
        return 1 << 40


def fits_in_memory(nbytes: float, what: str) -> None:
    """ValueError unless ``nbytes`` (what a call would allocate) fits in half the machine's RAM."""
    limit = physical_memory() // 2
    if nbytes > limit:
        raise ValueError(
            f"{what} would need about {nbytes / 2**30:.3g} GiB, more than half of this machine's "
            f"{2 * limit / 2**30:.3g} GiB of memory"
        )


def as_callback(cb: Any, name: str = "callback") -> Callback | None:
    """None or a callable, else ValueError (like every other bad argument)."""
    if not (cb is None or callable(cb)):
        raise ValueError(f"{name} must be callable (stage, iteration, value) or None, got {cb!r}")
    return cast("Callback | None", cb)


def progress_printer(
    verbose: bool,
    callback: Callback | None,
    describe: Callable[[str, int, float], str],
    every: float = 1.0,
) -> Callback | None:
    """The ``callback(stage, iteration, value)`` a long Rust job reports to: with ``verbose``,
    print ``describe(stage, iteration, value)`` to stderr at most every ``every`` seconds, then
    forward to the user's ``callback`` (whose ``False`` stops the job)."""
    callback_ = as_callback(callback)
    if not verbose:
        return callback_
    last = [0.0]

    def cb(stage: str, iteration: int, value: float) -> bool | None:
        now = time.perf_counter()
        if now - last[0] > every:
            last[0] = now
            print(f"  {describe(stage, iteration, value)}", file=sys.stderr)
        return None if callback_ is None else callback_(stage, iteration, value)

    return cb
