"""The ``skinrs`` command line, run as users run it: in a subprocess, checking exit codes and files."""

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import skinrs
from skinrs.io import read_gltf

COMMANDS = ("weights", "reduce", "pose", "info")


def skinrs_cli(*args, cwd=None, timeout=300):
    return subprocess.run(
        [sys.executable, "-m", "skinrs", *map(str, args)],
        check=False,
        capture_output=True,
        text=True,
        cwd=cwd,
        timeout=timeout,
    )


def assert_one_line_error(run, *words):
    assert run.returncode == 2, run.stderr
    lines = run.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in run.stderr, run.stderr
    for w in words:
        assert w in lines[0], lines[0]


@pytest.fixture(scope="module")
def arm(data_dir):
    """tests/data/arm: the libigl arm (arm.obj, arm.tgf)."""
    return data_dir / "arm"


@pytest.fixture(scope="module")
def arm_glb(tmp_path_factory, arm):
    """``skinrs weights arm.obj arm.tgf -o arm.glb`` (the README's example), run once."""
    out = tmp_path_factory.mktemp("cli") / "arm.glb"
    run = skinrs_cli("weights", arm / "arm.obj", arm / "arm.tgf", "-o", out)
    assert run.returncode == 0, run.stderr
    return out


@pytest.fixture(scope="module")
def capsule(tmp_path_factory):
    """A small closed capsule along x (.off, .ply, .stl) and a 2-bone .tgf inside it."""
    import trimesh

    d = tmp_path_factory.mktemp("capsule")
    mesh = trimesh.creation.capsule(height=1.6, radius=0.3, count=[24, 24])
    mesh.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, [0, 1, 0]))
    for ext in ("off", "ply", "stl"):
        mesh.export(d / f"capsule.{ext}")
    trimesh.PointCloud(mesh.vertices).export(d / "cloud.ply")
    skinrs.io.write_tgf(d / "capsule.tgf", [[-0.7, 0, 0], [0, 0, 0], [0.7, 0, 0]], [[0, 1], [1, 2]])
    return d, np.asarray(mesh.vertices)


def test_help_on_every_command():
    for args in ([], *([c] for c in COMMANDS)):
        run = skinrs_cli(*args, "--help")
        assert run.returncode == 0 and "usage: skinrs" in run.stdout, run.stderr
    script = Path(sys.executable).parent / "skinrs"  # the console script of pyproject.toml
    run = subprocess.run([script, "--help"], check=False, capture_output=True, text=True)
    assert run.returncode == 0 and all(c in run.stdout for c in COMMANDS)


@pytest.mark.slow  # (the arm's weights: 15-20 s)
def test_weights_of_the_arm_as_a_glb(arm, arm_glb):
    a = read_gltf(arm_glb)
    V, F = skinrs.io.read_obj(arm / "arm.obj")
    C, BE = skinrs.io.read_tgf(arm / "arm.tgf")
    assert np.abs(a["V"] - V).max() <= 1e-6 and (a["F"] == F).all()
    np.testing.assert_array_equal(a["BE"], BE)
    W = a["W"]
    assert W.min() >= 0 and np.abs(W.sum(1) - 1).max() <= 1e-6
    # the vertices closest to a bone's middle follow that bone
    for b, (h, t) in enumerate(BE):
        near = np.argsort(np.linalg.norm(V - (C[h] + C[t]) / 2, axis=1))[:20]
        assert (W[near].argmax(1) == b).all()


def test_weights_from_other_formats_and_to_weight_files(capsule, tmp_path):
    d, V = capsule
    outs = {}
    for ext, out in (("off", "w.dmat"), ("ply", "w.csv"), ("stl", "w.npz")):
        run = skinrs_cli("weights", d / f"capsule.{ext}", d / "capsule.tgf", "-o", tmp_path / out)
        assert run.returncode == 0, run.stderr
        outs[ext] = tmp_path / out
    with np.load(outs["stl"]) as z:  # STL corners are merged: rows of the merged mesh
        Ws = z["W"]
    # (PLY and STL hold float32 coordinates: TetGen meshes the inside a little differently)
    for W in (skinrs.io.read_dmat(outs["off"]), np.loadtxt(outs["ply"], delimiter=",")):
        assert W.shape == (len(V), 2) and np.abs(W.sum(1) - 1).max() <= 1e-9
        assert W[V[:, 0] < -0.8, 0].min() > 0.6 and W[V[:, 0] > 0.8, 1].min() > 0.6
    assert Ws.shape == (len(V), 2) and np.abs(Ws.sum(1) - 1).max() <= 1e-9


