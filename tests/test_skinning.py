"""Skinning: LBS, DQS, forward kinematics, normals, checked against independent references
(gpytoolbox LBS, libigl normals, closed-form rigid motions and hand-built kinematic chains)."""

import gpytoolbox as gpt
import igl
import numpy as np
import pytest
import scipy.sparse as sp
import skinrs
from _skin_data import cylinder, read_dmat, read_tgf, signed_volume


def random_affine(m, d, rng):
    T = rng.standard_normal((m, d, d + 1))
    T[:, :, :d] += 2 * np.eye(d)
    return T


def random_rotations(m, rng):
    Q, _ = np.linalg.qr(rng.standard_normal((m, 3, 3)))
    return Q * np.sign(np.linalg.det(Q))[:, None, None]


def rotation(axis, angle):
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K


def about(R, c):
    """[R | t] rotating by R about the point c."""
    return np.hstack([R, (c - R @ c)[:, None]])


def quat(axis, angle):
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    return np.concatenate([[np.cos(angle / 2)], np.sin(angle / 2) * axis])


# ---------------------------------------------------------------------------------------------
# LBS


@pytest.mark.parametrize("d", [2, 3])
def test_lbs_matches_gpytoolbox(d):
    rng = np.random.default_rng(1)
    n, m = 3000, 7
    V = rng.standard_normal((n, d)) * 3
    W = rng.random((n, m))  # need not be a partition of unity
    T = random_affine(m, d, rng)
    U_ref = gpt.linear_blend_skinning(V, W, T[:, :, :d], T[:, :, d])
    U = skinrs.lbs(V, W, T)
    assert U.shape == (n, d) and U.dtype == np.float64
    assert np.abs(U - U_ref).max() < 1e-12 * max(1.0, np.abs(U_ref).max())


def test_lbs_non_contiguous_and_float32_inputs_are_accepted():
    rng = np.random.default_rng(2)
    V = rng.standard_normal((200, 6))[:, ::2]  # strided view
    W = np.asfortranarray(rng.random((200, 4)))
    T = random_affine(4, 3, rng)
    U_ref = gpt.linear_blend_skinning(
        np.ascontiguousarray(V), np.ascontiguousarray(W), T[:, :, :3], T[:, :, 3]
    )
    np.testing.assert_allclose(skinrs.lbs(V, W, T), U_ref, rtol=0, atol=1e-12)
    U32 = skinrs.lbs(V.astype(np.float32), W.astype(np.float32), T)
    np.testing.assert_allclose(U32, U_ref, rtol=0, atol=1e-5 * np.abs(U_ref).max())


def test_lbs_out_is_written_and_returned():
    rng = np.random.default_rng(3)
    V, W, T = rng.standard_normal((100, 3)), rng.random((100, 3)), random_affine(3, 3, rng)
    out = np.full((100, 3), np.nan)
    U = skinrs.lbs(V, W, T, out=out)
    assert U is out
    np.testing.assert_allclose(
        out, gpt.linear_blend_skinning(V, W, T[:, :, :3], T[:, :, 3]), rtol=0, atol=1e-12
    )
    with pytest.raises(ValueError, match="out"):
        skinrs.lbs(V, W, T, out=np.empty((99, 3)))
    with pytest.raises(ValueError, match="out"):
        skinrs.lbs(V, W, T, out=np.empty((100, 3), dtype=np.float32))


@pytest.mark.parametrize("method", ["lbs", "dqs"])
def test_packed_and_dense_agree(method):
    rng = np.random.default_rng(4)
    n, m, k = 5000, 12, 5
    V = rng.standard_normal((n, 3))
    T = np.concatenate([random_rotations(m, rng), rng.standard_normal((m, 3, 1))], axis=2)
    # packed: k slots per row, the last slot of some rows is padding (weight 0, any index)
    I = np.stack([rng.choice(m, size=k, replace=False) for _ in range(n)])
    Wk = rng.random((n, k)) + 0.1
    Wk[::3, -1] = 0.0
    Wk /= Wk.sum(axis=1, keepdims=True)
    W = np.zeros((n, m))
    np.add.at(W, (np.repeat(np.arange(n), k), I.ravel()), Wk.ravel())
    f = getattr(skinrs, method)
    U_dense = f(V, W, T)
    U_packed = f(V, (I, Wk), T)
    U_sparse = f(V, sp.csr_matrix(W), T)
    assert np.abs(U_dense - U_packed).max() < 1e-12
    assert np.abs(U_dense - U_sparse).max() < 1e-12
    # int32 indices work the same
    assert np.abs(f(V, (I.astype(np.int32), Wk), T) - U_packed).max() == 0.0


