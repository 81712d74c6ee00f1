"""The ``skinrs`` command line (also ``python -m skinrs``): weights, batch, reduce, pose, info.

Every command takes ``--help``. Bad files and arguments give one line on stderr and exit code
2 (``--debug`` shows the traceback); Ctrl-C exits with 130. Output files are written to a
temporary file next to the target and renamed into place, so an interrupted or failed run
never leaves a partial file.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import sys
import tempfile
import time

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


# --------------------------------------------------------------------------------------------
# commands


def cmd_weights(args) -> None:
    job = weights_job(args)
    W = job["W"]
    say(args, f"weights: {W.shape[0]} vertices x {W.shape[1]} handles, {job['seconds']:.1f} s")
    say(args, f"wrote {args.output}")


def weights_job(args) -> dict:
    """All of ``skinrs weights`` but the messages (``skinrs batch`` runs it per asset): reads,
    solves, writes ``args.output`` atomically; returns ``mesh``, ``W``, ``C``, ``BE``, ``P``,
    ``seconds`` (the solve), ``gap`` and ``energy`` (None where the method reports none)."""
    out_ext = _ext(args.output)
    if out_ext not in (".glb", ".gltf") + WEIGHT_EXTS:
        raise UsageError(f"{args.output}: unknown output format {out_ext!r}")
    if out_ext in (".glb", ".gltf") and args.influences not in (None, 4, 8):
        raise UsageError(f"{args.output}: glTF stores 4 or 8 influences, not -k {args.influences}")
    mesh = read_any_mesh(args.mesh)
    if args.skeleton is not None:
        C, BE, P = read_skeleton(args.skeleton)
        mesh["asset"] = None  # the new skeleton replaces a glTF's own
    elif mesh["asset"] is not None and len(mesh["asset"]["C"]):
        C, BE, P = mesh["asset"]["C"], mesh["asset"]["BE"], mesh["asset"]["P"]
    else:
        raise UsageError(f"{args.mesh}: no skeleton in the file; give a .tgf or RigNet .txt")
    if mesh["F"] is None and args.method == "bbw":
        raise UsageError(f"{args.mesh}: a point cloud has no faces; use --method field")
    t0 = time.perf_counter()
    info = {"gap": None, "energy": None}
    W = _solve_weights(args, mesh, C, BE, P, info)
    seconds = time.perf_counter() - t0
    _write_weights_output(args, mesh, W, C, BE, P)
    return dict(info, mesh=mesh, W=W, C=C, BE=BE, P=P, seconds=seconds)


def _solve_weights(args, mesh, C, BE, P, info):
    """BBW (on the tet mesh, or meshing a surface's inside) or a geometric field's weights;
    ``info`` gets BBW's final relative ``gap`` and ``energy`` (None for the field)."""
    V, F = mesh["V"], mesh["F"]
    if args.method == "field":
        from .field import GeometricField

        opts = {} if args.steps is None else {"steps": args.steps}
        fld = GeometricField(V, F, C, BE=BE if len(BE) else None, P=P if len(P) else None, **opts)
        prog = Progress(args.quiet, args.steps or 6000, "step", lambda it, v: it)
        try:
            fld.optimize(callback=prog)
        finally:
            prog.close()
        return fld.vertex_weights()
    tol = args.tol if args.tol is not None else 1e-6
    prog = Progress(args.quiet, 100.0, "%", gap_progress(tol))
    try:
        if mesh["T"] is not None:
            from .bbw import bbw_dual

            W, res = bbw_dual(V, mesh["T"], C, BE=BE, P=P, tol=tol, callback=prog,
                              return_info=True)  # fmt: skip
            info.update(gap=res["relative_gap"], energy=res["energy"])
            return W
        from .meshing import skin_weights

        say(args, "meshing the inside with the skeleton (TetGen) ...")
        W, res = skin_weights(V, F, C, BE, P, tol=tol, callback=prog, return_info=True)
        info.update(
            gap=res["relative_gap"], energy=res["energy"], volume_vertices=res["volume_vertices"]
        )
        return W
    finally:
        prog.close()


def _write_weights_output(args, mesh, W, C, BE, P):
    """A skinned glTF asset, or the weights (reduced to -k influences when asked)."""
    V, F = mesh["V"], mesh["F"]
    if _ext(args.output) in (".glb", ".gltf"):
        from .gltf import write_gltf

        if F is None:
            raise UsageError(f"{args.output}: a glTF mesh needs faces; {args.mesh} has none")
        if mesh["T"] is not None:  # a tet mesh: the asset is its boundary surface
            used = np.unique(F)
            V, F, W = V[used], np.searchsorted(used, F), W[used]
        with atomic_output(args.output) as tmp:
            write_gltf(tmp, V, F, W, C, BE, P, k=args.influences or 4,
                       method=args.reduce_method, asset=mesh["asset"])  # fmt: skip
    elif args.influences:
        packed = _reduce_all_rows(args, mesh, W, C, BE, P)
        write_weights(args.output, io_unpack(packed, W.shape[1]), packed)
    else:
        write_weights(args.output, W)


def _reduce_all_rows(args, mesh, W, C, BE, P):
    """``W`` reduced to ``-k`` influences. On a tet mesh the surface rows get the chosen method
    (smooth and Poisson work on the boundary triangles) and the interior rows, which no
    triangle uses, keep their k largest weights."""
    from .reduce import reduce_weights

    V, F = mesh["V"], mesh["F"]
    k = min(args.influences, W.shape[1])
    method = args.reduce_method
    poses = _example_poses(method, C, BE, P)
    if mesh["T"] is None or method not in ("smooth", "poisson"):
        F_used = F if method in ("smooth", "poisson") else None
        return reduce_weights(W, k, method=method, V=V, F=F_used, bone_transforms=poses)
    surface = np.unique(F)
    idx, wts = reduce_weights(W, k, method="k-largest")
    s_idx, s_wts = reduce_weights(W[surface], k, method=method, V=V[surface],
                                  F=np.searchsorted(surface, F), bone_transforms=poses)  # fmt: skip
    idx[surface], wts[surface] = s_idx, s_wts
    return idx, wts


def io_unpack(packed, m):
    from .reduce import unpack_weights

    return unpack_weights(packed[0], packed[1], m)


def _example_poses(method, C, BE, P):
    if method not in ("geometric", "poisson"):
        return None
    if len(P):
        raise UsageError(f"--reduce-method {method} needs a skeleton without point handles")
    from .reduce import random_skeleton_poses

    return random_skeleton_poses(C, BE, 8, seed=0)


def cmd_reduce(args) -> None:
    from .reduce import reduce_weights

    W = read_weights(args.weights)
    V = F = C = BE = None
    if args.mesh is not None:
        m = read_any_mesh(args.mesh)
        V, F = m["V"], m["F"]
    if args.skeleton is not None:
        C, BE, P = read_skeleton(args.skeleton)
    needs = {"smooth": ("--mesh",), "geometric": ("--mesh", "--skeleton"),
             "poisson": ("--mesh", "--skeleton")}.get(args.method, ())  # fmt: skip
    missing = [o for o in needs if (V if o == "--mesh" else C) is None]
    if missing:
        raise UsageError(
            f"--method {args.method} needs {' and '.join(missing)} (or use --method k-largest)"
        )
    poses = _example_poses(args.method, C, BE, P) if C is not None else None
    prog = Progress(args.quiet, None, "sweep", lambda it, v: it)
    try:
        I, A = reduce_weights(W, args.k, method=args.method, V=V, F=F, bone_transforms=poses,
                              callback=prog)  # fmt: skip
    finally:
        prog.close()
    write_weights(args.output, io_unpack((I, A), W.shape[1]), (I, A))
    say(args, f"wrote {args.output}: {args.k} influences per vertex ({args.method})")


def _pose_transforms(args, asset):
    """Per-column transforms (m, 3, 4) for ``skinrs pose``."""
    from .reduce import random_skeleton_poses
    from .skinning import forward_kinematics, quaternions_from_xyzw

    C, BE, m = asset["C"], asset["BE"], asset["W"].shape[1]
    nP = len(asset["P"])
    spec = args.pose
    if spec.startswith(("frame:", "random")):
        kind, _, val = spec.partition(":")
        if kind == "frame":
            if not asset["animations"]:
                raise UsageError(f"{args.asset}: has no animation for --pose {spec}")
            T = asset["animations"][0]["T"]
            i = int(val) if val.lstrip("-").isdigit() else None
            if i is None or not -len(T) <= i < len(T):
                raise UsageError(f"--pose {spec}: the animation has frames 0..{len(T) - 1}")
            return T[i]
        seed = int(val) if val.isdigit() else 0
        bones = random_skeleton_poses(C, BE, 1, seed=seed)[0]
    else:
        Q = read_weights(spec) if _ext(spec) != ".npy" else np.load(spec)
        if Q.ndim == 3:
            bones = Q[nP:] if len(Q) == m else Q
        else:
            Q = quaternions_from_xyzw(Q) if _ext(spec) == ".dmat" else np.asarray(Q, dtype=float)
            bones = forward_kinematics(C, BE, Q)
    if bones.shape != (len(BE), 3, 4):
        raise UsageError(f"--pose {spec}: expected {len(BE)} bones, got shape {bones.shape}")
    ident = np.broadcast_to(np.hstack([np.eye(3), np.zeros((3, 1))]), (nP, 3, 4))
    return np.concatenate([ident, bones])


def cmd_pose(args) -> None:
    from .plot import _plt
    from .skinning import dqs, lbs

    mesh = read_any_mesh(args.asset)
    asset = mesh["asset"]
    if asset is None or not asset["W"].shape[1]:
        raise UsageError(f"{args.asset}: not a skinned glTF asset (.glb/.gltf with a skin)")
    T = _pose_transforms(args, asset)
    U = (dqs if args.dqs else lbs)(asset["V"], asset["W"], T)
    plt = _plt()
    fig = plt.figure(figsize=(6, 6))
    ax = fig.add_subplot(projection="3d")
    ax.plot_trisurf(U[:, 0], U[:, 2], U[:, 1], triangles=asset["F"], color="0.8",
                    edgecolor="none", shade=True)  # fmt: skip
    lo, hi = U.min(0), U.max(0)
    r = (hi - lo).max() / 2
    c = (hi + lo) / 2
    ax.set(xlim=(c[0] - r, c[0] + r), ylim=(c[2] - r, c[2] + r), zlim=(c[1] - r, c[1] + r))
    ax.set_box_aspect((1, 1, 1), zoom=1.4)
    ax.set_axis_off()
    ax.set_title(f"{os.path.basename(args.asset)}: {'DQS' if args.dqs else 'LBS'}, {args.pose}")
    with atomic_output(args.output) as tmp:
        fig.savefig(tmp, dpi=100, format=_ext(args.output).lstrip(".") or "png")
    plt.close(fig)
    say(args, f"wrote {args.output}")


def cmd_batch(args) -> int:
    from . import batch

    opts = {k: getattr(args, k) for k in batch.OPTION_DEFAULTS}
    report = batch.run(args.source, args.outdir, scheduler=args.scheduler, n_workers=args.workers,
                       memory_limit=args.memory_limit, retries=args.retries, timeout=args.timeout,
                       retry_failed=args.retry_failed, progress=not args.quiet, **opts)  # fmt: skip
    print(batch.summary_table(report))
    print(f"report: {os.path.join(args.outdir, 'report.html')}")
    return 1 if report["summary"]["failed"] else 0


def cmd_info(args) -> None:
    mesh = read_any_mesh(args.file)
    V, F, asset = mesh["V"], mesh["F"], mesh["asset"]
    info = {"file": args.file, "vertices": len(V), "faces": 0 if F is None else len(F)}
    if mesh["T"] is not None:
        info["tets"] = len(mesh["T"])
    if F is not None:
        import trimesh

        info["watertight"] = bool(trimesh.Trimesh(V, F, process=False).is_watertight)
    skel = None
    if args.skeleton is not None:
        skel = read_skeleton(args.skeleton)
    elif asset is not None and len(asset["C"]):
        skel = asset["C"], asset["BE"], asset["P"]
        info["animations"] = [
            {"name": a["name"], "frames": len(a["times"])} for a in asset["animations"]
        ]
        info["joint_names"] = asset["joints"]["names"]
    if skel is not None:
        C, BE, P = skel
        info.update(joints=len(C), bones=len(BE), point_handles=len(P))
        if F is not None and info.get("watertight"):
            from .field import winding_number

            inside = winding_number(V, F, C) > 0.5
            info["joints_outside"] = np.flatnonzero(~inside).tolist()
    if args.json:
        print(json.dumps(info))
        return
    for key, val in info.items():
        print(f"{key}: {val}")


# --------------------------------------------------------------------------------------------
# parser


def _add_weight_options(p) -> None:
    """The options of ``skinrs weights`` (``skinrs batch`` takes the same)."""
    p.add_argument("--method", choices=("bbw", "field"), default="bbw",
                   help="bbw: tet-meshed BBW (default); field: mesh-free geometric field "
                   "(soups, open meshes, point clouds)")  # fmt: skip
    p.add_argument("--tol", type=float, default=None, help="relative duality gap (bbw, 1e-6)")
    p.add_argument("--steps", type=int, help="optimisation steps (field, default 6000)")
    p.add_argument("-k", "--influences", type=int, choices=(1, 2, 3, 4, 5, 6, 7, 8),
                   help="influences per vertex (glTF: 4 by default, or 8)")  # fmt: skip
    p.add_argument("--reduce-method", default="poisson",
                   choices=("k-largest", "smooth", "geometric", "poisson"),
                   help="how weights are cut to -k influences (default poisson)")  # fmt: skip


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="skinrs", description=__doc__.split("\n")[0])
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
    b.add_argument("--workers", type=int, help="LocalCluster workers (default: cores)")
    b.add_argument("--memory-limit", default="auto",
                   help="LocalCluster memory per worker, e.g. 4GB (default: RAM / workers)")  # fmt: skip
    b.add_argument("--retries", type=int, default=1,
                   help="retries of an asset after an error or a dead worker (default 1)")  # fmt: skip
    b.add_argument("--timeout", type=float, help="seconds per asset (default: none)")
    b.add_argument("--retry-failed", action="store_true",
                   help="redo assets that failed in an earlier run (default: skip them)")  # fmt: skip
    b.set_defaults(run=cmd_batch)

    r = sub.add_parser("reduce", help="cut weights to k influences per vertex",
                       description="Poisson-based weight reduction (Landreneau & Schaefer 2010).")  # fmt: skip
    r.add_argument("weights", metavar="WEIGHTS", help="weights: .dmat, .npz (array W) or .csv")
    r.add_argument("-k", type=int, required=True, help="influences per vertex")
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


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    try:
        rc = args.run(args)
    except KeyboardInterrupt:
        print("skinrs: interrupted", file=sys.stderr)
        return 130
    except (UsageError, ValueError, OSError, ImportError) as e:
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
