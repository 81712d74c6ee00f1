"""``python -m skinrs.bench scale``: exact BBW at growing mesh sizes, with the paper's method.

Builds a deterministic series of tet meshes of the armadillo surface (``armadillo.obj`` from
``--data``, by default ``$SKINRS_DATA/armadillo``): the surface, decimated by VTK's quadric
decimation for the small sizes, is meshed by TetGen (``pq1.5``, plus a maximum tet volume for
the large sizes). 20 point handles are placed once, by farthest-point sampling over the interior
vertices of the smallest mesh (from the vertex nearest the centroid), and snapped to the nearest
interior vertex of each mesh; ``bc`` is the identity. Meshes are cached in ``--cache``.

For each size it prints n, tets, and for skinrs ``bbw_dual_constrained`` (default solver, tol
``--tol``, default 1e-9) and the paper's method (``paper_reference``: SciPy SuperLU on the KKT
system + L-BFGS on ``Y = U o U``, tol ``--paper-tol``, default 1e-6): L-BFGS iterations,
active-set rounds (", then L-BFGS" when a round's support factors would not fit skinrs's
``memory_limit``, ``--memory-limit``, and L-BFGS finished the solve), time per phase, wall and CPU
time, the largest round's support factors, peak RSS, the energy and skinrs's certified gap. Each
solve runs in its own process (so peak RSS is its own), under a wall-time limit and an
address-space cap (``--mem-gb``); the paper's method is not run at sizes after the first one where
it exceeded ``--paper-limit`` (600 s). Not a test: nothing is asserted.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path
from typing import Any, cast

import numpy as np
from numpy.typing import NDArray

# (name, fraction of the surface's faces removed by decimation, TetGen maximum tet volume)
SIZES = [
    ("10k", 0.95, None),
    ("30k", 0.8, None),
    ("85k", 0.0, None),
    ("100k", 0.0, 3e-7),
    ("300k", 0.0, 8e-8),
]
HANDLES = 20


def _data_dir(arg: str | None) -> Path:
    if arg:
        return Path(arg)
    root = os.environ.get(
        "SKINRS_DATA", str(Path(__file__).resolve().parents[3].parent / "shared/data")
    )
    return Path(root) / "armadillo"


def _tet_mesh(
    surface_path: Path, decimate: float, volume: float | None
) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """TetGen mesh (V, T) of the armadillo surface, decimated by ``decimate`` first."""
    import pyvista as pv
    import tetgen
    import trimesh

    # an .obj surface loads as a Trimesh (load() is typed as returning its base class)
    m = cast("trimesh.Trimesh", trimesh.load(surface_path, process=False))
    V, F = np.asarray(m.vertices, np.float64), np.asarray(m.faces, np.int64)
    if decimate > 0:
        faces = np.hstack([np.full((len(F), 1), 3), F]).ravel()
        s = pv.PolyData(V, faces).decimate(decimate)
        V, F = np.asarray(s.points, float), s.faces.reshape(-1, 4)[:, 1:]
    switches = "pq1.5Q" + (f"a{volume:g}" if volume else "")
    nodes, elems = tetgen.TetGen(V, F).tetrahedralize(switches=switches)[:2]
    return np.asarray(nodes, float), np.asarray(elems, np.int64)


def _interior(V: NDArray[np.float64], T: NDArray[np.int64]) -> NDArray[np.bool_]:
    """Mask of the vertices not on the boundary faces of the tet mesh."""
    faces = np.sort(
        np.vstack([T[:, [1, 2, 3]], T[:, [0, 2, 3]], T[:, [0, 1, 3]], T[:, [0, 1, 2]]]), 1
    )
    uniq, count = np.unique(faces, axis=0, return_counts=True)
    inside = np.ones(len(V), bool)
    inside[uniq[count == 1].ravel()] = False
    return inside


def _handle_points(
    V: NDArray[np.float64], T: NDArray[np.int64], k: int = HANDLES
) -> NDArray[np.float64]:
    """``k`` points by farthest-point sampling over the interior vertices, from the centroid's."""
    P = V[_interior(V, T)]
    pick = [int(np.argmin(((P - P.mean(0)) ** 2).sum(1)))]
    d = ((P - P[pick[0]]) ** 2).sum(1)
    for _ in range(k - 1):
        pick.append(int(np.argmax(d)))
        d = np.minimum(d, ((P - P[pick[-1]]) ** 2).sum(1))
    return P[pick]


