"""Geometric queries of skinrs.field against libigl and brute-force numpy.

Winding numbers: ``igl.winding_number`` (exact solid-angle sum) on a closed mesh, an open mesh
with holes and a triangle soup, at random points of the inflated bounding box. Visibility and
closest points: a vectorised scan over every element, which must give the same booleans and the
same distances (to 1e-12).
"""

from __future__ import annotations

import igl  # libigl is a test dependency (Makefile); a missing one must fail, not skip
import numpy as np
import pytest
import skinrs
from _generated import box_figure_soup, fan_triangles
from skinrs import io

MESHES = {
    "closed": "arm/arm.obj",
    "open": "plane/plane_holes.obj",
    "soup": None,  # generated: overlapping boxes, every face its own vertices, one box open
}


def _load(data_dir, key):
    if MESHES[key] is None:
        V, polys = box_figure_soup()
        return V, fan_triangles(polys)
    return io.read_obj(data_dir / MESHES[key])


def _box_points(V, n, rng, inflate=0.2):
    lo, hi = V.min(0), V.max(0)
    pad = inflate * (hi - lo)
    return rng.uniform(lo - pad, hi + pad, size=(n, V.shape[1]))


def _read_dat(path):
    """poly2tri .dat: rings of 'x y' lines separated by 'HOLE'; returns V (n, 2), E (n, 2)."""
    rings, cur = [], []
    for line in path.read_text().splitlines():
        s = line.split()
        if not s:
            continue
        if s[0].upper() == "HOLE":
            rings.append(cur)
            cur = []
        else:
            cur.append([float(s[0]), float(s[1])])
    rings.append(cur)
    V, E = [], []
    for r in rings:
        if not r:
            continue
        o = len(V)
        V.extend(r)
        m = len(r)
        E.extend([o + i, o + (i + 1) % m] for i in range(m))
    return np.array(V), np.array(E, dtype=np.int64)


# --- brute force ----------------------------------------------------------------------------


def _dot(a, b):
    return a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1] + a[..., 2] * b[..., 2]


def _cross(a, b):
    return np.stack(
        [
            a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1],
            a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2],
            a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0],
        ],
        axis=-1,
    )


def _hits_3d(V, F, p, q):
    """Möller–Trumbore of the open segment p->q against every triangle."""
    a, b, c = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    d = q - p
    e1, e2 = b - a, c - a
    h = _cross(d[None], e2)
    det = _dot(e1, h)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / det
        s = p[None] - a
        u = inv * _dot(s, h)
        qv = _cross(s, e1)
        v = inv * _dot(d[None], qv)
        t = inv * _dot(e2, qv)
    ok = (det != 0) & (u >= 0) & (u <= 1) & (v >= 0) & (u + v <= 1) & (t > 0) & (t < 1)
    return bool(ok.any())


def _cross2(a, b):
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def _hits_2d(V, E, p, q):
    a, b = V[E[:, 0]], V[E[:, 1]]
    d = q - p
    e = b - a
    den = _cross2(d[None], e)
    w = a - p[None]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = _cross2(w, e) / den
        s = _cross2(w, d[None]) / den
    ok = (den != 0) & (t > 0) & (t < 1) & (s >= 0) & (s <= 1)
    return bool(ok.any())


