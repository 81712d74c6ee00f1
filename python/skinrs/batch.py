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
import csv
import hashlib
import html
import json
import os
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, Literal, TypedDict

from ._cli_io import MESH_EXTS, UsageError, _ext

if TYPE_CHECKING:
    from distributed import Future
    from tqdm import tqdm
    from typing_extensions import Self

    from ._cli_commands import WeightsJob

#: The options of ``skinrs weights`` by name, as the command line, a .csv or a .jsonl manifest
#: give them (str, float, int or None).
Options = dict[str, Any]
#: A JSON object: an asset's record (``NAME.json``) or what a result depends on.
Record = dict[str, Any]

OPTION_DEFAULTS: Options = {
    "method": "bbw",
    "tol": None,
    "steps": None,
    "influences": None,
    "reduce_method": "poisson",
    "format": "glb",
}
FORMATS = ("glb", "gltf", "dmat", "npz", "csv")
# Documented test hook: with SKINRS_BATCH_TEST_HOOKS=1 in a worker's environment, an asset whose
# manifest row sets crash_worker_for_testing ends its worker process at once, as a segfaulting
# mesher would (tests/test_batch.py). Without the variable the column is an error.
TEST_HOOK_ENV = "SKINRS_BATCH_TEST_HOOKS"
TEST_HOOK_KEY = "crash_worker_for_testing"


class AssetSpec(TypedDict):
    """One asset: its ``name`` (of its output files), ``mesh`` and ``skeleton`` paths and its
    own ``options`` (a manifest row's overrides)."""

    name: str
    mesh: str
    skeleton: str | None
    options: Options


class Summary(TypedDict):
    """The counts of a batch run and its wall-clock ``seconds``."""

    assets: int
    done: int
    failed: int
    skipped: int
    failed_total: int
    seconds: float


class Report(TypedDict):
    """What :func:`run` returns (also ``report.json``): the ``summary`` and a record per asset."""

    summary: Summary
    records: list[Record]


# --------------------------------------------------------------------------------------------
# assets


def find_assets(source: str | os.PathLike[str]) -> list[AssetSpec]:
    """Asset specs ``dict(name, mesh, skeleton, options)`` from a directory or a manifest.

    A directory is searched recursively: a mesh file with a skeleton of the same stem
    (``STEM.tgf``, ``STEM_rig.txt`` or ``STEM.txt``) is one asset, and so is a ``.glb/.gltf``
    without one (its skin gives the skeleton). A manifest is ``.csv`` (header row) or ``.jsonl``
    with a ``mesh`` column, optional ``skeleton`` and ``name``, and per-asset overrides of the
    options (``method``, ``tol``, ``steps``, ``influences``, ``reduce_method``, ``format``);
    relative paths are relative to the manifest.
    """
    source = os.path.abspath(str(source))
    rows: list[dict[str, Any]]
    if os.path.isdir(source):
        rows = _scan_directory(source)
    elif _ext(source) == ".csv":
        with open(source, newline="") as fh:
            rows = [{k: v for k, v in r.items() if v not in ("", None)} for r in csv.DictReader(fh)]
    elif _ext(source) in (".jsonl", ".json"):
        with open(source) as fh:
            rows = [json.loads(line) for line in fh if line.strip()]
    else:
        raise UsageError(f"{source}: not a directory, .csv or .jsonl manifest")
    base = source if os.path.isdir(source) else os.path.dirname(source)
    specs: list[AssetSpec] = []
    seen: set[str] = set()
    for i, row in enumerate(rows):
        if "mesh" not in row:
            raise UsageError(f"{source}: row {i + 1} has no 'mesh'")
        row = dict(row)
        mesh = os.path.join(base, row.pop("mesh"))
        skel = row.pop("skeleton", None)
        name = str(row.pop("name", None) or _default_name(base, mesh))
        if not name or "/" in name or os.sep in name or name.startswith("."):
            raise UsageError(f"{source}: row {i + 1}: {name!r} is not a file name")
        if name in seen:
            raise UsageError(f"{source}: two assets are named {name!r}; give a 'name' column")
        seen.add(name)
        unknown = set(row) - set(OPTION_DEFAULTS) - {TEST_HOOK_KEY}
        if unknown:
            raise UsageError(f"{source}: row {i + 1}: unknown column(s) {sorted(unknown)}")
        specs.append({"name": name, "mesh": mesh, "skeleton": skel and os.path.join(base, skel),
                      "options": row})  # fmt: skip
    return specs


def _scan_directory(root: str) -> list[dict[str, Any]]:
    rows: list[dict[str, Any]] = []
    for d, dirs, files in os.walk(root):
        dirs.sort()
        names = set(files)
        for f in sorted(files):
            stem, ext = os.path.splitext(f)
            if ext.lower() not in MESH_EXTS:
                continue
            skel = next((s for s in (stem + ".tgf", stem + "_rig.txt", stem + ".txt")
                         if s in names), None)  # fmt: skip
            if skel is None and ext.lower() not in (".glb", ".gltf"):
                continue
            row = {"mesh": os.path.relpath(os.path.join(d, f), root)}
            if skel is not None:
                row["skeleton"] = os.path.relpath(os.path.join(d, skel), root)
            rows.append(row)
    return rows


