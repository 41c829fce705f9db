"""Batched particle filter kernels (SGDS-PF section 2.1, Eqs. 7–19) over one particle pool.

The pool is a structure of arrays with two buffers (leading axis 2: resampling gathers
from one into the other).  Every filter is a *group* that owns a fixed slab of slots
[off_g, off_g + cap_g) of which the first n_g are live; kernels run over the whole pool,
so one launch steps every group (every search block, every track).

Random numbers come from the counter-based generator keyed on (seed, frame, stream,
slot), so results do not depend on the thread count.  Segmented reductions are
deterministic too: each group's slab is cut into tiles of TILE slots, a tile is reduced
serially (tiles in parallel), and a group combines its tiles in order.  Cumulative
weights are f64.  The NumPy twin is ``tbd_taichi.numpy_kernels.particles``.
"""
import math

import taichi as ti

from .loops import THREAD_SPAN
from .populations import PopulationKernels
from .rng import ExponentialTables, NormalTables, exponential_at, key_prefix, normal_at, uniform_at, uniform_f64_at

TILE = 1024
PAD = 4  # zero border of the frame the weights read: a 5×5 window (Eq. 15) that touches the image stays inside it
WALKS = 4  # interleaved merge walks per tile in draw_parents
NEG_INF = -3.0e38
TWO_PI = 2.0 * math.pi

# random streams: one per use, so no two draws share a key
S_EXIST, S_BIRTH_X, S_BIRTH_Y, S_BIRTH_SPEED, S_BIRTH_ANGLE, S_BIRTH_I, S_BIRTH_PIXEL = range(1, 8)
S_BIRTH_MU, S_COPY = 20, 21
BIRTH_STREAMS = (S_BIRTH_X, S_BIRTH_Y, S_BIRTH_SPEED, S_BIRTH_ANGLE, S_BIRTH_I, S_BIRTH_PIXEL, S_BIRTH_MU, S_COPY)
COPY_TRIES = 16  # draws of a random slot to find an E = 1 particle to copy
S_NOISE_X, S_NOISE_VX, S_NOISE_I, S_RESAMPLE = range(8, 12)
S_RESAMPLE_END, S_NOISE_Y, S_NOISE_VY = 22, 23, 24
S_SYSTEMATIC = 99  # u0 of systematic resampling, one per group
NOISE_STREAMS = (S_NOISE_X, S_NOISE_VX, S_NOISE_Y, S_NOISE_VY, S_NOISE_I)  # n1 … n5 of ``propagate``

# per-group sums of ``moments`` (f64)
M_N, M_E, M_EX, M_EVX, M_EY, M_EVY, M_EI, M_TP, M_X, M_Y, M_XX, M_YY, M_XY, M_EXX, M_EYY, M_EXY = range(16)
N_MOMENTS = 16


@ti.func
def psf_samples(d0: ti.f32, inv2s2: ti.f32, step: ti.f32, p0: ti.i32, size: ti.i32):
    """Eq. 14 along one axis: g_k = exp(−(d0 + k)²/(2Σ²)) for k = 0…4 (0 where pixel p0 + k is outside
    [0, size)), from g_0 and the ratio r_k = g_{k+1}/g_k = exp(−(2(d0 + k) + 1)/(2Σ²)) = r_0·step^k,
    step = exp(−2/(2Σ²)): two exponentials instead of five, a few f32 ulps apart."""
    g = ti.Vector([0.0] * 5, dt=ti.f32)
    gk = ti.exp(-d0 * d0 * inv2s2)
    r = ti.exp(-(ti.f32(2.0) * d0 + ti.f32(1.0)) * inv2s2)
    for k in ti.static(range(5)):
        g[k] = gk if 0 <= p0 + k < size else ti.f32(0.0)
        gk *= r
        r *= step
    return g


@ti.func
def ncv_noise_factors(q1: ti.f32, q2: ti.f32):
    """Cholesky factor of Eq. 46's NCV noise (T = 1: [[q1/3, q1/2], [q1/2, q1]]) per axis, c11, c21, c22,
    and √q2 of the intensity walk."""
    return ti.sqrt(q1 / ti.f32(3.0)), ti.sqrt(q1) * ti.f32(0.8660254037844386), ti.sqrt(q1) * ti.f32(0.5), ti.sqrt(q2)


@ti.func
def psf_constants(psf_sigma: ti.f32, noise_sigma: ti.f32):
    """Eq. 14–15's constants: 1/(2Σ²), 1/(2πΣ²), 1/σ² and psf_samples' ratio step exp(−2/(2Σ²))."""
    inv2s2 = ti.f32(1.0) / (ti.f32(2.0) * psf_sigma * psf_sigma)
    norm = ti.f32(1.0) / (ti.f32(TWO_PI) * psf_sigma * psf_sigma)
    return inv2s2, norm, ti.f32(1.0) / (noise_sigma * noise_sigma), ti.exp(ti.f32(-2.0) * inv2s2)


