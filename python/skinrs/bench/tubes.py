"""Generated BBW cases with few bones on fine meshes: a capsule, a bent tube, a 2D pair of pants.

Each case is a deterministic mesh built by :func:`skinrs.meshing.mesh_with_skeleton` (TetGen
in 3D, Triangle in 2D, with a maximum element size so that the interior is as fine as the
boundary), its bones sampled into the mesh as constrained vertices:

========  =====  =======  =====  ==========================================================
case      dim    vertices bones  shape
========  =====  =======  =====  ==========================================================
capsule   3D     ~30k     3      straight capsule along x, 3 bones along its axis
elbow     3D     ~30k     4      the same capsule bent by 90 degrees, 4 bones along its axis
pants     2D     ~32k     5      a pair of pants: a spine, two thighs, two shins
========  =====  =======  =====  ==========================================================

Few bones on a fine volume mesh is where supports are largest: each weight is positive on most
of the mesh, so the active-set method factors near-full blocks every round. Meshes are written
once to ``cache`` (``<case>.npz`` with ``V, T, b, bc``). No stored optimum: the bench prints
energies, and the duality gap certifies skinrs' own.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..meshing import mesh_with_skeleton

CASES = ("capsule", "elbow", "pants")
Arrays = dict[str, NDArray[Any]]

#: Capsule: half-length of the cylinder part, radius; bend radius of the elbow's axis.
HALF, RADIUS, BEND = 1.2, 0.35, 0.6
#: TetGen's maximum tet volume and Triangle's maximum triangle area.
TET_VOLUME, TRIANGLE_AREA = "0.000012", "0.000022"


def _capsule_surface(
    around: int = 64,
) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """A closed capsule along x (cylinder from -HALF to HALF, radius RADIUS, hemispherical
    caps) as rings of ``around`` vertices spaced about as far apart as their vertices, so
    that it can be bent without its faces cutting the corner."""
    h = 2 * np.pi * RADIUS / around
    # the profile (x, r) by arc length: a quarter circle, the cylinder, a quarter circle
    cap = np.pi / 2 * RADIUS
    s = np.linspace(0.0, 2 * cap + 2 * HALF, round((2 * cap + 2 * HALF) / h) + 1)[1:-1]
    phi = np.clip(s, 0, cap) / RADIUS - np.clip(s - cap - 2 * HALF, 0, cap) / RADIUS
    x = np.where(s < cap, -HALF - RADIUS * np.cos(phi), np.minimum(s - cap - HALF, HALF))
    x = np.where(s > cap + 2 * HALF, HALF + RADIUS * np.cos(phi), x)
    r = RADIUS * np.sin(np.clip(phi, 0, np.pi / 2))
    a = 2 * np.pi * np.arange(around) / around
    rings = np.stack(
        [np.repeat(x, around), np.outer(r, np.cos(a)).ravel(), np.outer(r, np.sin(a)).ravel()], 1
    )
    V = np.vstack([[-HALF - RADIUS, 0, 0], rings, [HALF + RADIUS, 0, 0]])
    k, j = np.arange(len(s) - 1)[:, None], np.arange(around)[None, :]
    p, q = 1 + k * around + j, 1 + k * around + (j + 1) % around
    strips = np.stack([np.stack([p, q, p + around], -1), np.stack([q, q + around, p + around], -1)])
    last = len(V) - 1
    F = np.vstack(
        [
            np.column_stack([np.zeros(around, int), 1 + (j.ravel() + 1) % around, 1 + j.ravel()]),
            strips.reshape(-1, 3),
            np.column_stack(
                [
                    np.full(around, last),
                    last - around + j.ravel(),
                    last - around + (j.ravel() + 1) % around,
                ]
            ),
        ]
    )
    return V.astype(np.float64), F.astype(np.int64)


def _bend(X: NDArray[np.float64]) -> NDArray[np.float64]:
    """Bends the part ``x > 0`` of space by 90 degrees about a circle of radius BEND in the
    xy-plane (its axis, the x axis, onto a quarter circle and then straight on along +y);
    ``x <= 0`` stays. A cross-section keeps its shape, so a tube of radius below BEND stays a
    tube without self-intersection."""
    x, y, z = X[:, 0], X[:, 1], X[:, 2]
    arc = BEND * np.pi / 2
    theta = np.clip(x, 0.0, arc) / BEND
    along = np.maximum(x - arc, 0.0)  # straight on after the arc
    cx = np.where(x > 0, BEND * np.sin(theta) + along * np.cos(theta), x)
    cy = np.where(x > 0, BEND * (1 - np.cos(theta)) + along * np.sin(theta), 0.0)
    # the cross-section's in-plane axis turns with the tangent (cos, sin) to (-sin, cos)
    nx, ny = np.where(x > 0, -np.sin(theta), 0.0), np.where(x > 0, np.cos(theta), 1.0)
    return np.column_stack([cx + y * nx, cy + y * ny, z])


def _pants() -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.int64]]:
    """Outline (a closed polygon, counter-clockwise), joints and bones of a pair of pants."""
    outline = np.array(
        [[-0.5, -1.0], [-0.1, -1.0], [0.0, 0.0], [0.1, -1.0], [0.5, -1.0], [0.5, 1.0], [-0.5, 1.0]]
    )
    C = np.array(
        [
            [0.0, 0.9],
            [0.0, 0.35],
            [-0.3, 0.2],
            [-0.3, -0.35],
            [-0.3, -0.9],
            [0.3, 0.2],
            [0.3, -0.35],
            [0.3, -0.9],
        ]
    )
    BE = np.array([[0, 1], [2, 3], [3, 4], [5, 6], [6, 7]])
    return outline, C, BE


def build(case: str) -> Arrays:
    """Meshes ``case`` (one of :data:`CASES`); returns ``V, T, b, bc``."""
    if case == "pants":
        outline, C, BE = _pants()
        # bone samples about one element apart (the default spacing follows the outline's
        # edges, which are as long as the legs)
        V, T, b, bc = mesh_with_skeleton(
            outline, None, C, BE, samples_per_edge=150, flags=f"pq30a{TRIANGLE_AREA}Y"
        )
        return {"V": V, "T": T, "b": b, "bc": bc}
    V, F = _capsule_surface()
    if case == "capsule":
        C = np.array([[-HALF, 0, 0], [-0.4, 0, 0], [0.4, 0, 0], [HALF, 0, 0]])
        BE = np.array([[0, 1], [1, 2], [2, 3]])
    elif case == "elbow":
        # 5 joints on the axis: two bones before the bend, one across it, one after
        C = _bend(
            np.array(
                [[-HALF, 0, 0], [-0.5, 0, 0], [0.1, 0, 0], [0.85, 0, 0], [HALF, 0, 0]], np.float64
            )
        )
        BE = np.array([[0, 1], [1, 2], [2, 3], [3, 4]])
        V = _bend(V)
    else:
        raise ValueError(f"case must be one of {CASES}, not {case!r}")
    V, T, b, bc = mesh_with_skeleton(V, F, C, BE, flags=f"pq1.5a{TET_VOLUME}Y")
    return {"V": V, "T": T, "b": b, "bc": bc}


def load(case: str, cache: Path) -> Arrays:
    """``case``'s arrays from ``cache/<case>.npz``, meshed and written there the first time."""
    path = cache / f"{case}.npz"
    if not path.exists():
        cache.mkdir(parents=True, exist_ok=True)
        t = time.perf_counter()
        arrays = build(case)
        np.savez(path, V=arrays["V"], T=arrays["T"], b=arrays["b"], bc=arrays["bc"])
        print(
            f"meshed {case}: {len(arrays['V'])} vertices, {len(arrays['T'])} elements in "
            f"{time.perf_counter() - t:.0f} s",
            flush=True,
        )
    z = np.load(path)
    return {k: z[k] for k in z.files}