def test_weights_of_a_surface_split_at_a_seam(capsule, tmp_path):
    """Exporters split vertices at UV seams: the file's vertices that repeat a position get
    the weights of the surface without the split, each one its point's."""
    d, V = capsule
    F = _faces_of(d / "capsule.off")
    upper = V[F].mean(1)[:, 1] > 0  # faces of one half point at copies of their vertices
    copied = np.unique(F[upper])
    V2 = np.vstack([V, V[copied]])
    F2 = F.copy()
    F2[upper] = len(V) + np.searchsorted(copied, F[upper])
    skinrs.io.write_obj(tmp_path / "whole.obj", V, F)
    skinrs.io.write_obj(tmp_path / "split.obj", V2, F2)
    W = {}
    for name in ("whole", "split"):
        run = skinrs_cli("weights", tmp_path / f"{name}.obj", d / "capsule.tgf",
                         "-o", tmp_path / f"{name}.dmat")  # fmt: skip
        assert run.returncode == 0, run.stderr
        W[name] = skinrs.io.read_dmat(tmp_path / f"{name}.dmat")
    assert f"merged {len(copied)} vertices" in run.stderr, run.stderr
    assert W["split"].shape == (len(V2), 2)
    np.testing.assert_allclose(W["split"][: len(V)], W["whole"], atol=1e-12)
    np.testing.assert_array_equal(W["split"][len(V) :], W["split"][copied])


def _faces_of(path):
    import trimesh

    return np.asarray(trimesh.load(path, process=False).faces, dtype=np.int64)


def test_weights_with_k_influences(capsule, tmp_path):
    d, V = capsule
    run = skinrs_cli(
        "weights", d / "capsule.off", d / "capsule.tgf", "-k", "1", "--reduce-method",
        "k-largest", "-o", tmp_path / "w.npz",
    )  # fmt: skip
    assert run.returncode == 0, run.stderr
    with np.load(tmp_path / "w.npz") as z:
        assert z["indices"].shape == (len(V), 1) and ((z["W"] > 0).sum(1) == 1).all()


@pytest.mark.slow  # (the field's point set: ~5 s of CPU even for 12 steps)
def test_weights_of_a_point_cloud_with_the_field_method(capsule, tmp_path):
    d, V = capsule
    run = skinrs_cli("weights", d / "cloud.ply", d / "capsule.tgf", "-o", tmp_path / "f.dmat")
    assert_one_line_error(run, "use --method field")
    run = skinrs_cli(
        "weights", d / "cloud.ply", d / "capsule.tgf", "--method", "field", "--steps", "12",
        "-o", tmp_path / "f.dmat",
    )  # fmt: skip
    assert run.returncode == 0, run.stderr
    W = skinrs.io.read_dmat(tmp_path / "f.dmat")
    assert W.shape == (len(V), 2) and np.abs(W.sum(1) - 1).max() <= 1e-9
    assert W.min() >= 0  # (12 steps: plumbing only; tests/test_field.py checks the weights)


def test_weights_of_a_glb_keep_its_joints_and_pose_from_a_file(capsule, tmp_path):
    d, _ = capsule
    first, again = tmp_path / "capsule.glb", tmp_path / "again.gltf"
    run = skinrs_cli("weights", d / "capsule.off", d / "capsule.tgf", "-o", first)
    assert run.returncode == 0, run.stderr
    run = skinrs_cli("weights", first, "-o", again)  # the skeleton comes from the skin
    assert run.returncode == 0, run.stderr
    a, b = read_gltf(first), read_gltf(again)
    assert b["joints"]["names"] == a["joints"]["names"] == ["bone0", "bone1", "bone1_end"]
    assert np.abs(b["joints"]["bind"] - a["joints"]["bind"]).max() <= 1e-6
    # solved again on the float32 positions of the file (TetGen meshes the inside differently)
    assert b["W"].shape == a["W"].shape and np.abs(b["W"].sum(1) - 1).max() <= 1e-6
    assert (b["W"][b["V"][:, 0] > 0.8].argmax(1) == 1).all()
    T = skinrs.forward_kinematics(a["C"], a["BE"], [[1.0, 0, 0, 0], [0.8, 0, 0, 0.6]])
    np.save(tmp_path / "pose.npy", T)
    run = skinrs_cli("pose", first, "--pose", tmp_path / "pose.npy", "-o", tmp_path / "p.png")
    assert run.returncode == 0 and (tmp_path / "p.png").stat().st_size > 1000, run.stderr
    np.save(tmp_path / "bad.npy", T[:1])
    run = skinrs_cli("pose", first, "--pose", tmp_path / "bad.npy", "-o", tmp_path / "q.png")
    assert_one_line_error(run, "expected 2 bones")


