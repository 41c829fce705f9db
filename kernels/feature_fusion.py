"""Adaptive feature-fusion particle filter kernels (Huo et al., Electronics 2022, §3): per-pixel feature maps and
one launch for every particle's kernel-weighted histograms, correlations, fusion weights and likelihood.

* :meth:`FeatureFusionKernels.feature_maps`: the bin index of each pixel's grey level (Eq. 12), Sobel edge magnitude
  G = √(G_x² + G_y² + G_45² + G_135²) (Eqs. 14–16, S_135's bottom row read (−2, −1, 0)) and Gabor response
  W = H ∗ I (Eqs. 17–18; H separable: [N(x; σ_x)·cos(ωx)] ⊗ N(y; σ_y)), each quantised to M bins over a range
  fixed at frame 0; zero padding at the borders (a zero margin around the frame in the fields);
* :meth:`FeatureFusionKernels.weigh`: for particle p (a box centre), the three histograms over the window
  |i − x| ≤ H_x, |j − y| ≤ H_y weighted by k(r) = 1 − r², r = ‖x₀ − x_i‖/s, s = √(H_x² + H_y²) (Eqs. 11–13); the
  Pearson correlation c_i of each with the template's (Eq. 19); v_i = (c_i + 1)/Σ(c + 1) (Eq. 20); the
  Bhattacharyya coefficients ρ_i and the fused ρ = Σ v_i ρ_i (the v-weighted concatenation of Eq. 21, whose
  bin-wise sum would mix unrelated bins); log p(Y|X) = −(1 − ρ)/(2σ_L²) (Eq. 22 with d² = 1 − ρ);
* :meth:`FeatureFusionKernels.step`: one launch per frame: Eq. 1's random walk (or constant velocity) with the
  counter-based normals, clamped to the frame; ``weigh`` for every particle; Eqs. 10, 6 and 23 (weights, the
  estimate, N_eff) in one thread; ``weigh`` at the estimate.  Its constants come from :meth:`configure`.

The NumPy twin is ``tbd_taichi.numpy_kernels.feature_fusion``."""
import math

import numpy as np
import taichi as ti

from .loops import FrameSize, light_ir
from .rng import NormalTables, key_prefix, normals_at

FEATURES = 3  # grey, edge, Gabor
S_X, S_Y = 0, 1  # random-walk streams
FUSIONS = ("grey", "adaptive", "bin-sum")  # the fusion modes' codes are their indices (weigh_range)
SERIAL_WORK = 49_999  # particle-pixels: up to this, step() runs its particle loops in one thread (histogram_work)
CONFIG = ("sigma_q", "velocity", "half_x", "half_y", "sigma_l", "fusion")  # step()'s constants, in this order
MAX_HALF = 64  # px: the largest half window (a box of 129 px)
SOBEL = (
    ((1, 2, 1), (0, 0, 0), (-1, -2, -1)),  # S_x
    ((1, 0, -1), (2, 0, -2), (1, 0, -1)),  # S_y
    ((2, 1, 0), (1, 0, -1), (0, -1, -2)),  # S_45
    ((0, 1, 2), (-1, 0, 1), (-2, -1, 0)),  # S_135 (the paper's bottom row (−2, 1, 0) sums to 2: a typo)
)


def gabor_taps(sigma_x: float, sigma_y: float, omega: float) -> tuple[np.ndarray, np.ndarray]:
    """Eq. 17's separable factors over ±⌈3σ⌉: the row taps N(x; σ_x)·cos(ωx) and the column taps N(y; σ_y)."""
    rx, ry = int(np.ceil(3 * sigma_x)), int(np.ceil(3 * sigma_y))
    x, y = np.arange(-rx, rx + 1, dtype=float), np.arange(-ry, ry + 1, dtype=float)
    row = np.exp(-0.5 * (x / sigma_x) ** 2) / (np.sqrt(2 * np.pi) * sigma_x) * np.cos(omega * x)
    col = np.exp(-0.5 * (y / sigma_y) ** 2) / (np.sqrt(2 * np.pi) * sigma_y)
    return row.astype(np.float32), col.astype(np.float32)


