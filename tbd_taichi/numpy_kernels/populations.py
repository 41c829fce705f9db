"""NumPy twin of ``tbd_taichi.kernels.populations`` and ``kernels.population_numbers`` (Eqs. 36–38 on the
particle pool), vectorised; ``populations``, ``slab_populations`` and ``eliminated_per_population`` number the PPs
and set Eq. 37's quotas (the twin of the device's numbering, and the host reference the tests compare it with).

The per-PP sums are ``np.bincount`` sums, which add in state order as the kernel does, so both
give the same bits.  A mixin of ``NumpyParticleKernels``.
"""
from __future__ import annotations

import numpy as np

from ..kernels.populations import N_PP_SUMS, P_KEPT, P_KEPT_E, P_TP, P_X, P_Y, RULE_TRACKED
from .particles import NumpyParticleKernels


def stable_order(keys: np.ndarray) -> np.ndarray:
    """Stable argsort of non-negative integer ``keys``; radix sort (O(n)) when they fit in 16 bits."""
    small = len(keys) == 0 or int(keys.max()) < 1 << 16
    return np.argsort(keys.astype(np.uint16) if small else keys, kind="stable")


def rank_in_population(inverse: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """0-based position of each particle among its PP's particles, in state order."""
    order = stable_order(inverse)
    start = np.cumsum(counts) - counts
    rank = np.empty_like(inverse)
    rank[order] = np.arange(len(inverse)) - start[inverse[order]]
    return rank


def spread_removal(rank: np.ndarray, size: np.ndarray, take: np.ndarray, phase: np.ndarray) -> np.ndarray:
    """Eq. 37's random elimination of ``take`` of a PP's ``size`` particles, spread evenly over its
    resampled order: the particle of rank r goes iff ⌊((r+1)·take + q)/size⌋ > ⌊(r·take + q)/size⌋,
    q = ⌊phase·size⌋ (phase ~ U(0, 1) per PP).  Exactly ``take`` go, each with probability take/size.
    Resampled particles sit next to their siblings (sorted parents), so a contiguous subset would
    remove whole families."""
    size, take = size.astype(np.int64), take.astype(np.int64)
    q = np.minimum((phase * size).astype(np.int64), size - 1)
    return ((rank + 1) * take + q) // size > (rank * take + q) // size


def potential_targets(sums: np.ndarray, rule: np.ndarray):
    """Twin of ``PopulationKernels.potential_targets``, vectorised: (drop flags, hand-over ranks) per PP from
    Eq. 38's sums; ``rule`` = (T_PTp, T_PE, squared duplicate radius, most handed, active tracks T, then their
    T positions (x, y))."""
    t_ptp, t_pe, r2 = rule[:3]
    most, n_tracked = int(rule[3]), int(rule[4])
    tracked = rule[RULE_TRACKED:RULE_TRACKED + 2 * n_tracked].reshape(-1, 2)
    n, ne = sums[:, P_KEPT], sums[:, P_KEPT_E]
    with np.errstate(invalid="ignore", divide="ignore"):  # n or ne = 0: NaN, never above a threshold
        potential = (n > 0) & (ne > 0) & (sums[:, P_TP] / n > t_ptp) & (ne / n > t_pe)
        px, py = sums[:, P_X] / ne, sums[:, P_Y] / ne
    near = np.zeros(len(n), bool)
    for tx, ty in tracked.tolist():
        near |= (px - tx) * (px - tx) + (py - ty) * (py - ty) < r2
    handed = np.flatnonzero(potential & ~near)[:most]
    rank = np.full(len(n), -1, np.int32)
    rank[handed] = np.arange(len(handed), dtype=np.int32)
    return (potential & near) | (rank >= 0), rank


def populations(group: np.ndarray, seq: np.ndarray, table_limit: int = 1 << 22):
    """Particle populations as (block, Seq) pairs, ordered by block then Seq.

    ``group``: each particle's block, non-decreasing (state order); ``seq``: its Seq.
    Returns (block of each PP, PP index of each particle, particles per PP); see :func:`slab_populations`."""
    group = np.asarray(group, np.int64)
    return slab_populations(np.bincount(group) if len(group) else np.zeros(0, np.int64), seq, table_limit)


def slab_populations(slab_counts, seq: np.ndarray, table_limit: int = 1 << 22):
    """:func:`populations` of particles listed block by block, ``slab_counts[g]`` of block g (the pool's state
    order), without a per-particle block array: one bincount over a (block, Seq) table (each block's keys
    offset by a slice), or a sort where that table would exceed ``table_limit`` entries.  Where the table
    would be sparse (more entries than twice the particles), the Seq values present are first numbered
    densely, in order: long-lived PPs spread the Seq range (1024×1024 at the 1.4 preset: 61,000 values,
    4,300 of them present, 49 blocks, and 9.2 ms a frame, 3.5 ms numbered densely)."""
    seq = np.asarray(seq)
    if len(seq) == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0, np.int64)
    slab_counts = np.asarray(slab_counts, np.int64)
    blocks = np.flatnonzero(slab_counts)
    lo, n_groups = int(seq.min()), int(blocks[-1]) + 1
    span = int(seq.max()) - lo + 1
    key = (seq - lo).astype(np.int32, copy=False) if span <= table_limit else None
    width, first = span, 0  # table row width, first key of a row
    if key is not None and n_groups * span > 2 * len(seq):
        dense = np.cumsum(np.bincount(key, minlength=span) > 0, dtype=np.int32)  # 1 + dense id of each value
        key, width, first = np.take(dense, key), int(dense[-1]), 1
    if key is None or n_groups * width > table_limit:
        group = np.repeat(np.arange(len(slab_counts)), slab_counts)
        keys, code = np.unique(group * span + (seq.astype(np.int64) - lo), return_inverse=True)
        return keys // span, code.reshape(-1), np.bincount(code.reshape(-1), minlength=len(keys))
    ends = np.cumsum(slab_counts)
    for g in blocks:
        if g * width != first:
            key[ends[g] - slab_counts[g]:ends[g]] += np.int32(g * width - first)
    table = np.bincount(key, minlength=n_groups * width)
    keys = np.flatnonzero(table)
    index = np.empty(len(table), np.int32)  # PP index of each present key (every particle's key is present)
    index[keys] = np.arange(len(keys), dtype=np.int32)
    return keys // width, np.take(index, key), table[keys]


