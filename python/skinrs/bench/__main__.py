"""Dispatch ``python -m skinrs.bench NAME [args]`` to ``skinrs.bench.NAME.main(args)``."""

import importlib
import sys

NAMES = ("bbw", "field", "lbs", "reduce", "scale")


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] not in NAMES:
        print(f"usage: python -m skinrs.bench {{{','.join(NAMES)}}} [options]", file=sys.stderr)
        return 2
    mod = importlib.import_module(f"skinrs.bench.{argv[0]}")
    return int(mod.main(argv[1:]) or 0)


if __name__ == "__main__":
    sys.exit(main())
