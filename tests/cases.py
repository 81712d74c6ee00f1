"""Test/benchmark cases for bounded biharmonic weights, built without skinrs.

Every builder returns ``dict(V, T, C, P, BE, name)`` in libigl conventions:

- ``V`` (n, d) float64 vertex positions (d = 2 for triangle meshes, 3 for tet meshes),
- ``T`` (k, 3) triangles or (k, 4) tets, int64, 0-based,
- ``C`` (c, d) handle/joint positions, ``P`` (p,) point-handle indices into C,
- ``BE`` (e, 2) bone edges into C (parent -> child), ``name`` a short case name.

Point handles and bone samples are mesh vertices (Sec. 7 of Solomon & Stein 2025: each bone is
sampled with ~2 points per average edge length, at least 2, and the samples are meshed as
vertices), so ``boundary_conditions`` finds a non-empty constraint set for every handle/bone.

``boundary_conditions`` is an independent Python reading of libigl's
``igl::boundary_conditions(V, T, C, P, BE, CE)`` (see its docstring for the one deliberate change:
the distance tolerance is relative to the bounding-box diagonal).

The 2D cases are meshed with the ``triangle`` package (deterministic for a given input and flags);
the 3D cases are read from ``tests/data``; woody and big2d re-mesh the woody-2d outline of the
shared data set, which cannot be redistributed (env ``SKINRS_DATA``; only
``tests/reference/make_qp_reference.py`` rebuilds them, the tests read the stored fixtures).

Example
-------
>>> import cases                                             # doctest: +SKIP
>>> case = cases.build("bar")                                # doctest: +SKIP
>>> b, bc = cases.boundary_conditions(case["V"], case["T"], case["C"], case["P"], case["BE"])
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]

# libigl's FLOAT_EPS (igl/EPS.h), used both as the squared-distance tolerance and the slack on
# the bone parameter t in igl::boundary_conditions.
BC_EPS = 1e-7


def data_root() -> Path:
    """``tests/data``, or the shared data set named by env ``SKINRS_DATA`` if set."""
    env = os.environ.get("SKINRS_DATA")
    return Path(env) if env else ROOT / "tests" / "data"


# --------------------------------------------------------------------------------------------
# Small file parsers (independent of skinrs.io)
# --------------------------------------------------------------------------------------------


def read_mesh(path) -> tuple[np.ndarray, np.ndarray]:
    """MEDIT ``.mesh``: returns V (n,3) float64 and tets T (k,4) int64 (0-based).

    Sections are found by keyword; each entry ends with a reference column that is dropped.
    """
    tok = Path(path).read_text().split()
    keys = {t: i for i, t in enumerate(tok) if t[0].isalpha()}

    def block(name, width):
        i = keys[name]
        count = int(tok[i + 1])
        vals = tok[i + 2 : i + 2 + count * (width + 1)]
        return np.array(vals, dtype=float).reshape(count, width + 1)[:, :width]

    V = block("Vertices", 3)
    T = block("Tetrahedra", 4).astype(np.int64) - 1
    return V, T


def read_tgf(path) -> tuple[np.ndarray, np.ndarray]:
    """libigl ``.tgf`` skeleton: returns joints C (c,3) and bone edges BE (e,2) int64 (0-based).

    Joint lines are ``index x y z [junk...]`` (only the first 4 columns are meaningful); then a
    ``#`` line; then bone lines ``i j`` (1-based); then ``#``.
    """
    sections: list[list[list[str]]] = [[]]
    for line in Path(path).read_text().splitlines():
        s = line.strip()
        if s.startswith("#"):
            sections.append([])
        elif s:
            sections[-1].append(s.split())
    C = np.array([[float(x) for x in row[1:4]] for row in sections[0]])
    bones = sections[1] if len(sections) > 1 else []
    BE = np.array([[int(row[0]), int(row[1])] for row in bones], dtype=np.int64).reshape(-1, 2) - 1
    return C, BE


def read_dmat(path) -> np.ndarray:
    """ASCII libigl ``.dmat``: header ``cols rows`` then column-major values; returns (rows, cols)."""
    tok = Path(path).read_text().split()
    cols, rows = int(tok[0]), int(tok[1])
    vals = np.array(tok[2 : 2 + rows * cols], dtype=float)
    return vals.reshape(cols, rows).T.copy()


def read_obj(path) -> tuple[np.ndarray, np.ndarray]:
    """Minimal OBJ reader: ``v`` positions and triangulated ``f`` faces (fan split), 0-based."""
    V, F = [], []
    for line in Path(path).read_text().splitlines():
        parts = line.split()
        if not parts:
            continue
        if parts[0] == "v":
            V.append([float(x) for x in parts[1:4]])
        elif parts[0] == "f":
            idx = [int(p.split("/")[0]) - 1 for p in parts[1:]]
            F.extend([idx[0], idx[i], idx[i + 1]] for i in range(1, len(idx) - 1))
    return np.array(V), np.array(F, dtype=np.int64)


def read_poly_dat(path) -> list[np.ndarray]:
    """poly2tri ``.dat``: list of rings (outer first); a ``HOLE`` line starts a new ring."""
    rings: list[list[list[float]]] = [[]]
    for line in Path(path).read_text().splitlines():
        s = line.strip()
        if not s:
            continue
        if s.upper() == "HOLE":
            rings.append([])
        else:
            rings[-1].append([float(x) for x in s.split()[:2]])
    return [np.array(r) for r in rings if r]


# --------------------------------------------------------------------------------------------
# Boundary conditions (independent re-implementation of igl::boundary_conditions)
# --------------------------------------------------------------------------------------------


def boundary_conditions(V, T, C, P=None, BE=None, eps: float = BC_EPS):
    """Constrained vertices and their values for point handles and bones.

    Same semantics as libigl's ``boundary_conditions(V, Ele, C, P, BE, CE)`` (CE unsupported):
    column ``p`` (point handle ``C[P[p]]``) is 1 at every vertex with squared distance
    ``<= tol2``; column ``len(P)+e`` (bone ``C[BE[e,0]] -> C[BE[e,1]]``) is 1 at every vertex
    whose projection parameter ``t`` on the bone's line lies in ``[-eps, 1+eps]`` and whose
    squared distance to that line is ``<= tol2``. A vertex hit by several handles/bones gets its
    row normalised to sum to 1. libigl uses ``tol2 = 1e-7`` absolute; here
    ``tol2 = eps * diag**2`` with ``diag`` the bounding-box diagonal of V (the same on
    unit-size meshes, scale invariant otherwise).

    Inputs: V (n,d), T (unused, kept for the libigl signature), C (c,d), P (p,) int, BE (e,2) int.
    Outputs: b (k,) int64 sorted ascending, bc (k, p+e) float64.
    Raises ValueError if some handle/bone column gets no vertex.
    """
    V = np.asarray(V, dtype=float)
    C = np.asarray(C, dtype=float)[:, : V.shape[1]]
    P = np.zeros(0, np.int64) if P is None else np.asarray(P, dtype=np.int64).reshape(-1)
    BE = np.zeros((0, 2), np.int64) if BE is None else np.asarray(BE, dtype=np.int64).reshape(-1, 2)
    diag = float(np.linalg.norm(V.max(axis=0) - V.min(axis=0)))
    tol2 = eps * diag * diag
    m = len(P) + len(BE)
    hits = np.zeros((len(V), m), dtype=bool)
    for p, ci in enumerate(P):
        hits[:, p] = ((V - C[ci]) ** 2).sum(axis=1) <= tol2
    for e, (s, d) in enumerate(BE):
        tip, tail = C[s], C[d]
        u = tail - tip
        t = ((V - tip) @ u) / (u @ u)
        sqrd = ((V - (tip + t[:, None] * u)) ** 2).sum(axis=1)
        hits[:, len(P) + e] = (t >= -eps) & (t <= 1.0 + eps) & (sqrd <= tol2)
    empty = np.flatnonzero(~hits.any(axis=0))
    if len(empty):
        raise ValueError(f"handles/bones {empty.tolist()} have no mesh vertex within tolerance")
    b = np.flatnonzero(hits.any(axis=1)).astype(np.int64)
    bc = hits[b].astype(float)
    bc /= bc.sum(axis=1, keepdims=True)
    return b, bc


# --------------------------------------------------------------------------------------------
# Meshing helpers
# --------------------------------------------------------------------------------------------


def bone_samples(C, BE, rho: float) -> list[np.ndarray]:
    """Per bone, equally spaced samples (endpoints included) ~2 per length rho, at least 2."""
    out = []
    for s, d in BE:
        length = float(np.linalg.norm(C[d] - C[s]))
        k = max(2, int(np.ceil(2.0 * length / rho)) + 1)
        t = np.linspace(0.0, 1.0, k)[:, None]
        pts = C[s] + t * (C[d] - C[s])
        # exact endpoints: a joint shared by two bones must be the same float twice, else
        # triangle sees two vertices ~1e-17 apart and refines around them without end
        pts[0], pts[-1] = C[s], C[d]
        out.append(pts)
    return out


def edge_length_for_area(area: float) -> float:
    """Edge length of an equilateral triangle of the given area (target rho for meshing)."""
    return float(np.sqrt(4.0 * area / np.sqrt(3.0)))


def ring_polygon(center, radius, n, clockwise=False) -> np.ndarray:
    a = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    if clockwise:
        a = -a
    return np.asarray(center) + radius * np.c_[np.cos(a), np.sin(a)]


def triangulate_2d(rings, holes, points, bone_polylines, max_area, min_angle=30):
    """Quality Delaunay mesh (``triangle``, flags ``pq<min_angle>a<max_area>``) of a PSLG.

    rings: closed polygons (boundary + hole outlines); holes: one interior point per hole;
    points: extra vertices (point handles); bone_polylines: sampled bones, inserted as PSLG
    segments so every sample is a mesh vertex and the bone is kept as mesh edges.
    Returns V (n,2) float64 and T (k,3) int64 (counter-clockwise).
    """
    import triangle

    verts, segs = [], []
    offset = 0

    def add(pts, closed):
        nonlocal offset
        k = len(pts)
        verts.append(np.asarray(pts, float))
        idx = offset + np.arange(k)
        if closed:
            segs.append(np.c_[idx, np.roll(idx, -1)])
        elif k > 1:
            segs.append(np.c_[idx[:-1], idx[1:]])
        offset += k

    for r in rings:
        add(r, closed=True)
    for poly in bone_polylines:
        add(poly, closed=False)
    if len(points):
        add(np.asarray(points, float).reshape(-1, 2), closed=False)
    # Joints shared by several bones appear once per bone: merge exact duplicates ourselves
    # (triangle's own duplicate handling can crash on segments that use them).
    pts, inv = np.unique(np.vstack(verts), axis=0, return_inverse=True)
    seg = inv.reshape(-1)[np.vstack(segs)]
    seg = np.unique(np.sort(seg[seg[:, 0] != seg[:, 1]], axis=1), axis=0)
    pslg = {"vertices": pts, "segments": seg.astype(np.int32)}
    if len(holes):
        pslg["holes"] = np.asarray(holes, float).reshape(-1, 2)
    out = triangle.triangulate(pslg, f"pq{min_angle}a{max_area!r}Q")
    V = np.asarray(out["vertices"], dtype=float)
    T = np.asarray(out["triangles"], dtype=np.int64)
    used = np.zeros(len(V), bool)
    used[T.ravel()] = True
    if not used.all():
        raise ValueError("triangle left unreferenced vertices (points outside the domain?)")
    # enforce counter-clockwise orientation
    e1, e2 = V[T[:, 1]] - V[T[:, 0]], V[T[:, 2]] - V[T[:, 0]]
    flip = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0] < 0
    T[flip] = T[flip][:, [0, 2, 1]]
    return V, T


def boundary_loop_2d(V, F) -> np.ndarray:
    """Vertex indices of the single boundary loop of a triangle mesh (via libigl)."""
    import igl

    return np.asarray(igl.boundary_loop(np.asarray(F, dtype=np.int64)), dtype=np.int64)


# --------------------------------------------------------------------------------------------
# Cases
# --------------------------------------------------------------------------------------------


def _case(V, T, C, P, BE, name):
    return {
        "V": np.ascontiguousarray(V, dtype=np.float64),
        "T": np.ascontiguousarray(T, dtype=np.int64),
        "C": np.ascontiguousarray(C, dtype=np.float64),
        "P": np.asarray(P, dtype=np.int64).reshape(-1),
        "BE": np.asarray(BE, dtype=np.int64).reshape(-1, 2),
        "name": name,
    }


def bar(max_area: float = 1.2e-3):
    """2 x 0.5 rectangle centred at the origin with a 3-bone chain along its x axis."""
    rect = np.array([[-1.0, -0.25], [1.0, -0.25], [1.0, 0.25], [-1.0, 0.25]])
    C = np.array([[-0.75, 0.0], [-0.25, 0.0], [0.3, 0.0], [0.75, 0.0]])
    BE = np.array([[0, 1], [1, 2], [2, 3]])
    rho = edge_length_for_area(max_area)
    V, T = triangulate_2d([rect], [], [], bone_samples(C, BE, rho), max_area)
    return _case(V, T, C, [], BE, "bar")


def disc_holes(max_area: float = 1.5e-3):
    """Unit disc with two circular holes and four point handles (no bones)."""
    rho = edge_length_for_area(max_area)
    outer = ring_polygon((0.0, 0.0), 1.0, int(np.ceil(2 * np.pi / rho)))
    hole_c = [(-0.42, -0.15), (0.38, -0.2)]
    hole_r = [0.22, 0.18]
    holes = [
        ring_polygon(c, r, int(np.ceil(2 * np.pi * r / rho)), clockwise=True)
        for c, r in zip(hole_c, hole_r)
    ]
    C = np.array([[0.05, 0.62], [-0.62, 0.35], [0.0, -0.3], [0.55, -0.62]])
    P = np.arange(4)
    V, T = triangulate_2d([outer, *holes], hole_c, C, [], max_area)
    return _case(V, T, C, P, np.zeros((0, 2)), "disc-holes")


def _woody_mesh(max_area: float, name: str, data_dir=None):
    d = Path(data_dir) if data_dir else data_root()
    V0, F0 = read_obj(d / "woody-2d" / "woody.obj")
    C, BE = read_tgf(d / "woody-2d" / "woody.tgf")
    V0, C = V0[:, :2], C[:, :2]
    loop = boundary_loop_2d(V0, F0)
    rho = edge_length_for_area(max_area)
    V, T = triangulate_2d([V0[loop]], [], [], bone_samples(C, BE, rho), max_area)
    return _case(V, T, C, [], BE, name)


def woody(data_dir=None, max_area: float = 20.0):
    """woody-2d boundary re-meshed (~3k vertices) with the woody.tgf bones sampled as vertices."""
    return _woody_mesh(max_area, "woody", data_dir)


def big2d(data_dir=None, max_area: float = 1.4):
    """woody refined to >= 40k vertices: the 2D benchmark case."""
    return _woody_mesh(max_area, "big2d", data_dir)


def knight(data_dir=None):
    """libigl's decimated-knight tet mesh and skeleton (bone samples are already vertices)."""
    d = (Path(data_dir) if data_dir else data_root()) / "decimated-knight"
    V, T = read_mesh(d / "decimated-knight.mesh")
    C, BE = read_tgf(d / "decimated-knight.tgf")
    return _case(V, T, C, [], BE, "knight")


def hand(data_dir=None):
    """libigl tutorial 403 hand: 7234-vertex tet mesh, 20 bones."""
    d = (Path(data_dir) if data_dir else data_root()) / "hand-403"
    V, T = read_mesh(d / "hand.mesh")
    C, BE = read_tgf(d / "hand.tgf")
    return _case(V, T, C, [], BE, "hand")


BUILDERS = {
    "bar": bar,
    "disc-holes": disc_holes,
    "woody": woody,
    "big2d": big2d,
    "knight": knight,
    "hand": hand,
}

NEEDS_DATA = {"woody", "big2d", "knight", "hand"}


def build(name: str, data_dir=None) -> dict:
    """Build case ``name`` (one of ``BUILDERS``)."""
    fn = BUILDERS[name]
    return fn(data_dir) if name in NEEDS_DATA else fn()


REFERENCE_DIR = Path(__file__).resolve().parent / "reference"


def load_reference(name: str) -> dict:
    """Load ``tests/reference/<name>.npz`` as a dict of arrays (scalars unwrapped)."""
    with np.load(REFERENCE_DIR / f"{name}.npz", allow_pickle=False) as z:
        return {k: (z[k].item() if z[k].ndim == 0 else z[k]) for k in z.files}
