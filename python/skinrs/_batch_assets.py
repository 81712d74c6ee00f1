"""Assets of a batch run: discovery (a directory or a manifest), per-asset options and the key
a result depends on. Used by :mod:`skinrs.batch`; design in ``docs/batch.md``."""

from __future__ import annotations

import csv
import hashlib
import json
import os
from typing import Any, TypedDict

from ._cli_io import MESH_EXTS, UsageError, _ext

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