def test_weights_of_a_tet_mesh_make_an_asset_of_its_surface(data_dir, tmp_path):
    d = data_dir / "decimated-knight"
    out = tmp_path / "knight.glb"
    run = skinrs_cli("weights", d / "decimated-knight.mesh", d / "decimated-knight.tgf", "-o", out)
    assert run.returncode == 0, run.stderr
    V, T, F = skinrs.io.read_mesh(d / "decimated-knight.mesh")
    C, BE = skinrs.io.read_tgf(d / "decimated-knight.tgf")
    a = read_gltf(out)
    used = np.unique(F)
    assert np.abs(a["V"] - V[used]).max() <= 1e-5 and len(a["V"]) == 1774
    assert ((a["W"] > 0).sum(1) <= 4).all() and np.abs(a["W"].sum(1) - 1).max() <= 1e-6
    W = skinrs.bbw_dual(V, T, C, BE=BE, tol=1e-6)[used]
    clear = W.max(1) > 0.6  # where one bone dominates, the packed weights agree on which
    assert (a["W"][clear].argmax(1) == W[clear].argmax(1)).all()


def test_weights_beyond_memory_limit_fail_before_factoring(data_dir, tmp_path):
    # The knight's factor of B_ff alone takes about 1.2 MiB: 500kB cannot hold it.
    d = data_dir / "decimated-knight"
    out = tmp_path / "knight.dmat"
    mesh, tgf = d / "decimated-knight.mesh", d / "decimated-knight.tgf"
    run = skinrs_cli("-q", "weights", mesh, tgf, "-o", out, "--memory-limit", "500kB")
    assert_one_line_error(run, "memory_limit: the Cholesky factor of B_ff")
    assert not out.exists()
    run = skinrs_cli("weights", mesh, tgf, "-o", out, "--memory-limit", "1GiB")
    assert run.returncode == 0, run.stderr
    V, T, _ = skinrs.io.read_mesh(mesh)
    C, BE = skinrs.io.read_tgf(tgf)
    W = skinrs.bbw_dual(V, T, C, BE=BE, tol=1e-6)  # the command's default tol
    np.testing.assert_array_equal(skinrs.io.read_dmat(out), W)


def test_weights_of_a_tet_mesh_reduced_to_k_influences(data_dir, tmp_path):
    """Poisson reduction works on the boundary triangles; interior rows keep their k largest."""
    d = data_dir / "decimated-knight"
    out = tmp_path / "knight.npz"
    run = skinrs_cli(
        "weights", d / "decimated-knight.mesh", d / "decimated-knight.tgf", "-k", "2", "-o", out
    )  # fmt: skip
    assert run.returncode == 0, run.stderr
    V, T, F = skinrs.io.read_mesh(d / "decimated-knight.mesh")
    C, BE = skinrs.io.read_tgf(d / "decimated-knight.tgf")
    with np.load(out) as z:
        W2 = z["W"]
    assert W2.shape == (len(V), 7) and ((W2 > 0).sum(1) <= 2).all()
    assert np.abs(W2.sum(1) - 1).max() <= 1e-9 and W2.min() >= 0
    W = skinrs.bbw_dual(V, T, C, BE=BE, tol=1e-6)
    interior = np.setdiff1d(np.arange(len(V)), F)
    assert len(interior) == 48
    top2 = np.argsort(-W[interior], axis=1)[:, :2]
    kept = np.take_along_axis(W[interior], top2, 1)
    expected = kept / kept.sum(1, keepdims=True)
    got = np.take_along_axis(W2[interior], top2, 1)
    assert np.abs(got - expected).max() <= 1e-4


def test_reduce(capsule, tmp_path):
    d, V = capsule
    W = np.random.default_rng(0).random((len(V), 2))
    skinrs.io.write_dmat(tmp_path / "w.dmat", W / W.sum(1, keepdims=True))
    out = tmp_path / "r.dmat"
    run = skinrs_cli("reduce", tmp_path / "w.dmat", "-k", "1", "--method", "k-largest", "-o", out)
    assert run.returncode == 0, run.stderr
    R = skinrs.io.read_dmat(out)
    np.testing.assert_array_equal(R.argmax(1), W.argmax(1))
    assert ((R > 0).sum(1) == 1).all()
    run = skinrs_cli(
        "reduce", tmp_path / "w.dmat", "-k", "1", "--mesh", d / "capsule.off",
        "--skeleton", d / "capsule.tgf", "-o", tmp_path / "p.npz",
    )  # fmt: skip
    assert run.returncode == 0, run.stderr
    with np.load(tmp_path / "p.npz") as z:
        assert z["indices"].shape == (len(V), 1)
    run = skinrs_cli("reduce", tmp_path / "w.dmat", "-k", "1", "-o", out)
    assert_one_line_error(run, "--method poisson needs --mesh and --skeleton")


