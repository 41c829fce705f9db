"""SGDS-PF's tracking-mode bookkeeping (Jia et al. 2022, Algorithm 2): a track's record, Eq. 39's path, the
confidence evaluation functions ICEF (Eq. 40) and SCEF (Eqs. 41–42), Eq. 43's update, and the duplicate tests
that keep one track per target.  Host functions on arrays with one value per track (track_states.py applies them
to all tracks at once); the particle work is in the pools."""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field

import numpy as np

DUPLICATE_RADIUS = 2.0  # px: tracks and potential targets closer than this are one target
TRACK_MASK_HALF = math.ceil(DUPLICATE_RADIUS)  # px: half-side of the square around a track kept out of the search
LOST_FRAMES = 3  # frames without an E = 1 particle after which a track ends
MSW_LEF_OFFSET = 0.3  # ln MSW − the frame's best candidate LEF, measured with the printed MSW (msw_from_candidates)
ICEF_LOWER = 0.1  # Eq. 40: ICEF = 1 for 0.1 ≤ MTW/MSW < 1 (at 200×200; scaled to the frame area)


@dataclass(eq=False)  # tracks are compared by identity (list membership, removal)
class Track:
    """One tracking PF's record: its id, group, confirmation, reporting state and path (Eq. 39).  The numbers that
    change every frame (C, N_rt, the windows, the last position) are the group's row of ``TrackStates``."""

    track_id: int
    group: int
    confirmed: bool = False
    reported: bool = False  # confirmed and its peak z has reached min_peak_z
    reported_span: tuple | None = None  # (first, last) frame it was reported in
    reported_frames: int = 0  # frames it was reported in
    first_reported_at: tuple | None = None  # (x, y) where it was first reported
    whole: bool = False  # in the whole paths (reported, and not a still track that went before still_frames)
    path: deque = field(default_factory=deque)  # (frame, x, y, vx, vy, intensity, confidence)

    def last_xy(self) -> tuple[float, float]:
        return self.path[-1][1], self.path[-1][2]


