"""Reading glTF 2.0 skins (``.gltf`` / ``.glb``) into skinrs arrays; see :mod:`skinrs.gltf`."""

from __future__ import annotations

import os
import struct
import warnings
from typing import TYPE_CHECKING, Any, TypedDict, cast

import numpy as np
from numpy.typing import ArrayLike, NDArray

from . import gltf_rig as rig
from .io._weld import weld

if TYPE_CHECKING:
    import pygltflib

__all__ = ["read_gltf"]

_COMPONENTS = {5120: np.int8, 5121: np.uint8, 5122: np.int16, 5123: np.uint16, 5125: np.uint32,
               5126: np.float32}  # fmt: skip
_NCOMP = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT4": 16}


class GltfJoints(rig.Rig):
    """The joint nodes of a read skin, with the ``weights`` (n, J) of every joint node."""

    weights: NDArray[np.float64]


class GltfAsset(TypedDict):
    """What :func:`read_gltf` returns (its docstring says what each entry holds)."""

    V: NDArray[np.float64]
    F: NDArray[np.int64]
    vertex_map: NDArray[np.int64]
    C: NDArray[np.float64]
    BE: NDArray[np.int64]
    P: NDArray[np.int64]
    W: NDArray[np.float64]
    names: list[str]
    animations: list[rig.Animation]
    joints: GltfJoints


class _File:
    """A loaded glTF with its buffers, able to decode accessors and to name itself in errors."""

    def __init__(self, path: str | os.PathLike[str]) -> None:
        from .gltf import _pygltflib

        lib = _pygltflib()
        self.name = os.fspath(path)
        if not os.path.isfile(self.name):
            raise FileNotFoundError(self.name)
        try:
            self.g: pygltflib.GLTF2 = lib.GLTF2().load(self.name)
        except (
            OSError,
            ValueError,
            struct.error,
            KeyError,
            TypeError,
            IndexError,
            AttributeError,
        ) as e:
            raise ValueError(f"{self.name}: not a readable glTF file ({e})") from None
        if self.g is None:
            raise ValueError(f"{self.name}: not a readable glTF file")
        self.buffers: dict[int, bytes] = {}

    def error(self, what: str) -> ValueError:
        return ValueError(f"{self.name}: {what}")

    def buffer(self, i: int) -> bytes:
        if i not in self.buffers:
            uri = self.g.buffers[i].uri
            if uri is None:
                self.buffers[i] = self.g.binary_blob() or b""
            elif uri.startswith("data:"):
                self.buffers[i] = self.g.decode_data_uri(uri)
            else:
                with open(os.path.join(os.path.dirname(self.name), uri), "rb") as fh:
                    self.buffers[i] = fh.read()
        return self.buffers[i]

    def accessor(self, i: int) -> NDArray[Any]:
        """``(count, ncomp)`` array (float64 for normalised integers), as the spec decodes it."""
        if not isinstance(i, int) or not 0 <= i < len(self.g.accessors):
            raise self.error(f"refers to accessor {i}, the file has {len(self.g.accessors)}")
        a = self.g.accessors[i]
        if a.bufferView is not None and not 0 <= a.bufferView < len(self.g.bufferViews):
            raise self.error(f"accessor {i} refers to a missing bufferView {a.bufferView}")
        if a.sparse is not None:
            raise self.error(f"accessor {i} is sparse, which skinrs does not read")
        dt = np.dtype(_COMPONENTS[a.componentType]).newbyteorder("<")
        nc = _NCOMP[a.type]
        if a.bufferView is None:
            return np.zeros((a.count, nc), dtype=dt)
        v = self.g.bufferViews[a.bufferView]
        data = self.buffer(v.buffer)
        start = (v.byteOffset or 0) + (a.byteOffset or 0)
        stride = v.byteStride or dt.itemsize * nc
        if a.type == "MAT4" and dt.itemsize == 4:
            stride = v.byteStride or 64
        need = start + stride * (a.count - 1) + dt.itemsize * nc if a.count else start
        if need > len(data):
            raise self.error(f"accessor {i} reads past the end of buffer {v.buffer}")
        raw = np.lib.stride_tricks.as_strided(
            np.frombuffer(data, dtype=np.uint8, count=need - start, offset=start),
            shape=(a.count, dt.itemsize * nc),
            strides=(stride, 1),
        )
        A = np.ascontiguousarray(raw).view(dt).reshape(a.count, nc)
        if a.normalized:
            # the spec normalises integer components only (iinfo raises on a float one)
            integer = cast("np.dtype[np.integer[Any]]", dt)
            return A.astype(np.float64) / np.iinfo(integer).max
        return A


