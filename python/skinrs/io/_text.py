"""Shared helpers of the readers and writers: file sources that name file and line in their
errors, token conversion and text output."""

from __future__ import annotations

import functools
import os
import re
from typing import Any

import numpy as np
from numpy.typing import NDArray


class _Source:
    """A text file, able to build ``ValueError``s that name file and line."""

    def __init__(self, path: str | os.PathLike[str]) -> None:
        self.name = os.fspath(path)
        with open(self.name, "rb") as fh:
            data = fh.read()
        self.text = _decode(data)

    @functools.cached_property
    def lines(self) -> list[str]:
        return self.text.splitlines()

    @property
    def last_line_unterminated(self) -> bool:
        """Whether the last line has no newline (a file cut in the middle of a line)."""
        return bool(self.text.strip()) and not self.text.endswith(("\n", "\r"))

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


def _bulk(tokens: list[str], dtype: type) -> NDArray[Any] | None:
    """Convert a list of strings to an array, or return None when any token is not a number."""
    try:
        return np.array(tokens, dtype=dtype)
    except (ValueError, OverflowError):
        return None


def _first_bad(tokens: list[str], dtype: type) -> int:
    """Position of the first token that is not a number (or an integer outside int64)."""
    for k, t in enumerate(tokens):
        if dtype == np.int64:
            v = _to_int(t)
            if v is None or not -(2**63) <= v < 2**63:
                return k
        elif _to_float(t) is None:
            return k
    return len(tokens)


def _kind(dtype: type) -> str:
    return "an integer" if dtype == np.int64 else "a number"


def _write_lines(path: str | os.PathLike[str], lines: list[str]) -> None:
    with open(os.fspath(path), "w", encoding="utf-8", newline="\n") as fh:
        fh.write("\n".join(lines))
        fh.write("\n")


def _float_rows(A: NDArray[Any], prefix: str = "") -> list[str]:
    """Rows of ``A`` as text, each value written as the shortest string that reads back exactly."""
    return [prefix + " ".join(map(repr, row)) for row in A.tolist()]


def _int_rows(A: NDArray[Any], prefix: str = "", suffix: str = "") -> list[str]:
    return [prefix + " ".join(map(str, row)) + suffix for row in A.tolist()]


def _line_of_token(lines: list[str], k: int) -> int:
    """1-based line (counting the header as line 1) of the k-th whitespace token of ``lines``."""
    seen = 0
    for i, line in enumerate(lines):
        seen += len(line.split())
        if seen > k:
            return i + 1
    return len(lines)


def _pad_z(V: NDArray[Any]) -> NDArray[Any]:
    if V.shape[1] == 3:
        return V
    return np.hstack([V, np.zeros((V.shape[0], 1))])
