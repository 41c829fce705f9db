"""SGDS-PF: the saliency-guided double-stage particle filter (Jia et al., Sensors 2022, §2.2–2.3).

Per processed frame f (two frames behind the input, because of the saliency accumulation):

1. **Saliency** (Eqs. 20–33): the per-block proposal map OPsal_N of frame f.
2. **Searching mode** (Algorithm 1): one searching PF per image block, all in one particle
   pool.  Newborn and initial particles are drawn from the block's proposal map (Eqs. 34–35),
   labelled with their particle population (PP) by Eq. 36 (8-connected components of the
   proposal support, ``cv2.connectedComponents``); existence, propagation, weights,
   normalisation and resampling as in §2.1; the weakest PPs are eliminated (Eq. 37, P_e of
   the block's particles per frame); PP states follow Eq. 38; a PP with PTp > T_PTp and
   PE > T_PE is a potential target and moves, with its particles, to the tracking mode.
3. **Tracking mode** (Algorithm 2): one tracking PF of N_tpf particles per potential target, all
   in a second pool; newborns copy a random E = 1 particle of the same track.  Each frame the
   track's estimate (Eq. 19) extends its path (Eq. 39) and its confidence C is updated by
   ICEF (Eq. 40) and SCEF (Eqs. 41–42) (Eq. 43).  C < T_ft ends the track; N_rt > T_rt
   (frames with C = 1) confirms it.

Choices where the paper is open (see the README for the reasons): the intensity range of
newborns is Eq. 26's [snr − 2, snr + 3] in σ units of the PSF peak, converted to total
intensity (×2πΣ²) like the original PF; PE = ΣE/N_pp (the fraction of the PP's particles
with E = 1); SCEF uses dev_d = √((var_x + var_y)/2 + |cov_xy|) and SCEF = T_devr/max(dev)
when spread (the printed √cov can be imaginary), over the tracking PF's E = 1 particles: E = 0
particles are not propagated, so their positions are where each died, up to tens of frames behind
a moving target, and at low SNR (where resampling keeps them) they spread the cloud and end the
target's track (200×200, SNR 1.2, seeds 0–39: TSR 0.65 → 0.83 against all particles); ICEF is also 1 when MTW/MSW's geometric mean
over the track's last ``icef_window`` frames is ≥ ``icef_mean_ratio``, scaled to the frame area
(not in the paper, :func:`windowed_icef`, ``SGDSParams.icef_ratio_for``); a track is also confirmed once its cloud
has been compact for ``confirm_window`` frames with MTW/MSW's geometric mean ≥ ``confirm_mean_ratio`` (not in the
paper, :func:`held_compact`); Eq. 29's weight is the multi-frame
LEF (``lef_memory``, ``lef_scale``) and Eq. 40's MSW the best untracked candidate's LEF (``msw_reference``,
:func:`msw_from_candidates`), both not in the paper (``PAPER_SALIENCY`` restores them); a track also ends when its estimate
leaves the image or it has had no E = 1 particle for 3 frames; saliency within 2 px of an
active track is masked and a potential target within 2 px of a track is dropped, so one
target gives one track; of two tracks closer than 2 px the younger one is removed; a track handed over at
frame f starts its path with the PP's Eq. 38 estimate at f and its tracking PF first steps at f + 1 (the PP's
particles have weighed frame f already; the paper does not say, the implementation notes suggest it).
"""
from __future__ import annotations

import math
import time
from collections import deque
from dataclasses import dataclass, field

import cv2
import numpy as np

from . import backend
from .errors import InputError, ParameterError
from .background import DEFAULT_BACKGROUND
from .frontend import FrontEnd, FrontEndProcess, FrontFrame
from .params import SGDSParams
from .particles import STATE, ParticlePool
from .pf import birth_intensity_range
from .tables import TRACK_DTYPE, make_table

