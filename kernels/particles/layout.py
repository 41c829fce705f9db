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

This module: the pool's fields, its tiles, the loop helpers every stage runs on (``for_slots``,
``for_tiles``, ``for_groups``, ``for_split``), and the constants shared by the kernels and their NumPy twin
(tile size, frame border, random stream ids, ``moments`` columns, the particle state's names).
"""
import math

import taichi as ti

from ..loops import THREAD_SPAN
from ..rng import ExponentialTables, NormalTables
from ..models.likelihood import PAD  # noqa: F401 (re-exported) the likelihood window's zero border

TILE = 1024
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

# per-group columns of ``moments`` (f64): the sums of Eq. 19 (the first N_MOMENTS), then the last weigh's largest
# E = 1 log-weight (M_BEST); ``estimates`` fills all N_ESTIMATES
M_N, M_E, M_EX, M_EVX, M_EY, M_EVY, M_EI, M_TP, M_X, M_Y, M_XX, M_YY, M_XY, M_EXX, M_EYY, M_EXY = range(16)
N_MOMENTS = 16
M_BEST = N_MOMENTS
N_ESTIMATES = N_MOMENTS + 1

# the pool's constants (``LayoutMixin.constants``), set once per pool: the motion noise of Eq. 46, the intensity floor
# (Eq. 10), the PSF spread Σ (Eq. 14) and the noise σ (Eq. 15)
C_Q1, C_Q2, C_I_FLOOR, C_PSF_SIGMA, C_NOISE_SIGMA = range(5)
N_CONSTANTS = 5

FLOAT_STATE, INT_STATE = ("x", "vx", "y", "vy", "inten"), ("e", "tp", "seq")
STATE = FLOAT_STATE + INT_STATE  # a particle's state, in the order of write_slots/read_slots rows


@ti.func
def first_above(values: ti.template(), lo: ti.i32, hi: ti.i32, v: ti.f64) -> ti.i32:
    """The first index k in [lo, hi] with values[k] > v (hi if none), for ``values`` non-decreasing there: a binary
    search (the inverse-CDF draws of Eqs. 18 and 34)."""
    while lo < hi:
        mid = (lo + hi) // 2
        if values[mid] > v:
            hi = mid
        else:
            lo = mid + 1
    return lo


@ti.data_oriented
class LayoutMixin:
    """The pool's fields (structure of arrays, two buffers), its tiles and the loops over them."""

    def __init__(self, capacity: int, n_groups: int, n_tiles: int, frame_shape, map_capacity: int, serial: bool,
                 flat: bool, split: int = 1):
        c, g = capacity, n_groups
        self.capacity, self.serial, self.flat, self.split = capacity, serial, flat, split
        # frame_shape is not kept: the kernels read the frame's size from frame_hw at run time, so that a pool whose
        # fields do not grow with the frame compiles once for every size (populations sizes pixel_key by it)
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
        self.best_e = f32(g)  # gmax_e of the last weigh (``estimates``' M_BEST column)
        self.constants, self.seed_key = f32(N_CONSTANTS), ti.field(ti.u32, shape=1)  # C_* columns; the random key
        self.frame_hw = i32(2)  # (H, W), px: a field, so that a pool whose fields do not grow with the frame (the
        # tracking PFs') compiles its kernels once for every frame size
        self.gt0, self.gt1, self.gspc = i32(g), i32(g), f64(g)
        self.tile_start, self.tile_group = i32(n_tiles), i32(n_tiles)
        self.tile_max, self.tile_max_e, self.tile_total, self.tile_prefix = f32(n_tiles), f32(n_tiles), \
            f64(n_tiles), f64(n_tiles)
        self.tile_spc, self.tile_spc_prefix = f64(n_tiles), f64(n_tiles)
        self.tile_moments = f64(n_tiles, N_MOMENTS)
        self.map_pixel, self.map_seq, self.map_cdf = i32(map_capacity), i32(map_capacity), f64(map_capacity)
        self.map_off, self.map_n, self.map_total = i32(g), i32(g), f64(g)
        self.normal, self.exponential = NormalTables.shared(), ExponentialTables.shared()

    @ti.func
    def step_values(self, frame: ti.i32, b: ti.i32):
        """The values every stage of a step reads, as the stages take them: (seed, frame, b, q1, q2, I_floor, W, H,
        Σ, σ), the pool's ``constants``, ``seed_key`` and ``frame_hw`` (W and H, px) with the frame index and the
        current buffer b."""
        h, w = self.frame_hw[0], self.frame_hw[1]
        c = ti.static(self.constants)
        return (self.seed_key[0], frame, b, c[C_Q1], c[C_Q2], c[C_I_FLOOR], w, h, c[C_PSF_SIGMA],
                c[C_NOISE_SIGMA])

    @ti.func
    def tile_end(self, t: ti.i32) -> ti.i32:
        g = self.tile_group[t]
        return ti.min(self.tile_start[t] + TILE, self.off[g] + self.n[g])

    @ti.func
    def out_tile_end(self, t: ti.i32) -> ti.i32:
        """End of tile t's output slots (the first n_out of its group's slab)."""
        g = self.tile_group[t]
        return ti.min(self.tile_start[t] + TILE, self.off[g] + self.n_out[g])

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
        second pool), in one loop split like ``for_groups``: thread k takes groups k, k + split, … of each (split 1:
        one thread, serial pools)."""
        ti.loop_config(serialize=self.split == 1)
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
