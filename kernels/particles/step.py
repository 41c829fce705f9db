"""Steps 1–5 of the particle filter in one launch: ``step`` (the stages one after the other, or ``fused_step``'s
three passes over the tiles) and ``step_pair`` (two pools on one frame, ``stepped_group`` per group).
"""
from dataclasses import dataclass
from functools import lru_cache

import taichi as ti

from ..loops import light_ir
from ..rng import key_prefix
from .layout import BIRTH_STREAMS, NOISE_STREAMS, S_EXIST, S_RESAMPLE, S_RESAMPLE_END, S_SYSTEMATIC


@dataclass(frozen=True)
class StepOptions:
    """The compile-time choices of ``step``: ``systematic`` resampling (else multinomial), ``read_seq`` (the
    resampled particles' Seq into the step's ``seq``), ``fused`` (``fused_step``'s three passes), ``number``
    (SGDS-PF's searching pool: the resampled particles' populations numbered on the device, ``seq[0]`` the quota
    in and the number of populations out; ``population_numbers``).  Made by :meth:`of`, one object per
    combination, since a launch keys a template argument by its identity."""

    systematic: bool = False
    read_seq: bool = False
    fused: bool = False
    number: bool = False

    @staticmethod
    @lru_cache(maxsize=None)
    def of(systematic: bool, read_seq: bool, fused: bool, number: bool = False) -> "StepOptions":
        return StepOptions(bool(systematic), bool(read_seq), bool(fused), bool(number))


