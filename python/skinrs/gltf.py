"""glTF 2.0 skins, both ways: ``.gltf`` / ``.glb`` through pygltflib (pure Python, MIT).

:func:`write_gltf` turns a mesh, a skinrs skeleton (``C``, ``BE``, ``P``) and weights into a
skinned asset that Blender, three.js, Godot or Unity load; :func:`read_gltf` reads one back
(mesh, joint hierarchy, bind pose, weights, animations) in skinrs' conventions. Coordinates are
written as given (glTF is Y-up, in metres; convert before writing if yours are not).

How bone columns map to joint nodes (docs/gltf.md): column ``c`` of ``W`` is joint node ``c``.
A bone's node sits at its head, where skinrs' bone turns (:func:`skinrs.forward_kinematics`),
with +Y along the bone (as Blender's exporter writes bones); child bones' nodes sit at its tail,
a bone without children gets an end node ``<name>_end`` there (weight 0), and a point handle is
a node without children. Blender's importer then makes one bone per column with head and tail
where skinrs has them, and a skinrs pose moves the mesh in Blender as :func:`skinrs.lbs` does
(tests/test_gltf.py checks this in Blender).
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from types import ModuleType
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from . import gltf_rig as rig
from ._checks import as_elements, as_index_array, as_points
from .gltf_read import GltfAsset, read_gltf

if TYPE_CHECKING:
    import pygltflib

__all__ = ["read_gltf", "write_gltf"]

_ARRAY, _ELEMENTS = 34962, 34963
_TYPES = {1: "SCALAR", 2: "VEC2", 3: "VEC3", 4: "VEC4", 16: "MAT4"}
_COMPONENTS = {5120: np.int8, 5121: np.uint8, 5122: np.int16, 5123: np.uint16, 5125: np.uint32,
               5126: np.float32}  # fmt: skip
_CODES = {np.dtype(v): k for k, v in _COMPONENTS.items()}


def _pygltflib() -> ModuleType:
    try:
        import pygltflib
    except ImportError as e:  # pragma: no cover - depends on the environment
        raise ImportError("glTF needs pygltflib: pip install 'skinrs[gltf]'") from e
    module: ModuleType = pygltflib
    return module


# --------------------------------------------------------------------------------------------
# writing


class _Blob:
    """One binary buffer: arrays appended 4-byte aligned, one bufferView + accessor each."""

    def __init__(self, g: pygltflib.GLTF2, lib: ModuleType) -> None:
        self.g, self.lib, self.data = g, lib, bytearray()

    def add(self, A: NDArray[Any], target: int | None = None, minmax: bool = False) -> int:
        A = np.ascontiguousarray(A)
        self.data += b"\0" * (-len(self.data) % 4)
        self.g.bufferViews.append(
            self.lib.BufferView(
                buffer=0, byteOffset=len(self.data), byteLength=A.nbytes, target=target
            )
        )
        self.data += A.tobytes()
        flat = A.reshape(len(A), -1)
        acc = self.lib.Accessor(
            bufferView=len(self.g.bufferViews) - 1,
            componentType=_CODES[A.dtype],
            count=len(A),
            type=_TYPES[flat.shape[1]],
        )
        if minmax:
            acc.min, acc.max = flat.min(0).tolist(), flat.max(0).tolist()
        self.g.accessors.append(acc)
        return len(self.g.accessors) - 1


def _pack(
    W: NDArray[np.float64] | tuple[ArrayLike, ArrayLike],
    k: int,
    method: str,
    V: NDArray[np.float64],
    F: NDArray[np.int64],
    C: NDArray[np.float64],
    BE: NDArray[np.int64],
    P: NDArray[np.int64],
    poses: NDArray[np.float64] | None,
) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
    """``(indices, weights)`` with at most ``k`` influences per vertex."""
    if isinstance(W, tuple):
        I = np.asarray(W[0], dtype=np.int64)
        A = np.asarray(W[1], dtype=np.float64)
        if I.ndim != 2 or I.shape != A.shape:
            raise ValueError(
                f"packed W must be (indices, weights) of one shape (n, j), got {I.shape}"
            )
        if I.shape[1] > k:
            raise ValueError(f"packed W has {I.shape[1]} influences per vertex, more than k = {k}")
        return I, A
    from .reduce import random_skeleton_poses, reduce_weights

    m = W.shape[1]
    if m <= k:
        return np.broadcast_to(np.arange(m), W.shape).copy(), W
    if method in ("geometric", "poisson") and poses is None:
        if len(P):
            raise ValueError(
                f"method={method!r} needs example poses: pass poses= (point handles have no "
                "random poses) or method='k-largest'"
            )
        poses = random_skeleton_poses(C, BE, 8, seed=0)
    return reduce_weights(W, k, method=method, V=V, F=F, bone_transforms=poses)


def _joint_weights(
    I: NDArray[np.int64], A: NDArray[np.float64], column_joint: NDArray[np.int64], n_joints: int
) -> tuple[NDArray[np.unsignedinteger[Any]], NDArray[np.float32]]:
    """Per-vertex joint indices and float32 weights summing to 1 (glTF 3.7.3.3), 4 or 8 wide."""
    n = len(I)
    dense = np.zeros((n, n_joints))
    np.add.at(dense, (np.repeat(np.arange(n), I.shape[1]), column_joint[I].ravel()), A.ravel())
    if dense.min() < 0:
        raise ValueError("W has negative weights, which glTF does not allow")
    s = dense.sum(1)
    if np.any(s <= 0):
        raise ValueError(f"vertex {int(np.flatnonzero(s <= 0)[0])} has no weight")
    k = 4 if I.shape[1] <= 4 else 8  # a vertex has at most I.shape[1] joints
    order = np.argsort(-dense, axis=1, kind="stable")[:, :k]
    Wk = np.take_along_axis(dense, order, 1) / s[:, None]
    Jk = np.where(Wk > 0, order, 0)
    W32 = Wk.astype(np.float32)
    W32[:, 0] += np.float32(1) - W32.sum(1, dtype=np.float32)  # float32 sum as close to 1
    jt = np.uint8 if n_joints <= 256 else np.uint16
    return Jk.astype(jt), W32


def write_gltf(
    path: str | os.PathLike[str],
    V: ArrayLike,
    F: ArrayLike,
    W: ArrayLike | tuple[ArrayLike, ArrayLike],
    C: ArrayLike | None = None,
    BE: ArrayLike | None = None,
    P: ArrayLike | None = None,
    *,
    names: Sequence[str] | None = None,
    poses: ArrayLike | None = None,
    times: ArrayLike | None = None,
    k: int = 4,
    method: str = "poisson",
    asset: GltfAsset | None = None,
) -> None:
    """Write a skinned mesh as glTF 2.0 (``.glb`` binary or ``.gltf`` with an embedded buffer).

    Parameters
    ----------
    path : str or pathlib.Path, ending in ``.glb`` or ``.gltf``
    V : (n, 3) float; F : (f, 3) int triangles
    W : (n, #P + #BE) float, one column per point handle then per bone (libigl's order, what
        :func:`skinrs.skin_weights` returns), or packed ``(indices, weights)`` (n, <= 8)
    C : (j, 3) float joints; BE : (#BE, 2) int bones (parent -> child); P : (#P,) int handles
    names : list of str, one per column (default ``handle<i>``, ``bone<b>``)
    poses : (frames, #P + #BE, 3, 4) float, optional
        Rigid transforms per column (e.g. :func:`skinrs.forward_kinematics`), written as one
        animation ``skinrs`` that moves the joint nodes.
    times : (frames,) float, optional
        Key times in seconds (default 1/24 s apart).
    k : 4 or 8
        Influences per vertex (``JOINTS_0``/``WEIGHTS_0``, plus ``_1`` for 8).
    method : str
        :func:`skinrs.reduce_weights` method used when ``W`` has more than ``k`` columns
        (default ``"poisson"``, fitted on 8 random poses of the skeleton or on ``poses``).
    asset : dict, optional
        What :func:`read_gltf` returned: write ``W`` (one column per handle of that asset) onto
        its joint nodes, keeping their names, hierarchy, bind pose and (unless ``poses`` is
        given) animations. ``C``, ``BE``, ``P``, ``names`` are then taken from it.

    Weights are reduced, then summed per joint node, normalised (sum 1 in float32) and stored
    as float32 with unsigned byte (or short, beyond 256 joints) joint indices.

    Examples
    --------
    >>> import numpy as np, skinrs
    >>> V = np.array([[0.0, 0, 0], [0, 1, 0], [1, 0, 0], [0, 0, 1]])
    >>> F = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    >>> C, BE = np.array([[0.0, 0, 0], [0, 1, 0]]), np.array([[0, 1]])
    >>> skinrs.io.write_gltf("tet.glb", V, F, np.ones((4, 1)), C, BE)   # doctest: +SKIP
    """
    lib = _pygltflib()
    path = os.fspath(path)
    if not path.lower().endswith((".glb", ".gltf")):
        raise ValueError(f"path must end in .glb or .gltf, got {path!r}")
    V = as_points(V, "V", dims=(3,))
    F = as_elements(F, V, "F", cols=3)
    if k not in (4, 8):
        raise ValueError(f"k must be 4 or 8 (glTF stores influences in groups of 4), got {k!r}")
    if asset is not None:
        C, BE, P = asset["C"], asset["BE"], asset["P"]
        rig_ = _asset_rig(asset, names, keep_animations=poses is None)
    else:
        C, BE, P, rig_ = _skeleton_rig(C, BE, P, names)
    m = len(rig_["column"])
    if not isinstance(W, tuple):
        W = as_points(W, "W", dims=range(1, 1 << 30))
        if W.shape != (len(V), m):
            raise ValueError(
                f"W must have shape ({len(V)}, {m}) (one column per handle), got {W.shape}"
            )
    if poses is not None:
        poses = np.asarray(poses, dtype=np.float64)
        rig_["animations"] = [_animation(poses, times, rig_)]
    I, A = _pack(W, k, method, V, F, C, BE, P, poses)
    if I.size and (I.min() < 0 or I.max() >= m):
        raise ValueError(f"packed W refers to column {int(I.max())}, expected 0..{m - 1}")
    joints, weights = _joint_weights(I, A, rig_["column"], len(rig_["parents"]))

    g = lib.GLTF2(asset=lib.Asset(version="2.0", generator="skinrs"))
    blob = _Blob(g, lib)
    attrs = lib.Attributes(
        POSITION=blob.add(V.astype(np.float32), _ARRAY, minmax=True),
        JOINTS_0=blob.add(joints[:, :4], _ARRAY),
        WEIGHTS_0=blob.add(weights[:, :4], _ARRAY),
    )
    if joints.shape[1] == 8:
        attrs.JOINTS_1 = blob.add(joints[:, 4:], _ARRAY)
        attrs.WEIGHTS_1 = blob.add(weights[:, 4:], _ARRAY)
    idx = F.astype(np.uint16 if len(V) < 65536 else np.uint32).reshape(-1)
    prim = lib.Primitive(attributes=attrs, indices=blob.add(idx, _ELEMENTS), mode=4)
    g.meshes.append(lib.Mesh(name="skinned", primitives=[prim]))
    _write_skin(g, lib, blob, rig_)
    g.scenes.append(lib.Scene(nodes=[0]))
    g.scene = 0
    g.buffers.append(lib.Buffer(byteLength=len(blob.data)))
    g.set_binary_blob(bytes(blob.data))
    if path.lower().endswith(".gltf"):
        g.convert_buffers(lib.BufferFormat.DATAURI)
        g.save_json(path)
    else:
        g.save_binary(path)


def _skeleton_rig(
    C: ArrayLike | None, BE: ArrayLike | None, P: ArrayLike | None, names: Sequence[str] | None
) -> tuple[NDArray[np.float64], NDArray[np.int64], NDArray[np.int64], rig.Rig]:
    """Checked ``C, BE, P`` and the joint nodes of a skinrs skeleton (one per column)."""
    if C is None or BE is None:
        raise ValueError("pass the skeleton C and BE (or asset= from read_gltf)")
    C = as_points(C, "C", dims=(3,))
    BE = as_index_array(BE, len(C), "BE", cols=2)
    P = as_index_array([] if P is None else P, len(C), "P", ndim=1)
    if np.any(np.linalg.norm(C[BE[:, 1]] - C[BE[:, 0]], axis=1) == 0):
        raise ValueError("BE has a bone of zero length")
    cols = [f"handle{i}" for i in range(len(P))] + [f"bone{b}" for b in range(len(BE))]
    if names is not None:
        if len(names) != len(cols):
            raise ValueError(
                f"names must have one entry per column ({len(cols)}), got {len(names)}"
            )
        cols = [str(x) for x in names]
    jnames, parents, bind, column, labels = rig.skeleton_rig(C, BE, P, cols)
    nodes: rig.Rig = {
        "names": jnames,
        "parents": parents,
        "bind": bind,
        "column": column,
        "labels": labels,
        "animations": [],
    }
    return C, BE, P, nodes


def _asset_rig(asset: GltfAsset, names: Sequence[str] | None, keep_animations: bool) -> rig.Rig:
    """The joint nodes of an asset from :func:`read_gltf`, columns renamed by ``names``."""
    j = asset["joints"]
    out: rig.Rig = {
        "names": j["names"],
        "parents": j["parents"],
        "bind": j["bind"],
        "column": j["column"],
        "labels": j["labels"],
        "animations": list(j["animations"]) if keep_animations else [],
    }
    if names is not None:
        if len(names) != len(j["column"]):
            raise ValueError(
                f"names must have one entry per column ({len(j['column'])}), got {len(names)}"
            )
        out["names"] = list(out["names"])
        for c, joint in enumerate(j["column"]):
            out["names"][joint] = str(names[c])
    return out


def _animation(poses: NDArray[np.float64], times: ArrayLike | None, rig_: rig.Rig) -> rig.Animation:
    """Per-column poses (frames, m, 3, 4) as skinning transforms of every joint node."""
    m = len(rig_["column"])
    if poses.ndim != 4 or poses.shape[1:] != (m, 3, 4):
        raise ValueError(f"poses must have shape (frames, {m}, 3, 4), got {poses.shape}")
    t = np.arange(len(poses)) / 24.0 if times is None else np.asarray(times, dtype=float)
    if t.shape != (len(poses),) or np.any(np.diff(t) <= 0):
        raise ValueError(f"times must be {len(poses)} increasing seconds, got {t.shape}")
    T = rig.joint_poses(poses, rig_["column"], rig_["parents"], rig_["bind"])
    return {"name": "skinrs", "times": t, "T": T}


def _write_skin(g: pygltflib.GLTF2, lib: ModuleType, blob: _Blob, rig_: rig.Rig) -> None:
    """Nodes (a root, the mesh, the joints), the skin and the animations."""
    jnames, parents, bind, labels = rig_["names"], rig_["parents"], rig_["bind"], rig_["labels"]
    J0 = 2  # node 0: a common root (Panda3D needs one), node 1: the mesh, then the joints
    local = rig.local_matrices(parents, bind)
    roots = [J0 + j for j in range(len(parents)) if parents[j] < 0]
    g.nodes.append(lib.Node(name="skinrs", children=[1] + roots))
    g.nodes.append(lib.Node(name="skinned", mesh=0, skin=0))
    for j in range(len(parents)):
        tr, q, s = rig.decompose(local[j], f"the bind matrix of joint {jnames[j]!r}")
        node = lib.Node(name=str(jnames[j]), translation=tr.tolist(), rotation=q.tolist())
        label = labels[j]
        if label is not None:  # the joint of C it stands for: keeps C's numbering
            node.extras = {"skinrs_joint": int(label)}
        if np.abs(s - 1).max() > 1e-9:
            node.scale = s.tolist()
        node.children = [J0 + int(c) for c in np.flatnonzero(parents == j)] or None
        g.nodes.append(node)
    ibm = np.linalg.inv(bind).transpose(0, 2, 1).astype(np.float32)  # column-major
    g.skins.append(
        lib.Skin(
            name="skinrs",
            joints=list(range(J0, J0 + len(parents))),
            inverseBindMatrices=blob.add(ibm.reshape(-1, 16)),
            skeleton=0,
        )
    )
    for anim in rig_["animations"]:
        _write_animation(g, lib, blob, anim, parents, bind, jnames, J0)


def _write_animation(
    g: pygltflib.GLTF2,
    lib: ModuleType,
    blob: _Blob,
    anim: rig.Animation,
    parents: NDArray[np.int64],
    bind: NDArray[np.float64],
    jnames: list[str],
    J0: int,
) -> None:
    t = np.asarray(anim["times"], dtype=np.float64)
    G = rig.homogeneous(anim["T"]) @ bind  # world matrices of the joints per frame
    key = blob.add(t.astype(np.float32), minmax=True)
    channels, samplers = [], []
    L = np.stack([rig.local_matrices(parents, Gf) for Gf in G])
    for j in range(len(parents)):
        trs = [rig.decompose(L[f, j], f"joint {jnames[j]!r} in frame {f}") for f in range(len(t))]
        tr, q, s = (np.array(x) for x in zip(*trs))
        q[1:][np.sum(q[1:] * q[:-1], axis=1) < 0] *= -1  # shortest arcs between keys
        for path_, vals in (("translation", tr), ("rotation", q), ("scale", s)):
            if path_ == "scale" and np.abs(s - 1).max() <= 1e-9:
                continue
            samplers.append(
                lib.AnimationSampler(input=key, output=blob.add(vals.astype(np.float32)))
            )
            target = lib.AnimationChannelTarget(node=J0 + j, path=path_)
            channels.append(lib.AnimationChannel(sampler=len(samplers) - 1, target=target))
    g.animations.append(lib.Animation(name=anim["name"], channels=channels, samplers=samplers))
