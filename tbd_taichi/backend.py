"""Taichi backend selection: ``init(arch, threads, debug)``.

Every Taichi kernel in ``tbd_taichi.kernels`` runs on the runtime that
:func:`init` starts.  The default is the CPU; ``"gpu"`` picks the first GPU
backend that is present and ``"auto"`` falls back to the CPU silently.  Any
other backend that is not there is an error that lists what is available.
"""
from __future__ import annotations

import contextlib
import ctypes
import io
import os
import weakref
from dataclasses import dataclass

import numpy as np

os.environ.setdefault("ENABLE_TAICHI_HEADER_PRINT", "0")

import taichi as ti  # noqa: E402

from .errors import BackendError  # noqa: E402
from . import compile_speed, light_ir  # noqa: E402

compile_speed.install()  # before any kernel module is imported (its decorators run at import)
light_ir.install()  # the kernels marked light_ir compile without Taichi's advanced IR passes

ARCH_NAMES = ("cpu", "cuda", "vulkan", "metal", "gpu", "auto")
# compiled kernels kept on disk; Taichi's default 100 MiB evicts kernels that a test run, or a
# program that tracks several frame sizes (each compiles its own), needs again
OFFLINE_CACHE_BYTES = 512 << 20
GPU_ARCHS = ("cuda", "vulkan", "metal")


@dataclass(frozen=True)
class BackendConfig:
    """The settings of the running Taichi runtime."""

    arch: str
    threads: int | None
    debug: bool


_current: BackendConfig | None = None
_pinned: list[int] = []  # thread ids of the CPU worker threads pinned by the last init
_generation = 0
_spare: dict = {}  # (generation, key) → field sets whose owners are gone


def _ti_arch(name: str):
    return {"cpu": ti.cpu, "cuda": ti.cuda, "vulkan": ti.vulkan, "metal": ti.metal}[name]


def _probe(name: str) -> bool:
    from taichi.lang.misc import is_arch_supported

    if name == "cpu":
        return True
    ti.set_logging_level(ti.ERROR)  # silence "libcuda.so not found" while probing
    try:
        return bool(is_arch_supported(_ti_arch(name)))
    except Exception:  # a broken driver counts as absent
        return False
    finally:
        ti.set_logging_level(ti.WARN)


def available_archs() -> list[str]:
    """Backends this machine can run, CPU first."""
    return ["cpu"] + [name for name in GPU_ARCHS if _probe(name)]


def _resolve(arch: str) -> str:
    if arch not in ARCH_NAMES:
        raise BackendError(f"unknown arch {arch!r}; choose one of {', '.join(ARCH_NAMES)}")
    if arch in ("gpu", "auto"):
        gpus = [name for name in GPU_ARCHS if _probe(name)]
        if gpus:
            return gpus[0]
        if arch == "auto":
            return "cpu"
        raise BackendError(f"arch 'gpu' requested but no GPU backend is available; available: {', '.join(available_archs())}")
    if not _probe(arch):
        raise BackendError(f"arch {arch!r} is not available on this machine; available: {', '.join(available_archs())}")
    return arch


def init(arch: str = "cpu", threads: int | None = None, debug: bool = False) -> BackendConfig:
    """Start (or keep) the Taichi runtime on ``arch``.

    ``threads`` caps the CPU worker threads (None: all cores).  Calling ``init``
    again with the same settings does nothing; other settings restart the runtime,
    after which fields made before belong to the old runtime and are rebuilt by
    their owners (see :func:`generation`).  The offline cache is on, so a second
    process does not recompile the kernels.
    """
    global _current, _generation
    if threads is not None and (not isinstance(threads, int) or threads < 1):
        raise BackendError(f"threads must be a positive integer or None, got {threads!r}")
    name = _resolve(arch)
    wanted = BackendConfig(name, threads, bool(debug))
    if wanted == _current:
        return _current
    if _current is not None:
        shutdown()
    kwargs = dict(arch=_ti_arch(name), debug=bool(debug), offline_cache=True,
                  offline_cache_max_size_of_files=OFFLINE_CACHE_BYTES,
                  log_level=ti.WARN, enable_fallback=False, default_fp=ti.f32, default_ip=ti.i32,
                  fast_math=False)  # IEEE f32: the NumPy twins reproduce the same bits
    if threads is not None:
        kwargs["cpu_max_num_threads"] = threads
    compile_speed.install(debug=bool(debug))
    before = _thread_ids()
    try:
        with contextlib.redirect_stdout(io.StringIO()):  # drop "[Taichi] Starting on arch=..."
            ti.init(**kwargs)
    except Exception as exc:  # pragma: no cover - depends on drivers
        _current = None
        raise BackendError(f"could not start Taichi on {name!r}: {exc}; available: {', '.join(available_archs())}") from exc
    _current = wanted
    _pinned[:] = pin_worker_threads(before, cpu_threads()) if name == "cpu" else []
    _generation += 1
    _spare.clear()
    return _current


