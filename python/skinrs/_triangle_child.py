"""Entry point of the child process that runs Triangle: ``in.npz out.npz memory-limit``.

Run as a script (not through the ``skinrs`` package, whose import costs more than the mesh).
``in.npz`` holds ``vertices``, ``segments`` and ``switches``; ``out.npz`` gets ``vertices`` and
``triangles``. The address space is capped at ``memory-limit`` bytes, so Triangle's quality
refinement, which loops on some inputs, fails instead of filling the machine's memory.
"""

import sys

import numpy as np


def main() -> None:
    inp, out, limit = sys.argv[1:4]
    try:
        import resource

        resource.setrlimit(resource.RLIMIT_AS, (int(limit), int(limit)))
    except (ImportError, ValueError, OSError):  # no such limit on this platform
        pass
    import triangle

    with np.load(inp) as d:
        pslg = {"vertices": d["vertices"], "segments": d["segments"]}
        switches = str(d["switches"])
    try:
        res = triangle.triangulate(pslg, switches)
    except RuntimeError as e:  # "Triangulation failed -- probably because of invalid geometry"
        print(e, file=sys.stderr)
        sys.exit(3)
    np.savez(out, vertices=res["vertices"], triangles=res["triangles"])


if __name__ == "__main__":
    main()
