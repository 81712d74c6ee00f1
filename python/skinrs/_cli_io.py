"""Files and progress of the ``skinrs`` command line: reading meshes, skeletons and weights,
writing outputs atomically, progress reports.
"""

from __future__ import annotations

import contextlib
import math
import os
import sys
import tempfile

import numpy as np

MESH_EXTS = (".obj", ".off", ".ply", ".stl", ".mesh", ".gltf", ".glb")
WEIGHT_EXTS = (".dmat", ".npz", ".csv")


class UsageError(Exception):
    """A bad argument or file, reported in one line with exit code 2."""


def _ext(path) -> str:
    return os.path.splitext(str(path))[1].lower()


# --------------------------------------------------------------------------------------------
# files


def read_any_mesh(path):
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
            # STL stores every triangle on its own: merge its corners, keep other files' rows
            geom = trimesh.load(path, process=ext == ".stl")
        except (ValueError, KeyError, IndexError, TypeError) as e:
            raise UsageError(f"{path}: cannot read ({e})") from None
        V = np.asarray(geom.vertices, dtype=np.float64)
        F = np.asarray(getattr(geom, "faces", np.zeros((0, 3))), dtype=np.int64)
        if len(V) == 0:
            raise UsageError(f"{path}: no vertices")
        return {"V": V, "F": F if len(F) else None, "T": None, "asset": None}
    raise UsageError(f"{path}: unknown mesh format {ext!r}; expected one of {', '.join(MESH_EXTS)}")


def read_skeleton(path):
    """``(C, BE, P)`` from a libigl ``.tgf`` or a RigNet ``.txt`` rig."""
    from . import io

    if not os.path.isfile(path):
        raise UsageError(f"{path}: no such file")
    ext = _ext(path)
    if ext == ".tgf":
        return io.read_tgf(path, return_point_handles=True)
    if ext == ".txt":
        r = io.read_rignet_rig(path)
        return r["C"], r["BE"], np.zeros(0, dtype=np.int64)
    raise UsageError(f"{path}: unknown skeleton format {ext!r}; expected .tgf or RigNet .txt")


def read_weights(path) -> np.ndarray:
    from . import io

    if not os.path.isfile(path):
        raise UsageError(f"{path}: no such file")
    ext = _ext(path)
    if ext == ".dmat":
        return io.read_dmat(path)
    if ext == ".csv":
        return np.loadtxt(path, delimiter=",", ndmin=2)
    if ext == ".npz":
        with np.load(path) as z:
            if "W" not in z:
                raise UsageError(f"{path}: no array 'W' in the archive")
            return z["W"]
    raise UsageError(f"{path}: unknown weights format {ext!r}; expected {', '.join(WEIGHT_EXTS)}")


@contextlib.contextmanager
def atomic_output(path):
    """A temporary path next to ``path`` (same extension) that replaces it on success."""
    d = os.path.dirname(os.path.abspath(path)) or "."
    if not os.path.isdir(d):
        raise UsageError(f"{path}: directory {d} does not exist")
    fd, tmp = tempfile.mkstemp(prefix=".skinrs-", suffix=_ext(path), dir=d)
    os.close(fd)
    try:
        yield tmp
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)


def write_weights(path, W, packed=None) -> None:
    """Dense ``W`` as ``.dmat``, ``.csv`` or ``.npz`` (with the packed pair, when given)."""
    from . import io

    ext = _ext(path)
    with atomic_output(path) as tmp:
        if ext == ".dmat":
            io.write_dmat(tmp, W)
        elif ext == ".csv":
            np.savetxt(tmp, W, delimiter=",", fmt="%.17g")
        elif ext == ".npz":
            extra = {} if packed is None else {"indices": packed[0], "weights": packed[1]}
            with open(tmp, "wb") as fh:
                np.savez_compressed(fh, W=W, **extra)
        else:
            raise UsageError(f"{path}: unknown output format {ext!r}")


# --------------------------------------------------------------------------------------------
# progress


class Progress:
    """A tqdm bar fed by skinrs' ``callback(stage, iteration, value)`` (stderr lines without
    tqdm, nothing with ``--quiet``)."""

    def __init__(self, quiet: bool, total: float, unit: str, measure):
        self.quiet, self.measure, self.bar = quiet, measure, None
        if quiet:
            return
        try:
            from tqdm import tqdm
        except ImportError:
            self.bar = False
            return
        fmt = "{desc}: {percentage:3.0f}%|{bar}| {elapsed}" if unit == "%" else None
        self.bar = tqdm(total=total, unit=unit, file=sys.stderr, leave=False, bar_format=fmt)

    def __call__(self, stage, iteration, value):
        if self.quiet:
            return
        if stage.endswith(" cg"):  # inner conjugate gradients: a residual, not progress
            return
        done = self.measure(iteration, value)
        if self.bar is False:
            print(f"  {stage} {iteration}: {value:.3g}", file=sys.stderr)
        else:
            self.bar.set_description(stage)
            self.bar.update(max(0.0, done - self.bar.n))
        return

    def close(self):
        if self.bar is not None and self.bar is not False:
            self.bar.close()


def gap_progress(tol):
    """Percent of the way from a relative gap of 1 down to ``tol`` (log scale)."""
    top = -math.log10(tol)
    return lambda it, gap: 100.0 * min(1.0, max(0.0, -math.log10(max(gap, 1e-300)) / top))


def say(args, msg: str) -> None:
    if not args.quiet:
        print(msg, file=sys.stderr)
