"""Regression tests: each bad or extreme input of issue 21 gives a clear error or a correct
result. Calls that once crashed the process run in a ``_sandbox`` worker."""

from __future__ import annotations

import os
import signal
import threading
from concurrent.futures import ThreadPoolExecutor

import _fuzz_cases
import numpy as np
import pytest
import skinrs
from _fuzz_cases import cube_surface, cube_tets, grid_2d, square_outline
from _sandbox import Sandbox


@pytest.fixture(scope="module")
def sandbox():
    sb = Sandbox(timeout=30)
    yield sb
    sb.close()


def raises_naming(out, *names):
    """The sandboxed call raised ValueError whose message names one of ``names``."""
    assert out.raised("ValueError"), f"expected ValueError, got {out.error}: {out.message}"
    assert any(n in out.message for n in names), out.message
    return out.message


IDENTITY = np.stack([np.hstack([np.eye(3), np.zeros((3, 1))])] * 2)


def _skin_inputs(n=50):
    rng = np.random.default_rng(0)
    W = rng.random((n, 2))
    return rng.random((n, 3)), W / W.sum(1, keepdims=True)


# --- panics -------------------------------------------------------------------------------


@pytest.mark.parametrize("f", [skinrs.lbs, skinrs.dqs])
@pytest.mark.parametrize("rows", [40, 60])
def test_normals_of_the_wrong_shape(f, rows):
    V, W = _skin_inputs()
    with pytest.raises(ValueError, match=r"N must have shape \(50, 3\)"):
        f(V, W, IDENTITY, N=np.ones((rows, 3)))
    packed = (np.zeros((50, 1), np.int64), np.ones((50, 1)))
    with pytest.raises(ValueError, match="N must have shape"):
        f(V, packed, IDENTITY, N=np.ones((rows, 3)))


def test_closest_point_on_a_huge_square():
    V, E = square_outline()
    with pytest.raises(ValueError, match=r"V row \d+ .*overflow"):
        skinrs.closest_point(V * 1e155, E, np.array([[0.5, 0.5]]))
    # the largest accepted scale gives the right answer
    d, p, f, _ = skinrs.closest_point(V * 1e75, E, np.array([[0.5e75, -1e75]]))
    np.testing.assert_allclose(d, [1e75])
    np.testing.assert_allclose(p, [[0.5e75, 0]])
    assert f.tolist() == [0]


def test_panics_become_internal_error_not_panic_exception(sandbox):
    assert issubclass(skinrs.InternalError, RuntimeError)
    out = sandbox.call("skinrs._skinrs:_panic_for_tests", "index out of bounds")
    assert out.error == "InternalError" and "RuntimeError" in out.bases
    assert "bug in skinrs" in out.message and "index out of bounds" in out.message
    assert sandbox.call("skinrs:bone_parents", np.array([[0, 1]])).error is None  # still alive


# --- aborts (allocations decided by one integer) --------------------------------------------


def test_connected_components_huge_counts(sandbox):
    raises_naming(sandbox.call("skinrs:connected_components", np.array([[0, 10**11]])), "F")
    raises_naming(
        sandbox.call("skinrs:connected_components", np.array([[0, 1, 2]]), n=10**10), "n="
    )


def test_bone_parents_huge_joint_numbers(sandbox):
    out = sandbox.call("skinrs:bone_parents", np.array([[0, 10**10]]))
    assert out.error is None and out.value.tolist() == [-1]
    out = sandbox.call("skinrs:bone_parents", np.array([[0, 1]]), n_joints=10**9)
    assert out.error is None and out.value.tolist() == [-1]


@pytest.mark.parametrize("option", ["n_points", "samples", "pool"])
def test_field_sizes(sandbox, option):
    V, E = square_outline()
    kw = {"C": np.array([[0.3, 0.5], [0.7, 0.5]]), "P": np.array([0, 1]), option: 10**9}
    raises_naming(sandbox.call("skinrs:GeometricField", V, E, **kw), option)
    raises_naming(sandbox.call("skinrs:bbw_field", V, E, **kw), option)