def shutdown() -> None:
    """End the Taichi runtime (``ti.reset``: Taichi writes its offline cache then) and drop its spare fields; the
    next :func:`init` starts a new one (a new :func:`generation`: fields made before belong to the old runtime)."""
    global _current
    ti.reset()
    _current = None
    _pinned.clear()
    _spare.clear()


def _thread_ids() -> set[int]:
    """Ids of this process's threads (Linux; empty elsewhere)."""
    try:
        return {int(t) for t in os.listdir("/proc/self/task")}
    except OSError:
        return set()


def pin_worker_threads(before: set[int], threads: int) -> list[int]:
    """Pin the CPU runtime's worker threads, one to each CPU this process may use; returns their ids.

    Taichi starts its pool of ``threads`` workers last in ``ti.init``, so they are the newest threads
    not in ``before``.  Unpinned, Linux often queues both workers of the 2-core VM on one CPU, and a
    parallel loop then runs serially (a 2 ms loop took 1.6 ms on two threads, 1.05 ms pinned).  Done
    only when the workers are exactly as many as the CPUs of the process's affinity set (≥ 2), so a
    runtime limited to fewer threads, or several processes sharing the CPUs, is left to the scheduler;
    ``TBD_TAICHI_PIN_THREADS=0`` turns it off."""
    if os.environ.get("TBD_TAICHI_PIN_THREADS", "1") == "0" or not hasattr(os, "sched_setaffinity"):
        return []
    cpus = sorted(os.sched_getaffinity(0))
    workers = sorted(_thread_ids() - before)[-threads:]
    if threads < 2 or threads != len(cpus) or len(workers) != threads:
        return []
    try:
        for cpu, tid in zip(cpus, workers):
            os.sched_setaffinity(tid, {cpu})
    except OSError:  # a thread ended, or the affinity is not ours to set
        return []
    return workers


def pinned_workers() -> list[int]:
    """Thread ids of the CPU workers :func:`init` pinned (empty if it did not pin)."""
    return list(_pinned)


def background_cpu() -> int | None:
    """The CPU a helper process should use, that of the last pinned worker (the main thread's serial work
    tends to stay with the first), where :func:`init` pinned the workers; else None (the scheduler
    places it)."""
    try:
        return max(os.sched_getaffinity(_pinned[-1])) if _pinned else None
    except OSError:  # the worker is gone
        return None


def run_in_background(cpu: int) -> bool:
    """Move every thread of this process (and those it starts later) onto ``cpu`` at idle priority
    (Linux ``SCHED_IDLE``): a helper process then runs only in time the tracker leaves that CPU, and a
    worker thread that wakes for a parallel loop takes the CPU at once.  False where it cannot."""
    if not hasattr(os, "sched_setscheduler") or not hasattr(os, "SCHED_IDLE"):
        return False
    done: set = set()
    while new := _thread_ids() - done:  # again until no thread appeared meanwhile (one started by a thread
        for tid in sorted(new):        # not yet moved would inherit the normal policy)
            try:
                os.sched_setaffinity(tid, {cpu})
                os.sched_setscheduler(tid, os.SCHED_IDLE, os.sched_param(0))
            except ProcessLookupError:  # the thread has ended
                pass
            except OSError:
                return False
        done |= new
    return True


def ensure_init(arch: str | None = None) -> BackendConfig:
    """Initialise on ``arch`` if given; otherwise keep the running runtime, or start the CPU one."""
    if arch is not None:
        return init(arch) if _current is None or _resolve(arch) != _current.arch else _current
    return _current if _current is not None else init("cpu")


