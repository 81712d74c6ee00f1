"""A generated polygon soup: a box figure with a RigNet-style skeleton.

It stands in for game-style assets, which are rarely redistributable: every face of every box
has its own vertices (positions repeat, pieces only touch geometrically), boxes overlap
(self-intersections), faces mix quads and triangles, one box is open, and the skeleton has
coincident joints, as RigNet predicts them.

Example
-------
>>> from skinrs.data import box_figure
>>> V, polygons, names, C, BE = box_figure()
>>> V.shape, len(polygons), C.shape, BE.shape
((656, 3), 461, (12, 3), (11, 2))
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

# (center, half extents) of the boxes: torso, head, arms, legs, and a hat that lacks its bottom
BOXES = [
    ((0.0, 0.0, 0.0), (1.0, 1.5, 0.5)),
    ((0.0, 2.0, 0.0), (0.6, 0.6, 0.5)),
    ((-2.4, 1.0, 0.0), (1.5, 0.3, 0.3)),
    ((2.4, 1.0, 0.0), (1.5, 0.3, 0.3)),
    ((-0.3, -3.0, 0.0), (0.35, 1.6, 0.35)),
    ((0.3, -3.0, 0.0), (0.35, 1.6, 0.35)),
    ((0.0, 2.9, 0.0), (0.4, 0.3, 0.4)),
]
OPEN_BOX = 6  # the hat: its bottom face is missing
# Box faces as (normal axis, sign): outward-oriented quads.
FACES = [(0, -1), (0, 1), (1, -1), (1, 1), (2, -1), (2, 1)]


def _face_grid(
    center: tuple[float, float, float],
    half: tuple[float, float, float],
    axis: int,
    sign: int,
    n: int,
) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """(n+1)^2 vertices and n^2 outward quads of one box face, the face's own vertices."""
    u, v = (axis + 1) % 3, (axis + 2) % 3  # u x v = +axis
    if sign < 0:
        u, v = v, u  # keep the quads outward
    s = np.linspace(-1.0, 1.0, n + 1)
    P = np.zeros(((n + 1) ** 2, 3))
    P[:, axis] = sign * half[axis]
    P[:, u] = np.repeat(s, n + 1) * half[u]
    P[:, v] = np.tile(s, n + 1) * half[v]
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    a = (i * (n + 1) + j).ravel()
    Q = np.stack([a, a + n + 1, a + n + 2, a + 1], axis=1)
    return P + np.asarray(center), Q


def box_figure_soup(n: int = 3) -> tuple[NDArray[np.float64], list[NDArray[np.int64]]]:
    """``V (m, 3)`` and a list of polygons (0-based index arrays, 3 or 4 corners).

    Every ``5``-th quad is split into two triangles, so the soup mixes quads and triangles.
    """
    V: list[NDArray[np.float64]] = []
    polys: list[NDArray[np.int64]] = []
    for b, (c, h) in enumerate(BOXES):
        for axis, sign in FACES:
            if b == OPEN_BOX and (axis, sign) == (1, -1):
                continue
            P, Q = _face_grid(c, h, axis, sign, n)
            o = sum(len(x) for x in V)
            V.append(P)
            for q in Q + o:
                if len(polys) % 5 == 4:
                    polys += [q[[0, 1, 2]], q[[0, 2, 3]]]
                else:
                    polys.append(q)
    return np.concatenate(V), polys


# RigNet-style skeleton of the figure: name, position, parent. ``hip_dup_*`` are coincident
# joints, as RigNet predicts at the branching joints.
JOINTS = [
    ("root", (0.0, -0.5, 0.0), None),
    ("hip_dup_0", (0.0, -1.0, 0.0), "root"),
    ("hip_dup_1", (0.0, -1.0, 0.0), "root"),
    ("spine", (0.0, 1.0, 0.0), "root"),
    ("neck", (0.0, 1.6, 0.0), "spine"),
    ("head", (0.0, 2.4, 0.0), "neck"),
    ("shoulder_l", (-1.0, 1.0, 0.0), "spine"),
    ("hand_l", (-3.7, 1.0, 0.0), "shoulder_l"),
    ("shoulder_r", (1.0, 1.0, 0.0), "spine"),
    ("hand_r", (3.7, 1.0, 0.0), "shoulder_r"),
    ("foot_l", (-0.3, -4.4, 0.0), "hip_dup_0"),
    ("foot_r", (0.3, -4.4, 0.0), "hip_dup_1"),
]


def figure_skeleton() -> tuple[list[str], NDArray[np.float64], NDArray[np.int64]]:
    """``names``, ``C (12, 3)`` and ``BE (11, 2)`` (parent -> child) of the figure's rig."""
    names = [j[0] for j in JOINTS]
    ix = {n: i for i, n in enumerate(names)}
    C = np.array([j[1] for j in JOINTS])
    BE = np.array([[ix[p], ix[n]] for n, _, p in JOINTS if p is not None], dtype=np.int64)
    return names, C, BE


def box_figure(
    n: int = 3,
) -> tuple[
    NDArray[np.float64], list[NDArray[np.int64]], list[str], NDArray[np.float64], NDArray[np.int64]
]:
    """``(V, polygons, names, C, BE)``: the soup (``V (m, 3)``, a list of 0-based index arrays of
    3 or 4 corners, outward) and its skeleton (joint names, ``C (12, 3)``, ``BE (11, 2)`` parent
    -> child). ``n`` is the number of quads along each box face's side."""
    V, polygons = box_figure_soup(n)
    names, C, BE = figure_skeleton()
    return V, polygons, names, C, BE