def test_wrong_dimensions_do_not_build_huge_messages():
    V, T = cube_tets()
    with pytest.raises(ValueError, match=r"bc must have shape \(n, m\)"):
        skinrs.bbw_dual_constrained(V, T, np.array([0, 1]), np.array([1.0, 0.0]))
    with pytest.raises(ValueError, match="W must have shape"):
        skinrs.reduce_weights(np.array([0.5, 0.5]), 1, method="k-largest")
    with pytest.raises(ValueError, match="weights must have shape"):
        skinrs.unpack_weights(np.array([[0]]), np.array([1.0]), 2)
    with pytest.raises(ValueError, match="weights must have shape"):
        skinrs.transform_normals(
            np.array([[0.0, 0, 1]]), (np.array([[0]]), np.array([1.0])), bone_transforms=IDENTITY
        )


def test_paint_with_3d_weights():
    V, E = square_outline()
    g = skinrs.GeometricField(V, E, [[0.3, 0.5], [0.7, 0.5]], P=[0, 1], n_points=64, steps=2)
    with pytest.raises(ValueError, match="weights must have shape"):
        g.paint([[0.5, 0.5]], np.ones((1, 2, 1)))


# --- segfaults in the C meshers -------------------------------------------------------------


def test_skin_weights_with_a_repeated_vertex(sandbox):
    V = np.array([[0.0, 0], [4, 0], [4, 0], [4, 1], [0, 1]])
    C = np.array([[0.5, 0.5], [3.5, 0.5]])
    msg = raises_naming(sandbox.call("skinrs:skin_weights", V, None, C, [[0, 1]]), "V rows 1 and 2")
    assert "duplicate" in msg


def test_mesh_with_skeleton_bad_flags(sandbox):
    V, F = cube_surface()
    C = np.array([[0.3, 0.5, 0.5], [0.7, 0.5, 0.5]])
    for flags in ["zzzz!!", "ri", "pq1.2/10Yz", "q"]:
        out = sandbox.call("skinrs:mesh_with_skeleton", V, F, C, [[0, 1]], flags=flags)
        raises_naming(out, "flags")


def test_mesh_with_tiny_coordinates(sandbox):
    V = np.array([[0.0, 0], [4, 1e-266], [4, 1], [0, 1]])
    C = np.array([[0.5, 0.5], [3.5, 0.5]])
    out = sandbox.call("skinrs:mesh_with_skeleton", V, None, C, [[0, 1]])
    raises_naming(out, "V row 1")


def test_needle_outline(sandbox):
    # once a nondeterministic segfault in Triangle: normalised, rows 0 and 3 became one vertex
    V = np.array([[0.0, 0], [4, -4.7e16], [4, 1], [0, 1]])
    C = np.array([[0.5, 0.5], [2, 0.5], [3.5, 0.5]])
    for f in ("mesh_with_skeleton", "skin_weights"):
        out = sandbox.call(f"skinrs:{f}", V, None, C, [[0, 1], [1, 2]])
        assert "same units" in raises_naming(out, "C")
        # a skeleton along the needle: the outline's end is below double precision
        for _ in range(3):
            out = sandbox.call(f"skinrs:{f}", V, None, [[2, 0.5], [3.7, -4e16]], [[0, 1]])
            assert "lie 1 apart" in raises_naming(out, "V rows 0 and 3")


# A self-crossing outline on which Triangle's quality refinement loops, filling the memory
# (17 GB in 2 minutes); it runs in a child process with a memory bound (a few seconds).
LOOPING_OUTLINE = np.array(
    [[-4.0274381813233449, 2.8656206815747471], [-2.4834839993864797e-3, -4.0672663772630688e-3],
     [19.573146182101720, 5.8279162798843140], [-750.75201540134583, 347.29182527219450],
     [-7.5294784516984443e-3, 5.4783709894190456e-3], [-3.1713384495036585e-4, 8.7272363983125466e-4],
     [1.4283578719939157e-4, -2.2433194096868051e-5], [-1.6177871489921735e-2, -3.0183744660197136e-3]]
)  # fmt: skip
LOOPING_C = np.array([[0.21673101079154974, -0.01329912766410345],
                      [0.4353071030618173, 0.44207591857555717],
                      [0.22413942026274367, 0.8981862358742393]])  # fmt: skip


