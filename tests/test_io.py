"""File readers/writers against libigl, meshio, trimesh and the facts stated in the data README."""

import importlib
import sys
import types
from pathlib import Path

import numpy as np
import pytest
from _generated import (
    box_figure_soup,
    fan_triangles,
    figure_skeleton,
    figure_skin,
    write_rignet_rig,
    write_soup_obj,
)


def _import_io():
    """``skinrs.io``; without a built extension, load the pure-Python module on its own."""
    try:
        return importlib.import_module("skinrs.io")
    except ImportError:
        pkg_dir = Path(__file__).resolve().parents[1] / "python" / "skinrs"
        for name in [m for m in sys.modules if m == "skinrs" or m.startswith("skinrs.")]:
            del sys.modules[name]
        pkg = types.ModuleType("skinrs")
        pkg.__path__ = [str(pkg_dir)]  # a bare package: no __init__, so no _skinrs import
        sys.modules["skinrs"] = pkg
        return importlib.import_module("skinrs.io")


sio = _import_io()
igl = pytest.importorskip("igl")


def _write(tmp_path, name, text, mode="w"):
    p = tmp_path / name
    if mode == "wb":
        p.write_bytes(text)
    else:
        p.write_text(text, newline="")
    return p


def _sorted_rows(A):
    """Rows of A in lexicographic order (to compare element sets)."""
    A = np.asarray(A)
    return A[np.lexsort(A.T[::-1])]


def _canonical_triangles(F):
    """Each triangle rotated to start at its smallest index (orientation kept), rows sorted."""
    F = np.asarray(F)
    r = np.argmin(F, axis=1)
    rolled = np.stack([F[np.arange(len(F)), (r + k) % 3] for k in range(3)], axis=1)
    return _sorted_rows(rolled)


# --------------------------------------------------------------------------------------------
# TGF


@pytest.mark.parametrize(
    "rel, n, k",
    [
        ("hand-403/hand.tgf", 21, 20),
        ("decimated-knight/decimated-knight.tgf", 8, 7),
        ("arm/arm.tgf", 5, 4),
    ],
)
def test_tgf_counts_and_tree(data_dir, rel, n, k):
    C, BE, P = sio.read_tgf(data_dir / rel, return_point_handles=True)
    assert C.shape == (n, 3) and C.dtype == np.float64
    assert BE.shape == (k, 2) and BE.dtype == np.int64
    assert P.shape == (0,)  # README: no skeleton has point handles
    # README: a single tree rooted at joint 1 -> every other joint has exactly one parent
    parents = np.bincount(BE[:, 1], minlength=n)
    assert parents[0] == 0 and np.all(parents[1:] == 1)
    assert np.all(np.abs(C) < 1e3)  # the garbage columns (6.95e-310, 2.8e199) were dropped


def test_tgf_quirks_of_real_files(data_dir):
    arm = (data_dir / "arm/arm.tgf").read_text().splitlines()
    assert len(arm[0].split()) == 19  # the file really has the 19-column quirk
    C, BE = sio.read_tgf(str(data_dir / "arm/arm.tgf"))  # str path
    np.testing.assert_array_equal(C[0], [-0.72962893, 0.011729617, -0.1327604])
    np.testing.assert_array_equal(BE, [[0, 1], [1, 2], [2, 3], [3, 4]])

    C, BE = sio.read_tgf(data_dir / "hand-403/hand.tgf")
    lengths = np.linalg.norm(C[BE[:, 1]] - C[BE[:, 0]], axis=1)
    assert lengths.min() == pytest.approx(0.106, abs=5e-4)  # README: 0.106 .. 0.757
    assert lengths.max() == pytest.approx(0.757, abs=5e-4)
    np.testing.assert_array_equal(BE[0], [5, 6])  # first bone line "6 7", kept in file order


