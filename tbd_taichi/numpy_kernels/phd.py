"""NumPy twin of ``tbd_taichi.kernels.phd``: the same fields (as arrays), steps and contracts, vectorised over the
particles; sums within a group run in slot order as the kernels' do."""
from __future__ import annotations

import numpy as np

from ..kernels.phd import (BETA_ROW, BIRTH_WIDTH, CX, CY, DIM, ERF_END, ERF_STEPS, EST_COV, EST_MEAN, EST_MASS,
                           EST_PEAK, EST_PROB, EST_WIDTH, FRAME, GROUP_FLOAT, NO_CENTRE, RADIUS, erf_table_values,
                           GROUP_INT, LENGTH, LOG_ZERO, MAX_MODELS, N_HAT, OUT_ID, OUT_LEN, OUT_START, OUT_WEIGHT,
                           PIXEL_FIELDS, RATIO_CAP, SHIFT_MAX,
                           QSCALE, S_CELL, S_I, S_MODEL, S_NOISE, S_RESAMPLE, S_SWITCH, S_VX, S_VY, S_X, S_Y,
                           SQRT_HALF, START, TOP, TOTAL)
from ..kernels.loops import frame_class, in_corner
from .rng import normal, uniform

F32 = np.float32
_ERF = erf_table_values()


def erf(x) -> np.ndarray:
    """float32 erf by linear interpolation in the kernels' table, as the kernels' ``erf``."""
    x = np.asarray(x, F32)
    a = np.fmin(np.abs(x) * F32(ERF_STEPS), F32(ERF_END * ERF_STEPS))  # NaN reads the end, as the kernel's min
    i = a.astype(np.int32)
    lo = _ERF[i]
    y = lo + (a - i.astype(F32)) * (_ERF[i + 1] - lo)
    return np.where(x < 0, -y, y).astype(F32)


def pixel_fraction(centre, pos, scale) -> np.ndarray:
    """Eq. 4 along one axis: ½[erf((c + ½ − pos)·scale) − erf((c − ½ − pos)·scale)], scale = 1/(√2Σ)."""
    centre, pos = np.asarray(centre, F32), np.asarray(pos, F32)
    return F32(0.5) * (erf((centre + F32(0.5) - pos) * scale) - erf((centre - F32(0.5) - pos) * scale))


