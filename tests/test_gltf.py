"""glTF skins: write -> read round trips, and Blender (bpy) posing our .glb like skinrs.lbs."""

import importlib.util
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import skinrs
from scipy.spatial import cKDTree
from skinrs import gltf_rig
from skinrs.io import read_gltf, write_gltf

ROOT = Path(__file__).resolve().parents[1]

# Runs inside Blender's Python: imports a .glb; with a pose file, sets every pose bone to the
# skinrs transform of the same name, else steps through the animation; evaluates the skinned
# mesh and saves rest/posed vertices and bone heads/tails in glTF's Y-up coordinates; exports
# the scene again with Blender's glTF exporter.
BLENDER_SCRIPT = r"""
import sys
import bpy
import numpy as np
from mathutils import Matrix

glb, out, export, pose = sys.argv[-4:]
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.import_scene.gltf(filepath=glb)
scene = bpy.context.scene
arm = next(o for o in scene.objects if o.type == "ARMATURE")
mesh = next(o for o in scene.objects if o.type == "MESH" and o.parent == arm)
S = np.eye(4)
S[:3, :3] = [[1.0, 0, 0], [0, 0, -1], [0, 1, 0]]  # glTF Y-up -> Blender Z-up


def world(obj, points):
    M = np.linalg.inv(S) @ np.array(obj.matrix_world)
    return np.asarray(points).reshape(-1, 3) @ M[:3, :3].T + M[:3, 3]


def evaluated():
    ev = mesh.evaluated_get(bpy.context.evaluated_depsgraph_get())
    me = ev.to_mesh()
    co = np.empty(len(me.vertices) * 3)
    me.vertices.foreach_get("co", co)
    ev.to_mesh_clear()
    return world(mesh, co)


def depth(bone):
    return 0 if bone.parent is None else 1 + depth(bone.parent)


frames = []
if pose != "-":  # skinrs transforms T (world, glTF axes): bone matrix = T @ rest matrix
    p = np.load(pose)
    A = np.array(arm.matrix_world)
    for pb in sorted(arm.pose.bones, key=lambda b: depth(b.bone)):  # parents first
        if pb.name in list(p["names"]):
            T = np.eye(4)
            T[:3] = p["T"][list(p["names"]).index(pb.name)]
            M = np.linalg.inv(A) @ S @ T @ np.linalg.inv(S) @ A @ np.array(pb.bone.matrix_local)
            pb.matrix = Matrix(M.tolist())
            bpy.context.view_layer.update()
    frames.append(evaluated())
else:
    f0, f1 = arm.animation_data.action.frame_range
    for f in range(int(f0), int(f1) + 1):
        scene.frame_set(f)
        frames.append(evaluated())
co = np.empty(len(mesh.data.vertices) * 3)
mesh.data.vertices.foreach_get("co", co)
bones = arm.data.bones
bpy.ops.export_scene.gltf(filepath=export, export_format="GLB")
np.savez(out, rest=world(mesh, co), frames=np.array(frames), fps=scene.render.fps,
         names=np.array([b.name for b in bones]),
         heads=world(arm, [tuple(b.head_local) for b in bones]),
         tails=world(arm, [tuple(b.tail_local) for b in bones]))
"""


def blender_or_skip():
    exe = blender_python()
    if exe is None:
        pytest.skip(
            "Blender check skipped: no Python with bpy. `make venv` installs bpy into "
            ".venv-blender; or point SKINRS_BLENDER_PYTHON at a Python 3.11 with "
            "`pip install 'skinrs[blender]'`"
        )
    return exe


def run_blender(tmp_path, glb, pose=None):
    """Blender's view of ``glb`` (see BLENDER_SCRIPT) and the path of its own export."""
    exe = blender_or_skip()
    script, out, export = tmp_path / "blender.py", tmp_path / "out.npz", tmp_path / "export.glb"
    script.write_text(BLENDER_SCRIPT)
    args = [exe, script, glb, out, export, "-" if pose is None else pose]
    run = subprocess.run(
        list(map(str, args)), check=False, capture_output=True, text=True, timeout=300
    )
    assert run.returncode == 0, run.stderr[-2000:]
    return np.load(out), export


