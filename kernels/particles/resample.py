"""Step 5 of the particle filter: resampling (Eqs. 17–18), multinomial by exponential spacings or systematic,
with the parents found by interleaved merge walks and the states gathered into the other buffer.
"""
import taichi as ti

from ..rng import exponential_at, key_prefix, uniform_f64_at
from .layout import S_RESAMPLE, S_RESAMPLE_END, S_SYSTEMATIC, WALKS, first_above


@ti.data_oriented
class ResampleMixin:
    """Step 5 over the pool (Eqs. 17–18)."""

    @ti.func
    def first_slot_above(self, g: ti.i32, v: ti.f64) -> ti.i32:
        """Eq. 18: the first live slot of group g whose upper edge Σ_{j ≤ slot} w_j (cum, Eq. 17) exceeds v
        (the last one if none)."""
        return first_above(self.cum, self.off[g], self.off[g] + self.n[g] - 1, v)

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
    def resample(self, frame: ti.i32, b: ti.i32, counts: ti.types.ndarray(dtype=ti.i32, ndim=1),
                 systematic: ti.template()):
        """Step 5 in one launch (see ``resample_particles``), with the pool's random key (``step_values``)."""
        self.resample_particles(self.step_values(frame, b), counts, systematic)

    @ti.func
    def resample_particles(self, values: ti.template(), counts: ti.template(), systematic: ti.template()):
        """Step 5 (Eqs. 17–18): each group draws ``counts[g]`` parents from buffer b and buffer 1 − b
        receives them; live counts become ``counts``; ``values``: ``step_values``."""
        seed, frame, b = values[0], values[1], values[2]
        self.set_out_counts(counts)
        if ti.static(not systematic):
            self.tile_spacings(seed, frame)
            self.group_spacings(seed, frame)
        self.draw_parents(systematic, seed, frame)
        self.gather(b)
        self.commit_counts()

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
