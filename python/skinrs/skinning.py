"""Posing a mesh: linear blend skinning, dual-quaternion skinning, forward kinematics, normals.

All heavy work runs in Rust (rayon, GIL released). Large inputs (``V``, ``W``) are passed to Rust
as read-only views: nothing is copied when they already are C-contiguous float64, and their
NaN/inf check happens inside the skinning loop (a non-finite result is traced back to the input
row that caused it) instead of in a separate pass.
"""

from __future__ import annotations

from typing import Any, overload

import numpy as np
from numpy.typing import ArrayLike, NDArray

from . import _checks, _skinrs
from ._checks import as_index_array, as_points

#: Skinning weights: dense ``(n, m)``, a packed pair ``(indices (n, k), weights (n, k))`` or a
#: scipy.sparse ``(n, m)`` matrix.
Weights = Any

__all__ = [
    "bone_parents",
    "dqs",
    "forward_kinematics",
    "lbs",
    "per_vertex_normals",
    "quaternions_from_xyzw",
]


def _as_float_view(X: ArrayLike, name: str, ndim: int) -> NDArray[np.float64]:
    """C-contiguous float64 array with ``ndim`` dimensions; copies only when needed.

    Finiteness is not checked here (the Rust kernels check their output and name the input).
    """
    A = _checks.as_real_array(X, name)
    if A.ndim != ndim:
        raise ValueError(f"{name} must be {ndim}-dimensional, got shape {A.shape}")
    return np.ascontiguousarray(A, dtype=np.float64)


def _as_index_view(X: ArrayLike, name: str) -> NDArray[np.int64]:
    """C-contiguous int64 ``(n, k)`` index array; range checked by the Rust kernel."""
    A = _checks.as_real_array(X, name)
    if A.dtype == bool:
        raise ValueError(f"{name} must hold integer indices, got dtype {A.dtype}")
    if not np.issubdtype(A.dtype, np.integer) and (
        not np.all(np.isfinite(A)) or np.any(A != np.round(A))
    ):
        raise ValueError(f"{name} must hold integer indices, got non-integral values")
    if A.ndim != 2:
        raise ValueError(f"{name} must be 2-dimensional (n, k), got shape {A.shape}")
    if A.size and (A.max() > np.iinfo(np.int64).max or A.min() < np.iinfo(np.int64).min):
        raise ValueError(f"{name} holds index {A.max()}, beyond any number of handles")
    return np.ascontiguousarray(A, dtype=np.int64)


def _normals(N: ArrayLike | None, V: NDArray[np.float64]) -> NDArray[np.float64] | None:
    """Rest normals shaped like ``V`` (float64, C-contiguous), or None."""
    if N is None:
        return None
    N = _as_float_view(N, "N", 2)
    if N.shape != V.shape:
        raise ValueError(f"N must have shape {V.shape} like V, got {N.shape}")
    return N


def _split_weights(W: Weights) -> tuple[NDArray[np.float64], NDArray[np.int64] | None]:
    """``(weights, index or None)`` from dense ``W``, a packed pair, or a scipy.sparse matrix."""
    if isinstance(W, tuple):  # (indices, weights); a list is read as a dense matrix
        if len(W) != 2:
            raise ValueError(
                f"packed weights must be a pair (indices, weights), got {len(W)} items"
            )
        I, Wk = W
        I = _as_index_view(I, "W indices")
        Wk = _as_float_view(Wk, "W weights", 2)
        if I.shape != Wk.shape:
            raise ValueError(
                f"packed weights: indices {I.shape} and weights {Wk.shape} must have the same shape"
            )
        return Wk, I
    if not isinstance(W, np.ndarray) and hasattr(W, "tocsr"):
        # scipy.sparse (imported only here: importing it costs ~0.3 s)
        import scipy.sparse as sp

        if sp.issparse(W):
            return _sparse_to_packed(W)
    return _as_float_view(W, "W", 2), None


