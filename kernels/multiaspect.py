"""Multiaspect track-before-detect kernels (Bruno, Araújo & Pavlov 2008): one pool of G filters (groups) of N
particles each, slot p in group p // N; every step is one launch for all groups.

A particle is (x, ẋ, y, ẏ) in px and px/frame (x = column) and an aspect z ∈ {0, 1..K}, 0 = absent.  Buffers:
``prev`` (the particles at n − 1; two sides, the step reading side ``side`` writes the next frame's particles to
the other), ``prop`` (draws from the prior and their log-likelihood ratios), ``cur`` (resampled particles); ``pick``
holds resampled indices, ``anc`` each particle's ancestor in ``prev``.

Steps (the paper's equations):

* :meth:`MultiaspectKernels.load`: d = A·y, the 5-point stencil of Eq. 16 with zero boundary, per group;
* :meth:`MultiaspectKernels.propagate`: (z, s) ~ Eq. 2 (aspect by G, Eq. 1; exit with 1 − P_in, Eq. 6 in closed
  form; entry with p_a, uniform aspect, s ~ f₀, Eq. 5) and Eq. 4's white-noise acceleration, from ``prev[p]`` or
  from the ancestor ``prev[anc[p]]``, with each draw's ℓ and, for the resample-move filter, its MH move;
* :meth:`MultiaspectKernels.likelihood`: ℓ = (2λ − ρ)/(2σ_c²) (Eq. 10 over the absent hypothesis), λ by Eq. 15
  (computed once per (centroid, aspect) in a run of slots, :meth:`MultiaspectKernels.log_ratio`),
  ρ = E₀ − 2β_h·C_h − 2β_v·C_v from the border-aware tables (Eq. 12), 0 for z = 0 or off the extended grid;
* ``kernels.multiaspect_resampling`` (a mixin): ``resample``, weights ∝ e^ℓ (Eqs. 18, 23) or the second stage's
  ∝ e^(ℓ − ℓ̂) (Eq. 24), cumulated per group in f64, multinomial draws, the gather; ``metropolis_hastings``, the
  resample-move acceptance (Eqs. 19–21); ``summarize``, per group the absent count, the present particles' sums
  and each aspect's count (§3.4).

Sums within a group run serially in one thread (groups in parallel), so results do not depend on the thread
count; random numbers are ``kernels.rng``'s, keyed on (seed, frame, stream, slot).  The NumPy twin is
``tbd_taichi.numpy_kernels.multiaspect``."""
import numpy as np
import taichi as ti

from .loops import FrameSize, in_corner, light_ir, thread_span
from .phd import ERF_END, SQRT_HALF, ErfTable, erf
from .multiaspect_resampling import S_DRAW, STATE, SUM_ABSENT, SUM_ASPECT, SUM_VX, SUM_VY, SUM_X, SUM_Y  # noqa: F401
from .multiaspect_resampling import MultiaspectResampling
from .rng import ExponentialTables, NormalTables, key_prefix, normals_at, uniform_at, uniform_f64_at

S_EXIT, S_ASPECT, S_ENTER, S_NOISE = 0, 1, 2, 3  # streams; S_NOISE…S_NOISE+3: the four motion normals
S_F0 = 7  # f₀'s draws: x, y (uniform), ẋ, ẏ (normal and uniform parts): streams 7…12
S_BIRTH_CELL = 13  # a data-driven birth's cell
STAGE_STREAMS = 16  # propagate's stage s uses streams STAGE_BASE + 16·s + …
STAGE_BASE = 1000
S_MOVE = 200  # the MH acceptance uniforms: S_MOVE + the propagation stage (≤ 100)
S_PRIOR = 400  # the initial draw: 400…407
LAW = ("x0", "x1", "y0", "y1", "v_mean", "v_sd", "v_spread")  # f₀ and the prior: U[x0, x1] × U[y0, y1], velocity
# per axis v_mean + v_sd·n + v_spread·(2u − 1)
GPAR = ("beta_h", "beta_v", "sigma_c2")
N_LAW, N_GPAR = len(LAW), len(GPAR)
_NP = {ti.f32: np.float32, ti.i32: np.int32, ti.f64: np.float64}