def test_lbs_normals_follow_the_deformed_surface():
    """With one affine handle the deformed area-weighted normals are exactly cof(A) n."""
    V, F = cylinder(24, 20)
    rng = np.random.default_rng(5)
    A = np.eye(3) + 0.3 * rng.standard_normal((3, 3))
    T = np.hstack([A, rng.standard_normal((3, 1))])[None]
    N = skinrs.per_vertex_normals(V, F)
    U, NU = skinrs.lbs(V, np.ones((len(V), 1)), T, N=N)
    N_ref = igl.per_vertex_normals(U, F, igl.PER_VERTEX_NORMALS_WEIGHTING_TYPE_AREA)
    assert np.abs(NU - N_ref).max() < 1e-12
    assert np.abs(np.linalg.norm(NU, axis=1) - 1).max() < 1e-14


def test_per_vertex_normals_match_libigl():
    V, F = cylinder(30, 25)
    V = V + np.random.default_rng(6).standard_normal(V.shape) * 0.01
    N = skinrs.per_vertex_normals(V, F)
    N_ref = igl.per_vertex_normals(V, F, igl.PER_VERTEX_NORMALS_WEIGHTING_TYPE_AREA)
    assert np.abs(N - N_ref).max() < 1e-12


# ---------------------------------------------------------------------------------------------
# DQS


def test_dqs_equals_lbs_where_influences_coincide():
    """Rotations about one joint: where every influence of a vertex carries the same transform
    (here handles 0/1 share one, 2/3 another), DQS, LBS and the rigid motion agree."""
    rng = np.random.default_rng(7)
    c = np.array([0.3, -0.2, 0.5])
    R1, R2 = rotation([1, 2, 3], 2.5), rotation([-1, 0.5, 0.2], 3.0)
    T = np.stack([about(R1, c), about(R1, c), about(R2, c), about(R2, c)])
    n = 2000
    V = rng.standard_normal((n, 3))
    W = np.zeros((n, 4))
    half = n // 2
    W[:half, 0] = rng.random(half)
    W[:half, 1] = 1 - W[:half, 0]
    W[half:, 2] = rng.random(n - half)
    W[half:, 3] = 1 - W[half:, 2]
    rigid = np.vstack(
        [V[:half] @ T[0, :, :3].T + T[0, :, 3], V[half:] @ T[2, :, :3].T + T[2, :, 3]]
    )
    U_lbs, U_dqs = skinrs.lbs(V, W, T), skinrs.dqs(V, W, T)
    assert np.abs(U_lbs - rigid).max() < 1e-12
    assert np.abs(U_dqs - rigid).max() < 1e-12


def test_dqs_keeps_lengths_where_lbs_collapses():
    """Half-way between 0 and 180 degrees about a joint: LBS collapses points onto the axis,
    DQS rotates them by 90 degrees, keeping their distance to the axis."""
    c = np.array([1.0, 2.0, -1.0])
    axis = np.array([0.0, 0.0, 1.0])
    T = np.stack([about(np.eye(3), c), about(rotation(axis, np.pi), c)])
    rng = np.random.default_rng(8)
    V = c + rng.standard_normal((500, 3))
    W = np.full((500, 2), 0.5)
    radial = lambda X: np.linalg.norm((X - c)[:, :2], axis=1)
    U_lbs, U_dqs = skinrs.lbs(V, W, T), skinrs.dqs(V, W, T)
    assert radial(U_lbs).max() < 1e-12
    np.testing.assert_allclose(radial(U_dqs), radial(V), rtol=1e-12)
    expected = about(rotation(axis, np.pi / 2), c)
    np.testing.assert_allclose(U_dqs, V @ expected[:, :3].T + expected[:, 3], atol=1e-12)


def twisted_cylinder(method, angle):
    V, F = cylinder(48, 60, length=4.0, radius=0.5)
    s = np.clip(V[:, 0] / 4.0, 0, 1)
    w1 = s * s * (3 - 2 * s)  # smoothstep along the cylinder
    W = np.stack([1 - w1, w1], axis=1)
    T = np.stack([about(np.eye(3), np.zeros(3)), about(rotation([1, 0, 0], angle), np.zeros(3))])
    U = getattr(skinrs, method)(V, W, T)
    return signed_volume(U, F) / signed_volume(V, F)


def test_twisted_cylinder_candy_wrapper():
    lbs_ratio = twisted_cylinder("lbs", np.pi)
    dqs_ratio = twisted_cylinder("dqs", np.pi)
    assert lbs_ratio < 0.8, lbs_ratio  # LBS collapses the middle (about 0.49 here)
    assert abs(dqs_ratio - 1) < 0.02, dqs_ratio
    # and at a mild twist both are fine
    assert abs(twisted_cylinder("lbs", 0.3) - 1) < 0.02


