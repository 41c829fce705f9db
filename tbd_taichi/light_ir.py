"""Kernels compiled without Taichi's advanced IR passes: the ones marked by ``kernels.loops.light_ir``.

Taichi compiles a kernel at its first launch (``Kernel.launch_kernel``) with the runtime's compile config, and keys
both its in-memory and its offline cache on that config.  :func:`install` wraps the launch so that a marked
kernel's launches see ``advanced_optimization=False`` (and the config as it was afterwards): the kernel is built,
cached and found again under that setting in every process, while every other kernel keeps Taichi's default.
On the CPU backends only: the effect was measured there, and a GPU build keeps Taichi's default.
``backend.init`` installs it.  Why and which kernels: ``kernels.loops.light_ir``."""
from __future__ import annotations

import taichi as ti

from .kernels.loops import LIGHT_IR

CPU_ARCHS = (ti.x64, ti.arm64)  # where the mark applies (measured there; GPU backends keep Taichi's default)
_ORIGINAL: dict = {}  # "launch_kernel" -> the launch wrapped, while installed


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
        launch = _ORIGINAL["launch_kernel"]
        config = impl.current_cfg()
        if not getattr(self, LIGHT_IR, False) or config.arch not in CPU_ARCHS:
            return launch(self, t_kernel, *args)
        before = config.advanced_optimization
        config.advanced_optimization = False
        try:
            return launch(self, t_kernel, *args)
        finally:
            config.advanced_optimization = before

    _ORIGINAL["launch_kernel"] = Kernel.launch_kernel
    Kernel.launch_kernel = launch_kernel
    return True


def installed() -> bool:
    """Whether :func:`install` is in effect."""
    return bool(_ORIGINAL)