def _trs_matrix(node: pygltflib.Node) -> NDArray[np.float64]:
    if node.matrix is not None:
        return np.asarray(node.matrix, dtype=np.float64).reshape(4, 4).T
    return _compose(node.translation, node.rotation, node.scale)


def _compose(t: ArrayLike | None, q: ArrayLike | None, s: ArrayLike | None) -> NDArray[np.float64]:
    from scipy.spatial.transform import Rotation

    M = np.eye(4)
    R = Rotation.from_quat(q if q is not None else [0, 0, 0, 1]).as_matrix()
    M[:3, :3] = R * (np.asarray(s, dtype=np.float64) if s is not None else 1.0)
    if t is not None:
        M[:3, 3] = t
    return M


def _label(node: pygltflib.Node) -> int | None:
    """The skinrs joint index :func:`skinrs.io.write_gltf` stored on a joint node, or None."""
    x = (node.extras or {}).get("skinrs_joint") if isinstance(node.extras, dict) else None
    return x if isinstance(x, int) and not isinstance(x, bool) and x >= 0 else None


def _skinned_node(f: _File) -> int:
    nodes = f.g.nodes
    skinned = [i for i, n in enumerate(nodes) if n.mesh is not None and n.skin is not None]
    meshes = [i for i, n in enumerate(nodes) if n.mesh is not None]
    if not meshes:
        raise f.error("has no mesh node")
    if len({nodes[i].skin for i in skinned}) > 1:
        warnings.warn(f"{f.name}: several skins; reading the first skinned mesh", stacklevel=3)
    return (skinned or meshes)[0]


def _mesh(
    f: _File, mesh: int
) -> tuple[NDArray[np.float64], NDArray[np.int64], NDArray[np.int64], NDArray[np.float64]]:
    """Positions, triangles and per-joint weights of all primitives of one mesh, merged."""
    Vs: list[NDArray[np.float64]] = []
    Fs: list[NDArray[np.int64]] = []
    Js: list[NDArray[np.int64]] = []
    Ws: list[NDArray[np.float64]] = []
    off = 0
    for p, prim in enumerate(f.g.meshes[mesh].primitives):
        if (prim.mode if prim.mode is not None else 4) != 4:
            raise f.error(f"mesh {mesh} primitive {p} is not a triangle list (mode {prim.mode})")
        at = prim.attributes
        if at.POSITION is None:
            raise f.error(f"mesh {mesh} primitive {p} has no POSITION")
        V = f.accessor(at.POSITION).astype(np.float64)
        F = (
            f.accessor(prim.indices).astype(np.int64).reshape(-1, 3)
            if prim.indices is not None
            else np.arange(len(V)).reshape(-1, 3)
        )
        if F.size and F.max() >= len(V):
            raise f.error(f"mesh {mesh} primitive {p} has an index beyond its {len(V)} vertices")
        sets = [
            (getattr(at, f"JOINTS_{s}", None), getattr(at, f"WEIGHTS_{s}", None)) for s in (0, 1)
        ]
        J = [f.accessor(j).astype(np.int64) for j, w in sets if j is not None and w is not None]
        W = [f.accessor(w).astype(np.float64) for j, w in sets if j is not None and w is not None]
        Vs.append(V)
        Fs.append(F + off)
        Js.append(np.hstack(J) if J else np.zeros((len(V), 0), dtype=np.int64))
        Ws.append(np.hstack(W) if W else np.zeros((len(V), 0)))
        off += len(V)
    k = max(x.shape[1] for x in Js)
    pad = [np.pad(x, ((0, 0), (0, k - x.shape[1]))) for x in Js]
    padw = [np.pad(x, ((0, 0), (0, k - x.shape[1]))) for x in Ws]
    return np.vstack(Vs), np.vstack(Fs), np.vstack(pad), np.vstack(padw)


