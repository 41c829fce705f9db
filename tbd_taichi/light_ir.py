"""Kernels compiled without Taichi's advanced IR passes: the ones marked by ``kernels.loops.light_ir``.

Taichi compiles a kernel at its first launch (``Kernel.launch_kernel``) with the runtime's compile config; the
offline cache's key holds that config (Taichi 1.7 computes a kernel's key once and keeps it on the kernel, so a
later ``compile_kernel`` of the same kernel finds the same build).  :func:`install` wraps the launch, and
``launch.FastKernel`` its own look-up, in :func:`compile_setting`: a marked kernel is built, cached and found again
with ``advanced_optimization=False`` in every process, and the config is as it was afterwards; every other kernel
keeps Taichi's default.  On the CPU backends only: the effect was measured there, and a GPU build keeps Taichi's
default.  ``tbd_taichi.backend`` installs it when it is imported.  Why and which kernels:
``kernels.loops.light_ir``."""
from __future__ import annotations

import contextlib

import taichi as ti

from .kernels.loops import LIGHT_IR

CPU_ARCHS = (ti.x64, ti.arm64)  # where the mark applies (measured there; GPU backends keep Taichi's default)
_ORIGINAL: dict = {}  # "launch_kernel" -> the launch wrapped, while installed


@contextlib.contextmanager
def compile_setting(kernel):
    """The compile config as ``kernel`` (Taichi's ``Kernel``) is built and looked up under: for a marked kernel on
    a CPU backend, ``advanced_optimization=False`` inside the block and the runtime's setting again after it; for
    any other kernel the config as it is.  Every ``compile_kernel`` of a marked kernel runs inside it (Taichi's
    launch through :func:`install`, ``launch.FastKernel``'s look-up), so the kernel is never built or found under
    the other setting."""
    from taichi.lang import impl

    config = impl.current_cfg()
    if not getattr(kernel, LIGHT_IR, False) or config.arch not in CPU_ARCHS:
        yield
        return
    before = config.advanced_optimization
    config.advanced_optimization = False
    try:
        yield
    finally:
        config.advanced_optimization = before


def install() -> bool:
    """Wrap Taichi's kernel launch once (idempotent); False where this Taichi lacks the names it needs."""
    if _ORIGINAL:
        return True
    try:
        from taichi.lang import impl
        from taichi.lang.kernel_impl import Kernel
    except ImportError:  # pragma: no cover - another Taichi layout
        return False
    if not hasattr(Kernel, "launch_kernel") or not hasattr(impl, "current_cfg"):
        return False

    def launch_kernel(self, t_kernel, *args):
        with compile_setting(self):
            return _ORIGINAL["launch_kernel"](self, t_kernel, *args)

    _ORIGINAL["launch_kernel"] = Kernel.launch_kernel
    Kernel.launch_kernel = launch_kernel
    return True


def installed() -> bool:
    """Whether :func:`install` is in effect."""
    return bool(_ORIGINAL)
