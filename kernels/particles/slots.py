"""Live counts, host transfers of particle states and the *state order* (group, then slot) of a particle pool.

The host writes and reads particles by slot (``write_slots``/``read_slots``), removes them in place
(``keep_particles``), sets the live counts and the groups' proposal maps (``load_map``, Eq. 34), and reads their Seq
in state order (``read_seq``), the order ``tbd_taichi.particles.ParticlePool.states_at`` lists them in.
"""
import taichi as ti


@ti.data_oriented
class SlotsMixin:
    """Counts, host transfers and state order over the ``LayoutMixin`` fields."""

    @ti.func
    def store_counts(self, counts: ti.template()):
        """n ← counts (the host's checked live counts), keeping the previous ones in n_before."""
        ti.loop_config(serialize=True)
        for g in range(self.n.shape[0]):
            self.n_before[g] = self.n[g]
            self.n[g] = counts[g]

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

    @ti.func
    def state_starts(self):
        """state_start[g]: index of group g's first live particle in state order (prefix of n)."""
        ti.loop_config(serialize=True)
        for _ in range(1):  # one task
            s = 0
            for h in range(self.n.shape[0]):
                self.state_start[h] = s
                s += self.n[h]

    @ti.func
    def for_states(self, body: ti.template(), b: ti.i32, arrays: ti.template()):
        """body(s, i, b, arrays) for every live particle, s its index in state order and i its slot
        (after ``state_starts``); one task per group, slots in order.  ``arrays``: the kernel's array
        arguments, as ``ti.static((…))``."""
        ti.loop_config(serialize=self.serial)
        for g in range(self.n.shape[0]):
            s0, off = self.state_start[g], self.off[g]
            for i in range(off, off + self.n[g]):
                body(s0 + i - off, i, b, arrays)

    @ti.kernel
    def read_seq(self, b: ti.i32, seq: ti.types.ndarray(dtype=ti.i32, ndim=1)):
        """The Seq of every live particle, in state order."""
        self.seq_in_state_order(b, seq)

    @ti.func
    def seq_in_state_order(self, b: ti.i32, seq: ti.template()):
        self.state_starts()
        self.for_states(self.copy_seq, b, ti.static((seq,)))

    @ti.func
    def copy_seq(self, s: ti.i32, i: ti.i32, b: ti.i32, arrays: ti.template()):
        seq = ti.static(arrays[0])
        seq[s] = self.seq[b, i]

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