def _sparse_to_packed(W: Any) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """Packs a sparse ``(n, m)`` matrix into ``k = max nonzeros per row`` influences."""
    R = W.tocsr()
    R.sum_duplicates()
    n = R.shape[0]
    counts = np.diff(R.indptr)
    k = max(int(counts.max()) if n else 1, 1)
    I = np.zeros((n, k), dtype=np.int64)
    Wk = np.zeros((n, k), dtype=np.float64)
    rows = np.repeat(np.arange(n), counts)
    slots = np.arange(R.nnz) - np.repeat(R.indptr[:-1], counts)
    I[rows, slots] = R.indices
    Wk[rows, slots] = R.data
    return Wk, I


def _transforms(T: ArrayLike, d: int) -> NDArray[np.float64]:
    T = _as_float_view(T, "T", 3)
    if T.shape[1:] != (d, d + 1):
        raise ValueError(
            f"T must have shape (m, {d}, {d + 1}) (one affine [R | t] per handle) for "
            f"{d}D points, got {T.shape}"
        )
    if not np.all(np.isfinite(T)):
        j = int(np.argwhere(~np.isfinite(T))[0][0])
        raise ValueError(f"T[{j}] has a NaN or infinite entry")
    return T


def _points(V: ArrayLike, name: str = "V") -> NDArray[np.float64]:
    V = _as_float_view(V, name, 2)
    if V.shape[1] not in (2, 3):
        raise ValueError(f"{name} must have shape (n, 2) or (n, 3), got {V.shape}")
    return V


def _check_out(
    out: NDArray[np.float64] | None, shape: tuple[int, ...]
) -> NDArray[np.float64] | None:
    if out is None:
        return None
    if not isinstance(out, np.ndarray) or out.dtype != np.float64:
        raise ValueError("out must be a float64 numpy array")
    if out.shape != shape:
        raise ValueError(f"out must have shape {shape} like V, got {out.shape}")
    if not out.flags.c_contiguous or not out.flags.writeable:
        raise ValueError("out must be a writeable C-contiguous array")
    return out


