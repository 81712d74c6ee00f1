"""skinrs: exact bounded biharmonic skinning weights in Rust, for numpy users.

>>> import skinrs
>>> V, T, _ = skinrs.io.read_mesh("hand.mesh")        # doctest: +SKIP
>>> C, BE = skinrs.io.read_tgf("hand.tgf")            # doctest: +SKIP
>>> W = skinrs.bbw_dual(V, T, C, BE=BE)               # doctest: +SKIP
"""

from . import io
from .bbw import bbw_dual, bbw_dual_constrained, biharmonic_energy, boundary_conditions
from .operators import biharmonic_matrix, connected_components, cotan_laplacian, massmatrix

__version__ = "0.1.0"

__all__ = [
    "bbw_dual",
    "bbw_dual_constrained",
    "biharmonic_energy",
    "biharmonic_matrix",
    "boundary_conditions",
    "connected_components",
    "cotan_laplacian",
    "io",
    "massmatrix",
]
