"""Geometric queries for mesh-free skinning weights (Dodik et al. 2024).

The boundary is either a triangle mesh or soup in 3D (``V`` (n, 3), ``F`` (m, 3)) or a set of
segments in 2D (``V`` (n, 2), ``F`` (m, 2)); it need not be closed, manifold or consistently
connected. Normals follow libigl: outward for counter-clockwise triangles seen from outside and
for counter-clockwise outer polygons in 2D.

* :func:`winding_number`: generalized winding number, hierarchical (Barill et al. 2018) in 2D
  and 3D; 1 inside, 0 outside, in between for open shapes.
* :func:`segment_visible`: the visibility indicator of the kernel ``k_RT`` (eq. 4).
* :func:`closest_point`: closest boundary point, its primitive and normal (eq. 9).
* :func:`knn_distance`: distance to the k-th nearest neighbour (``sigma`` heuristic).
* :class:`GeometricField`, :func:`bbw_field`: mesh-free bounded biharmonic weights on the
  visibility-aware point field (Secs. 4-5, App. A).

Each call builds its acceleration structure in Rust (in parallel, with the GIL released).
"""

from __future__ import annotations

import time
from typing import TYPE_CHECKING, Literal, overload

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ._checks import Callback
from ._field_options import (  # noqa: F401
    FieldOptions,
    _boundary_edges_2d,
    _check_field_memory,
    _handles,
    default_options,
)
from ._field_queries import (  # noqa: F401
    _boundary,
    _queries,
    closest_point,
    knn_distance,
    segment_visible,
    winding_number,
)
from ._geometric_field import (  # noqa: F401
    GeometricField,
    _describe,
)
from ._info import Info

if TYPE_CHECKING:
    from typing_extensions import Unpack


__all__ = [
    "FieldOptions",
    "GeometricField",
    "bbw_field",
    "closest_point",
    "default_options",
    "knn_distance",
    "segment_visible",
    "winding_number",
]


@overload
def bbw_field(
    V: ArrayLike,
    F: ArrayLike | None,
    C: ArrayLike,
    BE: ArrayLike | None = None,
    P: ArrayLike | None = None,
    *,
    return_info: Literal[False] = False,
    **options: Unpack[FieldOptions],
) -> NDArray[np.float64]: ...
@overload
def bbw_field(
    V: ArrayLike,
    F: ArrayLike | None,
    C: ArrayLike,
    BE: ArrayLike | None = None,
    P: ArrayLike | None = None,
    *,
    return_info: Literal[True],
    **options: Unpack[FieldOptions],
) -> tuple[NDArray[np.float64], Info]: ...
@overload
def bbw_field(
    V: ArrayLike,
    F: ArrayLike | None,
    C: ArrayLike,
    BE: ArrayLike | None = None,
    P: ArrayLike | None = None,
    *,
    return_info: bool,
    **options: Unpack[FieldOptions],
) -> NDArray[np.float64] | tuple[NDArray[np.float64], Info]: ...
def bbw_field(
    V: ArrayLike,
    F: ArrayLike | None,
    C: ArrayLike,
    BE: ArrayLike | None = None,
    P: ArrayLike | None = None,
    *,
    tets: ArrayLike | None = None,
    neumann: bool = False,
    seed: int = 0,
    verbose: bool = False,
    callback: Callback | None = None,
    return_info: bool = False,
    n_points: int | None = None,
    samples: int | None = None,
    steps: int | None = None,
    upsamples: int | None = None,
    lr: float | None = None,
    lr_decay: float | None = None,
    beta1: float | None = None,
    beta2: float | None = None,
    adam_eps: float | None = None,
    h: float | None = None,
    eps: float | None = None,
    visibility: bool | None = None,
    wn_l: float | None = None,
    wn_h: float | None = None,
    pool: int | None = None,
    cache_visibility: bool | None = None,
    skip_rays: bool | None = None,
) -> NDArray[np.float64] | tuple[NDArray[np.float64], Info]:
    """Bounded biharmonic weights at the vertices of ``V`` without a volume mesh.

    One-shot :class:`GeometricField` (same arguments and options): optimise with the full
    schedule, return :meth:`GeometricField.vertex_weights`. ``callback`` is that of
    :meth:`GeometricField.optimize`; ``return_info`` also returns
    :meth:`GeometricField.info`.

    Examples
    --------
    >>> import numpy as np, skinrs
    >>> V = np.array([[0, 0], [2, 0], [2, 1], [0, 1]], dtype=float)
    >>> E = np.array([[0, 1], [1, 2], [2, 3], [3, 0]])
    >>> W = skinrs.bbw_field(V, E, [[0.3, 0.5], [1.7, 0.5]], P=[0, 1], steps=40,
    ...                      n_points=256, samples=256, upsamples=1, pool=4096)
    >>> W.shape, bool(np.allclose(W.sum(1), 1))
    ((4, 2), True)
    """
    t0 = time.perf_counter()
    fld = GeometricField(
        V,
        F,
        C,
        BE=BE,
        P=P,
        tets=tets,
        neumann=neumann,
        seed=seed,
        verbose=verbose,
        n_points=n_points,
        samples=samples,
        steps=steps,
        upsamples=upsamples,
        lr=lr,
        lr_decay=lr_decay,
        beta1=beta1,
        beta2=beta2,
        adam_eps=adam_eps,
        h=h,
        eps=eps,
        visibility=visibility,
        wn_l=wn_l,
        wn_h=wn_h,
        pool=pool,
        cache_visibility=cache_visibility,
        skip_rays=skip_rays,
    )
    fld.optimize(callback=callback)
    W = fld.vertex_weights()
    if not return_info:
        return W
    info = fld.info()
    info["seconds"] = time.perf_counter() - t0
    return W, info
