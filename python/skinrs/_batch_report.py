"""Reports of a batch run: ``report.json``, ``report.html`` and the plain-text summary table.
Used by :mod:`skinrs.batch`; design in ``docs/batch.md``."""

from __future__ import annotations

import html
import json
import os
import tempfile
from typing import TypedDict

from ._batch_assets import Record


class Summary(TypedDict):
    """The counts of a batch run and its wall-clock ``seconds``."""

    assets: int
    done: int
    failed: int
    skipped: int
    failed_total: int
    seconds: float


class Report(TypedDict):
    """What :func:`skinrs.batch.run` returns (also ``report.json``): the ``summary`` and a record per asset."""

    summary: Summary
    records: list[Record]


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