MIN_FRAMES = 5
PIPELINE_STAGES = ("normalise", "saliency", "searching", "tracking")  # SGDSPF.stage_seconds
DUPLICATE_RADIUS = 2.0  # px: tracks and potential targets closer than this are one target
TRACK_MASK_HALF = math.ceil(DUPLICATE_RADIUS)  # px: half-side of the square around a track kept out of the search
LOST_FRAMES = 3  # frames without an E = 1 particle after which a track ends
MSW_LEF_OFFSET = 0.3  # ln MSW − the frame's best candidate LEF, measured with the printed MSW (msw_from_candidates)
ICEF_LOWER = 0.1  # Eq. 40: ICEF = 1 for 0.1 ≤ MTW/MSW < 1 (at 200×200; scaled to the frame area)
PEAK_RHO = 0.1  # a track's running peak z: exponential mean from 0, this weight on the newest frame


@dataclass(eq=False)  # tracks are compared by identity (list membership, removal)
class Track:
    """One tracking PF's bookkeeping: confidence, confirmation counter and path (Eq. 39)."""

    track_id: int
    group: int
    confidence: float = 1.0
    n_rt: int = 0
    confirmed: bool = False
    frames_without_e: int = 0
    peak_z: float = 0.0  # running mean (from 0) of the frame's largest z within 1 px of the estimate
    reported: bool = False  # confirmed and its peak z has reached min_peak_z
    path: deque = field(default_factory=deque)  # (frame, x, y, vx, vy, intensity, confidence)
    log_ratios: deque = field(default_factory=deque)  # ln(MTW/MSW) of the last icef_window frames
    held: deque = field(default_factory=deque)  # (ln(MTW/MSW), SCEF = 1.1) of the last confirm_window frames

    def last_xy(self) -> tuple[float, float]:
        return self.path[-1][1], self.path[-1][2]


def nearest_pixel(x: float, y: float) -> tuple[int, int]:
    """The pixel (column, row) whose centre is nearest to (x, y) (centres at integers)."""
    return int(math.floor(x + 0.5)), int(math.floor(y + 0.5))


def peak_z(z: np.ndarray, x: float, y: float) -> float:
    """The largest z in the 3×3 pixels around (x, y) (σ units; NaN outside the image)."""
    h, w = z.shape
    cx, cy = nearest_pixel(x, y)
    window = z[max(cy - 1, 0):max(cy + 2, 0), max(cx - 1, 0):max(cx + 2, 0)]
    return float(window.max()) if window.size else float("nan")


def msw_from_candidates(best_lef: np.ndarray, width: int, tracked: list) -> float:
    """ln MSW for Eq. 40 from the frame's Eq. 24 candidates with the largest log ω̌_lef (Eq. 28)
    (``best_lef`` rows (value, pixel y·W + x), descending; not in the paper): the first one outside
    the squares of ±TRACK_MASK_HALF px around the ``tracked`` (x, y) points (the squares
    ``SGDSPF._suppress_tracked`` keeps out of the proposal), plus MSW_LEF_OFFSET;
    the last row's value if every row is tracked; −3e38 (no search evidence: ICEF = 1) without
    candidates.

    The printed MSW, the searching particles' largest weight, is about the same extreme of the
    noise (measured on the simulator, SNR 1.2 and 2.0 presets at 200×200: ln MSW − the best candidate's
    LEF = 0.29 on average) as long as the proposal spreads the particles over the candidates; this one
    does not depend on where the particles are, so it holds when the multi-frame LEF concentrates them.
    Like the searching particles (saliency is masked at tracks, Eq. 36's PPs are handed over), it
    leaves out what is tracked already, so a bright tracked object does not hold other tracks down."""
    rows = [(value, int(pixel)) for value, pixel in best_lef.tolist() if value > -1e37]
    if not rows:
        return -3.0e38
    centres = [nearest_pixel(x, y) for x, y in tracked]
    for value, pixel in rows:  # descending: the first free one (usually the first) decides
        cx, cy = pixel % width, pixel // width
        if not any(abs(cx - tx) <= TRACK_MASK_HALF and abs(cy - ty) <= TRACK_MASK_HALF for tx, ty in centres):
            return value + MSW_LEF_OFFSET
    return rows[-1][0] + MSW_LEF_OFFSET


