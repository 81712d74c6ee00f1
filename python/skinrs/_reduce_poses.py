"""Packed weights and example poses of :mod:`skinrs.reduce`."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from . import _checks
from ._checks import (
    as_index_array,
    as_points,
    as_weights,
    positive_float,
    positive_int,
)
from .skinning import forward_kinematics

#: Packed weights ``(indices (n, k) int, weights (n, k) float)``.
Packed = tuple[NDArray[np.int64], NDArray[np.float64]]


def _poses(
    control_points: ArrayLike | None,
    bone_transforms: ArrayLike | None,
    m: int,
    d: int | None,
    *,
    required: bool,
) -> tuple[NDArray[np.float64] | None, NDArray[np.float64] | None, bool]:
    """Checks the example poses; a single pose may be given without the leading axis.

    Returns ``(control_points, bone_transforms, single)``, batched, one of them ``None``.
    """
    if control_points is not None and bone_transforms is not None:
        raise ValueError("pass either control_points or bone_transforms, not both")
    if control_points is None and bone_transforms is None:
        if required:
            raise ValueError("example poses are needed: pass control_points or bone_transforms")
        return None, None, False
    if control_points is not None:
        P = _checks.as_real_array(control_points, "control_points")
        single = P.ndim == 2
        P = _checks.as_array(P[None] if single else P, "control_points", 3)
        dd = P.shape[2] if d is None else d
        if P.shape[0] < 1 or P.shape[1:] != (m, dd):
            raise ValueError(
                f"control_points must have shape (p, {m}, {dd}) (p poses of the {m} handles), "
                f"got {np.shape(control_points)}"
            )
        return P, None, single
    assert bone_transforms is not None
    T = _checks.as_real_array(bone_transforms, "bone_transforms")
    single = T.ndim == 3
    T = _checks.as_array(T[None] if single else T, "bone_transforms", 4)
    dd = 3 if d is None else d
    if T.shape[0] < 1 or T.shape[1:] != (m, dd, dd + 1):
        raise ValueError(
            f"bone_transforms must have shape (p, {m}, {dd}, {dd + 1}) (affine [A | t] per pose "
            f"and bone), got {np.shape(bone_transforms)}"
        )
    return None, T, single


def _packed(
    reduced: Packed | ArrayLike, n: int | None = None
) -> tuple[NDArray[np.int64], NDArray[np.float64], int]:
    """``(indices, weights)`` or a dense ``(n, m)`` matrix -> int64 indices, float weights, m."""
    if isinstance(reduced, tuple) and len(reduced) == 2:
        Wr = as_points(reduced[1], "weights", dims=None, coordinates=False)
        I = _checks.as_real_array(reduced[0], "indices")
        if I.shape != Wr.shape:
            raise ValueError(
                f"indices and weights must have the same shape, got {I.shape} and {Wr.shape}"
            )
        I = as_index_array(I, 1 << 62, "indices")
        if n is not None and I.shape[0] != n:
            raise ValueError(f"weights must have {n} rows (one per vertex), got {I.shape[0]}")
        return I, Wr, int(I.max()) + 1 if I.size else 0
    W = as_weights(reduced, n)
    n_, m = W.shape
    I = np.ascontiguousarray(np.broadcast_to(np.arange(m, dtype=np.int64), (n_, m)))
    return I, W, m


def _handle_count(
    control_points: ArrayLike | None, bone_transforms: ArrayLike | None, m: int, packed: bool
) -> int:
    """Handle count of the poses: dense weights fix it, packed weights bound it from below."""
    X = control_points if control_points is not None else bone_transforms
    if X is None or not packed:
        return m
    name = "control_points" if control_points is not None else "bone_transforms"
    shape = _checks.as_real_array(X, name).shape
    single = len(shape) == (2 if control_points is not None else 3)
    mp = shape[0] if single else (shape[1] if len(shape) > 1 else 0)
    if mp < m:
        raise ValueError(f"the weights refer to handle {m - 1}, but {name} has {mp} handles")
    return mp


def _bones(C: ArrayLike, BE: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    C = as_points(C, "C", dims=(3,))
    BE = as_index_array(BE, C.shape[0], "BE", cols=2, allow_empty=False)
    return C, BE


def _rotation(axis: NDArray[np.float64], angle: float) -> NDArray[np.float64]:
    """Rodrigues' formula for a unit axis."""
    x, y, z = axis
    K = np.array([[0, -z, y], [z, 0, -x], [-y, x, 0]])
    R: NDArray[np.float64] = np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * (K @ K)
    return R


def random_skeleton_poses(
    C: ArrayLike,
    BE: ArrayLike,
    n_poses: int,
    *,
    max_angle: float = np.pi / 6,
    max_twist: float | None = None,
    seed: int | np.random.Generator | None = None,
) -> NDArray[np.float64]:
    """Random plausible skeleton poses: bounded bends and twists of every bone about its head.

    Relative to its parent, each bone bends about a uniformly random axis perpendicular to the
    bone by an angle drawn uniformly from ``[-max_angle, max_angle]``, then twists about its own
    axis by at most ``max_twist``; forward kinematics chains them. The relative rotation of a bone
    is therefore at most ``max_angle + max_twist``.

    Parameters
    ----------
    C : (j, 3) rest joint positions. BE : (m, 2) bones (head, tail) as joint indices; a forest.
    n_poses : int. max_angle : float, radians. max_twist : float, radians (default
    ``max_angle / 3``; 0 for none). seed : int or numpy Generator.

    Returns
    -------
    (n_poses, m, 3, 4) bone transforms ``[A | t]``, ready for ``bone_transforms=``.

    >>> import numpy as np, skinrs
    >>> T = skinrs.random_skeleton_poses([[0, 0, 0], [0, 1, 0]], [[0, 1]], 2, seed=1)
    >>> T.shape
    (2, 1, 3, 4)
    """
    C, BE = _bones(C, BE)
    n_poses = positive_int(n_poses, "n_poses")
    max_angle = positive_float(max_angle, "max_angle")
    if max_angle > np.pi:
        raise ValueError(f"max_angle must be at most pi (radians), got {max_angle!r}")
    max_twist = (
        max_angle / 3 if max_twist is None else _checks.non_negative_float(max_twist, "max_twist")
    )
    if max_twist > np.pi:
        raise ValueError(f"max_twist must be at most pi (radians), got {max_twist!r}")
    if not isinstance(seed, np.random.Generator):
        seed = _checks.seed(seed)
    rng = np.random.default_rng(seed)
    m = BE.shape[0]
    _checks.fits_in_memory(96.0 * n_poses * m, f"n_poses={n_poses} poses of {m} bones")
    axis = C[BE[:, 1]] - C[BE[:, 0]]
    length = np.linalg.norm(axis, axis=1, keepdims=True)
    if np.any(length == 0):
        raise ValueError(f"bone {int(np.flatnonzero(length == 0)[0])} has zero length")
    axis /= length
    out = np.empty((n_poses, m, 3, 4))
    for p in range(n_poses):
        bend = rng.normal(size=(m, 3))
        bend -= (bend * axis).sum(1, keepdims=True) * axis  # perpendicular to the bone
        bend /= np.linalg.norm(bend, axis=1, keepdims=True)
        angles = np.asarray(rng.uniform(-max_angle, max_angle, size=m))
        twists = np.asarray(rng.uniform(-max_twist, max_twist, size=m))
        R = np.stack(
            [_rotation(b, a) @ _rotation(d, t) for b, a, d, t in zip(bend, angles, axis, twists)]
        )
        out[p] = forward_kinematics(C, BE, R)
    return out