def eliminated_per_population(pp_block: np.ndarray, counts: np.ndarray, per_block: int) -> np.ndarray:
    """Eq. 37: particles to remove from each PP so that each block loses ``per_block``,
    smallest PPs first (ties by Seq) and the last one partially."""
    order = np.lexsort((np.arange(len(counts)), counts, pp_block))
    c, b = counts[order], pp_block[order]
    before = np.cumsum(c) - c
    block_start = np.searchsorted(b, b)  # first sorted PP of the same block
    before = before - before[block_start]
    take = np.empty_like(counts)
    take[order] = np.clip(per_block - before, 0, c)
    return take


class NumpyPopulationKernels:
    """Twin of ``PopulationKernels``; uses the ``NumpyParticleKernels`` arrays.  The slabs lie in group
    order, so the live slots in increasing order are the particles in state order."""

    def eliminate(self, b, pp, table, keep, sums) -> None:
        slots = self.live_slots()
        size, take, phase = table[0].astype(np.int64), table[1].astype(np.int64), table[2]
        n_pp = len(size)
        keep[:] = ~spread_removal(rank_in_population(pp.astype(np.int64), size), size[pp], take[pp], phase[pp])
        kept = keep.astype(bool)
        with_e = kept & (self.e[b, slots] == 1)
        sums[:, P_KEPT] = np.bincount(pp, weights=kept, minlength=n_pp)
        sums[:, P_KEPT_E] = np.bincount(pp, weights=with_e, minlength=n_pp)
        sums[:, P_TP] = np.bincount(pp, weights=np.where(kept, self.tp[b, slots], 0), minlength=n_pp)
        sums[:, P_X] = np.bincount(pp, weights=np.where(with_e, self.x[b, slots], 0), minlength=n_pp)
        sums[:, P_Y] = np.bincount(pp, weights=np.where(with_e, self.y[b, slots], 0), minlength=n_pp)
        self._eliminated = (pp.copy(), size, kept)

    def hand_over(self, b, index, counts, decisions, floats, ints, members) -> None:
        drop, rank, cursor = decisions
        pp, size, kept = self._eliminated
        slots = self.live_slots()
        if members:  # the survivors of the ranked PPs, PP by PP (rank order), each in state order
            picked = np.flatnonzero(kept & (rank[pp] >= 0))
            picked = picked[np.argsort(rank[pp[picked]], kind="stable")]
            columns = cursor[0] + np.arange(len(picked))
            for row, name in enumerate(("x", "vx", "y", "vy", "inten")):
                floats[row, columns] = getattr(self, name)[b, slots[picked]]
            for row, name in enumerate(("e", "tp", "seq")):
                ints[row, columns] = getattr(self, name)[b, slots[picked]]
        keep = kept & (drop[pp] == 0)
        h, w = index.shape
        x = np.floor(self.x[b, slots] + np.float32(0.5)).astype(np.int64)
        y = np.floor(self.y[b, slots] + np.float32(0.5)).astype(np.int64)
        seq = self.seq[b, slots]
        inside = keep & (x >= 0) & (x < w) & (y >= 0) & (y < h) & (seq > 0)
        order = stable_order(size[pp][inside])  # larger PPs written last win, then later particles
        index[:] = 0
        index[y[inside][order], x[inside][order]] = seq[inside][order]
        self.keep_particles(b, keep)
        counts[:] = self.n

    def number_populations(self, b, io) -> None:
        """Twin of ``NumberingKernels.number_populations``: ``io[0]``, Eq. 37's quota in, the number of PPs out."""
        pp_block, pp, size = slab_populations(self.n, self.seq[b, self.live_slots()])
        self._numbers = (pp.astype(np.int32), size, eliminated_per_population(pp_block, size, int(io[0])))
        io[0] = len(size)

    def eliminate_and_hand_over_numbered(self, b, phase, rule, index, counts, outcome, floats, ints) -> None:
        pp, size, take = self._numbers
        self.eliminate_and_hand_over(b, pp, np.array([size, take, phase], np.float64), rule, index, counts, outcome,
                                     floats, ints)

    def eliminate_and_hand_over(self, b, pp, table, rule, index, counts, outcome, floats, ints) -> None:
        sums = np.zeros((table.shape[1], N_PP_SUMS))
        self.eliminate(b, pp, table, np.zeros(len(pp), np.int8), sums)
        drop, rank = potential_targets(sums, rule)
        kept = sums[:, P_KEPT].astype(np.int32)
        sizes = kept[rank >= 0]
        decisions = np.zeros((3, len(rank)), np.int32)  # hand_over's: drop, rank, each rank's first column
        decisions[0], decisions[1] = drop, rank
        decisions[2, :len(sizes)] = np.cumsum(sizes) - sizes
        self.hand_over(b, index, counts, decisions, floats, ints, True)
        outcome[0], outcome[1] = rank, kept


class NumpySearchingKernels(NumpyParticleKernels, NumpyPopulationKernels):
    """Twin of ``kernels.populations.SearchingKernels``: the pool's arrays and steps with Eqs. 37–38
    (SGDS-PF's ``SearchingPool``)."""
