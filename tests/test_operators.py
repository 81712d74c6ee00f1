"""Discrete operators against libigl (cotmatrix, massmatrix) and scipy (B = L^T M^-1 L, graph
components), plus the errors for bad meshes."""

import igl
import numpy as np
import pytest
import scipy.sparse as sp
import skinrs
from scipy.sparse.csgraph import connected_components as scipy_components
from skinrs.operators import connected_components

TOL = 1e-10

MESHES = {
    "woody-2d": "woody-2d/woody.obj",
    "spot-surface": "spot/spot_low_resolution.obj",
    "arm-surface": "arm/arm.obj",
    "knight-tets": "decimated-knight/decimated-knight.mesh",
    "hand-tets": "hand-403/hand.mesh",
}
IGL_MASS = {"voronoi": igl.MASSMATRIX_TYPE_VORONOI, "barycentric": igl.MASSMATRIX_TYPE_BARYCENTRIC}

_cache = {}


def load(data_dir, name):
    """(V, F) with F triangles or tets; the 2D mesh loses its z = 0 column."""
    if name not in _cache:
        path = str(data_dir / MESHES[name])
        if path.endswith(".mesh"):
            V, F, _ = igl.readMESH(path)
        else:
            V, F = igl.read_triangle_mesh(path)[:2]
        if name.endswith("2d"):
            assert np.all(V[:, 2] == 0)
            V = V[:, :2]
        _cache[name] = (
            np.ascontiguousarray(V, dtype=np.float64),
            np.ascontiguousarray(F, np.int64),
        )
    return _cache[name]


def rel_err(A, B):
    """max |A - B| / max |B| for sparse or dense arrays of the same shape."""
    assert A.shape == B.shape, (A.shape, B.shape)
    D = sp.csc_matrix(A) - sp.csc_matrix(B)
    return abs(D).max() / abs(sp.csc_matrix(B)).max()


def igl_mass(V, F, kind):
    """Diagonal of igl.massmatrix padded to #V (igl sizes triangle mass matrices by max(F)+1)."""
    m = np.asarray(igl.massmatrix(V, F, IGL_MASS[kind]).diagonal())
    return np.pad(m, (0, V.shape[0] - m.shape[0]))


@pytest.fixture(params=list(MESHES))
def mesh(request, data_dir):
    return load(data_dir, request.param)


def test_cotan_laplacian_matches_igl(mesh):
    V, F = mesh
    L = skinrs.cotan_laplacian(V, F)
    assert isinstance(L, sp.csc_matrix) and L.shape == (V.shape[0],) * 2
    assert rel_err(L, igl.cotmatrix(V, F)) < TOL
    # libigl's convention: symmetric (exactly), non-positive diagonal, zero row sums.
    assert abs(L - L.T).max() == 0
    assert L.diagonal().max() <= 0
    assert abs(L @ np.ones(V.shape[0])).max() < 1e-12 * abs(L).max()


@pytest.mark.parametrize("kind", ["voronoi", "barycentric"])
def test_massmatrix_matches_igl(mesh, kind):
    V, F = mesh
    M = skinrs.massmatrix(V, F, kind)
    assert isinstance(M, sp.csc_matrix) and M.shape == (V.shape[0],) * 2
    assert (M - sp.diags(M.diagonal())).nnz == 0
    ref = igl_mass(V, F, kind)
    m = M.diagonal()
    assert np.abs(m - ref).max() / np.abs(ref).max() < TOL
    assert m.min() > 0


@pytest.mark.parametrize("kind", ["voronoi", "barycentric"])
def test_biharmonic_matches_scipy_product_of_igl_matrices(mesh, kind):
    V, F = mesh
    L = igl.cotmatrix(V, F)
    m = igl_mass(V, F, kind)
    ref = L.T @ sp.diags(1.0 / (m / m.max())) @ L
    B = skinrs.biharmonic_matrix(V, F, mass=kind)
    assert isinstance(B, sp.csc_matrix) and B.shape == ref.shape
    assert rel_err(B, ref) < TOL
    assert (B != B.T).nnz == 0  # built exactly symmetric
    assert abs(B @ np.ones(V.shape[0])).max() < 1e-10 * abs(B).max()