def current() -> BackendConfig | None:
    """Settings of the running runtime, or None before :func:`init`."""
    return _current


def generation() -> int:
    """Counter bumped by every (re)start of the runtime; owners of fields compare it."""
    return _generation


_reused = weakref.WeakSet()  # sets reusable() has handed out more than once


def reusable(owner, key, factory):
    """Taichi fields (and the kernels compiled for them) for ``owner``: a set left by an owner
    that is gone and had the same ``key`` (field shapes), else ``factory()``.

    Kernels that take fields are compiled for those very fields, so a new tracker with new
    fields recompiles everything (seconds); reusing the fields of a finished tracker of the
    same shapes does not.  The caller re-initialises whatever state it relies on."""
    spare = _spare.setdefault((_generation, key), [])
    if spare:
        fields = spare.pop()
        _reused.add(fields)
    else:
        fields = factory()
    weakref.finalize(owner, spare.append, fields)
    return fields


def holds_old_values(fields) -> bool:
    """Whether :func:`reusable` handed ``fields`` out before, so that they hold their last owner's values; a set
    it has just made holds zeros (Taichi zero-fills every new field, ``tests/test_backend.py`` checks it), which
    spares a new owner the kernel that would zero them (compiled in every process: 40 ms each)."""
    return fields in _reused


def keep_freed_memory() -> bool:
    """Ask glibc to keep freed blocks of up to 32 MiB in the heap (mallopt M_MMAP_THRESHOLD and
    M_TRIM_THRESHOLD) for the rest of the process.

    By default each large NumPy temporary (over 128 KiB: any image or particle array) is a fresh
    mmap that page-faults on first touch and is returned to the system when freed, so every frame
    pays those faults again.  Measured on the 2-core CI machine: ``SGDSPF.update`` at 320×256 with
    the SNR 1.4 preset 24.1 → 22.3 ms, at 1024×1024 200 → 122 ms; the NumPy saliency stage at
    1024×1024 57 → 37 ms.  Peak memory is unchanged; freed memory stays with the process.
    The command line, the evaluation suite's workers and the benchmarks call it; a program that
    uses the API can call it once at start.  Returns False (and changes nothing) where the C
    library is not glibc."""
    try:
        libc = ctypes.CDLL("libc.so.6")
    except OSError:
        return False
    m_trim_threshold, m_mmap_threshold = -1, -3
    return bool(libc.mallopt(m_mmap_threshold, 32 << 20)) and bool(libc.mallopt(m_trim_threshold, 1 << 30))


# up to this many pixels the image kernels run serial loops: on the 2-core VM, in parallel, normalisation and
# saliency took 3.3 + 9.2 against 3.9 + 13.6 ms at 1024×1024, 1.9 + 3.8 against 1.5 + 4.1 ms at 640×512
SERIAL_PIXELS = 1 << 19


def serial_loops(work: int, limit: int | None = None) -> bool:
    """Whether kernels should run their loops on one thread: on the CPU, for at most ``limit`` units of work
    (None: images of at most SERIAL_PIXELS pixels, read at the call; there a parallel launch's dispatch costs
    more than the work it splits).  Never on a GPU, where one device thread would be slow."""
    cfg = current()
    return cfg is not None and cfg.arch == "cpu" and work <= (SERIAL_PIXELS if limit is None else limit)


def cpu_threads() -> int:
    """Worker threads of the CPU runtime: ``init``'s ``threads``, else the core count."""
    cfg = current()
    return (cfg.threads if cfg is not None else None) or os.cpu_count() or 1


_transfers = None  # the transfer kernels, through tbd_taichi.launch


def _transfer_kernel(direction: str, ndim: int):
    global _transfers
    if _transfers is None:
        from .kernels import transfer
        from .launch import Launcher

        _transfers = Launcher(transfer)
    return getattr(_transfers, f"{direction}_{ndim}d")


def _scalar_field(obj) -> bool:
    from taichi.lang.field import ScalarField

    return isinstance(obj, ScalarField) and len(obj.shape) in (1, 2)


