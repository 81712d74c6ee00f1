"""Sanity checks of the QP reference fixtures in tests/reference (no skinrs needed).

The fixtures are produced by tests/reference/make_qp_reference.py; these tests re-derive what
they can cheaply and independently: the boundary conditions (ours and libigl's own
``igl.boundary_conditions``), the biharmonic matrix, and the KKT conditions of the stored W_qp.
"""

import json

import cases
import numpy as np
import pytest
import scipy.sparse as sp

REF = cases.REFERENCE_DIR
# Every committed fixture; big2d (41k vertices) may store the mesh and constraints only.
NAMES = sorted(p.stem for p in REF.glob("*.npz"))
QP_NAMES = [n for n in NAMES if "W_qp" in np.load(REF / f"{n}.npz").files]


def _stored(name):
    return json.loads(np.load(REF / f"{name}.npz")["info_json"][()])["stored"]


# Fixtures whose W_qp satisfies every KKT sign to round-off (the others, e.g. big2d, are
# certified by a duality gap, tested for all below).
KKT_NAMES = [n for n in QP_NAMES if "gap certified" not in _stored(n)]


def fixture(name):
    path = REF / f"{name}.npz"
    if not path.exists():
        pytest.fail(f"missing fixture {path}; run tests/reference/make_qp_reference.py {name}")
    return cases.load_reference(name)


def biharmonic(V, T):
    import igl

    L = igl.cotmatrix(V, T)
    m = np.asarray(igl.massmatrix(V, T, igl.MASSMATRIX_TYPE_VORONOI).diagonal())
    return (L.T @ sp.diags(m.max() / m) @ L).tocsr()


@pytest.mark.parametrize("name", NAMES)
def test_fixture_shapes_and_boundary_conditions(name):
    fx = fixture(name)
    V, T, C, P, BE = fx["V"], fx["T"], fx["C"], fx["P"], fx["BE"]
    n, d = V.shape
    assert T.shape[1] == d + 1 and T.min() == 0 and T.max() == n - 1
    assert C.shape[1] == d
    m = len(P) + len(BE)
    b, bc = cases.boundary_conditions(V, T, C, P, BE)
    np.testing.assert_array_equal(fx["b"], b)
    np.testing.assert_array_equal(fx["bc"], bc)
    assert np.all(np.diff(b) > 0) and bc.shape == (len(b), m)
    np.testing.assert_allclose(bc.sum(axis=1), 1.0, atol=1e-15)
    # every handle/bone is constrained somewhere, and is exactly 1 at a non-joint vertex
    assert np.all(bc.max(axis=0) == 1.0)


@pytest.mark.parametrize("name", NAMES)
def test_boundary_conditions_match_libigl(name):
    """libigl's own boundary_conditions (absolute tol 1e-7) on the mesh scaled to unit diagonal."""
    import igl

    fx = fixture(name)
    V, C = fx["V"], fx["C"]
    if V.shape[1] == 2:
        V, C = np.c_[V, np.zeros(len(V))], np.c_[C, np.zeros(len(C))]
    s = np.linalg.norm(V.max(axis=0) - V.min(axis=0))
    b, bc = igl.boundary_conditions(V / s, fx["T"], C / s, fx["P"], fx["BE"])
    np.testing.assert_array_equal(b, fx["b"])
    np.testing.assert_allclose(bc, fx["bc"], atol=1e-15)


def test_boundary_conditions_semantics_small():
    """Hand-made case: point handle, bone, shared joint, t-range, tolerance."""
    V = np.array(
        [[0.0, 0.0], [0.5, 0.0], [1.0, 0.0], [1.0, 0.5], [1.5, 0.0], [0.5, 1e-5], [2.0, 2.0]]
    )
    C = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [2.0, 2.0]])
    P = np.array([3])
    BE = np.array([[0, 1], [1, 2]])
    b, bc = cases.boundary_conditions(V, None, C, P, BE)
    # vertex 4 lies on the line of bone 0 but beyond its tail (t = 1.5): not constrained;
    # vertex 5 is 1e-5 off the bone: squared distance 1e-10 <= 1e-7 * diag^2 -> constrained
    np.testing.assert_array_equal(b, [0, 1, 2, 3, 5, 6])
    expected = np.array([
        [0, 1, 0], [0, 1, 0], [0, 0.5, 0.5], [0, 0, 1], [0, 1, 0], [1, 0, 0],
    ])  # fmt: skip
    np.testing.assert_array_equal(bc, expected)
    with pytest.raises(ValueError):
        cases.boundary_conditions(V, None, np.array([[5.0, 5.0]]), np.array([0]), None)