# Runs in a subprocess: loads a .glb with panda3d-gltf (a game-engine loader: skinning matrix =
# joint world matrix x inverse bind matrix), sets every joint's parent-relative matrix, and saves
# the rest and CPU-skinned vertices in glTF's Y-up coordinates.
PANDA3D_SCRIPT = r"""
import sys
import numpy as np
from panda3d.core import LMatrix4f, Thread, GeomVertexReader, NodePath, loadPrcFileData
loadPrcFileData("", "window-type none\naudio-library-name null\nnotify-level error")
import gltf
from direct.actor.Actor import Actor

glb, pose, out = sys.argv[1:4]
p = np.load(pose)
S = np.eye(4)
S[:3, :3] = [[1.0, 0, 0], [0, 0, -1], [0, 1, 0]]  # glTF Y-up -> Panda3D Z-up
actor = Actor(NodePath(gltf.load_model(glb)))
for name, L in zip(p["names"], p["local"]):
    joint = actor.controlJoint(None, "modelRoot", str(name))
    joint.setMat(LMatrix4f(*(S @ L @ S.T).T.reshape(-1).tolist()))  # row-vector convention
actor.update(force=True)


def vertices(animated):
    xyz = []
    for path in actor.findAllMatches("**/+GeomNode"):
        for geom in path.node().getGeoms():
            data = geom.getAnimatedVertexData(True, Thread.getCurrentThread()) if animated else geom.getVertexData()
            reader = GeomVertexReader(data, "vertex")
            while not reader.isAtEnd():
                xyz.append(tuple(reader.getData3()))
    return np.array(xyz) @ S[:3, :3]


np.savez(out, rest=vertices(False), posed=vertices(True))
"""


def blender_python():
    """A Python that can import bpy, or None."""
    for exe in (os.environ.get("SKINRS_BLENDER_PYTHON"), ROOT / ".venv-blender" / "bin" / "python"):
        if exe and os.access(exe, os.X_OK):
            return str(exe)
    if importlib.util.find_spec("bpy") is not None:
        return sys.executable
    return None


@pytest.fixture(scope="module")
def arm(data_dir):
    V, F = skinrs.io.read_obj(data_dir / "arm" / "arm.obj")
    C, BE = skinrs.io.read_tgf(data_dir / "arm" / "arm.tgf")
    # two more bones branch off the elbow: joint nodes that share a head must still turn apart
    C = np.vstack([C, C[2] + [0, 0.25, 0.05], C[2] + [0, -0.2, 0.1]])
    BE = np.vstack([BE, [[2, 5], [2, 6]]])
    D = np.stack([_segment_distance(V, C[a], C[b]) for a, b in BE], axis=1)
    W = np.exp(-0.5 * (D / 0.05) ** 2) + 1e-9  # smooth, 6 influences everywhere
    return V, F, C, BE, W / W.sum(1, keepdims=True)


def _segment_distance(X, a, b):
    t = np.clip((X - a) @ (b - a) / ((b - a) @ (b - a)), 0, 1)
    return np.linalg.norm(X - (a + t[:, None] * (b - a)), axis=1)


def _identity(m):
    return np.broadcast_to(np.hstack([np.eye(3), np.zeros((3, 1))]), (m, 3, 4))


def _pose(C, BE, seed):
    rng = np.random.default_rng(seed)
    Q = rng.normal(size=(len(BE), 4))
    Q[:, 0] += 2.5  # turns of up to ~60 degrees
    return skinrs.forward_kinematics(C, BE, Q / np.linalg.norm(Q, axis=1, keepdims=True))