def icef_of_log_ratio(log_r: float, lower: float = ICEF_LOWER) -> float:
    """Eq. 40 on r = exp(``log_r``) = MTW/MSW (from :func:`log_weight_ratio`): r if r ≥ 1, 1 if
    ``lower`` ≤ r < 1, else 0.9.  ``lower`` is 0.1 as printed; the tracker scales it to the frame area
    like the window's threshold (``SGDSParams.icef_ratio_for``)."""
    r = math.exp(log_r)
    return r if r >= 1 else (1.0 if r >= lower else 0.9)


def log_weight_ratio(log_mtw: float, log_msw: float) -> float:
    """ln(MTW/MSW) of Eq. 40, clipped to ±50; −50 without E = 1 track particles, 0 without E = 1
    search particles (where Eq. 40's fallback gives ICEF = 1)."""
    if not math.isfinite(log_mtw) or log_mtw <= -1e37:
        return -50.0
    if not math.isfinite(log_msw) or log_msw <= -1e37:
        return 0.0
    return min(max(log_mtw - log_msw, -50.0), 50.0)


def windowed_icef(value: float, recent_log_ratios, window: int, mean_ratio: float) -> float:
    """Eq. 40 with memory (not in the paper): where the frame's r alone gives ICEF = 0.9, ICEF is 1
    when the geometric mean of r over the track's last ``window`` frames (``recent_log_ratios``,
    ln r, the newest last) is ≥ ``mean_ratio``.  ``window`` = 1 is Eq. 40 as printed.

    Why: MSW is the largest of some 10⁴ search weights, an extreme of the noise; at SNR 1.2 a
    target's single-frame r stays below 0.1 in about 80 % of frames, so its confidence never
    returns to 1 and it is never confirmed (docs/results/suite_analysis.md)."""
    if value != 0.9 or window <= 1 or len(recent_log_ratios) < window:
        return value
    return 1.0 if sum(recent_log_ratios) / window >= math.log(mean_ratio) else value


def held_compact(held, window: int, log_mean_ratio: float) -> bool:
    """Confirmation by a long window (not in the paper): over the track's last ``window`` frames
    (``held``: (ln MTW/MSW, whether SCEF = 1.1) per frame, the newest last) its tracking PF's E = 1 cloud
    was compact in every frame (Eq. 42) and the geometric mean of MTW/MSW (Eq. 40) is ≥
    exp(``log_mean_ratio``).  ``window`` = 0: never (Eq. 43's N_rt alone confirms).

    Why: at SNR 1.2 a target tracked for 100 frames and more by a compact cloud can have MTW/MSW ≈ 0.03,
    below the ICEF window's 0.05, so C shrinks by ICEF·SCEF = 0.9·1.1 per frame and never returns to 1;
    a noise track's cloud spreads within a few tens of frames (docs/results/suite_analysis.md)."""
    if window < 1 or len(held) < window:
        return False
    return all(compact for _, compact in held) and sum(r for r, _ in held) / window >= log_mean_ratio


def scef(cov: np.ndarray, t_devr: float):
    """Eqs. 41–42, sound reading: 1.1 if the spread along x, y and the diagonals is ≤ T_devr,
    else T_devr / (largest spread) < 1.  ``cov``: one (2, 2) covariance, or a stack (…, 2, 2) (one value each)."""
    cov = np.asarray(cov, np.float64)
    var_x, var_y, cov_xy = np.maximum(cov[..., 0, 0], 0.0), np.maximum(cov[..., 1, 1], 0.0), cov[..., 0, 1]
    spread = np.maximum(np.maximum(np.sqrt(var_x), np.sqrt(var_y)), np.sqrt((var_x + var_y) / 2 + np.abs(cov_xy)))
    with np.errstate(divide="ignore", invalid="ignore"):  # spread 0 (or NaN: an empty group) takes the other branch
        return np.where(spread <= t_devr, 1.1, t_devr / spread)


def update_confidence(c: float, icef_value: float, scef_value: float) -> float:
    """Eq. 43: C ← 1 if C·ICEF·SCEF ≥ 1, else C·ICEF·SCEF."""
    v = c * icef_value * scef_value
    return 1.0 if v >= 1.0 else v


def near_any(points: list, x: float, y: float) -> bool:
    """Whether (x, y) lies within DUPLICATE_RADIUS px of any of ``points`` [(x, y), …]: dx² + dy² < R² in
    f64, as the hand-over kernel tests it."""
    r2 = DUPLICATE_RADIUS * DUPLICATE_RADIUS
    return any((x - px) * (x - px) + (y - py) * (y - py) < r2 for px, py in points)


