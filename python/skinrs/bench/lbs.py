"""LBS / DQS throughput against numpy and against this machine's memory-copy bandwidth.

``python -m skinrs.bench lbs [--n 1000000] [--m 16] [--k 4] [--repeat 5]``

For a synthetic ``n``-vertex point set it times, in the same run:

* ``skinrs.lbs`` with dense weights ``(n, m)`` and with packed weights ``(n, k)`` over ``m``
  handles (``skinrs.dqs`` too, for reference);
* the numpy reference ``einsum`` implementation (blend the 3x4 matrices per vertex, then apply),
  and numpy's best (``W @ T`` through BLAS, then apply) for comparison;
* a numpy copy of a large array (the memory-copy bandwidth, read + write bytes per second).

Throughput is reported as vertices x influences per second and as bytes moved per second
(inputs read + output written, the same count as the copy's read + write), best of ``--repeat``
runs.

The reference bandwidth is ``np.copyto`` of ``--copy-mb`` (512 MB) into a preallocated array,
one thread. Two more copies are printed for context, not used for the target: one of the size
of the dense LBS data (glibc's memcpy switches to a faster 4-page interleaved streaming loop
above about 200 MB on this kind of machine, so a smaller copy is *slower*, and using it would
flatter LBS), and the 512 MB copy split over two threads (LBS runs on all cores; this is the
machine's best copy rate and the stricter reference).
"""

from __future__ import annotations

import argparse
import os
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor

import numpy as np
from numpy.typing import NDArray


def _best(f: Callable[[], object], repeat: int) -> float:
    best = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        f()
        best = min(best, time.perf_counter() - t0)
    return best


def _random_rigid(m: int, rng: np.random.Generator) -> NDArray[np.float64]:
    Q, _ = np.linalg.qr(rng.standard_normal((m, 3, 3)))
    Q *= np.sign(np.linalg.det(Q))[:, None, None]
    return np.concatenate([Q, rng.standard_normal((m, 3, 1))], axis=2)


def numpy_einsum_lbs(
    V: NDArray[np.float64], W: NDArray[np.float64], T: NDArray[np.float64]
) -> NDArray[np.float64]:
    """Reference LBS in numpy: blended matrices ``A_i = sum_j W_ij T_j``, then ``A_i [v_i; 1]``."""
    A = np.einsum("ij,jkl->ikl", W, T)
    U: NDArray[np.float64] = np.einsum("ikl,il->ik", A[:, :, :3], V) + A[:, :, 3]
    return U


def numpy_einsum_lbs_packed(
    V: NDArray[np.float64], I: NDArray[np.int64], Wk: NDArray[np.float64], T: NDArray[np.float64]
) -> NDArray[np.float64]:
    A = np.einsum("ij,ijkl->ikl", Wk, T[I])
    U: NDArray[np.float64] = np.einsum("ikl,il->ik", A[:, :, :3], V) + A[:, :, 3]
    return U


def numpy_matmul_lbs(
    V: NDArray[np.float64], W: NDArray[np.float64], T: NDArray[np.float64]
) -> NDArray[np.float64]:
    A = (W @ T.reshape(T.shape[0], -1)).reshape(-1, 3, 4)
    U: NDArray[np.float64] = np.einsum("ikl,il->ik", A[:, :, :3], V) + A[:, :, 3]
    return U