LANES = 4  # partial sums of λ (Eq. 15) kept apart
MEMO_BITS = 5
MEMO = 1 << MEMO_BITS  # entries of a run's ℓ cache (:meth:`MultiaspectKernels.log_ratio`)
RUN = 256  # slots per run of the particle loops on a CPU (:meth:`MultiaspectKernels.log_ratio`)


def template_support(th: int, tw: int) -> int:
    """The most non-zero pixels an aspect of a th × tw template can have, rounded up to whole LANES (λ's sum reads
    the zero padding up to the next multiple)."""
    return -(-th * tw // LANES) * LANES


def template_pixels(templates: np.ndarray, support: int, row_length: int) -> tuple:
    """Each aspect's non-zero pixels, padded to ``support``: (offsets, values, counts), (K, support) arrays and (K,),
    an offset being row·``row_length`` + column from the template's corner (the padded d's rows are
    ``row_length`` long); λ (Eq. 15) sums over them only (a vehicle fills about a third of its box)."""
    k = len(templates)
    offsets, vals = np.zeros((k, support), np.int32), np.zeros((k, support), np.float32)
    counts = np.zeros(k, np.int32)
    for z, t in enumerate(np.asarray(templates)):
        r, c = np.nonzero(t)
        counts[z] = len(r)
        offsets[z, :len(r)], vals[z, :len(r)] = r * row_length + c, t[r, c]
    return offsets, vals, counts


@ti.data_oriented
class MultiaspectKernels(MultiaspectResampling, FrameSize):
    """Fields of ``groups`` filters of ``n`` particles for frames of ``shape`` and the (K, h, w) templates.  The
    fields that follow the frame (d, the energy tables, the birth proposal) take the extents of the frame's size
    class (``loops.frame_class``) and the kernels read the frame's (H, W) from ``frame_hw``, so frames of one class
    share the compiled kernels."""

    FRAME_TABLES = ("energy", "birth_cdf", "birth_lq")  # put() places a frame's table in the class's corner

    def __init__(self, groups: int, n: int, shape, template_shape, serial: bool = False):
        self.groups, self.n = int(groups), int(n)
        self.k, th, tw = (int(v) for v in template_shape)
        self.support = template_support(th, tw)
        self.halves = ((th - 1) // 2, (tw - 1) // 2)
        self.serial = bool(serial)
        c, g, (h, w) = self.groups * self.n, self.groups, self.frame_size_field(shape)
        self.capacity = c
        self.prev = ti.field(ti.f32, (2 * c, STATE))  # side s: slots [s·C, (s + 1)·C)
        self.prev_z = ti.field(ti.i32, 2 * c)
        self.prop, self.cur = ti.field(ti.f32, (c, STATE)), ti.field(ti.f32, (c, STATE))
        self.prop_z, self.cur_z = ti.field(ti.i32, c), ti.field(ti.i32, c)
        self.prop_ll, self.cur_ll = ti.field(ti.f32, c), ti.field(ti.f32, c)
        self.pick, self.anc = ti.field(ti.i32, c), ti.field(ti.i32, c)
        self.cdf = ti.field(ti.f64, c)
        self.spacing = ti.field(ti.f64, c)  # partial sums of the Exp(1) spacings while resampling
        self.total = ti.field(ti.f64, g)
        hh, hw = self.halves
        # d (Eq. 16) with a zero border of twice the half sizes: a template at any extended-grid centroid reads it
        # without bounds checks; d[g, r + PAD_R, c + PAD_C] is pixel (r, c)
        self.padded = (h + 4 * hh, w + 4 * hw)
        self.d = ti.field(ti.f32, g * self.padded[0] * self.padded[1])  # flat: g, row, column
        self.gpar = ti.field(ti.f32, (g, len(GPAR)))
        self.motion = ti.field(ti.f32, 3)  # (a, b, c): one axis' Q Cholesky factor (w = (a·n₁, b·n₁ + c·n₂))
        self.law = ti.field(ti.f32, len(LAW))  # f₀ (Eq. 5): kernels.multiaspect.LAW
        # each aspect's non-zero pixels (Eq. 8's b_kl = 1): row and column offsets from the template's corner, value;
        # tcount[z] of them, the rest unused (set_templates)
        self.t_off = ti.field(ti.i32, (self.k, self.support))
        self.t_val = ti.field(ti.f32, (self.k, self.support))
        self.t_count = ti.field(ti.i32, self.k)
        self.energy = ti.field(ti.f32, (3, self.k, h + th - 1, w + tw - 1))  # the frame's in the corner
        self.gcdf = ti.field(ti.f32, (self.k, self.k))  # gcdf[j, i] = Σ_{i' ≤ i} G(i', j): column j's cumulative
        # data-driven births (not in the paper): per group the cumulative proposal q over the extended grid's cells
        # (row-major: the frame's (H + h − 1)·(W + w − 1) cells lead the class's) and log(f₀/q) per cell; a particle's
        # birth log-weight correction
        cells = (h + th - 1) * (w + tw - 1)  # the class's; a frame's: birth_cell
        self.birth_cdf = ti.field(ti.f64, (g, cells))
        self.birth_lq = ti.field(ti.f32, (g, cells))
        self.blw = ti.field(ti.f32, c)
        self.tables, self.exp_tables = NormalTables.shared(), ExponentialTables.shared()
        self.erf_table = ErfTable.shared()
        # one group: its serial per-group loops run in the launching thread (a parallel task costs ~0.08 ms to start)
        self.serial_groups = serial or self.groups == 1
        self.span = thread_span(self.serial_groups)
        # the particle loops walk runs of RUN consecutive slots, one thread each, reusing ℓ within a run
        # (:meth:`log_ratio`); on a GPU (span 1) a run is one slot
        self.span_particles = thread_span(serial)
        self.run = RUN if self.span_particles > 1 else 1
        self.runs = -(-c // self.run)

    # ------------------------------------------------------------------ Eq. 16

    def set_frame_size(self, shape) -> None:
        """The frames are now of ``shape`` (of the fields' class); d is cleared, so that its zero border holds no
        pixel of a larger frame of the class (fields reused from another tracker, ``backend.reusable``)."""
        super().set_frame_size(shape)
        self.d.fill(0.0)

    @ti.kernel
    def load(self, y: ti.types.ndarray(dtype=ti.f32, ndim=3), gpar: ti.types.ndarray(dtype=ti.f32, ndim=2)):
        """Each group's mean-removed frame y[g] (H, W) and its (β_h, β_v, σ_c²) row: d[g] = A·y[g] = y − β_h·(left
        + right) − β_v·(up + down), y = 0 outside the image (Eq. 16), into the padded d (its border stays 0).
        Rows in parallel at every frame size (a small frame's d in the launching thread was no faster at 120²)."""
        h, w = self.frame_hw[0], self.frame_hw[1]
        hh, hw = ti.static(self.halves)
        ti.loop_config(serialize=self.serial)
        for g, r in ti.ndrange(self.groups, h):  # one loop of rows: a second would be a second task (~0.08 ms)
            if r == 0:
                for i in range(N_GPAR):
                    self.gpar[g, i] = gpar[g, i]
            bh, bv = gpar[g, 0], gpar[g, 1]
            base = self.d_index(g, r + 2 * hh, 2 * hw)
            # the row's pixels with both horizontal neighbours in one branch-free pass, then its two end pixels
            # (inner rows without vertical checks: 0.11 against 0.12 ms at 120², measured)
            if r > 0 and r < h - 1:
                for c in range(1, w - 1):
                    self.d[base + c] = y[g, r, c] - bh * (y[g, r, c - 1] + y[g, r, c + 1]) \
                        - bv * (y[g, r - 1, c] + y[g, r + 1, c])
            else:
                for c in range(1, w - 1):
                    self.d[base + c] = y[g, r, c] - bh * (y[g, r, c - 1] + y[g, r, c + 1]) - bv * self.vertical(y, g, r, c)
            for c in ti.static(range(2)):
                col = c * (w - 1)
                left = y[g, r, col - 1] if col > 0 else 0.0
                right = y[g, r, col + 1] if col < w - 1 else 0.0
                self.d[base + col] = y[g, r, col] - bh * (left + right) - bv * self.vertical(y, g, r, col)

    @ti.func
    def vertical(self, y: ti.template(), g: ti.i32, r: ti.i32, c: ti.i32) -> ti.f32:
        """y's pixels above and below (r, c), 0 outside the image (Eq. 16's zero boundary)."""
        h = self.frame_hw[0]
        up = y[g, r - 1, c] if r > 0 else 0.0
        down = y[g, r + 1, c] if r < h - 1 else 0.0
        return up + down

    @ti.func
    def d_index(self, g: ti.i32, row: ti.i32, col: ti.i32) -> ti.i32:
        """The flat index of the padded d's (row, col) in group g."""
        hp, wp = ti.static(self.padded)
        return (g * hp + row) * wp + col

    def d_image(self, g: int) -> np.ndarray:
        """Group g's d (H, W), without the border."""
        (h, w), (hh, hw) = self.shape, self.halves
        return self.d.to_numpy().reshape((self.groups,) + self.padded)[g, 2 * hh:2 * hh + h, 2 * hw:2 * hw + w]

    # ------------------------------------------------------------------ Eqs. 1–6

    @ti.kernel
    def init_prior(self, seed: ti.u32, p_absent: ti.f32, law: ti.types.ndarray(dtype=ti.f32, ndim=1)):
        """prev (side 0) ← the prior: z = 0 with probability ``p_absent``, else uniform on 1..K; s ~ ``law`` (LAW)."""
        k_abs = key_prefix(seed, 0, S_PRIOR)
        k_asp = key_prefix(seed, 0, S_PRIOR + 1)
        prior = ti.Vector([law[i] for i in ti.static(range(N_LAW))], dt=ti.f32)
        for p in range(self.capacity):
            s = self.law_draw(seed, 0, S_PRIOR + 2, p, prior)
            for i in ti.static(range(STATE)):
                self.prev[p, i] = s[i]
            z = 0
            if uniform_at(k_abs, p) >= p_absent:
                z = 1 + ti.min(ti.cast(uniform_at(k_asp, p) * self.k, ti.i32), self.k - 1)
            self.prev_z[p] = z

    @ti.func
    def law_draw(self, seed: ti.u32, frame: ti.i32, stream: ti.i32, p: ti.i32, law):
        """(x, ẋ, y, ẏ) ~ ``law``: x ~ U[x0, x1], y ~ U[y0, y1], each velocity v_mean + v_sd·n + v_spread·(2u − 1)."""
        ux = uniform_at(key_prefix(seed, frame, stream), p)
        uy = uniform_at(key_prefix(seed, frame, stream + 1), p)
        nvx, nvy = normals_at(self.tables.w, self.tables.k, self.tables.phi,
                              [key_prefix(seed, frame, stream + 2), key_prefix(seed, frame, stream + 3)], p)
        uvx = uniform_at(key_prefix(seed, frame, stream + 4), p)
        uvy = uniform_at(key_prefix(seed, frame, stream + 5), p)
        return ti.Vector([law[0] + (law[1] - law[0]) * ux, law[4] + law[5] * nvx + law[6] * (2.0 * uvx - 1.0),
                          law[2] + (law[3] - law[2]) * uy, law[4] + law[5] * nvy + law[6] * (2.0 * uvy - 1.0)],
                         dt=ti.f32)

    @ti.kernel
    def configure(self, motion: ti.types.ndarray(dtype=ti.f32, ndim=1), law: ti.types.ndarray(dtype=ti.f32, ndim=1)):
        """The motion noise factor (a, b, c) and f₀'s LAW vector the propagation uses."""
        for i in range(3):
            self.motion[i] = motion[i]
        for i in range(N_LAW):
            self.law[i] = law[i]

    @light_ir
    @ti.kernel
    def propagate(self, seed: ti.u32, frame: ti.i32, stage: ti.i32, from_ancestor: ti.i32, coupled: ti.i32,
                  data_births: ti.i32, p_a: ti.f32, side: ti.i32, move: ti.i32):
        """prop[p] ~ p(s, z | prev[q]) with q = anc[p] if ``from_ancestor`` else p (Eqs. 2, 4, 5), by the
        :meth:`configure`'d motion (a, b, c), the Cholesky factor of one axis' Q (w = (a·n₁, b·n₁ + c·n₂)), and f₀;
        P_in by Eq. 6 in closed form with the position sd a; ``coupled``: exit iff the drawn s leaves the extended
        grid instead (same z law).  ``data_births``: an entering target's cell is drawn from the group's proposal q
        (birth_cdf) instead of f₀'s uniform law (its velocity still from f₀), and blw[p] = log(f₀/q) of the cell
        corrects its weight; blw = 0 for every other particle.  Each drawn particle's prop_ll is computed here too
        (:meth:`log_ratio`: one pass, no second launch).  prev is read on side ``side``.  ``move`` (the resample-move
        step, Eqs. 19–21, on the particle's own proposal): 1, accept prop[p] for cur[p] if u ≤ e^(ℓ̃ − ℓ) (the
        prior cancels in the independence sampler's ratio); 2, the same with the outcome written to prev's other
        side, the particles at n for the next frame (the last sweep)."""
        motion = ti.Vector([self.motion[i] for i in ti.static(range(3))], dt=ti.f32)
        law = ti.Vector([self.law[i] for i in ti.static(range(N_LAW))], dt=ti.f32)
        base = STAGE_BASE + STAGE_STREAMS * stage
        k_exit, k_asp = key_prefix(seed, frame, base + S_EXIT), key_prefix(seed, frame, base + S_ASPECT)
        k_enter = key_prefix(seed, frame, base + S_ENTER)
        kn = [key_prefix(seed, frame, base + S_NOISE + i) for i in ti.static(range(4))]
        k_move = key_prefix(seed, frame, S_MOVE + stage)
        span, run = ti.static(self.span_particles, self.run)
        for it in range(self.runs * span):
            if it % span == 0:  # one run of `run` slots in this thread (:meth:`log_ratio`)
                keys, ratios = ti.Vector([-1] * MEMO, dt=ti.i32), ti.Vector([0.0] * MEMO, dt=ti.f32)
                for p in range(it // span * run, ti.min((it // span + 1) * run, self.capacity)):
                    q = (self.anc[p] if from_ancestor != 0 else p) + side * self.capacity
                    z = self.prev_z[q]
                    x, vx, y, vy = self.prev[q, 0], self.prev[q, 1], self.prev[q, 2], self.prev[q, 3]
                    n = normals_at(self.tables.w, self.tables.k, self.tables.phi, kn, p)
                    moved = ti.Vector([x + vx + motion[0] * n[0], vx + motion[1] * n[0] + motion[2] * n[1],
                                       y + vy + motion[0] * n[2], vy + motion[1] * n[2] + motion[2] * n[3]], dt=ti.f32)
                    u_exit, u_asp = uniform_at(k_exit, p), uniform_at(k_asp, p)
                    new_z = 0
                    self.blw[p] = 0.0
                    if z != 0:
                        stays = self.on_grid(moved[0], moved[2])
                        if coupled == 0:
                            stays = u_exit < self.p_inside(x + vx, y + vy, motion[0])
                        if stays:
                            new_z = self.next_aspect(z, u_asp)
                    elif uniform_at(k_enter, p) < p_a:
                        new_z = 1 + ti.min(ti.cast(u_asp * self.k, ti.i32), self.k - 1)
                        moved = self.law_draw(seed, frame, base + S_F0, p, law)
                        if data_births != 0:
                            g = p // self.n
                            cell = self.birth_cell(g, uniform_f64_at(key_prefix(seed, frame, base + S_BIRTH_CELL), p))
                            moved[0] = self.cell_column(cell) + (moved[0] - law[0]) / (law[1] - law[0]) - 0.5
                            moved[2] = self.cell_row(cell) + (moved[2] - law[2]) / (law[3] - law[2]) - 0.5
                            self.blw[p] = self.birth_lq[g, cell]
                    for i in ti.static(range(STATE)):
                        self.prop[p, i] = moved[i]
                    self.prop_z[p] = new_z
                    self.prop_ll[p] = self.log_ratio(p, keys, ratios)
                    if move != 0:
                        self.metropolis_hastings(p, uniform_at(k_move, p), move == 2, 1 - side)

    @ti.func
    def birth_cell(self, g: ti.i32, u: ti.f64) -> ti.i32:
        """The first of the frame's cells whose cumulative proposal exceeds u (birth_cdf ends at 1)."""
        lo, hi = 0, (self.frame_hw[0] + 2 * self.halves[0]) * (self.frame_hw[1] + 2 * self.halves[1]) - 1
        while lo < hi:
            mid = (lo + hi) // 2
            if self.birth_cdf[g, mid] > u:
                hi = mid
            else:
                lo = mid + 1
        return lo

    @ti.func
    def cell_column(self, cell: ti.i32) -> ti.f32:
        """The centroid column of extended-grid cell ``cell`` (row-major, columns −h_w … W − 1 + h_w)."""
        width = self.frame_hw[1] + 2 * self.halves[1]
        return ti.cast(cell % width - self.halves[1], ti.f32)

    @ti.func
    def cell_row(self, cell: ti.i32) -> ti.f32:
        """The centroid row of extended-grid cell ``cell``."""
        width = self.frame_hw[1] + 2 * self.halves[1]
        return ti.cast(cell // width - self.halves[0], ti.f32)

    @ti.func
    def next_aspect(self, z: ti.i32, u: ti.f32) -> ti.i32:
        """Aspect i ~ G(·, z) (Eq. 1): the first i with gcdf[z − 1, i − 1] > u."""
        out = self.k
        for i in range(self.k):
            if out == self.k and u < self.gcdf[z - 1, i]:
                out = i + 1
        return out

    @ti.func
    def on_grid(self, x: ti.f32, y: ti.f32) -> ti.i32:
        """Whether the quantised centroid (Eq. 3) of (x, y) lies on the extended grid."""
        h, w = self.frame_hw[0], self.frame_hw[1]
        hh, hw = ti.static(self.halves)
        c = ti.cast(ti.floor(x + 0.5), ti.i32)
        r = ti.cast(ti.floor(y + 0.5), ti.i32)
        return -hw <= c < w + hw and -hh <= r < h + hh

    @ti.func
    def p_inside(self, mx: ti.f32, my: ti.f32, sd: ti.f32) -> ti.f32:
        """P_in of Eq. 6 (notes A1): Φ-differences of the extended grid's edges around the predicted (mx, my);
        exactly 1 in f32 when every edge is ≥ ERF_END/s away (erf is then 1 to f32 precision), so erf is skipped."""
        h, w = self.frame_hw[0], self.frame_hw[1]
        hh, hw = ti.static(self.halves)
        s = ti.f32(SQRT_HALF) / ti.max(sd, 1e-12)
        near = ti.min(ti.min(w - 0.5 + hw - mx, mx + hw + 0.5), ti.min(h - 0.5 + hh - my, my + hh + 0.5)) * s
        out = ti.f32(1.0)
        if near < ERF_END:
            t = ti.static(self.erf_table.values)
            px = 0.5 * (erf((w - 0.5 + hw - mx) * s, t) - erf((-hw - 0.5 - mx) * s, t))
            py = 0.5 * (erf((h - 0.5 + hh - my) * s, t) - erf((-hh - 0.5 - my) * s, t))
            out = px * py
        return out

    # ------------------------------------------------------------------ Eqs. 10–15

    @ti.kernel
    def likelihood(self):
        """prop_ll for every slot (:meth:`log_ratio`); :meth:`propagate` does this for the slots it draws."""
        span, run = ti.static(self.span_particles, self.run)
        for it in range(self.runs * span):
            if it % span == 0:
                keys, ratios = ti.Vector([-1] * MEMO, dt=ti.i32), ti.Vector([0.0] * MEMO, dt=ti.f32)
                for p in range(it // span * run, ti.min((it // span + 1) * run, self.capacity)):
                    self.prop_ll[p] = self.log_ratio(p, keys, ratios)

    @ti.func
    def lambda_key(self, p: ti.i32) -> ti.i32:
        """(corner, aspect) of prop[p] as one integer: the padded d's flat index of the template's top-left pixel
        times K plus z − 1; −1 for an absent particle or one off the extended grid (ℓ = 0)."""
        hh, hw = ti.static(self.halves)
        z = self.prop_z[p]
        key = -1
        if z != 0 and self.on_grid(self.prop[p, 0], self.prop[p, 2]):
            c = ti.cast(ti.floor(self.prop[p, 0] + 0.5), ti.i32)
            r = ti.cast(ti.floor(self.prop[p, 2] + 0.5), ti.i32)
            key = self.d_index(p // self.n, r + hh, c + hw) * self.k + z - 1
        return key

    @ti.func
    def log_ratio(self, p: ti.i32, keys: ti.template(), ratios: ti.template()) -> ti.f32:
        """ℓ of prop[p]: :meth:`template_ratio` at its :meth:`lambda_key`, 0 if absent or off the extended grid,
        plus the birth correction blw[p] (0 unless the particle entered from the data-driven proposal).  The ratio
        is taken from the run's small cache (``keys``, ``ratios``: MEMO entries, direct-mapped by a hash of the
        key) when an earlier slot of the run had the same key, else computed and cached: the particles of a frame
        crowd a few dozen (centroid, aspect) pairs around the target (they move ~0.06 px a frame), so most are
        repeats (the same sum, the same bits)."""
        key = self.lambda_key(p)
        out = ti.f32(0.0)
        if key >= 0:
            e = ti.cast((ti.cast(key, ti.u32) * ti.u32(2654435761)) >> ti.u32(32 - MEMO_BITS), ti.i32)
            if keys[e] == key:
                out = ratios[e]
            else:
                out = self.template_ratio(key)
                keys[e], ratios[e] = key, out
        return out + self.blw[p]

    @ti.func
    def template_ratio(self, key: ti.i32) -> ti.f32:
        """(2λ − ρ)/(2σ_c²) (Eqs. 10, 12, 15) for the :meth:`lambda_key` ``key``: λ = Σ a_kl(z)·d over the aspect's
        non-zero pixels from the padded d's index ``corner`` (no bounds checks: pixels off the image read the zero
        border), ρ = E₀ − 2β_h·C_h − 2β_v·C_v from the border-aware tables, whose (row, column) is the corner's
        within its group's padded d."""
        hp, wp = ti.static(self.padded)
        corner, a = key // self.k, key % self.k
        g, row, col = corner // (hp * wp), corner // wp % hp, corner % wp
        # LANES independent partial sums: one chain of dependent adds would wait out each add's latency
        part = ti.Vector([0.0] * LANES, dt=ti.f32)
        for i in range((self.t_count[a] + LANES - 1) // LANES):
            for u in ti.static(range(LANES)):
                j = i * LANES + u
                part[u] += self.t_val[a, j] * self.d[corner + self.t_off[a, j]]
        lam = part.sum()
        rho = self.energy[0, a, row, col] - 2.0 * self.gpar[g, 0] * self.energy[1, a, row, col] \
            - 2.0 * self.gpar[g, 1] * self.energy[2, a, row, col]
        return (2.0 * lam - rho) / (2.0 * self.gpar[g, 2])

    # ------------------------------------------------------------------ host transfers

    def set_templates(self, templates: np.ndarray, energy: np.ndarray) -> None:
        """The (K, h, w) templates as their non-zero pixels (:func:`template_pixels`) and their energy tables."""
        offsets, vals, counts = template_pixels(templates, self.support, self.padded[1])
        for name, v in (("t_off", offsets), ("t_val", vals), ("t_count", counts), ("energy", energy)):
            self.put(name, v)

    def set_particles(self, state: np.ndarray, z: np.ndarray, side: int = 0) -> None:
        """prev's side ``side`` ← (C, 4) states and (C,) aspects."""
        c = self.capacity
        full, full_z = self.prev.to_numpy(), self.prev_z.to_numpy()
        full[side * c:(side + 1) * c], full_z[side * c:(side + 1) * c] = state, z
        self.put("prev", full)
        self.put("prev_z", full_z)

    def particles(self, side: int = 0) -> tuple[np.ndarray, np.ndarray]:
        """prev's side ``side``: (C, 4) states and (C,) aspects."""
        c = self.capacity
        return self.prev.to_numpy()[side * c:(side + 1) * c], self.prev_z.to_numpy()[side * c:(side + 1) * c]

    def put(self, name: str, values) -> None:
        """Field ``name`` ← ``values`` (its whole shape; a FRAME_TABLES table of the frame: the class's corner)."""
        field = getattr(self, name)
        values = np.ascontiguousarray(values, dtype=_NP[field.dtype])
        if name in self.FRAME_TABLES:
            values = in_corner(values, field.shape)
        field.from_numpy(values.reshape(field.shape))

    def get(self, name: str) -> np.ndarray:
        """A copy of field ``name``."""
        return getattr(self, name).to_numpy()
