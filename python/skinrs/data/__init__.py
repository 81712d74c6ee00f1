"""Small bundled data for the demo (the libigl tutorial 403 hand)."""

from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent


def hand() -> tuple[Any, Any, Any, Any, Any]:
    """``(V, T, F, C, BE)`` of the libigl tutorial 403 hand (7,234 vertices, 20 bones)."""
    from .. import io

    V, T, F = io.read_mesh(HERE / "hand" / "hand.mesh")
    C, BE = io.read_tgf(HERE / "hand" / "hand.tgf")
    return V, T, F, C, BE


def box_figure(n: int = 3) -> Any:
    """A generated polygon soup with a skeleton; see :mod:`skinrs.data.figure`."""
    from .figure import box_figure as make

    return make(n)