def _snap(
    V: NDArray[np.float64], T: NDArray[np.int64], points: NDArray[np.float64]
) -> NDArray[np.int64]:
    """The interior vertex nearest each point (distinct)."""
    from scipy.spatial import cKDTree

    idx = np.flatnonzero(_interior(V, T))
    _, near = cKDTree(V[idx]).query(points)
    b: NDArray[np.int64] = idx[near]
    if len(set(b.tolist())) != len(b):
        raise RuntimeError("two handles snapped to one vertex")
    return b


def build_series(data: Path, cache: Path, names: list[str]) -> dict[str, Path]:
    """Writes (once) and returns the paths of ``cache/armadillo-<name>.npz`` (V, T, b, bc)."""
    cache.mkdir(parents=True, exist_ok=True)
    surface = data / "armadillo.obj"
    paths: dict[str, Path] = {}
    points: NDArray[np.float64] | None = None
    for name, decimate, volume in SIZES:
        path = cache / f"armadillo-{name}.npz"
        if name not in names and not (points is None and name == SIZES[0][0]):
            continue
        b: NDArray[np.int64] | None
        if path.exists():
            z = np.load(path)
            V, T, b = z["V"], z["T"], z["b"]
        else:
            t = time.perf_counter()
            V, T = _tet_mesh(surface, decimate, volume)
            b = None
            print(f"meshed {name}: {len(V)} vertices, {len(T)} tets in "
                  f"{time.perf_counter() - t:.0f} s", flush=True)  # fmt: skip
        if points is None:
            points = V[b] if b is not None else _handle_points(V, T)
        if b is None:
            b = _snap(V, T, points)
            np.savez(path, V=V, T=T, b=b, bc=np.eye(len(b)))
        paths[name] = path
    return {n: p for n, p in paths.items() if n in names}