def test_triangle_refinement_that_never_ends(sandbox):
    out = sandbox.call(
        "skinrs:mesh_with_skeleton", LOOPING_OUTLINE, None, LOOPING_C, [[0, 1], [1, 2]]
    )
    assert "crossing" in raises_naming(out, "V, F")


def _mesher_children() -> list[str]:
    """Processes started by this one that run the mesher child script."""
    found = []
    for pid in filter(str.isdigit, os.listdir("/proc")):
        try:
            with open(f"/proc/{pid}/stat") as f:
                ppid = int(f.read().rsplit(")", 1)[1].split()[1])
            with open(f"/proc/{pid}/cmdline", "rb") as f:
                cmd = f.read().decode(errors="replace")
        except (OSError, ValueError, IndexError):
            continue
        if ppid == os.getpid() and "_mesher_child" in cmd:
            found.append(pid)
    return found


@pytest.mark.skipif(not os.path.isdir("/proc"), reason="reads child processes from /proc")
def test_ctrl_c_stops_a_mesher_child():
    # Ctrl-C during the looping Triangle run (seconds until its memory bound) kills the child;
    # Python's own handler, in case the runner was started with SIGINT ignored
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    timer = threading.Timer(0.5, os.kill, (os.getpid(), signal.SIGINT))
    timer.start()
    try:
        with pytest.raises(KeyboardInterrupt):
            skinrs.mesh_with_skeleton(LOOPING_OUTLINE, None, LOOPING_C, [[0, 1], [1, 2]])
    finally:
        timer.cancel()
        signal.signal(signal.SIGINT, previous)
    assert _mesher_children() == []


def test_tetgen_heap_corruption_is_an_error(sandbox):
    # a cube with one corner pushed just through the opposite face: on some machines TetGen's
    # self-intersection check passes, then it corrupts its heap ("corrupted double-linked list",
    # abort); on others the check catches the fold. Either way the caller gets a RuntimeError
    # (TetGen runs in a child process), and the fTetWild fallback meshes the surface instead
    V, F = cube_surface()
    V = V.astype(float)
    V[4, 0] = 1 - 1.0000162464402906
    C = np.array([[0.3, 0.5, 0.5], [0.7, 0.5, 0.5]])
    out = sandbox.call("skinrs._external_meshers:_tetgen", V, F, C, "pq2Y", False, check=True)
    assert out.raised("RuntimeError"), out.message
    assert "TetGen failed" in out.message or "self-intersections" in out.message, out.message
    out = sandbox.call("skinrs:mesh_with_skeleton", V, F, C, [[0, 1]])
    assert out.error is None, out.message
    Vv, T, b, bc = out.value
    S = Vv[b]  # the bone samples: on the bone
    assert T.shape[1] == 4 and T.max() < len(Vv) and np.allclose(bc.sum(1), 1)
    assert np.allclose(S[:, 1:], 0.5) and np.all((S[:, 0] > 0.3 - 1e-9) & (S[:, 0] < 0.7 + 1e-9))


def test_triangle_area_switch_in_input_units():
    # the area bound reaches Triangle in unit-box units without an exponent ("6.25e-05" was
    # read as the switches e, 0, 5 and the bound dropped)
    V = np.array([[0.0, 0], [4, 0], [4, 1], [0, 1]]) * 100
    C = np.array([[50.0, 50], [350, 50]])
    Vv, T, _, _ = skinrs.mesh_with_skeleton(V, None, C, [[0, 1]], flags="pq30a10")
    e1, e2 = Vv[T[:, 1]] - Vv[T[:, 0]], Vv[T[:, 2]] - Vv[T[:, 0]]
    area = 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
    assert area.max() <= 10 * (1 + 1e-9) and area.sum() == pytest.approx(40_000)
    with pytest.raises(ValueError, match="flags 'pa0.00000001': .*memory"):
        skinrs.mesh_with_skeleton(V, None, C, [[0, 1]], flags="pa0.00000001")