def histogram_work(n: int, half_x: float, half_y: float) -> int:
    """The histograms' work of one :meth:`FeatureFusionKernels.step`: n particles × the window's pixels.  Up to
    ``SERIAL_WORK`` the step runs its particle loops in one thread on the CPU backend (``backend.serial_loops``: a
    parallel loop's start, tens of µs there, would cost more than it saves; docs/performance-history.md#feature-fusion-issue-39)."""
    return n * (2 * math.floor(half_x) + 1) * (2 * math.floor(half_y) + 1)


@ti.data_oriented
class FeatureFusionKernels(FrameSize):
    """Fields for ``n`` particles, frames of ``shape``, ``bins`` histogram bins and the Gabor taps' half widths.
    The per-pixel fields take the extents of the frame's size class (``loops.frame_class``) and the kernels read
    the frame's (H, W) from ``frame_hw``, so frames of one class share the compiled kernels."""

    def __init__(self, n: int, shape, bins: int, gabor_halves):
        self.n, self.bins = int(n), int(bins)
        self.gx, self.gy = (int(v) for v in gabor_halves)
        rows, columns = self.frame_size_field(shape)
        self.margin = m = max(self.gx, self.gy, 1)  # zero border: every tap reads without a bounds test
        self.image = ti.field(ti.f32, (rows + 2 * m, columns + 2 * m))  # the frame at [m, m + H) × [m, m + W)
        self.rowpass = ti.field(ti.f32, (rows + 2 * m, columns))  # the row pass, the frame at rows [m, m + H)
        self.binmap = ti.field(ti.i32, (FEATURES, rows, columns))
        self.ranges = ti.field(ti.f32, (FEATURES, 2))  # lo, hi of each feature's bins
        self.row_taps, self.col_taps = ti.field(ti.f32, 2 * self.gx + 1), ti.field(ti.f32, 2 * self.gy + 1)
        self.state = ti.field(ti.f32, (self.n, 4))  # x, y, ẋ, ẏ (px, px/frame)
        self.hist = ti.field(ti.f32, (self.n, FEATURES, self.bins))
        self.template = ti.field(ti.f32, (FEATURES, self.bins))
        self.loglik, self.rho = ti.field(ti.f32, self.n), ti.field(ti.f32, self.n)
        self.fusion = ti.field(ti.f32, (self.n, FEATURES))  # v_i (Eq. 20)
        self.corr = ti.field(ti.f32, (self.n, FEATURES))  # c_i (Eq. 19)
        self.logw = ti.field(ti.f64, self.n)  # accumulated log-weights (slot n − 1, the estimate, unused)
        self.config = ti.field(ti.f32, len(CONFIG))
        self.tables = NormalTables.shared()

    # ------------------------------------------------------------------ Eqs. 12, 14–18: per-pixel maps

    @ti.kernel
    def feature_maps(self, frame: ti.types.ndarray(dtype=ti.f32, ndim=2), raw: ti.types.ndarray(dtype=ti.f32, ndim=3),
                     write_raw: ti.i32):
        """binmap[f] = each pixel's bin of grey (the frame), edge magnitude G and Gabor response W; with
        ``write_raw``, ``raw`` (3, H, W) gets the unquantised values (frame 0 sets the ranges from them).  The
        zero border is written too: the fields may hold a larger frame of the class (``backend.reusable``)."""
        h, w, m = self.frame_hw[0], self.frame_hw[1], ti.static(self.margin)
        columns = ti.static(self.frame_extents[1])  # rows to the frame's, columns to the class's: a static row
        for r, c in ti.ndrange(h + 2 * m, columns + 2 * m):  # length (no division by W per pixel)
            if c < w + 2 * m:
                v = ti.f32(0.0)
                if m <= r < h + m and m <= c < w + m:  # a statement: the frame is read only inside
                    v = frame[r - m, c - m]
                self.image[r, c] = v
        for r, c in ti.ndrange(h + 2 * m, columns):  # the border rows too: zeros (the image's border is)
            if c < w:
                acc = ti.f32(0.0)
                for k in ti.static(range(-self.gx, self.gx + 1)):
                    acc += self.row_taps[k + self.gx] * self.image[r, c + m + k]
                self.rowpass[r, c] = acc
        for r, c in ti.ndrange(h, columns):
            if c < w:
                self.pixel_features(r, c, raw, write_raw)

    @ti.func
    def pixel_features(self, r: ti.i32, c: ti.i32, raw: ti.template(), write_raw: ti.i32):
        """:meth:`feature_maps`' values of pixel (r, c) and their bins."""
        m = ti.static(self.margin)
        gabor = ti.f32(0.0)
        for k in ti.static(range(-self.gy, self.gy + 1)):
            gabor += self.col_taps[k + self.gy] * self.rowpass[r + m + k, c]
        g2 = ti.f32(0.0)
        for s in ti.static(range(4)):
            acc = ti.f32(0.0)
            for a in ti.static(range(3)):
                for b in ti.static(range(3)):
                    if ti.static(SOBEL[s][a][b] != 0):
                        acc += ti.static(float(SOBEL[s][a][b])) * self.image[r + m + a - 1, c + m + b - 1]
            g2 += acc * acc
        values = ti.Vector([self.image[r + m, c + m], ti.sqrt(g2), gabor], dt=ti.f32)
        for f in ti.static(range(FEATURES)):
            if write_raw != 0:
                raw[f, r, c] = values[f]
            self.binmap[f, r, c] = self.bin_of(f, values[f])

    @ti.func
    def bin_of(self, f: ti.i32, v: ti.f32) -> ti.i32:
        """The bin of value v of feature f: M equal bins over [lo, hi], values outside in the end bins."""
        lo, hi = self.ranges[f, 0], self.ranges[f, 1]
        b = ti.cast(ti.floor((v - lo) / ti.max(hi - lo, 1e-12) * self.bins), ti.i32)
        return ti.min(ti.max(b, 0), self.bins - 1)

    @ti.kernel
    def rebin(self, raw: ti.types.ndarray(dtype=ti.f32, ndim=3)):
        """binmap from the unquantised maps and the current ranges (frame 0, once the ranges are set)."""
        h, w, columns = self.frame_hw[0], self.frame_hw[1], ti.static(self.frame_extents[1])
        for r, c in ti.ndrange(h, columns):  # as in feature_maps
            if c < w:
                for f in ti.static(range(FEATURES)):
                    self.binmap[f, r, c] = self.bin_of(f, raw[f, r, c])

    # ------------------------------------------------------------------ Eqs. 11–13, 19–22: one launch, all particles

    @ti.kernel
    def weigh(self, first: ti.i32, count: ti.i32, half_x: ti.f32, half_y: ti.f32, sigma_l: ti.f32, fusion: ti.i32):
        """:meth:`weigh_range` with these constants (frame 0's template, tests)."""
        self.weigh_range(first, count, half_x, half_y, sigma_l, fusion)

    @ti.func
    def weigh_range(self, first: ti.i32, count: ti.i32, half_x: ti.f32, half_y: ti.f32, sigma_l: ti.f32,
                    fusion: ti.i32):
        """Particles [first, first + count): histograms (Eqs. 11–13), c_i (Eq. 19), v_i (Eq. 20) and ρ by
        ``fusion`` (an index of ``FUSIONS``): 0, the grey histogram alone (v = (1, 0, 0)); 1, ρ = Σ v_i ρ_i, the
        v-weighted concatenation (Eqs. 21–22); 2, Eq. 21 as printed, the bin-wise sums F = Σ v_i f_i of the
        template and the candidate (the candidate's v on both sides) and ρ = Σ_b √(F_t F_c); then
        loglik = −(1 − ρ)/(2σ_L²)."""
        h, w = self.frame_hw[0], self.frame_hw[1]
        for p in range(first, first + count):
            x, y = self.state[p, 0], self.state[p, 1]
            for f, b in ti.ndrange(FEATURES, self.bins):
                self.hist[p, f, b] = 0.0
            s2 = half_x * half_x + half_y * half_y
            c0 = ti.cast(ti.ceil(x - half_x), ti.i32)
            c1 = ti.cast(ti.floor(x + half_x), ti.i32)
            r0 = ti.cast(ti.ceil(y - half_y), ti.i32)
            r1 = ti.cast(ti.floor(y + half_y), ti.i32)
            total = ti.f32(0.0)
            for r in range(ti.max(r0, 0), ti.min(r1, h - 1) + 1):
                for c in range(ti.max(c0, 0), ti.min(c1, w - 1) + 1):
                    k = 1.0 - ((c - x) * (c - x) + (r - y) * (r - y)) / s2  # Eq. 11
                    if k > 0:
                        total += k
                        for f in ti.static(range(FEATURES)):
                            self.hist[p, f, self.binmap[f, r, c]] += k
            norm = 1.0 / ti.max(total, 1e-12)  # α, Eq. 13
            cs = ti.Vector([0.0] * FEATURES, dt=ti.f32)
            rhos = ti.Vector([0.0] * FEATURES, dt=ti.f32)
            for f in ti.static(range(FEATURES)):
                for b in range(self.bins):
                    self.hist[p, f, b] *= norm
                cs[f] = self.pearson(p, f)
                rhos[f] = self.bhattacharyya(p, f)
            v = ti.Vector([1.0, 0.0, 0.0], dt=ti.f32)
            if fusion != 0:
                v = (cs + 1.0) / ti.max((cs + 1.0).sum(), 1e-12)  # Eq. 20 (the 0.5 cancels)
            rho = v.dot(rhos)
            if fusion == 2:  # Eq. 21's bin-wise sum
                rho = 0.0
                for b in range(self.bins):
                    ft, fc = ti.f32(0.0), ti.f32(0.0)
                    for f in ti.static(range(FEATURES)):
                        ft += v[f] * self.template[f, b]
                        fc += v[f] * self.hist[p, f, b]
                    rho += ti.sqrt(ft * fc)
            for f in ti.static(range(FEATURES)):
                self.fusion[p, f] = v[f]
                self.corr[p, f] = cs[f]
            self.rho[p] = rho
            self.loglik[p] = -(1.0 - rho) / (2.0 * sigma_l * sigma_l)

    @ti.func
    def pearson(self, p: ti.i32, f: ti.i32) -> ti.f32:
        """Eq. 19: the correlation of particle p's histogram f with the template's (0 when either is flat)."""
        mt, mc = ti.f32(0.0), ti.f32(0.0)
        for b in range(self.bins):
            mt += self.template[f, b]
            mc += self.hist[p, f, b]
        mt /= self.bins
        mc /= self.bins
        sxy, sxx, syy = ti.f32(0.0), ti.f32(0.0), ti.f32(0.0)
        for b in range(self.bins):
            dt, dc = self.template[f, b] - mt, self.hist[p, f, b] - mc
            sxy += dt * dc
            sxx += dt * dt
            syy += dc * dc
        out = ti.f32(0.0)
        if sxx > 0 and syy > 0:
            out = sxy / ti.sqrt(sxx * syy)
        return out

    @ti.func
    def bhattacharyya(self, p: ti.i32, f: ti.i32) -> ti.f32:
        """ρ_f = Σ √(template·candidate) over the bins (Eq. 22)."""
        acc = ti.f32(0.0)
        for b in range(self.bins):
            acc += ti.sqrt(self.template[f, b] * self.hist[p, f, b])
        return acc

    # ------------------------------------------------------------------ Eqs. 6, 10, 23

    @light_ir
    @ti.kernel
    def step(self, seed: ti.u32, frame: ti.i32, out: ti.types.ndarray(dtype=ti.f64, ndim=1), serial: ti.template()):
        """One frame in one launch (:meth:`frame_step`); ``serial``: all of it in the launching thread
        (:func:`histogram_work`: for a few hundred particles a parallel loop's start costs more than its work)."""
        if ti.static(serial):
            ti.loop_config(serialize=True)
            for _ in range(1):
                self.frame_step(seed, frame, out)
        else:
            self.frame_step(seed, frame, out)

    @ti.func
    def frame_step(self, seed: ti.u32, frame: ti.i32, out: ti.template()):
        """:meth:`random_walk`, :meth:`weigh_range` for particles [0, n − 1), :meth:`accumulate` (the estimate to
        slot n − 1) and :meth:`weigh_range` at the estimate, with :meth:`configure`'s constants; out = (x̂, ŷ,
        N_eff, ρ at x̂)."""
        sigma_q, velocity = self.config[0], ti.cast(self.config[1], ti.i32)
        half_x, half_y, sigma_l = self.config[2], self.config[3], self.config[4]
        fusion = ti.cast(self.config[5], ti.i32)
        self.random_walk(seed, frame, sigma_q, velocity)
        self.weigh_range(0, self.n - 1, half_x, half_y, sigma_l, fusion)
        self.accumulate(out)
        self.weigh_range(self.n - 1, 1, half_x, half_y, sigma_l, fusion)
        out[3] = ti.cast(self.rho[self.n - 1], ti.f64)

    def configure(self, sigma_q: float, velocity: int, half_x: float, half_y: float, sigma_l: float,
                  fusion: int) -> None:
        """:meth:`step`'s constants (``CONFIG``): σ_q (px), constant velocity (0/1), the half window H_x, H_y
        (px), σ_L and the fusion mode (an index of ``FUSIONS``)."""
        self.put("config", [sigma_q, velocity, half_x, half_y, sigma_l, fusion])

    @ti.func
    def accumulate(self, out: ti.template()):
        """In one thread, particles [0, n − 1): logw += loglik (Eq. 10 with the transition as the proposal), the
        normalised weights, the estimate Σ w·x (Eq. 6) into slot n − 1 and N_eff = 1/Σ w² (Eq. 23);
        out[:3] = (x̂, ŷ, N_eff)."""
        for _ in range(1):
            m = ti.f64(-1.0e300)
            for p in range(self.n - 1):
                self.logw[p] += ti.cast(self.loglik[p], ti.f64)
                m = ti.max(m, self.logw[p])
            total, sx, sy = ti.f64(0.0), ti.f64(0.0), ti.f64(0.0)
            for p in range(self.n - 1):
                self.logw[p] -= m
                wp = ti.exp(self.logw[p])
                total += wp
                sx += wp * self.state[p, 0]
                sy += wp * self.state[p, 1]
            sq = ti.f64(0.0)
            for p in range(self.n - 1):
                wp = ti.exp(self.logw[p]) / total
                sq += wp * wp
            self.state[self.n - 1, 0] = ti.cast(sx / total, ti.f32)
            self.state[self.n - 1, 1] = ti.cast(sy / total, ti.f32)
            out[0], out[1], out[2] = sx / total, sy / total, 1.0 / sq

    # ------------------------------------------------------------------ Eq. 1

    @ti.func
    def random_walk(self, seed: ti.u32, frame: ti.i32, sigma_q: ti.f32, velocity: ti.i32):
        """x ← x + ẋ·velocity + σ_q·n per axis (Eq. 1: a random walk, or constant velocity), kept in the frame;
        with ``velocity`` the displacement becomes the particle's velocity."""
        h, w = self.frame_hw[0], self.frame_hw[1]
        kx, ky = key_prefix(seed, frame, S_X), key_prefix(seed, frame, S_Y)
        for p in range(self.n):
            nx, ny = normals_at(self.tables.w, self.tables.k, self.tables.phi, [kx, ky], p)
            dx, dy = sigma_q * nx, sigma_q * ny
            if velocity != 0:
                dx += self.state[p, 2]
                dy += self.state[p, 3]
            nx = ti.min(ti.max(self.state[p, 0] + dx, 0.0), ti.cast(w - 1, ti.f32))
            ny = ti.min(ti.max(self.state[p, 1] + dy, 0.0), ti.cast(h - 1, ti.f32))
            if velocity != 0:
                self.state[p, 2] = nx - self.state[p, 0]
                self.state[p, 3] = ny - self.state[p, 1]
            self.state[p, 0] = nx
            self.state[p, 1] = ny

    # ------------------------------------------------------------------ host transfers

    def put(self, name: str, values) -> None:
        """Field ``name`` ← ``values`` (its whole shape)."""
        field = getattr(self, name)
        dtype = {ti.f32: np.float32, ti.i32: np.int32, ti.f64: np.float64}[field.dtype]
        field.from_numpy(np.ascontiguousarray(values, dtype=dtype).reshape(field.shape))

    def get(self, name: str) -> np.ndarray:
        """A copy of field ``name``."""
        return getattr(self, name).to_numpy()
