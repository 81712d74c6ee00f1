"""The rig math behind :mod:`skinrs.gltf`: skinrs skeletons <-> glTF joint nodes.

A glTF skin deforms with one matrix per *joint node*: ``G_j(t) @ IBM_j`` (the node's world
matrix times its inverse bind matrix). A skinrs skeleton has joints ``C`` and bones ``BE``,
bone ``b`` turning about its head ``C[BE[b, 0]]``. So a bone is a joint node placed at its head
whose children sit at its tail; see ``docs/gltf.md`` for how files map both ways.

Matrices here are 4x4 world matrices (float64); a rig is described by

- ``parents`` (J,): parent joint of each joint node, -1 for a root;
- ``bind`` (J, 4, 4): world matrix of each joint in the bind pose (inverse of its IBM);
- per-frame skinning transforms ``T`` (f, J, 3, 4): ``G_j(t) @ IBM_j`` (what :func:`skinrs.lbs`
  takes, identity in the bind pose).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, TypedDict

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .skinning import bone_parents

if TYPE_CHECKING:
    from scipy.spatial.transform import Rotation


class Animation(TypedDict):
    """One animation: ``name``, key ``times`` (frames,) in seconds and the skinning transforms
    ``T`` (frames, J, 3, 4) at those times (per joint node, or per handle column)."""

    name: str
    times: NDArray[np.float64]
    T: NDArray[np.float64]


class Rig(TypedDict):
    """The joint nodes of a skin: ``names``, ``parents`` (J,), ``bind`` (J, 4, 4), ``column``
    (the joint of each handle column), ``labels`` (the joint of ``C`` each node stands for, or
    None) and the ``animations`` (``T`` per joint node)."""

    names: list[str]
    parents: NDArray[np.int64]
    bind: NDArray[np.float64]
    column: NDArray[np.int64]
    labels: Sequence[int | None]
    animations: list[Animation]


def _rotation() -> type[Rotation]:
    from scipy.spatial.transform import Rotation  # imported on use: ~0.2 s

    rotation: type[Rotation] = Rotation
    return rotation


def homogeneous(T: ArrayLike) -> NDArray[np.float64]:
    """``(..., 3, 4)`` affine transforms as ``(..., 4, 4)`` matrices."""
    T = np.asarray(T, dtype=np.float64)
    M = np.zeros(T.shape[:-2] + (4, 4))
    M[..., :3, :] = T
    M[..., 3, 3] = 1.0
    return M


def y_to(d: NDArray[np.float64]) -> NDArray[np.float64]:
    """The smallest rotation taking +Y to the unit direction ``d`` (3x3)."""
    y = np.array([0.0, 1.0, 0.0])
    axis = np.cross(y, d)
    s, c = np.linalg.norm(axis), float(y @ d)
    if s < 1e-12:
        return np.eye(3) if c > 0 else np.diag([1.0, -1.0, -1.0])  # half turn about X
    R: NDArray[np.float64] = _rotation().from_rotvec(axis / s * np.arctan2(s, c)).as_matrix()
    return R


def skeleton_rig(
    C: NDArray[np.float64], BE: NDArray[np.int64], P: NDArray[np.int64], names: Sequence[str]
) -> tuple[list[str], NDArray[np.int64], NDArray[np.float64], NDArray[np.int64], list[int]]:
    """Joint nodes of a skinrs skeleton, one per handle column, plus an end node per leaf bone.

    Column ``c`` (point handles ``P`` first, then bones, as libigl orders weights) is joint
    ``c``. A bone's node sits at its head with +Y along the bone (as Blender's exporter writes
    bones); its child bones' nodes sit at its tail, and a bone without children gets an end node
    there (``<name>_end``, weight 0) so that every bone's tail is in the file.

    Returns ``(names, parents, bind, column_joint, labels)`` with ``column_joint[c] = c`` and
    ``labels`` the index in ``C`` of each node's position (kept in the file as node extras).
    """
    nP, m = len(P), len(BE)
    par = bone_parents(BE, n_joints=len(C)) if m else np.zeros(0, dtype=np.int64)
    parents = [-1] * nP + [int(p) + nP if p >= 0 else -1 for p in par]
    bind = [np.eye(4) for _ in range(nP + m)]
    for i, p in enumerate(P):
        bind[i][:3, 3] = C[p]
    for b, (h, t) in enumerate(BE):
        d = C[t] - C[h]
        bind[nP + b][:3, :3] = y_to(d / np.linalg.norm(d))
        bind[nP + b][:3, 3] = C[h]
    jnames = list(names)
    leaves = np.setdiff1d(np.arange(m), par[par >= 0])
    for b in leaves:
        jnames.append(f"{jnames[nP + b]}_end")
        parents.append(nP + int(b))
        end = bind[nP + b].copy()
        end[:3, 3] = C[BE[b, 1]]
        bind.append(end)
    labels = [int(p) for p in P] + [int(h) for h in BE[:, 0]] + [int(BE[b, 1]) for b in leaves]
    return jnames, np.array(parents, dtype=np.int64), np.array(bind), np.arange(nP + m), labels


def handles_of_rig(
    parents: NDArray[np.int64],
    bind: NDArray[np.float64],
    weights_used: NDArray[np.bool_],
    tol: float,
    labels: Sequence[int | None] | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.int64], NDArray[np.int64], NDArray[np.int64]]:
    """The skinrs skeleton seen in glTF joint nodes: ``(C, BE, P, column_joint)``.

    A joint with children at other points gives one bone per distinct child point (head at the
    joint, tail at the child), all driven by that joint; a joint with no such child that carries
    weight is a point handle; one that carries none only marks where its parent's bone ends.
    Points closer than ``tol`` are one joint of ``C``. ``labels`` (J,), the joint index of each
    node as :func:`skeleton_rig` wrote it, numbers ``C`` when they are consistent; otherwise
    joints are numbered in order of first appearance (point handles, then bones' heads, tails).
    """
    pos = bind[:, :3, 3]
    points: list[NDArray[np.float64]] = []
    point_nodes: list[list[int]] = []

    def point(node: int) -> int:
        for i, q in enumerate(points):
            if np.linalg.norm(q - pos[node]) <= tol:
                point_nodes[i].append(node)
                return i
        points.append(pos[node])
        point_nodes.append([node])
        return len(points) - 1

    segments: list[tuple[int, int]] = []  # (driving joint, a child node at the tail)
    handles: list[int] = []
    for j in range(len(parents)):
        tails: list[int] = []
        for c in np.flatnonzero(parents == j):
            if np.linalg.norm(pos[c] - pos[j]) > tol and all(
                np.linalg.norm(pos[c] - pos[t]) > tol for t in tails
            ):
                tails.append(int(c))
        segments += [(j, t) for t in tails]
        if not tails and weights_used[j]:
            handles.append(j)
    P = np.array([point(j) for j in handles], dtype=np.int64)
    BE = np.array([(point(j), point(t)) for j, t in segments], dtype=np.int64).reshape(-1, 2)
    column_joint = np.array(handles + [j for j, _ in segments], dtype=np.int64)
    C = np.array(points).reshape(-1, 3)
    order = _joint_numbers(labels, point_nodes)
    if order is not None:
        C[order] = C.copy()
        P, BE = order[P], order[BE]
    return C, BE, P, column_joint


def _joint_numbers(
    labels: Sequence[int | None] | None, point_nodes: list[list[int]]
) -> NDArray[np.int64] | None:
    """Number of each point from the nodes' labels, or None unless every point has one label
    and together they are ``0 .. len - 1``."""
    if labels is None:
        return None
    known = [x for x in labels if x is not None]
    if len(known) != len(labels):
        return None
    numbers = []
    for nodes in point_nodes:
        own = {int(known[n]) for n in nodes}
        if len(own) != 1:
            return None
        numbers.append(own.pop())
    order = np.array(numbers, dtype=np.int64)
    return order if np.array_equal(np.sort(order), np.arange(len(order))) else None


def decompose(
    M: NDArray[np.float64], what: str
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """``(translation, rotation xyzw, scale)`` of an affine 4x4 matrix; shear raises."""
    A = M[:3, :3]
    s = np.linalg.norm(A, axis=0)
    if np.linalg.det(A) < 0:
        s[0] = -s[0]
    if np.any(np.abs(s) < 1e-12):
        raise ValueError(f"{what} is singular and has no glTF translation/rotation/scale")
    R = A / s
    if np.abs(R.T @ R - np.eye(3)).max() > 1e-5:
        raise ValueError(f"{what} has a shear, which a glTF node cannot hold")
    q: NDArray[np.float64] = _rotation().from_matrix(R).as_quat()
    return M[:3, 3].copy(), q, s


def local_matrices(parents: NDArray[np.int64], world: NDArray[np.float64]) -> NDArray[np.float64]:
    """Node matrices relative to their parents (``world`` (J, 4, 4) -> (J, 4, 4))."""
    L = world.copy()
    has = parents >= 0
    L[has] = np.linalg.solve(world[parents[has]], world[has])
    return L


def world_matrices(parents: NDArray[np.int64], local: NDArray[np.float64]) -> NDArray[np.float64]:
    """World matrices from parent-relative ones (parents listed before or after children)."""
    W = np.empty_like(local)
    done = np.zeros(len(parents), dtype=bool)

    def visit(j: int) -> NDArray[np.float64]:
        if not done[j]:
            p = parents[j]
            W[j] = local[j] if p < 0 else visit(p) @ local[j]
            done[j] = True
        world: NDArray[np.float64] = W[j]
        return world

    for j in range(len(parents)):
        visit(j)
    return W


def joint_poses(
    T_columns: NDArray[np.float64],
    column_joint: NDArray[np.int64],
    parents: NDArray[np.int64],
    bind: NDArray[np.float64],
) -> NDArray[np.float64]:
    """Skinning transforms of every joint from those of the handle columns (f, J, 3, 4).

    A joint that drives no column (an end joint) follows its parent rigidly.
    """
    f, J = T_columns.shape[0], len(parents)
    out = np.full((f, J, 4, 4), np.nan)
    out[:, column_joint] = homogeneous(T_columns)
    for j in range(J):  # end joints come after their parents in skeleton_rig's order
        if np.isnan(out[0, j, 0, 0]):
            p = parents[j]
            out[:, j] = out[:, p] if p >= 0 else np.eye(4)
    return out[..., :3, :]


def sample(
    interp: str, times: ArrayLike, values: NDArray[np.float64], t: NDArray[np.float64]
) -> NDArray[np.float64]:
    """glTF animation sampler at times ``t``: STEP, LINEAR (slerp for unit quaternions) or
    CUBICSPLINE (``values`` holds in-tangent, value, out-tangent per key)."""
    key_times = np.asarray(times, dtype=np.float64)
    quat = values.shape[-1] == 4
    if interp == "CUBICSPLINE":
        values = values.reshape(len(key_times), 3, -1)
    i = np.clip(np.searchsorted(key_times, t, side="right") - 1, 0, len(key_times) - 1)
    i1 = np.minimum(i + 1, len(key_times) - 1)
    dt = np.where(i1 > i, key_times[i1] - key_times[i], 1.0)
    u = np.clip((t - key_times[i]) / dt, 0.0, 1.0)[:, None]
    if interp == "STEP":
        return values[i] if values.ndim == 2 else values[i, 1]
    if interp == "CUBICSPLINE":
        p0, m0 = values[i, 1], values[i, 2] * dt[:, None]
        p1, m1 = values[i1, 1], values[i1, 0] * dt[:, None]
        u2, u3 = u * u, u * u * u
        v: NDArray[np.float64] = (2 * u3 - 3 * u2 + 1) * p0 + (u3 - 2 * u2 + u) * m0
        v += (-2 * u3 + 3 * u2) * p1 + (u3 - u2) * m1
        return v / np.linalg.norm(v, axis=1, keepdims=True) if quat else v
    if quat:
        q0, q1 = values[i], values[i1].copy()
        q1[np.sum(q0 * q1, axis=1) < 0] *= -1
        out = np.empty_like(q0)
        for r in range(len(t)):
            key = _rotation().from_quat(np.stack([q0[r], q1[r]]))
            out[r] = _slerp(key, float(u[r, 0]))
        return out
    lerp: NDArray[np.float64] = (1 - u) * values[i] + u * values[i1]
    return lerp


def _slerp(key: Rotation, u: float) -> NDArray[np.float64]:
    rel = key[0].inv() * key[1]
    q: NDArray[np.float64] = (key[0] * _rotation().from_rotvec(rel.as_rotvec() * u)).as_quat()
    return q