@overload
def lbs(
    V: ArrayLike,
    W: Weights,
    T: ArrayLike,
    *,
    N: None = None,
    out: NDArray[np.float64] | None = None,
) -> NDArray[np.float64]: ...
@overload
def lbs(
    V: ArrayLike, W: Weights, T: ArrayLike, *, N: ArrayLike, out: NDArray[np.float64] | None = None
) -> tuple[NDArray[np.float64], NDArray[np.float64]]: ...
def lbs(
    V: ArrayLike,
    W: Weights,
    T: ArrayLike,
    *,
    N: ArrayLike | None = None,
    out: NDArray[np.float64] | None = None,
) -> NDArray[np.float64] | tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Linear blend skinning: ``U[i] = sum_j W[i, j] (R_j V[i] + t_j)``.

    Parameters
    ----------
    V : (n, d) float array
        Rest positions, d = 2 or 3.
    W : (n, m) float array, or a tuple (indices (n, k) int, weights (n, k) float), or a
        scipy.sparse (n, m) matrix
        Skinning weights. In the packed pair, vertex ``i`` is influenced by handle
        ``indices[i, l]`` with weight ``weights[i, l]``; unused slots carry weight 0.
    T : (m, d, d+1) float array
        Affine transform ``[R | t]`` of each handle (``x -> R x + t``).
    N : (n, d) float array, optional
        Rest normals. When given, the deformed unit normals are returned too: each normal is
        mapped by the cofactor ``det(A) A^{-T}`` of the vertex's blended linear part ``A``
        (exactly how a face normal of the deformed surface transforms), then normalised.
    out : (n, d) float64 C-contiguous array, optional
        Where to write ``U`` (no allocation, e.g. when posing many frames); returned.

    Returns
    -------
    U : (n, d) float array
        Deformed positions.
    NU : (n, d) float array
        Deformed unit normals, only when ``N`` is given.

    Examples
    --------
    >>> import numpy as np, skinrs
    >>> V = np.array([[0.0, 0, 0], [1, 0, 0]])
    >>> T = np.stack([np.hstack([np.eye(3), np.zeros((3, 1))]),
    ...               np.hstack([np.eye(3), [[1.0], [0], [0]]])])
    >>> skinrs.lbs(V, np.array([[1.0, 0], [0.5, 0.5]]), T)
    array([[0. , 0. , 0. ],
           [1.5, 0. , 0. ]])
    """
    V = _points(V)
    d = V.shape[1]
    T = _transforms(T, d)
    Wv, I = _split_weights(W)
    Nv = _normals(N, V)
    out = _check_out(out, V.shape)
    U, NU = _skinrs.lbs(V, Wv, T, index=I, N=Nv, out=out)
    return U if NU is None else (U, NU)


@overload
def dqs(
    V: ArrayLike,
    W: Weights,
    T: ArrayLike,
    *,
    N: None = None,
    out: NDArray[np.float64] | None = None,
) -> NDArray[np.float64]: ...
@overload
def dqs(
    V: ArrayLike, W: Weights, T: ArrayLike, *, N: ArrayLike, out: NDArray[np.float64] | None = None
) -> tuple[NDArray[np.float64], NDArray[np.float64]]: ...
def dqs(
    V: ArrayLike,
    W: Weights,
    T: ArrayLike,
    *,
    N: ArrayLike | None = None,
    out: NDArray[np.float64] | None = None,
) -> NDArray[np.float64] | tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Dual-quaternion skinning (Kavan et al. 2008) of rigid handle transforms.

    The rigid motions are blended as unit dual quaternions (each influence taken in the
    hemisphere of the vertex's largest-weight influence), which avoids the volume loss
    ("candy wrapper") of :func:`lbs` at twisting joints.

    Parameters
    ----------
    V : (n, 3) or (n, 2) float array
        Rest positions (2D points are handled as 3D points with z = 0).
    W : dense (n, m), packed tuple (indices, weights) or scipy.sparse
        Skinning weights, as in :func:`lbs`.
    T : (m, 3, 4) float array (or (m, 2, 3) for 2D)
        Rigid transforms ``[R | t]``; ``R`` must be a rotation (|R^T R - I| <= 1e-6).
    N : (n, d) float array, optional
        Rest normals; when given, also returns them rotated by each vertex's blended rotation.
    out : (n, d) float64 C-contiguous array, optional
        Where to write ``U``; returned.

    Returns
    -------
    U : (n, d) float array
        Deformed positions (and ``NU`` when ``N`` is given).

    Examples
    --------
    >>> import numpy as np, skinrs
    >>> c, s = np.cos(np.pi / 2), np.sin(np.pi / 2)
    >>> Rz = np.array([[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, 0.0]])
    >>> T = np.stack([np.hstack([np.eye(3), np.zeros((3, 1))]), Rz])
    >>> U = skinrs.dqs(np.array([[1.0, 0, 0]]), np.array([[0.5, 0.5]]), T)
    >>> bool(np.isclose(np.linalg.norm(U), 1.0))   # LBS would shrink it to 0.707
    True
    """
    V = _points(V)
    Wv, I = _split_weights(W)
    out = _check_out(out, V.shape)
    if V.shape[1] == 2:
        T2 = _transforms(T, 2)
        T3 = np.zeros((T2.shape[0], 3, 4))
        T3[:, :2, :2] = T2[:, :, :2]
        T3[:, :2, 3] = T2[:, :, 2]
        T3[:, 2, 2] = 1.0
        V3 = np.hstack([V, np.zeros((V.shape[0], 1))])
        N2 = _normals(N, V)
        N3 = None if N2 is None else np.hstack([N2, np.zeros((len(V), 1))])
        U3, NU = _skinrs.dqs(V3, Wv, T3, index=I, N=N3)
        if out is None:
            out = np.empty(V.shape)
        out[:] = U3[:, :2]
        return out if NU is None else (out, np.ascontiguousarray(NU[:, :2]))
    T = _transforms(T, 3)
    Nv = _normals(N, V)
    U, NU = _skinrs.dqs(V, Wv, T, index=I, N=Nv, out=out)
    return U if NU is None else (U, NU)


