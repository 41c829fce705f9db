"""Particle-population bookkeeping of SGDS-PF's searching PF (Eqs. 36–38) on the particle pool.

A particle population (PP) is the set of a block's particles that share a Seq (Eq. 36).  The PPs are
numbered (block, then Seq) with Eq. 37's quotas by the host, or on the device at the end of the step
(``population_numbers``); these kernels do the per-particle work on the pool's own fields, so the particles'
states never go to the host:

* :meth:`PopulationKernels.eliminate`: Eq. 37's spread-out random elimination of ``take`` of a
  PP's particles, and Eq. 38's sums over the survivors;
* :meth:`PopulationKernels.hand_over`: drops whole PPs (handed over, or already tracked), writes
  the index image P_pp and compacts the pool;
* :meth:`PopulationKernels.eliminate_and_hand_over`: both in one launch, with Eq. 38's potential-target
  test deciding which PPs are handed over or dropped, and ``eliminate_and_hand_over_numbered`` for PPs numbered on
  the device (the tracker's path: no host round trip between them, no particle's Seq on the host).

Particles are addressed in *state order* (group, then slot), as ``ParticlePool.state`` lists
them.  A mixin over the ``ParticleKernels`` fields, combined with them in :class:`SearchingKernels` (the
kernels of ``tbd_taichi.methods.sgds.searching_pool.SearchingPool``); the NumPy twin is
``tbd_taichi.numpy_kernels.populations``.
"""
import taichi as ti

from .loops import size_class
from .particles import ParticleKernels
from .population_numbers import NumberingKernels

# columns of eliminate's per-PP sums over the surviving particles (Eq. 38), f64
P_KEPT, P_KEPT_E, P_TP, P_X, P_Y = range(5)
N_PP_SUMS = 5
RULE_TRACKED = 5  # eliminate_and_hand_over's ``rule``: T_PTp, T_PE, r², most, T, then the T tracked (x, y)
I32_1D, I32_2D = ti.types.ndarray(dtype=ti.i32, ndim=1), ti.types.ndarray(dtype=ti.i32, ndim=2)
F64_1D, F64_2D = ti.types.ndarray(dtype=ti.f64, ndim=1), ti.types.ndarray(dtype=ti.f64, ndim=2)
F32_2D = ti.types.ndarray(dtype=ti.f32, ndim=2)


PIXEL_CLASS_FLOOR = 1 << 19  # entries: every frame up to 724 × 724 px (640 × 512 too) shares the tables' class


def pixel_class(frame_shape) -> int:
    """Entries of a per-pixel table for frames of ``frame_shape`` (H, W): their pixels rounded up to a power of
    two, at least PIXEL_CLASS_FLOOR (12 MiB of the searching pool's tables), so that frames of one class share the
    table's shape, and with it the compiled kernels (the kernels read the frame's size from ``frame_hw``; the
    tables are one-dimensional, indexed y·W + x, so no stride is wasted)."""
    return max(PIXEL_CLASS_FLOOR, size_class(int(frame_shape[0]) * int(frame_shape[1])))


