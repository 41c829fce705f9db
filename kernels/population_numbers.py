"""Numbering SGDS-PF's particle populations on the device (Eqs. 36–37), at the end of the searching PFs' step.

A particle population (PP) is the set of a block's particles that share a Seq (Eq. 36).  The PPs are numbered
block by block, and within a block by increasing Seq; Eq. 37 then takes ``quota`` particles from each block,
smallest PPs first (ties by Seq), the last one partially.  :meth:`NumberingKernels.number_populations` does both
for every block at once, one task per block:

1. each live particle's Seq goes into an open-addressing hash table of 2 × the block's capacity (linear probing,
   entries stamped with the call's epoch, so nothing is cleared), which counts the particles of each distinct Seq;
2. the block's distinct Seqs are heap-sorted by Seq (their rank is the PP's number within the block), then by
   (size, Seq) for Eq. 37's quotas;
3. a serial pass gives each block the number of its first PP, and a pass per block fills the per-PP size and
   quota tables that ``PopulationKernels.eliminate_numbered`` reads.

Every task is serial within its block, so the numbers do not depend on the thread count.  The host then needs only
the number of PPs (for their random phases), not each particle's Seq.  The NumPy twin is
``tbd_taichi.numpy_kernels.populations.NumpyPopulationKernels.number_populations`` (``slab_populations`` and
``eliminated_per_population``).
"""
import taichi as ti

HASH_MULTIPLIER = 2654435761  # Knuth's multiplicative hash (2^32 / golden ratio), on the Seq as u32


