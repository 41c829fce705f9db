"""One way to fan out independent work items (an evaluation run, a video to track): in this process, on a local
process pool, or on a Dask ``distributed`` cluster (``--scheduler tcp://HOST:PORT`` or ``local-dask``).

Every worker process starts Taichi once (:func:`ensure_backend`), not once per item.  Items run through
:func:`guarded`, so a failing item comes back as an :class:`Outcome` with its error instead of stopping the
others; the caller decides whether an error ends the whole job (the suite) or is recorded (batch-track).
Dask's own part (client, cluster, worker plugin) lives in :mod:`.dask_fanout`, imported only when a scheduler
is given, so the default needs no extra package.
"""
from __future__ import annotations

import importlib.util
import re
from dataclasses import dataclass
from typing import Any, Callable, Iterable, Iterator

from .errors import BackendError, TBDError

LOCAL_DASK = "local-dask"
SCHEDULER_HELP = ("run on a Dask cluster: tcp://HOST:PORT of a running `dask scheduler`, or local-dask for a "
                  "distributed.LocalCluster of --workers processes on this machine (needs pip install "
                  "'tbd-taichi[cluster]'; inputs must be paths every worker can read)")
_ADDRESS = re.compile(r"^(tcp|tls|ws|wss|inproc)://([^\s:/\[\]]+|\[[0-9A-Fa-f:.]+\])(:\d{1,5})?$")
_BACKEND: dict = {}  # this process's Taichi start: {"key": (arch, threads), "error": message or None}


def check_scheduler(value: str | None) -> str | None:
    """``--scheduler``: None, ``local-dask`` or a scheduler address; Dask's ``distributed`` must be installed."""
    if value is None:
        return None
    if value != LOCAL_DASK and not _ADDRESS.match(value):
        raise TBDError(f"--scheduler {value!r}: give tcp://HOST:PORT (a running `dask scheduler`) or {LOCAL_DASK}")
    try:
        found = importlib.util.find_spec("distributed") is not None
    except (ImportError, ValueError):  # a broken or blocked install
        found = False
    if not found:
        raise TBDError(f"--scheduler {value} needs Dask's distributed package: pip install 'tbd-taichi[cluster]'")
    return value


def start_backend(arch: str, threads: int | None) -> None:
    """Start Taichi in this process as every command does: freed memory kept for reuse, kernel builds counted
    (:mod:`.compile_stats`), then ``backend.init``."""
    from . import backend, compile_stats

    backend.keep_freed_memory()
    compile_stats.start_counting()
    backend.init(arch, threads=threads)


def ensure_backend(arch: str, threads: int | None) -> None:
    """Start Taichi in this process with ``arch`` and ``threads`` once; later calls return at once.  A backend
    that cannot start raises :class:`BackendError` now and at every later call (each item fails fast)."""
    key = (arch, threads)
    if _BACKEND.get("key") == key:
        if _BACKEND["error"]:
            raise BackendError(_BACKEND["error"])
        return
    _BACKEND.update(key=key, error=None)
    try:
        start_backend(arch, threads)
    except Exception as exc:  # any failure to start: one line, kept for every later item
        _BACKEND["error"] = f"worker could not start the {arch} backend: {exc}"
        raise BackendError(_BACKEND["error"]) from None


@dataclass
class Outcome:
    """One item's result (``value``) or its failure (``error``, one line; ``fatal`` when the worker's backend
    could not start or the cluster lost the item)."""

    item: Any
    value: Any = None
    error: str | None = None
    fatal: bool = False


def guarded(fn: Callable, item, arch: str, threads: int | None) -> Outcome:
    """Run ``fn(item)`` in a worker whose backend is started; a raised error becomes the Outcome's message."""
    try:
        ensure_backend(arch, threads)
    except BackendError as exc:
        return Outcome(item, error=str(exc), fatal=True)
    try:
        return Outcome(item, fn(item))
    except TBDError as exc:
        return Outcome(item, error=one_line(str(exc)))
    except Exception as exc:  # an item's own failure must not stop the others
        return Outcome(item, error=one_line(f"{type(exc).__name__}: {exc}"))