@ti.data_oriented
class ParticleKernels(PopulationKernels):
    """Fields and kernels of one particle pool; the scheduler is ``tbd_taichi.particles.ParticlePool``."""

    def __init__(self, capacity: int, n_groups: int, n_tiles: int, frame_shape, map_capacity: int, serial: bool,
                 flat: bool, split: int = 1):
        c, g = capacity, n_groups
        self.capacity, self.serial, self.flat, self.split = capacity, serial, flat, split
        self.frame_shape = (int(frame_shape[0]), int(frame_shape[1]))
        self.tiles_by_group = n_groups >= 2 * split  # for_tiles deals out whole groups (else single tiles)
        f32 = lambda *shape: ti.field(ti.f32, shape=shape)  # noqa: E731
        i32 = lambda *shape: ti.field(ti.i32, shape=shape)  # noqa: E731
        f64 = lambda *shape: ti.field(ti.f64, shape=shape)  # noqa: E731
        self.x, self.vx, self.y, self.vy, self.inten = f32(2, c), f32(2, c), f32(2, c), f32(2, c), f32(2, c)
        self.e, self.tp, self.seq = i32(2, c), i32(2, c), i32(2, c)
        self.logw, self.born, self.parent, self.cum, self.spc = f32(c), i32(c), i32(c), f64(c), f64(c)
        self.slot_group = i32(c)
        self.off, self.cap, self.n, self.n_out, self.kind = i32(g), i32(g), i32(g), i32(g), i32(g)
        self.n_before, self.state_start = i32(g), i32(g)
        self.pb, self.pd, self.mu = f32(g), f32(g), f32(g)
        self.bx0, self.bx1, self.by0, self.by1 = f32(g), f32(g), f32(g), f32(g)
        self.vmax, self.imin, self.imax = f32(g), f32(g), f32(g)
        self.gmax, self.gmax_e, self.gtotal = f32(g), f32(g), f64(g)
        self.gt0, self.gt1, self.gspc = i32(g), i32(g), f64(g)
        self.tile_start, self.tile_group = i32(n_tiles), i32(n_tiles)
        self.tile_max, self.tile_max_e, self.tile_total, self.tile_prefix = f32(n_tiles), f32(n_tiles), \
            f64(n_tiles), f64(n_tiles)
        self.tile_spc, self.tile_spc_prefix = f64(n_tiles), f64(n_tiles)
        self.tile_moments = f64(n_tiles, N_MOMENTS)
        self.map_pixel, self.map_seq, self.map_cdf = i32(map_capacity), i32(map_capacity), f64(map_capacity)
        self.map_off, self.map_n, self.map_total = i32(g), i32(g), f64(g)
        self.population_fields(c, frame_shape)
        self.normal, self.exponential = NormalTables(), ExponentialTables()

    # ------------------------------------------------------------ helpers

    @ti.func
    def tile_end(self, t: ti.i32) -> ti.i32:
        g = self.tile_group[t]
        return ti.min(self.tile_start[t] + TILE, self.off[g] + self.n[g])

    @ti.func
    def for_slots(self, resampled: ti.template(), prologue: ti.template(), body: ti.template(), args: ti.template()):
        """body(i, g, prologue(g, args), args) for every live slot i of group g (``resampled``: every
        output slot i − off_g < n_out_g of a non-empty group instead).

        CPU: one task per tile, with the group's values loaded once by ``prologue``.  Stores into
        the pool stop the compiler from hoisting field loads out of the loop, and a field load
        costs about as much as a light body, so this runs several times faster than a loop over
        slots that looks its group up.  GPU (``flat``): one thread per slot."""
        if ti.static(self.flat):
            for i in range(self.capacity):
                g = self.slot_group[i]
                if g >= 0 and self.n[g] > 0:
                    used = self.n[g]
                    if ti.static(resampled):
                        used = self.n_out[g]
                    if i - self.off[g] < used:
                        body(i, g, prologue(g, args), args)
        else:
            self.for_tiles(self.tile_slots, {'resampled': resampled, 'prologue': prologue, 'body': body, 'args': args})

    @ti.func
    def tile_slots(self, t: ti.i32, loop: ti.template()):
        """``for_slots`` over tile t (``loop``: its arguments in a dict, since a template argument's
        tuple cannot hold functions)."""
        g = self.tile_group[t]
        end = self.out_tile_end(t) if ti.static(loop['resampled']) else self.tile_end(t)
        if self.n[g] > 0:
            gv = loop['prologue'](g, loop['args'])
            for i in range(self.tile_start[t], end):
                loop['body'](i, g, gv, loop['args'])

    @ti.func
    def for_tiles(self, body: ti.template(), args: ti.template()):
        """body(t, args) for every tile t (the CPU layout).  With ``split`` > 1, thread k of ``split`` takes
        the tiles of groups k, k + split, … (pools of at least 2·split groups; else tiles k, k + split, …):
        a loop of split·THREAD_SPAN iterations, of which the first of each thread's run does the work,
        because Taichi's CPU range-for gives a thread runs of at least THREAD_SPAN iterations, so a loop
        over a few dozen tiles would run on one thread.  By group where the groups are enough to share
        out: resampling gathers a group's parents from all its tiles, and a thread that finds them in
        the other core's cache waits for them (the kernel profiler, 1.4 preset at 320×256: pass 1 of the
        searching step 1.67–1.69 ms by group, 1.81–1.85 ms with the tiles dealt out one by one).  Each
        tile is still reduced serially, so the results do not depend on the split."""
        if ti.static(self.split > 1 and self.tiles_by_group):
            self.for_groups(self.group_tiles, {'body': body, 'args': args})
        else:
            self.for_split(self.tile_start.shape[0], body, args)

    @ti.func
    def group_tiles(self, g: ti.i32, loop: ti.template()):
        """``for_tiles``' body for the tiles of group g, in order."""
        for t in range(self.gt0[g], self.gt1[g]):
            loop['body'](t, loop['args'])

    @ti.func
    def for_groups(self, body: ti.template(), args: ti.template()):
        """body(g, args) for every group g, split like ``for_tiles`` (thread k: groups k, k + split, …)."""
        self.for_split(self.n.shape[0], body, args)

    @ti.func
    def for_split(self, count: ti.template(), body: ti.template(), args: ti.template()):
        """body(u, args) for u = 0 … count − 1: serial, or with ``split`` > 1 thread k takes u = k, k + split, …
        (the first iteration of each thread's THREAD_SPAN-long run does its share, see ``for_tiles``)."""
        if ti.static(self.split > 1):
            for v in range(self.split * THREAD_SPAN):
                if v % THREAD_SPAN == 0:
                    k = v // THREAD_SPAN
                    for j in range((count - k + self.split - 1) // self.split):
                        body(k + j * self.split, args)
        else:
            ti.loop_config(serialize=self.serial)
            for u in range(count):
                body(u, args)

    @ti.func
    def for_groups_with(self, other: ti.template(), body: ti.template(), args: ti.template(),
                        other_body: ti.template(), other_args: ti.template()):
        """body(g, args) for this pool's groups and other_body(h, other_args) for the groups of ``other`` (a
        second pool), in one loop split like ``for_groups``: thread k takes groups k, k + split, … of each."""
        for v in range(self.split * THREAD_SPAN):
            if v % THREAD_SPAN == 0:
                k = v // THREAD_SPAN
                for j in range((self.n.shape[0] - k + self.split - 1) // self.split):
                    body(k + j * self.split, args)
                for j in range((other.n.shape[0] - k + self.split - 1) // self.split):
                    other_body(k + j * self.split, other_args)

    @ti.func
    def no_group_values(self, g: ti.i32, args: ti.template()):
        """A ``for_slots`` prologue for bodies that need no per-group values."""
        return 0

    # ------------------------------------------------------------ Eqs. 7–10

    @ti.func
    def existence_rates(self, g: ti.i32, args: ti.template()):
        return self.pb[g], self.pd[g]

    @ti.func
    def existence_step(self, i: ti.i32, g: ti.i32, rates: ti.template(), args: ti.template()):
        """Eqs. 7–8 for slot i: E ← [u ≥ P_d] if E = 1, [u < P_b] if E = 0; ``born`` marks 0 → 1."""
        key, b = args
        pb, pd = rates
        u = uniform_at(key, i)
        e0 = self.e[b, i]
        e1 = 0
        if e0 == 1:
            e1 = ti.cast(u >= pd, ti.i32)
        else:
            e1 = ti.cast(u < pb, ti.i32)
        self.born[i] = ti.cast(e0 == 0 and e1 == 1, ti.i32)
        self.e[b, i] = e1

    @ti.func
    def predict_existence(self, seed: ti.u32, frame: ti.i32, b: ti.i32):
        """Step 1, Eqs. 7–8, for every live particle."""
        self.for_slots(False, self.existence_rates, self.existence_step, (key_prefix(seed, frame, S_EXIST), b))

    @ti.func
    def map_entry_draw(self, g: ti.i32, v: ti.f64) -> ti.i32:
        """First entry of group g's proposal list whose cumulative weight exceeds v (binary search)."""
        lo = self.map_off[g]
        hi = lo + self.map_n[g] - 1
        while lo < hi:
            mid = (lo + hi) // 2
            if self.map_cdf[mid] > v:
                hi = mid
            else:
                lo = mid + 1
        return lo

    @ti.func
    def store_counts(self, counts: ti.template()):
        """n ← counts (the host's checked live counts), keeping the previous ones in n_before."""
        ti.loop_config(serialize=True)
        for g in range(self.n.shape[0]):
            self.n_before[g] = self.n[g]
            self.n[g] = counts[g]

    @ti.func
    def first_added_slot(self, g: ti.i32, args: ti.template()) -> ti.i32:
        return self.off[g] + self.n_before[g]

    @ti.func
    def mark_if_added(self, i: ti.i32, g: ti.i32, first: ti.i32, args: ti.template()):
        if i >= first:
            self.born[i] = 2

    @ti.func
    def mark_initial(self):
        """Slots added since n_before (the top-up of Eq. 35) become initial particles (born = 2).  On the
        CPU a loop per group over its added slots alone (usually none)."""
        if ti.static(self.flat):
            self.for_slots(False, self.first_added_slot, self.mark_if_added, ())
        else:
            ti.loop_config(serialize=self.serial)
            for g in range(self.n.shape[0]):
                for i in range(self.first_added_slot(g, ()), self.off[g] + self.n[g]):
                    self.born[i] = 2

    @ti.func
    def copy_state(self, src: ti.i32, j: ti.i32, dst: ti.i32, i: ti.i32):
        """Slot i of buffer dst takes x, vx, y, vy, I, Tp and Seq of slot j in buffer src (E is left to the caller)."""
        self.x[dst, i] = self.x[src, j]
        self.vx[dst, i] = self.vx[src, j]
        self.y[dst, i] = self.y[src, j]
        self.vy[dst, i] = self.vy[src, j]
        self.inten[dst, i] = self.inten[src, j]
        self.tp[dst, i] = self.tp[src, j]
        self.seq[dst, i] = self.seq[src, j]

    @ti.func
    def draw_newborn(self, seed: ti.u32, frame: ti.i32, b: ti.i32, width: ti.i32):
        """Step 2 for newborn (born = 1, E 0 → 1) and initial (born = 2) particles (Eq. 34).

        kind 0: position uniform over [bx0, bx1) × [by0, by1); kind 1: a pixel drawn from the
        group's proposal map plus U(−½, ½) in x and y, and Seq the PP label of that pixel (Eq. 36); with
        an empty map the particle cannot be placed and gets E = 0.  Speed U[0, vmax] in a uniform
        direction, intensity U[imin, imax], Tp = 1; initial particles draw E = [U < μ].
        kind 2 (tracking PFs): a copy of a random E = 1 particle of the same group (E = 0 if
        none is found), propagated afterwards like an existing particle.
        """
        keys = [key_prefix(seed, frame, st) for st in ti.static(BIRTH_STREAMS)]
        self.for_slots(False, self.no_group_values, self.newborn_draw, (keys, b, width))

    @ti.func
    def newborn_draw(self, i: ti.i32, g: ti.i32, _: ti.template(), args: ti.template()):
        """``draw_newborn`` for slot i (newborns are few, so their group's values are loaded here)."""
        keys, b, width = args
        kx, ky, ks, ka, ki, kp, km, kc = keys
        if self.born[i] >= 1:
            k = self.kind[g]
            if k == 2:
                found = -1
                for t in range(COPY_TRIES):
                    u = uniform_at(kc, i * COPY_TRIES + t)
                    j = self.off[g] + ti.min(ti.cast(u * ti.cast(self.n[g], ti.f32), ti.i32), self.n[g] - 1)
                    if found < 0 and self.e[b, j] == 1 and self.born[j] == 0:
                        found = j
                if found >= 0:
                    self.copy_state(b, found, b, i)
                    self.e[b, i] = 1
                else:
                    self.e[b, i] = 0
            elif k == 1 and self.map_n[g] == 0:
                self.e[b, i] = 0
            else:
                ux = uniform_at(kx, i)
                uy = uniform_at(ky, i)
                if k == 0:
                    self.x[b, i] = self.bx0[g] + (self.bx1[g] - self.bx0[g]) * ux
                    self.y[b, i] = self.by0[g] + (self.by1[g] - self.by0[g]) * uy
                else:
                    m = self.map_entry_draw(g, uniform_f64_at(kp, i) * self.map_total[g])
                    p = self.map_pixel[m]
                    self.x[b, i] = ti.cast(p % width, ti.f32) + (ux - ti.f32(0.5))
                    self.y[b, i] = ti.cast(p // width, ti.f32) + (uy - ti.f32(0.5))
                    self.seq[b, i] = self.map_seq[m]
                speed = self.vmax[g] * uniform_at(ks, i)
                angle = ti.f32(TWO_PI) * uniform_at(ka, i)
                self.vx[b, i] = speed * ti.cos(angle)
                self.vy[b, i] = speed * ti.sin(angle)
                self.inten[b, i] = self.imin[g] + (self.imax[g] - self.imin[g]) * uniform_at(ki, i)
                self.tp[b, i] = 1
                if self.born[i] == 2:
                    self.e[b, i] = ti.cast(uniform_at(km, i) < self.mu[g], ti.i32)

    @ti.func
    def propagate(self, seed: ti.u32, frame: ti.i32, b: ti.i32, q1: ti.f32, q2: ti.f32, i_floor: ti.f32,
                  width: ti.i32, height: ti.i32):
        """Step 2 for existing particles (E 1 → 1, and copied newborns of kind 2), Eqs. 9–10: NCV plus
        Cholesky-factored noise of Q (Eq. 46, T = 1), I ← max(I + √q2·n, i_floor), Tp ← Tp + 1.
        A particle whose position leaves the image (x ∉ [−½, W−½)) gets E = 0."""
        c11, c21, c22, sq2 = ncv_noise_factors(q1, q2)
        keys = [key_prefix(seed, frame, st) for st in ti.static(NOISE_STREAMS)]
        self.for_slots(False, self.copies_newborns, self.ncv_step,
                       (keys, (c11, c21, c22, sq2, i_floor), b, width, height))

    @ti.func
    def copies_newborns(self, g: ti.i32, args: ti.template()) -> ti.i32:
        """Whether group g's newborns are copies (kind 2), which are propagated like existing particles."""
        return self.kind[g] == 2

    @ti.func
    def ncv_step(self, i: ti.i32, g: ti.i32, copies: ti.i32, args: ti.template()):
        """``propagate`` for slot i."""
        keys, noise, b, width, height = args
        c11, c21, c22, sq2, i_floor = noise
        w, k, phi = ti.static(self.normal.w, self.normal.k, self.normal.phi)
        if self.e[b, i] == 1 and (self.born[i] == 0 or copies):
            n1, n2 = normal_at(w, k, phi, keys[0], i), normal_at(w, k, phi, keys[1], i)
            n3, n4 = normal_at(w, k, phi, keys[2], i), normal_at(w, k, phi, keys[3], i)
            n5 = normal_at(w, k, phi, keys[4], i)
            x = self.x[b, i] + self.vx[b, i] + c11 * n1
            y = self.y[b, i] + self.vy[b, i] + c11 * n3
            self.x[b, i] = x
            self.y[b, i] = y
            # plain stores: ``field[i] += v`` is Taichi's atomic add, a locked compare-and-swap loop in a
            # parallel CPU task (the split step), though no other thread writes slot i
            self.vx[b, i] = self.vx[b, i] + (c21 * n1 + c22 * n2)
            self.vy[b, i] = self.vy[b, i] + (c21 * n3 + c22 * n4)
            self.inten[b, i] = ti.max(self.inten[b, i] + sq2 * n5, i_floor)
            self.tp[b, i] = self.tp[b, i] + 1
            if x < -0.5 or x >= width - 0.5 or y < -0.5 or y >= height - 0.5:
                self.e[b, i] = 0

    @ti.kernel
    def predict(self, seed: ti.u32, frame: ti.i32, b: ti.i32, counts: ti.types.ndarray(dtype=ti.i32, ndim=1),
                q1: ti.f32, q2: ti.f32, i_floor: ti.f32, width: ti.i32, height: ti.i32):
        """Steps 1–2 in one launch (see ``predict_particles``)."""
        self.predict_particles(seed, frame, b, counts, q1, q2, i_floor, width, height)

    @ti.func
    def predict_particles(self, seed: ti.u32, frame: ti.i32, b: ti.i32, counts: ti.template(), q1: ti.f32,
                          q2: ti.f32, i_floor: ti.f32, width: ti.i32, height: ti.i32):
        """Steps 1–2: existence (Eqs. 7–8), live counts ← ``counts`` with the added slots as initial
        particles (Eq. 35), newborn and initial draws, propagation (Eqs. 9–10)."""
        self.predict_existence(seed, frame, b)
        self.store_counts(counts)
        self.mark_initial()
        self.draw_newborn(seed, frame, b, width)
        self.propagate(seed, frame, b, q1, q2, i_floor, width, height)

    # ------------------------------------------------------------ Eqs. 11–15

    @ti.func
    def log_weights(self, b: ti.i32, psf_sigma: ti.f32, noise_sigma: ti.f32, zp: ti.template()):
        """Step 3, Eq. 15 in the log domain: for E = 1,
        log ω̃ = Σ_{5×5} h(2z − h)/(2σ²) with h = I/(2πΣ²)·exp(−((i−x)² + (j−y)²)/(2Σ²)) (Eq. 14),
        over the in-image pixels of the 5×5 window around (⌊x+½⌋, ⌊y+½⌋); 0 for E = 0.
        The Gaussian is separable, h = a·gx·gy, so Σh² = a²·Σgx²·Σgy²; each axis's five samples
        come from two exponentials by the ratio recurrence of ``psf_samples``.  ``zp``: the frame with a
        zero border of PAD pixels (H + 2·PAD, W + 2·PAD)."""
        inv2s2, norm, inv_var, step = psf_constants(psf_sigma, noise_sigma)
        values = (b, inv2s2, norm, inv_var, step)
        if ti.static(self.flat):
            self.for_slots(False, self.no_group_values, self.store_log_weight, {'values': values, 'zp': zp})
            self.tile_maxima(b, False, ())
        else:  # the tile maxima of step 4 in the same pass (one pass over the pool fewer)
            self.tile_maxima(b, True, {'values': values, 'zp': zp})

    @ti.func
    def store_log_weight(self, i: ti.i32, g: ti.i32, _: ti.template(), args: ti.template()):
        """``log_weights`` for slot i, as a ``for_slots`` body."""
        self.logw[i] = self.log_weight(i, args)

    @ti.func
    def log_weight(self, i: ti.i32, args: ti.template()) -> ti.f32:
        """Eq. 15's log-weight of slot i (0 for E = 0); ``args``: {'values': the constants of
        ``log_weights``, 'zp': the bordered frame} (a dict: a tuple made in a kernel cannot hold an array)."""
        b, inv2s2, norm, inv_var, step = args['values']
        zp = ti.static(args['zp'])
        h, w = ti.static(self.frame_shape)
        lw = ti.f32(0.0)
        if self.e[b, i] == 1:
            x, y = self.x[b, i], self.y[b, i]
            cx = ti.cast(ti.floor(x + 0.5), ti.i32)
            cy = ti.cast(ti.floor(y + 0.5), ti.i32)
            gx = psf_samples(ti.cast(cx - 2, ti.f32) - x, inv2s2, step, cx - 2, w)
            gy = psf_samples(ti.cast(cy - 2, ti.f32) - y, inv2s2, step, cy - 2, h)
            # first window row/column in the padded frame; outside pixels read the zero
            # border (and their g is 0), so the sum needs no branches.  A window that
            # misses the image (g all 0) is clamped to one that does not overflow.
            r0 = ti.min(ti.max(cy, -2), h + 1) + PAD - 2
            c0 = ti.min(ti.max(cx, -2), w + 1) + PAD - 2
            sz = ti.f32(0.0)
            for j in ti.static(range(5)):
                row = ti.f32(0.0)
                for k in ti.static(range(5)):
                    row += gx[k] * zp[r0 + j, c0 + k]
                sz += gy[j] * row
            a = self.inten[b, i] * norm
            lw = (a * sz - ti.f32(0.5) * a * a * gx.dot(gx) * gy.dot(gy)) * inv_var
        return lw

    # ------------------------------------------------------------ Eqs. 16–18, segmented and deterministic

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
    def weigh(self, b: ti.i32, psf_sigma: ti.f32, noise_sigma: ti.f32, best: ti.types.ndarray(dtype=ti.f32, ndim=1),
              z: ti.types.ndarray(dtype=ti.f32, ndim=2)):
        """Steps 3–4 in one launch (see ``weigh_particles``)."""
        self.weigh_particles(b, psf_sigma, noise_sigma, best, z)

    @ti.func
    def weigh_particles(self, b: ti.i32, psf_sigma: ti.f32, noise_sigma: ti.f32, best: ti.template(),
                        z: ti.template()):
        """Steps 3–4 on the normalised frame z (zero-bordered: H + 2·PAD, W + 2·PAD): log-weights
        (Eq. 15), their normalisation, and each group's largest E = 1 log-weight into ``best``."""
        self.log_weights(b, psf_sigma, noise_sigma, z)
        self.normalise_weights()
        ti.loop_config(serialize=True)
        for g in range(best.shape[0]):
            best[g] = self.gmax_e[g]

    @ti.func
    def out_tile_end(self, t: ti.i32) -> ti.i32:
        """End of tile t's output slots (the first n_out of its group's slab)."""
        g = self.tile_group[t]
        return ti.min(self.tile_start[t] + TILE, self.off[g] + self.n_out[g])

    @ti.func
    def first_slot_above(self, g: ti.i32, v: ti.f64) -> ti.i32:
        """Eq. 18: the first live slot of group g whose upper edge Σ_{j ≤ slot} w_j (cum, Eq. 17) exceeds v
        (the last one if none)."""
        lo, hi = self.off[g], self.off[g] + self.n[g] - 1
        while lo < hi:
            mid = (lo + hi) // 2
            if self.cum[mid] > v:
                hi = mid
            else:
                lo = mid + 1
        return lo

    @ti.func
    def tile_spacings(self, seed: ti.u32, frame: ti.i32):
        """Multinomial resampling, part 1: Exp(1) spacings (f64, by the ziggurat: no logarithm for 99 %
        of them) over each group's output slots, summed within tiles (spc), with the tile totals."""
        self.for_tiles(self.tile_spacing_sums, key_prefix(seed, frame, S_RESAMPLE))

    @ti.func
    def tile_spacing_sums(self, t: ti.i32, key: ti.template()):
        """``tile_spacings`` for tile t."""
        w, k, f = ti.static(self.exponential.w, self.exponential.k, self.exponential.f)
        g = self.tile_group[t]
        s = ti.cast(0.0, ti.f64)
        if self.n[g] > 0:
            for i in range(self.tile_start[t], self.out_tile_end(t)):
                s += exponential_at(w, k, f, key, i)
                self.spc[i] = s
        self.tile_spc[t] = s

    @ti.func
    def group_spacings(self, seed: ti.u32, frame: ti.i32):
        """Multinomial resampling, part 2: exclusive tile prefixes of the spacings and each group's
        total, which includes one more spacing (the (n_out + 1)-th, keyed on the group)."""
        key = key_prefix(seed, frame, S_RESAMPLE_END)
        ti.loop_config(serialize=self.serial)
        for g in range(self.off.shape[0]):
            self.group_spacing(g, key)

    @ti.func
    def group_spacing(self, g: ti.i32, key: ti.u32):
        """``group_spacings`` for group g (``key``: the S_RESAMPLE_END prefix)."""
        w, k, f = ti.static(self.exponential.w, self.exponential.k, self.exponential.f)
        self.gspc[g] = self.exclusive_tile_prefix(g, self.tile_spc, self.tile_spc_prefix) + exponential_at(w, k, f, key, g)

    @ti.func
    def draw_parents(self, systematic: ti.template(), seed: ti.u32, frame: ti.i32):
        """Eq. 18 for sorted positions: output slot m < n_out_g of group g takes the parent whose
        cumulative-weight interval holds u_m·Σw.  Multinomial: u_m = S_m / S_{n_out+1}, S the running
        sum of exponential spacings, which are the order statistics of n_out i.i.d. U(0, 1) (the
        paper's independent uniforms, sorted); systematic: u_m = (m + u0_g)/n_out_g, u0_g keyed on
        (seed, frame, S_SYSTEMATIC, g).  Sorted u lets each tile binary-search its first parents and
        walk forward from there.  (Gathering each tile's outputs right after its walk was slower than
        a pass of its own.)"""
        self.for_tiles(self.tile_parents, {'systematic': systematic, 'key': key_prefix(seed, frame, S_SYSTEMATIC)})

    @ti.func
    def tile_parents(self, t: ti.i32, loop: ti.template()):
        """``draw_parents`` for tile t's output slots."""
        g = self.tile_group[t]
        i0, i1, n = self.tile_start[t], self.out_tile_end(t), self.n[g]
        if n > 0 and i0 < i1:
            off, total = self.off[g], self.gtotal[g]
            last = off + n - 1
            u0, scale, base = ti.cast(0.0, ti.f64), ti.cast(0.0, ti.f64), ti.cast(0.0, ti.f64)
            if ti.static(loop['systematic']):  # one uniform per group
                u0, scale = uniform_f64_at(loop['key'], g), ti.cast(self.n_out[g], ti.f64)
            else:
                base, scale = self.tile_spc_prefix[t], self.gspc[g]
            to_weight = total / scale  # one division per tile, not per output
            for i in range(i0, i1):  # the positions v_m = u_m·Σw, into spc
                if ti.static(loop['systematic']):
                    self.spc[i] = (ti.cast(i - off, ti.f64) + u0) * to_weight
                else:
                    self.spc[i] = (base + self.spc[i]) * to_weight
            self.merge_parents(g, i0, i1, last)

    @ti.func
    def merge_parents(self, g: ti.i32, i0: ti.i32, i1: ti.i32, last: ti.i32):
        """Eq. 18 for the sorted positions spc[i0:i1] of group g: parent[i] = the first slot above spc[i]
        (at most ``last``).  A merge of the positions with the upper edges takes one step per output
        or per parent passed, with no data-dependent branch (offspring counts are random).  The
        outputs are cut into WALKS runs whose walks advance in the same loop: each step depends on
        the one before, so interleaved walks keep the core busy while one waits for its loads."""
        lo, end, p = ti.Vector([0] * WALKS), ti.Vector([0] * WALKS), ti.Vector([0] * WALKS)
        common = i1 - i0 + last  # steps every walk needs (the minimum over walks)
        for k in ti.static(range(WALKS)):
            lo[k] = i0 + (i1 - i0) * k // WALKS
            end[k] = i0 + (i1 - i0) * (k + 1) // WALKS
            p[k] = last
            if lo[k] < end[k]:
                p[k] = self.first_slot_above(g, self.spc[lo[k]])
                steps = end[k] - lo[k] + self.first_slot_above(g, self.spc[end[k] - 1]) - p[k]
                common = ti.min(common, steps)
            else:
                common = 0
        for _ in range(common):
            for k in ti.static(range(WALKS)):
                self.merge_step(lo, p, k, last)
        for k in ti.static(range(WALKS)):
            while lo[k] < end[k]:
                self.merge_step(lo, p, k, last)

    @ti.func
    def merge_step(self, i: ti.template(), p: ti.template(), k: ti.template(), last: ti.i32):
        """One step of walk k: output i[k] takes parent p[k] (final once i[k] moves on), then either
        the output or the parent advances."""
        advance = ti.cast(p[k] < last, ti.i32) & ti.cast(self.cum[p[k]] <= self.spc[i[k]], ti.i32)
        self.parent[i[k]] = p[k]
        i[k] += 1 - advance
        p[k] += advance

    @ti.kernel
    def set_counts(self, counts: ti.types.ndarray(dtype=ti.i32, ndim=1)):
        """Live counts n ← ``counts`` from the host, in one small serial launch."""
        self.store_counts(counts)

    @ti.func
    def set_out_counts(self, counts: ti.template()):
        """n_out ← counts (0 for an empty group)."""
        ti.loop_config(serialize=True)
        for g in range(counts.shape[0]):
            self.set_out_count(g, counts)

    @ti.func
    def set_out_count(self, g: ti.i32, counts: ti.template()):
        """``set_out_counts`` for group g."""
        self.n_out[g] = ti.select(self.n[g] > 0, counts[g], 0)

    @ti.func
    def commit_counts(self):
        """After gathering: every group's live count becomes its resampled count."""
        ti.loop_config(serialize=True)
        for g in range(self.n.shape[0]):
            self.n[g] = self.n_out[g]

    @ti.kernel
    def resample(self, seed: ti.u32, frame: ti.i32, b: ti.i32, counts: ti.types.ndarray(dtype=ti.i32, ndim=1),
                 systematic: ti.template()):
        """Step 5 in one launch (see ``resample_particles``)."""
        self.resample_particles(seed, frame, b, counts, systematic)

    @ti.kernel
    def step(self, seed: ti.u32, frame: ti.i32, b: ti.i32, counts: ti.types.ndarray(dtype=ti.i32, ndim=1),
             q1: ti.f32, q2: ti.f32, i_floor: ti.f32, width: ti.i32, height: ti.i32, psf_sigma: ti.f32,
             noise_sigma: ti.f32, best: ti.types.ndarray(dtype=ti.f32, ndim=1),
             z: ti.types.ndarray(dtype=ti.f32, ndim=2), n_out: ti.types.ndarray(dtype=ti.i32, ndim=1),
             systematic: ti.template(), seq: ti.types.ndarray(dtype=ti.i32, ndim=1), read_seq: ti.template(),
             fused: ti.template()):
        """Steps 1–5 in one launch, for a filter with nothing to do between them (a launch costs
        tens of µs on the CPU backend); with ``read_seq`` also the resampled particles' Seq in state
        order into ``seq`` (:meth:`read_seq`, which the searching PFs need next); ``fused``: as
        :meth:`fused_step` (CPU, tile loops split, no kind 2 group)."""
        if ti.static(fused):
            self.fused_step(seed, frame, b, counts, q1, q2, i_floor, width, height, psf_sigma, noise_sigma, best, z,
                            n_out, systematic)
        else:
            self.predict_particles(seed, frame, b, counts, q1, q2, i_floor, width, height)
            self.weigh_particles(b, psf_sigma, noise_sigma, best, z)
            self.resample_particles(seed, frame, b, n_out, systematic)
        if ti.static(read_seq):
            self.seq_in_state_order(1 - b, seq)

    @ti.func
    def fused_step(self, seed: ti.u32, frame: ti.i32, b: ti.i32, counts: ti.template(), q1: ti.f32, q2: ti.f32,
                   i_floor: ti.f32, width: ti.i32, height: ti.i32, psf_sigma: ti.f32, noise_sigma: ti.f32,
                   best: ti.template(), z: ti.template(), n_out: ti.template(), systematic: ti.template()):
        """Steps 1–5 for a pool without copied newborns (kind 2) whose tile loops are split over the
        threads: three passes over the tiles instead of eight, since each parallel pass costs a start
        of Taichi's thread pool (about 50 µs on the 2-core VM).  Pass 1: existence, top-up, newborn
        draws, propagation, log-weight and tile maxima, each a loop over the tile's slots (no slot reads
        another: only kind 2 copies do; one loop per stage ran pass 1 in 1.80 ms, one loop doing all
        stages slot by slot in 2.0 ms: the kernel profiler, 1.4 preset at 320×256); pass 2: each tile's
        cumulative weights and spacings; pass 3: each tile's parents, then the gather of its outputs.
        Serial steps between them combine the tiles of each group.  The same operations on the same
        slots as the unfused step, so the same bits.  (``step_pair``'s single pass, ``stepped_group``, would
        also do here with whole groups per thread, but it adds about 12 s to the kernel's first compile, for the
        frames without an active track.)"""
        self.store_counts(counts)
        values = (seed, frame, b, q1, q2, i_floor, width, height, psf_sigma, noise_sigma)
        if ti.static(self.tiles_by_group):
            self.for_groups(self.predicted_group, {'values': values, 'z': z})
        else:
            self.for_tiles(self.predicted_tile, {'values': values, 'z': z})
        self.group_maxima()
        ti.loop_config(serialize=True)
        for g in range(best.shape[0]):
            best[g] = self.gmax_e[g]
        self.set_out_counts(n_out)
        self.for_tiles(self.weighted_tile, {'systematic': systematic, 'key': key_prefix(seed, frame, S_RESAMPLE)})
        self.group_prefix()
        if ti.static(not systematic):
            self.group_spacings(seed, frame)
        self.for_tiles(self.resampled_tile, {'systematic': systematic, 'b': b,
                                             'key': key_prefix(seed, frame, S_SYSTEMATIC)})
        self.commit_counts()

    @ti.kernel
    def step_pair(self, other: ti.template(), seed: ti.u32, frame: ti.i32, b: ti.i32,
                  counts: ti.types.ndarray(dtype=ti.i32, ndim=1), q1: ti.f32, q2: ti.f32, i_floor: ti.f32,
                  width: ti.i32, height: ti.i32, psf_sigma: ti.f32, noise_sigma: ti.f32,
                  best: ti.types.ndarray(dtype=ti.f32, ndim=1), z: ti.types.ndarray(dtype=ti.f32, ndim=2),
                  n_out: ti.types.ndarray(dtype=ti.i32, ndim=1), systematic: ti.template(),
                  seq: ti.types.ndarray(dtype=ti.i32, ndim=1), read_seq: ti.template(), other_seed: ti.u32,
                  other_b: ti.i32, other_counts: ti.types.ndarray(dtype=ti.i32, ndim=1),
                  other_best: ti.types.ndarray(dtype=ti.f32, ndim=1),
                  other_n_out: ti.types.ndarray(dtype=ti.i32, ndim=1),
                  moments: ti.types.ndarray(dtype=ti.f64, ndim=2)):
        """``step`` (fused, whole groups per thread) of this pool and of ``other``, a second pool on the
        same frame z with the same motion and PSF constants (the tracking PFs beside the searching PFs),
        in the same pass (``stepped_group`` for each group of either pool), so the threads share both pools'
        work and the serial pool ``other`` no longer leaves a core idle; with ``other``'s ``estimates`` into
        ``moments``.  Each group is stepped as ``fused_step`` steps it, so both pools get the bits of their own
        ``step``.  (One pass instead of three: step_with of 6 × 8000 + 32 × 500 particles at 320×256
        5.2–5.4 → 4.7–4.8 ms, in one process; the first compile of an ``SGDSPF`` configuration took 62 s before,
        75–91 s after, single runs without the offline cache.)"""
        self.store_counts(counts)
        other.store_counts(other_counts)
        values = (seed, frame, b, q1, q2, i_floor, width, height, psf_sigma, noise_sigma)
        other_values = (other_seed, frame, other_b, q1, q2, i_floor, width, height, psf_sigma, noise_sigma)
        self.for_groups_with(other, self.stepped_group,
                             {'values': values, 'z': z, 'best': best, 'n_out': n_out, 'systematic': systematic,
                              'resampled': self.resampled_tile, 'moments': ()},
                             other.stepped_group,
                             {'values': other_values, 'z': z, 'best': other_best, 'n_out': other_n_out,
                              'systematic': systematic, 'resampled': other.resampled_moments_tile, 'moments': moments})
        if ti.static(read_seq):
            self.seq_in_state_order(1 - b, seq)

    @ti.func
    def stepped_group(self, g: ti.i32, loop: ti.template()):
        """``fused_step``'s three passes for group g alone, by the thread that owns the group (whole groups per thread): pass 1
        (``predicted_group``), its maxima, pass 2 (``weighted_tile``), its prefix and spacing total, pass 3
        (``loop['resampled']``) and its moment sums, with no barrier between them, since no stage reads another
        group.  One start of the thread pool a step instead of three (about 60 µs each on the 2-core VM), and
        the group's particles stay in the core's cache from stage to stage; the same operations in the same
        order as ``fused_step``, so the same bits.  ``loop``: {'values', 'z'} as ``predicted_group`` takes them,
        'best' and 'n_out' as ``fused_step``'s, 'systematic', 'resampled' (``resampled_tile`` or
        ``resampled_moments_tile``) and 'moments' (``estimates``' output, or () for none)."""
        seed, frame, b = loop['values'][0], loop['values'][1], loop['values'][2]
        self.predicted_group(g, loop)
        self.group_maximum(g)
        loop['best'][g] = self.gmax_e[g]
        self.set_out_count(g, loop['n_out'])
        key = key_prefix(seed, frame, S_RESAMPLE)  # (a dict assigned to a name would turn its values into variables)
        for t in range(self.gt0[g], self.gt1[g]):
            self.weighted_tile(t, {'systematic': loop['systematic'], 'key': key})
        self.group_cumulative(g)
        if ti.static(not loop['systematic']):
            self.group_spacing(g, key_prefix(seed, frame, S_RESAMPLE_END))
        key = key_prefix(seed, frame, S_SYSTEMATIC)
        for t in range(self.gt0[g], self.gt1[g]):
            loop['resampled'](t, {'systematic': loop['systematic'], 'b': b, 'key': key})
        if ti.static(not isinstance(loop['moments'], tuple)):
            self.group_moment(g, loop['moments'])
        self.n[g] = self.n_out[g]

    @ti.func
    def resampled_moments_tile(self, t: ti.i32, loop: ti.template()):
        """``resampled_tile``, then the tile's ``estimates`` sums over its new particles."""
        self.resampled_tile(t, loop)
        self.moment_sums(t, 1 - loop['b'], self.out_tile_end(t))

    @ti.func
    def predicted_tile(self, t: ti.i32, loop: ti.template()):
        """``fused_step``'s pass 1 over tile t (tiles dealt out one by one: no copying group), see
        ``predicted_slots`` and ``weighed_tile``."""
        g = self.tile_group[t]
        if self.n[g] > 0:
            self.predicted_slots(g, self.tile_start[t], self.tile_end(t), loop)
        self.weighed_tile(t, loop)

    @ti.func
    def predicted_group(self, g: ti.i32, loop: ti.template()):
        """``fused_step``'s pass 1 over group g (whole groups per thread), see ``predicted_slots`` and
        ``weighed_tile``.  Each stage covers the whole group before the next, as in the unfused step, so
        copies (kind 2) find the group's particles as they would there."""
        if self.n[g] > 0:
            self.predicted_slots(g, self.off[g], self.off[g] + self.n[g], loop)
        for t in range(self.gt0[g], self.gt1[g]):
            self.weighed_tile(t, loop)

    @ti.func
    def predicted_slots(self, g: ti.i32, i0: ti.i32, i1: ti.i32, loop: ti.template()):
        """Steps 1–2 for slots [i0, i1) of group g, a loop per stage: Eqs. 7–8 for the slots live before
        the top-up (the added ones become initial particles), Eq. 34's draws, Eqs. 9–10."""
        seed, frame, b, q1, q2, i_floor, width, height, psf_sigma, noise_sigma = loop['values']
        # the keys and constants of each stage's loop, per call (a few hashes; made once before the
        # parallel loop instead, the pass took as long)
        rates = self.existence_rates(g, ())
        first_added = self.first_added_slot(g, ())
        exist = (key_prefix(seed, frame, S_EXIST), b)
        birth = ([key_prefix(seed, frame, st) for st in ti.static(BIRTH_STREAMS)], b, width)
        c11, c21, c22, sq2 = ncv_noise_factors(q1, q2)
        noise = ([key_prefix(seed, frame, st) for st in ti.static(NOISE_STREAMS)], (c11, c21, c22, sq2, i_floor),
                 b, width, height)
        copies = self.copies_newborns(g, ())
        for i in range(i0, i1):
            if i < first_added:
                self.existence_step(i, g, rates, exist)
            else:
                self.born[i] = 2
        for i in range(i0, i1):
            self.newborn_draw(i, g, 0, birth)
        for i in range(i0, i1):
            self.ncv_step(i, g, copies, noise)

    @ti.func
    def weighed_tile(self, t: ti.i32, loop: ti.template()):
        """Steps 3–4a for tile t: Eq. 15's log-weights and the tile maxima."""
        seed, frame, b, q1, q2, i_floor, width, height, psf_sigma, noise_sigma = loop['values']
        inv2s2, norm, inv_var, step = psf_constants(psf_sigma, noise_sigma)
        self.tile_maximum(t, {'b': b, 'weigh': True,
                              'args': {'values': (b, inv2s2, norm, inv_var, step), 'zp': loop['z']}})

    @ti.func
    def weighted_tile(self, t: ti.i32, loop: ti.template()):
        """``fused_step``'s pass 2 over tile t: Eq. 17 within the tile, and (multinomial) its spacings."""
        self.tile_cumulative_sum(t, ())
        if ti.static(not loop['systematic']):
            self.tile_spacing_sums(t, loop['key'])

    @ti.func
    def resampled_tile(self, t: ti.i32, loop: ti.template()):
        """``fused_step``'s pass 3 over tile t: Eq. 18's parents of its output slots, then their states."""
        self.tile_parents(t, loop)
        self.tile_slots(t, {'resampled': True, 'prologue': self.no_group_values, 'body': self.take_parent,
                            'args': loop['b']})

    @ti.func
    def resample_particles(self, seed: ti.u32, frame: ti.i32, b: ti.i32, counts: ti.template(),
                           systematic: ti.template()):
        """Step 5 (Eqs. 17–18): each group draws ``counts[g]`` parents from buffer b and buffer 1 − b
        receives them; live counts become ``counts``."""
        self.set_out_counts(counts)
        if ti.static(not systematic):
            self.tile_spacings(seed, frame)
            self.group_spacings(seed, frame)
        self.draw_parents(systematic, seed, frame)
        self.gather(b)
        self.commit_counts()

    @ti.kernel
    def write_slots(self, b: ti.i32, slots: ti.types.ndarray(dtype=ti.i32, ndim=1),
                    floats: ti.types.ndarray(dtype=ti.f32, ndim=2), ints: ti.types.ndarray(dtype=ti.i32, ndim=2),
                    counts: ti.types.ndarray(dtype=ti.i32, ndim=1)):
        """Host particle states into ``slots`` of buffer b (rows x, vx, y, vy, I of ``floats`` and E, Tp,
        Seq of ``ints``), and the live counts, in one launch for every group.  (A launch costs about
        20 µs per array argument here, so the states travel as two arrays, not eight.)"""
        ti.loop_config(serialize=self.serial)
        for k in range(slots.shape[0]):
            i = slots[k]
            self.x[b, i], self.vx[b, i], self.y[b, i] = floats[0, k], floats[1, k], floats[2, k]
            self.vy[b, i], self.inten[b, i] = floats[3, k], floats[4, k]
            self.e[b, i], self.tp[b, i], self.seq[b, i] = ints[0, k], ints[1, k], ints[2, k]
        self.store_counts(counts)

    @ti.kernel
    def keep_particles(self, b: ti.i32, keep: ti.types.ndarray(dtype=ti.i8, ndim=1)):
        """Remove particles in place: ``keep[k]`` for the k-th live particle in group-then-slot order
        (the host's state order)."""
        self.state_starts()
        self.compact(b, keep)

    @ti.func
    def compact(self, b: ti.i32, keep: ti.template()):
        """Each group's particles with keep[s] ≠ 0 (s: state order, after ``state_starts``) move to
        the front of its slab in order and its live count becomes their number (one pass per group,
        groups in parallel)."""
        ti.loop_config(serialize=self.serial)
        for g in range(self.n.shape[0]):
            j = self.off[g]
            for i in range(self.off[g], self.off[g] + self.n[g]):
                if keep[self.state_start[g] + i - self.off[g]] != 0:
                    if j != i:
                        self.copy_state(b, i, b, j)
                        self.e[b, j] = self.e[b, i]
                    j += 1
            self.n[g] = j - self.off[g]

    @ti.kernel
    def read_slots(self, b: ti.i32, slots: ti.types.ndarray(dtype=ti.i32, ndim=1),
                   floats: ti.types.ndarray(dtype=ti.f32, ndim=2), ints: ti.types.ndarray(dtype=ti.i32, ndim=2)):
        """The states of ``slots`` in buffer b to the host: rows x, vx, y, vy, I and log-weight of
        ``floats``, E, Tp and Seq of ``ints``, in one launch."""
        ti.loop_config(serialize=self.serial)
        for k in range(slots.shape[0]):
            i = slots[k]
            floats[0, k], floats[1, k], floats[2, k] = self.x[b, i], self.vx[b, i], self.y[b, i]
            floats[3, k], floats[4, k], floats[5, k] = self.vy[b, i], self.inten[b, i], self.logw[i]
            ints[0, k], ints[1, k], ints[2, k] = self.e[b, i], self.tp[b, i], self.seq[b, i]

    @ti.func
    def gather(self, src: ti.i32):
        """Copy each output slot's parent state from buffer src into buffer 1 − src; weights reset (1/L)."""
        self.for_slots(True, self.no_group_values, self.take_parent, src)

    @ti.func
    def take_parent(self, i: ti.i32, g: ti.i32, _: ti.template(), src: ti.template()):
        """``gather`` for output slot i."""
        p = self.parent[i]
        self.copy_state(src, p, 1 - src, i)
        self.e[1 - src, i] = self.e[src, p]
        self.logw[i] = 0.0

    # ------------------------------------------------------------ Eq. 19 and spreads

    @ti.func
    def tile_sums(self, b: ti.i32):
        """Per tile (serially, in slot order): the sums behind Eq. 19, P(E), mean Tp and the covariances of
        all particles and of the E = 1 particles."""
        self.for_tiles(self.tile_moment_sums, b)

    @ti.func
    def tile_moment_sums(self, t: ti.i32, b: ti.template()):
        """``tile_sums`` for tile t."""
        self.moment_sums(t, b, self.tile_end(t))

    @ti.func
    def moment_sums(self, t: ti.i32, b: ti.i32, end: ti.i32):
        """``tile_sums`` for the slots of tile t before ``end``, in buffer b."""
        acc = ti.Vector([0.0] * N_MOMENTS, dt=ti.f64)
        for i in range(self.tile_start[t], end):
            e = ti.cast(self.e[b, i], ti.f64)
            x = ti.cast(self.x[b, i], ti.f64)
            y = ti.cast(self.y[b, i], ti.f64)
            acc += ti.Vector([1.0, e, e * x, e * ti.cast(self.vx[b, i], ti.f64), e * y,
                              e * ti.cast(self.vy[b, i], ti.f64), e * ti.cast(self.inten[b, i], ti.f64),
                              ti.cast(self.tp[b, i], ti.f64), x, y, x * x, y * y, x * y,
                              e * x * x, e * y * y, e * x * y], dt=ti.f64)
        for k in ti.static(range(N_MOMENTS)):
            self.tile_moments[t, k] = acc[k]

    @ti.kernel
    def estimates(self, b: ti.i32, moments: ti.types.ndarray(dtype=ti.f64, ndim=2)):
        """Per group, the tile sums added in tile order into ``moments`` (G, N_MOMENTS)."""
        self.tile_sums(b)
        self.group_moments(moments)

    @ti.func
    def group_moments(self, moments: ti.template()):
        """``estimates``' second part: each group's tile sums, added in tile order."""
        ti.loop_config(serialize=self.serial)
        for g in range(self.off.shape[0]):
            self.group_moment(g, moments)

    @ti.func
    def group_moment(self, g: ti.i32, moments: ti.template()):
        """``group_moments`` for group g."""
        for k in ti.static(range(N_MOMENTS)):
            s = ti.cast(0.0, ti.f64)
            for t in range(self.gt0[g], self.gt1[g]):
                s += self.tile_moments[t, k]
            moments[g, k] = s

    @ti.kernel
    def load_map(self, off: ti.types.ndarray(dtype=ti.i32, ndim=1), count: ti.types.ndarray(dtype=ti.i32, ndim=1),
                 total: ti.types.ndarray(dtype=ti.f64, ndim=1), pixel: ti.types.ndarray(dtype=ti.i32, ndim=1),
                 seq: ti.types.ndarray(dtype=ti.i32, ndim=1), cdf: ti.types.ndarray(dtype=ti.f64, ndim=1)):
        """The groups' proposal maps (pixel lists with their PP labels and f64 cumulative weights), in one launch."""
        ti.loop_config(serialize=True)
        for g in range(off.shape[0]):
            self.map_off[g] = off[g]
            self.map_n[g] = count[g]
            self.map_total[g] = total[g]
        ti.loop_config(serialize=self.serial)
        for k in range(pixel.shape[0]):
            self.map_pixel[k] = pixel[k]
            self.map_seq[k] = seq[k]
            self.map_cdf[k] = cdf[k]