def test_dqs_normals_are_rotated():
    rng = np.random.default_rng(9)
    R = rotation([0.2, 1, -0.4], 1.1)
    T = about(R, np.array([0.5, 0.0, 0.1]))[None]
    V, N = rng.standard_normal((50, 3)), rng.standard_normal((50, 3))
    U, NU = skinrs.dqs(V, np.ones((50, 1)), T, N=N)
    np.testing.assert_allclose(NU, N @ R.T, atol=1e-13)
    np.testing.assert_allclose(U, V @ R.T + T[0, :, 3], atol=1e-13)


def test_dqs_2d():
    th = 0.7
    R = np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])
    T = np.stack([np.hstack([np.eye(2), [[0.0], [0.0]]]), np.hstack([R, [[1.0], [2.0]]])])
    V = np.random.default_rng(10).standard_normal((30, 2))
    U = skinrs.dqs(V, np.tile([0.0, 1.0], (30, 1)), T)
    np.testing.assert_allclose(U, V @ R.T + [1.0, 2.0], atol=1e-13)


# ---------------------------------------------------------------------------------------------
# Forward kinematics


def test_fk_identity_pose_is_rest_exactly(data_dir):
    C, BE = read_tgf(data_dir / "hand-403" / "hand.tgf")
    Q = np.tile([1.0, 0, 0, 0], (len(BE), 1))
    T = skinrs.forward_kinematics(C, BE, Q)
    rest = np.tile(np.hstack([np.eye(3), np.zeros((3, 1))]), (len(BE), 1, 1))
    assert T.shape == (20, 3, 4)
    assert np.array_equal(T, rest)


def test_fk_three_bone_chain_known_answer():
    """Chain along x, joints j0..j3 at x = 0..3: 90 deg about z at j0, 90 deg about z at j1,
    90 deg about x at j2. Worked out by hand (innermost rotation first):
    j1 = (0, 1, 0); j2: (2,0,0) -> about j1 -> (1,1,0) -> about j0 -> (-1, 1, 0);
    j3 lies on bone 2's x axis: (3,0,0) -> about j1 -> (1,2,0) -> about j0 -> (-2, 1, 0);
    the off-axis point p = (2,1,0) -> about x at j2 -> (2,0,1) -> about j1 -> (1,1,1)
    -> about j0 -> (-1, 1, 1)."""
    C = np.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 0], [3, 0, 0]])
    BE = np.array([[0, 1], [1, 2], [2, 3]])
    Q = np.array(
        [quat([0, 0, 1], np.pi / 2), quat([0, 0, 1], np.pi / 2), quat([1, 0, 0], np.pi / 2)]
    )
    T = skinrs.forward_kinematics(C, BE, Q)
    apply = lambda b, x: T[b, :, :3] @ np.asarray(x, float) + T[b, :, 3]
    np.testing.assert_allclose(apply(0, C[1]), [0, 1, 0], atol=1e-15)
    np.testing.assert_allclose(apply(1, C[2]), [-1, 1, 0], atol=1e-15)
    np.testing.assert_allclose(apply(2, C[3]), [-2, 1, 0], atol=1e-15)
    np.testing.assert_allclose(apply(2, [2, 1, 0]), [-1, 1, 1], atol=1e-15)
    # absolute rotations compose parent first: R2 = Rz(90) Rz(90) Rx(90)
    R2 = rotation([0, 0, 1], np.pi) @ rotation([1, 0, 0], np.pi / 2)
    np.testing.assert_allclose(T[2, :, :3], R2, atol=1e-15)
    # the bone order in BE does not matter
    perm = [2, 0, 1]
    T2 = skinrs.forward_kinematics(C, BE[perm], Q[perm])
    np.testing.assert_allclose(T2, T[perm], atol=1e-15)


def test_fk_hand_pose_keeps_joints_attached(data_dir):
    C, BE = read_tgf(data_dir / "hand-403" / "hand.tgf")
    Q = skinrs.quaternions_from_xyzw(read_dmat(data_dir / "hand-403" / "hand-pose.dmat"))
    assert Q.shape == (20, 4)
    np.testing.assert_allclose(
        Q[0], [0.75297704283434619, 0.61618142029453848, 0.21865691494778211, -0.074398815808914262]
    )
    T = skinrs.forward_kinematics(C, BE, Q)
    P = skinrs.bone_parents(BE)
    assert (P == -1).sum() == 1
    apply = lambda b, x: T[b, :, :3] @ x + T[b, :, 3]
    for b in range(len(BE)):
        R = T[b, :, :3]
        assert np.abs(R.T @ R - np.eye(3)).max() < 1e-14
        if P[b] >= 0:  # a bone's start joint moves with its parent
            s = C[BE[b, 0]]
            np.testing.assert_allclose(apply(b, s), apply(P[b], s), atol=1e-14)
        L = np.linalg.norm(C[BE[b, 1]] - C[BE[b, 0]])
        assert abs(np.linalg.norm(apply(b, C[BE[b, 1]]) - apply(b, C[BE[b, 0]])) - L) < 1e-14


