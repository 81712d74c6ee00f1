"""Timing of the discrete operators against libigl (+ scipy for B), same run, same mesh.

    python -m skinrs.bench.operators [--mesh PATH.mesh] [--repeat N]

Default mesh: ``$SKINRS_DATA/hand-403/hand.mesh`` (7,234 vertices, 29,998 tets). Prints the best
of N wall-clock times and the ratio igl / skinrs; nothing is asserted.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path


def _best(fn, repeat):
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return min(times)


def main(argv=None) -> int:
    import igl
    import scipy.sparse as sp

    import skinrs

    ap = argparse.ArgumentParser(prog="python -m skinrs.bench.operators")
    default = Path(os.environ.get("SKINRS_DATA", "../shared/data")) / "hand-403" / "hand.mesh"
    ap.add_argument("--mesh", default=str(default))
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args(argv)

    V, T, _ = igl.readMESH(args.mesh)
    print(f"{args.mesh}: {V.shape[0]} vertices, {T.shape[0]} elements, best of {args.repeat}")
    kinds = {"voronoi": igl.MASSMATRIX_TYPE_VORONOI, "barycentric": igl.MASSMATRIX_TYPE_BARYCENTRIC}

    def igl_B(kind):
        L = igl.cotmatrix(V, T)
        m = igl.massmatrix(V, T, kinds[kind]).diagonal()
        return (L.T @ sp.diags(1.0 / (m / m.max())) @ L).tocsc()

    rows = [
        ("L cotan_laplacian", lambda: skinrs.cotan_laplacian(V, T), lambda: igl.cotmatrix(V, T))
    ]
    for kind in kinds:
        rows.append(
            (
                f"M massmatrix {kind}",
                lambda k=kind: skinrs.massmatrix(V, T, kind=k),
                lambda k=kind: igl.massmatrix(V, T, kinds[k]),
            )
        )
        rows.append(
            (
                f"B biharmonic {kind}",
                lambda k=kind: skinrs.biharmonic_matrix(V, T, mass=k),
                lambda k=kind: igl_B(k),
            )
        )
    print(f"{'operator':<26}{'skinrs ms':>12}{'igl ms':>12}{'igl/skinrs':>12}")
    for name, ours, ref in rows:
        t_ours = _best(ours, args.repeat)
        t_ref = _best(ref, args.repeat)
        print(f"{name:<26}{1e3 * t_ours:>12.1f}{1e3 * t_ref:>12.1f}{t_ref / t_ours:>12.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