def _worker(method: str, tol: float, path: str, memory_limit: float | None) -> int:
    """Solves one case in this process and prints one JSON line."""
    z = np.load(path)
    V, T, b, bc = z["V"], z["T"], z["b"], z["bc"]
    cpu0 = time.process_time()
    t0 = time.perf_counter()
    out: dict[str, object]
    if method == "skinrs":
        from .. import bbw_dual_constrained, biharmonic_energy, biharmonic_matrix

        W, info = bbw_dual_constrained(
            V, T, b, bc, tol=tol, memory_limit=memory_limit, return_info=True
        )
        out = {k: info[k] for k in info if isinstance(info[k], (int, float, str, bool))}
    else:
        from .. import biharmonic_energy, biharmonic_matrix
        from . import paper_reference

        _, W, paper_info = paper_reference.paper_dual_lbfgs(V, T, b, bc, tol=tol)
        out = {
            "iterations": paper_info["iterations"],
            "time_factor": paper_info["time_factor"],
            "time_solve": paper_info["time_solve"],
        }
    out["wall"] = time.perf_counter() - t0
    out["cpu"] = time.process_time() - cpu0
    out["peak_rss_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    out["energy_check"] = float(biharmonic_energy(W, biharmonic_matrix(V, T)))
    print(json.dumps(out), flush=True)
    return 0


def _run(
    method: str, tol: float, path: Path, limit: float, mem_gb: float, memory_limit_gb: float
) -> dict[str, Any]:
    cmd = [sys.executable, "-m", "skinrs.bench.scale", "--worker", method, repr(tol), str(path)]
    cmd += ["--memory-limit", repr(memory_limit_gb)] if memory_limit_gb else []

    def cap() -> None:
        lim = int(mem_gb * 2**30)
        resource.setrlimit(resource.RLIMIT_AS, (lim, lim))

    try:
        r = subprocess.run(
            cmd, check=False, capture_output=True, text=True, timeout=limit, preexec_fn=cap
        )
    except subprocess.TimeoutExpired:
        return {"failed": f"over {limit:g} s"}
    if r.returncode != 0:
        last = (r.stderr.strip().splitlines() or ["?"])[-1]
        oom = "MemoryError" in r.stderr or "memory allocation" in r.stderr
        return {"failed": f"out of memory (cap {mem_gb:g} GB)" if oom else last[:80]}
    result: dict[str, Any] = json.loads(r.stdout.strip().splitlines()[-1])
    return result


def _cell(r: dict[str, Any], key: str, spec: str) -> str:
    return format(r[key], spec) if key in r else "-"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m skinrs.bench scale", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)  # fmt: skip
    ap.add_argument("--worker", nargs=3, help=argparse.SUPPRESS)
    ap.add_argument("--sizes", nargs="+", default=[s[0] for s in SIZES],
                    help="sizes to run (default: all of " + ", ".join(s[0] for s in SIZES) + ")")  # fmt: skip
    ap.add_argument("--tol", type=float, default=1e-9, help="skinrs tol (default 1e-9)")
    ap.add_argument("--paper-tol", type=float, default=1e-6, help="paper's tol (default 1e-6)")
    ap.add_argument("--paper-limit", type=float, default=600.0, help="paper's time cap (s)")
    ap.add_argument("--no-paper", action="store_true", help="skip the paper's method")
    ap.add_argument("--limit", type=float, default=1800.0, help="skinrs time cap (s)")
    ap.add_argument("--mem-gb", type=float, default=12.0, help="address-space cap per solve (GB)")
    ap.add_argument("--memory-limit", type=float, default=0.0,
                    help="skinrs memory_limit (GB; default: bbw_dual_constrained's, half of RAM)")  # fmt: skip
    ap.add_argument("--data", help="folder holding armadillo.obj")
    ap.add_argument("--cache", default=str(Path.home() / ".cache" / "skinrs" / "scale"))
    args = ap.parse_args(argv)
    if args.worker:
        method, tol, path = args.worker
        return _worker(method, float(tol), path, args.memory_limit * 1e9 or None)
    paths = build_series(_data_dir(args.data), Path(args.cache), args.sizes)
    print("\n| size | n | tets | method | L-BFGS it. | rounds | factor B_ff s | L-BFGS s | "
          "support factors s | CG s | smoother s | wall s | CPU s | support factors MB | "
          "peak RSS MB | energy | gap |")  # fmt: skip
    print("|---|---:|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    paper_on = not args.no_paper
    for name in [s[0] for s in SIZES if s[0] in paths]:
        z = np.load(paths[name])
        n, nt = len(z["V"]), len(z["T"])
        runs = [("skinrs", args.tol, args.limit)]
        if paper_on:
            runs.append(("paper", args.paper_tol, args.paper_limit))
        for method, tol, limit in runs:
            r = _run(method, tol, paths[name], limit, args.mem_gb, args.memory_limit)
            label = f"{method} tol {tol:g}"
            if "failed" in r:
                print(f"| {name} | {n} | {nt} | {label} | {r['failed']} |", flush=True)
                if method == "paper":
                    paper_on = False
                continue
            lb = r.get("time_lbfgs", r.get("time_solve"))
            # Rounds, and whether L-BFGS finished the solve because the next round's support
            # factors did not fit memory_limit.
            rounds = _cell(r, "rounds", "d") + (", then L-BFGS" if r.get("memory_fallback") else "")
            factor_mb = r["support_factor_bytes"] / 2**20 if "support_factor_bytes" in r else None
            print(
                f"| {name} | {n} | {nt} | {label} | {r['iterations']} | {rounds} | "
                f"{r['time_factor']:.1f} | {lb:.1f} | "
                f"{_cell(r, 'time_support_factor', '.1f')} | {_cell(r, 'time_cg', '.1f')} | "
                f"{_cell(r, 'time_smooth', '.1f')} | {r['wall']:.1f} | {r['cpu']:.1f} | "
                f"{'-' if factor_mb is None else format(factor_mb, '.0f')} | "
                f"{r['peak_rss_mb']:.0f} | {r['energy_check']:.10g} | "
                f"{_cell(r, 'relative_gap', '.1e')} |",
                flush=True,
            )
            if method == "paper" and r["wall"] > args.paper_limit:
                paper_on = False
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
