"""SGDS-PF's searching pool: the generic particle pool plus the particle-population bookkeeping of the
searching PFs (Eqs. 36–38): Eq. 37's spread-out elimination, Eq. 38's sums, the hand-over of potential
targets and the index image P_pp (Eq. 36).

The per-particle work runs in ``kernels.populations.PopulationKernels`` (Taichi) or
``numpy_kernels.populations.NumpyPopulationKernels`` (NumPy), mixed into the pool's kernels by
:class:`SearchingKernels`-style classes chosen in :meth:`SearchingPool._kernels_class`.
"""
from __future__ import annotations

import numpy as np

from ...errors import ParameterError
from ...kernels.particles.layout import FLOAT_STATE, INT_STATE
from ...kernels.populations import N_PP_SUMS, P_KEPT
from ...particles import ParticlePool


class SearchingPool(ParticlePool):
    """A :class:`~tbd_taichi.particles.ParticlePool` whose groups are SGDS-PF's searching PFs (one per search
    block), with the particle populations' elimination and hand-over on the pool's own fields.  Particles are
    addressed in state order (group, then slot), as :meth:`~tbd_taichi.particles.ParticlePool.state` lists them."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self._eliminated = None  # (particles, populations) of the last eliminate, until its hand_over
        self._numbered = None  # (populations, changes) of the last step with a quota (``ParticlePool.changes``)

    def step(self, frame: int, z: np.ndarray, n_out=None, systematic: bool = False, top_up=None,
             seq_out: np.ndarray | None = None, quota: int | None = None):
        """:meth:`ParticlePool.step`; with ``quota``, the populations it numbers serve
        :meth:`eliminate_and_hand_over_numbered` until the pool changes."""
        return self._kept_numbers(super().step(frame, z, n_out, systematic, top_up, seq_out, quota), quota)

    def step_with(self, other: ParticlePool, frame: int, z: np.ndarray, top_up=None,
                  seq_out: np.ndarray | None = None, quota: int | None = None) -> tuple:
        """:meth:`ParticlePool.step_with`, keeping the numbered populations as :meth:`step` does."""
        read, estimates = super().step_with(other, frame, z, top_up, seq_out, quota)
        return self._kept_numbers(read, quota), estimates

    def _kept_numbers(self, read, quota):
        """A step's read-out ``read``, kept (with the pool's change count) as the numbered populations when the
        step had a ``quota``; returned as it is."""
        self._numbered = None if quota is None else (read, self.changes)
        return read

    def _read_out_buffer(self, seq_out, quota, n_out: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        """:meth:`ParticlePool._read_out_buffer`; with ``quota`` (Eq. 37's particles a group, a whole number in
        [0, 2³¹)), a one-element array holding it, the step's ``seq`` argument that returns the number of
        populations."""
        if quota is None:
            return super()._read_out_buffer(seq_out, quota, n_out)
        if seq_out is not None:
            raise ParameterError("a step reads either the particles' Seq or their populations' number, not both")
        if not isinstance(quota, (int, np.integer)) or not 0 <= int(quota) < 2 ** 31:
            raise ParameterError(f"quota must be a whole number of particles in [0, 2³¹), got {quota!r}")
        return np.array([int(quota)], np.int32), None

    @staticmethod
    def _kernels_class(engine: str):
        """The pool's kernels with the population kernels mixed in."""
        if engine == "taichi":
            from ...kernels.populations import SearchingKernels

            return SearchingKernels
        from ...numpy_kernels.populations import NumpySearchingKernels

        return NumpySearchingKernels

    def eliminate(self, pp, size, take, phase) -> tuple[np.ndarray, np.ndarray]:
        """Eq. 37 on the device: particle s (state order) belongs to population pp[s] of ``size[k]``
        particles, ``take[k]`` of which go, spread over the population by ``phase[k]`` ∈ [0, 1).
        Returns the survivors' flags (state order) and per population the sums over survivors
        (columns ``kernels.populations.P_*``: count, count with E = 1, Σ Tp, Σ x and Σ y with E = 1).
        The pool is unchanged until :meth:`hand_over`, which must come next."""
        pp, table, n = self._population_table(pp, size, take, phase)
        self._numbered = None
        keep = np.zeros(n, np.int8)
        sums = np.zeros((table.shape[1], N_PP_SUMS))
        if n:
            self.k.eliminate(self.buf, pp, table, keep, sums)
        self._eliminated = (n, sums[:, P_KEPT].astype(np.int64))  # particles, and survivors per population
        return keep.view(bool), sums  # 0 or 1 in int8

    def _population_table(self, pp, size, take, phase) -> tuple[np.ndarray, np.ndarray, int]:
        """Checked :meth:`eliminate` arguments: (pp as int32, the (size, take, phase) table in f64, live particles)."""
        pp = np.ascontiguousarray(pp, dtype=np.int32).reshape(-1)
        table = np.array([size, take, phase], dtype=np.float64).reshape(3, -1)
        n = int(self.counts.sum())
        if pp.shape != (n,):
            raise ParameterError(f"need one population index per live particle ({n}), got {pp.shape}")
        if n and (pp.min() < 0 or pp.max() >= table.shape[1]):
            raise ParameterError(f"population indices must lie in [0, {table.shape[1]})")
        size, take, phase = table
        if (size < 1).any() or (take < 0).any() or (take > size).any() or ((phase < 0) | (phase >= 1)).any():
            raise ParameterError("need per population a size ≥ 1, a take in [0, size] and a phase in [0, 1)")
        return pp, table, n

    def _check_index_image(self, index: np.ndarray) -> None:
        if index.shape != self.frame_shape or index.dtype != np.int32 or not index.flags.c_contiguous:
            raise ParameterError(f"index image must be a C-contiguous int32 array of shape {self.frame_shape}")

    @staticmethod
    def _members(floats: np.ndarray, ints: np.ndarray, m: int) -> dict:
        """The handed-over particles' states from the kernels' member columns 0…m − 1."""
        states = dict(zip(FLOAT_STATE, floats[:, :m]))
        states.update(zip(INT_STATE, ints[:, :m]))
        return states

    def eliminate_and_hand_over(self, pp, size, take, phase, index: np.ndarray, t_ptp: float, t_pe: float,
                                tracked, radius: float, most: int) -> tuple[dict, list]:
        """:meth:`eliminate` and :meth:`hand_over` in one launch, the host's drop and hand-over choice made on the
        device by Algorithm 1's rule from Eq. 38's sums: a PP with survivors, some of them E = 1, PTp > ``t_ptp``
        and PE > ``t_pe`` is a potential target; it is dropped if its mean position (E = 1 survivors) lies
        closer than ``radius`` px to one of ``tracked`` [(x, y), …] (a tracked target), else handed over and
        dropped, in PP order, while fewer than ``most`` are.  Returns ``hand_over``'s (states, sizes) of the
        handed PPs."""
        pp, table, n = self._population_table(pp, size, take, phase)
        return self._decide_and_hand_over(lambda *out: self.k.eliminate_and_hand_over(self.buf, pp, table, *out),
                                          table.shape[1], n, index, (t_ptp, t_pe, tracked, radius, most))

    def eliminate_and_hand_over_numbered(self, phase, index: np.ndarray, t_ptp: float, t_pe: float, tracked,
                                         radius: float, most: int) -> tuple[dict, list]:
        """:meth:`eliminate_and_hand_over` of the populations that the step just before numbered on the device
        (``step(…, quota=…)``: their particles, sizes and Eq. 37 quotas never come to the host), PP k spread by
        ``phase[k]`` ∈ [0, 1), one per population."""
        if self._numbered is None or self._numbered[1] != self.changes:
            raise ParameterError("eliminate_and_hand_over_numbered needs a step with a quota just before, "
                                 "with no change of the pool between them")
        n_pp = self._numbered[0]
        phase = np.ascontiguousarray(phase, dtype=np.float64).reshape(-1)
        if phase.shape != (n_pp,):
            raise ParameterError(f"need one phase per population ({n_pp}), got {phase.shape[0]}")
        if ((phase < 0) | (phase >= 1)).any():
            raise ParameterError("every phase must lie in [0, 1)")
        return self._decide_and_hand_over(lambda *out: self.k.eliminate_and_hand_over_numbered(self.buf, phase, *out),
                                          n_pp, int(self.counts.sum()), index, (t_ptp, t_pe, tracked, radius, most))

    def _decide_and_hand_over(self, launch, n_pp: int, n: int, index: np.ndarray, rule: tuple) -> tuple[dict, list]:
        """The launch of an ``eliminate_and_hand_over`` kernel, ``launch(rule, index, counts, outcome, floats,
        ints)``, over n particles in ``n_pp`` populations; ``rule``: (T_PTp, T_PE, tracked, radius, most)."""
        self._check_index_image(index)
        self._eliminated = self._numbered = None  # the launch rewrites the populations' tables
        t_ptp, t_pe, tracked, radius, most = rule
        tracked = np.asarray(tracked, np.float64).reshape(-1, 2)
        rule = np.concatenate([[t_ptp, t_pe, radius * radius, max(int(most), 0), len(tracked)], tracked.ravel()])
        outcome = np.full((2, n_pp), -1, np.int32)  # per PP: hand-over rank, survivors
        floats = np.empty((len(FLOAT_STATE), max(n, 1)), np.float32)
        ints = np.empty((len(INT_STATE), floats.shape[1]), np.int32)
        if n:
            counts = np.empty(self.n_groups, np.int32)
            launch(rule, index, counts, outcome, floats, ints)
            self.counts = counts
        else:
            index[...] = 0
        sizes = outcome[1, outcome[0] >= 0]
        return self._members(floats, ints, int(sizes.sum())), sizes.tolist()

    def hand_over(self, drop, index: np.ndarray, handed=None) -> tuple[dict, list] | None:
        """After :meth:`eliminate`: remove its eliminated particles and those of the populations
        flagged in ``drop``; write the index image P_pp (Eq. 36) into ``index`` (H, W, int32): each
        pixel gets the Seq of the kept particles in it, those of the larger population winning, then
        the later in state order (0: none).  ``handed`` (population indices, usually among the dropped):
        the same launch first reads their particles that survived the elimination, and returns
        (states, sizes): arrays x, vx, y, vy, inten, e, tp, seq holding population after population in
        ``handed`` order, each in state order, and the number of each."""
        if self._eliminated is None:
            raise ParameterError("hand_over needs an eliminate first")
        n, kept = self._eliminated
        n_pp = len(kept)
        drop = np.ascontiguousarray(drop, dtype=np.int8).reshape(-1)
        if drop.shape != (n_pp,):
            raise ParameterError(f"need one drop flag per population ({n_pp}), got {drop.shape}")
        self._check_index_image(index)
        want = handed is not None
        handed = np.asarray(handed if want else [], np.int64).reshape(-1)
        if len(handed) and (handed.min() < 0 or handed.max() >= n_pp or len(np.unique(handed)) < len(handed)):
            raise ParameterError(f"handed populations must be distinct indices in [0, {n_pp})")
        self._eliminated = None
        sizes = kept[handed]
        floats = np.empty((len(FLOAT_STATE), max(int(sizes.sum()), 1)), np.float32)
        ints = np.empty((len(INT_STATE), floats.shape[1]), np.int32)
        if n:
            decisions = np.zeros((3, n_pp), np.int32)  # per PP: drop flag, hand-over rank; per rank: first column
            decisions[0], decisions[1] = drop, -1
            decisions[1, handed] = np.arange(len(handed))
            decisions[2, :len(handed)] = np.cumsum(sizes) - sizes
            counts = np.empty(self.n_groups, np.int32)
            self.k.hand_over(self.buf, index, counts, decisions, floats, ints, want)
            self.counts = counts
        else:
            index[...] = 0
        if not want:
            return None
        return self._members(floats, ints, int(sizes.sum())), sizes.tolist()