def within_duplicate_radius(x: np.ndarray, y: np.ndarray, px: np.ndarray, py: np.ndarray) -> np.ndarray:
    """(len(x), len(px)) bool: position k lies within DUPLICATE_RADIUS px of point j (near_any's test)."""
    dx, dy = x[:, None] - px, y[:, None] - py
    return dx * dx + dy * dy < DUPLICATE_RADIUS * DUPLICATE_RADIUS


def near_any_of(points: list, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """:func:`near_any` for each of the positions (x[k], y[k]) at once (bool array)."""
    if not points or not len(x):
        return np.zeros(len(x), bool)
    p = np.asarray(points, np.float64)
    return within_duplicate_radius(x, y, p[:, 0], p[:, 1]).any(axis=1)


def resize_population(n: int, size: int, u: np.ndarray) -> np.ndarray:
    """Indices that bring a PP of n particles to ``size`` (Algorithm 2's "random eliminating or
    copying"): a random subset without replacement if n ≥ size, else all plus random copies.
    ``u`` holds at least max(n, size) uniforms."""
    if n >= size:  # the size smallest u (distinct: 53-bit uniforms), in index order
        return np.sort(np.argpartition(u[:n], size - 1)[:size]) if size else np.zeros(0, np.int64)
    return np.concatenate([np.arange(n), np.floor(u[:size - n] * n).astype(np.int64)])


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


class SGDSPF:
    """Streaming SGDS-PF tracker.

    ``tracker = SGDSPF((H, W), snr=1.4, seed=0, engine="taichi", arch=None, **params)``;
    ``params`` override the Table 2 preset of :class:`~tbd_taichi.params.SGDSParams`.
    ``update(frame)`` takes one raw frame and returns the confirmed tracks' rows for the frame
    it has just finished, which is two frames behind (saliency needs frame f + 2).
    ``finish()`` processes the last two frames and returns every confirmed track with its
    whole path, which may begin before the track was confirmed (its history in the tracking PF).

    ``history=False`` keeps no paths (only each track's last point) and no online rows, so memory
    stays constant on endless streams; then ``finish()`` returns only the rows of the two flushed
    frames, and the caller keeps what ``update`` returned.

    ``frontend_process=True`` runs normalisation and saliency in a second process, one frame
    ahead (:mod:`tbd_taichi.frontend`): the same tracks, with ``update`` three frames behind;
    ``finish()`` ends that process.
    """

    def __init__(self, shape, snr: float = 1.4, seed: int = 0, engine: str = "taichi", arch: str | None = None,
                 max_tracks: int = 32, background: str = DEFAULT_BACKGROUND, bad_pixels: bool = True,
                 history: bool = True, frontend_process: bool = False, **params):
        if len(shape) != 2 or min(shape) < 8:
            raise ParameterError(f"shape must be (H, W) with H, W ≥ 8, got {tuple(shape)}")
        if max_tracks < 1:
            raise ParameterError("max_tracks must be ≥ 1")
        self.p = SGDSParams.for_snr(snr, **params)
        self.shape = (int(shape[0]), int(shape[1]))
        self.seed, self.history = int(seed), bool(history)
        if engine == "taichi":
            backend.ensure_init(arch)
        p = self.p
        front = FrontEndProcess if frontend_process else FrontEnd
        self.front = front(self.shape, snr=p.snr, L_ib=p.L_ib, psf_sigma=p.psf_sigma, background=background,
                           bad_pixels=bad_pixels, engine=engine, lef_memory=p.lef_memory, lef_scale=p.lef_scale)
        self.grid = self.front.grid
        common = dict(engine=engine, q1=p.q1, q2=p.q2, psf_sigma=p.psf_sigma, noise_sigma=p.noise_sigma)
        self.search = ParticlePool([p.N_sump] * self.grid.n_blocks, self.shape, seed=seed,
                                   map_capacity=self.shape[0] * self.shape[1], **common)
        self.tracks_pool = ParticlePool([p.N_tpf] * max_tracks, self.shape, seed=seed + 7919, **common)
        intensity = (max(p.snr - 2.0, 0.1), p.snr + 3.0)  # Eq. 26 as printed (σ units); see the module notes
        self.search.configure_groups(np.arange(self.grid.n_blocks), "map", pb=p.P_b, pd=p.P_d_search,
                                     vmax=p.V_limit, intensity=intensity, mu=p.mu)
        self.tracks_pool.configure_groups(np.arange(max_tracks), "copy", pb=p.P_b, pd=p.P_d_track,
                                          vmax=p.V_limit, intensity=intensity)
        pixels = self.shape[0] * self.shape[1]  # ICEF's thresholds scale with the frame area
        self.icef_ratio = p.icef_ratio_for(pixels)  # the ICEF window's threshold
        self.icef_lower = p.icef_ratio_for(pixels, ICEF_LOWER)  # Eq. 40's 0.1, scaled
        self.confirm_log_ratio = math.log(p.icef_ratio_for(pixels, p.confirm_mean_ratio))  # the long window's
        self.pp_index = np.zeros(self.shape, np.int32)  # P_pp of Eq. 36 (0: no PP)
        self._seq = np.empty(self.search.capacity, np.int32)  # the searching particles' Seq, read each frame
        self.next_pp = 1
        self.free_groups = list(range(max_tracks))[::-1]
        self.ended_groups: list[int] = []  # groups of tracks ended this frame: free at once, emptied by _start_tracks
        self.active: list[Track] = []
        self.finished: list[Track] = []
        self.next_track_id = 1
        self.online_rows: list[tuple] = []
        self.stage_seconds = dict.fromkeys(PIPELINE_STAGES, 0.0)  # cumulative wall time per stage
        if frontend_process:  # this process's wait for the front end (its own stages run alongside)
            self.stage_seconds["waiting"] = 0.0

    def _clock(self, stage: str, t0: float) -> float:
        now = time.perf_counter()
        self.stage_seconds[stage] += now - t0
        return now

    # ------------------------------------------------------------ input

    def update(self, frame) -> list[tuple]:
        """Add one raw frame; returns the confirmed rows (frame, track_id, x, y, vx, vy, I, C) of the
        frame finished now (frame t − 2, or t − 3 with ``frontend_process``), or [] before that."""
        t0 = time.perf_counter()
        done = self.front.push(frame)
        self._front_clock(t0)
        return [row for f in done for row in self._process(f)]

    def finish(self) -> np.ndarray:
        """Process the last frames and return the tracks table of every confirmed track's whole path."""
        if self.frames_in < MIN_FRAMES:
            raise InputError(f"{self.frames_in} frame(s), but SGDS-PF needs at least {MIN_FRAMES}")
        t0 = time.perf_counter()
        done = self.front.finish()
        self._front_clock(t0)
        rows = [row for f in done for row in self._process(f)]
        self.front.close()
        return self.whole_paths() if self.history else make_table(rows, TRACK_DTYPE)

    @property
    def frames_in(self) -> int:
        """Raw frames taken so far (counted by the front end)."""
        return self.front.frames_in

    def _front_clock(self, t0: float) -> None:
        """The front end's stage times (its own clock), and this process's wait for it."""
        self.stage_seconds.update(self.front.stage_seconds)
        if "waiting" in self.stage_seconds:
            self._clock("waiting", t0)

    def whole_paths(self) -> np.ndarray:
        rows = [(f, t.track_id, x, y, vx, vy, i, c) for t in self.finished + self.active if t.reported
                for (f, x, y, vx, vy, i, c) in t.path]
        return make_table(rows, TRACK_DTYPE)

    def online(self) -> np.ndarray:
        """Rows as they were output online (from confirmation on)."""
        return make_table(self.online_rows, TRACK_DTYPE)

    # ------------------------------------------------------------ one frame

    def _process(self, front: FrontFrame) -> list[tuple]:
        """Frame f: both PF stages in one step (the tracking PFs of the tracks begun by frame f − 1), the
        tracks' confirmation, then Eq. 37's elimination and the hand-over of frame f's potential targets,
        whose tracking PFs first step at f + 1 (a handed PP's particles have already weighed frame f)."""
        f, z = front.frame, front.z
        t0 = time.perf_counter()
        seq, est = self._filter_step(f, z, front)
        log_msw = self._log_msw(front)
        t0 = self._clock("searching", t0)
        rows = self._confirm_tracks(f, z, est, log_msw)
        t0 = self._clock("tracking", t0)
        self._eliminate_and_hand_over(f, seq)
        self._clock("searching", t0)
        if self.history:
            self.online_rows += rows
        return rows

    def _suppress_tracked(self, proposal: np.ndarray) -> None:
        """Zero the proposal in the ±TRACK_MASK_HALF px square around each active track (one target, one track),
        in place: ``proposal`` is the front frame's own copy, used for this frame's search only."""
        r = TRACK_MASK_HALF
        for t in self.active:
            cx, cy = nearest_pixel(*t.last_xy())
            proposal[max(cy - r, 0):cy + r + 1, max(cx - r, 0):cx + r + 1] = 0

    def _proposal_maps(self, proposal: np.ndarray, support: np.ndarray) -> dict:
        """Each block's proposal pixels (y·W + x, ascending) and their OPsal_N weights (f64), for the
        blocks that have any: {block: (pixels, weights)} (one stable sort by block, not a pass per block)."""
        pix = np.flatnonzero(support)
        blocks = self.grid.block_id.ravel()[pix]
        order = np.argsort(blocks, kind="stable")
        pix, blocks = pix[order], blocks[order]
        weights = proposal.ravel()[pix].astype(np.float64)
        bounds = np.searchsorted(blocks, np.arange(self.grid.n_blocks + 1))
        return {b: (pix[s:e], weights[s:e]) for b, (s, e) in enumerate(zip(bounds[:-1], bounds[1:])) if e > s}

    def _labels(self, support: np.ndarray) -> np.ndarray:
        """Eq. 36: existing PP ids where P_pp ≠ 0, else new ids from 8-connected components."""
        n, labels = cv2.connectedComponents(support.view(np.uint8), connectivity=8, ltype=cv2.CV_32S)
        np.add(labels, np.int32(self.next_pp - 1), out=labels, where=support)  # component k → PP id next_pp − 1 + k
        self.next_pp += n - 1
        old = self.pp_index != 0
        old &= support
        np.copyto(labels, self.pp_index, where=old)
        return labels

    def _filter_step(self, f: int, z: np.ndarray, front: FrontFrame):
        """Algorithm 1's PF step on frame f (proposal maps, Eqs. 34–36, §2.1) and, in the same launch, Algorithm
        2's for the active tracks.  Returns the searching particles' Seq (state order) and the tracking PFs'
        estimates (None without active tracks)."""
        p, pool, grid = self.p, self.search, self.grid
        proposal = front.proposal
        self._suppress_tracked(proposal)
        support = proposal > 0
        maps = self._proposal_maps(proposal, support)
        pool.set_proposal_map(maps, self._labels(support))
        has_map = np.zeros(grid.n_blocks, bool)
        has_map[list(maps)] = True
        top_up = np.where(has_map, p.N_sump, pool.counts)
        if not self.active:
            return pool.step(f, z, top_up=top_up, seq_out=self._seq), None
        return pool.step_with(self.tracks_pool, f, z, top_up=top_up, seq_out=self._seq)

    def _log_msw(self, front: FrontFrame) -> float:
        """ln MSW for Eq. 40 (``msw_reference``), after the searching PFs' step."""
        if self.p.msw_reference == "search":
            return float(self.search.max_log_weights().max())
        return msw_from_candidates(front.best_lef, self.shape[1], [t.last_xy() for t in self.active])

    def _eliminate_and_hand_over(self, f: int, seq: np.ndarray) -> None:
        """Eq. 37 elimination, Eq. 38 PP states, potential targets, and the index image P_pp; ``seq``: the
        searching particles' Seq in state order (from the step).

        A PP is a (block, Seq) pair.  The host numbers the PPs of all blocks at once and decides the
        quotas; the pool eliminates, applies Algorithm 1's potential-target rule (PTp > T_PTp, PE > T_PE
        with PE = ΣE/N_pp, Eq. 38; a potential target near an active track is dropped, the others are handed
        over while tracking PFs are free) and hands over in one launch
        (``ParticlePool.eliminate_and_hand_over``), so only the handed-over particles' states come to the
        host, PP after PP, each in state order."""
        p, pool = self.p, self.search
        pp_block, inverse, counts = slab_populations(pool.counts, seq)
        take = eliminated_per_population(pp_block, counts, int(round(p.P_e * p.N_sump)))
        rng = np.random.default_rng([self.seed, f])
        tracked = [t.last_xy() for t in self.active]
        members, sizes = pool.eliminate_and_hand_over(inverse, counts, take, rng.random(len(counts)), self.pp_index,
                                                      p.T_PTp, p.T_PE, tracked, DUPLICATE_RADIUS,
                                                      len(self.free_groups))
        self._start_tracks(f, members, sizes, rng, tracked)

    def _start_tracks(self, f: int, members: dict | None, sizes: list, rng: np.random.Generator,
                      tracked: list) -> None:
        """A tracking PF for each handed-over PP: ``members`` holds their particles' states, PP after
        PP (``sizes`` each), resized to N_tpf particles (Algorithm 2), all loaded in one launch, which also
        empties the groups of the tracks ended this frame (``ended_groups``; one launch fewer than emptying them
        apart).  ``tracked``: the active tracks' last positions, to which the new tracks are added."""
        n_tpf = self.p.N_tpf
        starts = np.cumsum(sizes) - sizes
        mean = self._pp_means(members, starts) if len(sizes) else {}
        near_tracked = near_any_of(tracked, mean["x"], mean["y"]).tolist() if len(sizes) else []
        picks, groups = [], []
        for k in range(len(sizes)):
            if not self.free_groups:
                break
            x, y = float(mean["x"][k]), float(mean["y"][k])
            if near_tracked[k] or near_any(tracked[len(tracked) - len(groups):], x, y):  # or a new track
                continue
            picks.append(starts[k] + resize_population(sizes[k], n_tpf, rng.random(max(n_tpf, sizes[k]))))
            groups.append(self.free_groups.pop())
            track = Track(self.next_track_id, groups[-1], path=deque(maxlen=None if self.history else 1),
                          log_ratios=deque(maxlen=self.p.icef_window),
                          held=deque(maxlen=max(self.p.confirm_window, 1)))
            self.next_track_id += 1
            track.path.append((f, x, y, float(mean["vx"][k]), float(mean["vy"][k]), float(mean["inten"][k]), 1.0))
            self.active.append(track)
            tracked.append((x, y))
        emptied, self.ended_groups = self.ended_groups, []
        if not groups and not emptied:
            return
        order = np.argsort(groups)
        index = np.concatenate([picks[k] for k in order]) if groups else np.zeros(0, np.int64)
        # the emptied groups that no new track took are touched with no particles: their count becomes 0
        self.tracks_pool.load_states(np.repeat(np.asarray(groups, np.int64)[order], n_tpf),
                                     {name: members[name][index] for name in STATE}, sorted(set(groups + emptied)))

    @staticmethod
    def _pp_means(members: dict, starts: np.ndarray) -> dict:
        """Eq. 38's PP state: per PP (particles from ``starts[k]`` on, each PP with an E = 1 particle)
        the mean x, y, vx, vy and intensity of its E = 1 particles (f64 sums)."""
        e = members["e"] == 1
        n_e = np.add.reduceat(e.astype(np.int64), starts)
        return {name: np.add.reduceat(np.where(e, members[name], 0).astype(np.float64), starts) / n_e
                for name in ("x", "y", "vx", "vy", "inten")}

    def _confirm_tracks(self, f: int, z: np.ndarray, est, log_msw: float) -> list[tuple]:
        """Algorithm 2 after the tracking PFs' step on frame f (estimates ``est``): paths (Eq. 39), confidences
        (Eqs. 40–43), confirmation and ends; returns the rows of the tracks reported at f."""
        p = self.p
        if not self.active:
            return []
        log_mtw = est.max_logw.tolist()
        finite = np.isfinite(est.x).tolist()
        states = np.stack([est.x, est.y, est.vx, est.vy, est.intensity], axis=1).tolist()
        scefs = scef(est.cov_e, p.T_devr).tolist()  # Eq. 41 over E = 1 particles (module notes); all groups at once
        rows = []
        h, w = self.shape
        for t in list(self.active):
            g = t.group
            t.frames_without_e = t.frames_without_e + 1 if not finite[g] else 0
            log_r = log_weight_ratio(log_mtw[g], log_msw)
            t.log_ratios.append(log_r)
            intensity_cef = windowed_icef(icef_of_log_ratio(log_r, self.icef_lower), t.log_ratios, p.icef_window,
                                          self.icef_ratio)
            t.confidence = update_confidence(t.confidence, intensity_cef, scefs[g])
            if finite[g]:  # Eq. 39
                t.path.append((f, *states[g], t.confidence))
            x, y = t.last_xy()
            lost = t.frames_without_e >= LOST_FRAMES or not (-0.5 <= x < w - 0.5 and -0.5 <= y < h - 0.5)
            if t.confidence < p.T_ft or lost:
                self._end_track(t)
                continue
            if t.confidence == 1.0:
                t.n_rt += 1
                if t.n_rt > p.T_rt:
                    t.confirmed = True
            t.held.append((log_r, scefs[g] > 1.0))
            if not t.confirmed and held_compact(t.held, p.confirm_window, self.confirm_log_ratio):
                t.confirmed = True
            if self._reportable(t, z) and t.path[-1][0] == f:
                rows.append((f, t.track_id) + tuple(t.path[-1][1:]))
        self._merge_duplicates()
        return rows

    def _reportable(self, t: Track, z: np.ndarray) -> bool:
        """Confirmed, and (with min_peak_z > 0) its running peak z at least min_peak_z: a real-video
        guard against confirmed clutter, which is fainter in z than the targets (docs/results/drone_ir.md).
        The running mean starts at 0, so a track must stay bright for about ten frames; short-lived
        transients are not reported."""
        if self.p.min_peak_z <= 0:
            t.reported = t.reported or t.confirmed
            return t.confirmed
        value = peak_z(z, *t.last_xy())
        if math.isfinite(value):
            t.peak_z += PEAK_RHO * (value - t.peak_z)
        ok = t.confirmed and t.peak_z >= self.p.min_peak_z
        t.reported = t.reported or ok
        return ok

    def _merge_duplicates(self) -> None:
        """Of two active tracks closer than DUPLICATE_RADIUS, the younger (larger id) ends; oldest first,
        and a track that has ended ends no other."""
        if len(self.active) < 2:
            return
        tracks = sorted(self.active, key=lambda t: t.track_id)
        x, y = np.array([t.last_xy() for t in tracks]).T
        close = np.triu(within_duplicate_radius(x, y, x, y), 1)
        if not close.any():
            return
        alive = np.ones(len(tracks), bool)
        for i in np.flatnonzero(close.any(axis=1)):
            if alive[i]:
                for j in np.flatnonzero(close[i] & alive):
                    alive[j] = False
                    self._end_track(tracks[j])

    def _end_track(self, t: Track) -> None:
        self.active.remove(t)
        self.free_groups.append(t.group)
        self.ended_groups.append(t.group)
        if t.reported and self.history:
            self.finished.append(t)


def make_tracker(method: str, shape, **kw):
    """A streaming tracker: "sgds" (SGDS-PF) or "pf" (the original PF), keyword arguments passed on."""
    from .pf import OriginalPF

    trackers = {"sgds": SGDSPF, "pf": OriginalPF}
    if method not in trackers:
        raise ParameterError(f"method must be 'sgds' or 'pf', got {method!r}")
    return trackers[method](shape, **kw)


def track(frames_or_path, method: str = "sgds", **kw) -> np.ndarray:
    """Run a tracker over a whole sequence (array (T, H, W) or anything ``tbd_taichi.io`` reads).

    ``method`` is "sgds" (SGDS-PF; whole paths of confirmed tracks) or "pf" (the original PF).
    """
    from . import io

    source = io.open_frames(frames_or_path)
    tracker = make_tracker(method, source.shape, **kw)
    for frame in io.iter_frames(source, min_frames=MIN_FRAMES):
        tracker.update(frame)
    return tracker.finish()
