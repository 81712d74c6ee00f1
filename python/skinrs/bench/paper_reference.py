"""SciPy re-implementation of Solomon & Stein 2025's BBW dual solver (the benchmark reference).

This follows the paper's own implementation (Sec. 6 and 8) as closely as the text allows, and
uses no skinrs code:

- B = L^T M^{-1} L with libigl's cotan L and Voronoi lumped M rescaled by its largest entry
  (Sec. 7); C selects the constrained vertices b, D = bc;
- the KKT matrix [[B, C^T], [C, 0]] (eq. 7) is factored once with SuperLU
  (``scipy.sparse.linalg.splu``); Q11 X and Q12 D are applied by solving with it (eq. 8);
- R = Q12 D P_m + (1/m) 1 1^T, P_m = I - (1/m) 1 1^T (eqs. 13-14); the dual (12)
  f(Y) = 1/2 tr(P_m Y^T Q11 Y) + tr(R^T Y), Y >= 0, gradient R + Q11 Y P_m (eq. 16);
- non-negativity by Y = U∘U [CMV22], U random with each column of U∘U summing to 1, optimised with
  SciPy's L-BFGS-B without bounds (plain L-BFGS), ``gtol = ftol = tol`` (default 1e-6) and
  100000 maximum iterations (also used as the function-evaluation cap);
- W = R + Q11 Y P_m (eq. 15), then clamped to [0, 1] and rows renormalised (Sec. 8).

Run standalone on a stored fixture (tests/reference/<case>.npz)::

    python -m skinrs.bench.paper_reference hand --tol 1e-6 1e-10
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypedDict

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import minimize

if TYPE_CHECKING:
    from typing_extensions import NotRequired


class PaperInfo(TypedDict):
    """What :func:`paper_dual_lbfgs` reports besides the weights (its docstring says what)."""

    iterations: int
    nfev: int
    time_factor: float
    time_solve: float
    energy: float
    energy_raw: float
    dual_objective: float
    success: bool
    message: str
    tol: float
    seed: int
    reached: NotRequired[bool]
    time_checks: NotRequired[float]


class _Monitor(TypedDict):
    checks: float
    iterations: int
    reached: bool
    x: NDArray[np.float64] | None


def biharmonic_matrix(V: ArrayLike, T: ArrayLike) -> sp.csc_matrix:
    """B = L^T M^{-1} L (libigl cotan L, Voronoi mass M / max(M)) as a scipy csc matrix."""
    import igl

    Vc = np.ascontiguousarray(V, dtype=np.float64)
    Tc = np.ascontiguousarray(T, dtype=np.int64)
    L = igl.cotmatrix(Vc, Tc)
    m = np.asarray(igl.massmatrix(Vc, Tc, igl.MASSMATRIX_TYPE_VORONOI).diagonal(), dtype=float)
    m = m / m.max()
    B = (L.T @ sp.diags(1.0 / m) @ L).tocsc()
    return ((B + B.T) * 0.5).tocsc()


def paper_dual_lbfgs(
    V: NDArray[np.float64],
    T: NDArray[np.int64],
    b: ArrayLike,
    bc: ArrayLike,
    tol: float = 1e-6,
    seed: int = 0,
    maxiter: int = 100000,
    B: sp.csc_matrix | None = None,
    target_energy: float | None = None,
    check_every: int = 10,
    time_limit: float | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.float64], PaperInfo]:
    """Solve PoU-BBW by the paper's dual (12) with L-BFGS on Y = U∘U.

    Inputs:
      V (n, d) vertex positions, T (k, d+1) triangles/tets,
      b (nb,) constrained vertex indices, bc (nb, m) their values,
      tol: L-BFGS ``gtol`` and ``ftol``; seed: random start; B: optional precomputed B.
      target_energy: if given, measure *time to accuracy*: every ``check_every`` iterations the
        post-processed W's energy is computed, and the run stops as soon as it is
        <= target_energy (or after ``time_limit`` seconds of solving). The checks' own time is
        not counted in ``time_solve``. Use a tiny ``tol`` so that L-BFGS does not stop first.
    Outputs:
      W_raw (n, m) = R + Q11 Y P_m (eq. 15, before post-processing),
      W (n, m) = W_raw clamped to [0, 1] with rows renormalised to sum 1,
      info dict: iterations, nfev, time_factor, time_solve, energy (of W), energy_raw,
      status/message of L-BFGS, and with ``target_energy`` also ``reached`` (bool).

    Example:
      >>> W_raw, W, info = paper_dual_lbfgs(V, T, b, bc, tol=1e-6)   # doctest: +SKIP
    """
    b_idx = np.asarray(b, dtype=np.int64)
    D = np.asarray(bc, dtype=np.float64)
    n = len(V)
    nb, m = D.shape
    t0 = time.perf_counter()
    if B is None:
        B = biharmonic_matrix(V, T)
    C = sp.csc_matrix((np.ones(nb), (np.arange(nb), b_idx)), shape=(nb, n))
    K = sp.bmat([[B, C.T], [C, None]], format="csc")
    lu = spla.splu(K)
    time_factor = time.perf_counter() - t0

    def apply_q11(Y: NDArray[np.float64]) -> NDArray[np.float64]:
        QY: NDArray[np.float64] = lu.solve(np.vstack([Y, np.zeros((nb, m))]))[:n]
        return QY

    def project(X: NDArray[np.float64]) -> NDArray[np.float64]:  # X P_m: subtract the row mean
        XP: NDArray[np.float64] = X - X.mean(axis=1, keepdims=True)
        return XP

    t1 = time.perf_counter()
    Q12D = lu.solve(np.vstack([np.zeros((n, m)), D]))[:n]
    R = project(Q12D) + 1.0 / m

    def fun(u: NDArray[np.float64]) -> tuple[float, NDArray[np.float64]]:
        U = u.reshape(n, m)
        Y = U * U
        G = R + project(apply_q11(Y))  # eq. (16); 1/2 tr(P Y^T Q Y) = 1/2 <Y, Q Y P>
        f = float(0.5 * np.sum(Y * (G - R)) + np.sum(R * Y))
        return f, (2.0 * U * G).ravel()

    def post_process(W_raw: NDArray[np.float64]) -> NDArray[np.float64]:
        # Sec. 8: clamp to [0, 1], renormalise rows
        W = np.clip(W_raw, 0.0, 1.0)
        W_rows: NDArray[np.float64] = W / W.sum(axis=1, keepdims=True)
        return W_rows

    monitor: _Monitor = {"checks": 0.0, "iterations": 0, "reached": False, "x": None}

    def callback(intermediate_result: Any) -> None:  # a scipy.optimize.OptimizeResult
        assert target_energy is not None  # (the callback is passed only with a target)
        monitor["iterations"] += 1
        if monitor["iterations"] % check_every:
            return
        t = time.perf_counter()
        U = intermediate_result.x.reshape(n, m)
        W = post_process(R + project(apply_q11(U * U)))
        reached = 0.5 * float(np.sum(W * (B @ W))) <= target_energy
        monitor["checks"] += time.perf_counter() - t
        out_of_time = time_limit is not None and t - t1 - monitor["checks"] > time_limit
        if reached or out_of_time:
            monitor["reached"] = reached
            monitor["x"] = intermediate_result.x.copy()
            raise StopIteration

    rng = np.random.default_rng(seed)
    U0 = rng.random((n, m))
    U0 /= np.sqrt((U0 * U0).sum(axis=0, keepdims=True))
    res = minimize(
        fun, U0.ravel(), jac=True, method="L-BFGS-B",
        callback=callback if target_energy is not None else None,
        options={"gtol": tol, "ftol": tol, "maxiter": maxiter, "maxfun": maxiter},
    )  # fmt: skip
    x = monitor["x"] if monitor["x"] is not None else res.x
    U = x.reshape(n, m)
    Y = U * U
    W_raw = R + project(apply_q11(Y))  # eq. (15)
    time_solve = time.perf_counter() - t1 - monitor["checks"]

    W = post_process(W_raw)
    info: PaperInfo = {
        "iterations": int(res.nit),
        "nfev": int(res.nfev),
        "time_factor": time_factor,
        "time_solve": time_solve,
        "energy": 0.5 * float(np.sum(W * (B @ W))),
        "energy_raw": 0.5 * float(np.sum(W_raw * (B @ W_raw))),
        "dual_objective": float(res.fun),
        "success": bool(res.success),
        "message": str(res.message),
        "tol": tol,
        "seed": seed,
    }
    if target_energy is not None:
        info["reached"] = monitor["reached"]
        info["time_checks"] = monitor["checks"]
        info["iterations"] = max(info["iterations"], monitor["iterations"])
    return W_raw, W, info


def _fixture(name: str) -> dict[str, NDArray[Any]]:
    root = Path(__file__).resolve().parents[3]
    path = root / "tests" / "reference" / f"{name}.npz"
    with np.load(path, allow_pickle=False) as z:
        return {k: z[k] for k in z.files}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m skinrs.bench.paper_reference")
    ap.add_argument("cases", nargs="*", default=["knight"], help="fixture names in tests/reference")
    ap.add_argument("--tol", type=float, nargs="+", default=[1e-6])
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    print(f"{'case':>10} {'tol':>7} {'iters':>7} {'t_fact':>8} {'t_solve':>9} {'energy':>18} "
          f"{'E_qp':>18} {'(E-Eqp)/Eqp':>11} {'max|dW|':>9}")  # fmt: skip
    for name in args.cases:
        fx = _fixture(name)
        B = biharmonic_matrix(fx["V"], fx["T"])
        for tol in args.tol:
            _, W, info = paper_dual_lbfgs(
                fx["V"], fx["T"], fx["b"], fx["bc"], tol=tol, seed=args.seed, B=B
            )
            line = (f"{name:>10} {tol:7.0e} {info['iterations']:7d} {info['time_factor']:8.2f} "
                    f"{info['time_solve']:9.2f} {info['energy']:18.10g}")  # fmt: skip
            if "W_qp" in fx:
                e_qp = float(fx["energy"])
                dw = float(np.abs(W - fx["W_qp"]).max())
                line += f" {e_qp:18.10g} {(info['energy'] - e_qp) / e_qp:11.2e} {dw:9.2e}"
            print(line, flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
