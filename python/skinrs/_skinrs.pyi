# Types of the compiled module (src/py/). Arguments arrive checked and converted by the Python
# layer: float64 and int64, C-contiguous.
from collections.abc import Callable
from typing import Any, TypeAlias

import numpy as np
from numpy.typing import NDArray

F64: TypeAlias = NDArray[np.float64]
I64: TypeAlias = NDArray[np.int64]
_Callback: TypeAlias = Callable[[str, int, float], Any] | None

__version__: str

MASS_KINDS: tuple[str, ...]
BBW_SOLVERS: tuple[str, ...]
BBW_DEFAULTS: dict[str, Any]
BOUNDARY_TOL: float
REDUCE_METHODS: tuple[str, ...]
REDUCE_ENERGIES: tuple[str, ...]
REDUCE_SOLVERS: tuple[str, ...]
REDUCE_DEFAULTS: dict[str, Any]

# operators
def _cotan_laplacian(v: F64, f: I64) -> tuple[F64, I64, I64, tuple[int, int]]: ...
def _massmatrix(v: F64, f: I64, kind: str) -> F64: ...
def _biharmonic_matrix(v: F64, f: I64, kind: str) -> tuple[F64, I64, I64, tuple[int, int]]: ...
def _connected_components(n: int, f: I64) -> tuple[int, I64]: ...

# constraints and BBW
def _boundary_conditions(v: F64, c: F64, p: I64, be: I64, tol: float) -> tuple[I64, F64]: ...
def _bbw_dual(
    l_data: F64,
    l_indices: I64,
    l_indptr: I64,
    masses: F64,
    b: I64,
    bc: F64,
    *,
    solver: str,
    tol: float,
    max_iter: int,
    partition_of_unity: bool,
    seed: int,
    lbfgs_memory: int,
    memory_limit: int,
    callback: _Callback,
) -> tuple[F64, dict[str, Any]]: ...

# skinning
def lbs(
    V: F64,
    W: F64,
    T: F64,
    index: I64 | None = None,
    N: F64 | None = None,
    out: F64 | None = None,
) -> tuple[F64, F64 | None]: ...
def dqs(
    V: F64,
    W: F64,
    T: F64,
    index: I64 | None = None,
    N: F64 | None = None,
    out: F64 | None = None,
) -> tuple[F64, F64 | None]: ...
def forward_kinematics(C: F64, BE: I64, Q: F64) -> F64: ...
def bone_parents(BE: I64, n_joints: int) -> I64: ...
def per_vertex_normals(V: F64, F: I64) -> F64: ...

# weight reduction
def reduce_weights(
    w: F64,
    k: int,
    method: str,
    *,
    v: F64 | None,
    f: I64 | None,
    control_points: F64 | None,
    bone_transforms: F64 | None,
    c: F64 | None,
    nonnegative: bool,
    max_sweeps: int,
    tol: float,
    relaxation: float,
    energy: str,
    solver: str,
    callback: _Callback,
) -> tuple[I64, F64, list[float], bool, int, int]: ...
def reduce_deform(
    v: F64,
    weights: F64,
    indices: I64 | None = None,
    control_points: F64 | None = None,
    bone_transforms: F64 | None = None,
) -> F64: ...
def reduce_transform_normals(
    normals: F64,
    indices: I64,
    weights: F64,
    control_points: F64 | None = None,
    bone_transforms: F64 | None = None,
    c: F64 | None = None,
) -> F64: ...
def reduce_deformation_errors(
    f: I64, full: F64, approx: F64
) -> tuple[F64, list[float], list[float]]: ...
def _reduce_local_qp(
    h: F64, g: F64, e_mat: F64, e_rhs: F64, nonneg: bool, x0: F64
) -> tuple[F64, F64, F64, int, bool]: ...

# geometric fields
def _winding_number(v: F64, f: I64, q: F64, beta: float) -> F64: ...
def _segment_hits(v: F64, f: I64, p: F64, q: F64) -> NDArray[np.bool_]: ...
def _closest_point(v: F64, f: I64, q: F64) -> tuple[F64, F64, I64, F64]: ...
def _knn_distance(x: F64, k: int) -> F64: ...
def _field_defaults(d: int) -> dict[str, Any]: ...

class InternalError(RuntimeError): ...

def _panic_for_tests(message: str) -> None: ...

class _GeometricField:
    def __init__(
        self,
        v: F64,
        f: I64 | None,
        simplices: I64 | None,
        c: F64,
        p: I64,
        be: I64,
        opts: dict[str, Any],
    ) -> None: ...
    def optimize(self, steps: int | None, resume: int, callback: _Callback = None) -> None: ...
    def paint(self, q: F64, w: F64) -> None: ...
    def evaluate(self, q: F64) -> tuple[F64, NDArray[np.uint8]]: ...
    def vertex_weights(
        self, v: F64, normal_elems: I64, adj: I64
    ) -> tuple[F64, NDArray[np.uint8]]: ...
    def energy(self, f: F64, step: int) -> tuple[float, F64]: ...
    def params(self) -> F64: ...
    def points(self) -> F64: ...
    def info(self) -> dict[str, Any]: ...