def _copy_bandwidth(copy_mb: int, r: int, bytes_dense: int) -> tuple[float, float, float, int, int]:
    """Memory-copy bandwidth: numpy copy into a preallocated array; bytes = read + write.

    Returns the bandwidth (bytes/s) of ``copy_mb`` MB on one thread and on ``threads`` threads,
    that of a copy moving as many bytes as dense LBS (``same`` float64s), ``threads``, ``same``.
    """
    src = np.ones(copy_mb * (1 << 20) // 8)
    dst = np.empty_like(src)
    t_copy = _best(lambda: np.copyto(dst, src), r)
    bw_copy = 2 * src.nbytes / t_copy
    threads = max(1, min(2, os.cpu_count() or 1))
    with ThreadPoolExecutor(threads) as ex:  # numpy releases the GIL while copying
        parts = np.array_split(np.arange(len(src)), threads)
        sl = [slice(p[0], p[-1] + 1) for p in parts]
        t_copy2 = _best(lambda: list(ex.map(lambda q: np.copyto(dst[q], src[q]), sl)), r)
    bw_copy2 = 2 * src.nbytes / t_copy2
    same = bytes_dense // 2 // 8  # a copy moving as many bytes as dense LBS
    t_same = _best(lambda: np.copyto(dst[:same], src[:same]), r)
    bw_same = 2 * same * 8 / t_same
    return bw_copy, bw_copy2, bw_same, threads, same


def main(argv: list[str] | None = None) -> int:
    import skinrs

    ap = argparse.ArgumentParser(
        prog="python -m skinrs.bench lbs", description=__doc__.split("\n")[0]
    )
    ap.add_argument("--n", type=int, default=1_000_000, help="vertices (default 1e6)")
    ap.add_argument("--m", type=int, default=16, help="handles (dense weight columns)")
    ap.add_argument("--k", type=int, default=4, help="influences per vertex (packed)")
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--copy-mb", type=int, default=512, help="size of the memcpy probe array")
    a = ap.parse_args(argv)
    n, m, k, r = a.n, a.m, a.k, a.repeat
    load = os.getloadavg()

    rng = np.random.default_rng(0)
    V = rng.standard_normal((n, 3))
    T = _random_rigid(m, rng)
    W = rng.random((n, m))
    W /= W.sum(axis=1, keepdims=True)
    I = np.stack([rng.choice(m, size=k, replace=False) for _ in range(min(n, 4096))])
    I = np.ascontiguousarray(np.resize(I, (n, k)), dtype=np.int64)
    Wk = rng.random((n, k))
    Wk /= Wk.sum(axis=1, keepdims=True)

    bytes_dense = V.nbytes + W.nbytes + V.nbytes  # read V, W; write U
    bytes_packed = V.nbytes + I.nbytes + Wk.nbytes + V.nbytes

    # (the probe's 1 GB is freed before the skinning runs)
    bw_copy, bw_copy2, bw_same, threads, same = _copy_bandwidth(a.copy_mb, r, bytes_dense)

    rows: list[tuple[str, float, float, float, float | None]] = []

    def row(name: str, t: float, infl: int, nbytes: int, ref: float | None = None) -> None:
        rows.append((name, t, n * infl / t, nbytes / t, (ref / t) if ref else None))

    # correctness guard, so a fast wrong kernel cannot look good here
    U = skinrs.lbs(V[:1000], W[:1000], T)
    assert np.allclose(U, numpy_einsum_lbs(V[:1000], W[:1000], T), atol=1e-12)
    U = skinrs.lbs(V[:1000], (I[:1000], Wk[:1000]), T)
    assert np.allclose(U, numpy_einsum_lbs_packed(V[:1000], I[:1000], Wk[:1000], T), atol=1e-12)

    t_np_dense = _best(lambda: numpy_einsum_lbs(V, W, T), max(1, r // 2))
    t_np_mm = _best(lambda: numpy_matmul_lbs(V, W, T), max(1, r // 2))
    t_np_packed = _best(lambda: numpy_einsum_lbs_packed(V, I, Wk, T), max(1, r // 2))
    t_dense = _best(lambda: skinrs.lbs(V, W, T), r)
    t_packed = _best(lambda: skinrs.lbs(V, (I, Wk), T), r)
    U = np.empty_like(V)
    t_dense_out = _best(lambda: skinrs.lbs(V, W, T, out=U), r)
    t_packed_out = _best(lambda: skinrs.lbs(V, (I, Wk), T, out=U), r)
    t_dqs_dense = _best(lambda: skinrs.dqs(V, W, T), r)
    t_dqs_packed = _best(lambda: skinrs.dqs(V, (I, Wk), T), r)

    row(f"numpy einsum, dense m={m}", t_np_dense, m, bytes_dense)
    row(f"numpy W@T (BLAS), dense m={m}", t_np_mm, m, bytes_dense, t_np_dense)
    row(f"skinrs.lbs, dense m={m}", t_dense, m, bytes_dense, t_np_dense)
    row("  same, out= preallocated", t_dense_out, m, bytes_dense, t_np_dense)
    row(f"numpy einsum, packed k={k}", t_np_packed, k, bytes_packed)
    row(f"skinrs.lbs, packed k={k}", t_packed, k, bytes_packed, t_np_packed)
    row("  same, out= preallocated", t_packed_out, k, bytes_packed, t_np_packed)
    row(f"skinrs.dqs, dense m={m}", t_dqs_dense, m, bytes_dense, t_np_dense)
    row(f"skinrs.dqs, packed k={k}", t_dqs_packed, k, bytes_packed, t_np_packed)

    print(
        f"LBS benchmark: n = {n:,} vertices, m = {m} handles, k = {k} packed influences, "
        f"best of {r}"
    )
    print(f"load average at start: {load[0]:.2f} (1 min)")
    print(f"memory copy (numpy, {a.copy_mb} MB, read+write): {bw_copy / 1e9:.2f} GB/s  [reference]")
    print(
        f"  for context: same bytes as dense LBS ({2 * same * 8 / 1e6:.0f} MB moved) "
        f"{bw_same / 1e9:.2f} GB/s; {a.copy_mb} MB on {threads} threads {bw_copy2 / 1e9:.2f} GB/s"
    )
    print(
        f"{'method':<30} {'time ms':>9} {'Ginfl/s':>9} {'GB/s':>7} {'% copy bw':>10} "
        f"{'% 2-thr copy':>13} {'x numpy einsum':>15}"
    )
    for name, t, ips, bps, ratio in rows:
        rs = f"{ratio:.1f}" if ratio else "-"
        print(
            f"{name:<30} {t * 1e3:9.2f} {ips / 1e9:9.3f} {bps / 1e9:7.2f} "
            f"{100 * bps / bw_copy:9.0f}% {100 * bps / bw_copy2:12.0f}% {rs:>15}"
        )
    ok_dense = t_np_dense / t_dense >= 5 and bytes_dense / t_dense_out >= 0.5 * bw_copy
    ok_packed = t_np_packed / t_packed >= 5 and bytes_packed / t_packed_out >= 0.5 * bw_copy
    print(
        "(the copy probe writes into a preallocated array, so bandwidth is compared with the "
        "out= rows;\n fresh outputs also pay the page faults of a new allocation)"
    )
    print(
        f"target (>= 5x numpy einsum and >= 50% of copy bandwidth): "
        f"dense {'met' if ok_dense else 'NOT met'}, packed {'met' if ok_packed else 'NOT met'}"
    )
    ok2_dense = bytes_dense / t_dense_out >= 0.5 * bw_copy2
    ok2_packed = bytes_packed / t_packed_out >= 0.5 * bw_copy2
    print(
        f"(against the {threads}-thread copy: dense {'met' if ok2_dense else 'NOT met'}, "
        f"packed {'met' if ok2_packed else 'NOT met'}; load average now "
        f"{os.getloadavg()[0]:.2f})"
    )
    return 0


if __name__ == "__main__":
    import sys

    sys.exit(main())
