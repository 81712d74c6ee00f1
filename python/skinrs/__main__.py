"""``python -m skinrs``: the command line (see :mod:`skinrs.cli`)."""

import sys

from .cli import main

sys.exit(main())