def test_fk_forest_and_2d():
    C = np.array([[0.0, 0], [1, 0], [5, 5], [5, 6]])
    BE = np.array([[0, 1], [2, 3]])
    T = skinrs.forward_kinematics(C, BE, [np.pi / 2, -np.pi / 2])
    assert T.shape == (2, 2, 3)
    np.testing.assert_allclose(T[0] @ [1.0, 0, 1], [0, 1], atol=1e-15)
    np.testing.assert_allclose(T[1] @ [5.0, 6, 1], [6, 5], atol=1e-15)


def test_fk_nearly_unit_quaternions_are_normalised():
    C = np.array([[0.0, 0, 0], [1, 0, 0]])
    q = quat([0, 1, 0], 0.4)
    T = skinrs.forward_kinematics(C, [[0, 1]], [q * (1 + 1e-4)])
    np.testing.assert_allclose(T[0, :, :3], rotation([0, 1, 0], 0.4), atol=1e-15)


# ---------------------------------------------------------------------------------------------
# Bad input


def test_bad_inputs_raise_value_error():
    rng = np.random.default_rng(11)
    V, W, T = rng.standard_normal((10, 3)), rng.random((10, 2)), random_affine(2, 3, rng)
    with pytest.raises(ValueError, match="W"):
        skinrs.lbs(V, W[:9], T)
    with pytest.raises(ValueError, match="W"):
        skinrs.lbs(V, rng.random((10, 3)), T)
    with pytest.raises(ValueError, match="T"):
        skinrs.lbs(V, W, T[:, :2])
    with pytest.raises(ValueError, match="T"):
        skinrs.lbs(V[:, :2], W, T)  # 2D points need (m, 2, 3)
    Vn = V.copy()
    Vn[4, 1] = np.nan
    with pytest.raises(ValueError, match=r"V has a NaN.*row 4"):
        skinrs.lbs(Vn, W, T)
    Wn = W.copy()
    Wn[7, 0] = np.inf
    with pytest.raises(ValueError, match=r"W has a NaN.*row 7"):
        skinrs.lbs(V, Wn, T)
    Tn = T.copy()
    Tn[1, 0, 0] = np.nan
    with pytest.raises(ValueError, match=r"T\[1\]"):
        skinrs.lbs(V, W, Tn)
    I = np.zeros((10, 2), dtype=np.int64)
    I[3, 1] = 2
    with pytest.raises(ValueError, match=r"\(3, 1\) is 2"):
        skinrs.lbs(V, (I, W), T)
    Tr = np.stack([about(rotation([0, 0, 1], 0.3), np.zeros(3))] * 2)
    I[3, 1] = -1
    with pytest.raises(ValueError, match="outside"):
        skinrs.dqs(V, (I, W), Tr)
    with pytest.raises(ValueError, match="same shape"):
        skinrs.lbs(V, (I[:, :1], W), T)
    with pytest.raises(ValueError, match="rigid"):
        skinrs.dqs(V, W, T)  # affine, not rigid
    Wz = W.copy()
    Wz[5] = 0.0
    with pytest.raises(ValueError, match="vertex 5"):
        skinrs.dqs(V, Wz, Tr)
    with pytest.raises(ValueError, match="numbers"):
        skinrs.lbs(V, np.array([["a", "b"]] * 10), T)


def test_bad_skeletons_and_quaternions_raise_value_error():
    C = np.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 0]])
    ident = [[1.0, 0, 0, 0]] * 2
    with pytest.raises(ValueError, match="not a unit quaternion"):
        skinrs.forward_kinematics(C, [[0, 1], [1, 2]], [[1.0, 0, 0, 0], [0.5, 0, 0, 0]])
    with pytest.raises(ValueError, match="cycle"):
        skinrs.forward_kinematics(C, [[0, 1], [1, 0]], ident)
    with pytest.raises(ValueError, match="child end"):
        skinrs.forward_kinematics(C, [[0, 2], [1, 2]], ident)
    with pytest.raises(ValueError, match="BE"):
        skinrs.forward_kinematics(C, [[0, 3], [1, 2]], ident)
    with pytest.raises(ValueError, match="Q"):
        skinrs.forward_kinematics(C, [[0, 1], [1, 2]], ident[:1])
    with pytest.raises(ValueError, match="multiple of 4"):
        skinrs.quaternions_from_xyzw(np.zeros(7))
