"""The tracker's front end: normalisation and the saliency stage, here or in a second process.

:class:`FrontEnd` turns raw frames into what the particle filters of frame f need: the
normalised frame z_f (``background.Preprocessor``) and its per-block proposal map OPsal_N
(``saliency.SaliencyExtractor``, Eqs. 20–33), which exists once frame f + 2 has arrived.
``push(frame)`` returns a list of :class:`FrontFrame` (frame t − 2 for input frame t, nothing
for the first two); ``finish()`` returns the last two.

:class:`FrontEndProcess` runs the same front end in a child process, one call ahead: ``push``
hands frame t over and returns what the child finished with frame t − 1, so the child prepares
the next frame on a second CPU core while this process runs the particle filters.  (Taichi
holds the GIL while a kernel runs, so threads cannot overlap the two.)  Where the runtime pinned
its CPU workers (``backend.init``), the child runs one thread on the last worker's CPU at idle
priority (``backend.run_in_background``): it takes only the time the tracker leaves that CPU,
mostly while this process runs serial code, and a worker that wakes for a parallel loop does not
wait for it (faster per frame than one process; docs/performance-history.md has the figures).  Frames pass
through shared memory; the results are the same bits, one frame later.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import time
import weakref
from dataclasses import dataclass
from multiprocessing import connection, shared_memory

import numpy as np

from . import backend
from .errors import WorkerError
from .io import stream_frame

FRONT_STAGES = ("normalise", "saliency")
ANSWER_SECONDS = 300.0  # longest wait for the child (its first frame compiles the kernels if not cached)
SLOTS = ("raw", "z", "proposal")  # shared (2, H, W) float32 buffers, used by frame parity
# the child imports the package from the parent's sys.path (argv[2], JSON): ``python -c`` would put the
# working directory first, and a source checkout there has no tbd_taichi.kernels (installed from kernels/)
CHILD_COMMAND = ("import json, sys; sys.path[:] = json.loads(sys.argv[2]); "
                 "from tbd_taichi.frontend import _child_main; _child_main(sys.argv[1])")
KEY_VARIABLE = "TBD_TAICHI_FRONT_END_KEY"  # the channel's authentication key, hex, for the child


@dataclass
class FrontFrame:
    """Frame ``frame``: normalised image z (H, W, σ units), proposal map OPsal_N (Eq. 33) and the
    Eq. 24 candidates with the largest log ω̌_lef (Eq. 28), ``best_lef`` (K, 2): (value, pixel y·W + x)
    descending, (−3e38, −1) past the last candidate."""

    frame: int
    z: np.ndarray
    proposal: np.ndarray
    best_lef: np.ndarray


class FrontEnd:
    """Normalisation and saliency in this process (SGDS-PF parameters snr, L_ib, psf_sigma, lef_memory,
    lef_scale; the ``Preprocessor``'s background and bad_pixels; engine "taichi" or "numpy")."""

    def __init__(self, shape, snr: float, L_ib: int, psf_sigma: float, background: str, bad_pixels: bool,
                 engine: str, lef_memory: float = 0.0, lef_scale: float = 1.0):
        from .background import Preprocessor
        from .saliency import SaliencyExtractor

        self.shape = (int(shape[0]), int(shape[1]))
        self.preprocess = Preprocessor(self.shape, background, bad_pixels, engine)
        self.saliency = SaliencyExtractor(self.shape, snr=snr, block_size=L_ib, psf_sigma=psf_sigma,
                                          engine=engine, details=False, lef_memory=lef_memory, lef_scale=lef_scale)
        self.grid = self.saliency.grid
        self.frames_in = 0
        self.last_z: np.ndarray | None = None  # z of the last frame pushed
        self._z: dict[int, np.ndarray] = {}
        self.stage_seconds = dict.fromkeys(FRONT_STAGES, 0.0)  # cumulative wall time per stage

    def push(self, frame) -> list[FrontFrame]:
        """Add raw frame t; returns frame t − 2 (nothing for t < 2)."""
        t0 = time.perf_counter()
        z = self.last_z = self.preprocess(frame, self.frames_in)
        self._z[self.frames_in] = z
        self.frames_in += 1
        t1 = time.perf_counter()
        self.stage_seconds["normalise"] += t1 - t0
        done = [self._front_frame(s) for s in self.saliency.push_checked(z)]  # z is finite: checked raw frame
        self.stage_seconds["saliency"] += time.perf_counter() - t1
        return done

    def finish(self) -> list[FrontFrame]:
        """The last (up to) two frames."""
        return [self._front_frame(s) for s in self.saliency.emit_remaining()]

    def _front_frame(self, s) -> FrontFrame:
        """Frame s.frame right after the saliency stage emitted it (the next emission overwrites its proposal)."""
        return FrontFrame(s.frame, self._z.pop(s.frame), self.saliency.engine.proposal_copy(), s.best_lef)

    def close(self) -> None:
        """Nothing to release (see :meth:`FrontEndProcess.close`)."""


def _serve(conn) -> None:
    """The child process: a FrontEnd that reads raw frame t from shared slot t % 2 and writes z_t
    and the proposal map of the frame it finishes (t − 2) into the output slots of that parity."""
    try:
        names, shape, options, arch, threads, cpu = conn.recv()
        memory = {key: _attach(name) for key, name in names.items()}
        slots = {key: np.ndarray((2,) + tuple(shape), np.float32, buffer=m.buf) for key, m in memory.items()}
        if options["engine"] == "taichi":
            backend.init(arch, threads=threads)
        if cpu is not None:
            backend.run_in_background(cpu)
        front = FrontEnd(shape, **options)
    except Exception as exc:  # noqa: BLE001 - the parent raises it
        conn.send(("error", f"{type(exc).__name__}: {exc}"))
        return
    conn.send(("ready", None))
    while True:
        kind, t = conn.recv()
        if kind == "close":
            break
        try:
            if kind == "frame":
                done = front.push(slots["raw"][t % 2])
                slots["z"][t % 2] = front.last_z
                for f in done:
                    slots["proposal"][t % 2] = f.proposal
                answer = [(f.frame, f.best_lef) for f in done]
            else:  # the last frames: few, through the pipe
                answer = [(f.frame, f.proposal, f.best_lef) for f in front.finish()]
        except Exception as exc:  # noqa: BLE001
            conn.send(("error", f"{type(exc).__name__}: {exc}"))
            continue
        conn.send(("done", (answer, dict(front.stage_seconds))))
    for m in memory.values():
        m.close()


def _attach(name: str) -> shared_memory.SharedMemory:
    """The parent's shared memory block, which the parent alone unlinks (before Python 3.13 an
    attaching process registers it with its own resource tracker, which would unlink it at exit)."""
    try:
        return shared_memory.SharedMemory(name=name, track=False)
    except TypeError:  # Python < 3.13
        from multiprocessing import resource_tracker

        block = shared_memory.SharedMemory(name=name)
        resource_tracker.unregister(block._name, "shared_memory")
        return block


def _child_main(address: str) -> None:
    """The child's entry: listen at ``address`` (key in KEY_VARIABLE) and serve one parent."""
    with connection.Listener(address, authkey=bytes.fromhex(os.environ[KEY_VARIABLE])) as listener:
        conn = listener.accept()
    with conn:
        _serve(conn)


def _connect(process: subprocess.Popen, address: str, key: bytes):
    """Connect to the child's listener, retrying until it is up; WorkerError if the child ends first."""
    deadline = time.monotonic() + ANSWER_SECONDS
    while True:
        try:
            return connection.Client(address, authkey=key)
        except (FileNotFoundError, ConnectionRefusedError):
            if process.poll() is not None or time.monotonic() > deadline:
                raise WorkerError(f"the front-end process did not start (exit code {process.poll()})") from None
            time.sleep(0.01)


class FrontEndProcess:
    """:class:`FrontEnd` in a child process, one frame ahead (see the module notes): ``push`` of
    frame t returns frame t − 3.  ``threads`` caps the child's Taichi CPU threads.  The child is a
    fresh interpreter (not a multiprocessing child), so scripts need no ``__main__`` guard."""

    def __init__(self, shape, threads: int | None = None, **options):
        from .saliency import block_grid

        self.shape = (int(shape[0]), int(shape[1]))
        self.grid = block_grid(self.shape, options["L_ib"])
        nbytes = 2 * self.shape[0] * self.shape[1] * 4
        memory = [shared_memory.SharedMemory(create=True, size=nbytes) for _ in SLOTS]
        self._slots = {key: np.ndarray((2,) + self.shape, np.float32, buffer=m.buf) for key, m in zip(SLOTS, memory)}
        arch = backend.current().arch if options.get("engine") == "taichi" else "cpu"
        address, key = connection.arbitrary_address(connection.default_family), os.urandom(16)
        process = subprocess.Popen([sys.executable, "-c", CHILD_COMMAND, address, json.dumps(sys.path)],
                                   env={**os.environ, KEY_VARIABLE: key.hex()}, stdout=subprocess.DEVNULL)
        self._process = process
        channel: dict = {}  # the connection, for the finalizer (which must not hold self)
        self._finalizer = weakref.finalize(self, _shut_down, channel, process, memory)
        self._conn = channel["conn"] = _connect(process, address, key)
        cpu = backend.background_cpu()  # with pinned workers: the child on the last CPU, at idle priority
        if cpu is not None:
            threads = 1
        self._conn.send(({k: m.name for k, m in zip(SLOTS, memory)}, self.shape, options, arch, threads, cpu))
        self._pending: int | None = None  # the frame handed over and not yet answered
        self._z: dict[int, np.ndarray] = {}
        self.frames_in = 0
        self.stage_seconds = dict.fromkeys(FRONT_STAGES, 0.0)
        self._answer()  # "ready", or the child's error

    def push(self, frame) -> list[FrontFrame]:
        """Hand raw frame t to the child (checked here, so a bad frame fails at its own call); returns
        frame t − 3 (nothing for t < 3)."""
        t = self.frames_in
        self._slots["raw"][t % 2] = stream_frame(frame, self.shape, t, "tracker")  # the child read t − 2 already
        self._send("frame", t)
        self.frames_in += 1
        done = self._collect()
        self._pending = t
        return done

    def finish(self) -> list[FrontFrame]:
        """The frames still in the child: frame t − 2 of the last push, then the last two."""
        done = self._collect()
        self._send("finish", None)
        answer = self._answer()
        self.stage_seconds.update(answer[1])
        return done + [FrontFrame(f, self._z.pop(f), proposal, best) for f, proposal, best in answer[0]]

    def _send(self, kind: str, t) -> None:
        try:
            self._conn.send((kind, t))
        except (OSError, ValueError):
            raise WorkerError(self._ended()) from None

    def _ended(self) -> str:
        try:
            code = self._process.wait(1.0)
        except subprocess.TimeoutExpired:
            code = None
        return f"the front-end process ended unexpectedly (exit code {code})"

    def _answer(self):
        """The child's next answer; WorkerError if it failed, ended or went silent."""
        try:
            if not self._conn.poll(ANSWER_SECONDS):
                raise WorkerError(f"the front-end process did not answer within {ANSWER_SECONDS:.0f} s")
            kind, payload = self._conn.recv()
        except (EOFError, OSError):
            raise WorkerError(self._ended()) from None
        if kind == "error":
            raise WorkerError(f"front-end process: {payload}")
        return payload

    def _collect(self) -> list[FrontFrame]:
        """The answer for the pending frame t: z_t (kept until its turn) and the frame it finished."""
        t, self._pending = self._pending, None
        if t is None:
            return []
        frames, seconds = self._answer()
        self.stage_seconds.update(seconds)
        self._z[t] = self._slots["z"][t % 2].copy()
        return [FrontFrame(f, self._z.pop(f), self._slots["proposal"][t % 2].copy(), best) for f, best in frames]

    def close(self) -> None:
        """Stop the child and free the shared memory (also done when the object is collected)."""
        self._finalizer()


def _shut_down(channel: dict, process: subprocess.Popen, memory) -> None:
    """Ask the child to stop (terminate it if it does not), close the channel, free the shared memory."""
    conn = channel.get("conn")
    if conn is not None:
        try:
            conn.send(("close", None))
        except (OSError, ValueError):
            pass
    try:
        process.wait(5.0)
    except subprocess.TimeoutExpired:
        process.terminate()
        process.wait(5.0)
    if conn is not None:
        conn.close()
    for m in memory:
        m.close()
        m.unlink()
