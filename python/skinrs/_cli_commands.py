"""The commands of the ``skinrs`` command line: weights, reduce, pose, batch, info."""

from __future__ import annotations

import argparse
import json
import os
import time
from typing import TYPE_CHECKING, TypedDict

import numpy as np
from numpy.typing import NDArray

from ._cli_io import (
    WEIGHT_EXTS,
    MeshFile,
    Progress,
    Skeleton,
    UsageError,
    _ext,
    atomic_output,
    gap_progress,
    read_any_mesh,
    read_skeleton,
    read_weights,
    say,
    write_weights,
)

if TYPE_CHECKING:
    from typing_extensions import NotRequired

    from ._reduce_poses import Packed
    from .gltf_read import GltfAsset

# coordinates and weights; indices
Floats = NDArray[np.float64]
Ints = NDArray[np.int64]

# The commands, and the file and progress helpers of _cli_io that skinrs.cli re-exports.
__all__ = [
    "WEIGHT_EXTS",
    "Progress",
    "UsageError",
    "_example_poses",
    "_ext",
    "_pose_transforms",
    "_reduce_all_rows",
    "_solve_weights",
    "_write_weights_output",
    "atomic_output",
    "cmd_batch",
    "cmd_info",
    "cmd_pose",
    "cmd_reduce",
    "cmd_weights",
    "gap_progress",
    "io_unpack",
    "read_any_mesh",
    "read_skeleton",
    "read_weights",
    "say",
    "weights_job",
    "write_weights",
]


class SolveInfo(TypedDict):
    """BBW's final relative ``gap`` and ``energy`` (None for a field), and the number of
    ``volume_vertices`` when the inside of a surface was meshed."""

    gap: float | None
    energy: float | None
    volume_vertices: NotRequired[int]


class WeightsJob(SolveInfo):
    """What :func:`weights_job` did: the ``mesh`` it read, the weights ``W``, the skeleton and
    the ``seconds`` of the solve."""

    mesh: MeshFile
    W: Floats
    C: Floats
    BE: Ints
    P: Ints
    seconds: float


# --------------------------------------------------------------------------------------------
# commands


def cmd_weights(args: argparse.Namespace) -> None:
    job = weights_job(args)
    W = job["W"]
    say(args, f"weights: {W.shape[0]} vertices x {W.shape[1]} handles, {job['seconds']:.1f} s")
    say(args, f"wrote {args.output}")


def weights_job(args: argparse.Namespace) -> WeightsJob:
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
    info: SolveInfo = {"gap": None, "energy": None}
    W = _solve_weights(args, mesh, C, BE, P, info)
    seconds = time.perf_counter() - t0
    _write_weights_output(args, mesh, W, C, BE, P)
    return {**info, "mesh": mesh, "W": W, "C": C, "BE": BE, "P": P, "seconds": seconds}


def _solve_weights(
    args: argparse.Namespace, mesh: MeshFile, C: Floats, BE: Ints, P: Ints, info: SolveInfo
) -> Floats:
    """BBW (on the tet mesh, or meshing a surface's inside) or a geometric field's weights;
    ``info`` gets BBW's final relative ``gap`` and ``energy`` (None for the field)."""
    V, F = mesh["V"], mesh["F"]
    if args.method == "field":
        from .field import GeometricField

        fld = GeometricField(
            V, F, C, BE=BE if len(BE) else None, P=P if len(P) else None, steps=args.steps
        )
        prog = Progress(args.quiet, args.steps or 6000, "step", lambda it, v: it)
        try:
            fld.optimize(callback=prog)
        finally:
            prog.close()
        return fld.vertex_weights()
    W: Floats
    tol = args.tol if args.tol is not None else 1e-6
    # Bytes of the solve (``skinrs weights --memory-limit``, or what a batch worker has left).
    memory_limit = getattr(args, "memory_limit", None)
    prog = Progress(args.quiet, 100.0, "%", gap_progress(tol))
    try:
        if mesh["T"] is not None:
            from .bbw import bbw_dual

            W, res = bbw_dual(V, mesh["T"], C, BE=BE, P=P, tol=tol, memory_limit=memory_limit,
                              callback=prog, return_info=True)  # fmt: skip
            info["gap"], info["energy"] = res["relative_gap"], res["energy"]
            return W
        from .io._weld import weld
        from .meshing import skin_weights

        # Exporters split vertices at UV seams and sharp edges; the inside is meshed with one
        # vertex per point, and every vertex of the file gets its point's weights back.
        assert F is not None  # weights_job sends a point cloud to --method field only
        Vw, Fw, vertex_map = weld(V, F)
        if len(Vw) < len(V):
            say(args, f"merged {len(V) - len(Vw)} vertices that repeat a position (and left "
                      f"out {len(F) - len(Fw)} faces that collapsed)")  # fmt: skip
        say(args, "meshing the inside with the skeleton (TetGen) ...")
        W, res = skin_weights(Vw, Fw, C, BE, P, tol=tol, memory_limit=memory_limit,
                              callback=prog, return_info=True)  # fmt: skip
        info["gap"], info["energy"] = res["relative_gap"], res["energy"]
        info["volume_vertices"] = res["volume_vertices"]
        return W[vertex_map]
    finally:
        prog.close()


