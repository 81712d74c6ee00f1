"""Deforming with reduced weights and measuring the reduction error (paper 002, Sec. 6)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike, NDArray

from . import _checks, _skinrs
from ._checks import (
    as_elements,
    as_index_array,
    as_points,
    as_weights,
    positive_int,
)
from ._reduce_poses import (
    Packed,
    _handle_count,
    _packed,
    _poses,
)


@dataclass
class ReductionError:
    """Paper 002 Sec. 6 errors of a reduced animation against the full-weight one.

    normal_angle : (p, n) angle (radians) between area-weighted vertex normals.
    normal_rms : (p,) RMS normal deviation per pose (radians).
    position_rms : (p,) RMS vertex distance per pose, in percent of the bounding-box diagonal
        of the full-weight pose.
    normal_rms_all, position_rms_all : the same over all poses.
    """

    normal_angle: np.ndarray
    normal_rms: np.ndarray
    position_rms: np.ndarray
    normal_rms_all: float
    position_rms_all: float


def unpack_weights(
    indices: ArrayLike, weights: ArrayLike, m: int, *, sparse: bool = False
) -> NDArray[np.float64] | sp.csr_matrix:
    """Dense ``(n, m)`` (or ``scipy.sparse.csr_matrix`` with ``sparse=True``) view of packed weights.

    >>> import numpy as np, skinrs
    >>> skinrs.unpack_weights(np.array([[2, 0]]), np.array([[.75, .25]]), 3).tolist()
    [[0.25, 0.0, 0.75]]
    """
    m = positive_int(m, "m")
    Wr = as_points(weights, "weights", dims=None, coordinates=False)
    if not sparse:
        _checks.fits_in_memory(
            8.0 * Wr.shape[0] * m, f"a dense ({Wr.shape[0]}, {m}) matrix (m={m})"
        )
    I = _checks.as_real_array(indices, "indices")
    if I.shape != Wr.shape:
        raise ValueError(
            f"indices and weights must have the same shape, got {I.shape} and {Wr.shape}"
        )
    I = as_index_array(I, m, "indices")
    n, k = I.shape
    rows = np.repeat(np.arange(n), k)
    S = sp.csr_matrix((Wr.ravel(), (rows, I.ravel())), shape=(n, m))
    return S if sparse else S.toarray()


def deform(
    V: ArrayLike,
    W: Packed | ArrayLike,
    *,
    control_points: ArrayLike | None = None,
    bone_transforms: ArrayLike | None = None,
) -> NDArray[np.float64]:
    """Deform rest vertices with full or packed weights (linear blend skinning / cage blending).

    ``x_v = sum_i W_vi c_i`` (cages) or ``x_v = sum_i W_vi A_i [v; 1]`` (bones).

    Parameters
    ----------
    V : (n, d) rest vertices.
    W : (n, m) dense weights, or ``(indices, weights)`` packed ``(n, k)``.
    control_points : (p, m, d) or (m, d); bone_transforms : (p, m, d, d+1) or (m, d, d+1).

    Returns
    -------
    (p, n, d) deformed positions, or (n, d) when a single pose was given.
    """
    V = as_points(V, "V")
    packed = isinstance(W, tuple)
    I, A, m = _packed(W, V.shape[0])
    m = _handle_count(control_points, bone_transforms, m, packed)
    P, T, single = _poses(control_points, bone_transforms, m, V.shape[1], required=True)
    X = _skinrs.reduce_deform(V, A, I if packed else None, P, T)
    return X[0] if single else X


def transform_normals(
    N: ArrayLike,
    reduced: Packed | ArrayLike,
    *,
    control_points: ArrayLike | None = None,
    bone_transforms: ArrayLike | None = None,
    C: ArrayLike | None = None,
) -> NDArray[np.float64]:
    """Deform rest normals from (packed) weights without mesh adjacency (paper 002 Sec. 5).

    Skeletons: ``n' ~ (sum_i a_i A_i)^-T n``. Cages: the affine map fitted per vertex by weighted
    least squares to its control points (weights ``a_i^2``), whose inverse transpose is
    ``adj(sum a_i^2 d_i d^_i^T) (sum a_i^2 d_i d_i^T)`` with ``d_i``, ``d^_i`` the rest and
    deformed control points relative to their weighted centroids; exact when the cage moves
    affinely or ``k = 4`` points are affinely independent.

    Parameters
    ----------
    N : (n, 3) rest unit normals.
    reduced : ``(indices, weights)`` packed or (n, m) dense weights.
    control_points : (p, m, 3) or (m, 3), with ``C`` (m, 3) the rest control points;
    bone_transforms : (p, m, 3, 4) or (m, 3, 4).

    Returns
    -------
    (p, n, 3) unit normals, or (n, 3) for a single pose.
    """
    N = as_points(N, "N", dims=(3,))
    I, A, m = _packed(reduced, N.shape[0])
    m = _handle_count(control_points, bone_transforms, m, isinstance(reduced, tuple))
    P, T, single = _poses(control_points, bone_transforms, m, 3, required=True)
    if P is not None:
        if C is None:
            raise ValueError("normals of a cage deformation need the rest control points C")
        C = as_points(C, "C", dims=(3,))
        if C.shape[0] != m:
            raise ValueError(f"C must have {m} rows (one per control point), got {C.shape[0]}")
    elif C is not None:
        raise ValueError("C (rest control points) is only used with control_points")
    X = _skinrs.reduce_transform_normals(N, I, A, P, T, C)
    return X[0] if single else X


def reduction_error(
    V: ArrayLike,
    F: ArrayLike,
    W: ArrayLike,
    reduced: Packed | ArrayLike,
    *,
    control_points: ArrayLike | None = None,
    bone_transforms: ArrayLike | None = None,
) -> ReductionError:
    """Paper 002 Sec. 6 metrics of reduced weights against the full weights over some poses.

    Both weight sets deform ``V``; normals are recomputed from each deformed mesh
    (area-weighted vertex normals) and compared by angle; positions by distance, in percent of
    the bounding-box diagonal of the full-weight pose. Use poses that were *not* used for fitting.

    Parameters
    ----------
    V : (n, 3), F : (f, 3) rest mesh.
    W : (n, m) full weights.
    reduced : ``(indices, weights)`` packed ``(n, k)`` (or dense (n, m)).
    control_points : (p, m, 3) or bone_transforms : (p, m, 3, 4) evaluation poses.

    Returns
    -------
    ReductionError
    """
    V = as_points(V, "V", dims=(3,))
    F = as_elements(F, V, "F", cols=3)
    W = as_weights(W, V.shape[0])
    full = deform(V, W, control_points=control_points, bone_transforms=bone_transforms)
    red = deform(V, reduced, control_points=control_points, bone_transforms=bone_transforms)
    if full.ndim == 2:
        full, red = full[None], red[None]
    ang, normal_rms, position_rms = _skinrs.reduce_deformation_errors(F, full, red)
    nrms, prms = np.asarray(normal_rms), np.asarray(position_rms)
    return ReductionError(
        normal_angle=ang,
        normal_rms=nrms,
        position_rms=prms,
        normal_rms_all=float(np.sqrt(np.mean(nrms**2))),
        position_rms_all=float(np.sqrt(np.mean(prms**2))),
    )
