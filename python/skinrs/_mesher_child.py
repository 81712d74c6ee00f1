"""Entry point of the child process that runs Triangle or TetGen:
``triangle|tetgen in.npz out.npz memory-limit``.

Run as a script (not through the ``skinrs`` package, whose import costs more than the mesh).
Both C libraries can crash or corrupt the heap on some inputs (Triangle on near-coincident
points, TetGen on slightly bent planar faces), and Triangle's quality refinement loops on
crossing segments; in a child process that is an exit code for the caller. The address space
is capped at ``memory-limit`` bytes, so a loop fails instead of filling the machine's memory.

``in.npz``: ``vertices``, ``segments`` and ``switches`` (Triangle), or ``points`` (the first
``n_surface`` on the surface), ``faces``, ``switches``, ``check`` and ``check_only`` (TetGen:
first look for self-intersections of the bare surface, and stop when there are some).
``out.npz``: ``vertices`` and ``elements``, or ``self_intersects`` (TetGen's check). A mesher
error goes to stderr (its message) with exit code 3.
"""

import sys
from typing import Any

import numpy as np

Arrays = dict[str, Any]


def _triangle(d: Arrays) -> Arrays:
    import triangle

    pslg = {"vertices": d["vertices"], "segments": d["segments"]}
    res = triangle.triangulate(pslg, str(d["switches"]))
    return {"vertices": res["vertices"], "elements": res["triangles"]}


def _tetgen(d: Arrays) -> Arrays:
    import tetgen

    V, F = d["points"], d["faces"]
    n = int(d["n_surface"])
    if bool(d["check"]) or bool(d["check_only"]):
        # TetGen, given a self-intersecting surface *and* points to insert, can abort; on the
        # bare surface (switch d) it reports the intersections cleanly
        try:
            tetgen.TetGen(V[:n], F).tetrahedralize(switches="dQ")
        except RuntimeError as e:  # "The input surface mesh contain self-intersections."
            if "self-intersect" in str(e):
                return {"self_intersects": np.array(True)}
        if bool(d["check_only"]):
            return {"self_intersects": np.array(False)}
    VV, TT = tetgen.TetGen(V, F).tetrahedralize(switches=str(d["switches"]))[:2]
    return {"vertices": np.array(VV, dtype=np.float64), "elements": np.array(TT, dtype=np.int64)}


def main() -> None:
    mode, inp, out, limit = sys.argv[1:5]
    try:
        import resource

        resource.setrlimit(resource.RLIMIT_AS, (int(limit), int(limit)))
    except (ImportError, ValueError, OSError):  # no such limit on this platform
        pass
    with np.load(inp) as d:
        arrays = {k: d[k] for k in d.files}
    try:
        res = {"triangle": _triangle, "tetgen": _tetgen}[mode](arrays)
    except RuntimeError as e:  # the mesher's own error ("Triangulation failed", ...)
        print(e, file=sys.stderr)
        sys.exit(3)
    np.savez(out, **res)


if __name__ == "__main__":
    main()
