"""The Dask side of :class:`.executor.Fanout`: a ``distributed`` client on a running scheduler or on a
``LocalCluster``, a worker plugin that starts Taichi once per worker, and the items as Dask futures.

A worker that dies takes its running items with it; the scheduler gives them to another worker (up to
``distributed.scheduler.allowed-failures`` deaths per item, then :class:`~distributed.KilledWorker`, which
comes back as that item's fatal :class:`~.executor.Outcome`).
"""
from __future__ import annotations

import asyncio
import atexit
import logging
import threading

import distributed

from .errors import TBDError
from .executor import LOCAL_DASK, Outcome, ensure_backend, guarded, stop_backend

CONNECT_TIMEOUT_S = 20


def _start_quietly(arch: str, threads: int | None) -> None:
    """Start this worker's backend (kept for each item if it fails); a worker that ends normally then saves
    the kernels it compiled to Taichi's offline cache (at exit, when no task runs)."""
    try:
        with _ONE_AT_A_TIME:  # never under a running item (a plugin registered again by a later command)
            ensure_backend(arch, threads)
    except TBDError:
        return  # kept by ensure_backend: each item then fails with it
    if not _SAVE_AT_EXIT:
        atexit.register(stop_backend)
        _SAVE_AT_EXIT.append(True)


_SAVE_AT_EXIT: list = []
_ONE_AT_A_TIME = threading.Lock()  # a worker started with --nthreads > 1 still runs one item at a time


def _run_item(item, fn, arch: str, threads: int | None) -> Outcome:
    """:func:`.executor.guarded` with the item first, as ``Client.map`` passes it; one item at a time per worker
    process (Taichi's runtime is one per process, and its launches are not meant for concurrent threads)."""
    with _ONE_AT_A_TIME:
        return guarded(fn, item, arch, threads)


class TaichiWorkerSetup(distributed.WorkerPlugin):
    """Starts Taichi with ``arch`` and ``threads`` when a worker joins, on the thread that runs its tasks (a
    GPU context belongs to a thread); a worker that cannot start it fails each of its items at once."""

    name = "tbd-taichi-backend"

    def __init__(self, arch: str, threads: int | None):
        self.arch, self.threads = arch, threads

    async def setup(self, worker) -> None:
        if (getattr(worker, "nthreads", 1) or 1) > 1:
            logging.getLogger("distributed.worker").warning(
                "tbd-taichi: this worker has %s threads but runs one item at a time (one Taichi runtime per "
                "process); start more worker processes with --nthreads 1 instead", worker.nthreads)
        pool = worker.executors.get("default")
        if pool is None:  # pragma: no cover - another distributed layout: the first item starts it
            return
        await asyncio.get_running_loop().run_in_executor(pool, _start_quietly, self.arch, self.threads)


class DaskCluster:
    """A client on ``scheduler`` (an address, or ``local-dask`` for a LocalCluster of ``workers`` processes of one
    task thread each), with :class:`TaichiWorkerSetup` registered on every worker, present and future."""

    def __init__(self, scheduler: str, workers: int, arch: str, threads: int | None):
        self.scheduler, self.arch, self.threads, self.cluster = scheduler, arch, threads, None
        try:
            if scheduler == LOCAL_DASK:
                self.cluster = distributed.LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                                        dashboard_address=":0", silence_logs=logging.ERROR)
                self.client = distributed.Client(self.cluster)
            else:
                self.client = distributed.Client(scheduler, timeout=CONNECT_TIMEOUT_S)
        except (OSError, TimeoutError) as exc:
            self.close()
            raise TBDError(f"--scheduler {scheduler}: no Dask scheduler answered within {CONNECT_TIMEOUT_S} s "
                           f"({exc})") from None
        self.client.register_plugin(TaichiWorkerSetup(arch, threads))
        self._label = f"{self.workers()} ({'LocalCluster' if self.cluster is not None else 'Dask'})"

    def workers(self) -> int:
        return len(self.client.scheduler_info(n_workers=-1).get("workers", {}))

    def label(self) -> str:
        """The workers when the command began, and the kind of cluster (workers may come and go later)."""
        return self._label

    def describe(self) -> str:
        where = "a Dask LocalCluster" if self.cluster is not None else f"the Dask scheduler {self.scheduler}"
        link = self.client.dashboard_link
        return f"{self.workers()} worker(s) of {where}" + (f" (dashboard {link})" if link else "")

    def run(self, fn, items):
        """Submit every item (each a task of its own: ``pure=False``) and yield Outcomes as they finish."""
        futures = self.client.map(_run_item, items, fn=fn, arch=self.arch, threads=self.threads, pure=False)
        owner = {future.key: item for future, item in zip(futures, items)}
        try:
            for future in distributed.as_completed(futures):
                try:
                    yield future.result()
                except Exception as exc:  # the cluster lost it (KilledWorker, cancelled): a fatal outcome
                    yield Outcome(owner[future.key], error=f"Dask: {type(exc).__name__}: {exc}", fatal=True)
        finally:
            self.client.cancel([f for f in futures if not f.done()])

    def close(self) -> None:
        for part in (getattr(self, "client", None), self.cluster):
            if part is not None:
                try:
                    part.close()
                except Exception:  # pragma: no cover - closing a half-started cluster
                    pass