def test_default_mass_is_voronoi(data_dir):
    V, F = load(data_dir, "knight-tets")
    assert (skinrs.massmatrix(V, F) != skinrs.massmatrix(V, F, "voronoi")).nnz == 0
    B = skinrs.biharmonic_matrix(V, F)
    assert (B != skinrs.biharmonic_matrix(V, F, mass="voronoi")).nnz == 0
    # the two lumpings really differ on this mesh, so the tests above tell them apart
    m_v = skinrs.massmatrix(V, F, "voronoi").diagonal()
    m_b = skinrs.massmatrix(V, F, "barycentric").diagonal()
    assert np.abs(m_v - m_b).max() > 1e-3 * m_b.max()


def test_2d_orientation_does_not_matter(data_dir):
    V, F = load(data_dir, "woody-2d")
    G = F.copy()
    G[::2] = G[::2, ::-1]  # every other triangle clockwise
    L, LG = skinrs.cotan_laplacian(V, F), skinrs.cotan_laplacian(V, G)
    assert rel_err(LG, L) < 1e-14
    assert rel_err(LG, igl.cotmatrix(V, G)) < TOL
    for kind in IGL_MASS:
        mG = skinrs.massmatrix(V, G, kind).diagonal()
        assert np.abs(mG - igl_mass(V, G, kind)).max() / mG.max() < TOL


def test_small_hand_computed_cases():
    V = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    F = np.array([[0, 1, 2]])
    L = skinrs.cotan_laplacian(V, F).toarray()
    np.testing.assert_allclose(L, [[-1, 0.5, 0.5], [0.5, -0.5, 0], [0.5, 0, -0.5]], atol=1e-15)
    m = skinrs.massmatrix(V, F, "voronoi").diagonal()
    np.testing.assert_allclose(m, [0.25, 0.125, 0.125], rtol=1e-15)
    m = skinrs.massmatrix(V, F, "barycentric").diagonal()
    np.testing.assert_allclose(m, [1 / 6] * 3, rtol=1e-15)
    # An unused vertex gets an empty row/column and zero mass.
    V4 = np.vstack([V, [[3.0, 3.0]]])
    assert skinrs.cotan_laplacian(V4, F).getcol(3).nnz == 0
    assert skinrs.massmatrix(V4, F).diagonal()[3] == 0
    assert skinrs.biharmonic_matrix(V4, F).shape == (4, 4)


# --- bad input ------------------------------------------------------------------------------


def with_extra_element(V, F, corners, new_points):
    """Appends points and one element made of existing/new vertex indices."""
    V2 = np.vstack([V, new_points]) if len(new_points) else V
    return V2, np.vstack([F, [corners]])


@pytest.mark.parametrize("op", ["cotan", "mass", "biharmonic"])
def test_degenerate_triangle_is_named(data_dir, op):
    V, F = load(data_dir, "woody-2d")
    a, b = F[0, 0], F[0, 1]
    n, m = V.shape[0], F.shape[0]
    V2, F2 = with_extra_element(V, F, [a, b, n], [(V[a] + V[b]) / 2])  # collinear
    fn = {
        "cotan": skinrs.cotan_laplacian,
        "mass": skinrs.massmatrix,
        "biharmonic": skinrs.biharmonic_matrix,
    }[op]
    with pytest.raises(ValueError, match=rf"triangle {m} .*degenerate"):
        fn(V2, F2)


def test_degenerate_surface_triangle_is_named(data_dir):
    V, F = load(data_dir, "spot-surface")
    F2 = F.copy()
    V2 = V.copy()
    V2[F2[40, 2]] = V2[F2[40, 0]] * 0.3 + V2[F2[40, 1]] * 0.7  # moves a vertex onto an edge
    with pytest.raises(ValueError, match=r"triangle \d+ .*degenerate"):
        skinrs.cotan_laplacian(V2, F2)