@pytest.mark.parametrize("scale_V, scale_C", [(2e5, 1.0), (1.0, 1e-5)])
def test_skeleton_in_other_units_than_the_shape(sandbox, scale_V, scale_C):
    # V scaled by 2e5 against an unscaled skeleton: a mesh of needles, and a solve of minutes
    V = np.array([[0.0, 0], [4, 0], [4, 1], [0, 1]]) * scale_V
    C = np.array([[0.5, 0.5], [2, 0.5], [3.5, 0.5]]) * scale_C
    out = sandbox.call("skinrs:skin_weights", V, None, C, [[0, 1], [1, 2]])
    assert "same units" in raises_naming(out, "C")


@pytest.mark.parametrize("spe, what", [(0, "samples_per_edge"), (1e9, "samples_per_edge")])
def test_samples_per_edge(spe, what):
    V = np.array([[0.0, 0], [4, 0], [4, 1], [0, 1]])
    with pytest.raises(ValueError, match=what):
        skinrs.mesh_with_skeleton(V, None, [[0.5, 0.5], [3.5, 0.5]], [[0, 1]], samples_per_edge=spe)


# --- hangs ----------------------------------------------------------------------------------


def test_knn_with_a_far_outlier(sandbox):
    X = np.random.default_rng(0).random((2000, 3))
    X[0] = [1e6, 0, 0]
    out = sandbox.call("skinrs:knn_distance", X)
    assert out.error is None
    d = out.value
    ref = np.sort(np.linalg.norm(X[:, None] - X[None], axis=-1), axis=1)[:, 9]
    np.testing.assert_allclose(d, ref, rtol=1e-12)
    X[0] = [1e308, 0, 0]
    raises_naming(sandbox.call("skinrs:knn_distance", X), "X row 0")


def test_field_evaluation_far_away(sandbox):
    out = sandbox.call("_fuzz_cases:field_evaluate", np.array([[1e6, 0.5], [1e70, 0.5]]))
    assert out.error is None, out.message
    np.testing.assert_allclose(out.value.sum(1), 1.0)


# --- silent wrong answers -------------------------------------------------------------------


def test_far_queries_are_refused_or_correct():
    V, E = square_outline()
    with pytest.raises(ValueError, match=r"Q row 0 .*overflow"):
        skinrs.winding_number(V, E, np.array([[1e200, 0.5]]))
    with pytest.raises(ValueError, match=r"Q row 0 .*overflow"):
        skinrs.closest_point(V, E, np.array([[1e160, 0.5]]))
    w = skinrs.winding_number(V, E, np.array([[1e75, 0.5], [0.5, 0.5]]))
    np.testing.assert_allclose(w, [0, 1], atol=1e-12)
    Vs, Fs = cube_surface()
    w = skinrs.winding_number(Vs * 1e74, Fs, np.array([[5e73, 5e73, 5e73], [1e75, 0, 0]]))
    np.testing.assert_allclose(w, [1, 0], atol=1e-9)


def test_normals_at_large_scale():
    V, F = cube_surface()
    N = skinrs.per_vertex_normals(V * 1e70, F)
    np.testing.assert_allclose(N, skinrs.per_vertex_normals(V, F), atol=1e-12)


def test_field_on_a_flat_closed_surface():
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0.0]])
    F = np.array([[0, 1, 2], [1, 3, 2], [0, 2, 1], [1, 2, 3]])
    with pytest.raises(ValueError, match="V is flat"):
        skinrs.bbw_field(V, F, [[0.2, 0.2, 0], [0.7, 0.7, 0]], P=[0, 1], steps=2)