def _weld(
    V: NDArray[np.float64], F: NDArray[np.int64], W: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.int64], NDArray[np.float64], NDArray[np.int64]]:
    """Merges vertices at identical positions (split at UV seams / sharp edges by exporters)."""
    Vw, Fw, vmap = weld(V, F)
    if len(Fw) < len(F):
        warnings.warn(
            f"welding made {len(F) - len(Fw)} triangles degenerate; they are left out",
            stacklevel=3,
        )
    counts = np.bincount(vmap, minlength=len(Vw)).astype(np.float64)
    Ww = np.zeros((len(Vw), W.shape[1]))
    np.add.at(Ww, vmap, W)
    return Vw, Fw, Ww / counts[:, None], vmap


def _world(f: _File, local: NDArray[np.float64]) -> NDArray[np.float64]:
    parents = np.full(len(f.g.nodes), -1)
    for i, n in enumerate(f.g.nodes):
        for c in n.children or []:
            parents[c] = i
    return rig.world_matrices(parents, local)


def _animations(
    f: _File, rest_local: NDArray[np.float64], joints: NDArray[np.int64], ibm: NDArray[np.float64]
) -> list[rig.Animation]:
    """Skinning transforms ``G_j(t) @ IBM_j`` (frames, J, 3, 4) at each animation's key times."""
    out: list[rig.Animation] = []
    for a, anim in enumerate(f.g.animations):
        chans = [
            c for c in anim.channels if c.target.node is not None and c.target.path != "weights"
        ]
        if not chans:
            continue
        keys = [f.accessor(anim.samplers[c.sampler].input)[:, 0].astype(np.float64) for c in chans]
        t = np.unique(np.concatenate(keys))
        trs: dict[int, dict[str, NDArray[np.float64]]] = {}
        for c, key in zip(chans, keys):
            s = anim.samplers[c.sampler]
            vals = f.accessor(s.output).astype(np.float64)
            node = trs.setdefault(c.target.node, {})
            node[c.target.path] = rig.sample(s.interpolation or "LINEAR", key, vals, t)
        T = np.empty((len(t), len(joints), 3, 4))
        for i in range(len(t)):
            local = rest_local.copy()
            for n, ch in trs.items():
                rest = f.g.nodes[n]
                local[n] = _compose(
                    ch["translation"][i] if "translation" in ch else rest.translation,
                    ch["rotation"][i] if "rotation" in ch else rest.rotation,
                    ch["scale"][i] if "scale" in ch else rest.scale,
                )
            T[i] = (_world(f, local)[joints] @ ibm)[:, :3]
        out.append({"name": anim.name or f"animation{a}", "times": t, "T": T})
    return out


