"""MM-PHD track-before-detect over a frame stream (Long et al. 2012, Fig. 1): a detector PHD filter with births
captures targets on the masked frame (Eq. 36), each capture gets a birth-free tracker, a track is confirmed after
``confirm_frames`` consecutive tracked frames (then the backward recursion extends it back, Eqs. 25–27) and halts
after ``halt_drops`` consecutive drops.  All filters are groups of one particle pool: each step is one launch.

Per frame k: every filter predicts (births into the detector); the trackers weigh z_k and give their estimates;
the detector weighs z_k masked with I_0 over the trackers' windows; the trackers' bookkeeping (tracked when
n̂ ≥ drop_below; Eq. 21's Q scale); every filter is resampled to L_max (trackers' mass capped at one target);
the detector's particles are split by k-means into round(n̂) classes, and a class of mass ≥ drop_below that is
6Σ from every tracker becomes a tracker.
"""
from __future__ import annotations

import contextlib
import time
from collections import deque
from dataclasses import dataclass, field

import numpy as np

from ...background import DEFAULT_BACKGROUND, Preprocessor
from ...errors import InputError
from ...kernels.phd import LENGTH, NO_CENTRE
from ...motion_models import VX, VY, X, Y
from ...peak_guard import SETTLE_FRAMES, running_peak_z
from ...tables import TRACK_COLUMNS, _dtype
from ..registry import OneSequence
from ..still_tracks import StillTrackRule
from .backward import BackwardRecursion
from .estimation import Capture, adapted_scale, captures, live_dims, log_det, unpack
from .params import derived, mm_phd_params, pool_capacity
from .pool import PhdPool

STAGES = ("normalise", "particles", "extraction", "backward")
MIN_FRAMES = 3  # §4.2: a track needs three tracked frames
CAPTURE_DRAWS = 1000  # particles drawn ∝ w̃ from the detector for k-means (a new tracker resamples them to L_max)


def track_columns(models) -> tuple[str, ...]:
    """The tracks CSV columns: the common ones, then P_r of Eq. 35 per model (``p_cv``, ``p_c_ct``, …)."""
    return TRACK_COLUMNS + tuple("p_" + m.replace("-", "_") for m in models)


def track_dtype(models) -> np.dtype:
    """The tracks table's dtype for :func:`track_columns` (the tables module's types)."""
    return _dtype(track_columns(models))


@dataclass
class Target:
    """One tracker: its id, particles in the pool, Q scale s (Eq. 21), run lengths and rows
    (frame, track_id, x, y, vx, vy, intensity, n̂, P_r…)."""

    track_id: int
    capture: Capture
    first_frame: int
    count: int
    scale: float = 1.0
    log_det: float | None = None
    streak: int = 1
    drops: int = 0
    confirmed: bool = False
    halted: bool = False
    rows: list = field(default_factory=list)
    position: np.ndarray = field(default_factory=lambda: np.zeros(2))
    velocity: np.ndarray = field(default_factory=lambda: np.zeros(2))
    velocity_sd: float = 0.0
    mass: float = 1.0
    last_frame: int = -1  # the last tracked frame, and the position and velocity there
    last_position: np.ndarray = field(default_factory=lambda: np.zeros(2))
    last_velocity: np.ndarray = field(default_factory=lambda: np.zeros(2))
    peak_z: float = 0.0  # running peak z at its estimates (peak_guard; min_peak_z)
    reported_span: tuple | None = None  # (first, last) frame it was reported in
    reported_frames: int = 0  # frames it was reported in
    first_reported_at: tuple | None = None  # (x, y) where it was first reported
    whole: bool = False  # in the whole paths (methods/still_tracks.py)

    def tracked(self, k: int) -> None:
        """Frame k is tracked: keep it, the position and the velocity as the last tracked ones."""
        self.last_frame, self.last_position, self.last_velocity = k, self.position.copy(), self.velocity.copy()

    def follow(self, mean: np.ndarray, cov: np.ndarray, mass: float, T: float) -> None:
        """The class estimate of this frame: position, velocity (px/s) and its largest standard deviation; an
        empty class (mass 0) keeps the predicted position and the velocity."""
        if mass <= 0:
            self.position = self.position + self.velocity * T
            return
        self.position, self.velocity = mean[[X, Y]], mean[[VX, VY]]
        self.velocity_sd = float(np.sqrt(max(cov[VX, VX], cov[VY, VY], 0.0)))


