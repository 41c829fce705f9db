"""NumPy twin of ``tbd_taichi.kernels.multiaspect``: the same fields (as arrays), steps and contracts, vectorised
over the particles; sums within a group run in slot order (cumulative sums) as the kernels' do."""
from __future__ import annotations

import numpy as np

from ..kernels.multiaspect import (GPAR, S_ASPECT, S_BIRTH_CELL, S_DRAW, S_ENTER, S_EXIT, S_F0, S_MOVE, S_NOISE, S_PRIOR,
                                   LAW, STAGE_BASE, STAGE_STREAMS, STATE, SUM_ABSENT, SUM_ASPECT, SUM_X)
from ..kernels.multiaspect import template_pixels, template_support
from ..kernels.phd import ERF_END, SQRT_HALF
from .phd import erf
from .rng import exponential, normal, uniform, uniform_f64

F32 = np.float32


class MultiaspectKernels:
    """The pool of ``kernels.multiaspect.MultiaspectKernels`` as arrays, with the same steps."""

    def __init__(self, groups: int, n: int, shape, template_shape, serial: bool = False):
        self.groups, self.n, self.shape = int(groups), int(n), (int(shape[0]), int(shape[1]))
        self.k, th, tw = (int(v) for v in template_shape)
        self.halves = ((th - 1) // 2, (tw - 1) // 2)
        c, g, (h, w) = self.groups * self.n, self.groups, self.shape
        self.capacity = c
        self.prev, self.prev_z = np.zeros((2 * c, STATE), F32), np.zeros(2 * c, np.int32)  # two sides
        self.prop, self.cur = np.zeros((c, STATE), F32), np.zeros((c, STATE), F32)
        self.prop_z, self.cur_z = np.zeros(c, np.int32), np.zeros(c, np.int32)
        self.prop_ll, self.cur_ll = np.zeros(c, F32), np.zeros(c, F32)
        self.pick, self.anc = np.zeros(c, np.int32), np.zeros(c, np.int32)
        self.cdf, self.total = np.zeros(c), np.zeros(g)
        hh, hw = self.halves
        self.d = np.zeros((g, h + 4 * hh, w + 4 * hw), F32)  # zero border of twice the half sizes, as the kernels'
        self.gpar = np.zeros((g, len(GPAR)), F32)
        self.motion, self.law = np.zeros(3, F32), np.zeros(len(LAW), F32)
        self.support = template_support(th, tw)
        self.t_off, self.t_val = np.zeros((self.k, self.support), np.int32), np.zeros((self.k, self.support), F32)
        self.t_count = np.zeros(self.k, np.int32)
        self.energy = np.zeros((3, self.k, h + th - 1, w + tw - 1), F32)
        self.gcdf = np.zeros((self.k, self.k), F32)
        self.n_cells = (h + th - 1) * (w + tw - 1)
        self.birth_cdf, self.birth_lq = np.zeros((g, self.n_cells)), np.zeros((g, self.n_cells), F32)
        self.blw = np.zeros(c, F32)
        self._slots = np.arange(c)

    def set_templates(self, templates: np.ndarray, energy: np.ndarray) -> None:
        """The templates as their non-zero pixels and their energy tables (see the kernels)."""
        self.t_off[...], self.t_val[...], self.t_count[...] = template_pixels(templates, self.support, self.d.shape[2])
        self.energy[...] = energy

    def set_particles(self, state: np.ndarray, z: np.ndarray, side: int = 0) -> None:
        """prev's side ``side`` ← (C, 4) states and (C,) aspects."""
        sl = slice(side * self.capacity, (side + 1) * self.capacity)
        self.prev[sl], self.prev_z[sl] = state, z

    def particles(self, side: int = 0) -> tuple[np.ndarray, np.ndarray]:
        """prev's side ``side``: (C, 4) states and (C,) aspects."""
        sl = slice(side * self.capacity, (side + 1) * self.capacity)
        return self.prev[sl].copy(), self.prev_z[sl].copy()

    def put(self, name: str, values) -> None:
        """Array ``name`` ← ``values`` (its whole shape)."""
        target = getattr(self, name)
        target[...] = np.asarray(values).reshape(target.shape)

    def get(self, name: str) -> np.ndarray:
        """A copy of array ``name``."""
        return getattr(self, name).copy()

    def load(self, y: np.ndarray, gpar: np.ndarray) -> None:
        """The frames y (G, H, W) and GMRF rows; d = A·y per group (Eq. 16), y = 0 outside the image."""
        (h, w), (hh, hw) = self.shape, self.halves
        self.gpar[...] = gpar
        bh, bv = self.gpar[:, 0, None, None], self.gpar[:, 1, None, None]
        y = np.pad(np.asarray(y, F32), ((0, 0), (1, 1), (1, 1)))
        self.d[:, 2 * hh:2 * hh + h, 2 * hw:2 * hw + w] = \
            y[:, 1:-1, 1:-1] - bh * (y[:, 1:-1, :-2] + y[:, 1:-1, 2:]) - bv * (y[:, :-2, 1:-1] + y[:, 2:, 1:-1])

    def d_image(self, g: int) -> np.ndarray:
        """Group g's d (H, W), without the border."""
        (h, w), (hh, hw) = self.shape, self.halves
        return self.d[g, 2 * hh:2 * hh + h, 2 * hw:2 * hw + w].copy()

    def configure(self, motion, law) -> None:
        """The motion noise factor and f₀'s LAW vector."""
        self.motion[...], self.law[...] = motion, law

    def _law_draw(self, seed: int, frame: int, stream: int, p: np.ndarray, law) -> np.ndarray:
        law = np.asarray(law, F32)
        ux, uy = uniform(seed, frame, stream, p), uniform(seed, frame, stream + 1, p)
        nvx, nvy = normal(seed, frame, stream + 2, p), normal(seed, frame, stream + 3, p)
        uvx, uvy = uniform(seed, frame, stream + 4, p), uniform(seed, frame, stream + 5, p)
        two, one = F32(2.0), F32(1.0)
        return np.stack([law[0] + (law[1] - law[0]) * ux, law[4] + law[5] * nvx + law[6] * (two * uvx - one),
                         law[2] + (law[3] - law[2]) * uy, law[4] + law[5] * nvy + law[6] * (two * uvy - one)],
                        axis=1).astype(F32)

    def _uniform_aspect(self, u: np.ndarray) -> np.ndarray:
        return (1 + np.minimum((u * F32(self.k)).astype(np.int32), self.k - 1)).astype(np.int32)

    def init_prior(self, seed: int, p_absent: float, law) -> None:
        """prev ← the prior (see the kernel)."""
        p, c = self._slots, self.capacity
        self.prev[:c] = self._law_draw(seed, 0, S_PRIOR + 2, p, law)
        absent = uniform(seed, 0, S_PRIOR, p) < F32(p_absent)
        self.prev_z[:c] = np.where(absent, 0, self._uniform_aspect(uniform(seed, 0, S_PRIOR + 1, p)))

    def _on_grid(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        (h, w), (hh, hw) = self.shape, self.halves
        c, r = np.floor(x + F32(0.5)).astype(np.int32), np.floor(y + F32(0.5)).astype(np.int32)
        return (c >= -hw) & (c < w + hw) & (r >= -hh) & (r < h + hh)

    def _p_inside(self, mx: np.ndarray, my: np.ndarray, sd: float) -> np.ndarray:
        """P_in of Eq. 6; 1 where every edge is ≥ ERF_END/s away (see the kernel)."""
        (h, w), (hh, hw) = self.shape, self.halves
        s = F32(SQRT_HALF) / F32(max(sd, 1e-12))
        half = F32(0.5)
        near = np.minimum(np.minimum(F32(w - 0.5 + hw) - mx, mx + F32(hw + 0.5)),
                          np.minimum(F32(h - 0.5 + hh) - my, my + F32(hh + 0.5))) * s < F32(ERF_END)
        out = np.ones(len(mx), F32)
        x, y = mx[near], my[near]
        px = half * (erf((F32(w - 0.5 + hw) - x) * s) - erf((F32(-hw - 0.5) - x) * s))
        py = half * (erf((F32(h - 0.5 + hh) - y) * s) - erf((F32(-hh - 0.5) - y) * s))
        out[near] = px * py
        return out

    def propagate(self, seed: int, frame: int, stage: int, from_ancestor: int, coupled: int, data_births: int,
                  p_a: float, side: int, move: int) -> None:
        """prop ~ Eqs. 2, 4, 5 from prev[p] or prev[anc[p]] on side ``side``, with ℓ; ``move``: the MH step (see
        the kernel)."""
        base, p = STAGE_BASE + STAGE_STREAMS * stage, self._slots
        q = (self.anc if from_ancestor else p) + side * self.capacity
        z, s = self.prev_z[q], self.prev[q]
        a, b, c = self.motion
        law = self.law
        n = [normal(seed, frame, base + S_NOISE + i, p) for i in range(4)]
        moved = np.stack([s[:, 0] + s[:, 1] + a * n[0], s[:, 1] + b * n[0] + c * n[1],
                          s[:, 2] + s[:, 3] + a * n[2], s[:, 3] + b * n[2] + c * n[3]], axis=1).astype(F32)
        u_exit, u_asp = uniform(seed, frame, base + S_EXIT, p), uniform(seed, frame, base + S_ASPECT, p)
        if coupled:
            stays = self._on_grid(moved[:, 0], moved[:, 2])
        else:
            stays = u_exit < self._p_inside(s[:, 0] + s[:, 1], s[:, 2] + s[:, 3], float(a))
        rows = self.gcdf[np.maximum(z - 1, 0)]
        following = (1 + np.minimum((u_asp[:, None] >= rows).sum(axis=1), self.k - 1)).astype(np.int32)
        enter = (z == 0) & (uniform(seed, frame, base + S_ENTER, p) < F32(p_a))
        new_z = np.where(z != 0, np.where(stays, following, 0), np.where(enter, self._uniform_aspect(u_asp), 0))
        self.blw[...] = 0.0
        if enter.any():
            born = p[enter]
            moved[enter] = self._law_draw(seed, frame, base + S_F0, born, law)
            if data_births:
                self._data_births(moved, enter, uniform_f64(seed, frame, base + S_BIRTH_CELL, born), law)
        self.prop[...] = moved
        self.prop_z[...] = new_z
        self.likelihood()
        if move:
            self._metropolis_hastings(uniform(seed, frame, S_MOVE + stage, p), move == 2, 1 - side)

    def _data_births(self, moved: np.ndarray, enter: np.ndarray, u: np.ndarray, law) -> None:
        """Entering particles' cells from the proposal q, their offsets from f₀'s uniforms, blw = log(f₀/q)."""
        law = np.asarray(law, F32)
        g = np.flatnonzero(enter) // self.n
        cell = np.empty(len(g), np.int64)
        for grp in np.unique(g):
            sel = g == grp
            cell[sel] = np.minimum(np.searchsorted(self.birth_cdf[grp], u[sel], side="right"), self.n_cells - 1)
        width = self.shape[1] + 2 * self.halves[1]
        col = (cell % width - self.halves[1]).astype(F32)
        row = (cell // width - self.halves[0]).astype(F32)
        half = F32(0.5)
        moved[enter, 0] = col + (moved[enter, 0] - law[0]) / (law[1] - law[0]) - half
        moved[enter, 2] = row + (moved[enter, 2] - law[2]) / (law[3] - law[2]) - half
        self.blw[enter] = self.birth_lq[g, cell]

    def likelihood(self) -> None:
        """prop_ll = (2λ − ρ)/(2σ_c²) + blw (Eqs. 10, 12, 15; λ over each aspect's non-zero pixels; see the kernel)."""
        hh, hw = self.halves
        z = self.prop_z
        live = np.flatnonzero((z != 0) & self._on_grid(self.prop[:, 0], self.prop[:, 2]))
        out = np.zeros(self.capacity, F32)
        if live.size:
            g = live // self.n
            c = np.floor(self.prop[live, 0] + F32(0.5)).astype(np.int64)
            r = np.floor(self.prop[live, 2] + F32(0.5)).astype(np.int64)
            m = int(self.t_count.max())
            a = z[live] - 1
            hp, wp = self.d.shape[1:]
            corner = (g * hp + r + hh) * wp + c + hw  # the template's top-left pixel in the flat padded d
            flat = self.d.reshape(-1)
            lam = (self.t_val[a, :m] * flat[corner[:, None] + self.t_off[a, :m]]).sum(axis=1, dtype=F32)
            e = self.energy[:, a, r + hh, c + hw]
            rho = e[0] - F32(2.0) * self.gpar[g, 0] * e[1] - F32(2.0) * self.gpar[g, 1] * e[2]
            out[live] = (F32(2.0) * lam - rho) / (F32(2.0) * self.gpar[g, 2])
        self.prop_ll[...] = out + self.blw

    def resample(self, seed: int, frame: int, number: int, second_stage: int, final: int, side: int) -> None:
        """Per group: cumulative weights, N sorted uniforms from N + 1 Exp(1) partial sums merged with them, the
        gather (see the kernel)."""
        v = (self.prop_ll - self.cur_ll if second_stage else self.prop_ll).reshape(self.groups, self.n)
        cdf = np.cumsum(np.exp(v - v.max(axis=1, keepdims=True)).astype(np.float64), axis=1)  # f32 terms
        self.cdf[...] = cdf.ravel()
        self.total[...] = cdf[:, -1]
        pick = np.empty(self.capacity, np.int64)
        for g in range(self.groups):
            e = exponential(seed, frame, S_DRAW + number, np.arange(g * self.n, (g + 1) * self.n + 1))
            partial = np.cumsum(e)
            target = partial[:-1] * (cdf[g, -1] / partial[-1])
            local = np.minimum(np.searchsorted(cdf[g], target, side="right"), self.n - 1)
            pick[g * self.n:(g + 1) * self.n] = local + g * self.n
        self.pick[...] = pick
        if final:
            out = slice((1 - side) * self.capacity, (2 - side) * self.capacity)
            self.prev[out], self.prev_z[out] = self.prop[pick], self.prop_z[pick]
            return
        self.cur[...], self.cur_z[...], self.cur_ll[...] = self.prop[pick], self.prop_z[pick], self.prop_ll[pick]
        self.anc[...] = pick

    def _metropolis_hastings(self, u: np.ndarray, final: bool, side: int) -> None:
        """Eqs. 19–21 on every slot's own proposal; ``final``: the outcome to prev's side ``side``."""
        accept = np.log(u) <= self.prop_ll - self.cur_ll
        if final:
            out = slice(side * self.capacity, (side + 1) * self.capacity)
            self.prev[out] = np.where(accept[:, None], self.prop, self.cur)
            self.prev_z[out] = np.where(accept, self.prop_z, self.cur_z)
            return
        self.cur[accept], self.cur_z[accept], self.cur_ll[accept] = (self.prop[accept], self.prop_z[accept],
                                                                     self.prop_ll[accept])

    def summarize(self, out: np.ndarray, side: int) -> None:
        """Per group of prev's side ``side``: absent count, present sums, aspect counts, into ``out``."""
        sl = slice(side * self.capacity, (side + 1) * self.capacity)
        z = self.prev_z[sl].reshape(self.groups, self.n)
        s = self.prev[sl].astype(np.float64).reshape(self.groups, self.n, STATE)
        out[:, SUM_ABSENT] = (z == 0).sum(axis=1)
        out[:, SUM_X:SUM_X + STATE] = (s * (z != 0)[:, :, None]).sum(axis=1)
        for a in range(self.k):
            out[:, SUM_ASPECT + a] = (z == a + 1).sum(axis=1)
