"""Files and progress of the ``skinrs`` command line: reading meshes, skeletons and weights,
writing outputs atomically, progress reports.
"""

from __future__ import annotations

import argparse
import contextlib
import math
import os
import sys
import tempfile
from collections.abc import Callable, Iterator
from typing import TYPE_CHECKING, Literal, TypedDict, cast

import numpy as np
from numpy.typing import NDArray

if TYPE_CHECKING:
    from tqdm import tqdm

    from .gltf_read import GltfAsset

MESH_EXTS = (".obj", ".off", ".ply", ".stl", ".mesh", ".gltf", ".glb")
WEIGHT_EXTS = (".dmat", ".npz", ".csv")


class UsageError(Exception):
    """A bad argument or file, reported in one line with exit code 2."""


class MeshFile(TypedDict):
    """What :func:`read_any_mesh` read: ``V``, the surface ``F`` and the tets ``T`` (None when
    the file has none) and, for glTF, the whole asset."""

    V: NDArray[np.float64]
    F: NDArray[np.int64] | None
    T: NDArray[np.int64] | None
    asset: GltfAsset | None


#: The skinrs skeleton ``(C, BE, P)``.
Skeleton = tuple[NDArray[np.float64], NDArray[np.int64], NDArray[np.int64]]


def _ext(path: str | os.PathLike[str]) -> str:
    return os.path.splitext(str(path))[1].lower()


# --------------------------------------------------------------------------------------------
# files


def read_any_mesh(path: str) -> MeshFile:
    """``dict(V, F, T, asset)`` from a surface, ``.mesh`` or glTF file (F None: point cloud)."""
    from . import io

    ext = _ext(path)
    if not os.path.isfile(path):
        raise UsageError(f"{path}: no such file")
    if ext in (".gltf", ".glb"):
        from .gltf import read_gltf

        a = read_gltf(path)
        return {"V": a["V"], "F": a["F"], "T": None, "asset": a}
    if ext == ".mesh":
        V, T, F = io.read_mesh(path)
        return {"V": V, "F": F if len(F) else None, "T": T if len(T) else None, "asset": None}
    if ext == ".obj":
        V, F = io.read_obj(path)
        return {"V": V, "F": F if len(F) else None, "T": None, "asset": None}
    if ext in (".off", ".ply", ".stl"):
        import trimesh

        try:
            # STL stores every triangle on its own: merge its corners, keep other files' rows;
            # these formats load as a Trimesh, or a PointCloud without faces (load() is typed
            # as returning their base class)
            loaded = trimesh.load(path, process=ext == ".stl")
            geom = cast("trimesh.Trimesh | trimesh.PointCloud", loaded)
        except (ValueError, KeyError, IndexError, TypeError) as e:
            raise UsageError(f"{path}: cannot read ({e})") from None
        V = np.asarray(geom.vertices, dtype=np.float64)
        F = np.asarray(getattr(geom, "faces", np.zeros((0, 3))), dtype=np.int64)
        if len(V) == 0:
            raise UsageError(f"{path}: no vertices")
        return {"V": V, "F": F if len(F) else None, "T": None, "asset": None}
    raise UsageError(f"{path}: unknown mesh format {ext!r}; expected one of {', '.join(MESH_EXTS)}")


def read_skeleton(path: str) -> Skeleton:
    """``(C, BE, P)`` from a libigl ``.tgf`` or a RigNet ``.txt`` rig."""
    from . import io

    if not os.path.isfile(path):
        raise UsageError(f"{path}: no such file")
    ext = _ext(path)
    if ext == ".tgf":
        skeleton: Skeleton = io.read_tgf(path, return_point_handles=True)
        return skeleton
    if ext == ".txt":
        r = io.read_rignet_rig(path)
        return r["C"], r["BE"], np.zeros(0, dtype=np.int64)
    raise UsageError(f"{path}: unknown skeleton format {ext!r}; expected .tgf or RigNet .txt")