def test_blender_poses_the_glb_like_lbs(arm, tmp_path):
    V, F, C, BE, W = arm
    packed = skinrs.reduce_weights(W, 4, method="k-largest")
    poses = np.stack([_identity(len(BE)), _pose(C, BE, 1), _pose(C, BE, 2)])
    glb = tmp_path / "arm.glb"
    write_gltf(glb, V, F, packed, C, BE, poses=poses, times=[0.0, 0.5, 1.0])
    b, export = run_blender(tmp_path, glb)
    dist, rows = cKDTree(b["rest"]).query(V)  # Blender may order vertices its own way
    diag = np.linalg.norm(np.ptp(V, axis=0))
    assert dist.max() <= 1e-6 * diag
    fps = float(b["fps"])
    for t, T in ((0.5, poses[1]), (1.0, poses[2])):
        U_blender = b["frames"][round(t * fps)][rows]
        deviation = np.linalg.norm(U_blender - skinrs.lbs(V, packed, T), axis=1).max() / diag
        assert deviation <= 1e-4  # measured: 2.5e-7 and 5.7e-7 (float32 in the file)
    names = list(b["names"])
    for k, (h, t) in enumerate(BE):  # one Blender bone per column, head and tail as in skinrs
        j = names.index(f"bone{k}")
        assert np.abs(b["heads"][j] - C[h]).max() <= 1e-6 * diag
        assert np.abs(b["tails"][j] - C[t]).max() <= 1e-6 * diag
    a = read_gltf(export)  # read_gltf on Blender's own export
    dist, rows = cKDTree(a["V"]).query(V)
    assert dist.max() <= 1e-6 * diag and a["names"] == [f"bone{k}" for k in range(len(BE))]
    assert np.abs(a["C"][a["BE"]] - C[BE]).max() <= 1e-6 * diag
    assert np.abs(a["W"][rows] - skinrs.unpack_weights(*packed, len(BE))).max() <= 1e-3
    U = skinrs.lbs(a["V"], a["W"], a["animations"][0]["T"][-1])[rows]
    assert np.linalg.norm(U - skinrs.lbs(V, packed, poses[-1]), axis=1).max() <= 1e-4 * diag


@pytest.mark.slow  # the arm's weights: 15-20 s
def test_blender_poses_the_command_lines_arm_like_lbs(data_dir, tmp_path):
    blender_or_skip()
    glb = tmp_path / "arm.glb"
    obj, tgf = data_dir / "arm" / "arm.obj", data_dir / "arm" / "arm.tgf"
    run = subprocess.run(
        [sys.executable, "-m", "skinrs", "-q", "weights", obj, tgf, "-o", glb],
        check=False,
        capture_output=True,
        text=True,
    )
    assert run.returncode == 0, run.stderr
    a = read_gltf(glb)
    T = skinrs.random_skeleton_poses(a["C"], a["BE"], 1, max_angle=1.0, seed=3)[0]
    np.savez(tmp_path / "pose.npz", names=np.array(a["names"]), T=T)
    b, _ = run_blender(tmp_path, glb, tmp_path / "pose.npz")  # posed bone by bone in Blender
    dist, rows = cKDTree(b["rest"]).query(a["V"])
    diag = np.linalg.norm(np.ptp(a["V"], axis=0))
    assert dist.max() <= 1e-6 * diag
    U = skinrs.lbs(a["V"], a["W"], T)
    assert np.linalg.norm(U - a["V"], axis=1).max() > 0.2 * diag  # a real pose
    deviation = np.linalg.norm(b["frames"][0][rows] - U, axis=1).max() / diag
    assert deviation <= 1e-4  # measured: 1.6e-7


def test_panda3d_poses_the_glb_like_lbs(arm, tmp_path):
    if importlib.util.find_spec("gltf") is None:
        pytest.skip("Panda3D check skipped: `make venv` installs panda3d and panda3d-gltf")
    V, F, C, BE, W = arm
    packed = skinrs.reduce_weights(W, 4, method="k-largest")
    write_gltf(tmp_path / "arm.glb", V, F, packed, C, BE)
    j = read_gltf(tmp_path / "arm.glb")["joints"]
    T = _pose(C, BE, 6)
    world = (
        gltf_rig.homogeneous(gltf_rig.joint_poses(T[None], j["column"], j["parents"], j["bind"])[0])
        @ j["bind"]
    )
    local = gltf_rig.local_matrices(j["parents"], world)  # each joint relative to its parent
    np.savez(tmp_path / "pose.npz", names=np.array(j["names"]), local=local)
    (tmp_path / "panda.py").write_text(PANDA3D_SCRIPT)
    args = [
        sys.executable,
        tmp_path / "panda.py",
        tmp_path / "arm.glb",
        tmp_path / "pose.npz",
        tmp_path / "out.npz",
    ]
    run = subprocess.run(
        list(map(str, args)), check=False, capture_output=True, text=True, timeout=300
    )
    assert run.returncode == 0, run.stderr[-2000:]
    out = np.load(tmp_path / "out.npz")
    dist, rows = cKDTree(out["rest"]).query(V)  # (Panda3D does not share vertices)
    diag = np.linalg.norm(np.ptp(V, axis=0))
    assert dist.max() <= 1e-6 * diag
    U = skinrs.lbs(V, packed, T)
    assert np.linalg.norm(U - V, axis=1).max() > 0.1 * diag  # a real pose
    assert np.linalg.norm(out["posed"][rows] - U, axis=1).max() <= 1e-4 * diag  # measured 1.7e-6


