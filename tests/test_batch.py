"""``skinrs batch`` on Dask: a LocalCluster and a dask-scheduler with two dask-workers.

The batch: six generated capsules, the decimated knight (tests/data), one asset poisoned to end
its worker process (the documented test hook of skinrs.batch) and one malformed OBJ. Each good
result must equal ``skinrs weights`` run on its own.
"""

import csv
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip(
    "distributed", reason="skinrs batch needs Dask: pip install 'skinrs[batch]' (make venv does)"
)

import skinrs
from skinrs import batch, cli

TOL = "1e-6"
GOOD = [f"capsule-{i}" for i in range(6)] + ["knight"]


def capsule(d: Path, i: int) -> tuple[Path, Path]:
    import trimesh

    height, radius = 1.2 + 0.2 * i, 0.25 + 0.03 * (i % 3)
    mesh = trimesh.creation.capsule(height=height, radius=radius, count=[8, 8])
    mesh.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, [0, 1, 0]))
    skinrs.io.write_obj(d / f"capsule-{i}.obj", np.asarray(mesh.vertices), np.asarray(mesh.faces))
    x = height / 2
    C = [[-x, 0, 0], [0, 0, 0], [x, 0, 0]] if i % 2 else [[-x, 0, 0], [-x / 3, 0, 0],
                                                        [x / 3, 0, 0], [x, 0, 0]]  # fmt: skip
    BE = [[j, j + 1] for j in range(len(C) - 1)]
    skinrs.io.write_tgf(d / f"capsule-{i}.tgf", C, BE)
    return d / f"capsule-{i}.obj", d / f"capsule-{i}.tgf"


@pytest.fixture(scope="module")
def library(tmp_path_factory, data_dir):
    """The manifest (CSV) and, per good asset, ``(mesh, skeleton)``."""
    d = tmp_path_factory.mktemp("library")
    pairs = {f"capsule-{i}": capsule(d, i) for i in range(6)}
    knight = data_dir / "decimated-knight"
    for f in ("decimated-knight.mesh", "decimated-knight.tgf"):
        shutil.copy(knight / f, d / f)
    pairs["knight"] = (d / "decimated-knight.mesh", d / "decimated-knight.tgf")
    (d / "bad.obj").write_text("v 0 0 0\nf 1 2 3\n")
    rows = [{"name": n, "mesh": m.name, "skeleton": s.name} for n, (m, s) in pairs.items()]
    rows.append({"name": "poisoned", "mesh": "capsule-0.obj", "skeleton": "capsule-0.tgf",
                 batch.TEST_HOOK_KEY: "1"})  # fmt: skip
    rows.append({"name": "malformed", "mesh": "bad.obj", "skeleton": "capsule-0.tgf"})
    with open(d / "assets.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, ["name", "mesh", "skeleton", batch.TEST_HOOK_KEY])
        w.writeheader()
        w.writerows(rows)
    return d / "assets.csv", pairs


@pytest.fixture(scope="module")
def references(library, tmp_path_factory):
    """``skinrs weights MESH SKELETON --tol 1e-6 -o NAME.dmat`` of each good asset."""
    out = tmp_path_factory.mktemp("reference")
    W = {}
    for name, (mesh, skel) in library[1].items():
        assert cli.main(["-q", "weights", str(mesh), str(skel), "--tol", TOL,
                         "-o", str(out / f"{name}.dmat")]) == 0  # fmt: skip
        W[name] = skinrs.io.read_dmat(out / f"{name}.dmat")
    return W


def check_first_run(report, outdir, references):
    recs = {r["name"]: r for r in report["records"]}
    s = report["summary"]
    assert (s["done"], s["failed"], s["skipped"]) == (7, 2, 0), batch.summary_table(report)
    for name in GOOD:
        assert recs[name]["status"] == "done"
        np.testing.assert_array_equal(skinrs.io.read_dmat(outdir / f"{name}.dmat"),
                                      references[name])  # fmt: skip
        rec = json.loads((outdir / f"{name}.json").read_text())
        assert rec["options"]["tol"] == 1e-6 and rec["peak_rss_mb"] > 50
        assert rec["gap"] <= 1e-6 and rec["energy"] > 0
        assert set(rec["inputs"]) == {"mesh", "skeleton"} and rec["skinrs_version"]
        assert (outdir / rec["thumbnail"]).read_bytes()[:4] == b"\x89PNG"
    assert "worker process died" in recs["poisoned"]["reason"]
    assert "out of range" in recs["malformed"]["reason"]
    assert not (outdir / "poisoned.dmat").exists() and not (outdir / "malformed.dmat").exists()
    page = (outdir / "report.html").read_text()
    assert page.count("<img") == 7 and "out of range" in page and "worker process died" in page
    assert json.loads((outdir / "report.json").read_text())["summary"]["failed"] == 2
    assert not list(outdir.glob(".skinrs-*"))


def test_batch_on_a_local_cluster_records_failures_and_resumes(
    library, references, tmp_path, monkeypatch
):
    monkeypatch.setenv(batch.TEST_HOOK_ENV, "1")
    manifest, _ = library
    out = tmp_path / "out"
    report = batch.run(manifest, out, n_workers=2, memory_limit="3GB", tol=1e-6, format="dmat",
                       progress=False)  # fmt: skip
    check_first_run(report, out, references)

    # a second run, from the command line: nothing to do (no cluster is started)
    stamps = {p: p.stat().st_mtime_ns for p in out.glob("*.*") if not p.name.startswith("report")}
    run = subprocess.run(
        [sys.executable, "-m", "skinrs", "-q", "batch", manifest, "-o", out, "--tol", TOL,
         "--format", "dmat", "--workers", "2"],
        capture_output=True, text=True, timeout=120, check=False,
    )  # fmt: skip
    assert run.returncode == 0, run.stderr
    assert "0 done, 0 failed, 9 skipped" in run.stdout, run.stdout
    assert {p: p.stat().st_mtime_ns for p in stamps} == stamps

    # one output deleted: only that asset is computed again
    (out / "capsule-3.dmat").unlink()
    report = batch.run(manifest, out, n_workers=1, tol=1e-6, format="dmat", progress=False)
    s = report["summary"]
    assert (s["done"], s["failed"], s["skipped"]) == (1, 0, 8), batch.summary_table(report)
    np.testing.assert_array_equal(skinrs.io.read_dmat(out / "capsule-3.dmat"),
                                  references["capsule-3"])  # fmt: skip
    changed = [p.name for p, t in stamps.items() if p.exists() and p.stat().st_mtime_ns != t]
    assert sorted(changed) == ["capsule-3.dmat", "capsule-3.json"]


def test_memory_estimate_refuses_an_asset_that_cannot_fit(library, tmp_path):
    manifest, _ = library
    spec = next(s for s in batch.find_assets(manifest) if s["name"] == "knight")
    opts = batch._options(spec, {"format": "dmat"})
    rec = batch.run_asset(spec, opts, batch._key(spec, opts), str(tmp_path), memory_limit=200e6)
    assert rec["status"] == "failed" and "more than the worker's memory limit" in rec["reason"]
    assert json.loads((tmp_path / "knight.json").read_text())["status"] == "failed"
    assert not (tmp_path / "knight.dmat").exists()


def test_the_solve_keeps_within_what_the_worker_has_left(library, tmp_path, monkeypatch):
    # Past the estimate, the solve is given the worker's limit less what the process holds:
    # here about nothing, so BBW refuses before factoring, and the record says why.
    import psutil

    manifest, _ = library
    spec = next(s for s in batch.find_assets(manifest) if s["name"] == "knight")
    opts = batch._options(spec, {"format": "dmat"})
    monkeypatch.setattr(batch, "estimate_peak_bytes", lambda *args: 0)
    limit = psutil.Process().memory_info().rss + 10_000
    rec = batch.run_asset(spec, opts, batch._key(spec, opts), str(tmp_path), memory_limit=limit)
    assert rec["status"] == "failed", rec
    assert rec["reason"].startswith("MemoryError: memory_limit: the Cholesky factor of B_ff")
    assert not (tmp_path / "knight.dmat").exists()


def _stop(procs):
    for p in procs:
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGTERM)
    for p in procs:
        try:
            p.wait(timeout=20)
        except subprocess.TimeoutExpired:
            os.killpg(p.pid, signal.SIGKILL)
            p.wait(timeout=20)


