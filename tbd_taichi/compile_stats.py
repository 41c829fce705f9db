"""How much of a run went to building kernels: Taichi compiles a kernel at its first call, in two steps that
:func:`compile_totals` counts from the moment :func:`start_counting` is called:

* **front end** (``Kernel.materialize``): the Python AST to Taichi IR, in every process (the offline cache is keyed
  on that IR); ``kernels`` counts the kernel instances built;
* **first launch** (``Kernel.launch_kernel`` of a new instance): compilation to machine code, or its load from the
  offline cache and JIT linking, plus the first run.

The counters are process-wide; :class:`CompileCounts` differences two readings.  Taichi writes the offline cache
when its runtime ends (``ti.reset`` or exit), so the files it gained are counted after that
(:func:`cache_file_count`, as ``tbd-taichi warmup`` does)."""
from __future__ import annotations

import os
import time
from dataclasses import dataclass

_TOTALS = {"kernels": 0, "front_end_s": 0.0, "first_launches": 0, "first_launch_s": 0.0}
_LAUNCHED: set = set()  # ids of compiled kernel instances launched at least once
_WRAPPED: dict = {}


@dataclass(frozen=True)
class CompileCounts:
    """Kernels built and seconds spent building them."""

    kernels: int = 0
    front_end_s: float = 0.0
    first_launches: int = 0
    first_launch_s: float = 0.0

    @property
    def seconds(self) -> float:
        """Front end plus first launches (s)."""
        return self.front_end_s + self.first_launch_s

    def since(self, before: "CompileCounts") -> "CompileCounts":
        """What was added after ``before``."""
        return CompileCounts(*(getattr(self, f) - getattr(before, f) for f in self.__dataclass_fields__))

    def as_dict(self) -> dict:
        """JSON fields: kernels, compile_s (front end + first launches), front_end_s, first_launch_s."""
        return {"kernels": self.kernels, "compile_s": round(self.seconds, 3),
                "front_end_s": round(self.front_end_s, 3), "first_launch_s": round(self.first_launch_s, 3)}


def start_counting() -> bool:
    """Wrap Taichi's kernel build and launch once (idempotent); False where this Taichi lacks them."""
    if _WRAPPED:
        return True
    try:
        from taichi.lang.kernel_impl import Kernel
    except ImportError:  # pragma: no cover - another Taichi layout
        return False
    if not (hasattr(Kernel, "materialize") and hasattr(Kernel, "launch_kernel")):
        return False
    materialize, launch = Kernel.materialize, Kernel.launch_kernel

    def counted_materialize(self, key=None, args=None, arg_features=None):
        before, started = len(self.compiled_kernels), time.perf_counter()
        out = materialize(self, key=key, args=args, arg_features=arg_features)
        if len(self.compiled_kernels) > before:
            _TOTALS["kernels"] += 1
            _TOTALS["front_end_s"] += time.perf_counter() - started
        return out

    def counted_launch(self, t_kernel, *args):
        if id(t_kernel) in _LAUNCHED:
            return launch(self, t_kernel, *args)
        started = time.perf_counter()
        out = launch(self, t_kernel, *args)
        _LAUNCHED.add(id(t_kernel))
        _TOTALS["first_launches"] += 1
        _TOTALS["first_launch_s"] += time.perf_counter() - started
        return out

    _WRAPPED.update(materialize=materialize, launch_kernel=launch)
    Kernel.materialize, Kernel.launch_kernel = counted_materialize, counted_launch
    return True


def cache_directory() -> str | None:
    """The offline cache's folder of the running Taichi (None before ``ti.init`` or without one)."""
    try:
        from taichi.lang import impl

        path = impl.current_cfg().offline_cache_file_path
    except Exception:  # noqa: BLE001 - no runtime yet
        return None
    return path or None


def cache_file_count(path: str | None = None, since: float | None = None) -> int:
    """Files under the offline cache folder (0 where there is none); with ``since`` (a ``time.time()``), only those
    written at or after it.  (Counting the files before and after a run undercounts what it wrote, even below 0:
    Taichi trims the oldest entries when the cache passes its size cap.)"""
    path = path or cache_directory()
    if not path or not os.path.isdir(path):
        return 0
    if since is None:
        return sum(len(files) for _, _, files in os.walk(path))
    return sum(_written_since(os.path.join(root, f), since) for root, _, files in os.walk(path) for f in files)


def _written_since(path: str, since: float) -> bool:
    try:
        return os.stat(path).st_mtime >= since
    except FileNotFoundError:  # trimmed while we walked
        return False


def compile_totals() -> CompileCounts:
    """The counters now (kernels and seconds since :func:`start_counting`)."""
    return CompileCounts(_TOTALS["kernels"], _TOTALS["front_end_s"], _TOTALS["first_launches"],
                         _TOTALS["first_launch_s"])