def _write(tmp_path, name, text):
    p = tmp_path / name
    p.write_text(text, newline="")
    return p


def test_truncated_tgf(tmp_path):
    text = "".join(f"{i} {i}.5 0.25 0\n" for i in range(1, 13)) + "#\n1 2\n#\n"
    cut = text[: text.index("12 12.5") + 9]  # inside joint 12's line
    with pytest.raises(ValueError, match=r"cut\.tgf: line 12 \(end of file\): .*cut"):
        skinrs.io.read_tgf(_write(tmp_path, "cut.tgf", cut))


def test_obj_cut_in_its_normals(tmp_path):
    text = "v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 1\nvn 0 0 1\nf 1//1 2//1 3//1\n"
    with pytest.raises(ValueError, match=r"cut\.obj: .*no face"):
        skinrs.io.read_obj(_write(tmp_path, "cut.obj", text[: text.index("vn 0 0 1\nf") + 4]))


def test_rignet_cut_and_cycle(tmp_path):
    text = (
        "joints a 0 0 0\njoints b 0 1 0\njoints c 0 2 0\nroot a\nhier a b\nhier b c\n"
        "skin 0 a 1.0\nskin 1 a 0.5 b 0.5\n"
    )
    with pytest.raises(ValueError, match=r"cut_rig\.txt: .*not connected to the root"):
        skinrs.io.read_rignet_rig(_write(tmp_path, "cut_rig.txt", text[: text.index("hier b")]))
    with pytest.raises(ValueError, match=r"cut_rig\.txt: line 8: .*sum to 0\.5"):
        skinrs.io.read_rignet_rig(_write(tmp_path, "cut_rig.txt", text[:-3]))
    cycle = text.replace("hier a b\nhier b c\n", "hier a b\nhier c b\nhier b c\n")
    with pytest.raises(ValueError, match="cycle.rig.txt: line 6"):
        skinrs.io.read_rignet_rig(_write(tmp_path, "cycle_rig.txt", cycle))
    cycle = "joints a 0 0 0\njoints b 0 1 0\njoints c 0 2 0\nroot a\nhier b c\nhier c b\n"
    with pytest.raises(ValueError, match="cycle_rig.txt: .*cycle"):
        skinrs.io.read_rignet_rig(_write(tmp_path, "cycle_rig.txt", cycle))


@pytest.mark.parametrize("bad", ["nan", "inf", "-inf"])
def test_dmat_rejects_non_finite(tmp_path, bad):
    with pytest.raises(ValueError, match=r"w\.dmat: line 3: .*NaN and infinite"):
        skinrs.io.read_dmat(_write(tmp_path, "w.dmat", f"1 2\n0.5\n{bad}\n"))
    raw = np.array([0.5, float(bad)]).astype("<f8").tobytes()
    (tmp_path / "b.dmat").write_bytes(b"0 0\n1 2\n" + raw)
    with pytest.raises(ValueError, match=r"b\.dmat: .*row 1, column 0"):
        skinrs.io.read_dmat(tmp_path / "b.dmat")


def test_complex_quaternions_and_fractional_seeds():
    with pytest.raises(ValueError, match="Q must be real"):
        skinrs.quaternions_from_xyzw(np.array([0, 0, 0, 1 + 1j]))
    V, F = square_outline()
    with pytest.raises(ValueError, match="seed"):
        skinrs.GeometricField(V, F, [[0.3, 0.5], [0.7, 0.5]], P=[0, 1], seed=1.5)
    with pytest.raises(ValueError, match="seed"):
        skinrs.random_skeleton_poses([[0, 0, 0], [0, 1, 0]], [[0, 1]], 2, seed=1.5)


# --- unclear errors -------------------------------------------------------------------------


