"""Valid small inputs for every public function, the ways to break each argument, and each
function's contract; used by ``test_fuzz.py`` (Hypothesis) and run in ``_sandbox`` workers.

A ``Spec`` names a target (``"module:function"``), builds valid keyword arguments, says what
kind each argument is (which decides how it is broken) and checks a result against the
function's contract (finite, shapes, rows summing to 1, ...).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

# --------------------------------------------------------------------------------------------
# Small valid geometry, built without skinrs
# --------------------------------------------------------------------------------------------


def grid_2d(n: int = 4):
    """Triangulated unit square: V (n*n, 2), F (2 (n-1)^2, 3), counter-clockwise."""
    x = np.linspace(0.0, 1.0, n)
    V = np.array([[a, b] for b in x for a in x])
    F = []
    for j in range(n - 1):
        for i in range(n - 1):
            a, b, c, d = j * n + i, j * n + i + 1, (j + 1) * n + i, (j + 1) * n + i + 1
            F += [[a, b, d], [a, d, c]]
    return V, np.array(F, dtype=np.int64)


def square_outline():
    V = np.array([[0.0, 0], [1, 0], [1, 1], [0, 1]])
    E = np.array([[0, 1], [1, 2], [2, 3], [3, 0]], dtype=np.int64)
    return V, E


def cube_surface():
    V = np.array([[x, y, z] for x in (0.0, 1) for y in (0.0, 1) for z in (0.0, 1)])
    F = np.array(
        [
            [0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
            [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3],
        ],
        dtype=np.int64,
    )  # fmt: skip
    # orient outward: a positive signed volume
    a, b, c = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    if np.einsum("ij,ij->", a, np.cross(b, c)) < 0:
        F = F[:, [0, 2, 1]]
    return V, F


def cube_tets():
    """Unit cube with its centre: 12 positively oriented tets."""
    V, F = cube_surface()
    V = np.vstack([V, [[0.5, 0.5, 0.5]]])
    T = np.c_[F, np.full(len(F), 8)]
    vol = np.einsum(
        "ij,ij->i",
        V[T[:, 1]] - V[T[:, 0]],
        np.cross(V[T[:, 2]] - V[T[:, 0]], V[T[:, 3]] - V[T[:, 0]]),
    )
    T[vol < 0] = T[vol < 0][:, [1, 0, 2, 3]]
    return V, T.astype(np.int64)


def rigid(m: int, d: int = 3, angle: float = 0.3):
    """m rigid transforms ``[R | t]`` of shape (m, d, d+1)."""
    out = np.zeros((m, d, d + 1))
    for j in range(m):
        a = angle * j
        R = np.eye(d)
        R[:2, :2] = [[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]]
        out[j, :, :d] = R
        out[j, :, d] = 0.1 * j
    return out


def weights(n: int, m: int, seed: int = 0):
    W = np.random.default_rng(seed).random((n, m)) + 0.05
    return W / W.sum(1, keepdims=True)


# --------------------------------------------------------------------------------------------
# Contracts
# --------------------------------------------------------------------------------------------


def finite_array(x, shape=None):
    x = np.asarray(x)
    assert np.all(np.isfinite(x)), "result has NaN or inf"
    if shape is not None:
        assert x.shape == tuple(shape), f"shape {x.shape} != {shape}"


def partition_of_unity(W, n=None, atol=1e-6):
    W = np.asarray(W)
    finite_array(W)
    if n is not None:
        assert W.shape[0] == n, f"{W.shape[0]} rows, expected {n}"
    assert np.allclose(W.sum(1), 1.0, atol=atol), "rows do not sum to 1"


def sparse_finite(M, n):
    assert M.shape == (n, n), f"shape {M.shape}"
    assert np.all(np.isfinite(M.data)), "NaN or inf entry"


def n_rows(kw, name="V"):
    return len(np.asarray(kw[name]))


# --------------------------------------------------------------------------------------------
# Specs
# --------------------------------------------------------------------------------------------

# Argument kinds: how an argument may be broken (see test_fuzz.MUTATIONS).
DENSITY, SIZE = "density", "size"
POINTS, INDEX, INDEX1, WEIGHTS, TRANSFORMS, INT, ITERS, FLOAT, CHOICE, BOOL, CALLBACK = (
    "points", "index", "index1", "weights", "transforms", "int", "iterations", "float",
    "choice", "bool", "callback",
)  # fmt: skip


@dataclass
class Spec:
    target: str
    build: Callable[[], dict]
    kinds: dict
    contract: Callable[[object, dict], None] = lambda r, kw: None
    weight: int = 4  # relative number of examples (slow targets get fewer)
    optional: tuple = ()  # arguments that may be None
    present: dict | None = None  # values for arguments the valid call leaves None


def _mesh2():
    V, F = grid_2d()
    return {"V": V, "F": F}


def _skin_kw(d=3, m=3, n=16):
    V = np.random.default_rng(1).random((n, d))
    return {"V": V, "W": weights(n, m), "T": rigid(m, d)}


def _skel():
    C = np.array([[0.2, 0.5, 0.5], [0.5, 0.5, 0.5], [0.8, 0.5, 0.5]])
    BE = np.array([[0, 1], [1, 2]], dtype=np.int64)
    return C, BE


def _contract_skin(r, kw):
    finite_array(r, np.shape(kw["V"]))


def _contract_fk(r, kw):
    m = len(np.asarray(kw["BE"]))
    finite_array(r)
    assert r.shape[0] == m


def _contract_cc(r, kw):
    count, labels = r
    assert 0 <= count <= len(labels)
    assert labels.min(initial=0) >= 0 and labels.max(initial=-1) < max(count, 1)


def _contract_bc(r, kw):
    b, bc = r
    assert len(b) == len(bc)
    finite_array(bc)


def _contract_bbw(r, kw):
    partition_of_unity(r, n_rows(kw), atol=1e-4)
    assert r.min() >= -1e-6


def _contract_winding(r, kw):
    finite_array(r, (len(np.asarray(kw["Q"])),))


def _contract_closest(r, kw):
    for x in r:
        finite_array(x)


def _contract_knn(r, kw):
    finite_array(r, (n_rows(kw, "X"),))
    assert np.all(r >= 0)


def _contract_reduce(r, kw):
    I, Wk = r
    finite_array(Wk)
    assert I.shape == Wk.shape
    assert np.allclose(Wk.sum(1), 1.0, atol=1e-4) or kw.get("method") == "k-largest"


def _contract_field(r, kw):
    partition_of_unity(r, atol=1e-6)


def _contract_mesh(r, kw):
    Vv, T, b, bc = r
    finite_array(Vv)
    assert T.min() >= 0 and T.max() < len(Vv)
    assert b.min(initial=0) >= 0 and b.max(initial=-1) < len(Vv)
    finite_array(bc)


def _bbw_dual_constrained():
    V, T = cube_tets()
    return {"V": V, "T": T, "b": np.array([0, 7], dtype=np.int64), "bc": np.eye(2)}


def _bbw_dual():
    V, T = cube_tets()
    C = np.array([[0.0, 0, 0], [1.0, 1, 1]])
    return {"V": V, "T": T, "C": C, "P": np.array([0, 1], dtype=np.int64)}


def _field_kw():
    V, E = square_outline()
    return {
        "V": V,
        "F": E,
        "C": np.array([[0.3, 0.5], [0.7, 0.5]]),
        "P": np.array([0, 1], dtype=np.int64),
        "steps": 6,
        "n_points": 64,
        "samples": 64,
        "upsamples": 0,
        "pool": 256,
    }


def _mesh_kw():
    V = np.array([[0.0, 0], [4, 0], [4, 1], [0, 1]])
    return {
        "V": V,
        "F": None,
        "C": np.array([[0.5, 0.5], [2, 0.5], [3.5, 0.5]]),
        "BE": np.array([[0, 1], [1, 2]], dtype=np.int64),
    }


def _mesh3_kw():
    V, F = cube_surface()
    return {
        "V": V,
        "F": F,
        "C": np.array([[0.3, 0.5, 0.5], [0.7, 0.5, 0.5]]),
        "BE": np.array([[0, 1]], dtype=np.int64),
    }


def _reduce_kw():
    return {"W": weights(16, 4), "k": 2, "method": "k-largest"}


def _poisson_kw():
    V, F = grid_2d()
    V = np.c_[V, np.zeros(len(V))]
    C = np.array([[0.1, 0.1, 0], [0.9, 0.1, 0], [0.5, 0.9, 0], [0.5, 0.5, 0]])
    cp = C[None] + 0.05 * np.random.default_rng(0).random((2, 4, 3))
    return {"W": weights(16, 4), "k": 2, "method": "poisson", "V": V, "F": F, "control_points": cp}


def _red_err_kw():
    V, F = grid_2d()
    V = np.c_[V, np.zeros(len(V))]
    W = weights(len(V), 3)
    C = np.array([[0.1, 0.1, 0], [0.9, 0.1, 0], [0.5, 0.9, 0]])
    cp = C[None] + 0.05 * np.random.default_rng(0).random((2, 3, 3))
    order = np.argsort(-W, axis=1)[:, :2]
    Wk = np.take_along_axis(W, order, 1)
    Wk /= Wk.sum(1, keepdims=True)
    return {"V": V, "F": F, "W": W, "reduced": (order, Wk), "control_points": cp}


def _skel_poses():
    C, BE = _skel()
    return {"C": C, "BE": BE, "n_poses": 3, "seed": 0}


def _skinning_spec(method: str) -> Spec:
    """lbs / dqs with dense weights and, when drawn, rest normals N."""
    return Spec(
        f"skinrs:{method}",
        _skin_kw,
        {"V": POINTS, "W": WEIGHTS, "T": TRANSFORMS, "N": POINTS},
        lambda r, kw: _contract_skin(r if kw.get("N") is None else r[0], kw),
        optional=("N",),
        weight=6,
        present={"N": np.tile([[0.0, 0, 1]], (16, 1))},
    )


SPECS: dict[str, Spec] = {
    "cotan_laplacian": Spec(
        "skinrs:cotan_laplacian",
        _mesh2,
        {"V": POINTS, "F": INDEX},
        lambda r, kw: sparse_finite(r, n_rows(kw)),
    ),
    "massmatrix": Spec(
        "skinrs:massmatrix",
        lambda: {**_mesh2(), "kind": "voronoi"},
        {"V": POINTS, "F": INDEX, "kind": CHOICE},
        lambda r, kw: sparse_finite(r, n_rows(kw)),
    ),
    "biharmonic_matrix": Spec(
        "skinrs:biharmonic_matrix",
        lambda: dict(zip("VF", cube_tets())),
        {"V": POINTS, "F": INDEX},
        lambda r, kw: sparse_finite(r, n_rows(kw)),
    ),
    "connected_components": Spec(
        "skinrs:connected_components",
        lambda: {"F": grid_2d()[1], "n": 16},
        {"F": INDEX, "n": SIZE},
        _contract_cc,
        optional=("n",),
    ),
    "boundary_conditions": Spec(
        "skinrs:boundary_conditions",
        lambda: {
            "V": cube_tets()[0],
            "C": np.array([[0.0, 0, 0], [1.0, 1, 1]]),
            "P": np.array([0, 1]),
            "BE": None,
        },
        {"V": POINTS, "C": POINTS, "P": INDEX1, "BE": INDEX, "tol": FLOAT},
        _contract_bc,
        optional=("BE", "P", "tol"),
        present={"BE": np.array([[0, 1]])},
    ),
    "biharmonic_energy": Spec(
        "_fuzz_cases:biharmonic_energy_of",
        lambda: {"W": weights(9, 2), "n": 9},
        {"W": WEIGHTS},
        lambda r, kw: finite_array(r),
    ),
    "bbw_dual_constrained": Spec(
        "skinrs:bbw_dual_constrained",
        _bbw_dual_constrained,
        {
            "V": POINTS,
            "T": INDEX,
            "b": INDEX1,
            "bc": WEIGHTS,
            "tol": FLOAT,
            "max_iter": ITERS,
            "seed": INT,
            "solver": CHOICE,
            "callback": CALLBACK,
            "mass": CHOICE,
        },
        _contract_bbw,
        weight=2,
        optional=("callback",),
    ),
    "bbw_dual": Spec(
        "skinrs:bbw_dual",
        _bbw_dual,
        {"V": POINTS, "T": INDEX, "C": POINTS, "P": INDEX1, "BE": INDEX, "bc_tol": FLOAT},
        _contract_bbw,
        weight=2,
        optional=("BE", "P"),
    ),
    "winding_number": Spec(
        "skinrs:winding_number",
        lambda: {**dict(zip("VF", cube_surface())), "Q": np.random.default_rng(0).random((5, 3))},
        {"V": POINTS, "F": INDEX, "Q": POINTS, "beta": FLOAT},
        _contract_winding,
        optional=("beta",),
    ),
    "winding_number_2d": Spec(
        "skinrs:winding_number",
        lambda: {**dict(zip("VF", square_outline())), "Q": np.array([[0.5, 0.5], [2.0, 0]])},
        {"V": POINTS, "F": INDEX, "Q": POINTS},
        _contract_winding,
    ),
    "segment_visible": Spec(
        "skinrs:segment_visible",
        lambda: {
            **dict(zip("VF", cube_surface())),
            "P": np.full((3, 3), 0.5),
            "Q": np.random.default_rng(0).random((3, 3)),
        },
        {"V": POINTS, "F": INDEX, "P": POINTS, "Q": POINTS},
        lambda r, kw: finite_array(np.asarray(r, float), (3,)),
    ),
    "closest_point": Spec(
        "skinrs:closest_point",
        lambda: {**dict(zip("VF", square_outline())), "Q": np.array([[0.5, 0.5], [3, 0.2]])},
        {"V": POINTS, "F": INDEX, "Q": POINTS},
        _contract_closest,
    ),
    "closest_point_3d": Spec(
        "skinrs:closest_point",
        lambda: {**dict(zip("VF", cube_surface())), "Q": np.array([[0.5, 0.5, 0.2]])},
        {"V": POINTS, "F": INDEX, "Q": POINTS},
        _contract_closest,
    ),
    "knn_distance": Spec(
        "skinrs:knn_distance",
        lambda: {"X": np.random.default_rng(0).random((40, 3)), "k": 3},
        {"X": POINTS, "k": INT},
        _contract_knn,
    ),
    "bbw_field": Spec(
        "skinrs:bbw_field",
        _field_kw,
        {
            "V": POINTS,
            "F": INDEX,
            "C": POINTS,
            "P": INDEX1,
            "steps": ITERS,
            "n_points": INT,
            "samples": INT,
            "pool": INT,
            "upsamples": INT,
        },
        _contract_field,
        weight=1,
        optional=("steps", "n_points", "samples", "pool", "upsamples"),
    ),
    "field_evaluate": Spec(
        "_fuzz_cases:field_evaluate",
        lambda: {"Q": np.array([[0.5, 0.5], [0.1, 0.9]])},
        {"Q": POINTS},
        _contract_field,
        weight=1,
    ),
    "field_paint": Spec(
        "_fuzz_cases:field_paint",
        lambda: {"points": np.array([[0.5, 0.5]]), "weights": np.array([[0.5, 0.5]])},
        {"points": POINTS, "weights": WEIGHTS},
        _contract_field,
        weight=1,
    ),
    "mesh_with_skeleton": Spec(
        "skinrs:mesh_with_skeleton",
        _mesh_kw,
        {
            "V": POINTS,
            "C": POINTS,
            "BE": INDEX,
            "samples_per_edge": DENSITY,
            "min_samples": ITERS,
            "flags": CHOICE,
        },
        _contract_mesh,
        weight=2,
        optional=("flags",),
    ),
    "mesh_with_skeleton_3d": Spec(
        "skinrs:mesh_with_skeleton",
        _mesh3_kw,
        {"V": POINTS, "F": INDEX, "C": POINTS, "BE": INDEX, "flags": CHOICE},
        _contract_mesh,
        weight=1,
        optional=("flags",),
    ),
    "skin_weights": Spec(
        "skinrs:skin_weights",
        _mesh_kw,
        {"V": POINTS, "C": POINTS, "BE": INDEX},
        lambda r, kw: partition_of_unity(r, n_rows(kw), atol=1e-4),
        weight=1,
    ),
    "lbs": _skinning_spec("lbs"),
    "lbs_2d": Spec(
        "skinrs:lbs",
        lambda: _skin_kw(d=2),
        {"V": POINTS, "W": WEIGHTS, "T": TRANSFORMS},
        _contract_skin,
    ),
    "dqs": _skinning_spec("dqs"),
    "bone_parents": Spec(
        "skinrs:bone_parents",
        lambda: {"BE": _skel()[1], "n_joints": 3},
        {"BE": INDEX, "n_joints": INT},
        lambda r, kw: finite_array(r),
        optional=("n_joints",),
    ),
    "forward_kinematics": Spec(
        "skinrs:forward_kinematics",
        lambda: {"C": _skel()[0], "BE": _skel()[1], "Q": np.array([[1.0, 0, 0, 0]] * 2)},
        {"C": POINTS, "BE": INDEX, "Q": WEIGHTS},
        _contract_fk,
    ),
    "quaternions_from_xyzw": Spec(
        "skinrs:quaternions_from_xyzw",
        lambda: {"Q": np.array([0.0, 0, 0, 1, 0, 0, 0, 1])},
        {"Q": WEIGHTS},
        lambda r, kw: finite_array(r),
    ),
    "per_vertex_normals": Spec(
        "skinrs:per_vertex_normals",
        lambda: dict(zip("VF", cube_surface())),
        {"V": POINTS, "F": INDEX},
        lambda r, kw: finite_array(r, np.shape(kw["V"])),
    ),
    "reduce_weights": Spec(
        "skinrs:reduce_weights",
        _reduce_kw,
        {
            "W": WEIGHTS,
            "k": INT,
            "method": CHOICE,
            "max_sweeps": ITERS,
            "tol": FLOAT,
            "callback": CALLBACK,
        },
        _contract_reduce,
        optional=("callback",),
    ),
    "reduce_weights_poisson": Spec(
        "skinrs:reduce_weights",
        _poisson_kw,
        {
            "W": WEIGHTS,
            "k": INT,
            "V": POINTS,
            "F": INDEX,
            "control_points": TRANSFORMS,
            "max_sweeps": ITERS,
        },
        _contract_reduce,
        weight=2,
    ),
    "unpack_weights": Spec(
        "skinrs:unpack_weights",
        lambda: {
            "indices": np.array([[0, 1], [2, 0]]),
            "weights": np.array([[0.5, 0.5], [1, 0.0]]),
            "m": 3,
        },
        {"indices": INDEX, "weights": WEIGHTS, "m": SIZE},
        lambda r, kw: finite_array(r),
    ),
    "reduction_error": Spec(
        "skinrs:reduction_error",
        _red_err_kw,
        {"V": POINTS, "F": INDEX, "W": WEIGHTS, "control_points": TRANSFORMS},
        lambda r, kw: None,
        weight=2,
    ),
    "transform_normals": Spec(
        "skinrs:transform_normals",
        lambda: {
            "N": np.tile([[0.0, 0, 1]], (4, 1)),
            "reduced": (np.zeros((4, 1), np.int64), np.ones((4, 1))),
            "bone_transforms": rigid(1)[None],
        },
        {"N": POINTS, "bone_transforms": TRANSFORMS},
        lambda r, kw: finite_array(r),
    ),
    "random_skeleton_poses": Spec(
        "skinrs:random_skeleton_poses",
        _skel_poses,
        {"C": POINTS, "BE": INDEX, "n_poses": ITERS, "seed": INT, "max_angle": FLOAT},
        lambda r, kw: finite_array(r),
        optional=("seed",),
    ),
}


# --------------------------------------------------------------------------------------------
# Callbacks (module level, so they reach the worker process)


def stop(*args):
    return False


def keep_going(*args):
    return None


def interrupt(*args):
    raise KeyboardInterrupt


class Own(Exception):
    """A callback's own exception type, which must reach the caller unchanged."""