def msw_from_candidates(best_lef: np.ndarray, width: int, tracked) -> float:
    """ln MSW for Eq. 40 from the frame's Eq. 24 candidates with the largest log ω̌_lef (Eq. 28)
    (``best_lef`` rows (value, pixel y·W + x), descending; not in the paper): the first one outside
    the squares of ±TRACK_MASK_HALF px around the ``tracked`` (x, y) points (an (n, 2) array or list) (the squares
    ``SGDSPF._suppress_tracked`` keeps out of the proposal), plus MSW_LEF_OFFSET;
    the last row's value if every row is tracked; −3e38 (no search evidence: ICEF = 1) without
    candidates.

    The printed MSW, the searching particles' largest weight, is about the same extreme of the
    noise (measured on the simulator, SNR 1.2 and 2.0 presets at 200×200: ln MSW − the best candidate's
    LEF = 0.29 on average) as long as the proposal spreads the particles over the candidates; this one
    does not depend on where the particles are, so it holds when the multi-frame LEF concentrates them.
    Like the searching particles (saliency is masked at tracks, Eq. 36's PPs are handed over), it
    leaves out what is tracked already, so a bright tracked object does not hold other tracks down."""
    values, pixels = best_lef[:, 0], best_lef[:, 1]
    some = values > -1e37
    if not some.any():
        return -3.0e38
    values, pixels = values[some], pixels[some].astype(np.int64)
    centres = np.floor(np.asarray(tracked, np.float64).reshape(-1, 2) + 0.5).astype(np.int64)
    near = ((np.abs(pixels[:, None] % width - centres[:, 0]) <= TRACK_MASK_HALF)
            & (np.abs(pixels[:, None] // width - centres[:, 1]) <= TRACK_MASK_HALF)).any(axis=1)
    free = np.flatnonzero(~near)  # descending: the first free one (usually the first) decides
    return float(values[free[0]] if len(free) else values[-1]) + MSW_LEF_OFFSET


def icef_of_log_ratio(log_r, lower: float = ICEF_LOWER):
    """Eq. 40 on r = exp(``log_r``) = MTW/MSW (from :func:`log_weight_ratio`; one value or an array): r if r ≥ 1,
    1 if ``lower`` ≤ r < 1, else 0.9.  ``lower`` is 0.1 as printed; the tracker scales it to the frame area like
    the window's threshold (``SGDSParams.icef_ratio_for``)."""
    r = np.exp(log_r)
    return np.where(r >= 1, r, np.where(r >= lower, 1.0, 0.9))


def log_weight_ratio(log_mtw, log_msw: float):
    """ln(MTW/MSW) of Eq. 40 for each ln MTW of ``log_mtw`` against the frame's ``log_msw``, clipped to ±50; −50
    without E = 1 track particles, 0 without E = 1 search particles (where Eq. 40's fallback gives ICEF = 1)."""
    log_mtw = np.asarray(log_mtw, np.float64)
    if not math.isfinite(log_msw) or log_msw <= -1e37:
        return np.where(np.isfinite(log_mtw) & (log_mtw > -1e37), 0.0, -50.0)
    return np.where(np.isfinite(log_mtw) & (log_mtw > -1e37), np.minimum(np.maximum(log_mtw - log_msw, -50.0), 50.0),
                    -50.0)


def windowed_icef(value, recent_sums, full, window: int, mean_ratio: float):
    """Eq. 40 with memory (not in the paper): where the frame's r alone gives ICEF = 0.9 (``value``), ICEF is 1
    when the geometric mean of r over the track's last ``window`` frames is ≥ ``mean_ratio``; ``recent_sums``: the
    sum of ln r over those frames, ``full``: whether the track has had ``window`` frames.  ``window`` = 1 is Eq. 40
    as printed.

    Why: MSW is the largest of some 10⁴ search weights, an extreme of the noise; at SNR 1.2 a
    target's single-frame r stays below 0.1 in about 80 % of frames, so its confidence never
    returns to 1 and it is never confirmed (docs/results/suite_analysis.md)."""
    if window <= 1:
        return value
    lifted = (value == 0.9) & full & (recent_sums / window >= math.log(mean_ratio))
    return np.where(lifted, 1.0, value)


def held_compact(compact, ratio_sums, full, window: int, log_mean_ratio: float):
    """Confirmation by a long window (not in the paper): over the track's last ``window`` frames its tracking PF's
    E = 1 cloud was compact in every frame (Eq. 42; ``compact``) and the geometric mean of MTW/MSW (Eq. 40; the sum
    of ln r ``ratio_sums``) is ≥ exp(``log_mean_ratio``); ``full``: whether the track has had ``window`` frames.
    ``window`` = 0: never (Eq. 43's N_rt alone confirms).

    Why: at SNR 1.2 a target tracked for 100 frames and more by a compact cloud can have MTW/MSW ≈ 0.03,
    below the ICEF window's 0.05, so C shrinks by ICEF·SCEF = 0.9·1.1 per frame and never returns to 1;
    a noise track's cloud spreads within a few tens of frames (docs/results/suite_analysis.md)."""
    if window < 1:
        return np.zeros(np.shape(compact), bool)
    return compact & full & (ratio_sums / window >= log_mean_ratio)


def scef(cov: np.ndarray, t_devr: float):
    """Eqs. 41–42, sound reading: 1.1 if the spread along x, y and the diagonals is ≤ T_devr,
    else T_devr / (largest spread) < 1.  ``cov``: one (2, 2) covariance, or a stack (…, 2, 2) (one value each)."""
    cov = np.asarray(cov, np.float64)
    var_x, var_y, cov_xy = np.maximum(cov[..., 0, 0], 0.0), np.maximum(cov[..., 1, 1], 0.0), cov[..., 0, 1]
    spread = np.maximum(np.maximum(np.sqrt(var_x), np.sqrt(var_y)), np.sqrt((var_x + var_y) / 2 + np.abs(cov_xy)))
    with np.errstate(divide="ignore", invalid="ignore"):  # spread 0 (or NaN: an empty group) takes the other branch
        return np.where(spread <= t_devr, 1.1, t_devr / spread)


def update_confidence(c, icef_value, scef_value):
    """Eq. 43: C ← 1 if C·ICEF·SCEF ≥ 1, else C·ICEF·SCEF (one value or arrays)."""
    v = c * icef_value * scef_value
    return np.where(v >= 1.0, 1.0, v)


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
