"""The one place that chooses the engine: ``"taichi"`` (the kernels of ``tbd_taichi.kernels``) or ``"numpy"``
(their vectorised twins in ``tbd_taichi.numpy_kernels``, same names and contracts).  Schedulers ask
:func:`kernel_module` for the module of a concept and use what it holds the same way on either engine."""
from __future__ import annotations

import importlib
from types import ModuleType

from .errors import ParameterError

ENGINES = ("taichi", "numpy")


def check_engine(engine: str) -> str:
    """``engine`` if it is one of ENGINES, else a ParameterError listing them."""
    if engine not in ENGINES:
        raise ParameterError(f"engine must be one of {', '.join(ENGINES)}, got {engine!r}")
    return engine


def kernel_module(engine: str, concept: str, arch: str | None = None) -> ModuleType:
    """The module of ``concept`` (e.g. "background", "particles") for ``engine``: ``tbd_taichi.kernels.<concept>``
    (with the Taichi runtime started on ``arch`` if it is not yet) or ``tbd_taichi.numpy_kernels.<concept>``."""
    if check_engine(engine) == "taichi":
        from . import backend

        backend.ensure_init(arch)
        return importlib.import_module(f"tbd_taichi.kernels.{concept}")
    return importlib.import_module(f"tbd_taichi.numpy_kernels.{concept}")


def frame_kernels(owner, engine: str, concept: str, name: str, dims: tuple, shape, arch: str | None = None):
    """``owner``'s instance of class ``name`` of ``concept``'s module for ``engine``, made with ``dims`` (the
    frame's ``shape`` (H, W) among them).  NumPy's is made anew.  Taichi's fields take the extents of the frame's
    size class (``kernels.loops.FrameSize``): they come from a finished owner of the same dims but for a frame of
    the same class (``backend.reusable``: no recompilation; then set to ``shape``) or are made for ``shape``, and
    are launched by the lean path."""
    cls = getattr(kernel_module(engine, concept, arch), name)
    if engine == "numpy":
        return cls(*dims)
    from . import backend
    from .kernels.loops import frame_class
    from .launch import Launcher

    shape = (int(shape[0]), int(shape[1]))
    key = (concept, name, frame_class(shape)) + tuple(v for v in dims if v != shape)
    fields = backend.reusable(owner, key, lambda: cls(*dims))
    if backend.holds_old_values(fields):  # lent: its frame size is its last owner's
        fields.set_frame_size(shape)
    return Launcher(fields)
