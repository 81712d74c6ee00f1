"""Pictures of weight functions with matplotlib (``pip install skinrs[plot]``)."""

from __future__ import annotations

import os
from collections.abc import Iterable
from typing import Any

import numpy as np
from numpy.typing import ArrayLike


def _plt() -> Any:
    try:
        import matplotlib

        matplotlib.use("Agg", force=False)
        import matplotlib.pyplot as plt
    except ImportError as e:  # pragma: no cover - depends on the environment
        raise ImportError("plots need matplotlib: pip install skinrs[plot]") from e
    return plt


def plot_weights(
    V: ArrayLike,
    F: ArrayLike,
    W: ArrayLike,
    *,
    columns: Iterable[int] | None = None,
    C: ArrayLike | None = None,
    BE: ArrayLike | None = None,
    path: str | os.PathLike[str] | None = None,
    title: str | None = None,
    view: tuple[int, int] = (0, 1),
) -> Any:
    """Colour maps of weight functions on a triangle mesh (a surface is shown projected).

    Parameters
    ----------
    V : (n, d) vertex positions; F : (k, 3) triangles (e.g. the boundary of a tet mesh)
    W : (n, m) weights; columns : which columns to show (default: up to 4 spread over m)
    C, BE : optional skeleton drawn on top; path : write a PNG there; view : the two
    coordinates used for the projection.

    Returns the matplotlib figure.
    """
    plt = _plt()
    V = np.asarray(V, dtype=float)
    W = np.asarray(W, dtype=float)
    m = W.shape[1]
    if columns is None:
        shown = np.unique(np.linspace(0, m - 1, min(4, m)).round().astype(int)).tolist()
    else:
        shown = list(columns)
    fig, axes = plt.subplots(1, len(shown), figsize=(4 * len(shown), 4.4), squeeze=False)
    x, y = V[:, view[0]], V[:, view[1]]
    # Paint far faces first so the visible side ends on top.
    depth_axis = ({0, 1, 2} - set(view)).pop() if V.shape[1] == 3 else None
    F = np.asarray(F)
    if depth_axis is not None:
        F = F[np.argsort(V[F, depth_axis].mean(1))]
    for ax, j in zip(axes[0], shown, strict=True):
        tc = ax.tripcolor(x, y, F, W[:, j], shading="gouraud", cmap="viridis", vmin=0, vmax=1)
        if C is not None and BE is not None:
            C = np.asarray(C, dtype=float)
            for a, b in np.asarray(BE):
                ax.plot(C[[a, b], view[0]], C[[a, b], view[1]], "w-", lw=1.2)
        ax.set_title(f"weight {j}")
        ax.set_aspect("equal")
        ax.axis("off")
    fig.colorbar(tc, ax=axes[0].tolist(), shrink=0.8)
    if title:
        fig.suptitle(title)
    if path is not None:
        fig.savefig(path, dpi=110)
    return fig