def own(*args):
    raise Own("callback failed")


# --------------------------------------------------------------------------------------------
# Targets that need more than one call (run inside the sandbox worker)
# --------------------------------------------------------------------------------------------

_FIELD = {}


def _field():
    if "f" not in _FIELD:
        import skinrs

        kw = _field_kw()
        g = skinrs.GeometricField(**kw)
        g.optimize()
        _FIELD["f"] = g
    return _FIELD["f"]


def field_evaluate(Q):
    return _field().evaluate(Q)


def field_paint(points, weights):
    import skinrs

    kw = _field_kw()
    g = skinrs.GeometricField(**kw)
    g.paint(points, weights)
    g.optimize(steps=2)
    return g.evaluate(np.array([[0.5, 0.5]]))


def biharmonic_energy_of(W, n):
    import skinrs

    V, F = grid_2d(3)
    B = skinrs.biharmonic_matrix(V, F)
    return skinrs.biharmonic_energy(W, B)


# --------------------------------------------------------------------------------------------
# Readers: valid files, and the contract of what they return
# --------------------------------------------------------------------------------------------

_TET = "0 0 0 1\n1 0 0 1\n0 1 0 1\n0 0 1 1\n1 1 1 1\n"

READER_FILES = {
    "read_tgf": ("t.tgf", "1 0 0 0\n2 1 0 0\n3 2 0 0\n4 2 1 0\n#\n1 2\n2 3\n3 4\n#\n"),
    "read_obj": (
        "m.obj",
        (
            "# cube corner\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nvn 0 0 1\nvn 1 0 0\n"
            "vt 0 0\nf 1//1 3//1 2//1\nf 1 2 4\nf 1/1 4/1 3/1\nf 2 3 4\n"
        ),
    ),
    "read_mesh": (
        "m.mesh",
        "MeshVersionFormatted 1\nDimension 3\nVertices\n5\n"
        + _TET
        + "Tetrahedra\n2\n1 2 3 4 0\n2 3 4 5 0\nTriangles\n1\n1 2 3 0\nEnd\n",
    ),
    "read_dmat": ("w.dmat", "2 3\n0.5 0.25 1\n0.5 0.75 0\n"),
    "read_polygon_dat": ("p.dat", "0 0\n4 0\n4 3\n0 3\nHOLE\n1 1\n2 1\n1 2\n"),
    "read_rignet_rig": (
        "r_rig.txt",
        (
            "joints a 0 0 0\njoints b 0 1 0\njoints c 0 2 0\nroot a\nhier a b\nhier b c\n"
            "skin 0 a 1.0\nskin 1 a 0.5 b 0.5\nskin 2 b 0.25 c 0.75\n"
        ),
    ),
}