@ti.data_oriented
class StepMixin:
    """The fused steps, composed of the stages of ``PropagateMixin``, ``WeightMixin``, ``ResampleMixin`` and
    ``EstimateMixin``."""

    @light_ir
    @ti.kernel
    def step(self, frame: ti.i32, b: ti.i32, counts: ti.types.ndarray(dtype=ti.i32, ndim=1),
             n_out: ti.types.ndarray(dtype=ti.i32, ndim=1), z: ti.types.ndarray(dtype=ti.f32, ndim=2),
             seq: ti.types.ndarray(dtype=ti.i32, ndim=1), options: ti.template()):
        """Steps 1–5 in one launch, for a filter with nothing to do between them (a launch costs
        tens of µs on the CPU backend), with the pool's constants (``step_values``): live counts after the
        top-up ``counts``, resampled counts ``n_out``.  ``options`` (:class:`StepOptions`): ``systematic``
        resampling; ``read_seq``, also the resampled particles' Seq in state order into ``seq``
        (:meth:`read_seq`); ``number``, the resampled particles' populations numbered instead (SGDS-PF's
        searching PFs: :meth:`read_out`); ``fused``, as :meth:`fused_step` (CPU, tile loops split, no kind 2
        group)."""
        values = self.step_values(frame, b)
        if ti.static(options.fused):
            self.fused_step(values, counts, z, n_out, options.systematic)
        else:
            self.predict_particles(values, counts)
            self.weigh_particles(values, z)
            self.resample_particles(values, n_out, options.systematic)
        self.read_out(1 - b, seq, options)

    @ti.func
    def read_out(self, b: ti.i32, seq: ti.template(), options: ti.template()):
        """After a step into buffer b: ``options.read_seq``, the particles' Seq in state order into ``seq``;
        ``options.number``, their populations numbered (``seq[0]``: Eq. 37's quota in, the number out)."""
        if ti.static(options.read_seq):
            self.seq_in_state_order(b, seq)
        if ti.static(options.number):
            self.number_populations(b, seq)

    @ti.func
    def fused_step(self, values: ti.template(), counts: ti.template(), z: ti.template(), n_out: ti.template(),
                   systematic: ti.template()):
        """Steps 1–5 for a pool without copied newborns (kind 2) whose tile loops are split over the
        threads: three passes over the tiles instead of eight, since each parallel pass costs a start
        of Taichi's thread pool.  Pass 1: existence, top-up, newborn draws, propagation, log-weight and
        tile maxima, each a loop over the tile's slots (no slot reads another: only kind 2 copies do);
        pass 2: each tile's cumulative weights and spacings; pass 3: each tile's parents, then the gather
        of its outputs.  Serial steps between them combine the tiles of each group.  The same operations
        on the same slots as the unfused step, so the same bits.  ``values``: ``step_values``."""
        seed, frame, b = values[0], values[1], values[2]
        self.store_counts(counts)
        if ti.static(self.tiles_by_group):
            self.for_groups(self.predicted_group, {'values': values, 'z': z})
        else:
            self.for_tiles(self.predicted_tile, {'values': values, 'z': z})
        self.group_maxima()
        self.keep_best()
        self.set_out_counts(n_out)
        self.for_tiles(self.weighted_tile, {'systematic': systematic, 'key': key_prefix(seed, frame, S_RESAMPLE)})
        self.group_prefix()
        if ti.static(not systematic):
            self.group_spacings(seed, frame)
        self.for_tiles(self.resampled_tile, {'systematic': systematic, 'b': b,
                                             'key': key_prefix(seed, frame, S_SYSTEMATIC)})
        self.commit_counts()

    @light_ir
    @ti.kernel
    def step_pair(self, other: ti.template(), frame: ti.i32, b: ti.i32, other_b: ti.i32,
                  counts: ti.types.ndarray(dtype=ti.i32, ndim=1), z: ti.types.ndarray(dtype=ti.f32, ndim=2),
                  seq: ti.types.ndarray(dtype=ti.i32, ndim=1), options: ti.template(),
                  moments: ti.types.ndarray(dtype=ti.f64, ndim=2)):
        """``step`` (fused, whole groups per thread, multinomial, every group resampled to its live count
        ``counts``) of this pool and of ``other``, a second pool on the same frame z with the same motion
        and PSF constants (the tracking PFs beside the searching PFs), stepped at its live counts (its own
        ``n``), in the same pass (``stepped_group`` for each group of either pool), so the threads share
        both pools' work and the serial pool ``other`` no longer leaves a core idle; with ``other``'s
        ``estimates`` into ``moments``.  Each group is stepped as ``fused_step`` steps it, so both pools
        get the bits of their own ``step``.  ``options``: this pool's read-out (:meth:`read_out`)."""
        self.store_counts(counts)
        other.store_counts(other.n)
        self.for_groups_with(other, self.stepped_group,
                             {'values': self.step_values(frame, b), 'z': z, 'n_out': counts,
                              'resampled': self.resampled_tile, 'moments': ()},
                             other.stepped_group,
                             {'values': other.step_values(frame, other_b), 'z': z, 'n_out': other.n,
                              'resampled': other.resampled_moments_tile, 'moments': moments})
        self.read_out(1 - b, seq, options)

    @ti.func
    def stepped_group(self, g: ti.i32, loop: ti.template()):
        """``fused_step``'s three passes for group g alone, by the thread that owns the group (whole groups per thread): pass 1
        (``predicted_group``), its maxima, pass 2 (``weighted_tile``), its prefix and spacing total, pass 3
        (``loop['resampled']``) and its moment sums, with no barrier between them, since no stage reads another
        group.  One start of the thread pool a step instead of three (about 60 µs each on the 2-core VM), and
        the group's particles stay in the core's cache from stage to stage; the same operations in the same
        order as ``fused_step``, so the same bits.  ``loop``: {'values', 'z'} as ``predicted_group`` takes them,
        'n_out' as ``fused_step``'s, 'resampled' (``resampled_tile`` or
        ``resampled_moments_tile``) and 'moments' (``estimates``' output, or () for none); multinomial."""
        seed, frame, b = loop['values'][0], loop['values'][1], loop['values'][2]
        self.predicted_group(g, loop)
        self.group_maximum(g)
        self.best_e[g] = self.gmax_e[g]
        self.set_out_count(g, loop['n_out'])
        key = key_prefix(seed, frame, S_RESAMPLE)  # (a dict assigned to a name would turn its values into variables)
        for t in range(self.gt0[g], self.gt1[g]):
            self.weighted_tile(t, {'systematic': False, 'key': key})
        self.group_cumulative(g)
        self.group_spacing(g, key_prefix(seed, frame, S_RESAMPLE_END))
        key = key_prefix(seed, frame, S_SYSTEMATIC)
        for t in range(self.gt0[g], self.gt1[g]):
            loop['resampled'](t, {'systematic': False, 'b': b, 'key': key})
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
        c11, c21, c22, sq2 = self.motion.noise_factors(q1, q2)
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
            self.propagate_slot(i, g, copies, noise)

    @ti.func
    def weighed_tile(self, t: ti.i32, loop: ti.template()):
        """Steps 3–4a for tile t: Eq. 15's log-weights and the tile maxima."""
        seed, frame, b, q1, q2, i_floor, width, height, psf_sigma, noise_sigma = loop['values']
        inv2s2, norm, inv_var, step = self.likelihood.constants(psf_sigma, noise_sigma)
        self.tile_maximum(t, {'b': b, 'weigh': True,
                              'args': {'values': (b, inv2s2, norm, inv_var, step, height, width), 'zp': loop['z']}})

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
