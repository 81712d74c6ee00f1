"""Readers and writers for the file formats skinning data comes in.

Pure Python + numpy. Every reader takes a ``str`` or ``pathlib.Path`` and returns numpy arrays
with libigl names and conventions: float64 coordinates, int64 **0-based** indices, 2D arrays
even when there is a single column or no row at all.

Formats: libigl ``.tgf`` skeletons, libigl ``.dmat`` matrices (ASCII and binary), MEDIT ``.mesh``
tet meshes, Wavefront ``.obj`` surfaces, poly2tri ``.dat`` outlines and RigNet ``*_rig.txt`` rigs.

A malformed file raises ``ValueError("<path>: line <n>: <what was expected>")``; a missing file
raises the usual ``FileNotFoundError``. Nothing is silently dropped: an index out of range, a
count that does not match the data, or an unknown keyword is an error.

>>> import skinrs.io as sio                                   # doctest: +SKIP
>>> V, T, F = sio.read_mesh("hand.mesh")                       # doctest: +SKIP
>>> C, BE = sio.read_tgf("hand.tgf")                           # doctest: +SKIP
>>> V.shape, T.shape, F.shape, C.shape, BE.shape               # doctest: +SKIP
((7234, 3), (29998, 4), (9556, 3), (21, 3), (20, 2))
"""

from ..gltf import read_gltf, write_gltf
from .dmat import read_dmat, write_dmat
from .medit import read_mesh, write_mesh
from .obj import read_obj, write_obj
from .polygon import read_polygon_dat
from .rignet import read_rignet_rig
from .tgf import read_tgf, write_tgf

__all__ = [
    "read_dmat",
    "read_gltf",
    "read_mesh",
    "read_obj",
    "read_polygon_dat",
    "read_rignet_rig",
    "read_tgf",
    "write_dmat",
    "write_gltf",
    "write_mesh",
    "write_obj",
    "write_tgf",
]