@pytest.mark.parametrize("name", QP_NAMES)
def test_qp_solution_duality_gap(name):
    """Weak duality pins the optimum from W_qp alone: with G = (B W)[free], the multipliers
    v_i = -G_ij at the row's largest weight (partition of unity; stationarity holds there) and
    Y = max(G + v 1^T, 0) (bounds) are dual feasible, so
    the Lagrangian dual -0.5 sum_j r_j^T B_ff^{-1} r_j - 1^T v + c0, r_j = q_j + v - y_j, is a lower
    bound on the optimal energy and the energy of the feasible W_qp an upper bound. Exact
    fixtures close the gap to round-off; big2d is certified to 1e-9 (8.8e-10 this way)."""
    import scipy.sparse.linalg as spla

    fx = fixture(name)
    V, T, b, bc, W = fx["V"], fx["T"], fx["b"], fx["bc"], fx["W_qp"]
    B = biharmonic(V, T).tocsc()
    free = np.setdiff1d(np.arange(len(V)), b)
    Bff = B[free][:, free].tocsc()
    Q = B[free][:, b] @ bc
    c0 = 0.5 * float(np.sum(bc * (B[b][:, b] @ bc)))
    G = (B @ W)[free]
    v = -G[np.arange(len(free)), W[free].argmax(axis=1)]
    Y = np.maximum(G + v[:, None], 0)
    R = Q + v[:, None] - Y
    lower = float(-0.5 * np.sum(R * spla.splu(Bff).solve(R)) - v.sum() + c0)
    # the upper bound needs an exactly feasible point: W_qp clamped (it is >= -1e-12) and
    # renormalised
    assert W.min() >= -1e-9 and np.abs(W.sum(axis=1) - 1).max() <= 1e-9
    Wp = np.maximum(W, 0)
    Wp /= Wp.sum(axis=1, keepdims=True)
    upper = 0.5 * float(np.sum(Wp * (B @ Wp)))
    assert lower <= upper * (1 + 1e-12)
    assert (upper - lower) / upper <= 1e-9, (upper, lower)


@pytest.mark.parametrize("name", KKT_NAMES)
def test_qp_solution_kkt(name):
    fx = fixture(name)
    V, T, b, bc, W = fx["V"], fx["T"], fx["b"], fx["bc"], fx["W_qp"]
    assert W.shape == (len(V), bc.shape[1])
    assert W.min() >= -1e-9
    np.testing.assert_allclose(W.sum(axis=1), 1.0, atol=1e-9)
    np.testing.assert_array_equal(W[b], bc)
    B = biharmonic(V, T)
    E = 0.5 * float(np.sum(W * (B @ W)))
    assert E == pytest.approx(float(fx["energy"]), rel=1e-9)
    # stationarity: G = B W on the free rows must equal v_i on the support of row i and be
    # >= v_i elsewhere, so with v_i = min_j G_ij, W_ij (G_ij - v_i) must vanish.
    free = np.setdiff1d(np.arange(len(V)), b)
    G = (B @ W)[free]
    Y = G - G.min(axis=1, keepdims=True)
    scale = np.abs(G).max()
    assert np.max(W[free] * Y) <= 1e-9 * scale
    # and a small perturbation along a feasible direction does not decrease the energy:
    # move mass between two support entries of a random set of rows (PoU kept, W kept >= 0)
    rng = np.random.default_rng(0)
    D = np.zeros_like(W)
    for i in rng.choice(free, size=min(200, len(free)), replace=False):
        j, k = np.argsort(-W[i])[:2]
        t = 0.5 * min(W[i, j], 1e-3)
        D[i, j], D[i, k] = -t, t
    assert 0.5 * float(np.sum((W + D) * (B @ (W + D)))) >= E - 1e-12 * abs(E)


def test_knight_nopou_oracle():
    """libigl's BBW unit-test oracle (MATLAB active set, no PoU) fixes exactly our b, bc."""
    fx = fixture("knight")
    info = json.loads(fx["info_json"])
    W_matlab = fx["W_nopou_matlab"]
    W_file = cases.read_dmat(
        cases.ROOT
        / "tests"
        / "data"
        / "decimated-knight"
        / "decimated-knight-matlab-active-set.dmat"
    )
    np.testing.assert_array_equal(W_matlab, W_file)
    assert W_matlab.shape == (len(fx["V"]), 7)
    np.testing.assert_array_equal(W_matlab[fx["b"]], fx["bc"])
    # recorded when the fixture was made: igl.bbw(max_iter=100) on our b, bc vs the oracle
    assert info["nopou"]["igl_bbw_max_err"] < 1e-4