class PhdKernels:
    """The pool of ``kernels.phd.PhdKernels`` as arrays, with the same steps."""

    def __init__(self, capacity: int, max_groups: int, shape, serial: bool = False):
        rows, columns = frame_class(shape)
        self.capacity, self.max_groups, self.pixels = int(capacity), int(max_groups), rows * columns
        c, g = self.capacity, self.max_groups
        self.state, self.state2 = np.zeros((c, DIM), F32), np.zeros((c, DIM), F32)
        self.model, self.model2, self.group, self.group2 = (np.zeros(c, np.int32) for _ in range(4))
        self.weight, self.weight2, self.loglik, self.wtilde, self.cdf, self.cellmass = (np.zeros(c, F32) for _ in range(6))
        self.cell = np.zeros(c, np.int32)
        self.gint, self.gflt = np.zeros((g, len(GROUP_INT)), np.int32), np.zeros((g, len(GROUP_FLOAT)), F32)
        self.gout, self.est = np.zeros((g, 3), F32), np.zeros((g, EST_WIDTH), F32)
        self.raw, self.masked = np.zeros(self.pixels, F32), np.zeros(self.pixels, F32)  # cell y·W + x
        self.cells = np.zeros(self.pixels, np.int32)
        self.F, self.F_inv, self.L = (np.zeros((MAX_MODELS, DIM, DIM), F32) for _ in range(3))
        self.model_cdf = np.zeros((MAX_MODELS + 1, MAX_MODELS), F32)
        self.birth = np.zeros(BIRTH_WIDTH, F32)
        self.frame_hw = np.array([int(shape[0]), int(shape[1])], np.int32)

    @property
    def shape(self) -> tuple[int, int]:
        """The frame's (H, W), px (``frame_hw``; the frames fill the leading H·W entries of ``raw`` and ``masked``)."""
        return int(self.frame_hw[0]), int(self.frame_hw[1])

    def put(self, name: str, values) -> None:
        """Array ``name`` ← ``values`` of its shape; a per-pixel array (PIXEL_FIELDS) takes a frame (H, W) or
        table, row after row, into its leading entries (zeros past them)."""
        target = getattr(self, name)
        values = np.asarray(values, target.dtype)
        target[...] = in_corner(values.ravel(), target.shape) if name in PIXEL_FIELDS else values.reshape(target.shape)

    def slots(self, start: int, count: int) -> dict:
        """Copies of slots [start, start + count): state, model, w̃ and cell mass."""
        sl = slice(start, start + count)
        return {"state": self.state[sl].copy(), "model": self.model[sl].copy(), "wtilde": self.wtilde[sl].copy(),
                "cellmass": self.cellmass[sl].copy()}

    def get(self, name: str) -> np.ndarray:
        """A copy of array ``name``."""
        return getattr(self, name).copy()

    def _draw(self, rows: np.ndarray, u: np.ndarray) -> np.ndarray:
        """The first model j with model_cdf[row, j] > u, per particle."""
        return np.minimum((u[:, None] >= self.model_cdf[rows]).sum(axis=1), MAX_MODELS - 1).astype(np.int32)

    def propagate(self, seed: int, frame_key: int, total: int, backward: int, n_cells: int, first_birth: int,
                  n_births: int) -> None:
        """Survivors switch and move from the second buffer into the first (Eqs. 1, 26, 31–34), births drawn
        (Eqs. 28–30); see the kernel."""
        survive, vmax, i_min, i_max, w_birth, i_floor = self.birth
        p = np.arange(total)
        born = (p >= first_birth) & (p < first_birth + n_births)
        b, s = p[born], p[~born]
        self.group[b] = 0
        if b.size:
            u = {st: uniform(seed, frame_key, st, b) for st in (S_CELL, S_X, S_Y, S_VX, S_VY, S_I, S_MODEL)}
            c = self.cells[np.minimum((u[S_CELL] * F32(n_cells)).astype(np.int32), n_cells - 1)]
            w = self.shape[1]
            st = np.zeros((b.size, DIM), F32)
            st[:, 0] = (c % w).astype(F32) - F32(0.5) + u[S_X]
            st[:, 2] = (c // w).astype(F32) - F32(0.5) + u[S_Y]
            st[:, 1] = vmax * (F32(2.0) * u[S_VX] - F32(1.0))
            st[:, 3] = vmax * (F32(2.0) * u[S_VY] - F32(1.0))
            st[:, 4] = i_min + (i_max - i_min) * u[S_I]
            self.state[b] = st
            self.model[b] = self._draw(np.full(b.size, BETA_ROW), u[S_MODEL])
            self.weight[b] = w_birth
        if s.size:
            r = self._draw(self.model2[s], uniform(seed, frame_key, S_SWITCH, s))
            self.model[s], self.group[s] = r, self.group2[s]
            n = np.stack([normal(seed, frame_key, S_NOISE + d, s) for d in range(DIM)], axis=1)
            F = (self.F_inv if backward else self.F)[r]
            scale = np.sqrt(self.gflt[self.group[s], QSCALE])[:, None]
            moved = np.einsum("pij,pj->pi", F, self.state2[s]) + scale * np.einsum("pij,pj->pi", self.L[r], n)
            moved[:, 4] = np.maximum(moved[:, 4], i_floor)
            self.state[s] = moved.astype(F32)
            self.weight[s] = self.weight2[s] * survive

    def likelihood(self, first: int, count: int, half: int, psf_sigma: float, masked: int) -> None:
        """Eq. 17's cell and Eq. 13's log ℓ over Eq. 18's window of Eq. 4's pixel integrals on the masked
        (``masked`` = 1) or the raw frame; see the kernel."""
        h, w = self.shape
        sl = slice(first, first + count)
        x, y, inten = self.state[sl, 0], self.state[sl, 2], self.state[sl, 4]
        col = np.floor(x + F32(0.5)).astype(np.int32)
        row = np.floor(y + F32(0.5)).astype(np.int32)
        inside = (col >= 0) & (col < w) & (row >= 0) & (row < h)
        k = np.arange(-half, half + 1, dtype=np.int32)
        cols, rows = col[:, None] + k, row[:, None] + k
        scale = F32(SQRT_HALF) / F32(psf_sigma)
        fx = pixel_fraction(cols.astype(F32), x[:, None], scale) * ((cols >= 0) & (cols < w))
        fy = pixel_fraction(rows.astype(F32), y[:, None], scale) * ((rows >= 0) & (rows < h))
        frame = (self.masked if masked == 1 else self.raw)[:h * w].reshape(h, w)
        z = frame[np.clip(rows, 0, h - 1)[:, :, None], np.clip(cols, 0, w - 1)[:, None, :]]
        hv = inten[:, None, None] * fy[:, :, None] * fx[:, None, :]
        acc = (hv * (z - F32(0.5) * hv)).sum(axis=(1, 2), dtype=F32)
        self.cell[sl] = np.where(inside, row * w + col, -1)
        self.loglik[sl] = np.where(inside, acc, F32(LOG_ZERO))

    def update(self, first_group: int, n_groups: int, lam: float, on_likelihood: int, th: float,
               miss: float, radius: float) -> None:
        """Eqs. 14–16, 19, 24 per group over the measurement cells z ≥ th, and with ``radius`` > 0 the class
        estimates (:meth:`_estimate_groups`); see the kernel."""
        h, w = self.shape
        frames = (self.raw[:h * w], self.masked[:h * w])
        for g in range(first_group, first_group + n_groups):
            a, b = self.gint[g, START], self.gint[g, START] + self.gint[g, LENGTH]
            ll, cell, wgt = self.loglik[a:b], self.cell[a:b], self.weight[a:b]
            inside = cell >= 0
            measured = inside & (frames[self.gint[g, FRAME]][np.where(inside, cell, 0)] >= F32(th))
            m = min(F32(ll.max()), F32(np.log(F32(lam)) + F32(SHIFT_MAX))) if b > a else F32(LOG_ZERO)
            lk = np.where(inside, np.exp(np.minimum(ll - m, F32(RATIO_CAP))), F32(0)).astype(F32)
            psi = np.bincount(cell[measured], weights=(wgt * lk)[measured], minlength=self.shape[0] * self.shape[1])
            lam_m = F32(lam) * np.exp(F32(min(-float(m), 80.0)), dtype=F32)
            cell_psi = psi[np.where(inside, cell, 0)].astype(F32)
            den = lam_m + cell_psi
            wt = np.where(inside, F32(miss) * wgt, F32(0)).astype(F32)
            np.divide(wgt * lk, den, out=wt, where=measured)  # off the measurements ℓ'/λe^(−s) may overflow
            self.cellmass[a:b] = np.divide(cell_psi, den, out=np.zeros(b - a, F32), where=measured)
            rho = np.where(measured, lk, F32(miss) * lk) if on_likelihood else wt
            self.wtilde[a:b] = wt.astype(F32)
            self.cdf[a:b] = np.cumsum(rho.astype(F32), dtype=F32)
            self.gout[g, N_HAT] = self.wtilde[a:b].sum(dtype=F32)
            self.gout[g, TOTAL] = self.cdf[b - 1] if b > a else 0.0
            self.gout[g, TOP] = self.cellmass[a:b].max(initial=0.0)
        if radius > 0:
            self._estimate_groups(first_group, n_groups, radius)

    def _estimate_groups(self, first_group: int, n_groups: int, radius: float) -> None:
        """Each group's class around the cell of largest PHD mass inside its gate: mass, weighted mean,
        covariance and model shares (Eqs. 19, 20, 35); see the kernel's ``estimate_group``."""
        w = self.shape[1]
        for g in range(first_group, first_group + n_groups):
            a, b = self.gint[g, START], self.gint[g, START] + self.gint[g, LENGTH]
            x, y = self.state[a:b, 0], self.state[a:b, 2]
            gx, gy, gate = self.gflt[g, CX], self.gflt[g, CY], self.gflt[g, RADIUS]
            inside = (self.cell[a:b] >= 0) & ((gx <= NO_CENTRE) | ((np.abs(x - gx) <= gate) & (np.abs(y - gy) <= gate)))
            members, best = np.zeros(b - a, bool), 0.0
            if inside.any():
                best = self.cellmass[a:b][inside].max()
                peak = self.cell[a:b][np.flatnonzero(inside)[np.argmax(self.cellmass[a:b][inside])]]
                members = (np.abs(x - F32(peak % w)) <= F32(radius)) & (np.abs(y - F32(peak // w)) <= F32(radius))
            wt = np.where(members, self.wtilde[a:b], 0).astype(np.float64)
            mass = wt.sum()
            if mass <= 0:
                wt = members.astype(np.float64)
            wt = wt / max(wt.sum(), 1e-300)
            st = self.state[a:b].astype(np.float64)
            mean = wt @ st if b > a else np.zeros(DIM)
            d = (st - mean) * members[:, None]
            cov = (d * wt[:, None]).T @ d
            self.est[g, EST_MEAN:EST_MEAN + DIM] = mean
            self.est[g, EST_COV:EST_COV + DIM * DIM] = cov.ravel()
            self.est[g, EST_PROB:EST_PROB + MAX_MODELS] = np.bincount(self.model[a:b], weights=wt,
                                                                      minlength=MAX_MODELS)[:MAX_MODELS]
            self.est[g, EST_MASS] = mass
            self.est[g, EST_PEAK] = best

    def resample(self, seed: int, frame_key: int, n_groups: int, max_out: int) -> None:
        """Systematic resampling into the second buffer (Eqs. 20, 24); see the kernel."""
        u = uniform(seed, frame_key, S_RESAMPLE, np.arange(n_groups))
        for g in range(n_groups):
            n_out = int(self.gint[g, OUT_LEN])
            if n_out <= 0:
                continue
            a, n = int(self.gint[g, START]), int(self.gint[g, LENGTH])
            j = np.arange(n_out)
            total = self.gout[g, TOTAL]
            if total > 0:
                target = (j.astype(F32) + u[g]) / F32(n_out) * total
                src = a + np.minimum(np.searchsorted(self.cdf[a:a + n], target, side="right"), n - 1)
            else:
                src = a + (j * n) // n_out
            o = slice(int(self.gint[g, OUT_START]), int(self.gint[g, OUT_START]) + n_out)
            self.state2[o], self.model2[o] = self.state[src], self.model[src]
            self.weight2[o], self.group2[o] = self.gflt[g, OUT_WEIGHT], self.gint[g, OUT_ID]

    def mask(self, first_group: int, n_groups: int, half: int, value: float) -> None:
        """masked = raw with ``value`` over the windows around the groups' estimated positions (Eq. 36)."""
        h, w = self.shape
        self.masked[...] = self.raw
        masked = self.masked[:h * w].reshape(h, w)  # a view
        est = self.est[first_group:first_group + n_groups]
        for x, y in zip(est[:, EST_MEAN], est[:, EST_MEAN + 2]):
            r, c = int(np.floor(y + F32(0.5))), int(np.floor(x + F32(0.5)))
            masked[max(r - half, 0):max(min(r + half + 1, h), 0), max(c - half, 0):max(min(c + half + 1, w), 0)] = value

    def load(self, offset: int, state: np.ndarray, model: np.ndarray, weight: float, group: int) -> None:
        """Slots [offset, offset + n) of the second buffer ← ``state`` rows and ``model``, weight ``weight``,
        group ``group``."""
        n = len(state)
        self.state2[offset:offset + n], self.model2[offset:offset + n] = state, model
        self.weight2[offset:offset + n], self.group2[offset:offset + n] = weight, group
