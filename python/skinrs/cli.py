"""The ``skinrs`` command line (also ``python -m skinrs``): weights, batch, reduce, pose, info.

Every command takes ``--help``. Bad files and arguments give one line on stderr and exit code
2 (``--debug`` shows the traceback); Ctrl-C exits with 130. Output files are written to a
temporary file next to the target and renamed into place, so an interrupted or failed run
never leaves a partial file.
"""

from __future__ import annotations

import argparse
import math
import re
import sys
from collections.abc import Callable, Sequence
from typing import NoReturn

from ._cli_commands import (  # noqa: F401 - re-exported
    WEIGHT_EXTS,
    Progress,
    UsageError,
    _example_poses,
    _ext,
    _pose_transforms,
    _reduce_all_rows,
    _solve_weights,
    _write_weights_output,
    atomic_output,
    cmd_batch,
    cmd_info,
    cmd_pose,
    cmd_reduce,
    cmd_weights,
    gap_progress,
    io_unpack,
    read_any_mesh,
    read_skeleton,
    read_weights,
    say,
    weights_job,
    write_weights,
)
from ._cli_io import MESH_EXTS, output_directory

# --------------------------------------------------------------------------------------------
# parser


class _Parser(argparse.ArgumentParser):
    """Usage errors in one line like every other error (the usage itself is in ``--help``)."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def _count(zero: bool = False) -> Callable[[str], int]:
    """An argparse type: a positive integer (or non-negative, with ``zero``)."""
    return lambda s: int(
        _number(s, int, zero, "non-negative integer" if zero else "positive integer")
    )


def _positive(s: str) -> float:
    """An argparse type: a positive finite number."""
    return _number(s, float, False, "positive finite number")


def _number(s: str, cast: Callable[[str], float], zero: bool, what: str) -> float:
    try:
        x = cast(s)
    except ValueError:
        x = math.nan
    if not (math.isfinite(x) and (x > 0 or (zero and x == 0))):
        raise argparse.ArgumentTypeError(f"must be a {what}, got {s!r}")
    return x


_SIZE_UNITS = {"": 1, "B": 1, "KB": 10**3, "MB": 10**6, "GB": 10**9, "TB": 10**12,
               "KIB": 2**10, "MIB": 2**20, "GIB": 2**30, "TIB": 2**40}  # fmt: skip


def _size(s: str) -> float:
    """An argparse type: a positive number of bytes, with an optional unit (4GB, 512MiB)."""
    m = re.fullmatch(r"\s*([0-9.eE+]+)\s*([A-Za-z]*)\s*", s)
    if m is None or m.group(2).upper() not in _SIZE_UNITS:
        raise argparse.ArgumentTypeError(f"must be a size such as 4GB or 512MiB, got {s!r}")
    return _number(m.group(1), float, False, "positive size") * _SIZE_UNITS[m.group(2).upper()]


def _add_weight_options(p: argparse.ArgumentParser) -> None:
    """The options of ``skinrs weights`` (``skinrs batch`` takes the same)."""
    p.add_argument("--method", choices=("bbw", "field"), default="bbw",
                   help="bbw: tet-meshed BBW (default); field: mesh-free geometric field "
                   "(soups, open meshes, point clouds)")  # fmt: skip
    p.add_argument("--tol", type=_positive, default=None, help="relative duality gap (bbw, 1e-6)")
    p.add_argument("--steps", type=_count(), help="optimisation steps (field, default 6000)")
    p.add_argument("-k", "--influences", type=int, choices=(1, 2, 3, 4, 5, 6, 7, 8),
                   help="influences per vertex (glTF: 4 by default, or 8)")  # fmt: skip
    p.add_argument("--reduce-method", default="poisson",
                   choices=("k-largest", "smooth", "geometric", "poisson"),
                   help="how weights are cut to -k influences (default poisson)")  # fmt: skip


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(prog="skinrs", description=__doc__.split("\n")[0])
    p.add_argument("--debug", action="store_true", help="show tracebacks of errors")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bars or messages")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")

    w = sub.add_parser("weights", help="compute skinning weights of a mesh and a skeleton",
                       description="Bounded biharmonic weights of MESH for SKELETON.")  # fmt: skip
    w.add_argument("mesh", metavar="MESH", help=f"mesh file ({', '.join(MESH_EXTS)})")
    w.add_argument("skeleton", metavar="SKELETON", nargs="?",
                   help=".tgf or RigNet .txt; omit for a glTF with a skin")  # fmt: skip
    w.add_argument("-o", "--output", required=True, metavar="OUT",
                   help="output: .glb/.gltf (skinned asset), .dmat, .npz or .csv")  # fmt: skip
    _add_weight_options(w)
    w.add_argument("--memory-limit", type=_size, default=None, metavar="SIZE",
                   help="memory of the BBW solve, e.g. 4GB (default: half the RAM; beyond it "
                   "the solve finishes with L-BFGS, or fails before factoring)")  # fmt: skip
    w.set_defaults(run=cmd_weights)

    b = sub.add_parser("batch", help="weights of many assets on Dask (local or a cluster)",
                       description="One `skinrs weights` job per asset on Dask distributed; "
                       "results, records and report.json/report.html in OUTDIR. A rerun skips "
                       "assets whose record matches (docs/batch.md).")  # fmt: skip
    b.add_argument("source", metavar="MANIFEST_OR_DIR",
                   help="directory (mesh + skeleton of one stem, or skinned .glb) or a .csv / "
                   ".jsonl manifest (mesh, skeleton, name, per-asset options)")  # fmt: skip
    b.add_argument("-o", "--outdir", required=True, help="directory for results and reports")
    b.add_argument("--format", default="glb", choices=("glb", "gltf", "dmat", "npz", "csv"),
                   help="output of each asset (default glb)")  # fmt: skip
    _add_weight_options(b)
    b.add_argument("--scheduler", help="tcp://host:port of a Dask scheduler (default: a "
                   "LocalCluster, one single-threaded worker process per core)")  # fmt: skip
    b.add_argument("--workers", type=_count(), help="LocalCluster workers (default: cores)")
    b.add_argument("--memory-limit", default="auto",
                   help="LocalCluster memory per worker, e.g. 4GB (default: RAM / workers)")  # fmt: skip
    b.add_argument("--retries", type=_count(zero=True), default=1,
                   help="retries of an asset after an error or a dead worker (default 1)")  # fmt: skip
    b.add_argument("--timeout", type=_positive, help="seconds per asset (default: none)")
    b.add_argument("--retry-failed", action="store_true",
                   help="redo assets that failed in an earlier run (default: skip them)")  # fmt: skip
    b.set_defaults(run=cmd_batch)

    r = sub.add_parser("reduce", help="cut weights to k influences per vertex",
                       description="Poisson-based weight reduction (Landreneau & Schaefer 2010).")  # fmt: skip
    r.add_argument("weights", metavar="WEIGHTS", help="weights: .dmat, .npz (array W) or .csv")
    r.add_argument("-k", type=_count(), required=True, help="influences per vertex")
    r.add_argument("--method", default="poisson",
                   choices=("k-largest", "smooth", "geometric", "poisson"),
                   help="default poisson (needs --mesh and --skeleton)")  # fmt: skip
    r.add_argument("--mesh", help="the mesh the weights belong to")
    r.add_argument("--skeleton", help=".tgf or RigNet .txt (example poses)")
    r.add_argument("-o", "--output", required=True, help=".dmat, .npz or .csv")
    r.set_defaults(run=cmd_reduce)

    q = sub.add_parser("pose", help="picture of a posed skinned asset",
                       description="Pose a glTF asset and save a picture (matplotlib).")  # fmt: skip
    q.add_argument("asset", metavar="ASSET", help=".glb or .gltf with a skin")
    q.add_argument("--pose", default="random:0",
                   help="random[:SEED] (default), frame:N (its animation), a libigl .dmat of "
                   "(x, y, z, w) quaternions per bone, or a .npy of (m, 4) (w, x, y, z) "
                   "quaternions or (m, 3, 4) transforms")  # fmt: skip
    q.add_argument("--dqs", action="store_true", help="dual-quaternion skinning (default LBS)")
    q.add_argument("-o", "--output", required=True, help="picture (.png, .pdf, .svg)")
    q.set_defaults(run=cmd_pose)

    i = sub.add_parser("info", help="counts, watertightness and skeleton of a file",
                       description="What a mesh or asset holds.")  # fmt: skip
    i.add_argument("file", metavar="FILE", help=f"mesh file ({', '.join(MESH_EXTS)})")
    i.add_argument("skeleton", nargs="?", help=".tgf or RigNet .txt to check against FILE")
    i.add_argument("--json", action="store_true", help="one JSON object instead of lines")
    i.set_defaults(run=cmd_info)
    return p


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        if getattr(args, "output", None) is not None:  # before the work, not after it
            output_directory(args.output)
        rc: int | None = args.run(args)
    except KeyboardInterrupt:
        print("skinrs: interrupted", file=sys.stderr)
        return 130
    except (UsageError, ValueError, OSError, ImportError, MemoryError) as e:
        if args.debug:
            raise
        print(f"skinrs {args.command}: error: {e}", file=sys.stderr)
        return 2
    except Exception as e:  # a bug: one line here, the traceback with --debug
        if args.debug:
            raise
        print(f"skinrs {args.command}: internal error: {type(e).__name__}: {e} (rerun with "
              "--debug for the traceback)", file=sys.stderr)  # fmt: skip
        return 1
    return rc or 0
