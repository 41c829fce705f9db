"""The ``tophat-pf`` scheduler: the candidate stage on frames 0–2, then one SIR filter per candidate in one pool
(kernels.tophat_pf), Alg. 5 at the end of each window, and the confirmed filter's rows."""
from __future__ import annotations

import csv
import time
import warnings

import numpy as np

from ... import backend
from ...engines import frame_kernels
from ...errors import InputError, ParameterError
from ...io import stream_frame
from ...kernels.tophat_pf import SUM_BX, SUM_BY, SUM_S, SUM_SNR, SUM_X, SUM_Y, step_layout
from ...tables import TRACK_COLUMNS, _dtype, make_table
from ...tophat import find_candidates
from ..registry import OneSequence
from .params import FIRST_FRAMES, tophat_pf_params, window_lengths, window_of
from .windows import eliminated, merged, strongest, trajectory_cost

STAGES = ("candidates", "background", "particles", "windows")  # frames 0–2; Algs. 8–9; the SIR step; Alg. 5
REPORTS = (1, 2)
PATHS = ("online", "whole")
DIAGNOSTIC_COLUMNS = ("window", "first_frame", "last_frame", "track_id", "x", "y", "cost", "evidence", "action")


def check_options(report, paths, diagnostics):
    """The run options, or a ParameterError/InputError naming the bad one; the diagnostics path checked early."""
    from ...validate import output_path

    if report not in REPORTS or isinstance(report, bool):
        raise ParameterError(f"tophat-pf option report = {report!r} must be 1 or 2 (tracks reported)")
    if paths not in PATHS:
        raise ParameterError(f"tophat-pf option paths = {paths!r} must be online (rows from the confirmation on) or "
                             "whole (the confirmed filter's path from frame 3)")
    return None if diagnostics is None else output_path("diagnostics", diagnostics, (".csv",))