def read_gltf(path: str | os.PathLike[str], *, weld: bool = True) -> GltfAsset:
    """Read the skinned mesh of a glTF 2.0 file (``.gltf`` or ``.glb``).

    Every primitive of the first skinned mesh (or the first mesh, without a skin) is merged
    into one triangle mesh. Joint nodes become the skinrs skeleton (see docs/gltf.md): a joint
    whose children sit elsewhere gives one bone per child point, driven by that joint; a
    childless joint that carries weight is a point handle; columns are point handles, then
    bones; a joint that drives several bones splits its weight evenly among them, so
    ``skinrs.lbs(V, W, T)`` poses the mesh exactly as glTF does.

    Parameters
    ----------
    path : str or pathlib.Path
    weld : bool
        Merge vertices at identical positions (exporters split them at UV seams and sharp
        edges); ``vertex_map`` then maps every vertex of the file to its row of ``V``.

    Returns
    -------
    dict with
        ``V`` (n, 3), ``F`` (f, 3): the mesh in bind pose; ``vertex_map`` (n_file,) int64;
        ``C`` (j, 3), ``BE`` (m, 2), ``P`` (p,): the skeleton in bind pose;
        ``W`` (n, p + m): weights per column; ``names``: joint name per column;
        ``animations``: list of dicts ``name``, ``times`` (frames,) s and ``T``
        (frames, p + m, 3, 4) transforms per column (``skinrs.lbs(V, W, T[i])`` poses frame i);
        ``joints``: the joint nodes themselves, ``names``, ``parents`` (-1 for a root),
        ``bind`` (J, 4, 4) world bind matrices, ``weights`` (n, J), ``column`` (p + m,) joint
        of each column, ``labels`` (joint of ``C`` per node, from skinrs' node extras, else
        None), ``animations`` (``T`` per joint), for :func:`skinrs.io.write_gltf`.
        Without a skin, the skeleton entries are empty and ``V`` is in world coordinates.

    Examples
    --------
    >>> a = skinrs.io.read_gltf("arm.glb")                         # doctest: +SKIP
    >>> U = skinrs.lbs(a["V"], a["W"], a["animations"][0]["T"][0])  # doctest: +SKIP
    """
    f = _File(path)
    n_idx = _skinned_node(f)
    node = f.g.nodes[n_idx]
    V, F, Jk, Wk = _mesh(f, node.mesh)
    rest_local = np.array([_trs_matrix(n) for n in f.g.nodes])
    if node.skin is None:
        V = V @ _world(f, rest_local)[n_idx][:3, :3].T + _world(f, rest_local)[n_idx][:3, 3]
        joints = np.zeros(0, dtype=np.int64)
        ibm: NDArray[np.float64] = np.zeros((0, 4, 4))
    else:
        skin = f.g.skins[node.skin]
        joints = np.asarray(skin.joints, dtype=np.int64)
        ibm = (
            f.accessor(skin.inverseBindMatrices).astype(np.float64).reshape(-1, 4, 4)
            .transpose(0, 2, 1)
            if skin.inverseBindMatrices is not None
            else np.broadcast_to(np.eye(4), (len(joints), 4, 4)).copy()
        )  # fmt: skip
    nJ = len(joints)
    if Jk.size and (Jk.max() >= nJ):
        raise f.error(f"a vertex refers to joint {int(Jk.max())}, the skin has {nJ}")
    W = np.zeros((len(V), nJ))
    np.add.at(W, (np.repeat(np.arange(len(V)), Jk.shape[1]), Jk.ravel()), Wk.ravel())
    vmap = np.arange(len(V))
    if weld:
        V, F, W, vmap = _weld(V, F, W)
    s = W.sum(1, keepdims=True)
    W = np.divide(W, s, out=np.zeros_like(W), where=s > 0)
    # joint hierarchy: the nearest ancestor that is a joint
    node_parent = np.full(len(f.g.nodes), -1)
    for i, n in enumerate(f.g.nodes):
        for c in n.children or []:
            node_parent[c] = i
    where = {int(n): j for j, n in enumerate(joints)}
    parents = np.full(nJ, -1, dtype=np.int64)
    for j, n in enumerate(joints):
        a = node_parent[n]
        while a >= 0 and int(a) not in where:
            a = node_parent[a]
        parents[j] = where.get(int(a), -1)
    # numpy's stubs type inv() as floating[Any]; float64 in gives float64 out
    bind = cast("NDArray[np.float64]", np.linalg.inv(ibm)) if nJ else ibm
    scale = float(np.linalg.norm(np.ptp(V, axis=0))) if len(V) else 1.0
    labels = [_label(f.g.nodes[n]) for n in joints]
    C, BE, P, column = rig.handles_of_rig(parents, bind, W.max(0) > 0, 1e-6 * scale, labels)
    share = np.bincount(column, minlength=nJ)[column] if nJ else np.zeros(0)
    names = [f.g.nodes[n].name or f"joint{j}" for j, n in enumerate(joints)]
    anims = _animations(f, rest_local, joints, ibm) if nJ else []
    return {
        "V": V,
        "F": F,
        "vertex_map": vmap,
        "C": C,
        "BE": BE,
        "P": P,
        "W": W[:, column] / share if nJ else np.zeros((len(V), 0)),
        "names": [names[j] for j in column],
        "animations": [{**a, "T": a["T"][:, column]} for a in anims],
        "joints": {
            "names": names,
            "parents": parents,
            "bind": bind,
            "weights": W,
            "column": column,
            "labels": labels,
            "animations": anims,
        },
    }
