"""The multiaspect kernels' weights, resampling, resample-move acceptance and §3.4 summaries (Bruno, Araújo &
Pavlov 2008, Eqs. 18–26), a mixin of :class:`kernels.multiaspect.MultiaspectKernels`, whose fields they use.
Sums within a group run serially in one thread, in slot order, so results do not depend on the thread count."""
import taichi as ti

from .rng import exponential_at, key_prefix

STATE = 4  # x, ẋ, y, ẏ
S_DRAW = 100  # multinomial draws: stream S_DRAW + the draw's number in the frame
SUM_ABSENT, SUM_X, SUM_VX, SUM_Y, SUM_VY, SUM_ASPECT = 0, 1, 2, 3, 4, 5  # columns of summarize's output; aspects
# from SUM_ASPECT


@ti.data_oriented
class MultiaspectResampling:
    """Eqs. 18–26 over the pool's fields (``prop``, ``cur``, ``prev``, ``cdf``, ``pick``, ``anc``, …)."""

    # ------------------------------------------------------------------ Eqs. 18, 23, 24: weights and resampling

    @ti.kernel
    def resample(self, seed: ti.u32, frame: ti.i32, number: ti.i32, second_stage: ti.i32, final: ti.i32,
                 side: ti.i32):
        """Multinomial resampling of each group, in one thread per group (slot order, f64):

        * weights: cdf = cumulative e^(v − max v) (terms in f32, the sum in f64) with v = prop_ll (Eqs. 18, 23)
          or, for the APF's second stage,
          prop_ll − cur_ll (Eq. 24: cur_ll holds the first stage's ℓ̂ of the particle's auxiliary index);
          total[g] = its last value;
        * draws: N sorted U(0, 1) as the normalised partial sums of N + 1 Exp(1) variates (the order statistics of
          N uniforms), merged with cdf: pick[j] = the first slot whose cdf exceeds U_(j)·total (a multinomial
          sample, in slot order);
        * gather: cur[j] ← prop[pick[j]] with its ℓ and anc[j] ← pick[j] (the ancestor in prev); ``final`` (the
          APF's post-sampling selection): prev[j] on the side other than ``side`` ← prop[pick[j]] instead."""
        span = ti.static(self.span)
        ti.loop_config(serialize=self.serial_groups)
        for it in range(self.groups * span):
            if it % span == 0:
                self.resample_group(it // span, seed, frame, number, second_stage, final, 1 - side)

    @ti.func
    def resample_group(self, g: ti.i32, seed: ti.u32, frame: ti.i32, number: ti.i32, second_stage: ti.i32,
                       final: ti.i32, out_side: ti.i32):
        """:meth:`resample` for group g, in this thread."""
        a, b = g * self.n, (g + 1) * self.n
        m = ti.f32(-3.0e38)
        for p in range(a, b):
            m = ti.max(m, self.log_weight(p, second_stage))
        cum = ti.f64(0.0)
        for p in range(a, b):
            cum += ti.cast(ti.exp(self.log_weight(p, second_stage) - m), ti.f64)  # terms f32, the sum f64
            self.cdf[p] = cum
        self.total[g] = cum
        key = key_prefix(seed, frame, S_DRAW + number)
        span = ti.f64(0.0)
        for j in range(a, b):
            span += exponential_at(self.exp_tables.w, self.exp_tables.k, self.exp_tables.f, key, j)
            self.spacing[j] = span
        span += exponential_at(self.exp_tables.w, self.exp_tables.k, self.exp_tables.f, key, b)
        scale = cum / span
        src = a
        for j in range(a, b):
            target = self.spacing[j] * scale
            while src < b - 1 and self.cdf[src] <= target:
                src += 1
            self.pick[j] = src
            if final != 0:
                self.keep(j, src, out_side)
            else:
                for d in ti.static(range(STATE)):
                    self.cur[j, d] = self.prop[src, d]
                self.cur_z[j] = self.prop_z[src]
                self.cur_ll[j] = self.prop_ll[src]
                self.anc[j] = src

    @ti.func
    def log_weight(self, p: ti.i32, second_stage: ti.i32) -> ti.f32:
        return self.prop_ll[p] - self.cur_ll[p] if second_stage != 0 else self.prop_ll[p]

    @ti.func
    def keep(self, j: ti.i32, i: ti.i32, side: ti.i32):
        """prev[j] on side ``side`` ← prop[i]."""
        o = j + side * self.capacity
        for d in ti.static(range(STATE)):
            self.prev[o, d] = self.prop[i, d]
        self.prev_z[o] = self.prop_z[i]

    # ------------------------------------------------------------------ Eqs. 19–21

    @ti.func
    def metropolis_hastings(self, j: ti.i32, u: ti.f32, final: ti.i32, side: ti.i32):
        """Accept prop[j] (drawn from the prior at the ancestor's n − 1 state) for cur[j] if u ≤ e^(ℓ̃ − ℓ) (Eq. 19),
        else keep cur[j] (Eqs. 20–21); ``final``: the outcome goes to prev[j] on side ``side`` instead."""
        accept = ti.log(u) <= self.prop_ll[j] - self.cur_ll[j]
        if final != 0:
            if accept:
                self.keep(j, j, side)
            else:
                o = j + side * self.capacity
                for d in ti.static(range(STATE)):
                    self.prev[o, d] = self.cur[j, d]
                self.prev_z[o] = self.cur_z[j]
        elif accept:
            for d in ti.static(range(STATE)):
                self.cur[j, d] = self.prop[j, d]
            self.cur_z[j] = self.prop_z[j]
            self.cur_ll[j] = self.prop_ll[j]

    # ------------------------------------------------------------------ §3.4

    @ti.kernel
    def summarize(self, out: ti.types.ndarray(dtype=ti.f64, ndim=2), side: ti.i32):
        """out[g] = (absent count, Σx, Σẋ, Σy, Σẏ over present particles, count of each aspect) of prev's side
        ``side``, per group in one thread (f64, slot order)."""
        span = ti.static(self.span)
        ti.loop_config(serialize=self.serial_groups)
        for it in range(self.groups * span):
            if it % span == 0:
                g = it // span
                absent = ti.f64(0.0)
                sums = ti.Vector([0.0] * STATE, dt=ti.f64)
                counts = ti.Vector([0.0] * self.k, dt=ti.f64)
                for p in range(g * self.n + side * self.capacity, (g + 1) * self.n + side * self.capacity):
                    z = self.prev_z[p]
                    if z == 0:
                        absent += 1.0
                    else:
                        sums += ti.Vector([self.prev[p, d] for d in ti.static(range(STATE))], dt=ti.f64)
                        for a in ti.static(range(self.k)):
                            if z == a + 1:
                                counts[a] += 1.0
                out[g, SUM_ABSENT] = absent
                for d in ti.static(range(STATE)):
                    out[g, SUM_X + d] = sums[d]
                for a in ti.static(range(self.k)):
                    out[g, SUM_ASPECT + a] = counts[a]