def test_round_trip_keeps_mesh_skeleton_weights_and_animation(arm, tmp_path):
    V, F, C, BE, W = arm
    packed = skinrs.reduce_weights(W, 4, method="k-largest")
    poses = np.stack([_identity(len(BE)), _pose(C, BE, 3)])
    names = [f"j{b}" for b in range(len(BE))]
    write_gltf(tmp_path / "arm.glb", V, F, packed, C, BE, poses=poses, names=names)
    a = read_gltf(tmp_path / "arm.glb")
    scale = np.abs(V).max()
    assert np.abs(a["V"] - V).max() <= 1e-7 * scale  # float32 positions
    np.testing.assert_array_equal(a["F"], F)
    np.testing.assert_array_equal(a["BE"], BE)
    assert np.abs(a["C"] - C).max() <= 1e-6 * scale
    assert a["P"].shape == (0,) and a["names"] == names
    assert np.abs(a["W"] - skinrs.unpack_weights(*packed, len(BE))).max() <= 1e-6
    (anim,) = a["animations"]
    np.testing.assert_allclose(anim["times"], [0, 1 / 24])
    assert np.abs(anim["T"] - poses).max() <= 1e-5
    assert a["joints"]["names"][len(BE) :] == ["j3_end", "j4_end", "j5_end"]
    # any numbering of the joints comes back (kept in the nodes' extras)
    perm = np.random.default_rng(0).permutation(len(C))
    C2, BE2 = C[perm], np.argsort(perm)[BE]
    write_gltf(tmp_path / "perm.glb", V, F, packed, C2, BE2)
    b = read_gltf(tmp_path / "perm.glb")
    np.testing.assert_array_equal(b["BE"], BE2)
    assert np.abs(b["C"] - C2).max() <= 1e-6 * scale


def test_more_than_k_columns_are_reduced_with_poisson_by_default(arm, tmp_path):
    V, F, C, BE, W = arm
    write_gltf(tmp_path / "arm.gltf", V, F, W, C, BE, k=4)
    a = read_gltf(tmp_path / "arm.gltf")
    poses = skinrs.random_skeleton_poses(C, BE, 8, seed=0)
    I, A = skinrs.reduce_weights(W, 4, method="poisson", V=V, F=F, bone_transforms=poses)
    assert np.abs(a["W"] - skinrs.unpack_weights(I, A, len(BE))).max() <= 1e-6
    assert ((a["W"] > 0).sum(1) <= 4).all()
    # 8 influences: JOINTS_1 / WEIGHTS_1 hold the rest, nothing dropped
    write_gltf(tmp_path / "arm8.glb", V, F, W, C, BE, k=8)
    assert np.abs(read_gltf(tmp_path / "arm8.glb")["W"] - W).max() <= 1e-6


def test_the_file_follows_the_gltf_rules(arm, tmp_path):
    V, F, C, BE, W = arm
    write_gltf(tmp_path / "arm.gltf", V, F, W, C, BE, method="k-largest")
    doc = json.loads((tmp_path / "arm.gltf").read_text())
    prim = doc["meshes"][0]["primitives"][0]
    joints = doc["accessors"][prim["attributes"]["JOINTS_0"]]
    weights = doc["accessors"][prim["attributes"]["WEIGHTS_0"]]
    assert joints["componentType"] == 5121 and joints["type"] == "VEC4"  # unsigned byte
    assert weights["componentType"] == 5126
    pos = doc["accessors"][prim["attributes"]["POSITION"]]
    assert np.allclose(pos["min"], V.min(0), atol=1e-6) and "max" in pos
    a = read_gltf(tmp_path / "arm.gltf")
    assert np.abs(a["W"].sum(1) - 1).max() <= 2e-7  # float32 weights sum to 1
    # a common root holds the mesh and the joints (Panda3D needs one)
    root = doc["nodes"][doc["scenes"][0]["nodes"][0]]
    assert 1 in root["children"] and doc["skins"][0]["skeleton"] == 0