class StageClock:
    """Wall seconds per stage, exclusive: a stage entered inside another pauses the outer one's count."""

    def __init__(self, stages):
        self.seconds = {s: 0.0 for s in stages}
        self.stack: list[list] = []

    @contextlib.contextmanager
    def __call__(self, stage: str):
        now = time.perf_counter()
        if self.stack:
            outer = self.stack[-1]
            self.seconds[outer[0]] += now - outer[1]
        self.stack.append([stage, now])
        try:
            yield
        finally:
            now = time.perf_counter()
            self.seconds[stage] += now - self.stack.pop()[1]
            if self.stack:
                self.stack[-1][1] = now

    def totals(self) -> dict:
        return dict(self.seconds)


def tracker_start(c: Capture, count: int, vmax: float, fresh: float, rng: np.random.Generator):
    """A new tracker's ``count`` particles: the capture's drawn with replacement, a ``fresh`` share of them with
    the velocity drawn anew from Eq. 29's U[−V_max, V_max] (the detector's likelihood-resampled particles carry
    few distinct velocities, and a target seen once has not shown its velocity yet)."""
    pick = rng.integers(0, len(c.state), count)
    state, model = c.state[pick].copy(), c.model[pick]
    anew = rng.random(count) < fresh
    state[np.ix_(anew, [VX, VY])] = rng.uniform(-vmax, vmax, (int(anew.sum()), 2))
    return state, model