class TophatPFTracker(OneSequence):
    """``update(frame)`` returns the rows reported now: none before the confirmation, then the confirmed filter's
    row each frame (report = 2: also the next-strongest survivor's); paths = whole adds the confirmed filter's
    rows from frame 3 at the confirmation.  Row: (frame, track_id = candidate rank, x, y, vx, vy = B,
    intensity = S_k at the estimate, confidence = 1 − J/2 of the last window)."""

    def __init__(self, shape, seed: int = 0, engine: str = "taichi", arch: str | None = None, report: int = 1,
                 paths: str = "whole", diagnostics=None, **params):
        self.shape = (int(shape[0]), int(shape[1]))
        self.p = tophat_pf_params(self.shape, **params)
        self.report, self.paths = report, paths
        self.diagnostics = check_options(report, paths, diagnostics)
        self.lengths = window_lengths(self.p.windows)
        self.seed, self.engine, self.arch = int(seed), engine, arch
        groups, ring = self.p.max_candidates, self.p.s_drift + 1
        self.k = frame_kernels(self, engine, "tophat_pf", "TophatPFKernels",
                               (groups, self.p.n_particles, self.shape, ring), self.shape, arch)
        self.tophat = frame_kernels(self, engine, "tophat", "TophatKernels",
                                    (self.shape, self.p.se_size, self.p.se_shape), self.shape, arch)
        self.k.configure(self.seed, np.array([self.p.c, self.p.sigma_v, self.p.s_drift, self.p.sigma_0], np.float32))
        self.first: list[np.ndarray] = []
        self.candidates = np.zeros((0, 3))
        self.alive = np.zeros(groups, bool)
        self.summaries: list[np.ndarray] = []  # per frame from summary_base: (G, SUMMARY)
        self.summary_base = FIRST_FRAMES  # the frame of summaries[0]
        self.window = (0, *window_of(self.lengths, 0, FIRST_FRAMES))  # (index, first, last)
        self.windows_on = True
        self.cost = np.zeros(groups)
        self.confirmed = -1
        self.reported: list[int] = []
        self.rows: list[tuple] = []
        self.log: list[tuple] = []
        self.frame = 0
        self.seconds = {s: 0.0 for s in STAGES}

    def update(self, frame: np.ndarray) -> list[tuple]:
        """Take one raw frame; return the rows reported now."""
        self._check_open("update")
        t0 = time.perf_counter()
        z = stream_frame(frame, self.shape, self.frame, "tracker")
        self.k.background(z, self.frame + 1)  # Algs. 8–9
        t1 = time.perf_counter()
        self.seconds["background"] += t1 - t0
        out: list[tuple] = []
        if self.frame < FIRST_FRAMES:
            self._candidate_stage(z)
            self.seconds["candidates"] += time.perf_counter() - t1
        elif len(self.candidates):
            out = self._filter_step()
        self.frame += 1
        return out

    def _candidate_stage(self, z: np.ndarray) -> None:
        """Frames 0–2 kept; at frame 2 the candidates (Eqs. 3.4–3.13), one per 8-connected component."""
        self.first.append(z)
        if len(self.first) < FIRST_FRAMES:
            return
        found, _, _ = find_candidates(np.stack(self.first), self.p.alpha, self.p.se_size, self.p.se_shape,
                                      self.p.max_candidates, engine=self.engine, kernels=self.tophat)
        self.first = []
        self.candidates = found
        if not len(found):
            warnings.warn("tophat-pf: no candidate above the threshold in frames 0–2 (lower alpha?); no tracks",
                          stacklevel=3)

    def _start(self) -> None:
        """Frame 3: each candidate's reference z = the 3×3 maximum of S_3 around it (the candidate pixel itself
        holds the target's negative ghost), and its particles."""
        h, w = self.shape
        s = backend.to_host(self.k.s).ravel()[:h * w].reshape(h, w)  # the Taichi field holds the class's pixels
        init = np.zeros((self.p.max_candidates, 3), np.float32)
        for g, (x, y, _) in enumerate(self.candidates):
            c, r = int(x), int(y)
            init[g] = x, y, s[max(r - 1, 0):min(r + 2, h), max(c - 1, 0):min(c + 2, w)].max()
        self.k.start(init, len(self.candidates))
        self.alive[:len(self.candidates)] = True

    def _filter_step(self) -> list[tuple]:
        t0 = time.perf_counter()
        if self.frame == FIRST_FRAMES:
            self._start()
        since = self.frame - FIRST_FRAMES
        end_1 = window_of(self.lengths, 0, FIRST_FRAMES)[1]
        learnt = self.p.drift and self.frame >= end_1  # B from window 1's path, at its last frame
        motion = learnt and self.frame > end_1 and self.p.weighting == "combined"  # Eq. 3.16 once B is there
        getattr(self.k, step_layout(self.k.live_count))(self.frame, since, int(learnt), int(motion))
        self.summaries.append(backend.to_host(self.k.summary))
        if not self.windows_on:  # Alg. 5 is over: only this frame's summary is read (its rows), so none piles up
            del self.summaries[:-1]
            self.summary_base = self.frame
        t1 = time.perf_counter()
        self.seconds["particles"] += t1 - t0
        out = []
        if self.windows_on and self.frame == self.window[2]:
            out = self._close_window()
        if self.confirmed >= 0:
            out += [self._row(self.frame, g) for g in self.reported]
        self.rows += out
        self.seconds["windows"] += time.perf_counter() - t1
        return out

    def _evidence(self) -> np.ndarray:
        """Each filter's mean S_k/σ_k at its estimate since frame 3."""
        return np.mean([s[:, SUM_SNR] for s in self.summaries], axis=0)

    def _close_window(self) -> list[tuple]:
        """Alg. 5 at the end of a window: J, the merge, the elimination while > 2 remain, the confirmation (at the
        end of window 3, or once ≤ 2 remain), and the next window while > 2 remain."""
        index, first, last = self.window
        path = np.stack([s[:, [SUM_X, SUM_Y]] for s in self.summaries[first - self.summary_base:]])
        self.cost = trajectory_cost(path.astype(np.float64), self.p.epsilon)
        evidence = self._evidence()
        before = self.alive.copy()
        alive = merged(path, self.alive, -evidence, self.p.merge_distance, self.reported)  # the stronger stays
        merged_away = before & ~alive
        if alive.sum() > 2:
            alive = eliminated(alive, self.cost, evidence, self.reported)
        out: list[tuple] = []
        if self.confirmed < 0 and (index >= 2 or alive.sum() <= 2):
            self.confirmed = strongest(alive, evidence, 1)[0]
            self.reported = [self.confirmed] + [g for g in strongest(alive, evidence, 2) if g != self.confirmed]
            self.reported = self.reported[:self.report]
            if self.report == 1:
                alive[:] = False  # the others no longer change the output
                alive[self.confirmed] = True
            if self.paths == "whole":
                out = [self._row(f, g) for g in self.reported for f in range(FIRST_FRAMES, self.frame)]
        self._log_window(index, first, last, before, alive, merged_away, evidence)
        if (alive != self.alive).any():
            self.alive = alive
            self.k.set_alive(alive.astype(np.int32))
        self.windows_on = int(alive.sum()) > 2
        self.window = (index + 1, *window_of(self.lengths, index + 1, last + 1))
        return out

    def _log_window(self, index, first, last, before, alive, merged_away, evidence) -> None:
        for g in np.nonzero(before)[0]:
            action = "confirmed" if g == self.confirmed and alive[g] else "kept" if alive[g] else \
                "merged" if merged_away[g] else "dropped"
            x, y = self.summaries[-1][g, [SUM_X, SUM_Y]]
            self.log.append((index + 1, first, last, int(g) + 1, float(x), float(y), float(self.cost[g]),
                             float(evidence[g]), action))

    def _row(self, frame: int, g: int) -> tuple:
        s = self.summaries[frame - self.summary_base][g]
        return (frame, g + 1, float(s[SUM_X]), float(s[SUM_Y]), float(s[SUM_BX]), float(s[SUM_BY]), float(s[SUM_S]),
                float(np.clip(1.0 - self.cost[g] / 2.0, 0.0, 1.0)))

    def finish(self) -> np.ndarray:
        """Every reported row as a tracks table (empty with no candidate); the diagnostics CSV if asked for."""
        self._close_sequence()
        if self.frame < FIRST_FRAMES + 1:
            raise InputError(f"tophat-pf needs at least {FIRST_FRAMES + 1} frames (3 for the candidates, then the "
                             f"filters), got {self.frame}")
        if self.diagnostics is not None:
            with open(self.diagnostics, "w", newline="") as f:
                out = csv.writer(f)
                out.writerow(DIAGNOSTIC_COLUMNS)
                out.writerows(self.log)
        return make_table(self.rows, _dtype(TRACK_COLUMNS))