@pytest.mark.slow  # (the arm's weights: 15-20 s)
def test_pose_writes_a_picture(arm, arm_glb, tmp_path):
    for pose, extra in (("random:1", []), ("random:2", ["--dqs"])):
        out = tmp_path / f"{pose.replace(':', '')}.png"
        run = skinrs_cli("pose", arm_glb, "--pose", pose, *extra, "-o", out)
        assert run.returncode == 0, run.stderr
        assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    run = skinrs_cli("pose", arm_glb, "--pose", "frame:0", "-o", tmp_path / "f.png")
    assert_one_line_error(run, "has no animation")
    run = skinrs_cli("pose", arm / "arm.obj", "-o", tmp_path / "f.png")
    assert_one_line_error(run, "not a skinned glTF asset")


@pytest.mark.slow  # (the arm's weights: 15-20 s)
def test_info(arm, arm_glb):
    run = skinrs_cli("info", arm / "arm.obj", arm / "arm.tgf", "--json")
    assert run.returncode == 0, run.stderr
    info = json.loads(run.stdout)
    assert info["vertices"] == 8311 and info["faces"] == 16618 and info["watertight"]
    assert info["joints"] == 5 and info["bones"] == 4 and info["joints_outside"] == []
    run = skinrs_cli("info", arm_glb)
    assert run.returncode == 0 and "bones: 4" in run.stdout and "bone3_end" in run.stdout


def test_bad_files_and_arguments(arm, tmp_path):
    (tmp_path / "bad.glb").write_bytes(b"garbage")
    (tmp_path / "bad.obj").write_text("v 0 0 0\nf 1 2 3\n")
    cases = [
        (("weights", tmp_path / "missing.obj", arm / "arm.tgf", "-o", tmp_path / "o.glb"), "no such file"),
        (("weights", arm / "arm.obj", arm / "arm.tgf", "-o", tmp_path / "o.xyz"), "unknown output format"),
        (("weights", arm / "arm.obj", "-o", tmp_path / "o.glb"), "no skeleton"),
        (("weights", arm / "arm.obj", arm / "arm.obj", "-o", tmp_path / "o.glb"), "unknown skeleton format"),
        (("weights", tmp_path / "bad.obj", arm / "arm.tgf", "-o", tmp_path / "o.glb"), "out of range"),
        (("weights", arm / "arm.obj", arm / "arm.tgf", "-k", "2", "-o", tmp_path / "o.glb"), "4 or 8"),
        (("info", tmp_path / "bad.glb"), "not a readable glTF"),
        (("info", arm / "arm.tgf"), "unknown mesh format"),
    ]  # fmt: skip
    for args, words in cases:
        assert_one_line_error(skinrs_cli(*args), words)
    assert not list(tmp_path.glob("o.*")) and not list(tmp_path.glob(".skinrs-*"))
    run = skinrs_cli("weights", arm / "arm.obj", "--method", "nope", "-o", tmp_path / "o.glb")
    assert_one_line_error(run, "invalid choice")
    run = skinrs_cli("--debug", "info", tmp_path / "bad.glb")
    assert run.returncode != 0 and "Traceback" in run.stderr


