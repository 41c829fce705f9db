"""NumPy twin of ``tbd_taichi.kernels.particles``: the same pool, the same keys, the same contracts.

Integer and f64 bookkeeping (existence draws, tile sums, cumulative weights, parents)
follows the kernels' operation order, so given the same weights it picks the same
parents; f32 transcendental results (exp, log, cos) may differ by a few ulps.
"""
from __future__ import annotations

import numpy as np

from ..kernels.particles import (COPY_TRIES, N_MOMENTS, NEG_INF, S_BIRTH_ANGLE, S_BIRTH_I, S_BIRTH_MU,
                                  S_BIRTH_PIXEL, S_BIRTH_SPEED, S_BIRTH_X, S_BIRTH_Y, S_COPY, S_EXIST, S_NOISE_I,
                                  S_NOISE_V, S_NOISE_XY, S_RESAMPLE, TILE, TWO_PI)
from . import rng

F32 = np.float32


class NumpyParticleKernels:
    """Arrays and vectorised steps of one particle pool (same names as the Taichi class)."""

    def __init__(self, capacity: int, n_groups: int, n_tiles: int, frame_shape, map_capacity: int, serial: bool):
        c, g = capacity, n_groups
        self.capacity = capacity
        for name in ("x", "vx", "y", "vy", "inten"):
            setattr(self, name, np.zeros((2, c), F32))
        for name in ("e", "tp", "seq"):
            setattr(self, name, np.zeros((2, c), np.int32))
        self.logw, self.born, self.parent, self.cum = np.zeros(c, F32), np.zeros(c, np.int32), \
            np.zeros(c, np.int32), np.zeros(c)
        self.slot_group = np.full(c, -1, np.int32)
        for name in ("off", "cap", "n", "n_out", "kind", "gt0", "gt1", "map_off", "map_n"):
            setattr(self, name, np.zeros(g, np.int32))
        for name in ("pb", "pd", "mu", "bx0", "bx1", "by0", "by1", "vmax", "imin", "imax", "gmax", "gmax_e"):
            setattr(self, name, np.zeros(g, F32))
        self.gtotal, self.u0, self.map_total = np.zeros(g), np.zeros(g), np.zeros(g)
        self.tile_start, self.tile_group = np.zeros(n_tiles, np.int32), np.zeros(n_tiles, np.int32)
        self.tile_max, self.tile_max_e = np.zeros(n_tiles, F32), np.zeros(n_tiles, F32)
        self.tile_total, self.tile_prefix = np.zeros(n_tiles), np.zeros(n_tiles)
        self.tile_moments, self.moments = np.zeros((n_tiles, N_MOMENTS)), np.zeros((g, N_MOMENTS))
        self.map_pixel, self.map_cdf = np.zeros(map_capacity, np.int32), np.zeros(map_capacity)
        self.z = np.zeros(frame_shape, F32)
        self.label = np.zeros(frame_shape, np.int32)

    # ------------------------------------------------------------ helpers

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

    def map_pixel_draw(self, g: np.ndarray, v: np.ndarray) -> np.ndarray:
        out = np.empty(len(g), np.int64)
        for grp in np.unique(g):
            sel = g == grp
            lo, n = self.map_off[grp], self.map_n[grp]
            k = np.searchsorted(self.map_cdf[lo:lo + n], v[sel], side="right")
            out[sel] = self.map_pixel[lo + np.minimum(k, n - 1)]
        return out

    def mark_initial(self, old_counts: np.ndarray) -> None:
        i = self.live_slots()
        g = self.slot_group[i]
        new = i - self.off[g] >= old_counts[g]
        self.born[i[new]] = 2

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
            p = self.map_pixel_draw(g[from_map], v)
            x[from_map] = (p % width).astype(F32) + (ux[from_map] - F32(0.5))
            y[from_map] = (p // width).astype(F32) + (uy[from_map] - F32(0.5))
            self.seq[b, i[from_map]] = self.label[p // width, p % width]
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
        q1, q2 = F32(q1), F32(q2)
        c11, c21, c22 = np.sqrt(q1 / F32(3.0)), np.sqrt(q1) * F32(0.8660254037844386), np.sqrt(q1) * F32(0.5)
        i = self.live_slots()
        i = i[(self.e[b, i] == 1) & ((self.born[i] == 0) | (self.kind[self.slot_group[i]] == 2))]
        n1, n3 = rng.normal_pair(seed, frame, S_NOISE_XY, i)
        n2, n4 = rng.normal_pair(seed, frame, S_NOISE_V, i)
        n5 = rng.normal_pair(seed, frame, S_NOISE_I, i)[0]
        x = self.x[b, i] + self.vx[b, i] + c11 * n1
        y = self.y[b, i] + self.vy[b, i] + c11 * n3
        self.x[b, i], self.y[b, i] = x, y
        self.vx[b, i] += c21 * n1 + c22 * n2
        self.vy[b, i] += c21 * n3 + c22 * n4
        self.inten[b, i] = np.maximum(self.inten[b, i] + np.sqrt(q2) * n5, F32(i_floor))
        self.tp[b, i] += 1
        out = (x < -0.5) | (x >= width - 0.5) | (y < -0.5) | (y >= height - 0.5)
        self.e[b, i[out]] = 0

    # ------------------------------------------------------------ Eqs. 11–15

    def log_weights(self, b: int, psf_sigma: float, noise_sigma: float) -> None:
        i = self.live_slots()
        self.logw[i] = 0.0
        i = i[self.e[b, i] == 1]
        h, w = self.z.shape
        sig = F32(psf_sigma)
        inv2s2 = F32(1.0) / (F32(2.0) * sig * sig)
        norm = F32(1.0) / (F32(TWO_PI) * sig * sig)
        inv_var = F32(1.0) / (F32(noise_sigma) * F32(noise_sigma))
        x, y = self.x[b, i], self.y[b, i]
        cx = np.floor(x + F32(0.5)).astype(np.int64)
        cy = np.floor(y + F32(0.5)).astype(np.int64)
        k = np.arange(-2, 3)
        px, py = cx[:, None] + k, cy[:, None] + k
        dx, dy = px.astype(F32) - x[:, None], py.astype(F32) - y[:, None]
        in_x, in_y = (px >= 0) & (px < w), (py >= 0) & (py < h)
        gx = np.where(in_x, np.exp(-dx * dx * inv2s2), F32(0)).astype(F32)
        gy = np.where(in_y, np.exp(-dy * dy * inv2s2), F32(0)).astype(F32)
        zwin = self.z[np.clip(py, 0, h - 1)[:, :, None], np.clip(px, 0, w - 1)[:, None, :]]
        use = (gy[:, :, None] > 0) & (gx[:, None, :] > 0)
        sz = np.zeros(len(i), F32)
        for j in range(5):
            row = np.zeros(len(i), F32)
            for kk in range(5):
                row = row + np.where(use[:, j, kk], gx[:, kk] * zwin[:, j, kk], F32(0))
            sz = sz + gy[:, j] * row
        a = self.inten[b, i] * norm
        sgx = ((((gx[:, 0] * gx[:, 0] + gx[:, 1] * gx[:, 1]) + gx[:, 2] * gx[:, 2]) + gx[:, 3] * gx[:, 3])
               + gx[:, 4] * gx[:, 4])
        sgy = ((((gy[:, 0] * gy[:, 0] + gy[:, 1] * gy[:, 1]) + gy[:, 2] * gy[:, 2]) + gy[:, 3] * gy[:, 3])
               + gy[:, 4] * gy[:, 4])
        self.logw[i] = (a * sz - F32(0.5) * a * a * sgx * sgy) * inv_var

    # ------------------------------------------------------------ Eqs. 16–18

    def _tile_slices(self):
        for t, (s, e) in enumerate(zip(self.tile_start, self.tile_ends())):
            yield t, int(s), int(max(e, s))

    def tile_maxima(self, b: int) -> None:
        for t, s, e in self._tile_slices():
            lw = self.logw[s:e]
            self.tile_max[t] = lw.max() if e > s else NEG_INF
            sel = self.e[b, s:e] == 1
            self.tile_max_e[t] = lw[sel].max() if sel.any() else NEG_INF

    def group_maxima(self) -> None:
        for g in range(len(self.off)):
            t = slice(self.gt0[g], self.gt1[g])
            self.gmax[g] = max(self.tile_max[t].max(initial=NEG_INF), F32(NEG_INF))
            self.gmax_e[g] = max(self.tile_max_e[t].max(initial=NEG_INF), F32(NEG_INF))

    def tile_cumulative(self) -> None:
        for t, s, e in self._tile_slices():
            g = self.tile_group[t]
            self.cum[s:e] = np.cumsum(np.exp(self.logw[s:e].astype(np.float64) - np.float64(self.gmax[g])))
            self.tile_total[t] = self.cum[e - 1] if e > s else 0.0

    def group_prefix(self) -> None:
        for g in range(len(self.off)):
            s = 0.0
            for t in range(self.gt0[g], self.gt1[g]):
                self.tile_prefix[t] = s
                s += self.tile_total[t]
            self.gtotal[g] = s

    def find_parent(self, g: int, v: np.ndarray) -> np.ndarray:
        t0, t1 = self.gt0[g], self.gt1[g]
        prefix = self.tile_prefix[t0:t1]
        t = t0 + np.searchsorted(prefix, v, side="right") - 1
        ends = self.tile_ends()
        t = np.maximum(t, t0)
        empty = self.tile_start[t] >= ends[t]
        while empty.any():
            t[empty & (t > t0)] -= 1
            empty = (self.tile_start[t] >= ends[t]) & (t > t0)
        r = v - self.tile_prefix[t]
        out = np.empty(len(v), np.int64)
        for tile in np.unique(t):
            sel = t == tile
            s, e = self.tile_start[tile], ends[tile]
            k = np.searchsorted(self.cum[s:e], r[sel], side="right")
            out[sel] = s + np.minimum(k, e - s - 1)
        return out

    def draw_parents(self, seed: int, frame: int, systematic: int) -> None:
        for g in range(len(self.off)):
            m_out = int(self.n_out[g])
            if m_out == 0 or self.n[g] == 0:
                continue
            slots = self.off[g] + np.arange(m_out)
            if systematic:
                u = (np.arange(m_out, dtype=np.float64) + self.u0[g]) / float(m_out)
            else:
                u = rng.uniform_f64(seed, frame, S_RESAMPLE, slots)
            self.parent[slots] = self.find_parent(g, u * self.gtotal[g])

    def set_counts(self, which: int, counts: np.ndarray) -> None:
        if which == 0:
            self.n[:] = counts
        else:
            self.n_out[:] = np.where(self.n > 0, counts, 0)

    def commit_counts(self) -> None:
        self.n[:] = self.n_out

    def load_frame(self, z: np.ndarray) -> None:
        self.z[...] = z

    def write_slots(self, b, start, x, vx, y, vy, inten, e, tp, seq) -> None:
        s = slice(start, start + len(x))
        for name, value in zip(("x", "vx", "y", "vy", "inten", "e", "tp", "seq"), (x, vx, y, vy, inten, e, tp, seq)):
            getattr(self, name)[b, s] = value

    def load_labels(self, labels: np.ndarray) -> None:
        self.label[...] = labels

    def gather(self, src: int) -> None:
        dst = 1 - src
        for g in range(len(self.off)):
            m_out = int(self.n_out[g])
            if m_out == 0 or self.n[g] == 0:
                continue
            slots = self.off[g] + np.arange(m_out)
            p = self.parent[slots]
            for name in ("x", "vx", "y", "vy", "inten", "e", "tp", "seq"):
                arr = getattr(self, name)
                arr[dst, slots] = arr[src, p]
            self.logw[slots] = 0.0

    # ------------------------------------------------------------ Eq. 19

    def tile_sums(self, b: int) -> None:
        for t, s, e in self._tile_slices():
            ev = self.e[b, s:e].astype(np.float64)
            x, y = self.x[b, s:e].astype(np.float64), self.y[b, s:e].astype(np.float64)
            cols = [np.ones_like(ev), ev, ev * x, ev * self.vx[b, s:e], ev * y, ev * self.vy[b, s:e],
                    ev * self.inten[b, s:e], self.tp[b, s:e].astype(np.float64), x, y, x * x, y * y, x * y]
            self.tile_moments[t] = [np.sum(c, dtype=np.float64) for c in cols]

    def group_sums(self) -> None:
        for g in range(len(self.off)):
            self.moments[g] = self.tile_moments[self.gt0[g]:self.gt1[g]].sum(axis=0)