def _write_weights_output(
    args: argparse.Namespace, mesh: MeshFile, W: Floats, C: Floats, BE: Ints, P: Ints
) -> None:
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


def _reduce_all_rows(
    args: argparse.Namespace, mesh: MeshFile, W: Floats, C: Floats, BE: Ints, P: Ints
) -> Packed:
    """``W`` reduced to ``-k`` influences. On a tet mesh the surface rows get the chosen method
    (smooth and Poisson work on the boundary triangles) and the interior rows, which no
    triangle uses, keep their k largest weights."""
    from .reduce import reduce_weights

    V, F = mesh["V"], mesh["F"]
    k = min(args.influences, W.shape[1])
    method = args.reduce_method
    poses = _example_poses(method, C, BE, P)
    if mesh["T"] is None or F is None or method not in ("smooth", "poisson"):
        F_used = F if method in ("smooth", "poisson") else None
        return reduce_weights(W, k, method=method, V=V, F=F_used, bone_transforms=poses)
    surface = np.unique(F)
    idx, wts = reduce_weights(W, k, method="k-largest")
    s_idx, s_wts = reduce_weights(W[surface], k, method=method, V=V[surface],
                                  F=np.searchsorted(surface, F), bone_transforms=poses)  # fmt: skip
    idx[surface], wts[surface] = s_idx, s_wts
    return idx, wts


def io_unpack(packed: Packed, m: int) -> Floats:
    from .reduce import unpack_weights

    W: Floats = unpack_weights(packed[0], packed[1], m)  # dense: sparse=False
    return W


def _example_poses(method: str, C: Floats, BE: Ints, P: Ints) -> Floats | None:
    if method not in ("geometric", "poisson"):
        return None
    if len(P):
        raise UsageError(f"--reduce-method {method} needs a skeleton without point handles")
    from .reduce import random_skeleton_poses

    return random_skeleton_poses(C, BE, 8, seed=0)


def cmd_reduce(args: argparse.Namespace) -> None:
    from .reduce import reduce_weights

    W = read_weights(args.weights)
    if W.ndim == 2 and args.k > W.shape[1]:
        raise UsageError(f"-k {args.k}: {args.weights} has only {W.shape[1]} handles (columns)")
    V: Floats | None = None
    F: Ints | None = None
    skeleton: Skeleton | None = None
    if args.mesh is not None:
        m = read_any_mesh(args.mesh)
        V, F = m["V"], m["F"]
    if args.skeleton is not None:
        skeleton = read_skeleton(args.skeleton)
    needs = {"smooth": ("--mesh",), "geometric": ("--mesh", "--skeleton"),
             "poisson": ("--mesh", "--skeleton")}.get(args.method, ())  # fmt: skip
    missing = [o for o in needs if (V if o == "--mesh" else skeleton) is None]
    if missing:
        raise UsageError(
            f"--method {args.method} needs {' and '.join(missing)} (or use --method k-largest)"
        )
    poses = _example_poses(args.method, *skeleton) if skeleton is not None else None
    prog = Progress(args.quiet, None, "sweep", lambda it, v: it)
    try:
        I, A = reduce_weights(W, args.k, method=args.method, V=V, F=F, bone_transforms=poses,
                              callback=prog)  # fmt: skip
    finally:
        prog.close()
    write_weights(args.output, io_unpack((I, A), W.shape[1]), (I, A))
    say(args, f"wrote {args.output}: {args.k} influences per vertex ({args.method})")


def _pose_transforms(args: argparse.Namespace, asset: GltfAsset) -> Floats:
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
            frame: Floats = T[i]
            return frame
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
    transforms: Floats = np.concatenate([ident, bones])
    return transforms


def cmd_pose(args: argparse.Namespace) -> None:
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


def cmd_batch(args: argparse.Namespace) -> int:
    from . import batch

    opts = {k: getattr(args, k) for k in batch.OPTION_DEFAULTS}
    report = batch.run(args.source, args.outdir, scheduler=args.scheduler, n_workers=args.workers,
                       memory_limit=args.memory_limit, retries=args.retries, timeout=args.timeout,
                       retry_failed=args.retry_failed, progress=not args.quiet, **opts)  # fmt: skip
    print(batch.summary_table(report))
    print(f"report: {os.path.join(args.outdir, 'report.html')}")
    return 1 if report["summary"]["failed"] else 0


def cmd_info(args: argparse.Namespace) -> None:
    mesh = read_any_mesh(args.file)
    V, F, asset = mesh["V"], mesh["F"], mesh["asset"]
    info: dict[str, object] = {
        "file": args.file,
        "vertices": len(V),
        "faces": 0 if F is None else len(F),
    }
    if mesh["T"] is not None:
        info["tets"] = len(mesh["T"])
    if F is not None:
        import trimesh

        info["watertight"] = bool(trimesh.Trimesh(V, F, process=False).is_watertight)
    skel: Skeleton | None = None
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
