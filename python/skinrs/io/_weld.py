"""Merging vertices at identical positions, as exporters split them at UV seams and sharp edges.

Shared by the glTF reader and the command line, which mesh the inside of a surface and so need
one vertex per point.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray


def weld(
    V: NDArray[np.float64], F: NDArray[np.int64]
) -> tuple[NDArray[np.float64], NDArray[np.int64], NDArray[np.int64]]:
    """``(Vw, Fw, vertex_map)``: ``V`` with exact duplicates merged (first appearance kept, in
    order), ``F`` renumbered with the faces that welding collapses left out (a face degenerate
    in ``F`` already is kept, for the caller's checks to name), and per row of ``V`` its
    row of ``Vw`` (so ``Vw[vertex_map] == V`` and weights on ``Vw`` map back as
    ``W[vertex_map]``)."""
    _, first, inverse = np.unique(V, axis=0, return_index=True, return_inverse=True)
    order = np.argsort(first)  # keep first-appearance order
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    vertex_map = rank[inverse.reshape(-1)]
    Fw = vertex_map[F]
    collapsed = _degenerate(Fw) & ~_degenerate(F)
    return V[first[order]], Fw[~collapsed], vertex_map


def _degenerate(F: NDArray[np.int64]) -> NDArray[np.bool_]:
    """Faces with a repeated vertex."""
    out = np.zeros(len(F), dtype=bool)
    for a in range(F.shape[1]):
        for b in range(a + 1, F.shape[1]):
            out |= F[:, a] == F[:, b]
    return out
