"""Weights for a library of assets on Dask distributed: ``skinrs batch`` / :func:`run`.

One Dask task per asset runs :func:`skinrs.cli.weights_job`, the code of ``skinrs weights``,
and writes the result and a JSON record into OUTDIR atomically. Design: ``docs/batch.md``.

Examples
--------
>>> import skinrs.batch                                                  # doctest: +SKIP
>>> report = skinrs.batch.run("assets/", "out/", tol=1e-6, n_workers=2)  # doctest: +SKIP
>>> report["summary"]                                                    # doctest: +SKIP
{'done': 7, 'failed': 1, 'skipped': 0, ...}
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, Literal

from ._batch_assets import (
    FORMATS,
    OPTION_DEFAULTS,
    TEST_HOOK_ENV,
    TEST_HOOK_KEY,
    AssetSpec,
    Options,
    Record,
    _key,
    _options,
    _sha256,
    find_assets,
)
from ._batch_report import Report, Summary, _write_json, summary_table, write_report
from ._cli_io import UsageError

if TYPE_CHECKING:
    from distributed import Future
    from tqdm import tqdm
    from typing_extensions import Self

    from ._cli_commands import WeightsJob

__all__ = [
    "FORMATS",
    "OPTION_DEFAULTS",
    "TEST_HOOK_ENV",
    "TEST_HOOK_KEY",
    "AssetSpec",
    "Report",
    "Summary",
    "estimate_peak_bytes",
    "find_assets",
    "run",
    "run_asset",
    "summary_table",
    "write_report",
]

# --------------------------------------------------------------------------------------------
# the per-asset job (runs on a Dask worker)


def estimate_peak_bytes(n_vertices: int, n_handles: int, tets: bool, method: str) -> int:
    """A rough upper estimate of a job's peak memory (bytes), calibrated on the test data.

    The solve holds a few dense ``(volume vertices x handles)`` float64 arrays and the sparse
    bi-Laplacian (~100 non-zeros a row); meshing a surface's inside gives about 5 volume
    vertices per surface vertex. Plus ~400 MB for the worker itself (Python, numpy, skinrs,
    Dask). Measured peaks (RSS) of the libigl hand, knight and arm: 356, 280, 221 MB; estimated
    440, 407, 546 MB.
    """
    n_volume = n_vertices if tets or method == "field" else 5 * n_vertices
    return int(400e6 + n_volume * (16 * 8 * max(n_handles, 1) + 3000))


class _Watch:
    """Samples the process' RSS (peak) and ends the process past the timeout: a Rust solve cannot
    be interrupted from another thread, and Dask restarts the worker (its failed record is
    written first)."""

    def __init__(self, timeout: float | None, on_timeout: Callable[[], None]) -> None:
        import psutil

        self.proc, self.peak, self.stop = psutil.Process(), 0, threading.Event()
        self.timeout, self.on_timeout, self.t0 = timeout, on_timeout, time.monotonic()
        self.thread = threading.Thread(target=self._loop, daemon=True)

    def _loop(self) -> None:
        while not self.stop.wait(0.05):
            self.peak = max(self.peak, self.proc.memory_info().rss)
            if self.timeout and time.monotonic() - self.t0 > self.timeout:
                self.on_timeout()
                os._exit(3)

    def __enter__(self) -> Self:
        self.peak = self.proc.memory_info().rss
        self.thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop.set()
        self.thread.join()


def _worker_memory_limit() -> int | None:
    try:
        from distributed import get_worker

        return get_worker().memory_manager.memory_limit
    except (ImportError, ValueError, AttributeError):
        return None


def run_asset(
    spec: AssetSpec,
    opts: Options,
    key: Record,
    outdir: str,
    timeout: float | None = None,
    memory_limit: float | Literal["worker"] | None = "worker",
) -> Record:
    """Weights of one asset into ``outdir`` (``NAME.EXT`` and ``NAME.json``, both atomic);
    returns the record. Bad input gives a failed record; other errors raise (Dask retries)."""
    from . import _cli_commands as cli

    name = spec["name"]
    out = os.path.join(outdir, f"{name}.{opts['format']}")
    rec_path = os.path.join(outdir, f"{name}.json")
    rec: Record = {"name": name, "mesh": spec["mesh"], "skeleton": spec["skeleton"], **key,
           "output": os.path.basename(out), "started": time.time()}  # fmt: skip
    if spec["options"].get(TEST_HOOK_KEY):
        if os.environ.get(TEST_HOOK_ENV) != "1":
            raise UsageError(f"{name}: {TEST_HOOK_KEY} needs {TEST_HOOK_ENV}=1 (tests only)")
        os._exit(11)
    limit = _worker_memory_limit() if memory_limit == "worker" else memory_limit

    def failed(reason: str) -> Record:
        rec.update(status="failed", reason=reason, seconds=time.time() - rec["started"])
        _write_json(rec_path, rec)
        return rec

    args = argparse.Namespace(mesh=spec["mesh"], skeleton=spec["skeleton"], output=out,
                              quiet=True, **{k: v for k, v in opts.items() if k != "format"})  # fmt: skip
    if limit:
        # The solve keeps within what the worker has left: beyond it BBW finishes with L-BFGS,
        # or fails with a record, rather than the nanny killing the worker.
        import psutil

        args.memory_limit = max(limit - psutil.Process().memory_info().rss, 1)
    try:
        if limit:
            mesh = cli.read_any_mesh(spec["mesh"])
            m = len(cli.read_skeleton(spec["skeleton"])[1]) if spec["skeleton"] else 1
            need = estimate_peak_bytes(len(mesh["V"]), m, mesh["T"] is not None, opts["method"])
            if need > limit:
                return failed(f"needs about {need / 1e9:.2f} GB, more than the worker's memory "
                              f"limit of {limit / 1e9:.2f} GB")  # fmt: skip

        def on_timeout() -> None:
            failed(f"timed out after {timeout:g} s (worker restarted)")

        with _Watch(timeout, on_timeout) as watch:
            job = cli.weights_job(args)
    except (UsageError, ValueError, OSError, MemoryError) as e:
        return failed(f"{type(e).__name__}: {e}")
    W = job["W"]
    rec.update(status="done", seconds=time.time() - rec["started"], solve_seconds=job["seconds"],
               vertices=int(W.shape[0]), handles=int(W.shape[1]), gap=job["gap"],
               volume_vertices=job.get("volume_vertices"),
               energy=job["energy"], peak_rss_mb=watch.peak / 2**20,
               output_sha256=_sha256(out), thumbnail=_thumbnail(job, outdir, name))  # fmt: skip
    _write_json(rec_path, rec)
    return rec


def _thumbnail(job: WeightsJob, outdir: str, name: str) -> str | None:
    """``thumbs/NAME.png``: the weights of the handle with the most weight (skinrs.plot)."""
    F, mesh = job["mesh"]["F"], job["mesh"]
    if F is None:
        return None
    try:
        from .plot import _plt, plot_weights
    except ImportError:
        return None
    plt = _plt()
    W = job["W"]
    V = mesh["V"]
    col = int(W.sum(0).argmax())
    fig = plot_weights(V, F, W, columns=[col], C=job["C"], BE=job["BE"])
    os.makedirs(os.path.join(outdir, "thumbs"), exist_ok=True)
    path = os.path.join(outdir, "thumbs", f"{name}.png")
    fd, tmp = tempfile.mkstemp(prefix=".skinrs-", suffix=".png", dir=os.path.dirname(path))
    os.close(fd)
    fig.savefig(tmp, dpi=36, format="png")
    plt.close(fig)
    os.replace(tmp, path)
    return os.path.relpath(path, outdir)


# --------------------------------------------------------------------------------------------
# the driver


def _up_to_date(rec_path: str, key: Record, outdir: str, retry_failed: bool) -> Record | None:
    """The stored record when it matches ``key`` (and its output is intact), else None."""
    try:
        with open(rec_path) as fh:
            rec: Record = json.load(fh)
    except (OSError, ValueError):
        return None
    if any(rec.get(k) != v for k, v in key.items()):
        return None
    if rec.get("status") == "failed":
        return None if retry_failed else rec
    out = os.path.join(outdir, rec.get("output", ""))
    return rec if rec.get("status") == "done" and _sha256(out) == rec.get("output_sha256") else None


def _cluster_config(retries: int) -> dict[str, float]:
    # allowed-failures: how often a task may be on a worker that dies before it is given up;
    # worker-saturation 1.0: a worker holds only the task it runs, so a crash blames no other.
    return {"distributed.scheduler.allowed-failures": retries,
            "distributed.scheduler.worker-saturation": 1.0}  # fmt: skip


def run(
    source: str | os.PathLike[str],
    outdir: str | os.PathLike[str],
    *,
    scheduler: str | None = None,
    n_workers: int | None = None,
    memory_limit: str | float | None = "auto",
    retries: int = 1,
    timeout: float | None = None,
    retry_failed: bool = False,
    progress: bool = True,
    **options: Any,
) -> Report:
    """Weights of every asset of ``source`` (directory or manifest) into ``outdir`` on Dask.

    Parameters
    ----------
    source : a directory or a ``.csv`` / ``.jsonl`` manifest (see :func:`find_assets`)
    outdir : results ``NAME.FORMAT``, records ``NAME.json``, ``thumbs/``, ``report.json``,
        ``report.html``; created if missing
    scheduler : ``"tcp://host:port"`` of a running Dask scheduler (outdir and the inputs must be
        visible to its workers at the same paths), or None for a LocalCluster of ``n_workers``
        processes (default: the number of cores), one thread each, ``memory_limit`` each
    retries : how often an asset is retried after an error or a dead worker (default 1)
    timeout : seconds per asset (None: no limit)
    retry_failed : also redo assets whose record says failed (by default a rerun skips them)
    **options : as ``skinrs weights``: ``method``, ``tol``, ``steps``, ``influences``,
        ``reduce_method``, and ``format`` (glb, gltf, dmat, npz, csv); a manifest row overrides

    Returns the report (also ``outdir/report.json``): ``records`` and ``summary``.
    """
    try:
        import dask
        from distributed import Client, LocalCluster, as_completed
    except ImportError as e:
        raise ImportError("skinrs batch needs Dask: pip install 'skinrs[batch]'") from e
    t0 = time.time()
    outdir = os.path.abspath(str(outdir))
    specs = find_assets(source)  # first: a bad source leaves no empty outdir behind
    os.makedirs(outdir, exist_ok=True)
    records: dict[str, Record] = {}
    todo: list[tuple[AssetSpec, Options, Record]] = []
    for spec in specs:
        opts = _options(spec, options)
        key = _key(spec, opts)
        old = _up_to_date(os.path.join(outdir, spec["name"] + ".json"), key, outdir, retry_failed)
        if old is not None:
            records[spec["name"]] = dict(old, skipped=True)
        else:
            todo.append((spec, opts, key))
    bar = _bar(progress, len(specs), len(records))
    cluster: LocalCluster | None = None
    client: Client | None = None
    try:
        with dask.config.set(_cluster_config(retries)):
            if todo and scheduler is None:
                cluster = LocalCluster(n_workers=n_workers or os.cpu_count(), threads_per_worker=1,
                                       processes=True, memory_limit=memory_limit,
                                       dashboard_address=None)  # fmt: skip
            if todo:
                client = Client(scheduler or cluster)
                futures: dict[Future[Record], tuple[AssetSpec, Record]] = {}
                submitted = time.time()
                for spec, opts, key in todo:
                    fut = client.submit(run_asset, spec, opts, key, outdir, timeout, pure=False,
                                        retries=retries, key=f"skinrs-{spec['name']}-{time.time()}")  # fmt: skip
                    futures[fut] = (spec, key)
                # results are fetched as they finish and the futures dropped: a result left on
                # a worker that dies later would be computed again
                done = as_completed(futures, with_results=True, raise_errors=False)
                for fut, res in done:
                    spec, key = futures.pop(fut)
                    records[spec["name"]] = _result(res, spec, key, outdir, submitted)
                    bar(spec["name"], records[spec["name"]]["status"])
    except KeyboardInterrupt:
        bar.close()
        print("skinrs batch: interrupted; finished assets are kept, a rerun continues",
              file=sys.stderr)  # fmt: skip
        raise
    finally:
        if client is not None:
            client.close()
        if cluster is not None:
            cluster.close()
    bar.close()
    ordered = [records[s["name"]] for s in specs]
    return write_report(outdir, ordered, time.time() - t0)


def _result(res: object, spec: AssetSpec, key: Record, outdir: str, submitted: float) -> Record:
    """A finished task's record; a task given up by Dask gets a failed record here."""
    rec_path = os.path.join(outdir, spec["name"] + ".json")
    if isinstance(res, dict):
        return res
    exc = res[1] if isinstance(res, tuple) else res  # (type, exception, traceback) or exception
    reason = f"{type(exc).__name__}: {exc}"
    if type(exc).__name__ == "KilledWorker":
        reason = "its worker process died on every attempt (crash, out of memory or killed)"
        try:  # a timeout writes its own reason before it ends the process
            with open(rec_path) as fh:
                old: Record = json.load(fh)
            if old.get("started", 0) >= submitted and "timed out" in old.get("reason", ""):
                return dict(old)  # (the last attempt's record, with its time)
        except (OSError, ValueError):
            pass
    rec: Record = {"name": spec["name"], "mesh": spec["mesh"], "skeleton": spec["skeleton"], **key,
           "status": "failed", "reason": reason, "started": time.time()}  # fmt: skip
    _write_json(rec_path, rec)
    return rec


class _bar:
    """A tqdm bar over assets (a line per asset without tqdm, nothing with progress=False)."""

    def __init__(self, on: bool, total: int, skipped: int) -> None:
        self.on = on
        self.tqdm: tqdm | None = None
        if on:
            try:
                from tqdm import tqdm

                self.tqdm = tqdm(total=total, initial=skipped, unit="asset", file=sys.stderr)
            except ImportError:
                pass

    def __call__(self, name: str, status: str) -> None:
        if self.tqdm is not None:
            self.tqdm.set_postfix_str(f"{name}: {status}")
            self.tqdm.update(1)
        elif self.on:
            print(f"  {name}: {status}", file=sys.stderr)

    def close(self) -> None:
        if self.tqdm is not None:
            self.tqdm.close()
            self.tqdm = None