def read_weights(path: str) -> NDArray[np.float64]:
    from . import io

    if not os.path.isfile(path):
        raise UsageError(f"{path}: no such file")
    ext = _ext(path)
    if ext == ".dmat":
        return io.read_dmat(path)
    if ext == ".csv":
        try:
            return np.loadtxt(path, delimiter=",", ndmin=2)
        except ValueError as e:  # numpy's message names neither the file nor the format
            raise UsageError(f"{path}: not comma-separated numbers ({e})") from None
    if ext == ".npz":
        with np.load(path) as z:
            if "W" not in z:
                raise UsageError(f"{path}: no array 'W' in the archive")
            W: NDArray[np.float64] = z["W"]
            return W
    raise UsageError(f"{path}: unknown weights format {ext!r}; expected {', '.join(WEIGHT_EXTS)}")


def output_directory(path: str) -> str:
    """The directory ``path`` would be written to; UsageError when it does not exist (checked
    before a command starts its work, and again when it writes)."""
    d = os.path.dirname(os.path.abspath(path)) or "."
    if not os.path.isdir(d):
        raise UsageError(f"{path}: directory {d} does not exist")
    return d


@contextlib.contextmanager
def atomic_output(path: str) -> Iterator[str]:
    """A temporary path next to ``path`` (same extension) that replaces it on success."""
    d = output_directory(path)
    fd, tmp = tempfile.mkstemp(prefix=".skinrs-", suffix=_ext(path), dir=d)
    os.close(fd)
    try:
        yield tmp
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)


def write_weights(
    path: str,
    W: NDArray[np.float64],
    packed: tuple[NDArray[np.int64], NDArray[np.float64]] | None = None,
) -> None:
    """Dense ``W`` as ``.dmat``, ``.csv`` or ``.npz`` (with the packed pair, when given)."""
    from . import io

    ext = _ext(path)
    with atomic_output(path) as tmp:
        if ext == ".dmat":
            io.write_dmat(tmp, W)
        elif ext == ".csv":
            np.savetxt(tmp, W, delimiter=",", fmt="%.17g")
        elif ext == ".npz":
            with open(tmp, "wb") as fh:
                if packed is None:
                    np.savez_compressed(fh, W=W)
                else:
                    np.savez_compressed(fh, W=W, indices=packed[0], weights=packed[1])
        else:
            raise UsageError(f"{path}: unknown output format {ext!r}")


# --------------------------------------------------------------------------------------------
# progress


class Progress:
    """A tqdm bar fed by skinrs' ``callback(stage, iteration, value)`` (stderr lines without
    tqdm, nothing with ``--quiet``)."""

    def __init__(
        self, quiet: bool, total: float | None, unit: str, measure: Callable[[int, float], float]
    ) -> None:
        self.quiet, self.measure = quiet, measure
        self.bar: tqdm | Literal[False] | None = None
        if quiet:
            return
        try:
            from tqdm import tqdm
        except ImportError:
            self.bar = False
            return
        # tqdm's {desc} already ends in ": " once a description is set.
        fmt = "{desc}{percentage:3.0f}%|{bar}| {elapsed}" if unit == "%" else None
        self.bar = tqdm(total=total, unit=unit, file=sys.stderr, leave=False, bar_format=fmt)

    def __call__(self, stage: str, iteration: int, value: float) -> None:
        if self.quiet:
            return
        if stage.endswith(" cg"):  # inner conjugate gradients: a residual, not progress
            return
        done = self.measure(iteration, value)
        if self.bar is False:
            print(f"  {stage} {iteration}: {value:.3g}", file=sys.stderr)
        elif self.bar is not None:  # (None only when quiet)
            self.bar.set_description(stage)
            self.bar.update(max(0.0, done - self.bar.n))
        return

    def close(self) -> None:
        if self.bar is not None and self.bar is not False:
            self.bar.close()


def gap_progress(tol: float) -> Callable[[int, float], float]:
    """Percent of the way from a relative gap of 1 down to ``tol`` (log scale)."""
    top = -math.log10(tol)
    return lambda it, gap: 100.0 * min(1.0, max(0.0, -math.log10(max(gap, 1e-300)) / top))


def say(args: argparse.Namespace, msg: str) -> None:
    if not args.quiet:
        print(msg, file=sys.stderr)