@ti.data_oriented
class PopulationKernels:
    """Eqs. 37–38 over the pool; needs the ``ParticleKernels`` fields and :meth:`population_fields`."""

    def population_fields(self, capacity: int, frame_shape):
        """Scratch kept between eliminate and hand_over: per state index the PP and keep flag, per PP
        its size, quota and running remainder, per pixel the index image's precedence (``pixel_class`` entries,
        pixel y·W + x)."""
        self.state_pp, self.state_keep = ti.field(ti.i32, capacity), ti.field(ti.i8, capacity)
        self.pp_size, self.pp_take, self.pp_acc = ti.field(ti.i32, capacity), ti.field(ti.i32, capacity), \
            ti.field(ti.i32, capacity)
        self.pixel_key = ti.field(ti.i64, shape=pixel_class(frame_shape))
        self.pp_sums = ti.field(ti.f64, shape=(capacity, N_PP_SUMS))  # eliminate's sums, copied out at its end
        # eliminate_and_hand_over's decisions: per PP drop flag and rank, per rank its first member column
        self.pp_drop, self.pp_rank, self.pp_cursor = ti.field(ti.i8, capacity), ti.field(ti.i32, capacity), \
            ti.field(ti.i32, capacity)

    @ti.kernel
    def eliminate(self, b: ti.i32, pp: ti.types.ndarray(dtype=ti.i32, ndim=1),
                  table: ti.types.ndarray(dtype=ti.f64, ndim=2), keep: ti.types.ndarray(dtype=ti.i8, ndim=1),
                  sums: ti.types.ndarray(dtype=ti.f64, ndim=2)):
        """Eq. 37 and Eq. 38's sums.  Particle s (state order) belongs to PP k = pp[s]; ``table`` rows
        hold each PP's size, take and phase.  The r-th particle of a PP in slot order goes iff
        ⌊((r+1)·take + q)/size⌋ > ⌊(r·take + q)/size⌋ with q = min(⌊phase·size⌋, size − 1), so
        exactly take of size go, spread evenly over the PP's resampled order.  That is a running
        remainder acc = (r·take + q) mod size per PP: add take, the particle goes when it reaches
        size.  keep[s] ← 1 for survivors; sums[k] ← (survivors, survivors with E = 1, Σ Tp over
        survivors, Σ x and Σ y over survivors with E = 1), added in state order (f64).  pp, sizes
        and keep stay on the device for :meth:`hand_over`.  A PP lies in one group, so groups run
        in parallel."""
        self.eliminate_particles(b, table, ti.static((pp, keep)))
        ti.loop_config(serialize=True)  # the sums pass through a field: an argument array's pointer is
        for k in range(table.shape[1]):  # reloaded after every store, which made the pass slower
            for c in ti.static(range(N_PP_SUMS)):
                sums[k, c] = self.pp_sums[k, c]

    @ti.func
    def eliminate_particles(self, b: ti.i32, table: ti.template(), arrays: ti.template()):
        """``eliminate``'s work up to the sums in ``pp_sums``; ``arrays``: (pp,) or (pp, keep)."""
        self.state_starts()
        ti.loop_config(serialize=True)
        for k in range(table.shape[1]):
            self.pp_size[k] = ti.cast(table[0, k], ti.i32)
            self.pp_take[k] = ti.cast(table[1, k], ti.i32)
            self.start_spread(k, table[2, k])
        self.for_states(self.remove_spread, b, arrays)

    @ti.func
    def eliminate_numbered(self, b: ti.i32, phase: ti.template()):
        """``eliminate_particles`` for the PPs that the step numbered (``NumberingKernels.number_populations``:
        their sizes and quotas are on the device), with PP k's ``phase[k]``."""
        self.state_starts()
        ti.loop_config(serialize=True)
        for k in range(phase.shape[0]):
            self.start_spread(k, phase[k])
        ti.loop_config(serialize=self.serial)
        for g in range(self.n.shape[0]):  # as for_states, each particle's PP found by its Seq, run by run
            s0, off, first = self.state_start[g], self.off[g], self.group_first_pp[g]
            h, run_seq, k = -1, 0, -1
            acc, sums = 0, ti.Vector([0.0] * N_PP_SUMS, ti.f64)  # PP k's remainder and sums, in registers
            for i in range(off, off + self.n[g]):
                seq = self.seq[b, i]
                if h < 0 or seq != run_seq:
                    if k >= 0:
                        self.store_spread(k, acc, sums)
                    h, run_seq = self.seq_entry(g, seq), seq
                    k = first + self.entry_rank[h]
                    acc, sums = self.pp_acc[k], self.loaded_sums(k)
                s = s0 + i - off
                self.state_pp[s] = k
                self.state_keep[s] = self.spread_particle(k, i, b, acc, sums)
            if k >= 0:
                self.store_spread(k, acc, sums)

    @ti.func
    def start_spread(self, k: ti.i32, phase: ti.f64):
        """PP k's running remainder q = min(⌊phase·size⌋, size − 1) (Eq. 37's spread) and zero sums."""
        self.pp_acc[k] = ti.min(ti.cast(phase * ti.cast(self.pp_size[k], ti.f64), ti.i32), self.pp_size[k] - 1)
        for c in ti.static(range(N_PP_SUMS)):
            self.pp_sums[k, c] = 0.0

    @ti.func
    def remove_spread(self, s: ti.i32, i: ti.i32, b: ti.i32, arrays: ti.template()):
        """``eliminate`` for particle s (slot i) of PP k = arrays[0][s]; ``arrays``: (pp,) or (pp, keep), whose
        keep[s] takes the keep flag."""
        k = arrays[0][s]
        acc, sums = self.pp_acc[k], self.loaded_sums(k)
        kept = self.spread_particle(k, i, b, acc, sums)
        self.store_spread(k, acc, sums)
        self.state_pp[s] = k
        if ti.static(len(arrays) > 1):
            arrays[1][s] = kept
        self.state_keep[s] = kept

    @ti.func
    def spread_particle(self, k: ti.i32, i: ti.i32, b: ti.i32, acc: ti.template(), sums: ti.template()) -> ti.i8:
        """Eq. 37 for the next particle (slot i) of PP k, whose running remainder ``acc`` and Eq. 38 sums ``sums``
        (both updated in place) the caller holds: the keep flag (1: survives)."""
        a = acc + self.pp_take[k]
        gone = a >= self.pp_size[k]
        acc = a - ti.select(gone, self.pp_size[k], 0)
        if not gone:
            sums[P_KEPT] += 1.0
            sums[P_TP] += ti.cast(self.tp[b, i], ti.f64)
            if self.e[b, i] == 1:
                sums[P_KEPT_E] += 1.0
                sums[P_X] += ti.cast(self.x[b, i], ti.f64)
                sums[P_Y] += ti.cast(self.y[b, i], ti.f64)
        return ti.cast(not gone, ti.i8)

    @ti.func
    def loaded_sums(self, k: ti.i32):
        """PP k's Eq. 38 sums as a vector."""
        return ti.Vector([self.pp_sums[k, c] for c in ti.static(range(N_PP_SUMS))], ti.f64)

    @ti.func
    def store_spread(self, k: ti.i32, acc: ti.i32, sums: ti.template()):
        """PP k's running remainder and sums back into ``pp_acc`` and ``pp_sums``."""
        self.pp_acc[k] = acc
        for c in ti.static(range(N_PP_SUMS)):
            self.pp_sums[k, c] = sums[c]

    @ti.func
    def index_pixel(self, b: ti.i32, s: ti.i32, i: ti.i32):
        """(y, x, y·W + x) of the pixel nearest particle s in slot i if it is kept, has Seq > 0 and lies in
        the image (it takes part in the index image), else (0, 0, −1)."""
        h, w = self.frame_hw[0], self.frame_hw[1]
        x = ti.cast(ti.floor(self.x[b, i] + 0.5), ti.i32)
        y = ti.cast(ti.floor(self.y[b, i] + 0.5), ti.i32)
        ok = self.state_keep[s] != 0 and self.seq[b, i] > 0 and 0 <= x < w and 0 <= y < h
        return ti.select(ok, y, 0), ti.select(ok, x, 0), ti.select(ok, y * w + x, -1)

    @ti.func
    def index_key(self, s: ti.i32) -> ti.i64:
        """The index image's precedence of state-order particle s: its PP's size, then s."""
        return (ti.cast(self.pp_size[self.state_pp[s]], ti.i64) << 32) + s

    @ti.kernel
    def hand_over(self, b: ti.i32, index: ti.types.ndarray(dtype=ti.i32, ndim=2),
                  counts: ti.types.ndarray(dtype=ti.i32, ndim=1), decisions: ti.types.ndarray(dtype=ti.i32, ndim=2),
                  floats: ti.types.ndarray(dtype=ti.f32, ndim=2), ints: ti.types.ndarray(dtype=ti.i32, ndim=2),
                  members: ti.template()):
        """After :meth:`eliminate`: the particles of dropped PPs go too; the index image P_pp (Eq. 36): each
        pixel holds the Seq of the kept particles (Seq > 0) in it, those of the larger PP winning, then the
        later in state order; the kept particles move to the front of their slabs, and ``counts`` receives
        every group's new live count.  ``decisions`` (3, PPs), the host's choices as
        :meth:`potential_targets` makes them on the device: per PP k its drop flag (row 0) and hand-over
        rank (row 1; −1: not handed over), per rank r the first member column of that PP (row 2).  With
        ``members``, the survivors of elimination in each handed-over PP are first copied out, in state
        order from its first column on: rows x, vx, y, vy, I of ``floats`` and E, Tp, Seq of ``ints``, as
        ``read_slots`` gives them."""
        ti.loop_config(serialize=True)
        for k in range(decisions.shape[1]):
            self.pp_drop[k] = ti.cast(decisions[0, k], ti.i8)
            self.pp_rank[k] = decisions[1, k]
            self.pp_cursor[k] = decisions[2, k]
        self.hand_over_particles(b, self.pp_drop, index, counts, ti.static((self.pp_rank, self.pp_cursor, floats,
                                                                            ints)), members)

    @ti.func
    def hand_over_particles(self, b: ti.i32, drop: ti.template(), index: ti.template(), counts: ti.template(),
                            copies: ti.template(), members: ti.template()):
        """``hand_over``'s work; ``copies``: (rank, cursor, floats, ints)."""
        rank, cursor, floats, ints = ti.static(copies)
        h, w = self.frame_hw[0], self.frame_hw[1]
        ti.loop_config(serialize=self.serial)
        for y, x in ti.ndrange(h, w):
            self.pixel_key[y * w + x] = -1
            index[y, x] = 0
        if ti.static(members):  # one pass: each particle is copied out before its claim may drop it
            self.for_states(self.copy_and_claim, b, ti.static((drop, index, rank, cursor, floats, ints)))
        else:
            self.for_states(self.claim_pixel, b, ti.static((drop, index)))
        if ti.static(not self.serial):  # the winners write their Seq
            self.for_states(self.write_winner, b, ti.static((drop, index)))
        self.compact(b, self.state_keep)
        ti.loop_config(serialize=True)
        for g in range(counts.shape[0]):
            counts[g] = self.n[g]

    @ti.kernel
    def eliminate_and_hand_over(self, b: ti.i32, pp: I32_1D, table: F64_2D, rule: F64_1D, index: I32_2D,
                                counts: I32_1D, outcome: I32_2D, floats: F32_2D, ints: I32_2D):
        """:meth:`eliminate`, the potential-target decisions (:meth:`potential_targets`) and :meth:`hand_over`
        with members in one launch.  ``rule``: T_PTp, T_PE, the squared duplicate radius in px², the most PPs
        to hand over, the number T of active tracks, then their positions x₀, y₀, …, x_T−1, y_T−1 in px
        (``RULE_TRACKED`` on).  ``outcome``: per PP k its hand-over rank (row 0; −1: not handed over) and its
        survivors of elimination (row 1); the handed PPs' survivors fill ``floats`` and ``ints`` in rank
        order, as ``hand_over`` writes them."""
        self.eliminate_particles(b, table, ti.static((pp,)))
        self.potential_targets(table.shape[1], rule, outcome)
        self.hand_over_particles(b, self.pp_drop, index, counts,
                                 ti.static((self.pp_rank, self.pp_cursor, floats, ints)), True)

    @ti.kernel
    def eliminate_and_hand_over_numbered(self, b: ti.i32, phase: F64_1D, rule: F64_1D, index: I32_2D,
                                         counts: I32_1D, outcome: I32_2D, floats: F32_2D, ints: I32_2D):
        """:meth:`eliminate_and_hand_over` for the PPs the step numbered on the device (each PP k's ``phase[k]``;
        ``NumberingKernels.number_populations``), so no per-particle array comes from the host."""
        self.eliminate_numbered(b, phase)
        self.potential_targets(phase.shape[0], rule, outcome)
        self.hand_over_particles(b, self.pp_drop, index, counts,
                                 ti.static((self.pp_rank, self.pp_cursor, floats, ints)), True)

    @ti.func
    def potential_targets(self, n_pp: ti.i32, rule: ti.template(), outcome: ti.template()):
        """Algorithm 1's hand-over decisions from Eq. 38's sums (``pp_sums``), PP after PP in PP order: a PP with
        survivors, E = 1 among them, PTp = ΣTp/N_pp > T_PTp and PE = ΣE/N_pp > T_PE is a potential target.  It
        is dropped if its mean position (E = 1 survivors, px) lies within the duplicate radius of an active
        track (tracked already), else handed over (and dropped) while fewer than the allowed number are.  Sets
        ``pp_drop``, ``pp_rank``, the handed PPs' first member columns ``pp_cursor``, and ``outcome``."""
        ti.loop_config(serialize=True)
        for _ in range(1):  # one task
            t_ptp, t_pe, r2 = rule[0], rule[1], rule[2]
            most, n_tracked = ti.cast(rule[3], ti.i32), ti.cast(rule[4], ti.i32)
            handed, column = 0, 0
            for k in range(n_pp):
                n, ne = self.pp_sums[k, P_KEPT], self.pp_sums[k, P_KEPT_E]
                drop, rank = 0, -1
                if n > 0 and ne > 0 and self.pp_sums[k, P_TP] / n > t_ptp and ne / n > t_pe:
                    px, py = self.pp_sums[k, P_X] / ne, self.pp_sums[k, P_Y] / ne
                    near = 0
                    for j in range(n_tracked):
                        dx = px - rule[RULE_TRACKED + 2 * j]
                        dy = py - rule[RULE_TRACKED + 2 * j + 1]
                        if dx * dx + dy * dy < r2:
                            near = 1
                    if near:  # tracked already
                        drop = 1
                    elif handed < most:
                        drop, rank = 1, handed
                        self.pp_cursor[handed] = column
                        column += ti.cast(n, ti.i32)
                        handed += 1
                self.pp_drop[k] = ti.cast(drop, ti.i8)
                self.pp_rank[k] = rank
                outcome[0, k] = rank
                outcome[1, k] = ti.cast(n, ti.i32)

    @ti.func
    def copy_and_claim(self, s: ti.i32, i: ti.i32, b: ti.i32, arrays: ti.template()):
        """``copy_member`` then ``claim_pixel`` for particle s (slot i)."""
        drop, index, rank, cursor, floats, ints = ti.static(arrays)
        self.copy_member(s, i, b, ti.static((rank, cursor, floats, ints)))
        self.claim_pixel(s, i, b, ti.static((drop, index)))

    @ti.func
    def copy_member(self, s: ti.i32, i: ti.i32, b: ti.i32, arrays: ti.template()):
        """``hand_over``'s copy of particle s (slot i) if it survived elimination in a handed-over PP (a
        PP lies in one group, whose task alone moves its cursor)."""
        rank, cursor, floats, ints = ti.static(arrays)
        r = rank[self.state_pp[s]]
        if r >= 0 and self.state_keep[s] != 0:
            m = cursor[r]
            cursor[r] = m + 1
            floats[0, m], floats[1, m], floats[2, m] = self.x[b, i], self.vx[b, i], self.y[b, i]
            floats[3, m], floats[4, m] = self.vy[b, i], self.inten[b, i]
            ints[0, m], ints[1, m], ints[2, m] = self.e[b, i], self.tp[b, i], self.seq[b, i]

    @ti.func
    def claim_pixel(self, s: ti.i32, i: ti.i32, b: ti.i32, arrays: ti.template()):
        """``hand_over`` for particle s (slot i): drop it with its PP, else bid for its pixel.  A serial
        loop visits s in increasing order, so the last larger key wins at once; parallel loops
        take the atomic maximum and let :meth:`write_winner` write the Seq."""
        drop, index = ti.static(arrays)
        if drop[self.state_pp[s]] != 0:
            self.state_keep[s] = ti.i8(0)
        y, x, p = self.index_pixel(b, s, i)
        if p >= 0:
            key = self.index_key(s)
            if ti.static(self.serial):
                if key > self.pixel_key[p]:
                    self.pixel_key[p] = key
                    index[y, x] = self.seq[b, i]
            else:
                ti.atomic_max(self.pixel_key[p], key)

    @ti.func
    def write_winner(self, s: ti.i32, i: ti.i32, b: ti.i32, arrays: ti.template()):
        """The particle that won its pixel writes its Seq there (parallel ``hand_over``)."""
        _, index = ti.static(arrays)
        y, x, p = self.index_pixel(b, s, i)
        if p >= 0 and self.pixel_key[p] == self.index_key(s):
            index[y, x] = self.seq[b, i]


@ti.data_oriented
class SearchingKernels(ParticleKernels, PopulationKernels, NumberingKernels):
    """The particle pool's kernels with Eqs. 36–38 on its fields: SGDS-PF's searching PFs."""

    @staticmethod
    def frame_key(frame_shape) -> tuple:
        """What of the frame's size the fields' shapes hold (``ParticleKernels.frame_key``): pixel_key's class."""
        return (pixel_class(frame_shape),)

    def __init__(self, capacity: int, n_groups: int, n_tiles: int, frame_shape, map_capacity: int, serial: bool,
                 flat: bool, split: int = 1, motion=None, likelihood=None):
        super().__init__(capacity, n_groups, n_tiles, frame_shape, map_capacity, serial, flat, split, motion,
                         likelihood)
        self.population_fields(capacity, frame_shape)
        self.numbering_fields(capacity, n_groups)
