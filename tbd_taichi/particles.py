"""The particle pool scheduler: many independent particle filters in one pool (SGDS-PF section 2.1).

A pool holds G groups (one per search block or track).  Group g owns the fixed slab
[off_g, off_g + cap_g) of slots and has n_g live particles; one kernel launch steps
every group.  The scheduler here owns the bookkeeping (slabs, counts, capacities,
birth proposals, the buffer that holds the current state); the kernels in
``tbd_taichi.kernels.particles`` (or their NumPy twins) do the per-particle work.

One filter step (:meth:`ParticlePool.step`), for every group at once:

1. existence prediction, Eqs. 7–8 (P_b, P_d per group);
2. newborn particles (E 0 → 1) drawn from the group's birth proposal: uniform over a
   region, or from a per-pixel proposal map (the SGDS-PF hook); existing particles
   propagated by the NCV model, Eqs. 9–10, with the process noise Q of Eq. 46
   (q1 = 0.001, q2 = 0.01 by default: the simulator's own values, so the filter's
   motion model matches the scenario it is tested on);
3. log importance weights, Eq. 15 (5×5 window, PSF of Eq. 14, Σ and σ parameters);
4. segmented normalisation, Eq. 16 (per-group log-sum-exp, cumulative sums in f64);
5. segmented resampling, Eqs. 17–18: multinomial (the paper's L independent uniforms,
   drawn in sorted order as normalised sums of exponential spacings, so parents are found
   by a forward walk) or systematic; a group's output count may differ from its input
   count, and offspring sit in parent order;
6. estimates per group (:meth:`ParticlePool.estimates`): Eq. 19 (mean over E = 1
   particles), the existence probability ΣE/n, mean Tp and the positional covariance.

SGDS-PF's particle populations (Eqs. 36–38: elimination, hand-over, the index image) are not part of the
generic pool: ``tbd_taichi.methods.sgds.searching_pool.SearchingPool`` adds them.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import backend
from .engines import check_engine
from .errors import ParameterError
from .kernels.particles.layout import (FLOAT_STATE, INT_STATE, M_BEST, M_E, M_EI, M_EVX, M_EVY, M_EX, M_EXX, M_EXY, M_EY,
                                      M_EYY, M_N, M_TP, M_X, M_XX, M_XY, M_Y, M_YY, N_ESTIMATES, PAD, STATE, TILE)
from .kernels.particles.step import StepOptions

BIRTH_KINDS = {"uniform": 0, "map": 1, "copy": 2}
GROUP_PARAMS = ("pb", "pd", "mu", "bx0", "bx1", "by0", "by1", "vmax", "imin", "imax")
SERIAL_PARTICLES = 1 << 16  # up to this many slots, serial loops beat a parallel launch on the CPU
# with at most this many CPU threads the particle loops stay serial at any size: on the 2-core VM a step of
# 392,000 particles in 49 groups (1024×1024 at the SNR 1.4 preset) takes 29 ms serial and 37 ms parallel
SERIAL_THREADS = 2
SPLIT_PARTICLES = 1 << 14


def tile_threads(capacity: int, n_tiles: int, flat: bool) -> int:
    """CPU threads that share the tile loops (1: serial): the pinned workers (``backend.pinned_workers``),
    for pools of at least SPLIT_PARTICLES slots.  Unpinned, the workers often share one CPU and a
    split loop only pays the thread pool's start."""
    workers = len(backend.pinned_workers())
    if flat or capacity < SPLIT_PARTICLES or workers < 2:
        return 1
    return min(workers, n_tiles)


def one_thread_per_slot(arch: str) -> bool:
    """Kernel layout: one thread per particle slot (GPUs) or one task per tile of slots (the CPU)."""
    return arch != "cpu"


@dataclass
class GroupEstimates:
    """Per-group estimates after a step (arrays of length G; NaN where a group has no E = 1 particle)."""

    n: np.ndarray  # live particles
    p_exist: np.ndarray  # ΣE / n, the existence probability
    x: np.ndarray  # Eq. 19, px
    vx: np.ndarray  # px/frame
    y: np.ndarray
    vy: np.ndarray
    intensity: np.ndarray  # total intensity (Eq. 14 units)
    tp_mean: np.ndarray  # mean presence count Tp
    cov: np.ndarray  # (G, 2, 2) covariance of all particles' (x, y), px²
    cov_e: np.ndarray  # (G, 2, 2) covariance of the E = 1 particles' (x, y), px² (NaN without any)
    max_logw: np.ndarray  # largest log-weight of an E = 1 particle in the last step


