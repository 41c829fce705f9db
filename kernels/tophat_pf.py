"""Top-hat + particle filter kernels (Güler 2016, §3.4): the online background of Algs. 8–9 and one launch that
steps every candidate's SIR filter.

The pool holds G groups (the candidates) of N particles; slot p belongs to group p // N.  A group lives until
Alg. 5 drops it (``alive``); a dead group's slots are skipped.  Positions are px (x = column, y = row, 0-based).

* :meth:`TophatPFKernels.background`: Total ← Total + I_k, B̂_k = Total / (k + 1), S_k = I_k − B̂_k (Algs. 8–9 with
  0-based frames: Total holds frames 0..k) and σ_k = std(S_k) over the frame (Eq. 3.14's σ_k);
* :meth:`TophatPFKernels.start`: each group's reference z and N particles at its candidate + σ₀·n;
* :meth:`TophatPFKernels.step`: per particle x_k = x_{k−1} + B + C·n, n ~ N(0, I₂) (Eq. 3.2 with A = I₂) and
  log w = (z·S_k(x) − z²/2)/σ_k² (Eq. 3.14 over the noise density at the particle's pixel: the other pixels
  cancel) − ‖B − (pixel(x_k) − x̂_{k−1})‖²/(2σ_v²) (Eq. 3.16 with Δv = B and v at the particle's pixel centre, while
  ``motion``); off-image particles weigh 0;
  per group the maximum, the cumulative weights c_i = Σ_{l≤i} w_l in f64 (Alg. 2 without the c₁ = 0 typo), N̂_eff
  (Eq. 2.15), systematic resampling (Alg. 2: u_j = (u₁ + j)/N), the estimate = mean of the resampled particles,
  S_k and S_k/σ_k at its pixel, and the drift B = (x̂_k − x̂_{k−m})/m with m = min(S, k − k₀) (Alg. 6: the mean
  of the last m displacements, a sliding window), while ``drift``.

Sums within a group run serially in one thread (groups in parallel), so the results do not depend on the thread
count; random numbers are ``kernels.rng``'s, keyed on (seed, frame, stream, slot).  The NumPy twin is
``tbd_taichi.numpy_kernels.tophat_pf``."""
import taichi as ti
from taichi.lang import impl

from .loops import FrameSize, thread_span
from .rng import NormalTables, key_prefix, normals_at, uniform_f64_at

S_X, S_Y, S_START_X, S_START_Y, S_RESAMPLE = 0, 1, 2, 3, 4  # random streams
SUMMARY = ("x", "y", "s", "snr", "bx", "by", "neff", "loglik")  # per-group columns of ``summary``
SUM_X, SUM_Y, SUM_S, SUM_SNR, SUM_BX, SUM_BY, SUM_NEFF, SUM_LOGLIK = range(len(SUMMARY))
CONFIG = ("c", "sigma_v", "s_drift", "sigma_0")  # ``configure``'s values
NEG_INF = -3.0e38
BY_GROUP_MIN = 4  # live groups from which a CPU step runs each group's whole step in one thread


def step_layout(live: int) -> str:
    """The step kernel for ``live`` groups: ``step_by_group`` (each group's whole step in one thread) on a CPU from
    max(BY_GROUP_MIN, threads) groups, so that every thread has a group; else ``step_by_particle``.  On a GPU
    (thread_span 1) one thread per group would serialise each group's particles, so a GPU always steps by
    particle."""
    if thread_span(False) > 1 and live >= max(BY_GROUP_MIN, impl.current_cfg().cpu_max_num_threads):
        return "step_by_group"
    return "step_by_particle"


