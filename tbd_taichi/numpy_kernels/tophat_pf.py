"""NumPy twin of ``tbd_taichi.kernels.tophat_pf``: the same fields (as arrays), steps and contracts, vectorised over
the live groups' particles; random numbers draw for draw as the kernels'."""
from __future__ import annotations

import numpy as np

from ..kernels.tophat_pf import (CONFIG, NEG_INF, S_RESAMPLE, S_START_X, S_START_Y, S_X, S_Y, SUM_BX, SUM_BY,
                                 SUM_LOGLIK, SUM_NEFF, SUM_S, SUM_SNR, SUM_X, SUM_Y, SUMMARY)
from .rng import normal, uniform_f64

F32 = np.float32


class TophatPFKernels:
    """The fields of ``kernels.tophat_pf.TophatPFKernels`` as arrays, with the same steps."""

    def __init__(self, groups: int, n: int, shape, ring: int):
        self.groups, self.n, self.shape, self.ring = int(groups), int(n), (int(shape[0]), int(shape[1])), int(ring)
        slots = self.groups * self.n
        self.total = np.zeros(self.shape)
        self.s = np.zeros(self.shape, F32)
        self.stats = np.zeros(2)
        self.x, self.y = np.zeros(slots, F32), np.zeros(slots, F32)
        self.xp, self.yp = np.zeros(slots, F32), np.zeros(slots, F32)
        self.logw = np.zeros(slots, F32)
        self.alive = np.zeros(self.groups, np.int32)
        self.ref = np.zeros(self.groups, F32)
        self.ring_xy = np.zeros((self.groups, self.ring, 2), F32)
        self.drift = np.zeros((self.groups, 2), F32)
        self.summary = np.zeros((self.groups, len(SUMMARY)), F32)
        self.config = np.zeros(len(CONFIG), F32)
        self.seed = 0

    @property
    def live_count(self) -> int:
        """The live groups (the kernel's host-side count, which chooses its loop layout)."""
        return int((self.alive == 1).sum())

    def configure(self, seed: int, values) -> None:
        self.seed = int(seed)
        self.config[:] = np.asarray(values, F32)
        self.total[:] = 0.0

    def background(self, frame: np.ndarray, count: int) -> None:
        """Total ← Total + I; S = I − Total/count; stats = (σ, mean) of S."""
        frame = np.asarray(frame, F32).astype(np.float64)
        self.total += frame
        self.s[:] = (frame - self.total / count).astype(F32)
        s = self.s.astype(np.float64)
        mean = s.sum() / s.size
        self.stats[:] = np.sqrt(max((s * s).sum() / s.size - mean * mean, 0.0)), mean

    def start(self, init: np.ndarray, count: int) -> None:
        """Groups g < ``count`` alive from init[g] = (x, y, z)."""
        init = np.asarray(init, F32)
        self.alive[:] = (np.arange(self.groups) < count).astype(np.int32)
        live = np.arange(count)
        self.ref[live] = init[live, 2]
        self.drift[live] = 0.0
        self.summary[live] = 0.0
        self.summary[live, SUM_X], self.summary[live, SUM_Y] = init[live, 0], init[live, 1]
        self.ring_xy[live] = init[live, None, :2]
        p = np.arange(count * self.n)
        g = p // self.n
        sigma_0 = self.config[3]
        self.x[p] = init[g, 0] + sigma_0 * normal(self.seed, 0, S_START_X, p)
        self.y[p] = init[g, 1] + sigma_0 * normal(self.seed, 0, S_START_Y, p)

    def set_alive(self, alive) -> None:
        self.alive[:] = np.asarray(alive, np.int32)

    def step(self, frame: int, since: int, drift: int, motion: int) -> None:
        live = np.nonzero(self.alive == 1)[0]
        if not len(live):
            return
        p = (live[:, None] * self.n + np.arange(self.n)).ravel()
        self._propagate_and_weigh(frame, live, p, motion)
        cum, total, u1 = self._normalise(frame, live, p)
        self._resample(live, p, cum, total, u1)
        self._estimate(live, p, since, drift)

    step_by_group = step_by_particle = step  # the kernel's two loop layouts: the same numbers

    def _propagate_and_weigh(self, frame: int, live, p, motion: int) -> None:
        h, w = self.shape
        c, sigma_v = self.config[0], self.config[1]
        g = np.repeat(live, self.n)
        sigma = F32(self.stats[0])
        inv_var = F32(1.0) / max(sigma * sigma, F32(1e-30))
        x = self.x[p] + self.drift[g, 0] + c * normal(self.seed, frame, S_X, p)
        y = self.y[p] + self.drift[g, 1] + c * normal(self.seed, frame, S_Y, p)
        self.xp[p], self.yp[p] = x, y
        col, row = np.floor(x + F32(0.5)).astype(np.int64), np.floor(y + F32(0.5)).astype(np.int64)
        inside = (col >= 0) & (col < w) & (row >= 0) & (row < h)
        z = self.ref[g]
        sv = self.s[np.clip(row, 0, h - 1), np.clip(col, 0, w - 1)]
        lw = (z * sv - F32(0.5) * z * z) * inv_var  # Eq. 3.14 over the noise density
        if motion:  # Eq. 3.16
            dx = self.drift[g, 0] - (col.astype(F32) - self.summary[g, SUM_X])
            dy = self.drift[g, 1] - (row.astype(F32) - self.summary[g, SUM_Y])
            lw = lw - (dx * dx + dy * dy) * (F32(1.0) / (F32(2.0) * sigma_v * sigma_v))
        self.logw[p] = np.where(inside, lw, F32(NEG_INF)).astype(F32)

    def _normalise(self, frame: int, live, p):
        lw = self.logw[p].reshape(len(live), self.n)
        m = lw.max(axis=1)
        none = m <= F32(NEG_INF)
        # f32 terms (e^x of an f32 x, rounded from f64 as the libm expf the kernel calls), summed in f64
        wts = np.where(none[:, None], 1.0, np.exp((lw - m[:, None]).astype(F32).astype(np.float64))
                   .astype(F32).astype(np.float64))
        cum = np.cumsum(wts, axis=1)
        total, total2 = cum[:, -1], (wts * wts).sum(axis=1)
        self.summary[live, SUM_NEFF] = (total * total / total2).astype(F32)
        self.summary[live, SUM_LOGLIK] = np.log(total / self.n).astype(F32) + np.maximum(m, F32(-1e30))
        return cum, total, uniform_f64(self.seed, frame, S_RESAMPLE, live)

    def _resample(self, live, p, cum, total, u1) -> None:
        """Alg. 2: the first particle whose c_i exceeds (u₁ + j)·(Σw/N), per group."""
        k, n = len(live), self.n
        v = (u1[:, None] + np.arange(n)) * (total / n)[:, None]
        offset = (np.arange(k) * 2.0 * (n + 1))[:, None]  # rows apart: c ≤ N, so the rows never interleave
        idx = np.searchsorted((cum + offset).ravel(), (v + offset).ravel(), side="right")
        rows = np.repeat(np.arange(k), n)
        parents = np.minimum(idx, rows * n + n - 1)
        src = p[parents]
        self.x[p], self.y[p] = self.xp[src], self.yp[src]

    def _estimate(self, live, p, since: int, drift: int) -> None:
        h, w = self.shape
        xs = self.x[p].reshape(len(live), self.n).astype(np.float64)
        ys = self.y[p].reshape(len(live), self.n).astype(np.float64)
        ex, ey = (xs.sum(axis=1) / self.n).astype(F32), (ys.sum(axis=1) / self.n).astype(F32)
        col = np.clip(np.floor(ex + F32(0.5)).astype(np.int64), 0, w - 1)
        row = np.clip(np.floor(ey + F32(0.5)).astype(np.int64), 0, h - 1)
        sigma = F32(self.stats[0])
        self.summary[live, SUM_X], self.summary[live, SUM_Y] = ex, ey
        self.summary[live, SUM_S] = self.s[row, col]
        self.summary[live, SUM_SNR] = self.s[row, col] / max(sigma, F32(1e-30))
        self.ring_xy[live, since % self.ring] = np.stack([ex, ey], axis=1)
        if drift:
            m = min(int(self.config[2]), since)
            if m > 0:
                old = self.ring_xy[live, (since - m) % self.ring]
                self.drift[live, 0] = (ex - old[:, 0]) / F32(m)
                self.drift[live, 1] = (ey - old[:, 1]) / F32(m)
        self.summary[live, SUM_BX], self.summary[live, SUM_BY] = self.drift[live, 0], self.drift[live, 1]
