"""``python -m bench.report``: ``pyclpt bench`` from a checkout."""
import sys

from .report import main

sys.exit(main(sys.argv[1:]))
