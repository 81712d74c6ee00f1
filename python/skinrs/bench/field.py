"""Throughput of the geometric-field queries against libigl, same run, same mesh and points.

    python -m skinrs.bench field [--mesh PATH.obj] [--queries N] [--repeat R]

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
from pathlib import Path

import numpy as np


def _best(fn, repeat):
    times, out = [], None
    for _ in range(repeat):
        t = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t)
    return min(times), out


def main(argv=None) -> int:
    import igl

    import skinrs
    from skinrs import io

    ap = argparse.ArgumentParser(prog="python -m skinrs.bench field")
    default = Path(os.environ.get("SKINRS_DATA", "../shared/data")) / "arm" / "arm.obj"
    ap.add_argument("--mesh", default=str(default))
    ap.add_argument("--queries", type=int, default=100_000)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args(argv)

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

    rows = []
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
    sigma = float(np.median(skinrs.knn_distance(X, 9)))
    P = Q
    R = rng.uniform(lo - pad, hi + pad, size=(n, 3))
    h = n // 2
    d = rng.standard_normal((h, 3))
    R[:h] = P[:h] + 3 * sigma * d / np.linalg.norm(d, axis=1, keepdims=True)
    t_seg, vis = _best(lambda: skinrs.segment_visible(V, F, P, R), args.repeat)
    t_short, _ = _best(lambda: skinrs.segment_visible(V, F, P[:h], R[:h]), args.repeat)
    t_build, _ = _best(lambda: skinrs.segment_visible(V, F, P[:1], R[:1]), args.repeat)
    t_knn, _ = _best(lambda: skinrs.knn_distance(X, 9), args.repeat)
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