def test_an_existing_asset_keeps_its_joints_and_animation_when_reweighted(arm, tmp_path):
    V, F, C, BE, W = arm
    poses = np.stack([_identity(len(BE)), _pose(C, BE, 4), _pose(C, BE, 5)])
    write_gltf(tmp_path / "a.glb", V, F, W, C, BE, poses=poses, method="k-largest")
    a = read_gltf(tmp_path / "a.glb")
    W2 = np.roll(a["W"], 1, axis=1)
    W2 = 0.5 * (a["W"] + W2)  # other weights, same skeleton
    write_gltf(tmp_path / "b.glb", a["V"], a["F"], W2, asset=a, method="k-largest")
    b = read_gltf(tmp_path / "b.glb")
    for key in ("names", "parents"):
        assert list(b["joints"][key]) == list(a["joints"][key])
    assert np.abs(b["joints"]["bind"] - a["joints"]["bind"]).max() <= 1e-6
    assert np.abs(b["animations"][0]["T"] - a["animations"][0]["T"]).max() <= 1e-5
    I, A = skinrs.reduce_weights(W2, 4, method="k-largest")
    assert np.abs(b["W"] - skinrs.unpack_weights(I, A, W2.shape[1])).max() <= 1e-6


def test_a_joint_with_children_at_several_points_drives_one_bone_each():
    # hips (0) with spine (1) and two legs (2, 3); an end joint (4) above the spine
    pos = np.array([[0, 1, 0], [0, 1.5, 0], [0.2, 0.9, 0], [-0.2, 0.9, 0], [0, 2, 0.0]])
    bind = np.broadcast_to(np.eye(4), (5, 4, 4)).copy()
    bind[:, :3, 3] = pos
    parents = np.array([-1, 0, 0, 0, 1])
    used = np.array([True, True, True, True, False])
    C, BE, P, column = gltf_rig.handles_of_rig(parents, bind, used, 1e-9)
    assert P.shape == (2,)  # the legs carry weight and have no children: point handles
    np.testing.assert_array_equal(column, [2, 3, 0, 0, 0, 1])
    np.testing.assert_allclose(C[BE[:, 0]], pos[[0, 0, 0, 1]])
    np.testing.assert_allclose(C[BE[:, 1]], pos[[1, 2, 3, 4]])


def test_bad_input_is_named(arm, tmp_path):
    V, F, C, BE, W = arm
    with pytest.raises(ValueError, match=r"\.glb or \.gltf"):
        write_gltf(tmp_path / "a.obj", V, F, W, C, BE)
    with pytest.raises(ValueError, match="one column per handle"):
        write_gltf(tmp_path / "a.glb", V, F, W[:, :3], C, BE)
    with pytest.raises(ValueError, match="k must be 4 or 8"):
        write_gltf(tmp_path / "a.glb", V, F, W, C, BE, k=5)
    with pytest.raises(ValueError, match="negative"):
        write_gltf(
            tmp_path / "a.glb", V, F, (np.zeros((len(V), 1), int), -np.ones((len(V), 1))), C, BE
        )
    with pytest.raises(ValueError, match="6 influences per vertex, more than k = 4"):
        write_gltf(tmp_path / "a.glb", V, F, skinrs.reduce_weights(W, 6, method="k-largest"), C, BE)
    with pytest.raises(ValueError, match="poses must have shape"):
        write_gltf(tmp_path / "a.glb", V, F, W, C, BE, poses=np.zeros((2, 3, 3, 4)))
    assert not (tmp_path / "a.glb").exists()
    (tmp_path / "bad.glb").write_bytes(b"not a glb at all")
    with pytest.raises(ValueError, match="bad.glb: not a readable glTF"):
        read_gltf(tmp_path / "bad.glb")
    with pytest.raises(FileNotFoundError):
        read_gltf(tmp_path / "missing.glb")