def test_tgf_variants(tmp_path):
    text = "\n1 0 0 0 9 9\n\n2 1 0 0\r\n3 2 0\n4 3 1 1\n#\n1 2\n\n2 3 1 0 0\n#\n7 8 9\n"
    C, BE, P = sio.read_tgf(_write(tmp_path, "a.tgf", text), return_point_handles=True)
    np.testing.assert_array_equal(C, [[0, 0, 0], [1, 0, 0], [2, 0, 0], [3, 1, 1]])
    np.testing.assert_array_equal(BE, [[0, 1], [1, 2]])
    np.testing.assert_array_equal(P, [3])  # joint 4 is referenced by no bone
    # no bone section at all: every joint is a point handle
    C, BE, P = sio.read_tgf(
        _write(tmp_path, "b.tgf", "1 0 0 0\n2 1 1 1\n"), return_point_handles=True
    )
    assert C.shape == (2, 3) and BE.shape == (0, 2)
    np.testing.assert_array_equal(P, [0, 1])
    C, BE = sio.read_tgf(_write(tmp_path, "c.tgf", "1 0 0 0\n2 1 1 1\n#\n"))
    assert BE.shape == (0, 2)


@pytest.mark.parametrize(
    "text, line, what",
    [
        ("1 0 0 0\n2 1 1 1\n#\n1 3\n#\n", 4, "joint 3"),
        ("1 0 0 0\n2 1 1 1\n#\n1 x\n#\n", 4, "bone line"),
        ("1 0 0 0\n2 1 abc 1\n#\n", 2, "coordinate"),
        ("1 0 0 0\n3 1 1 1\n#\n", 2, "joint index 2"),
        ("1 0 0 0\n2 1 1 1\n#\n1 2 0 0 1\n#\n", 4, "cage"),
        ("1 0 0 0\n2 1 1 1\n#\n2 2\n#\n", 4, "itself"),
        ("hello\n", 1, "joint line"),
    ],
)
def test_tgf_malformed(tmp_path, text, line, what):
    with pytest.raises(ValueError, match=rf"bad\.tgf: line {line}: .*{what}"):
        sio.read_tgf(_write(tmp_path, "bad.tgf", text))


def test_tgf_round_trip(data_dir, tmp_path):
    C, BE = sio.read_tgf(data_dir / "hand-403/hand.tgf")
    sio.write_tgf(tmp_path / "h.tgf", C, BE)
    C2, BE2 = sio.read_tgf(tmp_path / "h.tgf")
    np.testing.assert_array_equal(C2, C)
    np.testing.assert_array_equal(BE2, BE)
    # 2D joints are written with z = 0
    sio.write_tgf(str(tmp_path / "w.tgf"), C[:, :2], BE)
    C3, _ = sio.read_tgf(tmp_path / "w.tgf")
    np.testing.assert_array_equal(C3, np.c_[C[:, :2], np.zeros(len(C))])
    with pytest.raises(ValueError, match="BE"):
        sio.write_tgf(tmp_path / "x.tgf", C, np.array([[0, 21]]))


# --------------------------------------------------------------------------------------------
# DMAT


DMATS = [
    ("hand-403/hand-pose.dmat", (80, 1)),
    ("decimated-knight/decimated-knight-matlab-active-set.dmat", (1822, 7)),
    ("arm/arm-weights.dmat", (8311, 4)),
]


@pytest.mark.parametrize("rel, shape", DMATS)
def test_dmat_matches_igl(data_dir, rel, shape):
    W = sio.read_dmat(data_dir / rel)
    assert W.shape == shape and W.dtype == np.float64
    np.testing.assert_array_equal(W, igl.readDMAT(str(data_dir / rel)))


def test_dmat_column_major(data_dir):
    # a row-major misread would break the partition of unity and the unit quaternions
    np.testing.assert_allclose(
        sio.read_dmat(data_dir / "arm/arm-weights.dmat").sum(1), 1, atol=1e-6
    )
    Q = sio.read_dmat(data_dir / "hand-403/hand-pose.dmat").reshape(20, 4)  # (x, y, z, w)
    np.testing.assert_allclose(np.linalg.norm(Q, axis=1), 1, atol=1e-6)
    assert np.sum(np.all(Q == [0, 0, 0, 1], axis=1)) == 3


def test_dmat_binary_written_by_igl(tmp_path):
    W = np.random.default_rng(1).random((300, 5))
    p = tmp_path / "b.dmat"
    igl.writeDMAT(str(p), W, False)  # libigl's binary form: "0 0", header, float64 data
    assert p.read_bytes().startswith(b"0 0\n")
    np.testing.assert_array_equal(sio.read_dmat(p), W)