def covariance_from_means(means: np.ndarray) -> np.ndarray:
    """(G, 2, 2) covariances of (x, y) from the columns E[x], E[y], E[x²], E[y²], E[xy] of ``means`` (G, 5)."""
    mx, my, mxx, myy, mxy = means.T
    cov = np.empty((len(means), 2, 2))
    cov[:, 0, 0] = mxx - mx * mx
    cov[:, 1, 1] = myy - my * my
    cov[:, 0, 1] = cov[:, 1, 0] = mxy - mx * my
    return cov


class ParticlePool:
    """A pool of ``len(capacities)`` particle filters with fixed capacities.

    ``frame_shape`` is (H, W) of the frames the filters weigh; ``engine`` is "taichi"
    or "numpy"; ``seed`` keys every random draw.
    """

    def __init__(self, capacities, frame_shape, engine: str = "taichi", seed: int = 0, map_capacity: int = 0,
                 q1: float = 0.001, q2: float = 0.01, psf_sigma: float = 0.7, noise_sigma: float = 1.0,
                 intensity_floor: float = 0.1, arch: str | None = None):
        caps = np.asarray(capacities, dtype=np.int64).reshape(-1)
        check_engine(engine)
        if caps.size == 0 or (caps < 1).any():
            raise ParameterError(f"every group needs a capacity ≥ 1, got {caps.tolist()}")
        if min(q1, q2) < 0 or psf_sigma <= 0 or noise_sigma <= 0:
            raise ParameterError("q1, q2 must be ≥ 0 and psf_sigma, noise_sigma > 0")
        self.engine_name, self.seed = engine, int(seed) & 0xFFFFFFFF
        self.frame_shape = (int(frame_shape[0]), int(frame_shape[1]))
        self.caps = caps.astype(np.int32)
        self.off = (np.cumsum(caps) - caps).astype(np.int32)
        self.capacity = int(caps.sum())
        self.n_groups = len(caps)
        self.q1, self.q2, self.psf_sigma, self.noise_sigma = q1, q2, psf_sigma, noise_sigma
        self.intensity_floor = intensity_floor
        tiles = [(g, int(self.off[g]) + k) for g in range(self.n_groups) for k in range(0, int(caps[g]), TILE)]
        tile_group = np.array([t[0] for t in tiles], np.int32)
        gt0 = np.searchsorted(tile_group, np.arange(self.n_groups)).astype(np.int32)
        gt1 = np.searchsorted(tile_group, np.arange(self.n_groups), side="right").astype(np.int32)
        self.map_capacity = max(int(map_capacity), 1)
        serial, flat, split = self.capacity <= SERIAL_PARTICLES, False, 1
        if engine == "taichi":
            backend.ensure_init(arch)
            flat = one_thread_per_slot(backend.current().arch)
            serial = not flat and (serial or backend.cpu_threads() <= SERIAL_THREADS)
            split = tile_threads(self.capacity, len(tiles), flat)
        Kernels = self._kernels_class(engine)
        self.split = split  # threads sharing the tile loops (kernels.particles.ParticleKernels.for_tiles)
        sizes, layout = (self.capacity, self.n_groups, len(tiles)), (self.map_capacity, serial, flat, split)
        dims = sizes + (self.frame_shape,) + layout  # the Kernels' arguments
        if engine == "taichi":
            from .launch import Launcher

            # the frame's size keys a reused set only as far as a field's shape holds it (kernels read frame_hw)
            shapes = sizes + Kernels.frame_key(self.frame_shape) + layout
            fields = backend.reusable(self, (Kernels.__name__,) + shapes, lambda: Kernels(*dims))
            self.k, fresh = Launcher(fields), not backend.holds_old_values(fields)
        else:
            self.k, fresh = Kernels(*dims), False
        self.counts = np.zeros(self.n_groups, np.int32)
        self.k.set_counts(self.counts)
        self._no_seq = np.zeros(1, np.int32)  # step's Seq output when none is read
        self._z = self._bordered_frame()  # the normalised frame weigh reads, zero-bordered
        self._step_z = self._bordered_frame()  # step's copy of its frame
        self.buf = 0
        self.params = {name: np.zeros(self.n_groups, np.float32) for name in GROUP_PARAMS}
        self.kinds = np.zeros(self.n_groups, np.int32)
        # the pool's set-up, written by one kernel on the Taichi engine; configure_groups writes the same fields
        # again (the group parameters are these very arrays), so that one compiled kernel serves both
        self._setup = {
            "slot_group": np.repeat(np.arange(self.n_groups, dtype=np.int32), caps), "off": self.off,
            "cap": self.caps, "tile_group": tile_group, "tile_start": np.array([t[1] for t in tiles], np.int32),
            "gt0": gt0, "gt1": gt1,
            # C_* (f64 here: the Taichi field rounds to f32 as a scalar argument would, the NumPy twin keeps them)
            "constants": np.array([q1, q2, intensity_floor, psf_sigma, noise_sigma], np.float64),
            "seed_key": np.array([self.seed], np.uint32), "frame_hw": np.array(self.frame_shape, np.int32),
            **self.params, "kind": self.kinds}
        backend.from_host_many(self.k, self._setup)
        if not fresh:  # reused fields (new Taichi fields are zeros); best_e: each group's largest E = 1 log-weight
            backend.zero_many(self.k, ("x", "vx", "y", "vy", "inten", "e", "tp", "seq", "logw", "born", "best_e"))
        self.set_proposal_map({})

    @staticmethod
    def _kernels_class(engine: str):
        """The kernels behind the pool: ``kernels.particles.ParticleKernels`` or its NumPy twin (a subclass of the
        pool may add kernels of its own, as SGDS-PF's ``SearchingPool`` does)."""
        if engine == "taichi":
            from .kernels.particles import ParticleKernels

            return ParticleKernels
        from .numpy_kernels.particles import NumpyParticleKernels

        return NumpyParticleKernels

    # ------------------------------------------------------------ host ↔ engine

    def _put(self, name: str, array: np.ndarray) -> None:
        backend.from_host(getattr(self.k, name), array)

    def _get(self, name: str) -> np.ndarray:
        return backend.to_host(getattr(self.k, name))

    # ------------------------------------------------------------ configuration

    def configure_groups(self, groups, kind: str = "uniform", pb: float = 0.05, pd: float = 0.05,
                         region=None, vmax: float = 1.0, intensity=(1.0, 10.0), mu: float = 0.5) -> None:
        """Set the birth/death model and birth proposal of ``groups`` (indices).

        ``kind``: "uniform" over ``region`` = (x0, x1, y0, y1) px (default: the whole image,
        [−½, W−½) × [−½, H−½)), "map" (the group's proposal map) or "copy" (a random E = 1
        particle of the group: tracking PFs).  ``vmax`` px/frame; ``intensity`` = (I_min, I_max);
        ``mu`` the existence probability of initial particles added by the top-up of :meth:`predict` (Eq. 34).
        """
        if kind not in BIRTH_KINDS:
            raise ParameterError(f"birth kind must be one of {', '.join(BIRTH_KINDS)}, got {kind!r}")
        if not (0 <= pb <= 1 and 0 <= pd <= 1 and 0 <= mu <= 1) or vmax < 0 or intensity[0] > intensity[1]:
            raise ParameterError("need 0 ≤ pb, pd, mu ≤ 1, vmax ≥ 0 and I_min ≤ I_max")
        h, w = self.frame_shape
        x0, x1, y0, y1 = region if region is not None else (-0.5, w - 0.5, -0.5, h - 0.5)
        groups = np.atleast_1d(np.asarray(groups, dtype=np.int64))
        values = dict(pb=pb, pd=pd, mu=mu, bx0=x0, bx1=x1, by0=y0, by1=y1, vmax=vmax, imin=intensity[0], imax=intensity[1])
        for name, value in values.items():
            self.params[name][groups] = value
        self.kinds[groups] = BIRTH_KINDS[kind]
        backend.from_host_many(self.k, self._setup)  # self.params and self.kinds are its arrays

    def set_proposal_map(self, per_group: dict, labels: np.ndarray | None = None) -> None:
        """Per-pixel birth proposals: {group: (pixel indices y·W + x, weights ≥ 0)}; cumulative weights in f64.
        A particle drawn from a pixel takes that pixel's PP label in ``labels`` (H, W) as its Seq (Eq. 36; 0
        without labels)."""
        maps = [(np.asarray(pix, np.int32), np.cumsum(np.asarray(wts, np.float64))) for pix, wts in
                (per_group.get(g, (np.zeros(0), np.zeros(0))) for g in range(self.n_groups))]
        count = np.array([len(pix) for pix, _ in maps], np.int32)
        off, pos = (np.cumsum(count) - count).astype(np.int32), int(count.sum())
        total = np.array([c[-1] if len(c) else 0.0 for _, c in maps])
        pixels, cdf = [pix for pix, _ in maps if len(pix)], [c for _, c in maps if len(c)]
        if pos > self.map_capacity:
            raise ParameterError(f"proposal maps hold {pos} pixels, more than the pool's map capacity {self.map_capacity}")
        if labels is not None and np.shape(labels) != self.frame_shape:
            raise ParameterError(f"labels must have the frame's shape {self.frame_shape}, got {np.shape(labels)}")
        full_pix = np.concatenate(pixels) if pixels else np.zeros(1, np.int32)
        full_cdf = np.concatenate(cdf) if cdf else np.zeros(1)
        seq = np.zeros(len(full_pix), np.int32) if labels is None or not pixels else \
            np.asarray(labels).reshape(-1)[full_pix].astype(np.int32)
        self.k.load_map(off, count, total, full_pix.astype(np.int32), seq, full_cdf)

    @property
    def counts(self) -> np.ndarray:
        """Live particles per group.  Every launch that changes the particles sets it anew, and each new value
        counts one more in ``changes`` (what a subclass's results computed on the device are valid for)."""
        return self._counts

    @counts.setter
    def counts(self, value: np.ndarray) -> None:
        self._counts, self.changes = value, getattr(self, "changes", -1) + 1

    def set_counts(self, counts) -> None:
        """Set the live particle count of every group (checked against its capacity)."""
        self.counts = self._checked_counts(counts, "live count")
        self.k.set_counts(self.counts)

    def _checked_counts(self, counts, what: str) -> np.ndarray:
        """``counts`` as int32, one per group, each within its group's capacity (else ParameterError)."""
        counts = np.asarray(counts, dtype=np.int64).reshape(-1)
        if counts.shape != (self.n_groups,):
            raise ParameterError(f"need one {what} per group ({self.n_groups}), got {counts.shape}")
        over = np.flatnonzero((counts > self.caps) | (counts < 0))
        if over.size:
            g = int(over[0])
            raise ParameterError(f"group {g}: {what} {int(counts[g])} exceeds its capacity {int(self.caps[g])} "
                                 f"(or is negative); the pool is unchanged")
        return counts.astype(np.int32)

    def max_log_weights(self) -> np.ndarray:
        """Per group, the largest log-weight of an E = 1 particle in the last :meth:`weigh` (−3e38: none)."""
        return self._get("best_e").astype(np.float64)

    # ------------------------------------------------------------ state

    def state(self) -> dict:
        """Live particles of the current buffer: arrays x, vx, y, vy, inten, e, tp, seq, group, slot, logw."""
        return self.states_at(np.arange(int(self.counts.sum())))

    def _slots_in_order(self, group: np.ndarray, per_group: np.ndarray) -> np.ndarray:
        """Slots of particles listed by non-decreasing ``group``: each group's k-th goes to off_g + k."""
        start = np.cumsum(per_group) - per_group
        return (self.off[group] + np.arange(len(group)) - start[group]).astype(np.int32)

    def set_state(self, group_states: dict) -> None:
        """Load particles: {group: dict of arrays x, vx, y, vy, inten, e, tp[, seq]}; sets the live counts
        of those groups (the others keep theirs)."""
        groups = np.array(sorted(group_states), dtype=np.int64)
        sizes = [len(group_states[g]["x"]) for g in groups]
        cols = {name: np.concatenate([np.broadcast_to(group_states[g].get(name, 0), n) for g, n in zip(groups, sizes)])
                if sizes else np.zeros(0) for name in STATE}
        self.load_states(np.repeat(groups, sizes), cols, groups)

    def load_states(self, group: np.ndarray, cols: dict, groups=None) -> None:
        """Load particles given as flat arrays: ``group`` (non-decreasing group of each particle) and
        ``cols`` {x, vx, y, vy, inten, e, tp[, seq]}; the live count of every group in ``groups``
        (default: all) becomes its number of particles, in one kernel launch."""
        group = np.asarray(group, dtype=np.int64)
        if len(group) and (np.diff(group) < 0).any():
            raise ParameterError("particles must be ordered by group")
        per_group = np.bincount(group, minlength=self.n_groups)[: self.n_groups]
        counts = self.counts.astype(np.int64).copy()
        touched = np.arange(self.n_groups) if groups is None else np.asarray(groups, dtype=np.int64)
        counts[touched] = per_group[touched]
        counts = self._checked_counts(counts, "particle count")
        if not len(group):
            self.set_counts(counts)
            return
        slots = self._slots_in_order(group, per_group)
        floats = np.empty((len(FLOAT_STATE), len(group)), np.float32)
        ints = np.empty((len(INT_STATE), len(group)), np.int32)
        for rows, names in ((floats, FLOAT_STATE), (ints, INT_STATE)):
            for row, name in zip(rows, names):
                row[:] = cols.get(name, 0)
        self.k.write_slots(self.buf, slots, floats, ints, counts)
        self.counts = counts

    def keep(self, keep) -> None:
        """Remove particles: ``keep`` holds one flag per live particle in :meth:`state` order; the
        survivors keep their order at the front of their group's slab (one launch)."""
        keep = np.asarray(keep, dtype=bool).reshape(-1)
        if keep.shape != (int(self.counts.sum()),):
            raise ParameterError(f"need one keep flag per live particle ({int(self.counts.sum())}), got {keep.shape}")
        self.k.keep_particles(self.buf, keep.view(np.int8))
        self.counts = self._counts_kept(keep)

    def _counts_kept(self, kept: np.ndarray) -> np.ndarray:
        """Live counts per group after keeping the particles flagged in ``kept`` (state order)."""
        before = np.concatenate(([0], np.cumsum(kept, dtype=np.int64)))
        ends = np.cumsum(self.counts, dtype=np.int64)
        return (before[ends] - before[ends - self.counts]).astype(np.int32)

    def seq_in_state_order(self, out: np.ndarray | None = None) -> np.ndarray:
        """The Seq (particle-population label, Eq. 36) of every live particle, in :meth:`state` order;
        into the front of ``out`` (int32, at least that long) if given, which saves a fresh array per frame."""
        seq = self._seq_buffer(out, int(self.counts.sum()))
        if len(seq):
            self.k.read_seq(self.buf, seq)
        return seq

    @staticmethod
    def _seq_buffer(out: np.ndarray | None, n: int) -> np.ndarray:
        """The first n elements of ``out`` (checked: C-contiguous int32, long enough), or a new array."""
        if out is None:
            return np.empty(n, np.int32)
        if out.dtype != np.int32 or out.ndim != 1 or len(out) < n or not out.flags.c_contiguous:
            raise ParameterError(f"out must be a C-contiguous int32 array of at least {n} elements")
        return out[:n]

    def states_at(self, index) -> dict:
        """Like :meth:`state`, for the live particles at positions ``index`` of the state order."""
        index = np.asarray(index, dtype=np.int64).reshape(-1)
        ends = np.cumsum(self.counts, dtype=np.int64)
        group = np.searchsorted(ends, index, side="right")
        slots = (self.off[group] + index - (ends - self.counts)[group]).astype(np.int32)
        floats = np.empty((len(FLOAT_STATE) + 1, len(slots)), np.float32)  # and the log-weight
        ints = np.empty((len(INT_STATE), len(slots)), np.int32)
        if len(slots):
            self.k.read_slots(self.buf, slots, floats, ints)
        out = dict(zip(FLOAT_STATE + ("logw",), floats))
        out.update(zip(INT_STATE, ints))
        out.update(group=group, slot=slots.astype(np.int64))
        return out

    # ------------------------------------------------------------ one step

    def _bordered_frame(self) -> np.ndarray:
        """A zero frame with the kernels' border of PAD pixels, (H + 2·PAD, W + 2·PAD) float32."""
        h, w = self.frame_shape
        return np.zeros((h + 2 * PAD, w + 2 * PAD), np.float32)

    def _into_border(self, z: np.ndarray, out: np.ndarray) -> np.ndarray:
        """z (H, W) copied into the middle of the bordered frame ``out`` (float32; its border stays 0).
        The weights read the frame through the border, so a 5×5 window at the edge needs no tests;
        one NumPy copy costs a few µs, a kernel loop writing a padded field 0.09 ms at 320×256."""
        z = np.asarray(z)
        if z.shape != self.frame_shape:
            raise ParameterError(f"frame has shape {z.shape}; the pool was built for {self.frame_shape}")
        np.copyto(out[PAD:-PAD, PAD:-PAD], z, casting="unsafe")
        return out

    def load_frame(self, z: np.ndarray) -> None:
        """The normalised frame the next weights use (H, W), float32.  The pool keeps a copy: the
        weights read it when ``weigh`` runs, and the caller may reuse its array before that."""
        self._into_border(z, self._z)

    def predict(self, frame: int, top_up=None) -> None:
        """Steps 1–2: existence (Eqs. 7–8), newborn and initial draws, NCV propagation (Eqs. 9–10).

        ``top_up`` (optional counts per group) grows the groups after the existence step; the
        added slots become initial particles, drawn in the same launch as the newborns (Eq. 35)."""
        counts = self._topped_up(top_up)
        self.k.predict(frame, self.buf, counts)
        self.counts = counts

    def _topped_up(self, top_up) -> np.ndarray:
        """Live counts after the existence step: max(top_up, counts), checked (the counts if None)."""
        if top_up is None:
            return self.counts
        return self._checked_counts(np.maximum(np.asarray(top_up, np.int64).reshape(-1), self.counts), "live count")

    def weigh(self) -> None:
        """Steps 3–4: log-weights (Eq. 15) and the segmented normalisation (Eqs. 16–17)."""
        self.k.weigh(self.buf, self._z)

    def normalise(self) -> None:
        """Step 4 on the current log-weights: per-group maxima and f64 cumulative sums (Eqs. 16–17)."""
        self.k.normalise(self.buf)

    def _resampled_counts(self, n_out, live=None) -> np.ndarray:
        """Checked output counts per group (default: the ``live`` counts, by default the current ones;
        0 for an empty group)."""
        live = self.counts if live is None else live
        n_out = live if n_out is None else self._checked_counts(n_out, "resampled count")
        return np.where(live > 0, n_out, 0).astype(np.int32)

    def resample(self, frame: int, n_out=None, systematic: bool = False) -> None:
        """Step 5 (Eqs. 17–18): each group draws ``n_out[g]`` particles (default: its live count)."""
        n_out = self._resampled_counts(n_out)
        self.k.resample(frame, self.buf, n_out, bool(systematic))
        self.buf = 1 - self.buf
        self.counts = n_out

    def step(self, frame: int, z: np.ndarray, n_out=None, systematic: bool = False, top_up=None,
             seq_out: np.ndarray | None = None, quota: int | None = None):
        """One full filter step on normalised frame ``z`` for every group: predict (with ``top_up``),
        weigh and resample in one launch (``z`` serves this step only; ``weigh`` keeps using the last
        ``load_frame``).  ``n_out`` defaults to the live counts after the top-up.  With ``seq_out``
        (as for :meth:`seq_in_state_order`) the same launch also reads the resampled particles' Seq,
        and the filled front of ``seq_out`` is returned.  With ``quota`` (SGDS-PF's ``SearchingPool``) it numbers
        the particle populations, Eq. 37's ``quota`` particles a group, on the device and returns their number."""
        z = self._into_border(z, self._step_z)
        counts = self._topped_up(top_up)
        n_out = self._resampled_counts(n_out, counts)
        out, seq = self._read_out_buffer(seq_out, quota, n_out)
        self.k.step(frame, self.buf, counts, n_out, z, out,
                    StepOptions.of(systematic, seq is not None, self._fused_step(), quota is not None))
        self.buf = 1 - self.buf
        self.counts = n_out
        return int(out[0]) if quota is not None else seq

    def step_with(self, other: "ParticlePool", frame: int, z: np.ndarray, top_up=None,
                  seq_out: np.ndarray | None = None, quota: int | None = None) -> tuple:
        """:meth:`step` of this pool (with ``top_up``, ``seq_out`` and ``quota``) and of ``other`` (its live
        counts) on the same frame, then ``other``'s :meth:`estimates`: the same results as those three calls, in
        one launch where the kernels allow (:meth:`pairs_with`), so the threads that share this pool's
        groups share ``other``'s as well.  Returns (what :meth:`step` returns, ``other``'s estimates)."""
        if not self.pairs_with(other):
            read = self.step(frame, z, top_up=top_up, seq_out=seq_out, quota=quota)
            other.step(frame, z)
            return read, other.estimates()
        z = self._into_border(z, self._step_z)
        counts = self._topped_up(top_up)
        n_out = self._resampled_counts(None, counts)
        out, seq = self._read_out_buffer(seq_out, quota, n_out)
        moments = np.empty((other.n_groups, N_ESTIMATES))
        # other steps at its live counts, which its kernels hold (``n``) as every launch that changes them sets them
        self.k.step_pair(other.k._target, frame, self.buf, other.buf, n_out, z, out,
                         StepOptions.of(False, seq is not None, True, quota is not None), moments)
        for pool, out_counts in ((self, n_out), (other, other.counts)):
            pool.buf, pool.counts = 1 - pool.buf, out_counts
        return int(out[0]) if quota is not None else seq, other._estimates_from(moments)

    def _read_out_buffer(self, seq_out, quota, n_out: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        """The step's ``seq`` argument and the Seq it reads (None: none): the front of ``seq_out`` (an empty read
        travels as the 1-element spare); a ``quota`` needs a pool that numbers populations (``SearchingPool``)."""
        if quota is not None:
            raise ParameterError("this pool's kernels do not number particle populations (quota)")
        seq = None if seq_out is None else self._seq_buffer(seq_out, int(n_out.sum()))
        return (seq if seq is not None and len(seq) else self._no_seq), seq

    def pairs_with(self, other: "ParticlePool") -> bool:
        """Whether :meth:`step_with` can step ``other`` in this pool's launch: both on Taichi's CPU layout with
        the same frame shape and the same motion, PSF, noise and intensity-floor constants, and this pool either
        fused with whole groups per thread or, like ``other``, serial and unsplit (one thread steps both pools'
        groups, as their own serial steps would)."""
        same = (self.frame_shape, self.q1, self.q2, self.psf_sigma, self.noise_sigma, self.intensity_floor) == \
            (other.frame_shape, other.q1, other.q2, other.psf_sigma, other.noise_sigma, other.intensity_floor)
        if not (same and self.engine_name == other.engine_name == "taichi") or self.k.flat or other.k.flat:
            return False
        if self.split == 1:
            return self.k.serial and other.k.serial and other.split == 1
        return self._fused_step() and self.k.tiles_by_group

    def _fused_step(self) -> bool:
        """Whether ``step`` runs as the kernels' three-pass ``fused_step``: split tile loops, and copying
        groups (kind 2) only where whole groups go to each thread (``tiles_by_group``), since a copy
        reads other slots of its group."""
        return self.split > 1 and (self.k.tiles_by_group or not (self.kinds == BIRTH_KINDS["copy"]).any())

    def normalised_weights(self) -> np.ndarray:
        """Eq. 16 per live particle, in :meth:`state` order (for tests and diagnostics)."""
        lw, gmax, total = self._get("logw"), self._get("gmax"), self._get("gtotal")
        out = []
        for g in range(self.n_groups):
            s = slice(int(self.off[g]), int(self.off[g] + self.counts[g]))
            out.append(np.exp(lw[s].astype(np.float64) - np.float64(gmax[g])) / total[g])
        return np.concatenate(out) if out else np.zeros(0)

    def estimates(self) -> GroupEstimates:
        """Eq. 19, existence probability, mean Tp and covariances per group (current buffer)."""
        m = np.empty((self.n_groups, N_ESTIMATES))
        self.k.estimates(self.buf, m)
        return self._estimates_from(m)

    def _estimates_from(self, m: np.ndarray) -> GroupEstimates:
        """:meth:`estimates` from the kernels' per-group sums ``m`` (G, N_ESTIMATES)."""
        n, ne = m[:, M_N], m[:, M_E]
        with np.errstate(invalid="ignore", divide="ignore"):  # the means, NaN where their count is 0
            every = np.where(n[:, None] > 0, m[:, [M_TP, M_X, M_Y, M_XX, M_YY, M_XY]] / n[:, None], np.nan)
            live = np.where(ne[:, None] > 0, m[:, [M_EX, M_EVX, M_EY, M_EVY, M_EI, M_EXX, M_EYY, M_EXY]] / ne[:, None],
                            np.nan)
        return GroupEstimates(n.astype(np.int64), np.where(n > 0, ne / np.maximum(n, 1), 0.0), *live[:, :5].T,
                              every[:, 0], covariance_from_means(every[:, 1:]),
                              covariance_from_means(live[:, [0, 2, 5, 6, 7]]), m[:, M_BEST].copy())