def bone_parents(BE: ArrayLike, *, n_joints: int | None = None) -> NDArray[np.int64]:
    """Parent bone of each bone from directed edges (-1 for a root).

    Bone ``b``'s parent is the bone that ends at joint ``BE[b, 0]``. The bones may form a forest;
    a joint that ends two bones, a self-loop or a cycle raises ``ValueError``.

    Examples
    --------
    >>> import numpy as np, skinrs
    >>> skinrs.bone_parents(np.array([[0, 1], [1, 2], [1, 3]]))
    array([-1,  0,  0])
    """
    if n_joints is None:
        B = as_index_array(BE, 2**63 - 1, "BE", cols=2)
        n_joints = int(B.max()) + 1 if B.size else 0
    n_joints = _checks.integer(n_joints, "n_joints", 0, 2**63 - 1)
    BE = as_index_array(BE, n_joints, "BE", cols=2)
    return _skinrs.bone_parents(BE, n_joints)


def forward_kinematics(C: ArrayLike, BE: ArrayLike, Q: ArrayLike) -> NDArray[np.float64]:
    """Absolute bone transforms from relative rotations about each bone's rest start joint.

    Bone ``b`` rotates by ``Q[b]`` about its rest start joint ``C[BE[b, 0]]``, after its parent's
    motion (parents from the directed edges, see :func:`bone_parents`): ``T_b = T_parent o
    rot(Q_b about C[BE[b, 0]])``. This is libigl's ``forward_kinematics``.

    Parameters
    ----------
    C : (n, 3) float array
        Rest joint positions (or (n, 2) for a 2D skeleton).
    BE : (m, 2) int array
        Directed bone edges, parent joint -> child joint.
    Q : (m, 4) or (m, 3, 3) float array
        Unit quaternions ``(w, x, y, z)`` (rows within 1e-3 of unit length are normalised,
        others raise ``ValueError``), or rotation matrices (orthonormal within 1e-6,
        determinant +1). For a 2D skeleton, ``Q`` is ``(m,)`` angles in radians.

    Returns
    -------
    T : (m, 3, 4) float array (or (m, 2, 3) in 2D)
        Transforms ``[R | t]`` for :func:`lbs` / :func:`dqs`. The identity pose gives ``[I | 0]``.

    Examples
    --------
    >>> import numpy as np, skinrs
    >>> C = np.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 0]])
    >>> BE = np.array([[0, 1], [1, 2]])
    >>> q = [np.cos(np.pi / 4), 0, 0, np.sin(np.pi / 4)]        # 90 degrees about z
    >>> T = skinrs.forward_kinematics(C, BE, [[1.0, 0, 0, 0], q])
    >>> np.round(T[1] @ [2.0, 0, 0, 1], 12)                     # the tip swings up
    array([1., 1., 0.])
    """
    C = as_points(C, "C", dims=(2, 3))
    BE = as_index_array(BE, C.shape[0], "BE", cols=2)
    Q = _checks.as_real_array(Q, "Q")
    if C.shape[1] == 2:
        return _forward_kinematics_2d(C, BE, Q)
    if np.ndim(Q) == 3:
        return _skinrs.forward_kinematics(C, BE, _quaternions_from_matrices(Q))
    return _skinrs.forward_kinematics(C, BE, _as_float_view(Q, "Q", 2))


def _forward_kinematics_2d(
    C: NDArray[np.float64], BE: NDArray[np.int64], angles: ArrayLike
) -> NDArray[np.float64]:
    """2D skeleton: one angle per bone, as rotations about z of the skeleton at z = 0."""
    theta = _as_float_view(angles, "Q", np.ndim(angles)).reshape(-1)
    if theta.shape[0] != BE.shape[0]:
        raise ValueError(
            f"for a 2D skeleton Q must hold one angle per bone ({BE.shape[0]}), "
            f"got shape {np.shape(angles)}"
        )
    if not np.all(np.isfinite(theta)):
        raise ValueError("Q has a NaN or infinite angle")
    Q4 = np.zeros((len(theta), 4))
    Q4[:, 0] = np.cos(theta / 2)
    Q4[:, 3] = np.sin(theta / 2)
    C3 = np.hstack([C, np.zeros((C.shape[0], 1))])
    T3 = _skinrs.forward_kinematics(C3, BE, Q4)
    return np.ascontiguousarray(T3[:, :2][:, :, [0, 1, 3]])


