"""Throughput of the geometric-field queries against libigl, same run, same mesh and points.

    python -m skinrs.bench field [--mesh PATH.obj] [--queries N] [--repeat R]
    python -m skinrs.bench field --optimize [--case hand|arm] [--steps-per-level S] [--full]

``--optimize`` measures the geometric-field optimisation itself with the paper's default
settings in 3D (App. A: 2^13 -> 2^16 points, M = 2^11 samples, 6000 steps, three doublings):
total time, rays traced per second, share of time in visibility, and (hand-403) the surface
agreement with the exact FEM weights of ``tests/reference/hand.npz``. ``--full`` runs the whole
schedule; by default each of the four resolution levels runs two windows of ``S`` steps
(default 100) of the default configuration: the first fills the per-sample visibility cache,
the second is the steady state, and each level's remaining steps are extrapolated from the
second window. It also
measures the two-ball ray skip (a segment covered by the boundary-free balls around its ends
cannot cross the boundary) by running level 0 with and without it.

Default mesh: ``$SKINRS_DATA/arm/arm.obj`` (8,311 vertices, 16,618 triangles). Query points are
uniform in the bounding box inflated by 20%. Prints the best of R wall-clock times (each call
builds its tree, as the public functions do), queries per second and the ratio igl / skinrs,
plus the winding numbers' largest deviation from the exact ``igl.winding_number``. Segment
tests: half short segments (length ~ 3 sigma of a 64k-point cloud, the kernel support of
Dodik et al.), half across the whole box. Nothing is asserted.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import TypeVar

import numpy as np
from numpy.typing import NDArray

Out = TypeVar("Out")
#: One timing window of the optimisation: points, seconds, rays, visibility's share of the time.
Window = tuple[int, float, int, float]


def _best(fn: Callable[[], Out], repeat: int) -> tuple[float, Out]:
    times: list[float] = []
    out: Out
    for _ in range(repeat):
        t = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t)
    return min(times), out


def _load_case(
    case: str,
) -> tuple[
    NDArray[np.float64],
    NDArray[np.int64],
    NDArray[np.float64],
    NDArray[np.int64],
    NDArray[np.float64] | None,
]:
    from skinrs import io

    data = Path(os.environ.get("SKINRS_DATA", "../shared/data"))
    if case == "hand":
        V, _T, F = io.read_mesh(data / "hand-403" / "hand.mesh")
        C, BE = io.read_tgf(data / "hand-403" / "hand.tgf")
        ref = Path(__file__).resolve().parents[3] / "tests" / "reference" / "hand.npz"
        Wref = np.load(ref)["W_qp"] if ref.is_file() else None
        return V, F, C, BE, Wref
    V, F = io.read_obj(data / "arm" / "arm.obj")
    C, BE = io.read_tgf(data / "arm" / "arm.tgf")
    return V, F, C, BE, None


def _optimize(args: argparse.Namespace) -> int:
    import skinrs

    V, F, C, BE, Wref = _load_case(args.case)
    print(
        f"{args.case}: {len(V)} vertices, {len(F)} boundary triangles, {len(BE)} bones, "
        f"{os.cpu_count()} cpus; default 3D schedule (App. A), winding-number sampling"
    )
    if not args.full:
        # Ray skip on/off, level 0, same samples.
        for skip in (True, False):
            f0 = skinrs.GeometricField(V, F, C, BE=BE, skip_rays=skip, cache_visibility=False)
            t = time.perf_counter()
            f0.optimize(steps=args.skip_steps)
            dt = time.perf_counter() - t
            i = f0.info()
            print(
                f"level 0, {args.skip_steps} steps, no cache, skip_rays={skip}: {dt:.1f} s, "
                f"{i['pairs']} pairs, {i['rays']} rays ({i['rays'] / max(i['pairs'], 1):.0%}), "
                f"{i['rays'] / max(i['time_visibility'], 1e-9):.3g} rays per thread-second"
            )
    S = 1500 if args.full else args.steps_per_level
    t = time.perf_counter()
    fld = skinrs.GeometricField(V, F, C, BE=BE, steps=4 * S * (1 if args.full else 2))
    t_setup = time.perf_counter() - t
    total = t_setup
    rows: list[tuple[int, list[Window]]] = []
    threads = os.cpu_count() or 1
    # Per level: a first window (the visibility cache of the pool fills up) and a second,
    # steady-state window; the rest of the level's 1500 steps costs like the second.
    for level in range(4):
        windows: list[Window] = []
        for _ in range(1 if args.full else 2):
            before = fld.info()
            t = time.perf_counter()
            fld.optimize(steps=S)
            dt = time.perf_counter() - t
            i = fld.info()
            rays = i["rays"] - before["rays"]
            tvis = i["time_visibility"] - before["time_visibility"]
            tenergy = i["time_energy"] - before["time_energy"]
            windows.append((i["n_points"], dt, rays, tvis / max(tenergy * threads, 1e-9)))
        rows.append((level, windows))
        if args.full:
            total += windows[0][1]
        else:
            total += windows[0][1] + windows[1][1] * (1500 - S) / S
    print(f"setup (pool of {fld.info()['pool']} samples, first points): {t_setup:.1f} s")
    print(
        f"{'level':>5}{'window':>8}{'points':>8}{'s/step':>9}{'rays':>11}{'rays/s':>10}{'vis':>6}"
    )
    for level, windows in rows:
        for w, (n, dt, rays, share) in enumerate(windows):
            print(
                f"{level:>5}{w:>8}{n:>8}{dt / S:>9.3f}{rays:>11}{rays / max(dt, 1e-9):>10.3g}"
                f"{share:>6.0%}"
            )
    what = "measured" if args.full else f"extrapolated from 2 x {S} steps per level"
    print(f"total for 6000 steps ({what}): {total:.0f} s = {total / 60:.1f} min")
    if Wref is not None:
        W = fld.vertex_weights()
        surf = np.unique(F)
        D = np.abs(W[surf] - Wref[surf])
        print(
            f"surface vs FEM after this run: mean |dw| {D.mean():.4f}, 95th pct "
            f"{np.percentile(D, 95):.4f}, max {D.max():.4f}"
        )
    return 0


def main(argv: list[str] | None = None) -> int:
    import igl

    import skinrs
    from skinrs import io

    ap = argparse.ArgumentParser(prog="python -m skinrs.bench field")
    default = Path(os.environ.get("SKINRS_DATA", "../shared/data")) / "arm" / "arm.obj"
    ap.add_argument("--mesh", default=str(default))
    ap.add_argument("--queries", type=int, default=100_000)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--optimize", action="store_true", help="benchmark the field optimisation")
    ap.add_argument("--case", choices=("hand", "arm"), default="hand")
    ap.add_argument("--steps-per-level", type=int, default=100)
    ap.add_argument("--skip-steps", type=int, default=20)
    ap.add_argument("--full", action="store_true", help="run all 6000 steps")
    args = ap.parse_args(argv)
    if args.optimize:
        return _optimize(args)

    V, F = io.read_obj(args.mesh)
    n = args.queries
    rng = np.random.default_rng(0)
    lo, hi = V.min(0), V.max(0)
    pad = 0.2 * (hi - lo)
    Q = rng.uniform(lo - pad, hi + pad, size=(n, 3))
    print(
        f"{args.mesh}: {V.shape[0]} vertices, {F.shape[0]} triangles, {n} queries, "
        f"best of {args.repeat}, {os.cpu_count()} cpus"
    )

    rows: list[tuple[str, float, float, float | None]] = []
    t_ex, w_ex = _best(lambda: igl.winding_number(V, F, Q), args.repeat)
    t_fi, w_fi = _best(lambda: igl.fast_winding_number(V, F, Q), args.repeat)
    t_s2, w_s2 = _best(lambda: skinrs.winding_number(V, F, Q), args.repeat)
    t_s3, w_s3 = _best(lambda: skinrs.winding_number(V, F, Q, beta=3.0), args.repeat)
    err = {k: np.abs(w - w_ex).max() for k, w in [("fi", w_fi), ("s2", w_s2), ("s3", w_s3)]}
    rows.append(("winding skinrs b=2 / igl exact", t_s2, t_ex, err["s2"]))
    rows.append(("winding skinrs b=2 / igl fast b=2", t_s2, t_fi, err["s2"]))
    rows.append(("winding skinrs b=3 / igl exact", t_s3, t_ex, err["s3"]))
    print(f"igl.fast_winding_number max |w - exact| = {err['fi']:.2e}")

    t_cp, _ = _best(lambda: skinrs.closest_point(V, F, Q), args.repeat)
    t_ci, _ = _best(lambda: igl.point_mesh_squared_distance(Q, V, F), args.repeat)
    rows.append(("closest skinrs / igl point_mesh_sq_dist", t_cp, t_ci, None))

    print(f"{'query':<42}{'skinrs q/s':>13}{'igl q/s':>13}{'igl/skinrs':>12}{'max err':>10}")
    for name, t_ours, t_ref, e in rows:
        es = f"{e:10.1e}" if e is not None else f"{'':>10}"
        print(f"{name:<42}{n / t_ours:>13.3g}{n / t_ref:>13.3g}{t_ref / t_ours:>12.2f}{es}")

    # Segment tests: sigma as the method would pick it for 64k interior-ish samples.
    X = Q[: min(n, 64_000)]
    sigma = float(np.median(skinrs.knn_distance(X, k=9)))
    P = Q
    R = rng.uniform(lo - pad, hi + pad, size=(n, 3))
    h = n // 2
    d = rng.standard_normal((h, 3))
    R[:h] = P[:h] + 3 * sigma * d / np.linalg.norm(d, axis=1, keepdims=True)
    t_seg, vis = _best(lambda: skinrs.segment_visible(V, F, P, R), args.repeat)
    t_short, _ = _best(lambda: skinrs.segment_visible(V, F, P[:h], R[:h]), args.repeat)
    t_build, _ = _best(lambda: skinrs.segment_visible(V, F, P[:1], R[:1]), args.repeat)
    t_knn, _ = _best(lambda: skinrs.knn_distance(X, k=9), args.repeat)
    print(f"BVH build (one segment query): {1e3 * t_build:.1f} ms")
    for name, m, t in [
        (f"mixed, {vis.mean():.0%} visible", n, t_seg),
        (f"short, length 3 sigma = {3 * sigma:.3g}", h, t_short),
    ]:
        print(
            f"segment_visible ({name}): {m / t:.3g} segments/s, "
            f"{m / max(t - t_build, 1e-9):.3g} without the build"
        )
    print(f"knn_distance k=9: {X.shape[0] / t_knn:.3g} points/s on {X.shape[0]} points")
    return 0


if __name__ == "__main__":
    sys.exit(main())
