"""``python -m tbd_taichi`` is the ``tbd-taichi`` command."""
import sys

from .cli import main

sys.exit(main())