def _quaternions_from_matrices(R: ArrayLike) -> NDArray[np.float64]:
    """Unit quaternions ``(w, x, y, z)`` of rotation matrices ``R (m, 3, 3)`` (Shepperd's method:
    the largest of the four squared components is computed first, for accuracy)."""
    R = _as_float_view(R, "Q", 3)
    if R.shape[1:] != (3, 3):
        raise ValueError(f"rotation matrices Q must have shape (m, 3, 3), got {R.shape}")
    if not np.all(np.isfinite(R)):
        raise ValueError("Q has a NaN or infinite entry")
    err = np.abs(np.einsum("bij,bkj->bik", R, R) - np.eye(3)).max() if len(R) else 0.0
    if err > 1e-6 or np.any(np.linalg.det(R) <= 0):
        raise ValueError("Q must hold rotation matrices (orthonormal, determinant +1)")
    t = np.trace(R, axis1=1, axis2=2)
    d = np.stack([t, R[:, 0, 0], R[:, 1, 1], R[:, 2, 2]], axis=1)
    Q = np.empty((len(R), 4))
    for b, (Rb, c) in enumerate(zip(R, d.argmax(1), strict=True)):
        if c == 0:
            w = 0.5 * np.sqrt(1 + t[b])
            Q[b] = [w, Rb[2, 1] - Rb[1, 2], Rb[0, 2] - Rb[2, 0], Rb[1, 0] - Rb[0, 1]]
            Q[b, 1:] /= 4 * w
        else:
            i = c - 1
            j, k = (i + 1) % 3, (i + 2) % 3
            x = 0.5 * np.sqrt(1 + Rb[i, i] - Rb[j, j] - Rb[k, k])
            Q[b, 0] = (Rb[k, j] - Rb[j, k]) / (4 * x)
            Q[b, 1 + i] = x
            Q[b, 1 + j] = (Rb[j, i] + Rb[i, j]) / (4 * x)
            Q[b, 1 + k] = (Rb[k, i] + Rb[i, k]) / (4 * x)
    return Q


def quaternions_from_xyzw(Q: ArrayLike) -> NDArray[np.float64]:
    """Reorders libigl/Eigen storage ``(x, y, z, w)`` to skinrs' ``(w, x, y, z)``.

    Accepts a flat ``(4m,)`` or ``(4m, 1)`` column (as read from ``hand-pose.dmat``: bone ``b``'s
    quaternion is entries ``4b .. 4b+3``) or an ``(m, 4)`` array of ``(x, y, z, w)`` rows.

    Examples
    --------
    >>> import skinrs
    >>> skinrs.quaternions_from_xyzw([0.0, 0.0, 0.0, 1.0])
    array([[1., 0., 0., 0.]])
    """
    A = _checks.as_real_array(Q, "Q").astype(np.float64)
    if A.ndim == 2 and A.shape[1] == 4:
        X = A
    elif A.ndim == 1 or (A.ndim == 2 and A.shape[1] == 1):
        if A.size % 4:
            raise ValueError(f"a flat quaternion list needs a multiple of 4 entries, got {A.size}")
        X = A.reshape(-1, 4)
    else:
        raise ValueError(f"Q must have shape (4m,), (4m, 1) or (m, 4), got {A.shape}")
    if not np.all(np.isfinite(X)):
        raise ValueError("Q has a NaN or infinite entry")
    return np.ascontiguousarray(X[:, [3, 0, 1, 2]])


def per_vertex_normals(V: ArrayLike, F: ArrayLike) -> NDArray[np.float64]:
    """Area-weighted unit vertex normals of a triangle mesh.

    Each vertex gets the normalised sum of its faces' ``(v1 - v0) x (v2 - v0)`` (as libigl's
    ``per_vertex_normals`` with area weighting); a vertex with no incident face of positive area
    gets the zero vector.

    Examples
    --------
    >>> import numpy as np, skinrs
    >>> V = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]])
    >>> skinrs.per_vertex_normals(V, np.array([[0, 1, 2]]))[0]
    array([0., 0., 1.])
    """
    V = as_points(V, "V", dims=(3,))
    F = as_index_array(F, V.shape[0], "F", cols=3)
    return _skinrs.per_vertex_normals(V, F)