@ti.data_oriented
class TophatPFKernels(FrameSize):
    """Fields for ``groups`` filters of ``n`` particles on frames of ``shape``, the drift's ring of ``ring``
    estimates (S + 1) and a frame sum of ``sum_dtype``."""

    def __init__(self, groups: int, n: int, shape, ring: int):
        self.groups, self.n, self.ring = int(groups), int(n), int(ring)
        rows, columns = self.frame_size_field(shape)  # the size class: the kernels read (H, W) from frame_hw
        slots = self.groups * self.n
        self.total = ti.field(ti.f64, rows * columns)  # Σ I (Algs. 8–9), pixel y·W + x
        self.s = ti.field(ti.f32, rows * columns)  # S_k = I_k − B̂_k (counts), pixel y·W + x
        self.row_sums = ti.field(ti.f64, (rows, 2))  # Σ S, Σ S² per row
        self.stats = ti.field(ti.f64, 2)  # σ_k, mean of S_k
        self.x, self.y = ti.field(ti.f32, slots), ti.field(ti.f32, slots)  # resampled particles
        self.xp, self.yp = ti.field(ti.f32, slots), ti.field(ti.f32, slots)  # propagated particles
        self.logw = ti.field(ti.f32, slots)
        self.cum = ti.field(ti.f64, slots)
        self.below = ti.field(ti.i32, slots)  # resampling: the points below each particle's c_i
        self.first_copy = ti.field(ti.i32, self.groups * (self.n + 1))  # resample_group's marks, −1 between steps
        self.first_copy.fill(-1)
        self.alive = ti.field(ti.i32, self.groups)
        self.live = ti.field(ti.i32, self.groups)  # the live groups, in order; n_live of them
        self.n_live = ti.field(ti.i32, ())
        self.ref = ti.field(ti.f32, self.groups)  # z (counts)
        self.gmax, self.gtotal, self.u1 = (ti.field(ti.f64, self.groups) for _ in range(3))
        self.ring_xy = ti.field(ti.f32, (self.groups, self.ring, 2))  # the last ``ring`` estimates
        self.drift = ti.field(ti.f32, (self.groups, 2))  # B (px/frame)
        self.summary = ti.field(ti.f32, (self.groups, len(SUMMARY)))
        self.config = ti.field(ti.f32, len(CONFIG))
        self.seed = ti.field(ti.u32, ())
        self.tables = NormalTables.shared()
        self.live_count = 0  # live groups, as the host last set them

    @ti.kernel
    def configure(self, seed: ti.u32, values: ti.types.ndarray(dtype=ti.f32, ndim=1)):
        """The seed and CONFIG's values (C, σ_v, S, σ₀); Total ← 0."""
        self.seed[None] = seed
        for i in ti.static(range(len(CONFIG))):
            self.config[i] = values[i]
        for i in self.total:
            self.total[i] = 0.0

    # ------------------------------------------------------------------ Algs. 8–9: the background

    @ti.kernel
    def background(self, frame: ti.types.ndarray(dtype=ti.f32, ndim=2), count: ti.i32):
        """Total ← Total + I; S = I − Total/count (``count`` = frames in Total); stats = (σ, mean) of S."""
        h, w = self.frame_hw[0], self.frame_hw[1]
        per_pixel = ti.static(thread_span(False) == 1)  # a GPU: a thread per pixel for S, then one per row for sums
        if ti.static(per_pixel):
            for r, c in ti.ndrange(h, w):
                self.background_pixel(frame, r, c, w, count)
        for r in range(h):  # on the CPU a row per iteration, S and its sums in one pass (no division by W)
            a, b = ti.cast(0.0, ti.f64), ti.cast(0.0, ti.f64)
            for c in range(w):
                if ti.static(not per_pixel):
                    self.background_pixel(frame, r, c, w, count)
                v = ti.cast(self.s[r * w + c], ti.f64)
                a += v
                b += v * v
            self.row_sums[r, 0] = a
            self.row_sums[r, 1] = b
        ti.loop_config(serialize=True)
        for _ in range(1):
            a, b = ti.cast(0.0, ti.f64), ti.cast(0.0, ti.f64)
            for r in range(h):
                a += self.row_sums[r, 0]
                b += self.row_sums[r, 1]
            mean = a / (h * w)
            self.stats[0] = ti.sqrt(ti.max(b / (h * w) - mean * mean, 0.0))
            self.stats[1] = mean

    @ti.func
    def background_pixel(self, frame: ti.template(), r: ti.i32, c: ti.i32, w: ti.i32, count: ti.i32):
        """Pixel (r, c) of :meth:`background`: Total += I, S = I − Total/count."""
        t = self.total[r * w + c] + ti.cast(frame[r, c], ti.f64)
        self.total[r * w + c] = t
        self.s[r * w + c] = ti.cast(ti.cast(frame[r, c], ti.f64) - t / ti.cast(count, ti.f64), ti.f32)

    # ------------------------------------------------------------------ the particles

    def start(self, init, count: int) -> None:
        """:meth:`start_filters`; the host keeps the live count (:meth:`step` chooses its loops by it)."""
        if not 0 <= int(count) <= self.groups:
            raise ValueError(f"start: count {count} outside 0..{self.groups} groups")
        self.live_count = int(count)
        self.start_filters(init, count)

    def set_alive(self, alive) -> None:
        """:meth:`update_alive`; the host keeps the live count."""
        self.live_count = int((alive == 1).sum())
        self.update_alive(alive)

    @ti.kernel
    def start_filters(self, init: ti.types.ndarray(dtype=ti.f32, ndim=2), count: ti.i32):
        """Groups g < ``count`` alive with init[g] = (x, y, z): z the reference, N particles at (x, y) + σ₀·n
        (streams S_START_X, S_START_Y, frame 0); the ring, the drift and the summary start at (x, y)."""
        n, groups = ti.static(self.n, self.groups)
        w, k, phi = ti.static(self.tables.w, self.tables.k, self.tables.phi)
        kx, ky = key_prefix(self.seed[None], 0, S_START_X), key_prefix(self.seed[None], 0, S_START_Y)
        sigma_0 = self.config[3]
        for g in range(groups):
            self.alive[g] = ti.cast(g < count, ti.i32)
            if g < count:
                self.ref[g] = init[g, 2]
                self.drift[g, 0] = 0.0
                self.drift[g, 1] = 0.0
                for j in ti.static(range(len(SUMMARY))):
                    self.summary[g, j] = 0.0
                self.summary[g, SUM_X] = init[g, 0]
                self.summary[g, SUM_Y] = init[g, 1]
                for m in range(self.ring):
                    self.ring_xy[g, m, 0] = init[g, 0]
                    self.ring_xy[g, m, 1] = init[g, 1]
        self.list_live()
        for p in range(count * n):
            g = p // n
            nx, ny = normals_at(w, k, phi, [kx, ky], p)
            self.x[p] = init[g, 0] + sigma_0 * nx
            self.y[p] = init[g, 1] + sigma_0 * ny

    @ti.kernel
    def update_alive(self, alive: ti.types.ndarray(dtype=ti.i32, ndim=1)):
        """alive ← ``alive`` (Alg. 5's survivors)."""
        for g in range(self.groups):
            self.alive[g] = alive[g]
        self.list_live()

    @ti.func
    def list_live(self):
        """live[0..n_live) ← the alive groups in order (one serial pass: the slot loops then run over live groups'
        slots only)."""
        ti.loop_config(serialize=True)
        for _ in range(1):
            m = 0
            for g in range(self.groups):
                if self.alive[g] == 1:
                    self.live[m] = g
                    m += 1
            self.n_live[None] = m

    def step(self, frame: int, since: int, drift: int, motion: int) -> None:
        """One SIR step of every live group on the current S_k (see the module's docstring); ``since``: frames
        since the filters started (the drift averages over min(S, since) displacements).  One launch, chosen by
        :func:`step_layout`: each group's whole step in one thread (its particles stay in the core's cache from the
        propagation to the estimate), or the propagation spread over the particles.  Both give the same numbers.
        A tracker picks the kernel by :func:`step_layout` itself (through the launcher's fast path)."""
        getattr(self, step_layout(self.live_count))(frame, since, drift, motion)

    @ti.kernel
    def step_by_particle(self, frame: ti.i32, since: ti.i32, drift: ti.i32, motion: ti.i32):
        """:meth:`step` in three loops: propagate and weigh every particle, then per group normalise, then per group
        resample and estimate."""
        n = ti.static(self.n)
        keys, k = self.noise_keys(frame), self.weigh_constants()
        for q in range(self.n_live[None] * n):
            g = self.live[q // n]
            self.logw[g * n + q % n] = self.propagate_and_weigh(g, g * n + q % n, keys, k, motion)
        span = ti.static(thread_span(False))
        for t in range(self.n_live[None] * span):
            if t % span == 0:
                g = self.live[t // span]
                m = ti.f32(NEG_INF)
                for i in range(g * n, (g + 1) * n):
                    m = ti.max(m, self.logw[i])
                self.normalise(g, m, frame)
        for t in range(self.n_live[None] * span):
            if t % span == 0:
                self.estimate(self.live[t // span], since, drift)

    @ti.kernel
    def step_by_group(self, frame: ti.i32, since: ti.i32, drift: ti.i32, motion: ti.i32):
        """:meth:`step` in one loop over the live groups, each group's propagation, normalisation and estimate in
        one thread."""
        n = ti.static(self.n)
        span = ti.static(thread_span(False))
        keys, k = self.noise_keys(frame), self.weigh_constants()
        for t in range(self.n_live[None] * span):
            if t % span == 0:
                g = self.live[t // span]
                m = ti.f32(NEG_INF)
                for p in range(g * n, (g + 1) * n):
                    lw = self.propagate_and_weigh(g, p, keys, k, motion)
                    self.logw[p] = lw
                    m = ti.max(m, lw)
                self.normalise(g, m, frame)
                self.estimate(g, since, drift)

    @ti.func
    def weigh_constants(self):
        """(C, 1/σ_k², 1/(2σ_v²)) of this frame's propagation."""
        c, sigma_v = self.config[0], self.config[1]
        sigma = ti.cast(self.stats[0], ti.f32)
        return ti.Vector([c, 1.0 / ti.max(sigma * sigma, 1e-30), 1.0 / (2.0 * sigma_v * sigma_v)], dt=ti.f32)

    @ti.func
    def noise_keys(self, frame: ti.i32):
        """The x and y noise streams' key prefixes of this frame (u32)."""
        return ti.Vector([key_prefix(self.seed[None], frame, S_X), key_prefix(self.seed[None], frame, S_Y)],
                         dt=ti.u32)

    @ti.func
    def propagate_and_weigh(self, g: ti.i32, p: ti.i32, keys, k, motion: ti.i32) -> ti.f32:
        """Particle p of group g: x_k = x_{k−1} + B + C·n (Eq. 3.2) into (xp, yp); returns its log-weight
        (Eqs. 3.14 and 3.16); ``keys``: :meth:`noise_keys`, ``k``: :meth:`weigh_constants`."""
        h, w = self.frame_hw[0], self.frame_hw[1]
        tw, tk, tphi = ti.static(self.tables.w, self.tables.k, self.tables.phi)
        bx, by = self.drift[g, 0], self.drift[g, 1]
        nx, ny = normals_at(tw, tk, tphi, [keys[0], keys[1]], p)
        x = self.x[p] + bx + k[0] * nx
        y = self.y[p] + by + k[0] * ny
        self.xp[p] = x
        self.yp[p] = y
        col = ti.cast(ti.floor(x + 0.5), ti.i32)
        row = ti.cast(ti.floor(y + 0.5), ti.i32)
        lw = ti.f32(NEG_INF)
        if 0 <= col < w and 0 <= row < h:
            z = self.ref[g]
            lw = (z * self.s[row * w + col] - 0.5 * z * z) * k[1]  # Eq. 3.14 over the noise density
            if motion != 0:  # Eq. 3.16, Δv = B, v = pixel(x_k) − x̂_{k−1}
                dx = bx - (ti.cast(col, ti.f32) - self.summary[g, SUM_X])
                dy = by - (ti.cast(row, ti.f32) - self.summary[g, SUM_Y])
                lw -= (dx * dx + dy * dy) * k[2]
        return lw

    @ti.func
    def normalise(self, g: ti.i32, m: ti.f32, frame: ti.i32):
        """Group g with log-weight maximum m: c_i = Σ_{l≤i} exp(lw_l − m) (f32 terms, the sums f64), the total,
        N̂_eff = (Σw)²/Σw² (Eq. 2.15), the mean likelihood log((Σ e^lw)/N) and Alg. 2's u₁ ~ U[0, 1)."""
        n = ti.static(self.n)
        s, s2 = ti.cast(0.0, ti.f64), ti.cast(0.0, ti.f64)
        for i in range(g * n, (g + 1) * n):
            wi = ti.cast(1.0, ti.f64)  # every particle off the image (m = NEG_INF): keep them all alike
            if m > NEG_INF:
                wi = ti.cast(ti.exp(self.logw[i] - m), ti.f64)
            s += wi
            s2 += wi * wi
            self.cum[i] = s
        self.gmax[g] = m
        self.gtotal[g] = s
        self.u1[g] = uniform_f64_at(key_prefix(self.seed[None], frame, S_RESAMPLE), g)
        self.summary[g, SUM_NEFF] = ti.cast(s * s / s2, ti.f32)
        self.summary[g, SUM_LOGLIK] = ti.cast(ti.log(s / n), ti.f32) + ti.max(m, ti.f32(-1e30))

    @ti.func
    def resample_group(self, g: ti.i32) -> ti.types.vector(2, ti.f64):
        """Alg. 2 for group g: output j copies the first particle whose c_i exceeds the point (u₁ + j)·(Σw/N);
        returns the sums of the copies' x and y.  Without a branch per output (a forward walk's exit test is
        mispredicted about once an output, which cost more than the propagation): particle i fills outputs
        [b_{i−1}, b_i), b_i = :meth:`points_below` c_i (b = N for the last), so each particle marks the first
        output it fills (first_copy, −1 elsewhere) and a running maximum over the outputs gives each its particle."""
        n = ti.static(self.n)
        a, last = g * n, (g + 1) * n - 1
        marks, unused = g * (n + 1), g * (n + 1) + n  # group g's marks and a slot for particles with no copy
        spacing, u1 = self.gtotal[g] / n, self.u1[g]
        inv = 1.0 / spacing
        for i in range(a, last):  # a loop of its own: without the marks' stores it runs about twice as fast
            self.below[i] = self.points_below(self.cum[i], u1, spacing, inv)
        self.below[last] = n
        prev = 0
        for i in range(a, last + 1):
            c = self.below[i]
            self.first_copy[ti.select(c > prev, marks + prev, unused)] = i
            prev = c
        sx, sy = ti.cast(0.0, ti.f64), ti.cast(0.0, ti.f64)
        src = a
        for j in range(n):
            src = ti.max(src, self.first_copy[marks + j])
            self.first_copy[marks + j] = -1  # ready for the next frame
            x, y = self.xp[src], self.yp[src]
            self.x[a + j] = x
            self.y[a + j] = y
            sx += x
            sy += y
        return ti.Vector([sx, sy])

    @ti.func
    def points_below(self, c: ti.f64, u1: ti.f64, spacing: ti.f64, inv: ti.f64) -> ti.i32:
        """#{j < N : (u₁ + j)·spacing < c}, the points exactly as the walk computes them: ⌈c/spacing − u₁⌉ (the
        value is > −1: ⌊·⌋ + 1 unless it is a whole number), clipped to N; within 10⁻⁹ of a whole number, where
        rounding decides, the count is corrected by one either way against the points themselves (rare: the
        branch is predicted)."""
        n = ti.static(self.n)
        x = c * inv - u1
        k = ti.min(ti.cast(x + 1.0, ti.i32), n)  # x + 1 > 0: the cast is ⌊x⌋ + 1
        if ti.abs(x - ti.round(x)) < 1e-9 * (1.0 + ti.abs(x)):
            if k > 0 and (u1 + ti.cast(k - 1, ti.f64)) * spacing >= c:
                k -= 1
            if k < n and (u1 + ti.cast(k, ti.f64)) * spacing < c:
                k += 1
        return k

    @ti.func
    def estimate(self, g: ti.i32, since: ti.i32, drift: ti.i32):
        """Group g: systematic resampling (``resample_group``), x̂ = mean of the resampled particles, S_k and
        S_k/σ_k at its pixel, and the drift B = (x̂_k − x̂_{k−m})/m, m = min(S, since) (Alg. 6), while ``drift``."""
        n, ring = ti.static(self.n, self.ring)
        h, w = self.frame_hw[0], self.frame_hw[1]
        sigma = ti.cast(self.stats[0], ti.f32)
        s_drift = ti.cast(self.config[2], ti.i32)
        sums = self.resample_group(g)
        ex, ey = ti.cast(sums[0] / n, ti.f32), ti.cast(sums[1] / n, ti.f32)
        col = ti.min(ti.max(ti.cast(ti.floor(ex + 0.5), ti.i32), 0), w - 1)
        row = ti.min(ti.max(ti.cast(ti.floor(ey + 0.5), ti.i32), 0), h - 1)
        self.summary[g, SUM_X] = ex
        self.summary[g, SUM_Y] = ey
        self.summary[g, SUM_S] = self.s[row * w + col]
        self.summary[g, SUM_SNR] = self.s[row * w + col] / ti.max(sigma, 1e-30)
        slot = since % ring
        self.ring_xy[g, slot, 0] = ex
        self.ring_xy[g, slot, 1] = ey
        if drift != 0:
            m = ti.min(s_drift, since)
            if m > 0:
                old = (since - m) % ring
                self.drift[g, 0] = (ex - self.ring_xy[g, old, 0]) / m
                self.drift[g, 1] = (ey - self.ring_xy[g, old, 1]) / m
        self.summary[g, SUM_BX] = self.drift[g, 0]
        self.summary[g, SUM_BY] = self.drift[g, 1]