@pytest.mark.parametrize("binary", [False, True])
def test_dmat_round_trip(tmp_path, binary):
    rng = np.random.default_rng(0)
    W = rng.standard_normal((17, 3)) * 10.0 ** rng.integers(-300, 300, (17, 3))
    W[0, 0], W[1, 1], W[2, 2] = -0.0, 5e-324, 0.1
    p = tmp_path / "w.dmat"
    sio.write_dmat(p, W, binary=binary)
    np.testing.assert_array_equal(sio.read_dmat(p), W)
    np.testing.assert_array_equal(igl.readDMAT(str(p)), W)  # libigl reads what we write
    sio.write_dmat(str(p), W[:, 1], binary=binary)  # 1D -> one column
    assert sio.read_dmat(p).shape == (17, 1)
    sio.write_dmat(p, np.zeros((0, 4)), binary=binary)
    assert sio.read_dmat(p).shape == (0, 4)
    sio.write_dmat(p, np.zeros((0, 0)), binary=binary)
    assert sio.read_dmat(p).shape == (0, 0)


def test_dmat_ascii_layout(tmp_path):
    # column-major: the values of the first column come first
    p = _write(tmp_path, "a.dmat", "2 3\n1\n2\n3\n4 5\n6")
    np.testing.assert_array_equal(sio.read_dmat(p), [[1, 4], [2, 5], [3, 6]])
    sio.write_dmat(p, np.array([[1.5, 4], [2, 5], [3, 6]]))
    assert p.read_text() == "2 3\n1.5\n2.0\n3.0\n4.0\n5.0\n6.0\n"


@pytest.mark.parametrize(
    "content, pattern",
    [
        ("2 3\n1\n2\n3\n4\n5\n", r"line 6 \(end of file\): truncated: expected 6 values"),
        ("2 3\n1\n2\n3\n4\n5\n6\n7\n", r"line 8: unexpected value '7'"),
        ("2 3\n1\n2\nfoo\n4\n5\n6\n", r"line 4: expected a number, got 'foo'"),
        ("2 x\n1\n", r"line 1: expected a header 'cols rows'"),
        ("", r"line 1: expected a header"),
        (b"0 0\n2 3\n" + np.arange(5.0).tobytes(), r"line 3 \(binary data\): truncated"),
        (b"0 0\n2 3\n" + np.arange(7.0).tobytes(), r"line 3 \(binary data\): has trailing bytes"),
        (b"0 0\n2\n" + np.arange(6.0).tobytes(), r"line 2: expected a header"),
    ],
)
def test_dmat_malformed(tmp_path, content, pattern):
    p = _write(tmp_path, "bad.dmat", content, "wb" if isinstance(content, bytes) else "w")
    with pytest.raises(ValueError, match=r"bad\.dmat: " + pattern):
        sio.read_dmat(p)


def test_dmat_real_file_truncated(data_dir, tmp_path):
    lines = (data_dir / "arm/arm-weights.dmat").read_text().splitlines()
    p = _write(tmp_path, "cut.dmat", "\n".join(lines[:-10]) + "\n")
    with pytest.raises(ValueError, match=rf"cut\.dmat: line {len(lines) - 10} .*truncated"):
        sio.read_dmat(p)
    sio.write_dmat(
        tmp_path / "b.dmat", sio.read_dmat(data_dir / "arm/arm-weights.dmat"), binary=True
    )
    raw = (tmp_path / "b.dmat").read_bytes()
    with pytest.raises(ValueError, match="truncated"):
        sio.read_dmat(_write(tmp_path, "cut2.dmat", raw[:-8], "wb"))


# --------------------------------------------------------------------------------------------
# MEDIT .mesh


MESHES = [
    ("hand-403/hand.mesh", 7234, 29998, 9556, 4780),
    ("decimated-knight/decimated-knight.mesh", 1822, 5452, 3544, 1774),
]