def test_named_errors_for_out_of_range_integers():
    V, T = cube_tets()
    b, bc = np.array([0, 7]), np.eye(2)
    for kw, name in [({"seed": -1}, "seed"), ({"max_iter": 2**70}, "max_iter")]:
        with pytest.raises(ValueError, match=name):
            skinrs.bbw_dual_constrained(V, T, b, bc, **kw)
    with pytest.raises(ValueError, match=r"F holds index 18446744073709551615"):
        skinrs.cotan_laplacian(*grid_2d()[:1], np.full((1, 3), 2**64 - 1, dtype=np.uint64))


def test_callback_errors_pass_through():
    V, T = grid_2d(12)

    def interrupt(*a):
        raise KeyboardInterrupt

    class Mine(Exception):
        pass

    def mine(*a):
        raise Mine("from the callback")

    b, bc = np.array([0, 143]), np.eye(2)
    with pytest.raises(KeyboardInterrupt):
        skinrs.bbw_dual_constrained(V, T, b, bc, callback=interrupt)
    with pytest.raises(Mine, match="from the callback"):
        skinrs.bbw_dual_constrained(V, T, b, bc, callback=mine)
    with pytest.raises(ValueError, match="callback must be callable"):
        skinrs.bbw_dual_constrained(V, T, b, bc, callback=5)


def _callback_calls():
    """A call of each binding that reports progress to a callback."""
    V, T = grid_2d(12)
    return {
        "bbw": lambda cb: skinrs.bbw_dual_constrained(V, T, [0, 143], np.eye(2), callback=cb),
        "reduce": lambda cb: skinrs.reduce_weights(**_fuzz_cases._poisson_kw(), callback=cb),
        "field": lambda cb: skinrs.bbw_field(**_fuzz_cases._field_kw(), callback=cb),
    }


@pytest.mark.parametrize("name", ["bbw", "reduce", "field"])
def test_callbacks_run_on_the_calling_thread(name):
    # the callback's exception is kept per thread until the computation (which may run its
    # loops on rayon's threads) has stopped; it must reach the caller in every thread
    call = _callback_calls()[name]
    seen: list[int] = []
    call(lambda *a: seen.append(threading.get_ident()))
    assert seen and set(seen) == {threading.get_ident()}

    class Mine(Exception):
        pass

    def run(i):
        def cb(*a):
            seen.append(threading.get_ident())
            if i == 2:
                raise KeyboardInterrupt
            raise Mine(f"from thread {i}")

        try:
            call(cb)
        except (Mine, KeyboardInterrupt) as e:
            return type(e).__name__, str(e), threading.get_ident()
        return None

    seen.clear()
    with ThreadPoolExecutor(3) as pool:
        out = list(pool.map(run, range(3)))
    assert [o[:2] for o in out] == [("Mine", "from thread 0"), ("Mine", "from thread 1"),
                                    ("KeyboardInterrupt", "")]  # fmt: skip
    assert set(seen) == {o[2] for o in out}


def test_overflowing_coordinates_say_overflow():
    V, F = grid_2d()
    with pytest.raises(ValueError, match=r"V row \d+ .*overflow"):
        skinrs.cotan_laplacian(V * 1e300, F)
    with pytest.raises(ValueError, match=r"V spans only .*underflow"):
        skinrs.cotan_laplacian(V * 1e-80, F)


def test_knn_errors_name_k_and_X():
    with pytest.raises(ValueError, match="k must be smaller"):
        skinrs.knn_distance(np.random.default_rng(0).random((5, 2)), k=5)


def test_numpy_errors_do_not_leak():
    V, W = _skin_inputs(4)
    with pytest.raises(ValueError, match="N must have shape"):
        skinrs.dqs(V[:, :2], W, IDENTITY[:, :2, [0, 1, 3]], N=np.ones((3, 2)))
    Vg, Fg = grid_2d(3)
    B = skinrs.biharmonic_matrix(Vg, Fg)
    with pytest.raises(ValueError, match=r"W must have 9 rows like B"):
        skinrs.biharmonic_energy(np.ones((8, 2)), B)
