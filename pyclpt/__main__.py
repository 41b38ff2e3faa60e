"""``python -m pyclpt``: the ``pyclpt`` command line (:mod:`pyclpt.cli`)."""
from __future__ import annotations

import sys

from pyclpt.cli import main

if __name__ == "__main__":
    sys.exit(main())