@pytest.mark.parametrize("rel, nv, nt, nf, nsurf", MESHES)
def test_mesh_matches_igl_and_readme(data_dir, rel, nv, nt, nf, nsurf):
    V, T, F = sio.read_mesh(data_dir / rel)
    assert V.shape == (nv, 3) and T.shape == (nt, 4) and F.shape == (nf, 3)
    assert T.dtype == np.int64 and F.dtype == np.int64 and V.dtype == np.float64
    assert np.unique(F).size == nsurf
    Vi, Ti, Fi = igl.readMESH(str(data_dir / rel))
    np.testing.assert_array_equal(V, Vi)
    np.testing.assert_array_equal(T, Ti)
    np.testing.assert_array_equal(F, Fi)
    # README: every tet positively oriented (a shifted or permuted index would break this)
    a, b, c, d = (V[T[:, i]] for i in range(4))
    assert np.all(np.linalg.det(np.stack([b - a, c - a, d - a], axis=1)) > 0)


def test_mesh_triangles_are_tet_boundary(data_dir):
    _, T, F = sio.read_mesh(data_dir / "decimated-knight/decimated-knight.mesh")
    faces = np.concatenate([T[:, [1, 2, 3]], T[:, [0, 3, 2]], T[:, [0, 1, 3]], T[:, [0, 2, 1]]])
    key, count = np.unique(np.sort(faces, axis=1), axis=0, return_counts=True)
    np.testing.assert_array_equal(key[count == 1], _sorted_rows(np.sort(F, axis=1)))


def test_mesh_matches_meshio(data_dir):
    meshio = pytest.importorskip("meshio")
    m = meshio.read(data_dir / "decimated-knight/decimated-knight.mesh")
    V, T, F = sio.read_mesh(data_dir / "decimated-knight/decimated-knight.mesh")
    # meshio parses "MeshVersionFormatted 1" coordinates in single precision
    np.testing.assert_allclose(V, m.points, rtol=0, atol=2e-7)
    np.testing.assert_array_equal(T, np.concatenate([c.data for c in m.cells if c.type == "tetra"]))
    np.testing.assert_array_equal(
        F, np.concatenate([c.data for c in m.cells if c.type == "triangle"])
    )


TET = "0 0 0 1\n1 0 0 1\n0 1 0 1\n0 0 1 1\n"