def test_inverted_tet_is_named(data_dir):
    V, T = load(data_dir, "knight-tets")
    T2 = T.copy()
    T2[17, [0, 1]] = T2[17, [1, 0]]
    for fn in (skinrs.cotan_laplacian, skinrs.massmatrix, skinrs.biharmonic_matrix):
        with pytest.raises(ValueError, match=r"tet 17 .*inverted \(volume -"):
            fn(V, T2)


def test_flat_tet_is_named(data_dir):
    V, T = load(data_dir, "knight-tets")
    a, b, c = T[0, :3]
    n, m = V.shape[0], T.shape[0]
    V2, T2 = with_extra_element(V, T, [a, b, c, n], [(V[a] + V[b] + V[c]) / 3])
    with pytest.raises(ValueError, match=rf"tet {m} .*degenerate"):
        skinrs.cotan_laplacian(V2, T2)


@pytest.mark.parametrize(
    "make, msg",
    [
        (lambda V, F: (np.where(np.arange(V.size).reshape(V.shape) == 7, np.nan, V), F), "NaN"),
        (lambda V, F: (V, np.vstack([F, [[0, 1, V.shape[0]]]])), "outside"),
        (lambda V, F: (V, np.vstack([F, [[0, 1, 1]]])), "repeats a vertex"),
        (lambda V, F: (V, F[:, :2]), "columns"),
        (lambda V, F: (np.c_[V, V], F), "shape"),
        (lambda V, F: (V, F.astype(float) + 0.5), "integer"),
    ],
)
def test_bad_input_raises_value_error(data_dir, make, msg):
    V, F = load(data_dir, "woody-2d")
    V2, F2 = make(V, F)
    for fn in (skinrs.cotan_laplacian, skinrs.massmatrix, skinrs.biharmonic_matrix):
        with pytest.raises(ValueError, match=msg):
            fn(V2, F2)


def test_tets_need_3d_points():
    with pytest.raises(ValueError, match="3D"):
        skinrs.cotan_laplacian(np.eye(4)[:, :2], np.array([[0, 1, 2, 3]]))


def test_bad_mass_kind():
    V = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    F = np.array([[0, 1, 2]])
    with pytest.raises(ValueError, match="voronoi"):
        skinrs.massmatrix(V, F, "full")
    with pytest.raises(ValueError, match="mass"):
        skinrs.biharmonic_matrix(V, F, mass=1)


# --- connected components -------------------------------------------------------------------


def scipy_labels(F, n):
    """Components of the graph joining consecutive corners of each element (a cycle per row)."""
    F = np.asarray(F)
    i = F.ravel()
    j = np.roll(F, -1, axis=1).ravel()
    A = sp.coo_matrix((np.ones(i.size), (i, j)), shape=(n, n))
    return scipy_components(A, directed=False)


@pytest.mark.parametrize(
    "path, extra",
    [
        ("truck-soup/truck.obj", 0),  # 66 components, non-manifold soup
        ("human/human_man.obj", 0),  # 3 components
        ("hand-403/hand.mesh", 5),  # tets, plus 5 isolated vertices
    ],
)
def test_connected_components_match_scipy(data_dir, path, extra):
    p = str(data_dir / path)
    F = igl.readMESH(p)[1] if p.endswith(".mesh") else igl.read_triangle_mesh(p)[1]
    n = int(F.max()) + 1 + extra
    count, labels = connected_components(F, n=n)
    ref_count, ref_labels = scipy_labels(F, n)
    assert count == ref_count
    assert labels.dtype == np.int64 and labels.shape == (n,)
    np.testing.assert_array_equal(labels, ref_labels)


def test_connected_components_defaults_and_errors():
    count, labels = connected_components(np.array([[0, 1], [2, 3], [3, 4]]))
    assert count == 2 and labels.tolist() == [0, 0, 1, 1, 1]
    with pytest.raises(ValueError, match="outside"):
        connected_components(np.array([[0, 5]]), n=3)
    with pytest.raises(ValueError, match="outside"):
        connected_components(np.array([[0, -1]]))
    with pytest.raises(ValueError, match="non-negative"):
        connected_components(np.array([[0, 1]]), n=-2)
