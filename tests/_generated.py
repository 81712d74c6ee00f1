"""File fixtures written by the tests: OBJ and RigNet-format files of ``skinrs.data.box_figure``.

Imported lazily by the tests (``skinrs`` needs its built extension).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np


def box_figure_soup():
    """``V`` and the polygons of the generated soup."""
    from skinrs.data import box_figure

    V, polys, _, _, _ = box_figure()
    return V, polys


def figure_skeleton():
    """``names``, ``C`` and ``BE`` of the generated soup's skeleton."""
    from skinrs.data import box_figure

    _, _, names, C, BE = box_figure()
    return names, C, BE


def fan_triangles(polys) -> np.ndarray:
    """Triangles of a fan split of each polygon from its first corner."""
    return np.array([[p[0], p[k], p[k + 1]] for p in polys for k in range(1, len(p) - 1)])


def write_soup_obj(path: Path, V, polys) -> Path:
    """OBJ with ``v/vt/vn`` corners whose texture and normal indices differ from the vertex's."""
    lines = ["# box figure, a polygon soup", "g figure", "s off", "usemtl skin"]
    lines += [f"v {x:.17g} {y:.17g} {z:.17g}" for x, y, z in V]
    m = len(V)
    lines += [f"vt {i / m:.6f} 0.5" for i in range(m)] + ["vn 0 0 1"] * m
    for p in polys:  # texture index m - i, normal index i + 2 (mod m): neither equals i + 1
        lines.append("f " + " ".join(f"{i + 1}/{m - i}/{(i + 1) % m + 1}" for i in p))
    path.write_text("\n".join(lines) + "\n")
    return path


def figure_skin(V, k: int = 3):
    """Weights ``(m, 12)``: each vertex on its ``k`` nearest joints, inverse distance, rounded to
    4 decimals as RigNet writes them (rows sum to 1 within 1e-4)."""
    _, C, _ = figure_skeleton()
    D = np.linalg.norm(V[:, None] - C[None], axis=2)
    W = np.zeros_like(D)
    near = np.argsort(D, axis=1)[:, :k]
    rows = np.arange(len(V))[:, None]
    W[rows, near] = 1.0 / (D[rows, near] + 1e-3)
    return np.round(W / W.sum(axis=1, keepdims=True), 4)


def write_rignet_rig(path: Path, V) -> Path:
    """The figure's rig in RigNet's text format: joints, root, one skin line per vertex, hier."""
    names, C, BE = figure_skeleton()
    W = figure_skin(V)
    lines = [f"joints {n} {x:.8f} {y:.8f} {z:.8f}" for n, (x, y, z) in zip(names, C)]
    lines.append(f"root {names[0]}")
    for i, row in enumerate(W):
        cols = np.flatnonzero(row)
        lines.append(f"skin {i} " + " ".join(f"{names[j]} {row[j]:.4f}" for j in cols) + " ")
    lines += [f"hier {names[a]} {names[b]}" for a, b in BE]
    path.write_text("\n".join(lines) + "\n")
    return path