def to_host(source) -> np.ndarray:
    """A NumPy copy of a 1-D or 2-D scalar field, by a typed kernel: about 40 µs on the CPU where
    ``field.to_numpy()`` costs about 0.2 ms.  NumPy arrays (the NumPy engine's storage) are copied,
    other fields go through ``to_numpy``."""
    if isinstance(source, np.ndarray):
        return source.copy()
    if not _scalar_field(source):
        return source.to_numpy()
    from taichi.lang.util import to_numpy_type

    out = np.empty(source.shape, dtype=to_numpy_type(source.dtype))
    _transfer_kernel("field_to_array", len(source.shape))(source, out, serial_loops(out.size))
    return out


def from_host(target, array) -> None:
    """Copy ``array`` (converted to the target's dtype) into a field or NumPy array of the same
    shape; 1-D and 2-D scalar fields by a typed kernel (see :func:`to_host`)."""
    if isinstance(target, np.ndarray):
        target[...] = array
        return
    if not _scalar_field(target):
        target.from_numpy(np.ascontiguousarray(array))
        return
    _copy_to_field(target, array, lambda a: a.shape == tuple(target.shape), "a field")


def from_host_leading(target, array) -> None:
    """Copy the 1-D ``array`` (converted to the target's dtype) into the leading ``len(array)`` entries of a 1-D
    field or NumPy array (a frame, or a table that follows it, in a field of its size class); the rest keeps its
    values.  Fields by the typed kernel of :func:`from_host`, which loops over the array."""
    if isinstance(target, np.ndarray):
        target[:len(array)] = array
        return
    _copy_to_field(target, array, lambda a: a.ndim == 1 and len(target.shape) == 1 and len(a) <= target.shape[0],
                   "the start of a field")


def _copy_to_field(target, array, fits, where: str) -> None:
    """``array`` in the scalar field's dtype, checked by ``fits`` (else a ValueError naming ``where`` it does not
    fit), copied by the typed kernel that loops over the array."""
    from taichi.lang.util import to_numpy_type

    array = np.ascontiguousarray(array, dtype=to_numpy_type(target.dtype))
    if not fits(array):
        raise ValueError(f"array of shape {array.shape} does not fit {where} of shape {tuple(target.shape)}")
    _transfer_kernel("array_to_field", array.ndim)(array, target, serial_loops(array.size))


BATCH_DTYPES = ("f32", "f64", "i32", "u32")  # field dtypes a batch write holds exactly in f64


def _batchable(field) -> bool:
    from taichi.lang.field import ScalarField

    return isinstance(field, ScalarField) and str(field.dtype) in BATCH_DTYPES


def from_host_many(target, arrays: dict) -> None:
    """``target.name`` ← ``arrays[name]`` for each name (converted to the attribute's dtype and shape): NumPy
    attributes by assignment; Taichi scalar fields of f32, f64, i32 or u32 by one kernel for all of them
    (``kernels.transfer.arrays_to_fields``: a setup writing twenty fields compiles one kernel, not twenty);
    other fields by :func:`from_host`."""
    batch, parts = [], []
    for name, array in arrays.items():
        field = getattr(target, name)
        if isinstance(field, np.ndarray) or not _batchable(field):
            from_host(field, array)
            continue
        array = np.asarray(array)
        if array.shape != tuple(field.shape):
            raise ValueError(f"{name}: array of shape {array.shape} does not fit a field of shape {tuple(field.shape)}")
        batch.append(field)
        parts.append(array.astype(np.float64).ravel())
    if batch:
        from .kernels.transfer import arrays_to_fields

        offsets = tuple(int(v) for v in np.cumsum([0] + [p.size for p in parts[:-1]]))
        arrays_to_fields(np.concatenate(parts), tuple(batch), offsets)


def zero_many(target, names) -> None:
    """``target.name`` ← 0 for each name: NumPy attributes in place, Taichi fields (scalar or vector, any dtype: 0
    is exact in each) by one kernel (``kernels.transfer.zero_fields``)."""
    fields = []
    for name in names:
        field = getattr(target, name)
        if isinstance(field, np.ndarray):
            field[...] = 0
        else:
            fields.append(field)
    if fields:
        from .kernels.transfer import zero_fields

        zero_fields(tuple(fields))
