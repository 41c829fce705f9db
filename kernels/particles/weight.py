"""Steps 3–4 of the particle filter: log-weights (Eqs. 14–15), their maxima and the segmented, deterministic
normalisation (Eqs. 16–17: per-tile f64 cumulative sums combined per group in tile order).
"""
import taichi as ti

from .layout import NEG_INF


@ti.data_oriented
class WeightMixin:
    """Steps 3–4 over the pool (Eqs. 14–17)."""

    @ti.func
    def log_weights(self, values: ti.template(), zp: ti.template()):
        """Step 3, Eq. 15 in the log domain: for E = 1,
        log ω̃ = Σ_{5×5} h(2z − h)/(2σ²) with h = I/(2πΣ²)·exp(−((i−x)² + (j−y)²)/(2Σ²)) (Eq. 14),
        over the in-image pixels of the 5×5 window around (⌊x+½⌋, ⌊y+½⌋); 0 for E = 0.
        The Gaussian is separable, h = a·gx·gy, so Σh² = a²·Σgx²·Σgy²; each axis's five samples
        come from two exponentials by a ratio recurrence (the likelihood model ``self.likelihood``).  ``values``:
        ``step_values`` (the buffer b, the frame's W and H, Σ and σ); ``zp``: the frame with a zero border of PAD
        pixels (H + 2·PAD, W + 2·PAD)."""
        b, width, height, psf_sigma, noise_sigma = values[2], values[6], values[7], values[8], values[9]
        inv2s2, norm, inv_var, step = self.likelihood.constants(psf_sigma, noise_sigma)
        weighing = (b, inv2s2, norm, inv_var, step, height, width)
        if ti.static(self.flat):
            self.for_slots(False, self.no_group_values, self.store_log_weight, {'values': weighing, 'zp': zp})
            self.tile_maxima(b, False, ())
        else:  # the tile maxima of step 4 in the same pass (one pass over the pool fewer)
            self.tile_maxima(b, True, {'values': weighing, 'zp': zp})

    @ti.func
    def store_log_weight(self, i: ti.i32, g: ti.i32, _: ti.template(), args: ti.template()):
        """``log_weights`` for slot i, as a ``for_slots`` body."""
        self.logw[i] = self.log_weight(i, args)

    @ti.func
    def log_weight(self, i: ti.i32, args: ti.template()) -> ti.f32:
        """Eq. 15's log-weight of slot i (0 for E = 0); ``args``: {'values': the constants of
        ``log_weights`` and the frame's H and W (px), 'zp': the bordered frame} (a dict: a tuple made in a kernel
        cannot hold an array)."""
        b, inv2s2, norm, inv_var, step, h, w = args['values']
        zp = ti.static(args['zp'])
        lw = ti.f32(0.0)
        if self.e[b, i] == 1:
            lw = self.likelihood.log_ratio(self.x[b, i], self.y[b, i], self.inten[b, i], zp,
                                           (inv2s2, norm, inv_var, step), h, w)
        return lw

    @ti.func
    def tile_maxima(self, b: ti.i32, weigh: ti.template(), args: ti.template()):
        """Per tile: the largest log-weight, and the largest among E = 1 particles.  ``weigh``: compute
        and store each log-weight first (``log_weight`` with ``args``), in the same pass."""
        self.for_tiles(self.tile_maximum, {'b': b, 'weigh': weigh, 'args': args})

    @ti.func
    def tile_maximum(self, t: ti.i32, loop: ti.template()):
        """``tile_maxima`` for tile t."""
        m, me = ti.f32(NEG_INF), ti.f32(NEG_INF)
        for i in range(self.tile_start[t], self.tile_end(t)):
            if ti.static(loop['weigh']):
                self.logw[i] = self.log_weight(i, loop['args'])
            lw = self.logw[i]
            m = ti.max(m, lw)
            if self.e[loop['b'], i] == 1:
                me = ti.max(me, lw)
        self.tile_max[t] = m
        self.tile_max_e[t] = me

    @ti.func
    def group_maxima(self):
        """Per group: max over its tiles (gmax normalises Eq. 16; gmax_e is the best E = 1 log-weight)."""
        ti.loop_config(serialize=self.serial)
        for g in range(self.off.shape[0]):
            self.group_maximum(g)

    @ti.func
    def group_maximum(self, g: ti.i32):
        """``group_maxima`` for group g."""
        m, me = ti.f32(NEG_INF), ti.f32(NEG_INF)
        for t in range(self.gt0[g], self.gt1[g]):
            m = ti.max(m, self.tile_max[t])
            me = ti.max(me, self.tile_max_e[t])
        self.gmax[g] = m
        self.gmax_e[g] = me

    @ti.func
    def tile_cumulative(self):
        """Eq. 17 within a tile: cum[i] = Σ_{tile start ≤ j ≤ i} exp(logw_j − gmax_g) in f64.  E = 0
        particles have log-weight 0, so their weight exp(−gmax) is computed once per tile."""
        self.for_tiles(self.tile_cumulative_sum, ())

    @ti.func
    def tile_cumulative_sum(self, t: ti.i32, _: ti.template()):
        """``tile_cumulative`` for tile t."""
        gmax = ti.cast(self.gmax[self.tile_group[t]], ti.f64)
        w0 = ti.exp(-gmax)
        s = ti.cast(0.0, ti.f64)
        for i in range(self.tile_start[t], self.tile_end(t)):
            lw = self.logw[i]
            w = w0
            if lw != 0.0:
                w = ti.exp(ti.cast(lw, ti.f64) - gmax)
            s += w
            self.cum[i] = s
        self.tile_total[t] = s

    @ti.func
    def exclusive_tile_prefix(self, g: ti.i32, totals: ti.template(), prefix: ti.template()) -> ti.f64:
        """prefix[t] = Σ of group g's tile totals before tile t, added in tile order (f64); returns their sum."""
        s = ti.cast(0.0, ti.f64)
        for t in range(self.gt0[g], self.gt1[g]):
            prefix[t] = s
            s += totals[t]
        return s

    @ti.func
    def group_prefix(self):
        """Eq. 17 across tiles: exclusive prefix of tile totals per group, and the group total."""
        ti.loop_config(serialize=self.serial)
        for g in range(self.off.shape[0]):
            self.gtotal[g] = self.exclusive_tile_prefix(g, self.tile_total, self.tile_prefix)
        ti.loop_config(serialize=self.serial)
        for t in range(self.tile_start.shape[0]):
            self.add_tile_prefix(t)

    @ti.func
    def add_tile_prefix(self, t: ti.i32):
        """Tile t's cumulative weights (Eq. 17 within the tile) become its group's: + the earlier tiles' total."""
        pre = self.tile_prefix[t]
        for i in range(self.tile_start[t], self.tile_end(t)):
            self.cum[i] = self.cum[i] + pre

    @ti.func
    def group_cumulative(self, g: ti.i32):
        """``group_prefix`` for group g alone."""
        self.gtotal[g] = self.exclusive_tile_prefix(g, self.tile_total, self.tile_prefix)
        for t in range(self.gt0[g], self.gt1[g]):
            self.add_tile_prefix(t)

    @ti.func
    def normalise_weights(self):
        """Step 4 from the tile maxima: per-group maxima and f64 cumulative sums (Eqs. 16–17)."""
        self.group_maxima()
        self.tile_cumulative()
        self.group_prefix()

    @ti.kernel
    def normalise(self, b: ti.i32):
        """Step 4 alone, on log-weights set from outside."""
        self.tile_maxima(b, False, ())
        self.normalise_weights()

    @ti.kernel
    def weigh(self, b: ti.i32, z: ti.types.ndarray(dtype=ti.f32, ndim=2)):
        """Steps 3–4 in one launch (see ``weigh_particles``), with the pool's Σ and σ (``step_values``)."""
        self.weigh_particles(self.step_values(0, b), z)

    @ti.func
    def weigh_particles(self, values: ti.template(), z: ti.template()):
        """Steps 3–4 on the normalised frame z (zero-bordered: H + 2·PAD, W + 2·PAD): log-weights
        (Eq. 15), their normalisation, and each group's largest E = 1 log-weight into ``best_e``;
        ``values``: ``step_values``."""
        self.log_weights(values, z)
        self.normalise_weights()
        self.keep_best()

    @ti.func
    def keep_best(self):
        """best_e ← gmax_e: each group's largest E = 1 log-weight of this weigh (``estimates`` reports it)."""
        ti.loop_config(serialize=True)
        for g in range(self.best_e.shape[0]):
            self.best_e[g] = self.gmax_e[g]