def test_bad_input_gives_one_line_and_exit_2(arm, tmp_path):
    # a small fuzz of the command line: bad files, formats, -k and options (run in parallel)
    d = tmp_path
    (d / "junk.obj").write_bytes(b"garbage\x00\x01")
    (d / "nan.obj").write_text("v nan 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    (d / "cut.obj").write_text((arm / "arm.obj").read_text()[:200])
    (d / "bad.tgf").write_text("0 0 0\n")
    (d / "w.csv").write_text("0.5 0.5\n")
    (d / "w.dmat").write_text("3 2\n0.5 0.5\n0.5 0.5\n0.5 0.5\n")
    np.savez(d / "w.npz", X=np.ones((2, 2)))
    mesh, tgf, out = arm / "arm.obj", arm / "arm.tgf", d / "o.glb"
    cases = [
        (("weights", d / "junk.obj", tgf, "-o", out), "junk.obj: line 1"),
        (("weights", d / "nan.obj", tgf, "-o", out), "non-finite"),
        (("weights", d / "cut.obj", tgf, "-o", out), "cut.obj: line"),
        (("weights", mesh, d / "bad.tgf", "-o", out), "bad.tgf: line 1"),
        (("weights", mesh, tgf, "-o", d / "nodir" / "o.glb"), "does not exist"),
        (("weights", mesh, tgf, "-k", "0", "-o", out), "--influences"),
        (("weights", mesh, tgf, "-k", "x", "-o", out), "--influences"),
        (("weights", mesh, tgf, "--tol", "-1", "-o", out), "--tol"),
        (("weights", mesh, tgf, "--tol", "nan", "-o", out), "--tol"),
        (("weights", mesh, tgf, "--steps", "0", "--method", "field", "-o", out), "--steps"),
        (("weights", mesh, tgf, "--memory-limit", "4XB", "-o", out), "--memory-limit"),
        (("weights", mesh, tgf, "--memory-limit", "-1GB", "-o", out), "--memory-limit"),
        (("weights", mesh, tgf, "--frobnicate", "-o", out), "--frobnicate"),
        (("weights", mesh, tgf), "-o"),
        (("reduce", d / "w.csv", "-k", "1", "--method", "k-largest", "-o", d / "o.csv"), "w.csv"),
        (("reduce", d / "w.npz", "-k", "1", "--method", "k-largest", "-o", d / "o.csv"), "'W'"),
        (("reduce", d / "w.dmat", "-k", "0", "-o", d / "o.csv"), "-k"),
        (("reduce", d / "w.dmat", "-k", "9", "--method", "k-largest", "-o", d / "o.csv"), "only 3 handles"),
        (("reduce", d / "missing.dmat", "-k", "1", "-o", d / "o.csv"), "no such file"),
        (("pose", d / "missing.glb", "-o", d / "p.png"), "no such file"),
        (("pose", mesh, "-o", d / "p.png"), "not a skinned glTF"),
        (("info", d / "junk.obj"), "junk.obj: line 1"),
        (("info", mesh, d / "bad.tgf"), "bad.tgf"),
        (("batch", d / "missing", "-o", d / "b"), "manifest"),
        (("batch", d, "-o", d / "b", "--workers", "0"), "--workers"),
        (("batch", d, "-o", d / "b", "--retries", "-1"), "--retries"),
        (("nope",), "invalid choice"),
        ((), "COMMAND"),
    ]  # fmt: skip
    procs = [
        subprocess.Popen([sys.executable, "-m", "skinrs", *map(str, args)], text=True,
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE)
        for args, _ in cases
    ]  # fmt: skip
    for (args, words), proc in zip(cases, procs, strict=True):
        out, err = proc.communicate(timeout=300)
        run = subprocess.CompletedProcess(proc.args, proc.returncode, out, err)
        assert_one_line_error(run, words)
    assert not list(d.glob("o.*")) and not list(d.glob("p.*")) and not (d / "b").exists()


# `python -m skinrs` with Python's Ctrl-C handler: a runner started in the background by a shell
# without job control ignores SIGINT, an ignored signal stays ignored across exec, and Python
# then installs no KeyboardInterrupt.
SKINRS_WITH_CTRL_C = (
    "import runpy, signal; signal.signal(signal.SIGINT, signal.default_int_handler); "
    "runpy.run_module('skinrs', run_name='__main__', alter_sys=True)"
)


def test_ctrl_c_exits_130_and_writes_nothing(arm, tmp_path):
    out = tmp_path / "arm.glb"
    proc = subprocess.Popen(
        [sys.executable, "-c", SKINRS_WITH_CTRL_C, "weights", arm / "arm.obj", arm / "arm.tgf",
         "-o", out],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )  # fmt: skip
    for line in proc.stderr:  # wait until the work has started
        if "meshing" in line:
            break
    time.sleep(1)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err
    assert "interrupted" in err and "Traceback" not in err
    assert os.listdir(tmp_path) == []


def test_progress_bar_reads_stage_then_percent(capsys):
    from skinrs._cli_io import Progress, gap_progress

    bar = Progress(False, 100.0, "%", gap_progress(1e-6))
    bar("dual", 3, 1e-3)
    bar.close()
    err = capsys.readouterr().err
    assert "\rdual: " in err and ": :" not in err, repr(err)