def _seg_dist2(x, a, b):
    e = b - a
    l2 = (e * e).sum(-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(l2 > 0, ((x - a) * e).sum(-1) / l2, 0.0)
    t = np.clip(t, 0.0, 1.0)
    p = a + t[..., None] * e
    return ((x - p) ** 2).sum(-1)


def _tri_dist2(x, V, F):
    """Squared distance from x to each triangle: the plane if the projection is inside, else
    the nearest edge (an independent formulation from the Voronoi-region code in Rust)."""
    a, b, c = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    n = _cross(b - a, c - a)
    nn = _dot(n, n)
    edges = np.minimum(np.minimum(_seg_dist2(x, a, b), _seg_dist2(x, b, c)), _seg_dist2(x, c, a))
    with np.errstate(divide="ignore", invalid="ignore"):
        h = _dot(x - a, n) / nn
        y = x - h[:, None] * n
        inside = (
            (_dot(_cross(b - a, y - a), n) >= 0)
            & (_dot(_cross(c - b, y - b), n) >= 0)
            & (_dot(_cross(a - c, y - c), n) >= 0)
            & (nn > 0)
        )
        plane = h * h * nn
    return np.where(inside, np.minimum(plane, edges), edges)


# --- winding numbers -------------------------------------------------------------------------


# Max |w - exact| at beta = 3, at beta = 2, and the median at beta = 2. The soup's boxes have
# large faces meeting at corners, where the far-field expansion errs most (libigl's
# fast_winding_number errs as much there: 9e-3 at beta = 2).
TOL_WINDING = {"closed": (1e-3, 5e-3, 5e-4), "open": (1e-3, 5e-3, 5e-4), "soup": (2e-3, 1e-2, 1e-3)}


@pytest.mark.parametrize("key", ["closed", "open", "soup"])
def test_winding_number_matches_igl(data_dir, key):
    V, F = _load(data_dir, key)
    rng = np.random.default_rng(5)
    Q = _box_points(V, 2000, rng)
    w_ref = igl.winding_number(V, F, Q)
    # beta = 3: within 1e-3 of the exact winding number everywhere.
    w = skinrs.winding_number(V, F, Q, beta=3.0)
    assert w.shape == (2000,)
    err = np.abs(w - w_ref)
    tol3, tol2, median2 = TOL_WINDING[key]
    assert err.max() < tol3, f"{key}: beta=3 max |w - igl| = {err.max():.2e}"
    # beta = 2 (the default, Barill et al.'s): the truncation error near the surface reaches a
    # few 1e-3, as for libigl's own implementation of the same method on the same points.
    w2 = skinrs.winding_number(V, F, Q)
    err2 = np.abs(w2 - w_ref)
    err_igl = np.abs(igl.fast_winding_number(V, F, Q) - w_ref)
    assert err2.max() < tol2 and np.median(err2) < median2, f"{key}: beta=2 {err2.max():.2e}"
    assert err2.max() < 1.6 * err_igl.max()
    if key == "closed":
        # A closed mesh: the values are (numerically) 0 or 1 away from the surface.
        assert np.all(np.minimum(np.abs(w), np.abs(w - 1)) < 1e-3)
        assert 0 < np.sum(w > 0.5) < 2000


def test_winding_number_exact_with_infinite_beta(data_dir):
    V, F = _load(data_dir, "soup")
    Q = _box_points(V, 200, np.random.default_rng(1))
    w = skinrs.winding_number(V, F, Q, beta=np.inf)
    np.testing.assert_allclose(w, igl.winding_number(V, F, Q), atol=1e-10)


def test_winding_number_2d_polygon_with_holes(data_dir):
    V, E = _read_dat(data_dir / "polygons-2d" / "dude.dat")
    Q = _box_points(V, 2000, np.random.default_rng(2))
    w_ref = igl.winding_number(V, E, Q)
    w = skinrs.winding_number(V, E, Q, beta=np.inf)
    np.testing.assert_allclose(w, w_ref, rtol=0, atol=1e-10)
    # The outer ring is clockwise: -1 inside, 0 outside and in the holes.
    assert np.all(np.minimum(np.abs(w), np.abs(w + 1)) < 1e-10)
    assert 100 < np.sum(w < -0.5) < 1900
    # Hierarchical with the 2D default beta = 4.
    err = np.abs(skinrs.winding_number(V, E, Q) - w_ref)
    assert err.max() < 2e-3 and np.median(err) < 3e-4
    # beta = 2 in 2D: the 1/d kernel makes it ~1e-2 at worst.
    assert np.abs(skinrs.winding_number(V, E, Q, beta=2) - w_ref).max() < 2e-2


def test_winding_number_2d_large_outline(data_dir):
    V, E = _read_dat(data_dir / "polygons-2d" / "nazca_monkey.dat")
    Q = _box_points(V, 2000, np.random.default_rng(12))
    w_ref = igl.winding_number(V, E, Q)
    err = np.abs(skinrs.winding_number(V, E, Q) - w_ref)
    assert err.max() < 3e-3 and np.median(err) < 5e-4
    np.testing.assert_allclose(skinrs.winding_number(V, E, Q, beta=np.inf), w_ref, atol=1e-10)


def test_winding_number_orientation_and_soup_of_one_triangle():
    V = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]])
    F = np.array([[0, 1, 2]])
    q = np.array([[0.2, 0.2, -1e-3], [0.2, 0.2, 1e-3]])
    w = skinrs.winding_number(V, F, q)
    # Just behind / in front of the triangle: about +1/2 and -1/2.
    assert w[0] > 0.49 and w[1] < -0.49


