"""SGDS-PF's tracking-mode bookkeeping (Jia et al. 2022, Algorithm 2): a track's record, Eq. 39's path, the
confidence evaluation functions ICEF (Eq. 40) and SCEF (Eqs. 41–42), Eq. 43's update, and the duplicate tests
that keep one track per target.  Host functions on a few values per track; the particle work is in the pools."""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field

import numpy as np

from ...peak_guard import nearest_pixel

DUPLICATE_RADIUS = 2.0  # px: tracks and potential targets closer than this are one target
TRACK_MASK_HALF = math.ceil(DUPLICATE_RADIUS)  # px: half-side of the square around a track kept out of the search
LOST_FRAMES = 3  # frames without an E = 1 particle after which a track ends
MSW_LEF_OFFSET = 0.3  # ln MSW − the frame's best candidate LEF, measured with the printed MSW (msw_from_candidates)
ICEF_LOWER = 0.1  # Eq. 40: ICEF = 1 for 0.1 ≤ MTW/MSW < 1 (at 200×200; scaled to the frame area)


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
    reported_span: tuple | None = None  # (first, last) frame it was reported in
    reported_frames: int = 0  # frames it was reported in
    first_reported_at: tuple | None = None  # (x, y) where it was first reported
    whole: bool = False  # in the whole paths (reported, and not a still track that went before still_frames)
    path: deque = field(default_factory=deque)  # (frame, x, y, vx, vy, intensity, confidence)
    log_ratios: deque = field(default_factory=deque)  # ln(MTW/MSW) of the last icef_window frames
    held: deque = field(default_factory=deque)  # (ln(MTW/MSW), SCEF = 1.1) of the last confirm_window frames

    def last_xy(self) -> tuple[float, float]:
        return self.path[-1][1], self.path[-1][2]


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
