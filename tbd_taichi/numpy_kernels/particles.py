"""NumPy twin of ``tbd_taichi.kernels.particles``: the same pool, the same keys, the same contracts.

Integer and f64 bookkeeping (existence draws, tile sums, cumulative weights, parents)
follows the kernels' operation order, so given the same weights it picks the same
parents; f32 transcendental results (exp, log, cos) may differ by a few ulps.
"""
from __future__ import annotations

import numpy as np

from ..kernels.particles.layout import (C_I_FLOOR, C_NOISE_SIGMA, C_PSF_SIGMA, C_Q1, C_Q2, COPY_TRIES, M_BEST,
                                         N_CONSTANTS, N_MOMENTS, NEG_INF, S_BIRTH_ANGLE, S_BIRTH_I, S_BIRTH_MU,
                                         S_BIRTH_PIXEL, S_BIRTH_SPEED, S_BIRTH_X, S_BIRTH_Y, S_COPY, S_EXIST,
                                         NOISE_STREAMS, PAD, S_RESAMPLE, S_RESAMPLE_END, S_SYSTEMATIC, STATE, TILE,
                                         TWO_PI)
from . import models, rng

F32 = np.float32


class NumpyParticleKernels:
    """Arrays and vectorised steps of one particle pool (same names as the Taichi class; ``serial``, ``flat``
    and ``split``, the Taichi kernels' loop layout, do not change the results and are not used here)."""

    def __init__(self, capacity: int, n_groups: int, n_tiles: int, frame_shape, map_capacity: int, serial: bool,
                 flat: bool, split: int = 1):
        c, g = capacity, n_groups
        self.capacity = capacity
        for name in ("x", "vx", "y", "vy", "inten"):
            setattr(self, name, np.zeros((2, c), F32))
        for name in ("e", "tp", "seq"):
            setattr(self, name, np.zeros((2, c), np.int32))
        self.logw, self.born, self.parent, self.cum, self.spc = np.zeros(c, F32), np.zeros(c, np.int32), \
            np.zeros(c, np.int32), np.zeros(c), np.zeros(c)
        self.slot_group = np.full(c, -1, np.int32)
        for name in ("off", "cap", "n", "n_out", "n_before", "kind", "gt0", "gt1", "map_off", "map_n"):
            setattr(self, name, np.zeros(g, np.int32))
        for name in ("pb", "pd", "mu", "bx0", "bx1", "by0", "by1", "vmax", "imin", "imax", "gmax", "gmax_e"):
            setattr(self, name, np.zeros(g, F32))
        self.best_e = np.zeros(g, F32)
        # f64: the host's values exactly, which the NumPy steps use as Python floats (as the Taichi kernels take
        # them rounded to f32)
        self.constants, self.seed_key = np.zeros(N_CONSTANTS), np.zeros(1, np.uint32)
        self.frame_hw = np.array(frame_shape, np.int32)  # (H, W), written again by the pool's set-up, as in Taichi
        self.gtotal, self.map_total, self.gspc = np.zeros(g), np.zeros(g), np.zeros(g)
        self.tile_start, self.tile_group = np.zeros(n_tiles, np.int32), np.zeros(n_tiles, np.int32)
        self.tile_max, self.tile_max_e = np.zeros(n_tiles, F32), np.zeros(n_tiles, F32)
        self.tile_total, self.tile_prefix = np.zeros(n_tiles), np.zeros(n_tiles)
        self.tile_spc, self.tile_spc_prefix = np.zeros(n_tiles), np.zeros(n_tiles)
        self.tile_moments = np.zeros((n_tiles, N_MOMENTS))
        self.map_pixel, self.map_seq = np.zeros(map_capacity, np.int32), np.zeros(map_capacity, np.int32)
        self.map_cdf = np.zeros(map_capacity)

    # ------------------------------------------------------------ helpers

    def step_values(self) -> tuple:
        """(seed, q1, q2, I_floor, W, H, Σ, σ): the pool's ``constants`` (as Python floats) and ``seed_key`` and the
        frame's shape (``frame_hw``)."""
        c = [float(v) for v in self.constants]
        h, w = (int(v) for v in self.frame_hw)
        return (int(self.seed_key[0]), c[C_Q1], c[C_Q2], c[C_I_FLOOR], w, h, c[C_PSF_SIGMA], c[C_NOISE_SIGMA])

    def live_slots(self) -> np.ndarray:
        g = self.slot_group
        idx = np.arange(self.capacity)
        ok = g >= 0
        ok[ok] = idx[ok] - self.off[g[ok]] < self.n[g[ok]]
        return np.flatnonzero(ok)

    def tile_ends(self) -> np.ndarray:
        g = self.tile_group
        return np.minimum(self.tile_start + TILE, self.off[g] + self.n[g])

    # ------------------------------------------------------------ Eqs. 7–10

    def predict_existence(self, seed: int, frame: int, b: int) -> None:
        i = self.live_slots()
        g = self.slot_group[i]
        u = rng.uniform(seed, frame, S_EXIST, i)
        e0 = self.e[b, i]
        e1 = np.where(e0 == 1, u >= self.pd[g], u < self.pb[g]).astype(np.int32)
        self.born[i] = ((e0 == 0) & (e1 == 1)).astype(np.int32)
        self.e[b, i] = e1

    def map_entry_draw(self, g: np.ndarray, v: np.ndarray) -> np.ndarray:
        out = np.empty(len(g), np.int64)
        for grp in np.unique(g):
            sel = g == grp
            lo, n = self.map_off[grp], self.map_n[grp]
            k = np.searchsorted(self.map_cdf[lo:lo + n], v[sel], side="right")
            out[sel] = lo + np.minimum(k, n - 1)
        return out

    def store_counts(self, counts: np.ndarray) -> None:
        self.n_before[:] = self.n
        self.n[:] = counts

    def mark_initial(self) -> None:
        i = self.live_slots()
        g = self.slot_group[i]
        new = i - self.off[g] >= self.n_before[g]
        self.born[i[new]] = 2

    def predict(self, frame: int, b: int, counts: np.ndarray) -> None:
        seed, q1, q2, i_floor, width, height, _, _ = self.step_values()
        self.predict_existence(seed, frame, b)
        self.store_counts(counts)
        self.mark_initial()
        self.draw_newborn(seed, frame, b, width)
        self.propagate(seed, frame, b, q1, q2, i_floor, width, height)

    def draw_newborn(self, seed: int, frame: int, b: int, width: int) -> None:
        i = self.live_slots()
        i = i[self.born[i] >= 1]
        g = self.slot_group[i]
        kind = self.kind[g]
        self._copy_newborn(seed, frame, b, i[kind == 2], g[kind == 2])
        unplaceable = (kind == 1) & (self.map_n[g] == 0)
        self.e[b, i[unplaceable]] = 0
        keep = (kind <= 1) & ~unplaceable
        i, g = i[keep], g[keep]
        ux, uy = rng.uniform(seed, frame, S_BIRTH_X, i), rng.uniform(seed, frame, S_BIRTH_Y, i)
        x = self.bx0[g] + (self.bx1[g] - self.bx0[g]) * ux
        y = self.by0[g] + (self.by1[g] - self.by0[g]) * uy
        from_map = self.kind[g] == 1
        if from_map.any():
            v = rng.uniform_f64(seed, frame, S_BIRTH_PIXEL, i[from_map]) * self.map_total[g[from_map]]
            m = self.map_entry_draw(g[from_map], v)
            p = self.map_pixel[m].astype(np.int64)
            x[from_map] = (p % width).astype(F32) + (ux[from_map] - F32(0.5))
            y[from_map] = (p // width).astype(F32) + (uy[from_map] - F32(0.5))
            self.seq[b, i[from_map]] = self.map_seq[m]
        speed = self.vmax[g] * rng.uniform(seed, frame, S_BIRTH_SPEED, i)
        angle = F32(TWO_PI) * rng.uniform(seed, frame, S_BIRTH_ANGLE, i)
        self.x[b, i], self.y[b, i] = x, y
        self.vx[b, i], self.vy[b, i] = speed * np.cos(angle), speed * np.sin(angle)
        self.inten[b, i] = self.imin[g] + (self.imax[g] - self.imin[g]) * rng.uniform(seed, frame, S_BIRTH_I, i)
        self.tp[b, i] = 1
        initial = self.born[i] == 2
        self.e[b, i[initial]] = (rng.uniform(seed, frame, S_BIRTH_MU, i[initial]) < self.mu[g[initial]]).astype(np.int32)

    def _copy_newborn(self, seed: int, frame: int, b: int, i: np.ndarray, g: np.ndarray) -> None:
        """Kind 2: copy a random E = 1, not-newborn particle of the same group (first hit of COPY_TRIES draws)."""
        found = np.full(len(i), -1, np.int64)
        for t in range(COPY_TRIES):
            u = rng.uniform(seed, frame, S_COPY, i.astype(np.int64) * COPY_TRIES + t)
            j = self.off[g] + np.minimum((u * self.n[g].astype(F32)).astype(np.int64), self.n[g] - 1)
            ok = (found < 0) & (self.e[b, j] == 1) & (self.born[j] == 0)
            found[ok] = j[ok]
        hit = found >= 0
        for name in ("x", "vx", "y", "vy", "inten", "tp", "seq"):
            arr = getattr(self, name)
            arr[b, i[hit]] = arr[b, found[hit]]
        self.e[b, i] = hit.astype(np.int32)

    def propagate(self, seed, frame, b, q1, q2, i_floor, width, height) -> None:
        """Eqs. 9–10 (``models.ncv_step``) for the particles that move; Tp + 1; E ← 0 outside the image."""
        factors = models.ncv_noise_factors(q1, q2)
        i = self.live_slots()
        i = i[(self.e[b, i] == 1) & ((self.born[i] == 0) | (self.kind[self.slot_group[i]] == 2))]
        n = tuple(rng.normal(seed, frame, stream, i) for stream in NOISE_STREAMS)
        x, vx, y, vy, inten = models.ncv_step(self.x[b, i], self.vx[b, i], self.y[b, i], self.vy[b, i],
                                              self.inten[b, i], n, factors, i_floor)
        self.x[b, i], self.vx[b, i], self.y[b, i], self.vy[b, i], self.inten[b, i] = x, vx, y, vy, inten
        self.tp[b, i] += 1
        out = (x < -0.5) | (x >= width - 0.5) | (y < -0.5) | (y >= height - 0.5)
        self.e[b, i[out]] = 0

    # ------------------------------------------------------------ Eqs. 11–15

    def log_weights(self, b: int, psf_sigma: float, noise_sigma: float, z: np.ndarray) -> None:
        """Eq. 15 (``models.point_psf_log_ratio``) for every live E = 1 particle, 0 for E = 0; ``z`` zero-bordered
        by PAD pixels, as the kernel reads it."""
        i = self.live_slots()
        self.logw[i] = 0.0
        i = i[self.e[b, i] == 1]
        self.logw[i] = models.point_psf_log_ratio(self.x[b, i], self.y[b, i], self.inten[b, i],
                                                  z[PAD:-PAD, PAD:-PAD], models.psf_constants(psf_sigma, noise_sigma))

    def normalise(self, b: int) -> None:
        self.tile_maxima(b)
        self.group_maxima()
        self.tile_cumulative()
        self.group_prefix()

    def weigh(self, b: int, z: np.ndarray) -> None:
        *_, psf_sigma, noise_sigma = self.step_values()
        self.log_weights(b, psf_sigma, noise_sigma, z)
        self.normalise(b)
        self.best_e[:] = self.gmax_e

    # ------------------------------------------------------------ Eqs. 16–18

    def _tile_slices(self):
        for t, (s, e) in enumerate(zip(self.tile_start, self.tile_ends())):
            yield t, int(s), int(max(e, s))

    def _tile_matrix(self, per_slot: np.ndarray, ends: np.ndarray, fill) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Per-slot values laid out as (n_tiles, TILE) rows, ``fill`` past each tile's end; with the
        slot index and validity of every cell.  Row-wise NumPy reductions then follow the kernels'
        serial in-tile order (a padding 0 added to a sum, or −inf to a max, changes nothing)."""
        idx = self.tile_start[:, None] + np.arange(TILE)
        valid = idx < ends[:, None]
        return np.where(valid, per_slot[np.minimum(idx, self.capacity - 1)], fill), idx, valid

    def _tile_cumsum(self, per_slot: np.ndarray, ends: np.ndarray, out: np.ndarray) -> np.ndarray:
        """In-tile running sums (f64) into ``out`` at each tile's slots; returns the tile totals."""
        m, idx, valid = self._tile_matrix(per_slot.astype(np.float64), ends, 0.0)
        c = np.cumsum(m, axis=1)
        out[idx[valid]] = c[valid]
        return c[:, -1]

    def tile_maxima(self, b: int) -> None:
        ends = self.tile_ends()
        self.tile_max[:] = self._tile_matrix(self.logw, ends, F32(NEG_INF))[0].max(axis=1)
        lw_e = np.where(self.e[b] == 1, self.logw, F32(NEG_INF))
        self.tile_max_e[:] = self._tile_matrix(lw_e, ends, F32(NEG_INF))[0].max(axis=1)

    def group_maxima(self) -> None:
        for g in range(len(self.off)):
            t = slice(self.gt0[g], self.gt1[g])
            self.gmax[g] = max(self.tile_max[t].max(initial=NEG_INF), F32(NEG_INF))
            self.gmax_e[g] = max(self.tile_max_e[t].max(initial=NEG_INF), F32(NEG_INF))

    def tile_cumulative(self) -> None:
        gmax = np.zeros(self.capacity)
        live = self.slot_group >= 0
        gmax[live] = self.gmax[self.slot_group[live]]
        with np.errstate(over="ignore"):  # slots past the live ones hold stale weights
            w = np.exp(self.logw.astype(np.float64) - gmax)
        self.tile_total[:] = self._tile_cumsum(w, self.tile_ends(), self.cum)

    @staticmethod
    def _exclusive_prefix(totals: np.ndarray, t0: int, t1: int, prefix: np.ndarray) -> float:
        """prefix[t] = Σ_{t0 ≤ k < t} totals[k] in tile order (serial f64); returns the whole sum."""
        s = 0.0
        for t in range(t0, t1):
            prefix[t] = s
            s += totals[t]
        return s

    def group_prefix(self) -> None:
        for g in range(len(self.off)):
            self.gtotal[g] = self._exclusive_prefix(self.tile_total, self.gt0[g], self.gt1[g], self.tile_prefix)

    def _out_tile_ends(self) -> np.ndarray:
        g = self.tile_group
        return np.where(self.n[g] > 0, np.minimum(self.tile_start + TILE, self.off[g] + self.n_out[g]), 0)

    def tile_spacings(self, seed: int, frame: int) -> None:
        spacing = rng.exponential(seed, frame, S_RESAMPLE, np.arange(self.capacity))
        self.tile_spc[:] = self._tile_cumsum(spacing, self._out_tile_ends(), self.spc)

    def group_spacings(self, seed: int, frame: int) -> None:
        end = rng.exponential(seed, frame, S_RESAMPLE_END, np.arange(len(self.off)))
        for g in range(len(self.off)):
            self.gspc[g] = self._exclusive_prefix(self.tile_spc, self.gt0[g], self.gt1[g], self.tile_spc_prefix) + end[g]

    def draw_parents(self, systematic: bool, seed: int, frame: int) -> None:
        u0 = rng.uniform_f64(seed, frame, S_SYSTEMATIC, np.arange(len(self.off)))
        for g in range(len(self.off)):
            n, m_out, off = int(self.n[g]), int(self.n_out[g]), int(self.off[g])
            if n == 0 or m_out == 0:
                continue
            slots = off + np.arange(m_out)
            if systematic:
                v = (slots - off + u0[g]) * (self.gtotal[g] / np.float64(m_out))
            else:
                v = (self.tile_spc_prefix[self.gt0[g] + (slots - off) // TILE] + self.spc[slots]) * \
                    (self.gtotal[g] / self.gspc[g])
            live = off + np.arange(n)
            edges = self.tile_prefix[self.gt0[g] + (live - off) // TILE] + self.cum[live]  # Eq. 17
            self.parent[slots] = off + np.minimum(np.searchsorted(edges, v, side="right"), n - 1)

    def set_counts(self, counts: np.ndarray) -> None:
        self.store_counts(counts)

    def step(self, frame, b, counts, n_out, z, seq, options) -> None:
        """``options.fused`` changes only how the Taichi kernel orders its loops, not the result."""
        self.predict(frame, b, counts)
        self.weigh(b, z)
        self.resample(frame, b, n_out, options.systematic)
        if options.read_seq:
            self.read_seq(1 - b, seq)
        if options.number:
            self.number_populations(1 - b, seq)

    def resample(self, frame: int, b: int, counts: np.ndarray, systematic: bool) -> None:
        seed = self.step_values()[0]
        self.n_out[:] = np.where(self.n > 0, counts, 0)
        if not systematic:
            self.tile_spacings(seed, frame)
            self.group_spacings(seed, frame)
        self.draw_parents(systematic, seed, frame)
        self.gather(b)
        self.n[:] = self.n_out

    def write_slots(self, b, slots, floats, ints, counts) -> None:
        for name, value in zip(STATE, list(floats) + list(ints)):
            getattr(self, name)[b, slots] = value
        self.store_counts(counts)

    def keep_particles(self, b: int, keep: np.ndarray) -> None:
        start = 0
        for g in range(len(self.off)):
            off, n = int(self.off[g]), int(self.n[g])
            kept = off + np.flatnonzero(keep[start:start + n])
            for name in STATE:
                arr = getattr(self, name)
                arr[b, off:off + len(kept)] = arr[b, kept]
            self.n[g] = len(kept)
            start += n

    def read_slots(self, b, slots, floats, ints) -> None:
        for name, out in zip(STATE, list(floats[:5]) + list(ints)):
            out[:] = getattr(self, name)[b, slots]
        floats[5] = self.logw[slots]

    def gather(self, src: int) -> None:
        dst = 1 - src
        for g in range(len(self.off)):
            m_out = int(self.n_out[g])
            if m_out == 0 or self.n[g] == 0:
                continue
            slots = self.off[g] + np.arange(m_out)
            p = self.parent[slots]
            for name in STATE:
                arr = getattr(self, name)
                arr[dst, slots] = arr[src, p]
            self.logw[slots] = 0.0

    # ------------------------------------------------------------ Eq. 19

    def tile_sums(self, b: int) -> None:
        for t, s, e in self._tile_slices():
            ev = self.e[b, s:e].astype(np.float64)
            x, y = self.x[b, s:e].astype(np.float64), self.y[b, s:e].astype(np.float64)
            cols = [np.ones_like(ev), ev, ev * x, ev * self.vx[b, s:e], ev * y, ev * self.vy[b, s:e],
                    ev * self.inten[b, s:e], self.tp[b, s:e].astype(np.float64), x, y, x * x, y * y, x * y,
                    ev * x * x, ev * y * y, ev * x * y]
            self.tile_moments[t] = [np.sum(c, dtype=np.float64) for c in cols]

    def estimates(self, b: int, moments: np.ndarray) -> None:
        self.tile_sums(b)
        for g in range(len(self.off)):
            moments[g, :N_MOMENTS] = self.tile_moments[self.gt0[g]:self.gt1[g]].sum(axis=0)
        moments[:, M_BEST] = self.best_e

    def load_map(self, off, count, total, pixel, seq, cdf) -> None:
        self.map_off[:], self.map_n[:], self.map_total[:] = off, count, total
        self.map_pixel[:len(pixel)], self.map_seq[:len(seq)], self.map_cdf[:len(cdf)] = pixel, seq, cdf

    def read_seq(self, b, seq) -> None:
        live = self.seq[b, self.live_slots()]
        seq[:len(live)] = live  # the front, as the kernel writes it (the step's spare when none is live)