@pytest.mark.parametrize(
    "text",
    [
        "MeshVersionFormatted 1\nDimension 3\nVertices\n4\n"
        + TET
        + "Tetrahedra\n1\n1 2 3 4 0\nEnd\n",
        # same line counts, comments, no End, Triangles after Tetrahedra
        "# made by hand\nMeshVersionFormatted 2 Dimension\n3\nVertices 4\n"
        + TET
        + "Tetrahedra 1 # one tet\n1 2 3 4 7\nTriangles 1\n2 3 4 1\nEdges 0\n",
        # entries spread over lines, extra skipped sections
        (
            "MeshVersionFormatted 1\nDimension 3\nVertices\n4\n0 0 0\n1 1 0 0 1 0 1 0 1 0 0 1 1\n"
            "Corners 1\n1\nEdges 1\n1 2 0\nTetrahedra\n1\n1 2\n3 4 0\nTriangles\n1\n2 3 4 1\n"
            "Quadrilaterals 0\nEnd"
        ),
    ],
)
def test_mesh_variants(tmp_path, text):
    V, T, F = sio.read_mesh(_write(tmp_path, "t.mesh", text))
    np.testing.assert_array_equal(V, [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    np.testing.assert_array_equal(T, [[0, 1, 2, 3]])
    assert F.shape == (0 if "Triangles" not in text else 1, 3)
    if F.size:
        np.testing.assert_array_equal(F, [[1, 2, 3]])


def test_mesh_dimension_2(tmp_path):
    text = "MeshVersionFormatted 1\nDimension 2\nVertices 3\n0 0 1\n1 0 1\n0 1 1\nTriangles 1\n1 2 3 1\n"
    V, T, F = sio.read_mesh(_write(tmp_path, "d2.mesh", text))
    np.testing.assert_array_equal(V, [[0, 0], [1, 0], [0, 1]])
    assert T.shape == (0, 4)
    np.testing.assert_array_equal(F, [[0, 1, 2]])


HEAD = "MeshVersionFormatted 1\nDimension 3\nVertices\n4\n"


@pytest.mark.parametrize(
    "text, line, what",
    [
        (HEAD + TET + "Tetrahedra\n1\n1 2 3 5 0\nEnd\n", 11, "references vertex 5, expected 1..4"),
        (HEAD + TET + "Tetrahedra\n1\n0 2 3 4 0\nEnd\n", 11, "references vertex 0"),
        (HEAD + TET + "Tetrahedra\n2\n1 2 3 4 0\nEnd\n", 12, r"entry 2 of 2 .* got 'End'"),
        (HEAD + TET + "Tetrahedra\n2\n1 2 3 4 0\n", 11, r"\(end of file\).*entry 2 of 2"),
        (HEAD + "0 0 0 1\n1 0 0 1\n0 1 0 1\nEnd\n", 8, r"a number in entry 4 of 4.*'End'"),
        (HEAD + "0 0 0 1\n1 0 zz 1\n0 1 0 1\n0 0 1 1\n", 6, "got 'zz'"),
        (HEAD + TET + "Tetrahedra\nmany\n", 10, "number of entries"),
        (HEAD + TET + "Garbage 3\n", 9, "section keyword, got 'Garbage'"),
        (HEAD + TET + "Hexahedra 1\n1 2 3 4 1 2 3 4 0\n", 9, "not supported"),
        ("Dimension 3\nVertices\n0\n", 1, "MeshVersionFormatted"),
        ("MeshVersionFormatted 1\nDimension 3\nEnd\n", 3, "no 'Vertices'"),
    ],
)
def test_mesh_malformed(tmp_path, text, line, what):
    with pytest.raises(ValueError, match=rf"bad\.mesh: line {line}\b.*{what}"):
        sio.read_mesh(_write(tmp_path, "bad.mesh", text))


def test_mesh_round_trip(data_dir, tmp_path):
    V, T, F = sio.read_mesh(data_dir / "decimated-knight/decimated-knight.mesh")
    p = tmp_path / "k.mesh"
    sio.write_mesh(p, V, T, F)
    V2, T2, F2 = sio.read_mesh(p)
    np.testing.assert_array_equal(V2, V)
    np.testing.assert_array_equal(T2, T)
    np.testing.assert_array_equal(F2, F)
    Vi, Ti, Fi = igl.readMESH(str(p))  # libigl reads what we write
    np.testing.assert_array_equal(Vi, V)
    np.testing.assert_array_equal(Ti, T)
    np.testing.assert_array_equal(Fi, F)
    sio.write_mesh(str(p), V, T)  # no triangles
    _, T3, F3 = sio.read_mesh(p)
    assert F3.shape == (0, 3) and np.array_equal(T3, T)
    with pytest.raises(ValueError, match="T holds index"):
        sio.write_mesh(p, V, T + 1)


# --------------------------------------------------------------------------------------------
# OBJ


OBJS = [
    ("arm/arm.obj", 8311, 16618),
    ("human/human_man.obj", 6890, 13776),
    ("plane/plane_holes.obj", 8519, 16747),
    ("spot/spot_low_resolution.obj", 829, 1654),
]


@pytest.fixture
def soup_obj(tmp_path):
    """A generated polygon soup (quads and triangles, repeated positions, ``v/vt/vn`` corners
    whose texture/normal indices differ from the vertex index): path, V and polygons."""
    V, polys = box_figure_soup()
    return write_soup_obj(tmp_path / "figure.obj", V, polys), V, polys


@pytest.mark.parametrize("rel, nv, nf", OBJS)
def test_obj_counts(data_dir, rel, nv, nf):
    V, F = sio.read_obj(data_dir / rel)
    assert V.shape == (nv, 3) and F.shape == (nf, 3)
    assert V.dtype == np.float64 and F.dtype == np.int64
    assert F.min() >= 0 and F.max() < nv


@pytest.mark.parametrize(
    "rel",
    [
        "arm/arm.obj",  # plain
        "human/human_man.obj",
        "plane/plane_holes.obj",  # open
        "spot/spot_low_resolution.obj",  # v//vn
    ],
)
def test_obj_matches_igl(data_dir, rel):
    V, F = sio.read_obj(data_dir / rel)
    Vi, Fi = igl.read_triangle_mesh(str(data_dir / rel))
    np.testing.assert_array_equal(V, Vi)
    np.testing.assert_array_equal(F, Fi)


def test_obj_soup_matches_igl(soup_obj):
    path, V0, polys = soup_obj
    V, F = sio.read_obj(path)
    Vi, Fi = igl.read_triangle_mesh(str(path))
    np.testing.assert_array_equal(V, Vi)
    np.testing.assert_array_equal(F, Fi)
    np.testing.assert_array_equal(V, V0)
    np.testing.assert_array_equal(F, fan_triangles(polys))


def test_obj_polygon_soup_against_trimesh_and_meshio(soup_obj):
    path, _, polys0 = soup_obj
    V, F, polys = sio.read_obj(path, return_polygons=True)
    sizes = np.array([len(p) for p in polys])
    assert len(polys) == len(polys0) and np.sum(sizes == 3) > 0 and np.sum(sizes == 4) > 0
    assert all(np.array_equal(a, b) for a, b in zip(polys, polys0))
    assert len(np.unique(V, axis=0)) < len(V)  # a soup: positions repeat
    meshio = pytest.importorskip("meshio")
    m = meshio.read(path)
    np.testing.assert_array_equal(V, m.points)
    ref = [row for block in m.cells for row in block.data]  # meshio keeps file order in runs
    assert len(ref) == len(polys)
    assert all(np.array_equal(a, b) for a, b in zip(polys, ref))
    trimesh = pytest.importorskip("trimesh")
    t = trimesh.load(path, process=False, maintain_order=True)
    np.testing.assert_array_equal(V, t.vertices)
    # trimesh splits quads into the same triangles, written from another corner
    np.testing.assert_array_equal(_canonical_triangles(F), _canonical_triangles(t.faces))


def test_obj_unusual_lines_take_the_checked_path(soup_obj, tmp_path):
    # "v x y z w" lines and "f" lines with tabs make the reader go line by line: same result
    path = soup_obj[0]
    lines = path.read_text().splitlines()
    lines = [ln + " 1.0" if ln.startswith("v ") else ln.replace(" ", "\t") for ln in lines]
    V, F, P = sio.read_obj(path, return_polygons=True)
    V2, F2, P2 = sio.read_obj(_write(tmp_path, "w.obj", "\n".join(lines)), return_polygons=True)
    np.testing.assert_array_equal(V2, V)
    np.testing.assert_array_equal(F2, F)
    assert all(np.array_equal(a, b) for a, b in zip(P, P2)) and len(P) == len(P2)


def test_obj_2d(data_dir, tmp_path):
    x, y = np.meshgrid(np.linspace(0, 3, 7), np.linspace(0, 2, 5))
    V0 = np.c_[x.ravel(), y.ravel()]
    F0 = np.array([[0, 1, 8], [0, 8, 7], [1, 2, 9]])
    text = "".join(f"v {a:.17g} {b:.17g} 0\n" for a, b in V0)
    text += "".join(f"f {i + 1} {j + 1} {k + 1}\n" for i, j, k in F0)
    p = _write(tmp_path, "flat.obj", text)
    V, F = sio.read_obj(p, dim=2)
    np.testing.assert_array_equal(V, V0)
    np.testing.assert_array_equal(F, F0)
    with pytest.raises(ValueError, match=r"arm\.obj: line \d+: dim=2 needs z = 0"):
        sio.read_obj(data_dir / "arm/arm.obj", dim=2)
    with pytest.raises(ValueError, match="dim"):
        sio.read_obj(p, dim=4)


def test_obj_variants(tmp_path):
    text = (
        "mtllib x.mtl\no thing\n# comment\nv 0 0 0\nv 1 0 0 1.0\nvt 0 0\nvn 0 0 1\n"
        "v 1 1 0  # trailing comment\r\nv 0 1 0 0.5 0.5 0.5\ng grp\ns off\nusemtl m\n"
        "f 1/1 2/1 3/1 4/1\nf -4//1 -3//1 -1//1\nl 1 2\nv 5 5\nf 3/1/1 4/1/1 -1/1/1\n"
    )
    V, F, polys = sio.read_obj(_write(tmp_path, "v.obj", text), return_polygons=True)
    np.testing.assert_array_equal(V, [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [5, 5, 0]])
    np.testing.assert_array_equal(F, [[0, 1, 2], [0, 2, 3], [0, 1, 3], [2, 3, 4]])
    assert [p.tolist() for p in polys] == [[0, 1, 2, 3], [0, 1, 3], [2, 3, 4]]
    V, F = sio.read_obj(_write(tmp_path, "e.obj", "v 0 0 0\n"))
    assert V.shape == (1, 3) and F.shape == (0, 3)
    # a pentagon fans into 3 triangles
    pent = "v 0 0 0\nv 1 0 0\nv 2 1 0\nv 1 2 0\nv 0 1 0\nf 1 2 3 4 5\n"
    _, F = sio.read_obj(_write(tmp_path, "p.obj", pent))
    np.testing.assert_array_equal(F, [[0, 1, 2], [0, 2, 3], [0, 3, 4]])


TRI = "v 0 0 0\nv 1 0 0\nv 0 1 0\n"


@pytest.mark.parametrize(
    "text, line, what",
    [
        (TRI + "f 1 2 4\n", 4, r"face vertex '4' is out of range"),
        (TRI + "f 1 2 0\n", 4, r"face vertex '0'"),
        (TRI + "f 1 2 -4\n", 4, r"face vertex '-4'"),
        ("v 0 0 0\nf 1 2 3\nv 1 0 0\nv 0 1 0\nf -1 -2 -4\n", 5, r"'-4'.*3 vertices read so far"),
        (TRI + "f 1 2 3\nhello world\n", 5, "got 'hello'"),
        (TRI + "f 1 2\n", 4, "at least 3 vertices"),
        (TRI + "f 1/1 2/x /3\n", 4, "vertex index in a face, got '/3'"),
        (TRI + "f 1 two 3\n", 4, "got 'two'"),
        ("v 0 0 0\nv 1 0 nan\n", 2, "non-finite"),
        ("v 0 0 0\nv 1 0 z\n", 2, "got 'z'"),
        ("v 0\n", 1, "vertex line"),
    ],
)
def test_obj_malformed(tmp_path, text, line, what):
    with pytest.raises(ValueError, match=rf"bad\.obj: line {line}: .*{what}"):
        sio.read_obj(_write(tmp_path, "bad.obj", text))


def test_obj_round_trip(soup_obj, tmp_path):
    V, F = sio.read_obj(soup_obj[0])
    p = tmp_path / "t.obj"
    sio.write_obj(p, V, F)
    V2, F2 = sio.read_obj(p)
    np.testing.assert_array_equal(V2, V)
    np.testing.assert_array_equal(F2, F)
    Vi, Fi = igl.read_triangle_mesh(str(p))  # libigl reads what we write
    np.testing.assert_array_equal(Vi, V)
    np.testing.assert_array_equal(Fi, F)
    # quads and 2D vertices
    Q = np.array([[0, 1, 2, 3]])
    sio.write_obj(str(p), np.array([[0.0, 0], [1, 0], [1, 1], [0, 1]]), Q)
    V3, _, P3 = sio.read_obj(p, return_polygons=True, dim=2)
    np.testing.assert_array_equal(V3, [[0, 0], [1, 0], [1, 1], [0, 1]])
    np.testing.assert_array_equal(P3[0], Q[0])
    with pytest.raises(ValueError, match="F"):
        sio.write_obj(p, V, F + len(V))


# --------------------------------------------------------------------------------------------
# poly2tri .dat


def _signed_area(P):
    x, y = P[:, 0], P[:, 1]
    return 0.5 * np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y)


def test_polygon_dat(data_dir):
    outer, holes = sio.read_polygon_dat(data_dir / "polygons-2d/dude.dat")
    assert outer.shape == (94, 2) and [h.shape for h in holes] == [(4, 2), (6, 2)]
    # README: outer clockwise, holes counter-clockwise, area about 14,903
    assert _signed_area(outer) < 0 and all(_signed_area(h) > 0 for h in holes)
    area = -_signed_area(outer) - sum(_signed_area(h) for h in holes)
    assert area == pytest.approx(14903, abs=1)
    np.testing.assert_array_equal(outer[0], [280.35714, 648.79075])
    monkey, holes = sio.read_polygon_dat(data_dir / "polygons-2d/nazca_monkey.dat")  # CRLF
    assert monkey.shape == (1204, 2) and holes == []
    assert _signed_area(monkey) > 0
    np.testing.assert_allclose(np.ptp(monkey, axis=0), [125, 123], atol=1)


@pytest.mark.parametrize(
    "text, line, what",
    [
        ("0 0\n1 0\n1 x\n", 3, "point 'x y'"),
        ("0 0\n1 0\n1 1 1\n", 3, "point 'x y'"),
        ("0 0\n1 0\n1 1\nHOLE\n0.1 0.1\n0.2 0.1\n", 4, "hole starting here has 2 points"),
        ("0 0\n1 0\n", 1, "outer ring"),
    ],
)
def test_polygon_dat_malformed(tmp_path, text, line, what):
    with pytest.raises(ValueError, match=rf"bad\.dat: line {line}: .*{what}"):
        sio.read_polygon_dat(_write(tmp_path, "bad.dat", text))


# --------------------------------------------------------------------------------------------
# RigNet rig


def test_rignet_rig(tmp_path):
    V, _ = box_figure_soup()
    rig = sio.read_rignet_rig(write_rignet_rig(tmp_path / "figure_rig.txt", V))
    names, C, BE, W = rig["names"], rig["C"], rig["BE"], rig["W"]
    names0, C0, BE0 = figure_skeleton()
    assert list(names) == names0 and names[rig["root"]] == "root"
    np.testing.assert_array_equal(C, C0)
    np.testing.assert_array_equal(BE, BE0)
    np.testing.assert_array_equal(W, figure_skin(V))
    assert W.shape == (V.shape[0], len(names0))
    np.testing.assert_allclose(W.sum(axis=1), 1, atol=1e-4)
    assert (W != 0).sum(axis=1).max() == 3
    # coincident joints, a tree rooted at "root"
    ix = {n: i for i, n in enumerate(names)}
    np.testing.assert_array_equal(C[ix["hip_dup_0"]], C[ix["hip_dup_1"]])
    parents = np.bincount(BE[:, 1], minlength=len(names))
    assert parents[rig["root"]] == 0 and parents.max() == 1


RIG = "joints a 0 0 0\njoints b 0 1 0\nroot a\n"


@pytest.mark.parametrize(
    "text, line, what",
    [
        (RIG + "hier a c\n", 4, "unknown joint 'c'"),
        (RIG + "skin 0 a 0.5 c 0.5\n", 4, "unknown joint 'c'"),
        (RIG + "skin 0 a\n", 4, "expected 'skin"),
        (RIG + "skin 0 a x\n", 4, "weight after joint 'a'"),
        (RIG + "skin 0 a 1\nskin 0 b 1\n", 5, "second 'skin' line"),
        (RIG + "skin 1 a 1\n", 4, "vertex id 1 is out of range"),
        (RIG + "skin 0 a 0 a 1\n", 4, "joint 'a' appears twice"),
        (RIG + "hier a b\nhier b b\n", 5, "its own parent"),
        (RIG + "joints c 0 0 1\nhier a b\nhier c b\n", 6, r"already a child \(line 5\)"),
        (RIG + "hier b a\n", 4, "it is the root"),
        (RIG + "bones a b\n", 4, "got 'bones'"),
        (RIG + "joints a 1 1 1\n", 4, "defined twice"),
        ("joints a 0 0\n", 1, "joints <name> x y z"),
    ],
)
def test_rignet_malformed(tmp_path, text, line, what):
    with pytest.raises(ValueError, match=rf"bad\.txt: line {line}\b.*{what}"):
        sio.read_rignet_rig(_write(tmp_path, "bad.txt", text))


def test_missing_file_is_not_a_value_error(tmp_path):
    with pytest.raises(FileNotFoundError):
        sio.read_mesh(tmp_path / "nope.mesh")
