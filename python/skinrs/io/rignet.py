"""RigNet rigs (``*_rig.txt``): joints, hierarchy, root and skin weights."""

from __future__ import annotations

import os
from collections.abc import Callable
from typing import Any, cast

import numpy as np
from numpy.typing import NDArray

from ._text import _Source, _to_float, _to_int


def read_rignet_rig(path: str | os.PathLike[str]) -> dict[str, Any]:
    """Read a RigNet rig (``*_rig.txt``): joints, hierarchy, root and per-vertex skin weights.

    Lines: ``joints <name> x y z``, ``root <name>``, ``hier <parent> <child>`` and
    ``skin <vertex> <joint> <w> [<joint> <w> ...]`` (vertex 0-based, one line per vertex).

    Parameters
    ----------
    path : str or pathlib.Path

    Returns
    -------
    rig : dict with
        ``names`` : list of str, joint names in file order;
        ``C`` : (n, 3) float64 joint positions;
        ``BE`` : (k, 2) int64 0-based ``(parent, child)`` joint pairs, in ``hier`` order;
        ``root`` : int, index of the root joint;
        ``W`` : (nverts, n) float64 dense skin weights, one column per **joint** (ordered as
        ``names``), ``nverts`` = the number of ``skin`` lines (ids ``0..nverts-1``, each once).

    Examples
    --------
    >>> rig = read_rignet_rig("smith_ori_rig.txt")        # doctest: +SKIP
    >>> rig["C"].shape, rig["BE"].shape, rig["W"].shape   # doctest: +SKIP
    ((25, 3), (24, 2), (518, 25))
    """
    src = _Source(path)
    names: list[str] = []
    index: dict[str, int] = {}
    C: list[list[float]] = []
    roots: list[tuple[str, int]] = []
    hier: list[tuple[str, str, int]] = []
    skins: list[tuple[int, list[str], int]] = []
    for lineno, raw in enumerate(src.lines, 1):
        s = raw.split()
        if not s or s[0].startswith("#"):
            continue
        key = s[0]
        if key == "joints":
            xyz = [_to_float(t) for t in s[2:]]
            if len(s) != 5 or any(v is None or not np.isfinite(v) for v in xyz):
                raise src.error(lineno, f"expected 'joints <name> x y z', got {raw.strip()!r}")
            if s[1] in index:
                raise src.error(lineno, f"joint {s[1]!r} is defined twice")
            index[s[1]] = len(names)
            names.append(s[1])
            C.append(cast("list[float]", xyz))
        elif key == "root":
            if len(s) != 2:
                raise src.error(lineno, f"expected 'root <name>', got {raw.strip()!r}")
            roots.append((s[1], lineno))
        elif key == "hier":
            if len(s) != 3:
                raise src.error(lineno, f"expected 'hier <parent> <child>', got {raw.strip()!r}")
            hier.append((s[1], s[2], lineno))
        elif key == "skin":
            vid = _to_int(s[1]) if len(s) > 1 else None
            if vid is None or vid < 0 or len(s) < 4 or len(s) % 2 != 0:
                raise src.error(
                    lineno,
                    f"expected 'skin <vertex> <joint> <w> [<joint> <w> ...]', got {raw.strip()!r}",
                )
            skins.append((vid, s[2:], lineno))
        else:
            raise src.error(lineno, f"expected joints/root/hier/skin, got {key!r}")
    if not names:
        raise src.eof_error("no 'joints' line")

    def joint(name: str, lineno: int) -> int:
        if name not in index:
            raise src.error(lineno, f"unknown joint {name!r}")
        return index[name]

    if len(roots) != 1:
        where = roots[1][1] if len(roots) > 1 else len(src.lines)
        raise src.error(where, f"expected exactly one 'root' line, found {len(roots)}")
    root = joint(*roots[0])
    BE = np.array([(joint(p, ln), joint(c, ln)) for p, c, ln in hier], dtype=np.int64).reshape(
        -1, 2
    )
    parent_line: dict[int, int] = {}
    for (_, _, ln), (p, c) in zip(hier, BE.tolist()):
        if p == c:
            raise src.error(ln, f"'hier' makes {names[c]!r} its own parent")
        if c == root or c in parent_line:
            why = "the root" if c == root else f"already a child (line {parent_line[c]})"
            raise src.error(ln, f"'hier' makes {names[c]!r} a child, but it is {why}")
        parent_line[c] = ln
    W = _rignet_skin(src, skins, joint, len(names))
    _rignet_tree(src, names, root, BE)
    return {"names": names, "C": np.array(C, dtype=np.float64), "BE": BE, "root": root, "W": W}


def _rignet_tree(src: _Source, names: list[str], root: int, BE: NDArray[np.int64]) -> None:
    """Every joint hangs from the root through 'hier' lines (no cycle, none missing)."""
    children: dict[int, list[int]] = {}
    for p, c in BE.tolist():
        children.setdefault(p, []).append(c)
    reached = np.zeros(len(names), dtype=bool)
    stack = [root]
    while stack:
        j = stack.pop()
        if not reached[j]:
            reached[j] = True
            stack += children.get(j, [])
    if not reached.all():
        j = int(np.flatnonzero(~reached)[0])
        raise src.eof_error(
            f"joint {names[j]!r} is not connected to the root {names[root]!r} by 'hier' lines "
            "(a cycle, or the file is cut)"
        )


def _rignet_skin(
    src: _Source,
    skins: list[tuple[int, list[str], int]],
    joint: Callable[[str, int], int],
    n: int,
) -> NDArray[np.float64]:
    nverts = len(skins)  # one line per vertex, ids 0..nverts-1 in any order
    W = np.zeros((nverts, n), dtype=np.float64)
    seen = np.zeros(nverts, dtype=bool)
    for vid, pairs, lineno in skins:
        if vid >= nverts:
            raise src.error(
                lineno,
                f"vertex id {vid} is out of range: {nverts} 'skin' lines (one per vertex) "
                f"need ids 0..{nverts - 1}",
            )
        if seen[vid]:
            raise src.error(lineno, f"vertex {vid} has a second 'skin' line")
        seen[vid] = True
        used: set[int] = set()
        for name, wtok in zip(pairs[::2], pairs[1::2]):
            j = joint(name, lineno)
            w = _to_float(wtok)
            if w is None or not np.isfinite(w):
                raise src.error(lineno, f"expected a weight after joint {name!r}, got {wtok!r}")
            if j in used:
                raise src.error(lineno, f"joint {name!r} appears twice for vertex {vid}")
            used.add(j)
            W[vid, j] = w
        total = W[vid].sum()
        if abs(total - 1.0) > 1e-3:
            raise src.error(
                lineno, f"the weights of vertex {vid} sum to {total:.6g}, not 1 (a cut line?)"
            )
    return W