def _finite_arrays(*arrays):
    for a in arrays:
        assert np.all(np.isfinite(np.asarray(a, float))), "non-finite value read"


def _indices_in(A, n):
    A = np.asarray(A)
    assert A.size == 0 or (A.min() >= 0 and A.max() < n), "index out of range"


def reader_contract(name, r):
    if name == "read_tgf":
        C, BE = r
        _finite_arrays(C)
        _indices_in(BE, len(C))
    elif name == "read_obj":
        V, F = r
        _finite_arrays(V)
        _indices_in(F, len(V))
    elif name == "read_mesh":
        V, T, F = r
        _finite_arrays(V)
        _indices_in(T, len(V))
        _indices_in(F, len(V))
    elif name == "read_dmat":
        _finite_arrays(r)
        assert r.ndim == 2
    elif name == "read_polygon_dat":
        outer, holes = r
        _finite_arrays(outer, *holes)
        assert len(outer) >= 3 and all(len(h) >= 3 for h in holes)
    elif name == "read_rignet_rig":
        _finite_arrays(r["C"], r["W"])
        _indices_in(r["BE"], len(r["C"]))
        assert len(r["BE"]) == len(r["C"]) - 1, "not one tree over the joints"
        assert r["W"].shape[0] == 0 or np.allclose(r["W"].sum(1), 1, atol=1e-3)
