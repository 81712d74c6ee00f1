"""skinrs: exact bounded biharmonic skinning weights in Rust, for numpy users.

>>> import skinrs
>>> V, T, _ = skinrs.io.read_mesh("hand.mesh")        # doctest: +SKIP
>>> C, BE = skinrs.io.read_tgf("hand.tgf")            # doctest: +SKIP
>>> W = skinrs.bbw_dual(V, T, C, BE=BE)               # doctest: +SKIP
"""

from . import _skinrs, field, io
from ._info import Info
from ._skinrs import InternalError
from .bbw import bbw_dual, bbw_dual_constrained, biharmonic_energy, boundary_conditions
from .field import (
    GeometricField,
    bbw_field,
    closest_point,
    knn_distance,
    segment_visible,
    winding_number,
)
from .meshing import MeshingWarning, mesh_with_skeleton, skin_weights
from .operators import biharmonic_matrix, connected_components, cotan_laplacian, massmatrix
from .reduce import (
    random_skeleton_poses,
    reduce_weights,
    reduction_error,
    transform_normals,
    unpack_weights,
)
from .skinning import (
    bone_parents,
    dqs,
    forward_kinematics,
    lbs,
    per_vertex_normals,
    quaternions_from_xyzw,
)

__version__: str = _skinrs.__version__

__all__ = [
    "GeometricField",
    "Info",
    "InternalError",
    "MeshingWarning",
    "bbw_dual",
    "bbw_dual_constrained",
    "bbw_field",
    "biharmonic_energy",
    "biharmonic_matrix",
    "bone_parents",
    "boundary_conditions",
    "closest_point",
    "connected_components",
    "cotan_laplacian",
    "dqs",
    "field",
    "forward_kinematics",
    "io",
    "knn_distance",
    "lbs",
    "massmatrix",
    "mesh_with_skeleton",
    "per_vertex_normals",
    "quaternions_from_xyzw",
    "random_skeleton_poses",
    "reduce_weights",
    "reduction_error",
    "segment_visible",
    "skin_weights",
    "transform_normals",
    "unpack_weights",
    "winding_number",
]