# --- visibility ------------------------------------------------------------------------------


def _segment_pairs(V, n, rng):
    """Half long segments across the box, half short ones (mostly visible)."""
    P = _box_points(V, n, rng)
    Q = _box_points(V, n, rng)
    scale = 0.05 * np.linalg.norm(V.max(0) - V.min(0))
    Q[: n // 2] = P[: n // 2] + scale * rng.standard_normal((n // 2, V.shape[1]))
    return P, Q


@pytest.mark.parametrize("key", ["closed", "soup"])
def test_segment_visible_matches_brute_force(data_dir, key):
    V, F = _load(data_dir, key)
    P, Q = _segment_pairs(V, 400, np.random.default_rng(3))
    vis = skinrs.segment_visible(V, F, P, Q)
    ref = np.array([not _hits_3d(V, F, p, q) for p, q in zip(P, Q)])
    assert vis.dtype == bool and vis.shape == (400,)
    np.testing.assert_array_equal(vis, ref)
    assert 20 < vis.sum() < 380


def test_segment_visible_2d_matches_brute_force(data_dir):
    V, E = _read_dat(data_dir / "polygons-2d" / "nazca_monkey.dat")
    P, Q = _segment_pairs(V, 1000, np.random.default_rng(4))
    vis = skinrs.segment_visible(V, E, P, Q)
    ref = np.array([not _hits_2d(V, E, p, q) for p, q in zip(P, Q)])
    np.testing.assert_array_equal(vis, ref)
    assert 50 < vis.sum() < 950


def test_segment_visible_endpoints_on_boundary_and_degenerate():
    V = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    E = np.array([[0, 1], [1, 2], [2, 3], [3, 0]])
    P = np.array([[0.5, 0.0], [0.3, 0.3], [0.5, 0.5]])
    Q = np.array([[0.5, 0.5], [0.3, 0.3], [0.5, 1.0]])
    # Ending on the boundary does not block; an empty segment is visible.
    np.testing.assert_array_equal(skinrs.segment_visible(V, E, P, Q), [True, True, True])


# --- closest points --------------------------------------------------------------------------


@pytest.mark.parametrize("key", ["closed", "soup"])
def test_closest_point_matches_brute_force(data_dir, key):
    V, F = _load(data_dir, key)
    Q = _box_points(V, 200, np.random.default_rng(6))
    dist, point, face, normal = skinrs.closest_point(V, F, Q)
    assert dist.shape == (200,) and point.shape == (200, 3)
    assert face.shape == (200,) and normal.shape == (200, 3)
    ref = np.array([np.sqrt(_tri_dist2(q, V, F).min()) for q in Q])
    np.testing.assert_allclose(dist, ref, rtol=0, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(point - Q, axis=1), dist, rtol=0, atol=1e-12)
    # The point lies on the reported face, whose unit normal is returned.
    on_face = np.array([_tri_dist2(p, V, F[f : f + 1])[0] for p, f in zip(point, face)])
    assert np.sqrt(on_face).max() < 1e-12
    n = np.cross(V[F[face, 1]] - V[F[face, 0]], V[F[face, 2]] - V[F[face, 0]])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    np.testing.assert_allclose(normal, n, atol=1e-12)


def test_closest_point_2d_matches_brute_force(data_dir):
    V, E = _read_dat(data_dir / "polygons-2d" / "dude.dat")
    Q = _box_points(V, 500, np.random.default_rng(7))
    dist, point, face, normal = skinrs.closest_point(V, E, Q)
    d2 = np.array([_seg_dist2(q[None], V[E[:, 0]], V[E[:, 1]]) for q in Q])
    np.testing.assert_allclose(dist, np.sqrt(d2.min(1)), rtol=0, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(point - Q, axis=1), dist, rtol=0, atol=1e-12)
    np.testing.assert_allclose(np.sqrt(d2[np.arange(500), face]), dist, rtol=0, atol=1e-12)
    t = V[E[face, 1]] - V[E[face, 0]]
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    np.testing.assert_allclose(normal, np.stack([t[:, 1], -t[:, 0]], 1), atol=1e-15)


# --- nearest neighbours ----------------------------------------------------------------------


@pytest.mark.parametrize("dim", [2, 3])
def test_knn_distance_matches_kdtree(dim):
    from scipy.spatial import cKDTree

    rng = np.random.default_rng(8)
    X = rng.standard_normal((3000, dim)) * np.array([1.0, 0.3, 0.05][:dim])
    d = skinrs.knn_distance(X, k=9)
    ref = cKDTree(X).query(X, k=10)[0][:, 9]
    np.testing.assert_allclose(d, ref, rtol=0, atol=1e-12)


def test_knn_distance_on_surface_samples(data_dir):
    from scipy.spatial import cKDTree

    V, _ = _load(data_dir, "closed")
    d = skinrs.knn_distance(V, k=9)
    np.testing.assert_allclose(d, cKDTree(V).query(V, k=10)[0][:, 9], rtol=0, atol=1e-12)


# --- argument checks -------------------------------------------------------------------------


def _square():
    V = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    E = np.array([[0, 1], [1, 2], [2, 3], [3, 0]])
    return V, E


@pytest.mark.parametrize(
    "call, match",
    [
        (lambda V, E: skinrs.winding_number(V, E, [[np.nan, 0.0]]), "Q has a NaN"),
        (lambda V, E: skinrs.winding_number(np.where(V == 1, np.inf, V), E, V), "V has a NaN"),
        (lambda V, E: skinrs.winding_number(V, E[:, [0, 1, 1]], V), "F must have 2 columns"),
        (lambda V, E: skinrs.winding_number(V, E + 4, V), "outside the valid range"),
        (lambda V, E: skinrs.winding_number(V, E[:0], V), "F must not be empty"),
        (lambda V, E: skinrs.winding_number(V, E, np.zeros((3, 3))), "Q must have shape"),
        (lambda V, E: skinrs.winding_number(V, E, V, beta=0), "beta must be positive"),
        (lambda V, E: skinrs.winding_number(V, E.astype(float) + 0.5, V), "integer"),
        (lambda V, E: skinrs.segment_visible(V, E, V, V[:2]), "same number of rows"),
        (lambda V, E: skinrs.closest_point(V[:0], E, V), "at least 1 rows"),
        (lambda V, E: skinrs.closest_point(V, E, "abc"), "Q must hold numbers"),
        (lambda V, E: skinrs.knn_distance(V, k=4), "k must be smaller"),
        (lambda V, E: skinrs.knn_distance(V, k=0), "k must be a positive integer"),
        (lambda V, E: skinrs.knn_distance(np.zeros((5, 4)), k=1), "X must have shape"),
    ],
)
def test_bad_input_raises_value_error(call, match):
    V, E = _square()
    with pytest.raises(ValueError, match=match):
        call(V, E)


def test_empty_query_sets():
    V, E = _square()
    assert skinrs.winding_number(V, E, np.zeros((0, 2))).shape == (0,)
    assert skinrs.segment_visible(V, E, np.zeros((0, 2)), np.zeros((0, 2))).shape == (0,)
    d, p, f, n = skinrs.closest_point(V, E, np.zeros((0, 2)))
    assert d.shape == (0,) and p.shape == (0, 2) and f.shape == (0,) and n.shape == (0, 2)


def test_large_batches_keep_query_order(data_dir):
    # Batches of >= 1024 queries run in Morton order internally; results must come back in
    # query order, identical to small batches (which run in order).
    V, F = _load(data_dir, "soup")
    rng = np.random.default_rng(9)
    P, Q = _box_points(V, 3000, rng), _box_points(V, 3000, rng)
    chunks = [slice(0, 1000), slice(1000, 2000), slice(2000, 3000)]
    w = skinrs.winding_number(V, F, Q)
    np.testing.assert_array_equal(
        w, np.concatenate([skinrs.winding_number(V, F, Q[c]) for c in chunks])
    )
    vis = skinrs.segment_visible(V, F, P, Q)
    ref = np.concatenate([skinrs.segment_visible(V, F, P[c], Q[c]) for c in chunks])
    np.testing.assert_array_equal(vis, ref)
    big = skinrs.closest_point(V, F, Q)
    small = [skinrs.closest_point(V, F, Q[c]) for c in chunks]
    for a, parts in zip(big, zip(*small)):
        np.testing.assert_array_equal(a, np.concatenate(parts))