@ti.data_oriented
class NumberingKernels:
    """Eq. 36–37's PP numbers over the ``ParticleKernels`` fields; needs ``PopulationKernels``' ``pp_size`` and
    ``pp_take`` and :meth:`numbering_fields`."""

    def numbering_fields(self, capacity: int, n_groups: int):
        """Per hash entry (2 per slot, group g's at 2·off[g]) the Seq, the epoch that wrote it, its particles, its
        PP's rank in the block and quota; per slot-range position the block's distinct entries (in Seq order) and
        the same by (size, Seq); per group its first PP and PP count."""
        i32 = lambda *shape: ti.field(ti.i32, shape=shape)  # noqa: E731
        self.pp_by_seq, self.pp_by_size = i32(capacity), i32(capacity)
        self.entry_seq, self.entry_epoch, self.entry_count = i32(2 * capacity), i32(2 * capacity), i32(2 * capacity)
        self.entry_rank, self.entry_take = i32(2 * capacity), i32(2 * capacity)
        self.group_first_pp, self.group_pps = i32(n_groups), i32(n_groups)
        self.number_epoch = i32(1)

    @ti.func
    def number_populations(self, b: ti.i32, io: ti.template()):
        """The PPs of buffer b's live particles, numbered block by block, then by Seq, with Eq. 37's quotas:
        ``io[0]`` holds the quota per block (particles) on entry and the number of PPs on return; ``pp_size``
        and ``pp_take`` hold each PP's particles and quota; a particle of group g with Seq q is in PP
        ``group_first_pp[g] + entry_rank[seq_entry(g, q)]``."""
        quota = io[0]
        # the epoch only grows, also in fields a later pool reuses (never zeroed): 2³² numberings before it wraps
        self.number_epoch[0] += 1
        # one task per block, the blocks in the launching thread on the CPU: dealt out over two threads
        # (``for_groups``) the numbering took 0.63–0.74 ms a frame at the SNR 1.2 preset against 0.53–0.55
        ti.loop_config(serialize=self.serial)
        for g in range(self.n.shape[0]):
            self.group_pps[g] = self.block_populations(g, b, quota)
            self.block_quotas(g, quota)
        ti.loop_config(serialize=True)
        for _ in range(1):  # one task: the blocks' first PPs
            first = 0
            for g in range(self.n.shape[0]):
                self.group_first_pp[g] = first
                first += self.group_pps[g]
            io[0] = first
        ti.loop_config(serialize=self.serial)
        for g in range(self.n.shape[0]):  # each PP's size and quota, at its number
            first, off = self.group_first_pp[g], self.off[g]
            for r in range(self.group_pps[g]):
                self.pp_size[first + r] = self.entry_count[self.pp_by_seq[off + r]]
                self.pp_take[first + r] = self.entry_take[self.pp_by_seq[off + r]]

    @ti.func
    def seq_entry(self, g: ti.i32, seq: ti.i32) -> ti.i32:
        """Group g's hash entry of ``seq``: the entry that holds it in this call's epoch, else the free entry where
        it goes (linear probing from its hash over the group's 2·cap[g] entries, from 2·off[g] on).  A PP's
        number is then ``group_first_pp[g] + entry_rank[entry]``."""
        base, length = 2 * self.off[g], ti.max(2 * self.cap[g], 1)
        h = base + ti.cast((ti.cast(seq, ti.u32) * ti.u32(HASH_MULTIPLIER)) % ti.cast(length, ti.u32), ti.i32)
        while self.entry_epoch[h] == self.number_epoch[0] and self.entry_seq[h] != seq:
            h = ti.select(h + 1 == base + length, base, h + 1)
        return h

    @ti.func
    def block_populations(self, g: ti.i32, b: ti.i32, quota: ti.i32) -> ti.i32:
        """Group g's distinct Seqs (its PPs), each with its particles in its hash entry, in ``pp_by_seq`` and
        ``pp_by_size`` from position off[g] on; returns the group's number of PPs."""
        off = self.off[g]
        m, h, run_seq, run = 0, -1, 0, 0  # the current run of equal Seqs: its entry, Seq and length
        epoch = self.number_epoch[0]
        for i in range(off, off + self.n[g]):
            seq = self.seq[b, i]
            if h < 0 or seq != run_seq:  # resampled siblings sit side by side: runs of one Seq are common
                if h >= 0:
                    self.entry_count[h] += run
                h = self.seq_entry(g, seq)
                if self.entry_epoch[h] != epoch:
                    self.entry_epoch[h], self.entry_seq[h], self.entry_count[h] = epoch, seq, 0
                    self.pp_by_seq[off + m] = h
                    self.pp_by_size[off + m] = h
                    m += 1
                run_seq, run = seq, 0
            run += 1
        if h >= 0:
            self.entry_count[h] += run
        return m

    @ti.func
    def block_quotas(self, g: ti.i32, quota: ti.i32):
        """Group g's PPs sorted by Seq (each PP's rank, its number within the block) and by (size, Seq) for Eq.
        37: ``quota`` particles go from the block, smallest PPs first, the last one partially."""
        off, m = self.off[g], self.group_pps[g]
        self.heap_sort(self.pp_by_seq, off, m, False)
        self.heap_sort(self.pp_by_size, off, m, True)
        before = 0
        for r in range(m):
            self.entry_rank[self.pp_by_seq[off + r]] = r
            e = self.pp_by_size[off + r]
            self.entry_take[e] = ti.min(ti.max(quota - before, 0), self.entry_count[e])  # Eq. 37
            before += self.entry_count[e]

    @ti.func
    def precedes(self, h: ti.i32, k: ti.i32, by_size: ti.template()) -> ti.i32:
        """Whether hash entry h sorts before entry k: by Seq, or by (particles, Seq) with ``by_size``."""
        earlier = ti.cast(self.entry_seq[h] < self.entry_seq[k], ti.i32)
        if ti.static(by_size):
            ch, ck = self.entry_count[h], self.entry_count[k]
            earlier = ti.select(ch == ck, earlier, ti.cast(ch < ck, ti.i32))
        return earlier

    @ti.func
    def heap_sort(self, items: ti.template(), lo: ti.i32, m: ti.i32, by_size: ti.template()):
        """Sort the hash entries items[lo:lo + m] in place by :meth:`precedes` (heapsort: O(m log m) for any m)."""
        start = m // 2 - 1
        while start >= 0:
            self.sift_down(items, lo, start, m, by_size)
            start -= 1
        end = m - 1
        while end > 0:
            top = items[lo]
            items[lo] = items[lo + end]
            items[lo + end] = top
            self.sift_down(items, lo, 0, end, by_size)
            end -= 1

    @ti.func
    def sift_down(self, items: ti.template(), lo: ti.i32, root: ti.i32, end: ti.i32, by_size: ti.template()):
        """Heapsort's sift-down of items[lo + root] within the heap items[lo:lo + end] (largest at the root)."""
        r = root
        while 2 * r + 1 < end:
            child = 2 * r + 1
            if child + 1 < end and self.precedes(items[lo + child], items[lo + child + 1], by_size):
                child += 1
            if self.precedes(items[lo + r], items[lo + child], by_size):
                parent = items[lo + r]
                items[lo + r] = items[lo + child]
                items[lo + child] = parent
                r = child
            else:
                break