def test_batch_through_a_dask_scheduler_and_two_workers(library, references, tmp_path):
    env = dict(os.environ, DASK_DISTRIBUTED__SCHEDULER__ALLOWED_FAILURES="1",
               DASK_DISTRIBUTED__SCHEDULER__WORKER_SATURATION="1.0")  # fmt: skip
    env[batch.TEST_HOOK_ENV] = "1"
    sched_file = tmp_path / "scheduler.json"
    with open(tmp_path / "dask.log", "w") as log:
        run_on_cluster(library, references, tmp_path, sched_file, log, env)


def run_on_cluster(library, references, tmp_path, sched_file, log, env):
    dask = Path(sys.executable).parent / "dask"
    common = {"env": env, "start_new_session": True, "stdout": log, "stderr": log}
    procs = [subprocess.Popen([dask, "scheduler", "--host", "127.0.0.1", "--port", "0",
                               "--no-dashboard", "--scheduler-file", sched_file], **common)]  # fmt: skip
    try:
        address, deadline = None, time.monotonic() + 60
        while address is None and time.monotonic() < deadline:
            time.sleep(0.2)
            try:
                address = json.loads(sched_file.read_text())["address"]
            except (OSError, ValueError, KeyError):
                pass
        assert address is not None, "dask scheduler did not start within 60 s"
        assert address.startswith("tcp://127.0.0.1:")
        for _ in range(2):
            procs.append(subprocess.Popen(
                [dask, "worker", address, "--nthreads", "1", "--host", "127.0.0.1",
                 "--no-dashboard", "--memory-limit", "3GB"], **common))  # fmt: skip
        from distributed import Client

        with Client(address, timeout=60) as client:
            client.wait_for_workers(2, timeout=60)
        out = tmp_path / "out"
        run = subprocess.run(
            [sys.executable, "-m", "skinrs", "-q", "batch", library[0], "-o", out, "--tol", TOL,
             "--format", "dmat", "--scheduler", address],
            capture_output=True, text=True, timeout=240, check=False,
        )  # fmt: skip
        assert run.returncode == 1, run.stderr  # (two assets failed)
        report = json.loads((out / "report.json").read_text())
        check_first_run(report, out, references)
    finally:
        _stop(procs)