def _default_name(base: str, mesh: str) -> str:
    rel = os.path.relpath(mesh, base)
    stem = os.path.splitext(rel)[0] if not rel.startswith("..") else os.path.basename(mesh)
    return stem.replace(os.sep, "--")


def _options(spec: AssetSpec, common: Options) -> Options:
    opts = dict(OPTION_DEFAULTS)
    opts.update({k: v for k, v in common.items() if v is not None})
    opts.update(spec["options"])
    for key, cast in (("tol", float), ("steps", int), ("influences", int)):
        if opts[key] is not None:
            opts[key] = cast(opts[key])
    opts.pop(TEST_HOOK_KEY, None)
    if opts["format"] not in FORMATS:
        raise UsageError(f"{spec['name']}: format {opts['format']!r} is not one of {FORMATS}")
    return opts


def _sha256(path: str | None) -> str | None:
    if path is None or not os.path.isfile(path):
        return None
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _key(spec: AssetSpec, opts: Options) -> Record:
    """What a result depends on: the inputs' contents, the options and skinrs' version."""
    from . import __version__

    return {
        "inputs": {"mesh": _sha256(spec["mesh"]), "skeleton": _sha256(spec["skeleton"])},
        "options": opts,
        "skinrs_version": __version__,
    }


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


def _write_json(path: str, obj: object) -> None:
    d = os.path.dirname(path)
    fd, tmp = tempfile.mkstemp(prefix=".skinrs-", suffix=".json", dir=d)
    try:
        with os.fdopen(fd, "w") as fh:
            json.dump(obj, fh, indent=1, default=float)
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)


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
    except (UsageError, ValueError, OSError) as e:
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
    os.makedirs(outdir, exist_ok=True)
    specs = find_assets(source)
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


# --------------------------------------------------------------------------------------------
# reports


def write_report(outdir: str, records: list[Record], seconds: float) -> Report:
    """``report.json`` and ``report.html`` in ``outdir``; returns the report."""
    done = [r for r in records if r["status"] == "done" and not r.get("skipped")]
    failed = [r for r in records if r["status"] == "failed" and not r.get("skipped")]
    summary: Summary = {"assets": len(records), "done": len(done), "failed": len(failed),
               "skipped": sum(bool(r.get("skipped")) for r in records),
               "failed_total": sum(r["status"] == "failed" for r in records),
               "seconds": seconds}  # fmt: skip
    report: Report = {"summary": summary, "records": records}
    _write_json(os.path.join(outdir, "report.json"), report)
    fd, tmp = tempfile.mkstemp(prefix=".skinrs-", suffix=".html", dir=outdir)
    with os.fdopen(fd, "w") as fh:
        fh.write(_html(summary, records))
    os.replace(tmp, os.path.join(outdir, "report.html"))
    return report


def _html(summary: Summary, records: list[Record]) -> str:
    e = html.escape
    rows = []
    for r in records:
        thumb = r.get("thumbnail")
        img = f'<img src="{e(thumb)}" height="120">' if thumb else ""
        gap = "" if r.get("gap") is None else f"{r['gap']:.1e}"
        what = e(r.get("reason", "")) if r["status"] == "failed" else e(r.get("output", ""))
        status = r["status"] + (" (earlier run)" if r.get("skipped") else "")
        rows.append(f"<tr class={r['status']}><td>{e(r['name'])}</td><td>{status}</td>"
                    f"<td>{r.get('seconds', 0):.1f}</td><td>{gap}</td>"
                    f"<td>{r.get('peak_rss_mb', 0):.0f}</td><td>{what}</td><td>{img}</td></tr>")  # fmt: skip
    seconds = round(summary["seconds"], 1)
    head = ", ".join(f"{k} {v if k != 'seconds' else seconds}" for k, v in summary.items())
    return ("<!doctype html><meta charset=utf-8><title>skinrs batch</title><style>"
            "td{padding:2px 8px;vertical-align:middle}.failed{background:#fdd}</style>"
            f"<h1>skinrs batch</h1><p>{e(head)}</p><table><tr><th>asset<th>status<th>s"
            "<th>gap<th>peak MB<th>output / reason<th>weights</tr>"
            + "\n".join(rows) + "</table>\n")  # fmt: skip


def summary_table(report: Report) -> str:
    """The report as a plain-text table (one line per asset, then the totals)."""
    lines = [f"{'asset':<32} {'status':<8} {'s':>7}  output / reason"]
    for r in report["records"]:
        status = "skipped" if r.get("skipped") else r["status"]
        what = r.get("reason") if r["status"] == "failed" else r.get("output")
        lines.append(f"{r['name']:<32} {status:<8} {r.get('seconds', 0):7.1f}  {what}")
    s = report["summary"]
    lines.append(f"{s['done']} done, {s['failed']} failed, {s['skipped']} skipped "
                 f"in {s['seconds']:.1f} s")  # fmt: skip
    return "\n".join(lines)
