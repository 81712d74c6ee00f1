"""Discrete operators on triangle and tetrahedral meshes, in libigl's conventions.

``cotan_laplacian`` equals ``igl.cotmatrix``, ``massmatrix`` equals ``igl.massmatrix`` (Voronoi or
barycentric lumping) and ``biharmonic_matrix`` is the energy matrix ``B = L^T M^-1 L`` of bounded
biharmonic weights (Solomon & Stein 2025, Sec. 7). The work is done in Rust, in parallel, with
the GIL released.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike, NDArray

from . import _checks, _skinrs

#: The lumped mass kinds (from the Rust core).
MASS_KINDS: tuple[str, ...] = _skinrs.MASS_KINDS


def _mesh(V: ArrayLike, F: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    V = _checks.as_points(V, "V")
    F = _checks.as_elements(F, V, "F")
    return V, F


def _mass_kind(kind: object, name: str) -> str:
    if not isinstance(kind, str) or kind.lower() not in MASS_KINDS:
        raise ValueError(f"{name} must be one of {MASS_KINDS}, got {kind!r}")
    return kind.lower()


def _csc(
    parts: tuple[NDArray[np.float64], NDArray[np.int64], NDArray[np.int64], tuple[int, int]],
) -> sp.csc_matrix:
    data, indices, indptr, shape = parts
    return sp.csc_matrix((data, indices, indptr), shape=shape)


def cotan_laplacian(V: ArrayLike, F: ArrayLike) -> sp.csc_matrix:
    """Cotangent Laplacian of a triangle mesh (2D or 3D) or a tetrahedral mesh.

    Same convention as ``igl.cotmatrix``: ``L`` is symmetric and **negative** semidefinite, with
    ``L[i, j] = (cot a_ij + cot b_ij) / 2`` for triangles (sum over the triangles sharing edge
    ``ij``), ``L[i, j] = sum l_kl cot(theta_kl) / 6`` for tets (sum over the tets sharing edge
    ``ij`` of the opposite edge's length times the cotangent of its dihedral angle) and
    ``L[i, i] = -sum_j L[i, j]``. Triangle orientation does not matter.

    Parameters
    ----------
    V : (n, d) float array
        Vertex positions, ``d`` = 2 or 3 (3 for tets).
    F : (m, 3) or (m, 4) int array
        Triangles or tetrahedra (rows index ``V``).

    Returns
    -------
    L : (n, n) scipy.sparse.csc_matrix
        Vertices referenced by no element have an empty row and column.

    Raises
    ------
    ValueError
        Bad shapes or indices, NaN coordinates, a degenerate element or an inverted tet; the
        message names the element.

    Examples
    --------
    >>> import numpy as np, skinrs
    >>> V = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    >>> L = skinrs.cotan_laplacian(V, np.array([[0, 1, 2]]))
    >>> L.toarray()
    array([[-1. ,  0.5,  0.5],
           [ 0.5, -0.5,  0. ],
           [ 0.5,  0. , -0.5]])
    """
    V, F = _mesh(V, F)
    return _csc(_skinrs._cotan_laplacian(V, F))


def massmatrix(V: ArrayLike, F: ArrayLike, *, kind: str = "voronoi") -> sp.csc_matrix:
    """Lumped (diagonal) mass matrix, equal to ``igl.massmatrix``.

    Parameters
    ----------
    V : (n, d) float array
        Vertex positions, ``d`` = 2 or 3 (3 for tets).
    F : (m, 3) or (m, 4) int array
        Triangles or tetrahedra.
    kind : {"voronoi", "barycentric"}
        ``"voronoi"`` (``igl.MASSMATRIX_TYPE_VORONOI``): circumcentric dual area/volume, with
        libigl's rules for obtuse triangles (half the area to the obtuse corner, a quarter to the
        others) and for circumcentres outside a tet. ``"barycentric"``: a third of each triangle's
        area / a quarter of each tet's volume per corner.

    Returns
    -------
    M : (n, n) scipy.sparse.csc_matrix
        Diagonal; ``M.diagonal().sum()`` is the total area/volume. Unused vertices get 0.

    Examples
    --------
    >>> import numpy as np, skinrs
    >>> V = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    >>> skinrs.massmatrix(V, np.array([[0, 1, 2]])).diagonal()
    array([0.25 , 0.125, 0.125])
    """
    kind = _mass_kind(kind, "kind")
    V, F = _mesh(V, F)
    m = _skinrs._massmatrix(V, F, kind)
    n = m.shape[0]
    idx = np.arange(n + 1, dtype=np.int64)
    return sp.csc_matrix((m, idx[:n], idx), shape=(n, n))


def biharmonic_matrix(V: ArrayLike, F: ArrayLike, *, mass: str = "voronoi") -> sp.csc_matrix:
    """Biharmonic energy matrix ``B = L^T M^-1 L``.

    ``L`` is :func:`cotan_laplacian` and ``M`` the lumped mass matrix of kind ``mass``, divided by
    its largest entry first (Solomon & Stein 2025, Sec. 7). The bounded biharmonic energy of
    weights ``W`` is ``trace(W^T B W)``.

    Parameters
    ----------
    V : (n, d) float array
    F : (m, 3) or (m, 4) int array
    mass : {"voronoi", "barycentric"}

    Returns
    -------
    B : (n, n) scipy.sparse.csc_matrix
        Exactly symmetric, positive semidefinite, constants in its null space.

    Examples
    --------
    >>> import numpy as np, skinrs
    >>> V = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    >>> B = skinrs.biharmonic_matrix(V, np.array([[0, 1, 2], [0, 2, 3]]))
    >>> bool(abs(B @ np.ones(4)).max() < 1e-14)
    True
    """
    mass = _mass_kind(mass, "mass")
    V, F = _mesh(V, F)
    return _csc(_skinrs._biharmonic_matrix(V, F, mass))


def connected_components(F: ArrayLike, *, n: int | None = None) -> tuple[int, NDArray[np.int64]]:
    """Connected components of the vertices of a mesh (vertices sharing an element are connected).

    Parameters
    ----------
    F : (m, s) int array
        Elements (edges, triangles, tets ...).
    n : int, optional
        Number of vertices (default ``F.max() + 1``). Vertices in no element are components of
        their own.

    Returns
    -------
    count : int
    labels : (n,) int64 array
        Component of each vertex, numbered in order of each component's smallest vertex (as
        ``scipy.sparse.csgraph.connected_components``).

    Examples
    --------
    >>> import numpy as np, skinrs.operators as ops
    >>> ops.connected_components(np.array([[0, 1, 2], [3, 4, 5]]), n=7)
    (3, array([0, 0, 0, 1, 1, 1, 2]))
    """
    A = _checks.as_real_array(F, "F")
    if A.ndim == 2 and A.shape[1] == 0:
        raise ValueError(f"F must have at least one column, got shape {A.shape}")
    if n is None:
        F = _checks.as_index_array(A, 2**63 - 1, "F")
        n = int(F.max()) + 1 if F.size else 0
        what = f"labels for the {n} vertices that F's largest index implies"
    else:
        n = _checks.integer(n, "n", 0, 2**63 - 1)
        what = f"labels for n={n} vertices"
    # union-find keeps three vertex-sized arrays next to the labels
    _checks.fits_in_memory(32.0 * n, what)
    F = _checks.as_index_array(A, n, "F")
    count, labels = _skinrs._connected_components(n, F)
    return int(count), labels
