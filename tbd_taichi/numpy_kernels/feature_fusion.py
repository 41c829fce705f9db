"""NumPy twin of ``tbd_taichi.kernels.feature_fusion``: the same fields (as arrays), steps and contracts,
vectorised over pixels and particles."""
from __future__ import annotations

import numpy as np

from ..kernels.feature_fusion import CONFIG, FEATURES, S_X, S_Y, SOBEL
from .rng import normal

F32 = np.float32


def _shifted(image: np.ndarray, dr: int, dc: int) -> np.ndarray:
    """image[r + dr, c + dc] with zeros outside."""
    h, w = image.shape
    out = np.zeros_like(image)
    out[max(0, -dr):h - max(0, dr), max(0, -dc):w - max(0, dc)] = \
        image[max(0, dr):h - max(0, -dr), max(0, dc):w - max(0, -dc)]
    return out


class FeatureFusionKernels:
    """The fields of ``kernels.feature_fusion.FeatureFusionKernels`` as arrays, with the same steps."""

    def __init__(self, n: int, shape, bins: int, gabor_halves):
        self.n, self.shape, self.bins = int(n), (int(shape[0]), int(shape[1])), int(bins)
        self.gx, self.gy = (int(v) for v in gabor_halves)
        h, w = self.shape
        self.binmap = np.zeros((FEATURES, h, w), np.int32)
        self.ranges = np.zeros((FEATURES, 2), F32)
        self.row_taps, self.col_taps = np.zeros(2 * self.gx + 1, F32), np.zeros(2 * self.gy + 1, F32)
        self.state = np.zeros((self.n, 4), F32)
        self.hist = np.zeros((self.n, FEATURES, self.bins), F32)
        self.template = np.zeros((FEATURES, self.bins), F32)
        self.loglik, self.rho = np.zeros(self.n, F32), np.zeros(self.n, F32)
        self.fusion = np.zeros((self.n, FEATURES), F32)
        self.corr = np.zeros((self.n, FEATURES), F32)
        self.logw = np.zeros(self.n)
        self.config = np.zeros(len(CONFIG), F32)

    def put(self, name: str, values) -> None:
        target = getattr(self, name)
        target[...] = np.asarray(values).reshape(target.shape)

    def get(self, name: str) -> np.ndarray:
        return getattr(self, name).copy()

    def _bins(self, raw: np.ndarray) -> np.ndarray:
        lo, hi = self.ranges[:, 0, None, None], self.ranges[:, 1, None, None]
        b = np.floor((raw - lo) / np.maximum(hi - lo, F32(1e-12)) * F32(self.bins)).astype(np.int64)
        return np.clip(b, 0, self.bins - 1).astype(np.int32)

    def feature_maps(self, frame: np.ndarray, raw: np.ndarray, write_raw: int) -> None:
        """Grey, Sobel magnitude and Gabor maps (into ``raw`` with ``write_raw``), their bins into binmap."""
        image = np.asarray(frame, F32)
        rowpass = sum((self.row_taps[k + self.gx] * _shifted(image, 0, k) for k in range(-self.gx, self.gx + 1)),
                      np.zeros_like(image))
        gabor = sum((self.col_taps[k + self.gy] * _shifted(rowpass, k, 0) for k in range(-self.gy, self.gy + 1)),
                    np.zeros_like(image))
        g2 = np.zeros_like(image)
        for kernel in SOBEL:
            acc = np.zeros_like(image)
            for a in range(3):
                for b in range(3):
                    if kernel[a][b]:
                        acc += F32(kernel[a][b]) * _shifted(image, a - 1, b - 1)
            g2 += acc * acc
        values = np.stack([image, np.sqrt(g2), gabor])
        if write_raw:
            raw[...] = values
        self.binmap[...] = self._bins(values)

    def rebin(self, raw: np.ndarray) -> None:
        self.binmap[...] = self._bins(np.asarray(raw, F32))

    def weigh(self, first: int, count: int, half_x: float, half_y: float, sigma_l: float, fusion: int) -> None:
        """Histograms, Eq. 19's c, Eq. 20's v, the fused ρ and the log-likelihood of particles [first, first + count)."""
        sl = slice(first, first + count)
        h, w = self.shape
        hx, hy = F32(half_x), F32(half_y)
        s2 = hx * hx + hy * hy
        ox = np.arange(-int(np.ceil(half_x)) - 1, int(np.ceil(half_x)) + 2)
        oy = np.arange(-int(np.ceil(half_y)) - 1, int(np.ceil(half_y)) + 2)
        x, y = self.state[sl, 0], self.state[sl, 1]
        cols = np.ceil(x - hx).astype(np.int64)[:, None] + (ox - ox[0])[None, :]
        rows = np.ceil(y - hy).astype(np.int64)[:, None] + (oy - oy[0])[None, :]
        inside_c = (cols <= np.floor(x + hx)[:, None]) & (cols >= 0) & (cols < w)
        inside_r = (rows <= np.floor(y + hy)[:, None]) & (rows >= 0) & (rows < h)
        dc = cols.astype(F32) - x[:, None]
        dr = rows.astype(F32) - y[:, None]
        k = F32(1.0) - (dc[:, None, :] ** 2 + dr[:, :, None] ** 2) / s2
        use = inside_r[:, :, None] & inside_c[:, None, :] & (k > 0)
        k = np.where(use, k, F32(0.0))
        rc = np.clip(rows, 0, h - 1)[:, :, None]
        cc = np.clip(cols, 0, w - 1)[:, None, :]
        hist = np.zeros((count, FEATURES, self.bins), F32)
        flat_p = np.repeat(np.arange(count), k.shape[1] * k.shape[2])
        for f in range(FEATURES):
            b = self.binmap[f][rc, cc].reshape(-1)
            np.add.at(hist[:, f, :], (flat_p, b), k.reshape(-1))
        total = k.sum(axis=(1, 2))
        hist /= np.maximum(total, F32(1e-12))[:, None, None]
        self.hist[sl] = hist
        t = self.template[None]
        dt, dcand = t - t.mean(axis=2, keepdims=True), hist - hist.mean(axis=2, keepdims=True)
        sxx, syy = (dt * dt).sum(axis=2), (dcand * dcand).sum(axis=2)
        with np.errstate(invalid="ignore", divide="ignore"):
            c = np.where((sxx > 0) & (syy > 0), (dt * dcand).sum(axis=2) / np.sqrt(sxx * syy), F32(0.0))
        rhos = np.sqrt(t * hist).sum(axis=2)
        if fusion:
            v = (c + 1) / np.maximum((c + 1).sum(axis=1, keepdims=True), F32(1e-12))
        else:
            v = np.tile(np.array([[1.0, 0.0, 0.0]], F32), (count, 1))
        rho = (v * rhos).sum(axis=1)
        if fusion == 2:  # Eq. 21's bin-wise sum, the candidate's v on both sides
            ft, fc = (v[:, :, None] * t).sum(axis=1), (v[:, :, None] * hist).sum(axis=1)
            rho = np.sqrt(ft * fc).sum(axis=1)
        self.fusion[sl], self.corr[sl], self.rho[sl] = v, c, rho
        self.loglik[sl] = -(F32(1.0) - rho) / (F32(2.0) * F32(sigma_l) ** 2)

    def accumulate(self, out: np.ndarray) -> None:
        """Eq. 10's weights, Eq. 6's estimate into the last slot, Eq. 23's N_eff (see the kernel)."""
        m = self.n - 1
        self.logw[:m] += self.loglik[:m].astype(np.float64)
        self.logw[:m] -= self.logw[:m].max()
        w = np.exp(self.logw[:m])
        total = w.sum()
        x, y = (w * self.state[:m, 0]).sum() / total, (w * self.state[:m, 1]).sum() / total
        self.state[m, 0], self.state[m, 1] = x, y
        out[:3] = (x, y, 1.0 / ((w / total) ** 2).sum())

    def configure(self, sigma_q: float, velocity: int, half_x: float, half_y: float, sigma_l: float,
                  fusion: int) -> None:
        """step()'s constants (``CONFIG``), as the kernel's."""
        self.put("config", [sigma_q, velocity, half_x, half_y, sigma_l, fusion])

    def step(self, seed: int, frame: int, out: np.ndarray, serial: bool = False) -> None:
        """The random walk, every particle weighed, Eqs. 10, 6, 23, the estimate weighed (see the kernel; ``serial``
        changes nothing here)."""
        sigma_q, velocity, half_x, half_y, sigma_l, fusion = self.config
        self.random_walk(seed, frame, sigma_q, int(velocity))
        self.weigh(0, self.n - 1, half_x, half_y, sigma_l, int(fusion))
        self.accumulate(out)
        self.weigh(self.n - 1, 1, half_x, half_y, sigma_l, int(fusion))
        out[3] = self.rho[self.n - 1]

    def random_walk(self, seed: int, frame: int, sigma_q: float, velocity: int) -> None:
        """Eq. 1's random walk (or constant velocity), clamped to the frame (see the kernel)."""
        h, w = self.shape
        p = np.arange(self.n)
        dx = F32(sigma_q) * normal(seed, frame, S_X, p)
        dy = F32(sigma_q) * normal(seed, frame, S_Y, p)
        if velocity:
            dx, dy = dx + self.state[:, 2], dy + self.state[:, 3]
        nx = np.clip(self.state[:, 0] + dx, 0, w - 1).astype(F32)
        ny = np.clip(self.state[:, 1] + dy, 0, h - 1).astype(F32)
        if velocity:
            self.state[:, 2], self.state[:, 3] = nx - self.state[:, 0], ny - self.state[:, 1]
        self.state[:, 0], self.state[:, 1] = nx, ny
