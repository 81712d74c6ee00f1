"""Meshing with the skeleton inside (TetGen / Triangle through optional packages) and weights on
the user's own vertices. Samples are re-derived here from the paper's rule (Sec. 7) and found
geometrically in the volume mesh; weights are checked for the BBW properties."""

import itertools
import sys
from pathlib import Path

import numpy as np
import pytest
import skinrs
from _skin_data import cylinder, read_mesh, read_obj, read_tgf
from scipy.spatial import cKDTree
from skinrs import meshing


def mean_edge_length(V, F):
    E = np.unique(np.sort(np.vstack([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1), axis=0)
    return np.linalg.norm(V[E[:, 0]] - V[E[:, 1]], axis=1).mean()


def expected_samples(C, BE, rho):
    """About two samples per average edge length, at least two per bone, endpoints included."""
    out = []
    for i, j in BE:
        L = np.linalg.norm(C[j] - C[i])
        k = max(2, int(np.ceil(2 * L / rho)) + 1)
        out.append(C[i] + np.linspace(0, 1, k)[:, None] * (C[j] - C[i]))
    return np.vstack(out)


def check_weights(W, Wv, b, bc):
    assert W.min() >= 0.0
    assert np.abs(W.sum(axis=1) - 1).max() < 1e-12
    assert Wv.min() >= 0.0
    assert np.array_equal(Wv[b], bc)  # constrained rows hold exactly


def check_bc(Vv, b, bc, C, BE):
    """Each constrained vertex lies on its bones (1e-12), one-hot off the joints, and a joint is
    shared equally by the bones meeting there."""
    for v, row in zip(b, bc, strict=True):
        bones = np.flatnonzero(row)
        np.testing.assert_allclose(row[bones], 1.0 / len(bones), rtol=0, atol=1e-15)
        for e in bones:
            a, c = C[BE[e, 0]], C[BE[e, 1]]
            t = np.clip((Vv[v] - a) @ (c - a) / ((c - a) @ (c - a)), 0, 1)
            assert np.linalg.norm(a + t * (c - a) - Vv[v]) < 1e-12
        if len(bones) > 1:  # only joints are shared
            joint = [j for j in np.unique(BE) if np.array_equal(Vv[v], C[j])]
            assert len(joint) == 1
            assert len(bones) == np.sum(BE == joint[0])


@pytest.fixture(scope="module")
def arm(data_dir):
    V, F = read_obj(data_dir / "arm" / "arm.obj")
    C, BE = read_tgf(data_dir / "arm" / "arm.tgf")
    W, vol = skinrs.skin_weights(V, F, C, BE, tol=1e-3, return_mesh=True)
    return V, F, C, BE, W, vol


def test_arm_volume_mesh_has_every_bone_sample_as_a_vertex(arm):
    V, F, C, BE, _, vol = arm
    Vv, T, b = vol["V"], vol["T"], vol["b"]
    assert np.array_equal(Vv[: len(V)], V)  # surface vertices unchanged, first rows
    S = expected_samples(C, BE, mean_edge_length(V, F))
    d, idx = cKDTree(Vv).query(S)
    assert d.max() <= 1e-12, d.max()
    # the constrained vertices are exactly the samples (joints counted once)
    assert np.array_equal(np.unique(idx), np.sort(b))
    X = Vv[T]
    vols = np.einsum("ij,ij->i", X[:, 1] - X[:, 0], np.cross(X[:, 2] - X[:, 0], X[:, 3] - X[:, 0]))
    assert np.abs(vols).min() > 0
    check_bc(Vv, b, vol["bc"], C, BE)
    # the lead's geometric detection of vertices on bones finds the same constraints
    b2, bc2 = skinrs.boundary_conditions(Vv, C, BE=BE, tol=1e-9)
    assert np.array_equal(b2, np.sort(b))
    np.testing.assert_allclose(bc2, vol["bc"][np.argsort(b)], atol=1e-15)


def test_arm_skin_weights(arm):
    V, _, C, BE, W, vol = arm
    assert W.shape == (len(V), len(BE))
    check_weights(W, vol["W"], vol["b"], vol["bc"])
    np.testing.assert_array_equal(W, vol["W"][: len(V)])
    # each bone dominates the surface around its middle
    for e, (i, j) in enumerate(BE):
        mid = (C[i] + C[j]) / 2
        near = np.argsort(np.linalg.norm(V - mid, axis=1))[:20]
        assert np.all(W[near].argmax(axis=1) == e)


def test_hand_skin_weights(data_dir):
    V, F, _ = read_mesh(data_dir / "hand-403" / "hand.mesh")
    C, BE = read_tgf(data_dir / "hand-403" / "hand.tgf")
    W, vol = skinrs.skin_weights(V, F, C, BE, tol=1e-3, return_mesh=True)
    assert W.shape == (len(V), 20)
    assert np.array_equal(vol["V"][: len(V)], V)
    check_weights(W, vol["W"], vol["b"], vol["bc"])
    check_bc(vol["V"], vol["b"], vol["bc"], C, BE)
    # joint 2 (index 1) is the wrist hub where 6 bones meet: 1/6 each
    hub = vol["b"][np.flatnonzero([np.array_equal(vol["V"][v], C[1]) for v in vol["b"]])]
    assert len(hub) == 1
    row = vol["W"][hub[0]]
    assert np.array_equal(np.flatnonzero(row), np.flatnonzero((BE == 1).any(axis=1)))
    np.testing.assert_allclose(row[row > 0], 1 / 6, rtol=0, atol=1e-15)
    S = expected_samples(C, BE, mean_edge_length(V, F))
    assert cKDTree(vol["V"]).query(S)[0].max() <= 1e-12


def test_2d_outline_bones_are_vertices_and_segments():
    # an L-shaped outline with a two-bone skeleton around the corner
    V = np.array([[0.0, 0], [4, 0], [4, 4], [3, 4], [3, 1], [0, 1]])
    C = np.array([[0.5, 0.5], [3.5, 0.5], [3.5, 3.5]])
    BE = np.array([[0, 1], [1, 2]])
    W, vol = skinrs.skin_weights(V, None, C, BE, tol=1e-6, return_mesh=True)
    Vv, T, b = vol["V"], vol["T"], vol["b"]
    assert np.array_equal(Vv[:6], V)
    check_weights(W, vol["W"], b, vol["bc"])
    check_bc(Vv, b, vol["bc"], C, BE)
    # the bones are edges of the triangulation between consecutive samples
    edges = {tuple(sorted(e)) for t in T for e in ((t[0], t[1]), (t[1], t[2]), (t[2], t[0]))}
    for e in range(2):
        on = b[vol["bc"][:, e] > 0]
        on = on[np.argsort(np.linalg.norm(Vv[on] - C[BE[e, 0]], axis=1))]
        assert all(tuple(sorted(p)) in edges for p in itertools.pairwise(on))
    # no triangle outside the L (the notch x > 3, y > 1 is not part of it... it is; the
    # missing part is 0 <= x < 3, 1 < y <= 4)
    cent = Vv[T].mean(axis=1)
    assert not np.any((cent[:, 0] < 3) & (cent[:, 1] > 1))
    area = 0.5 * np.abs(np.cross(Vv[T[:, 1]] - Vv[T[:, 0]], Vv[T[:, 2]] - Vv[T[:, 0]])).sum()
    assert abs(area - 7.0) < 1e-12


def test_2d_vertices_triangle_adds_on_a_bone_are_held():
    # An area bound far below the sample spacing makes Triangle split the bone segments; the
    # vertices it adds there lie on the bone and must be constrained like its samples, or the
    # bone's weight sags between them.
    V = np.array([[0.0, 0], [4, 0], [4, 1], [0, 1]])
    C = np.array([[0.5, 0.5], [3.5, 0.5]])
    BE = np.array([[0, 1]])
    Vv, _T, b, bc = skinrs.mesh_with_skeleton(V, None, C, BE, flags="pq30a0.001")
    samples = expected_samples(C, BE, rho=2.5)  # the outline's mean edge length
    t = np.clip((Vv - C[0]) @ (C[1] - C[0]) / 9.0, 0, 1)
    on_bone = np.flatnonzero(np.linalg.norm(C[0] + t[:, None] * (C[1] - C[0]) - Vv, axis=1)
                             < 1e-12)  # fmt: skip
    assert len(on_bone) > 2 * len(samples)  # Triangle did add vertices on the bone
    np.testing.assert_array_equal(np.sort(b), on_bone)
    np.testing.assert_array_equal(bc, np.ones((len(b), 1)))
    check_bc(Vv, b, bc, C, BE)


def test_2d_triangle_mesh_keeps_its_vertices():
    z = np.load(Path(__file__).resolve().parent / "reference" / "bar.npz")  # made by `triangle`
    V, F = np.c_[z["V"], np.zeros(len(z["V"]))], z["T"]  # a z = 0 column, as in 2D OBJ files
    C, BE = np.c_[z["C"], np.zeros(len(z["C"]))], z["BE"]
    Vv, T, b, bc = skinrs.mesh_with_skeleton(V, F, C, BE)
    assert Vv.shape[1] == 3 and np.array_equal(Vv[: len(V)], V)
    S = expected_samples(C[:, :2], BE, mean_edge_length(V[:, :2], F))
    assert cKDTree(Vv[:, :2]).query(S)[0].max() <= 1e-12
    check_bc(Vv[:, :2], b, bc, C[:, :2], BE)
    assert T.shape[1] == 3 and len(np.unique(T)) == len(Vv)


def test_2d_vertices_next_to_the_skeleton_become_its_samples():
    # A joint 1e-7 from one vertex of the mesh and a bone passing 1e-7 from another: inserted
    # as they are, each makes a sliver with a cotangent ~1e7 (B entries ~1e14), which slows
    # the solve by orders of magnitude. Those vertices must hold the samples instead.
    import igl

    z = np.load(Path(__file__).resolve().parent / "reference" / "bar.npz")
    V, F = z["V"], z["T"]
    inner = np.flatnonzero(np.abs(V[:, 1]) < 0.1)
    p = inner[np.argmin(np.linalg.norm(V[inner] - [-0.6, 0.0], axis=1))]
    r = inner[np.argmin(np.linalg.norm(V[inner] - [0.0, 0.0], axis=1))]
    C0 = V[p] + [1e-7, 0.0]
    along = (V[r] - C0) / np.linalg.norm(V[r] - C0)
    C1 = C0 + 2 * (V[r] + 1e-7 * np.array([-along[1], along[0]]) - C0)
    Vv, T, b, bc = skinrs.mesh_with_skeleton(V, F, np.array([C0, C1]), np.array([[0, 1]]))
    assert np.array_equal(Vv[: len(V)], V)
    assert p in b and r in b
    np.testing.assert_array_equal(bc, np.ones((len(b), 1)))
    area = igl.doublearea(Vv, T) / 2
    around = np.isin(T, [p, r]).any(axis=1)
    assert area[around].min() >= 1e-2 * np.median(area)


# ---------------------------------------------------------------------------------------------
# Skeletons partly or wholly outside, missing packages, fallback mesher


@pytest.fixture
def tube():
    V, F = cylinder(24, 30, length=4.0, radius=0.5)
    C = np.array([[0.2, 0, 0], [2.0, 0, 0], [3.8, 0, 0]])
    return V, F, C, np.array([[0, 1], [1, 2]])


def test_bone_partly_outside_warns_and_keeps_inside_samples(tube):
    V, F, C, BE = tube
    C = C.copy()
    C[2] = [6.0, 0, 0]  # the second bone ends 2 units past the cap: half of it outside
    with pytest.warns(meshing.MeshingWarning, match=r"bone 1 is partly outside.*\(5\d%"):
        Vv, _T, b, bc = skinrs.mesh_with_skeleton(V, F, C, BE)
    assert np.all(Vv[b, 0] <= 4.0)
    assert np.array_equal(Vv[: len(V)], V)
    assert bc[:, 1].sum() > 1


def test_bone_wholly_outside_is_an_error(tube):
    V, F, C, BE = tube
    C = np.vstack([C, [[0.0, 3, 0], [1.0, 3, 0]]])
    BE = np.vstack([BE, [[3, 4]]])
    with pytest.raises(ValueError, match="bone 2 lies wholly outside"):
        skinrs.mesh_with_skeleton(V, F, C, BE)


def test_missing_meshing_package_says_what_to_install(tube, monkeypatch):
    V, F, C, BE = tube
    monkeypatch.setitem(sys.modules, "tetgen", None)
    with pytest.raises(ImportError, match=r"pip install skinrs\[mesh\]"):
        skinrs.mesh_with_skeleton(V, F, C, BE)
    monkeypatch.setitem(sys.modules, "triangle", None)
    with pytest.raises(ImportError, match=r"pip install skinrs\[mesh\]"):
        square = np.array([[0.0, 0], [1, 0], [1, 1], [0, 1]])
        skinrs.mesh_with_skeleton(square, None, np.array([[0.2, 0.5], [0.8, 0.5]]), [[0, 1]])


def test_tetgen_failure_without_fallback_is_a_clear_error(tube, monkeypatch):
    V, F, C, BE = tube

    def broken(*args, **kw):
        raise RuntimeError("Failed to tetrahedralize")

    monkeypatch.setattr(meshing, "_tetgen", broken)
    monkeypatch.setitem(sys.modules, "pytetwild", None)
    with pytest.raises(ImportError, match=r"TetGen failed.*pytetwild.*pip install skinrs\[mesh\]"):
        skinrs.mesh_with_skeleton(V, F, C, BE)


def test_bad_arguments(tube):
    V, F, C, BE = tube
    with pytest.raises(ValueError, match="no handles"):
        skinrs.mesh_with_skeleton(V, F, C)
    with pytest.raises(ValueError, match="triangles F"):
        skinrs.mesh_with_skeleton(V, None, C, BE)
    with pytest.raises(ValueError, match="BE"):
        skinrs.mesh_with_skeleton(V, F, C, [[0, 5]])
    with pytest.raises(ValueError, match="zero length"):
        skinrs.mesh_with_skeleton(V, F, C, [[0, 0]])
    with pytest.raises(ValueError, match="point handle 0 lies outside"):
        skinrs.mesh_with_skeleton(V, F, np.vstack([C, [[0, 5.0, 0]]]), BE, P=[3])


def test_fallback_remeshes_the_repaired_surface_and_interpolates_weights(tube, monkeypatch):
    """TetGen fails on the input; the fallback's clean boundary is meshed again with the samples
    inserted exactly, and skin_weights interpolates the weights back to the input vertices."""
    V, F, C, BE = tube
    real, calls = meshing._tetgen, []

    def first_fails(*args, **kw):
        calls.append(1)
        if len(calls) == 1:
            raise RuntimeError("Failed to tetrahedralize")
        return real(*args, **kw)

    def fallback(V, F, S, verbose, **options):  # stands in for fTetWild (no samples)
        return real(V, F, np.zeros((0, 3)), "pq1.5YQ", verbose)

    monkeypatch.setattr(meshing, "_tetgen", first_fails)
    monkeypatch.setattr(meshing, "_tetwild", fallback)
    with pytest.warns(meshing.MeshingWarning, match="repaired surface"):
        W, vol = skinrs.skin_weights(V, F, C, BE, tol=1e-3, return_mesh=True)
    S = expected_samples(C, BE, mean_edge_length(V, F))
    assert cKDTree(vol["V"][vol["b"]]).query(S)[0].max() == 0.0
    check_bc(vol["V"], vol["b"], vol["bc"], C, BE)
    assert W.shape == (len(V), 2) and W.min() >= 0
    assert np.abs(W.sum(axis=1) - 1).max() < 1e-12
    assert np.all(W[V[:, 0] < 0.5].argmax(axis=1) == 0)
    assert np.all(W[V[:, 0] > 3.5].argmax(axis=1) == 1)


def test_point_handles_come_first(tube):
    V, F, C, BE = tube
    C = np.vstack([C, [[3.0, 0.2, 0.1]]])
    W, vol = skinrs.skin_weights(V, F, C, BE, P=[3], tol=1e-3, return_mesh=True)
    b, bc, Vv = vol["b"], vol["bc"], vol["V"]
    assert W.shape == (len(V), 3) and bc.shape[1] == 3
    handle = b[bc[:, 0] == 1.0]
    assert len(handle) == 1 and np.array_equal(Vv[handle[0]], C[3])
    assert np.all(bc[bc[:, 0] > 0, 1:] == 0)
    check_bc(Vv, b[bc[:, 0] == 0], bc[bc[:, 0] == 0][:, 1:], C, BE)
    check_weights(W, vol["W"], b, bc)


# --- the real fallback: pytetwild (fTetWild) on a surface TetGen rejects ----------------------


@pytest.fixture(scope="module")
def crossing_tubes():
    """Two overlapping closed tubes, the second bent by 50 degrees (an elbow modelled as two
    intersecting parts, as artists do): a self-intersecting surface that TetGen rejects. One bone
    runs along each tube."""
    c, s = np.cos(np.radians(50)), np.sin(np.radians(50))
    R = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    V1, F1 = cylinder(12, 10, length=2.5, radius=0.5)
    V2, F2 = cylinder(12, 10, length=2.5, radius=0.5)
    V2 = (V2 - [0.4, 0, 0]) @ R.T + [2.1, 0, 0]
    V, F = np.vstack([V1, V2]), np.vstack([F1, F2 + len(V1)])
    C = np.array([[0.2, 0, 0], [2.1, 0, 0], [2.1, 0, 0] + R @ [1.9, 0, 0]])
    return V, F, C, np.array([[0, 1], [1, 2]])


def _tubes_checks(V, F, C, BE, W, vol):
    Vv, T, b, bc = vol["V"], vol["T"], vol["b"], vol["bc"]
    S = expected_samples(C, BE, mean_edge_length(V, F))
    assert cKDTree(Vv[b]).query(S)[0].max() == 0.0  # every bone sample is a vertex, exactly
    assert len(b) == len(np.unique(b)) == len(S) - 1  # the shared joint once
    check_bc(Vv, b, bc, C, BE)
    assert meshing._tet_volumes(Vv, T).min() > 0  # no inverted or flat tet
    check_weights(vol["W"], vol["W"], b, bc)  # volume weights: >= 0, rows sum to 1, bc exact
    assert W.shape == (len(V), 2) and W.min() >= 0.0
    assert np.abs(W.sum(axis=1) - 1).max() < 1e-12
    # far ends of the tubes follow their own bone
    far0 = np.linalg.norm(V - C[0], axis=1) < 0.6
    far1 = np.linalg.norm(V - C[2], axis=1) < 0.6
    assert np.all(W[far0].argmax(axis=1) == 0) and np.all(W[far1].argmax(axis=1) == 1)


def test_tetgen_rejects_crossing_tubes_and_pytetwild_meshes_them(
    crossing_tubes, tmp_path, monkeypatch
):
    """Real fallback: TetGen refuses the self-intersecting surface, fTetWild repairs it, and
    TetGen meshes the repaired boundary with every bone sample inserted exactly."""
    import pytetwild  # noqa: F401 - installed by `make venv`; a missing package is a failure

    monkeypatch.chdir(tmp_path)  # TetGen and fTetWild write scratch files here; none may stay
    V, F, C, BE = crossing_tubes
    assert meshing._self_intersects(V, F)
    with pytest.raises(RuntimeError, match="self-intersections"):
        meshing._tetgen(V, F, np.zeros((0, 3)), "pq2YQ", False)  # (no samples: TetGen is sane)
    with pytest.warns(meshing.MeshingWarning, match="fTetWild's repaired surface"):
        W, vol = skinrs.skin_weights(V, F, C, BE, tol=1e-3, return_mesh=True)
    _tubes_checks(V, F, C, BE, W, vol)
    assert list(tmp_path.iterdir()) == []


def test_pytetwild_fallback_snaps_nearest_vertices_onto_bone_samples(
    crossing_tubes, tmp_path, monkeypatch
):
    """Last resort, with the real fTetWild: when TetGen fails on the repaired boundary too, the
    nearest interior fTetWild vertices are moved onto the samples (no tet inverted), samples
    left without a movable vertex are inserted, and the warning reports the snapping distance.
    fTetWild is randomised (even single-threaded), so which samples are inserted varies."""
    import pytetwild  # noqa: F401

    monkeypatch.chdir(tmp_path)
    V, F, C, BE = crossing_tubes

    def refuses(*args, **kw):  # TetGen also refuses fTetWild's boundary
        raise RuntimeError("Failed to tetrahedralize")

    seen = {}
    real_snap = meshing._snap

    def spy(Vw, Tw, S, **kw):  # records the real snapping (inputs and answer), changes nothing
        out = real_snap(Vw, Tw, S, **kw)
        seen.update(Vw=Vw.copy(), Tw=Tw.copy(), S=S, idx=out[2], dist=out[3])
        return out

    monkeypatch.setattr(meshing, "_tetgen", refuses)
    monkeypatch.setattr(meshing, "_snap", spy)
    with pytest.warns(meshing.MeshingWarning, match=r"moved \d+ volume vertices") as rec:
        W, vol = skinrs.skin_weights(V, F, C, BE, tol=1e-3, return_mesh=True)
    _tubes_checks(V, F, C, BE, W, vol)
    Vw, S, idx, dist = seen["Vw"], seen["S"], seen["idx"], seen["dist"]
    moved = idx < len(Vw)
    np.testing.assert_allclose(
        dist[moved], np.linalg.norm(Vw[idx[moved]] - S[moved], axis=1), rtol=0, atol=1e-15
    )
    assert np.all(dist[~moved] == 0)
    assert moved.sum() >= 0.8 * len(S)  # insertion is the exception
    msg = next(str(w.message) for w in rec if "snapping distance" in str(w.message))
    largest = float(msg.split("largest ")[1].split(",")[0])
    assert largest == pytest.approx(dist.max(), rel=1e-2)
    assert f"moved {moved.sum()} volume vertices" in msg
    assert ("inserted" in msg) == (not moved.all())
    # each sample took a vertex near it: within one target edge length of fTetWild's mesh
    rho = mean_edge_length(V, F)
    assert dist.max() <= rho
    # old vertices that changed were moved onto samples; inserted ones come after them
    Vv = vol["V"]
    assert len(Vv) == len(Vw) + (~moved).sum()
    changed = np.flatnonzero(np.any(Vv[: len(Vw)] != Vw, axis=1))
    assert set(changed) <= set(idx[moved].tolist())
    assert np.array_equal(Vv[idx], S)
    assert meshing._boundary_faces(vol["T"]).shape == meshing._boundary_faces(seen["Tw"]).shape
    assert list(tmp_path.iterdir()) == []


def kuhn_cube(n):
    """The unit cube cut into n^3 cells of 6 positively oriented tets each (deterministic)."""
    g = np.linspace(0, 1, n + 1)
    V = np.stack(np.meshgrid(g, g, g, indexing="ij"), -1).reshape(-1, 3)
    vid = np.arange(len(V)).reshape(n + 1, n + 1, n + 1)
    T = []
    for i, j, k in itertools.product(range(n), repeat=3):
        for perm in itertools.permutations(range(3)):
            corner, path = np.array([i, j, k]), [vid[i, j, k]]
            for axis in perm:
                corner[axis] += 1
                path.append(vid[tuple(corner)])
            T.append(path)
    T = np.array(T)
    flip = meshing._tet_volumes(V, T) < 0
    T[flip] = T[flip][:, [0, 1, 3, 2]]
    return V, T


def check_conforming(V, T, V0, T0):
    """Tets positive, every interior face shared by two tets, boundary and volume unchanged."""
    vol = meshing._tet_volumes(V, T)
    assert vol.min() > 1e-3 * vol.mean()
    faces = np.sort(T[:, [[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]]].reshape(-1, 3), axis=1)
    _, count = np.unique(faces, axis=0, return_counts=True)
    assert count.max() == 2
    before = np.sort(np.sort(meshing._boundary_faces(T0), axis=1), axis=0)
    after = np.sort(np.sort(meshing._boundary_faces(T), axis=1), axis=0)
    assert np.array_equal(before, after)
    assert vol.sum() == pytest.approx(meshing._tet_volumes(V0, T0).sum(), rel=1e-12)


@pytest.mark.parametrize(
    ("p", "fan"),
    [
        ([0.31, 0.47, 0.52], 4),  # inside a tet: 1 -> 4
        ([0.25, 0.4, 0.25], 6),  # on a face shared by two tets: 2 -> 6
        ([0.75, 0.75, 0.75], 12),  # on a cell diagonal, an edge of six tets: 6 -> 12
        ([0.5005, 0.5, 0.5002], 24),  # next to a vertex: the cavity grows past the slivers
    ],
)
def test_insert_vertex_refans_a_cavity_around_the_point(p, fan):
    V0, T0 = kuhn_cube(2)
    vmin = 1e-3 * meshing._tet_volumes(V0, T0).mean()
    p = np.array(p)
    V, T, q = meshing._insert_vertex(V0, T0, p, vmin)
    assert q == len(V0) and np.array_equal(V[q], p) and np.array_equal(V[:q], V0)
    assert np.any(T == q, axis=1).sum() == fan
    check_conforming(V, T, V0, T0)


def test_insert_vertex_refuses_points_on_the_surface_or_outside():
    V0, T0 = kuhn_cube(2)
    vmin = 1e-3 * meshing._tet_volumes(V0, T0).mean()
    with pytest.raises(ValueError, match=r"on or next to the surface"):
        meshing._insert_vertex(V0, T0, np.array([0.3, 0.2, 0.0]), vmin)
    with pytest.raises(ValueError, match=r"outside the fallback mesh"):
        meshing._insert_vertex(V0, T0, np.array([0.3, 0.2, 1.5]), vmin)


def test_snap_inserts_samples_whose_near_vertices_cannot_move():
    """With one candidate vertex per sample, samples sharing a nearest vertex (or whose nearest
    vertex is on the surface) must be inserted; every sample ends exactly on a vertex."""
    V0, T0 = kuhn_cube(4)
    S = np.c_[np.linspace(0.2, 0.8, 9), np.full(9, 0.45), np.full(9, 0.55)]
    Vv, T, idx, dist = meshing._snap(V0, T0, S, k=1)
    assert np.array_equal(Vv[idx], S) and len(np.unique(idx)) == len(S)
    inserted = idx >= len(V0)
    assert 0 < inserted.sum() < len(S)
    assert np.all(dist[inserted] == 0) and np.all(dist[~inserted] > 0)
    assert len(Vv) == len(V0) + inserted.sum()
    check_conforming(Vv, T, V0, T0)


def test_self_intersecting_surface_without_pytetwild_says_what_to_do(crossing_tubes, monkeypatch):
    V, F, C, BE = crossing_tubes
    monkeypatch.setitem(sys.modules, "pytetwild", None)
    with pytest.raises(
        ImportError, match=r"self-intersections.*pytetwild.*pip install skinrs\[mesh\].*repair"
    ):
        skinrs.mesh_with_skeleton(V, F, C, BE)