class MMPHDTracker(OneSequence):
    """``update(frame)`` takes one raw frame and returns the rows of confirmed tracks for it (from confirmation
    on); ``finish()`` returns every confirmed track's whole path (capture and backward frames included), or with
    ``history=False`` nothing more (the rows were all output by ``update``; ``online()`` has them)."""

    def __init__(self, shape, seed: int = 0, engine: str = "taichi", arch: str | None = None,
                 background: str = DEFAULT_BACKGROUND, bad_pixels: bool = True, history: bool = True, **params):
        self.shape = (int(shape[0]), int(shape[1]))
        self.p = mm_phd_params(self.shape, **params)
        self.d = derived(self.p)
        self.seed, self.engine, self.arch, self.history = int(seed), engine, arch, history
        self.pool = PhdPool(self.shape, self.p, self.d, pool_capacity(self.p), self.p.max_tracks + 1, seed, engine,
                            arch)
        self.preprocess = Preprocessor(self.shape, background, bad_pixels, engine)
        self.buffer: deque = deque(maxlen=self.p.backward_frames + 1)
        self.dims = live_dims(self.d.models)
        self.columns = track_columns(self.d.models)
        self.targets: list[Target] = []
        self.det_count, self.next_id, self.frame = 0, 1, 0
        self.done_rows: list[tuple] = []
        self.still_rule = StillTrackRule(self.p.still_frames, self.p.still_radius)  # which tracks the whole paths take
        self.online_rows: list[tuple] = []
        self.n_hat_history: list[float] = []
        self.confirmations: dict[int, int] = {}
        self.halted: list[Target] = []  # lost confirmed tracks that a capture may still continue (_revived)
        self.clock = StageClock(STAGES)
        self._backward = None

    @property
    def timings(self) -> dict:
        """Cumulative wall seconds per stage (STAGES): normalise; particles (every kernel step: predict, births,
        likelihood, Ψ, update, class estimates, mask, resample); extraction (k-means captures, bookkeeping, new
        trackers); backward (the backward recursions)."""
        return self.clock.totals()

    def update(self, frame: np.ndarray) -> list[tuple]:
        """Process one raw frame; returns the rows of confirmed tracks at this frame."""
        self._check_open("update")
        with self.clock("normalise"):
            z = self.preprocess(frame, self.frame)
        k = self.frame
        self.buffer.append((k, z))
        with self.clock("particles"):
            n_hat, est = self._filter_step(k, z)
        with self.clock("extraction"):
            released = self._bookkeeping(k, n_hat, est)
            released += self._resample_and_capture(k, n_hat)
        self.n_hat_history.append(float(n_hat[0]))
        self.frame += 1
        self.online_rows.extend(released)
        return released

    def online(self) -> np.ndarray:
        """The rows as ``update`` output them (from confirmation on)."""
        return self._table(self.online_rows)

    def finish(self) -> np.ndarray:
        """Every confirmed track's rows (whole paths); with ``history=False`` none (``update`` output them)."""
        if self.frames_in < MIN_FRAMES:
            raise InputError(f"{self.frames_in} frame(s), but MM-PHD needs at least {MIN_FRAMES} frames "
                             f"(a track is confirmed after {self.p.confirm_frames} tracked frames)")
        self._close_sequence()
        rows = [] if not self.history else self.done_rows + [r for t in self.targets if t.confirmed
                                                             for r in self._kept_rows(t)]
        return self._table(rows)

    def _table(self, rows) -> np.ndarray:
        table = np.array([tuple(r) for r in rows], dtype=track_dtype(self.d.models))
        return np.sort(table, order=["frame", "track_id"])

    # ------------------------------------------------------------------ one frame

    def _filter_step(self, k: int, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Predict all filters (Eqs. 1, 28–34), weigh the trackers on z_k, mask (Eq. 36), weigh the detector."""
        pool, n_tr = self.pool, len(self.targets)
        n_cells = pool.set_frame(z)
        births = self.p.births
        lengths = [self.det_count + births] + [t.count for t in self.targets]
        T, r0 = self.p.frame_interval, self.d.class_radius
        centres = np.array([[NO_CENTRE, NO_CENTRE]] + [t.position + t.velocity * T for t in self.targets])
        radii = [r0] + [r0 + self.p.gate_sigmas * t.velocity_sd * T for t in self.targets]
        total = pool.layout(lengths, [1] + [0] * n_tr, [1.0] + [t.scale for t in self.targets], centres, radii)
        pool.propagate(k, total, n_cells, births)
        pool.weigh(1, n_tr, estimate=True)
        pool.mask(1, n_tr)
        pool.weigh(0, 1, on_likelihood=self.p.detector_resampling == "likelihood", segmented=True)
        n_hat, self.det_top = pool.n_hat()
        return n_hat, pool.estimates()

    def _bookkeeping(self, k: int, n_hat: np.ndarray, est: np.ndarray) -> list[tuple]:
        """Each tracker's frame: tracked (n̂ ≥ drop_below) or dropped, confirmation (then the backward
        recursion), halting, Eq. 21's Q scale; returns the rows released now."""
        p, released = self.p, []
        if not self.targets:
            return released
        stats = [unpack(est[1 + i], len(self.d.models)) for i in range(len(self.targets))]
        z = self.buffer[-1][1]
        for t, e, total in zip(self.targets, stats, n_hat[1:]):
            t.follow(e.mean, e.cov, e.mass, self.p.frame_interval)
            t.peak_z = running_peak_z(t.peak_z, z, *t.position)
            t.mass = e.peak
            if e.peak >= p.drop_below:
                t.drops = 0
                t.tracked(k)
                # a tentative track counts strong frames: a strong peak cell holding most of its PHD mass
                t.streak += t.confirmed or (e.peak >= p.confirm_above and e.mass >= p.confirm_share * total)
                t.rows.append(self._row(k, t.track_id, e.mean, e.probs, e.peak))
                if not t.confirmed and t.streak >= p.confirm_frames:
                    self._confirm(t, k)
                if self._reported(t, k):
                    released.append(t.rows[-1])
            else:
                t.streak, t.drops = 0, t.drops + 1
                t.halted = t.drops >= p.halt_drops
        self._exclude_duplicates()
        if p.adaptive_q:
            now = np.array([log_det(e.cov, self.dims) for e in stats])
            before = np.array([now[i] if t.log_det is None else t.log_det for i, t in enumerate(self.targets)])
            scales = adapted_scale(np.array([t.scale for t in self.targets]), now, before, p.q_max_ratio)
            for t, s, ld in zip(self.targets, scales, now):
                t.scale, t.log_det = float(s), float(ld)
        return released

    def _exclude_duplicates(self) -> None:
        """Targets are ≥ 6Σ apart (Eq. 12): of two live trackers closer than that, the younger halts."""
        gap = 6.0 * self.p.psf_sigma
        live = [t for t in self.targets if not t.halted]
        for i, a in enumerate(live):
            for b in live[i + 1:]:
                if not a.halted and not b.halted and np.hypot(*(a.position - b.position)) < gap:
                    b.halted = True

    def _confirm(self, t: Target, k: int) -> None:
        """Confirmation at frame k: the backward recursion from the capture frame (Eqs. 25–27) prepends rows."""
        t.confirmed = True
        self.confirmations[t.track_id] = k
        if not self.p.backward:
            return
        with self.clock("backward"):
            if self._backward is None:
                self._backward = BackwardRecursion(self.shape, self.p, self.d, self.seed, self.engine, self.arch)
            earlier = [(f, z) for f, z in reversed(self.buffer) if f < t.first_frame]
            back = self._backward.rows(t.capture, earlier, t.track_id)
        t.rows[:0] = [self._row(f, t.track_id, mean, probs, nh) for f, mean, probs, nh in reversed(back)]

    def _resample_and_capture(self, k: int, n_hat: np.ndarray) -> list[tuple]:
        """The detector's captures (before resampling), then every filter resampled to L_max (ended trackers
        dropped; a tracker's mass at most one target), then the captures become trackers: tentative ones, or the
        continuation of a confirmed track that halted within revive_frames near there (:meth:`_revived`); returns
        the rows of the continued tracks."""
        p, L = self.p, self.p.max_particles
        det_len = int(self.pool.gint[0, LENGTH])
        found = self._captures(k, n_hat[0], det_len) \
            if round(n_hat[0]) >= 1 and self.det_top[0] >= p.capture_above else []
        self._evict_faint(k, len(found))
        out_len = [L] + [L] * len(self.targets)
        weights = [n_hat[0] / L] + [1.0 / L] * len(self.targets)  # a tracker holds one target (see docs)
        keep = [True] + [not t.halted for t in self.targets]
        with self.clock("particles"):
            offset = self.pool.resample(k, out_len, weights, keep, room=p.births)
        for t in self.targets:
            if t.halted and t.confirmed:
                self.done_rows.extend(self._kept_rows(t))
                self.still_rule.ended(t, tuple(float(v) for v in t.position))
                if t.drops >= p.halt_drops:  # lost, not halted as another track's duplicate
                    self.halted.append(t)
        self.halted = [t for t in self.halted if self._revivable(t, k)]
        self.targets = [t for t in self.targets if not t.halted]
        for t in self.targets:
            t.count = L
        self.det_count = L
        rng = np.random.default_rng([self.seed, k, 1])
        released = []
        for c in found:
            if len(self.targets) >= p.max_tracks:
                break
            old = self._revived(k, c)
            t = Target(self.next_id if old is None else old.track_id, c, k, L,
                       scale=p.q_max_ratio if p.adaptive_q and p.start_q_max else 1.0)
            t.follow(c.mean, c.cov, c.mass, self.p.frame_interval)
            t.peak_z = running_peak_z(0.0 if old is None else old.peak_z, self.buffer[-1][1], *t.position)
            t.velocity_sd = p.vmax / np.sqrt(3.0)  # the tracker starts from Eq. 29's velocity prior
            t.tracked(k)
            t.rows.append(self._row(k, t.track_id, c.mean, c.probs, min(c.mass, 1.0)))
            state, model = tracker_start(c, L, p.vmax, p.fresh_velocity, rng)
            self.pool.load(offset, state, model, 1.0 / L, len(self.targets) + 1)
            offset += L
            self.targets.append(t)
            if old is None:
                self.next_id += 1
            else:
                t.confirmed, t.streak = True, p.confirm_frames
                t.whole, t.reported_frames, t.first_reported_at = old.whole, old.reported_frames, old.first_reported_at
                if self._reported(t, k):
                    released.append(t.rows[-1])
        return released

    def _evict_faint(self, k: int, waiting: int) -> None:
        """With min_peak_z > 0 and more captures ``waiting`` than free trackers: halt the trackers that have had
        SETTLE_FRAMES frames to reach the guard and stay below it, faintest first, one per capture without a
        tracker.  Still clutter holds its tracker for good (its peak cell keeps the mass), and the guard would
        never report it, while the target waits for a free tracker (docs/methods/mm-phd.md#real-video)."""
        live = [t for t in self.targets if not t.halted]
        excess = waiting - (self.p.max_tracks - len(live))
        if self.p.min_peak_z <= 0 or excess <= 0:
            return
        faint = [t for t in live if k - t.first_frame >= SETTLE_FRAMES and t.peak_z < self.p.min_peak_z]
        for t in sorted(faint, key=lambda t: t.peak_z)[:excess]:
            t.halted = True

    def _reported(self, t: Target, k: int) -> bool:
        """Whether t's row of frame k is reported: t is confirmed and, with min_peak_z > 0, its running peak z is
        at least min_peak_z (the real-video guard, :mod:`~tbd_taichi.peak_guard`); keeps the reported span."""
        ok = t.confirmed and (self.p.min_peak_z <= 0 or t.peak_z >= self.p.min_peak_z)
        if ok:
            t.reported_span = (t.reported_span or (k,))[:1] + (k,)
            t.reported_frames += 1
            self.still_rule.reported(t, tuple(float(v) for v in t.position))
        return ok

    def _kept_rows(self, t: Target) -> list:
        """A confirmed track's whole path: every row (backward frames included); with min_peak_z > 0 the rows
        from the first to the last frame it was reported in, as SGDS-PF's guard keeps them."""
        if self.p.min_peak_z <= 0:
            return t.rows
        if not t.whole:  # never reported, or a still track that went before still_frames
            return []
        first, last = t.reported_span
        return [r for r in t.rows if first <= r[0] <= last]

    def _revived(self, k: int, c: Capture) -> Target | None:
        """The lost confirmed track, last tracked 1 … revive_frames frames before k, whose position there moved on by
        its velocity lies nearest capture c within its gate (the class radius + gate_sigmas velocity standard
        deviations × the time since), taken off the halted list; None if there is none or revive_frames is 0."""
        T, best, dist = self.p.frame_interval, None, np.inf
        for t in self.halted:
            if not self._revivable(t, k):
                continue
            dt = (k - t.last_frame) * T
            d = float(np.hypot(*(c.mean[[X, Y]] - (t.last_position + t.last_velocity * dt))))
            if d <= self.d.class_radius + self.p.gate_sigmas * t.velocity_sd * dt and d < dist:
                best, dist = t, d
        if best is not None:
            self.halted.remove(best)
        return best

    def _revivable(self, t: Target, k: int) -> bool:
        """Whether a capture at frame k may continue lost track t: last tracked 1 … revive_frames frames before."""
        return 0 < k - t.last_frame <= self.p.revive_frames

    def _captures(self, k: int, n_hat: float, det_len: int) -> list[Capture]:
        """k-means on the detector's PHD (:func:`captures`); the classes whose peak cell holds PHD mass ≥
        confirm_above, at least 6Σ from every live tracker."""
        p = self.p
        det = self.pool.particles(0, det_len)
        gap = 6.0 * p.psf_sigma  # Eq. 12
        rng = np.random.default_rng([self.seed, k])
        live = [t.position for t in self.targets if not t.halted]
        return [c for c in captures(det, n_hat, len(self.d.models), gap, self.d.class_radius, CAPTURE_DRAWS, rng)
                if c.peak >= p.capture_above and all(np.hypot(*(c.mean[[X, Y]] - q)) >= gap for q in live)]

    def _row(self, frame: int, track_id: int, mean: np.ndarray, probs: np.ndarray, n_hat: float) -> tuple:
        """A tracks row: velocities in px/frame (the state's px/s times T), confidence min(n̂, 1), then P_r."""
        T = self.p.frame_interval
        return (int(frame), int(track_id), float(mean[0]), float(mean[2]), float(mean[1] * T), float(mean[3] * T),
                float(mean[4]), float(min(n_hat, 1.0)), *(float(v) for v in probs))
