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
from collections.abc import Callable
from functools import partial
from pathlib import Path


def _best(fn: Callable[[], object], repeat: int) -> float:
    times: list[float] = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return min(times)


def main(argv: list[str] | None = None) -> int:
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

    def igl_B(kind: str) -> sp.csc_matrix:
        L = igl.cotmatrix(V, T)
        m = igl.massmatrix(V, T, kinds[kind]).diagonal()
        return (L.T @ sp.diags(1.0 / (m / m.max())) @ L).tocsc()

    rows: list[tuple[str, Callable[[], object], Callable[[], object]]] = [
        ("L cotan_laplacian", lambda: skinrs.cotan_laplacian(V, T), lambda: igl.cotmatrix(V, T))
    ]
    for kind, igl_kind in kinds.items():
        rows.append(
            (
                f"M massmatrix {kind}",
                partial(skinrs.massmatrix, V, T, kind=kind),
                partial(igl.massmatrix, V, T, igl_kind),
            )
        )
        rows.append(
            (
                f"B biharmonic {kind}",
                partial(skinrs.biharmonic_matrix, V, T, mass=kind),
                partial(igl_B, kind),
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
