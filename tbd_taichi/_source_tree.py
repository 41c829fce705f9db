"""Running from a source checkout: ``kernels/`` sits beside ``tbd_taichi/`` in the repository (the design's
top level) and installs as ``tbd_taichi.kernels``.  In a checkout nothing puts it there, so when the package is
imported from the repository root (``python -m tbd_taichi``, ``python -m pytest``, with or without an
install), :func:`mount_kernels` loads ``../kernels`` as ``tbd_taichi.kernels``."""
from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

PACKAGE = "tbd_taichi"


def mount_kernels() -> None:
    """Register the checkout's ``kernels/`` as ``tbd_taichi.kernels`` where the package has no ``kernels``
    subpackage of its own (an installed package has one; a checkout does not)."""
    here = Path(__file__).resolve().parent
    name = f"{PACKAGE}.kernels"
    source = here.parent / "kernels"
    if name in sys.modules or (here / "kernels" / "__init__.py").is_file() or not (source / "__init__.py").is_file():
        return
    spec = importlib.util.spec_from_file_location(name, source / "__init__.py", submodule_search_locations=[str(source)])
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    setattr(sys.modules[PACKAGE], "kernels", module)  # as an import of the subpackage would
