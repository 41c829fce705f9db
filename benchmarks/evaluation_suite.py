"""The Monte Carlo evaluation of the SGDS-PF paper's section 3.3, written to docs/results/.

Same as ``tbd-taichi evaluate-suite --out-dir docs/results [options]``; any option of that
command can be passed (for example ``--tests 10`` or ``--quick``).

    python benchmarks/evaluation_suite.py [--tests N] [--workers N] ...
"""
import os
import sys
from pathlib import Path

from tbd_taichi import cli

OUT = Path(__file__).resolve().parent.parent / "docs" / "results"

if __name__ == "__main__":
    sys.exit(cli.main(["evaluate-suite", "--out-dir", os.path.relpath(OUT)] + sys.argv[1:]))