def one_line(text: str) -> str:
    """An error message on one line (an OpenCV or NumPy message may span several)."""
    return " ".join(text.split())


def _pool_initializer(arch: str, threads: int | None) -> None:
    """A pool worker ignores SIGINT (Ctrl-C reaches the whole process group; the parent alone decides to stop)
    and starts its backend before its first item."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        ensure_backend(arch, threads)
    except BackendError:
        return  # kept: each item reports it
    from multiprocessing.util import Finalize

    Finalize(None, stop_backend, exitpriority=10)  # at a normal exit (the pool closed, not terminated)


def stop_backend() -> None:
    """End this worker's Taichi runtime; Taichi then writes the kernels it compiled to its offline cache, so the
    next worker on this machine loads them instead of compiling them again."""
    if _BACKEND.get("key") and not _BACKEND.get("error"):
        from . import backend

        backend.shutdown()
        _BACKEND.clear()


def _pool_call(job: tuple) -> Outcome:
    return guarded(*job)


class Fanout:
    """Where items run: ``scheduler`` None with ``workers`` 1 (this process), > 1 (a spawned process pool of that
    many workers, each with ``threads`` Taichi threads, default 1), or a Dask scheduler (:func:`check_scheduler`).
    Use as a context manager; :meth:`run` yields an :class:`Outcome` per item as items finish."""

    def __init__(self, workers: int = 1, arch: str = "cpu", threads: int | None = None, scheduler: str | None = None):
        self.workers, self.arch, self.scheduler = max(1, int(workers)), arch, check_scheduler(scheduler)
        parallel = self.scheduler is not None or self.workers > 1
        self.threads = (threads or 1) if parallel else threads
        self._dask = None

    def __enter__(self) -> "Fanout":
        if self.scheduler is not None:
            from .dask_fanout import DaskCluster

            self._dask = DaskCluster(self.scheduler, self.workers, self.arch, self.threads)
        return self

    def __exit__(self, *exc) -> None:
        if self._dask is not None:
            self._dask.close()
            self._dask = None

    def describe(self) -> str:
        """Where the items run, for the command's first line."""
        if self._dask is not None:
            return self._dask.describe()
        return "this process" if self.workers == 1 else f"{self.workers} local worker processes"

    @property
    def label(self) -> int | str:
        """The ``workers`` field a result records: the count, with the cluster's kind where there is one."""
        if self._dask is not None:
            return self._dask.label()
        return self.workers

    def run(self, fn: Callable, items: Iterable) -> Iterator[Outcome]:
        """Each item's :class:`Outcome`, in the order they finish.  ``fn`` must be importable by the workers."""
        items = list(items)
        if not items:
            return
        if self._dask is not None:
            yield from self._dask.run(fn, items)
        elif self.workers == 1:
            for item in items:
                yield guarded(fn, item, self.arch, self.threads)
        else:
            import multiprocessing

            ctx = multiprocessing.get_context("spawn")  # each worker starts its own Taichi runtime
            pool = ctx.Pool(min(self.workers, len(items)), initializer=_pool_initializer,
                            initargs=(self.arch, self.threads))
            try:
                yield from pool.imap_unordered(_pool_call, [(fn, item, self.arch, self.threads) for item in items])
                pool.close()  # the workers end normally and save their compiled kernels
            except BaseException:  # Ctrl-C, an error, or the caller stopped early: stop the workers now
                pool.terminate()
                raise
            finally:
                pool.join()


__all__ = ["LOCAL_DASK", "SCHEDULER_HELP", "Fanout", "Outcome", "check_scheduler", "ensure_backend", "guarded",
           "start_backend", "stop_backend"]
