"""Small readers for the shared data used by the skinning and meshing tests.

Kept independent of ``skinrs.io`` on purpose: the tests check skinrs against data read by code
that is not skinrs's.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np


def read_tgf(path: Path):
    """``C (n, 3)`` joints and ``BE (m, 2)`` 0-based directed bones of a libigl .tgf file."""
    joints, bones, section = [], [], 0
    for line in Path(path).read_text().splitlines():
        s = line.split()
        if not s:
            continue
        if s[0].startswith("#"):
            section += 1
            continue
        if section == 0:
            joints.append([float(x) for x in s[1:4]])
        elif section == 1:
            bones.append([int(s[0]) - 1, int(s[1]) - 1])
    return np.array(joints), np.array(bones, dtype=np.int64).reshape(-1, 2)


def read_dmat(path: Path) -> np.ndarray:
    """ASCII .dmat: first line ``cols rows``, then column-major numbers."""
    tok = Path(path).read_text().split()
    cols, rows = int(tok[0]), int(tok[1])
    return np.array(tok[2 : 2 + cols * rows], dtype=np.float64).reshape(cols, rows).T


def read_obj(path: Path):
    V, F = [], []
    for line in Path(path).read_text().splitlines():
        s = line.split()
        if not s:
            continue
        if s[0] == "v":
            V.append([float(x) for x in s[1:4]])
        elif s[0] == "f":
            F.append([int(x.split("/")[0]) - 1 for x in s[1:4]])
    return np.array(V), np.array(F, dtype=np.int64)


def read_mesh(path: Path):
    """MEDIT .mesh: ``V (n, 3)``, boundary ``F (k, 3)``, ``T (t, 4)``, all 0-based."""
    tok = Path(path).read_text().split()
    out, i = {}, 0
    while i < len(tok):
        key = tok[i]
        if key in ("Vertices", "Triangles", "Tetrahedra"):
            n = int(tok[i + 1])
            width = {"Vertices": 4, "Triangles": 4, "Tetrahedra": 5}[key]
            a = np.array(tok[i + 2 : i + 2 + n * width], dtype=np.float64).reshape(n, width)
            out[key] = a[:, :-1]
            i += 2 + n * width
        else:
            i += 1
    return (
        out["Vertices"],
        out["Triangles"].astype(np.int64) - 1,
        out["Tetrahedra"].astype(np.int64) - 1,
    )


def cylinder(n_around=48, n_along=60, length=4.0, radius=0.5):
    """Closed, outward-oriented triangle mesh of a cylinder along x, with capped ends."""
    th = 2 * np.pi * np.arange(n_around) / n_around
    xs = np.linspace(0.0, length, n_along)
    ring = np.stack([np.zeros_like(th), radius * np.cos(th), radius * np.sin(th)], axis=1)
    V = np.concatenate([ring + [x, 0, 0] for x in xs])
    F = []
    for a in range(n_along - 1):
        for b in range(n_around):
            i, j = a * n_around + b, a * n_around + (b + 1) % n_around
            k, l = i + n_around, j + n_around
            F += [[i, k, j], [j, k, l]]
    c0, c1 = len(V), len(V) + 1
    V = np.vstack([V, [[0, 0, 0], [length, 0, 0]]])
    last = (n_along - 1) * n_around
    for b in range(n_around):
        F.append([c0, b, (b + 1) % n_around])
        F.append([c1, last + (b + 1) % n_around, last + b])
    return V, np.array(F, dtype=np.int64)[:, [0, 2, 1]]  # outward


def signed_volume(V, F) -> float:
    """Volume enclosed by a closed, outward-oriented triangle mesh (divergence theorem)."""
    a, b, c = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)
