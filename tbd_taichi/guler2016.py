"""The ``guler2016`` scenario: a one-pixel target on a synthetic wall recording, after Güler's 2016 METU thesis
(§3.1 and Ch. 4: "SENSOR TYPE-1/2" sequences, Motions 1 and 2, target levels "Mean+Δ").  The thesis's two
recordings (a detector fixed in front of a wall exposed to temperature changes, background only) are not public,
so the walls are synthesised to match the statistics it gives (first frame, Fig. 3.2) and its tracking limits.

Frames: 100 × 100 px, 134 frames at 100 Hz, 14-bit counts stored as uint16 (``Scenario.frames``).  A wall
(:func:`wall_background`) is

    I_k(r, c) = MEAN + d_k + p(r) + t(r, c) + n_k(r, c),    rounded to integers and clipped to [0, 16383],

* p(r), the row temperature profile: a smooth function of the row (the part that the row-mean removal of the
  thesis's Eqs. 3.4–3.5 takes out; t has zero row means);
* t(r, c), the static spatial texture.  ``S1`` (structured): soft-edged patches (a thresholded smooth field),
  bright and dark blobs of 0.6–1.6 px (σ) at the target's scale (clutter candidates, denser in a "complex" band
  on the Motion-1 row, Ch. 4: "in Motion 1, the target enters a quite complex region of the background
  pattern") and fine fixed-pattern grain, soft-limited (tanh: it trims the blobs' tails).  The blobs and grain
  are weak beside the patches (S1_BLOB_WEIGHT 0.3, S1_GRAIN_WEIGHT 0.1): pixel-scale static texture passes the
  tracker's 5 × 5 top-hat, and with more of it the thesis's candidate stage (α = 3) could not find a Δ = 20
  target on S1, which the thesis did.
  ``S2`` (smooth): a smooth field (Gaussian-filtered, 6 px) with cold corners (a vignetting falloff, ρ⁸),
  which gives the long cold tail of the thesis's S2 histogram (mean − min 23, max − mean 17 counts);
* n_k(r, c), temporal white Gaussian noise of σ_n = SIGMA[wall]·√noise_share;
* d_k, a slow global drift: s·A·(1 − cos(2πk/P)), s = ±1, A ~ U[1.5, 2] counts, P ~ U[2, 4] × 134 frames:
  0 at frame 0, a change of A to 2A (1.5–4 counts) over the first 134 frames and never more than 2A ≤ 4.

The variance of a frame is SIGMA[wall]²: the temporal noise takes ``noise_share`` of it, the static part p + t
the rest, of which ROW_SHARE[wall] is the row profile (S1: 0.35; S2: 0.55, before the vignette, whose row means
join the profile).  The default share is per wall, NOISE_SHARE = {S1: 0.15, S2: 0.65}: one temporal noise
σ_n ≈ 3.5 counts on both walls (3.56 and 3.47; one kind of detector), so S1's σ 9.2 is mostly wall structure
(static σ 8.5) and S2's 4.3 mostly noise (static σ 2.5).  The thesis gives only the whole frame's statistics;
the shares are calibrated on its limits: both sensors lose the target at Δ = 10 (S1 Motion 1 "lost", S2 Motion 1
"NO TRACK") and hold it at Δ ≈ 14–15, and a limit Δ/σ_n ≈ 3 that is the same on both walls needs the same σ_n.

Generators.  The static part p + t is drawn from ``np.random.default_rng(wall_seed)``, the drift and the noise
from ``np.random.default_rng([seed, NOISE_STREAM])`` (:func:`simulate_guler2016`).  The thesis had one recording
per sensor and repeated its runs on it, so ``wall_seed`` None means RECORDING[wall] = {S1: 9, S2: 0}, one fixed
wall per sensor, and ``seed`` varies the noise (and, in the suite, the tracker's seed).  RECORDING[wall] is the
first wall seed whose four start pixels (START_PIXELS, the pixels lit in frames 0–2: Motion 1 (0, 69), (1, 69);
Motion 2 (0, 39), (1, 40); (x, y)) have a static level within 1.5·σ_n of the frame mean (:func:`start_levels`;
S1 seed 9: −1.2, −5.2, −3.1, −2.6 counts against 5.3; S2 seed 0: 0.1, 0.2, 2.3, 2.6 against 5.2).  The thesis's
Table 4.4 finds its targets as candidates at α = 3 down to Δ = 15, so its start pixels cannot lie on warm spots:
the target replaces the pixel with the frame mean + Δ, so its contrast over the pixel's own static level is Δ
less that level, and a warm start pixel hides it (a cold one is refused too, as "within" is both ways).  The wall
depends on ``wall``, ``wall_seed`` and ``noise_share`` only, not on the motion, Δ or ``seed``, and its first
frames do not depend on the sequence length: every target of the thesis's tables is embedded in the same
recording.

Frame 0's statistics: the thesis (§3.1, Fig. 3.2; σ from Tables 4.1–4.3) / the recording over noise seeds 0–39 /
wall seeds 0–39 (noise seed = wall seed); min–max, mean; default noise shares:

=====  ===========  =====================================  ============================================
wall   mean         range max − min (counts)               σ over the frame (counts)
=====  ===========  =====================================  ============================================
S1     7195 / ±0.1  59 (7166–7225) / 47–59, 51 / 48–67, 56  9.15–9.26 / 9.11–9.26, 9.20 / 9.12–9.30, 9.21
S2     8602 / ±0.1  40 (8579–8619) / 32–41, 36 / 32–43, 37  4.13–4.45 / 4.22–4.37, 4.30 / 4.25–4.36, 4.31
=====  ===========  =====================================  ============================================

S2's cold tail: mean − min 23 counts in the thesis, 18–25 (mean 20.5) on the recording and 18–28 (21.3) over
wall seeds (max − mean 17; 13–20 (15.0) and 13–19 (15.5)).  Over 134 frames a frame's mean stays within 4 counts of
frame 0's (the drift) and its σ within 0.19 (S1), 0.17 (S2) (every frame: S1 9.08–9.33, S2 4.20–4.42).
(σ of the thesis's walls: see below; the σ ≈ 20–30 counts of the project's notes is wrong.)

Target (§3.1): one pixel whose value is *replaced* by round(frame mean + Δ) (the mean of that frame's wall,
before the target; rounded half up, clipped to 16383), Δ one of DELTAS = (100, 60, 50, 30, 20, 15, 14, 13, 10)
in the thesis (any Δ > 0 here), present from frame 0.  Motions (0-based: the thesis's [row, column] = [70, 1] and [40, 1] are 1-based):

* Motion 1: from (x 0, y 69) rightwards at 1 px per 2 frames: x_k = ⌊k/2⌋, y_k = 69;
* Motion 2: from (x 0, y 39) down-right at 45°, 0.5 px/frame along the path (0.5/√2 per axis): the lit pixel
  is the rounded continuous position, x_k = ⌊0.5k/√2 + ½⌋, y_k = 39 + x_k (frame 133: (47, 86)).

Both stay in view for the 134 frames; a longer sequence (``frames`` up to 5000) goes on with the wall alone once
the target leaves (Motion 1 after frame 199, Motion 2 after frame 171), and the truth has rows only for the
frames in which it is in view.

Truth: ``tables.TRUTH_COLUMNS`` (frame, target_id, x, y, vx, vy, intensity): x = column, y = row of the lit pixel
(whole numbers), 0-based; vx, vy the continuous path's velocity (px/frame); intensity = Δ (the contrast above the
frame mean); target_id 0.  ``tbd-taichi evaluate`` reads it as point truth.

SNR (Eq. 4.1): |S − B̄| / √(Σ(S_B − B̄)²/N_B) = Δ/σ, σ the std over the frame without the target; ``params``
records σ of frame 0 (``sigma``), ``snr`` = Δ/σ and ``snr_thesis`` = Δ/(100·σ).  Tables 4.1–4.3 of the thesis
equal Δ/915 and Δ/926 (S1, mean and min) and Δ/413, Δ/445 (S2): their denominator is √(Σ(S_B − B̄)²) =
√N_B·σ = 100σ, i.e. the N_B = 100 × 100 under Eq. 4.1's square root was dropped (the tables' "SNR 0.0328" for
S1 at Δ = 30 is an SNR of 3.3); read the other way it gives the σ above, 9.15–9.26 (S1) and 4.13–4.45 (S2).
"""
from __future__ import annotations

import math

import numpy as np
from scipy import ndimage

from .errors import ParameterError
from .simulate import Scenario
from .tables import TRUTH_DTYPE, make_table

SHAPE = (100, 100)
FRAMES = 134
FPS = 100.0  # Hz (§3.1)
BITS = 14
MAX_VALUE = 2 ** BITS - 1  # 16383
MIN_FRAMES, MAX_FRAMES = 4, 5000  # the thesis's method needs 3 frames of candidates and starts its PF at the 4th
WALLS = ("S1", "S2")
MEAN = {"S1": 7195.0, "S2": 8602.0}  # counts: frame-1 means (§3.1, Fig. 3.2)
SIGMA = {"S1": 9.2, "S2": 4.3}  # counts: the frame's std (Tables 4.1-4.3 imply 9.15-9.26 and 4.13-4.45)
ROW_SHARE = {"S1": 0.35, "S2": 0.55}  # the row profile's share of the static variance (S2: before the vignette)
NOISE_SHARE = {"S1": 0.15, "S2": 0.65}  # the temporal noise's share of the frame variance (default): one σ_n ≈ 3.5
# counts on both walls (one kind of detector); S1's σ is mostly wall structure, S2's mostly noise
RECORDING = {"S1": 9, "S2": 0}  # the default wall seeds: the first whose four start pixels (Motions 1, 2, frames
# 0–2) lie within 1.5·σ_n of the frame mean (the thesis's targets are candidates at α = 3 down to Δ = 15)
MOTIONS = (1, 2)
STARTS = {1: (0, 69), 2: (0, 39)}  # (x, y), 0-based
START_PIXELS = ((0, 69), (1, 69), (0, 39), (1, 40))  # (x, y): the pixels lit in frames 0-2 (Motion 1, then 2)
SPEED = 0.5  # px/frame along the path: 1 px per 2 frames (Ch. 4)
VELOCITY = {1: (SPEED, 0.0), 2: (SPEED / math.sqrt(2.0), SPEED / math.sqrt(2.0))}  # (vx, vy), px/frame
DELTAS = (100, 60, 50, 30, 20, 15, 14, 13, 10)  # counts above the frame mean (Tables 4.1-4.8)
DELTA = 30.0  # the default (Fig. 3.3's example)
DRIFT_AMPLITUDE = (1.5, 2.0)  # counts: A of the drift s·A·(1 − cos(2πk/P))
DRIFT_PERIOD = (2 * FRAMES, 4 * FRAMES)  # frames: P
# S1 texture: patch edges, blobs (count, of which in the complex band; σ px; band rows), grain, soft limit
S1_PATCH_SMOOTH, S1_PATCH_SHARPNESS = 7.0, 3.0
S1_BLOBS, S1_BAND_BLOBS, S1_BLOB_SIGMA, S1_BAND_ROWS = 50, 30, (0.6, 1.6), (60, 79)
S1_BLOB_WEIGHT, S1_GRAIN_WEIGHT, S1_SOFT_LIMIT = 0.3, 0.1, 1.2
S2_SMOOTH, S2_VIGNETTE_POWER, S2_VIGNETTE_WEIGHT = 6.0, 8, 1.0
ROW_SMOOTH = {"S1": 12.0, "S2": 15.0}  # rows: the profile's smoothing σ
NOISE_STREAM = 1  # the noise's generator: default_rng([seed, NOISE_STREAM]), apart from any wall's
NOISE_CHUNK = 256  # frames of noise drawn at a time


def check_guler2016(wall, motion, delta, frames=None, noise_share=None) -> None:
    """A ParameterError for a wall not in WALLS, a motion not 1 or 2, a Δ that is not a finite number > 0,
    ``frames`` not a whole number in [4, 5000] or ``noise_share`` not in [0, 1]."""
    from .validate import positive, whole

    if not isinstance(wall, str) or wall not in WALLS:
        raise ParameterError(f"wall (--wall) must be one of {', '.join(WALLS)}, got {wall!r}")
    if isinstance(motion, bool) or not isinstance(motion, (int, np.integer)) or motion not in MOTIONS:
        raise ParameterError(f"motion (--motion) must be 1 or 2 (the thesis's Motion 1, 2), got {motion!r}")
    positive("delta (--delta)", delta)
    if frames is not None:
        whole("frames (--frames)", frames, MIN_FRAMES, MAX_FRAMES)
    if noise_share is not None and (isinstance(noise_share, bool) or not isinstance(
            noise_share, (int, float, np.integer, np.floating)) or not 0.0 <= noise_share <= 1.0):
        raise ParameterError(f"noise_share must be a number in [0, 1], got {noise_share!r}")


def truth_path(motion: int, frames: int) -> np.ndarray:
    """(frames, 2) int64: the lit pixel (x, y) of ``motion`` in frames 0..frames−1 (module docstring); rows past
    the image's edge are kept (the caller drops them)."""
    k = np.arange(int(frames))
    x0, y0 = STARTS[int(motion)]
    if motion == 1:
        step = k // 2
        return np.stack([x0 + step, np.full_like(step, y0)], axis=1).astype(np.int64)
    step = np.floor(VELOCITY[2][0] * k + 0.5).astype(np.int64)  # round half up (never a tie: 0.5/√2 is irrational)
    return np.stack([x0 + step, y0 + step], axis=1)


def _unit(a: np.ndarray) -> np.ndarray:
    a = a - a.mean()
    sd = a.std()
    return a / sd if sd > 0 else a


def _row_free(a: np.ndarray) -> np.ndarray:
    return a - a.mean(axis=1, keepdims=True)


def _blobs(rng: np.random.Generator, n: int, rows: tuple[int, int]) -> np.ndarray:
    """``n`` Gaussian spots (σ in S1_BLOB_SIGMA px, amplitude ±[0.5, 1]) with centres in ``rows``."""
    h, w = SHAPE
    yy, xx = np.mgrid[0:h, 0:w]
    out = np.zeros(SHAPE)
    for _ in range(n):
        y, x = rng.uniform(rows[0], rows[1]), rng.uniform(0, w - 1)
        s = rng.uniform(*S1_BLOB_SIGMA)
        a = rng.choice((-1.0, 1.0)) * rng.uniform(0.5, 1.0)
        out += a * np.exp(-((yy - y) ** 2 + (xx - x) ** 2) / (2 * s * s))
    return out


def _static(wall: str, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """The unit-variance static parts: (row profile (H,), texture (H, W) with zero row means), before scaling."""
    h, w = SHAPE
    profile = _unit(ndimage.gaussian_filter1d(rng.standard_normal(h), ROW_SMOOTH[wall], mode="reflect"))
    if wall == "S1":
        profile = _unit(profile + _unit(np.arange(h, dtype=float)))  # a gradient plus a smooth wander
        z = ndimage.gaussian_filter(rng.standard_normal(SHAPE), S1_PATCH_SMOOTH, mode="reflect")
        patches = np.tanh(S1_PATCH_SHARPNESS * z / z.std())
        blobs = _blobs(rng, S1_BLOBS, (0, h - 1)) + _blobs(rng, S1_BAND_BLOBS, S1_BAND_ROWS)
        grain = ndimage.gaussian_filter(rng.standard_normal(SHAPE), 0.7, mode="reflect")
        texture = _unit(patches) + S1_BLOB_WEIGHT * _unit(blobs) + S1_GRAIN_WEIGHT * _unit(grain)
        texture = np.tanh(_unit(texture) / S1_SOFT_LIMIT)
        share = ROW_SHARE[wall]
        static = math.sqrt(share) * profile[:, None] + math.sqrt(1 - share) * _unit(_row_free(texture))
    else:
        smooth = _unit(ndimage.gaussian_filter(rng.standard_normal(SHAPE), S2_SMOOTH, mode="reflect"))
        yy, xx = np.mgrid[0:h, 0:w]
        rho2 = ((yy - (h - 1) / 2) ** 2 + (xx - (w - 1) / 2) ** 2) / (((h - 1) ** 2 + (w - 1) ** 2) / 4)
        vignette = -rho2 ** (S2_VIGNETTE_POWER / 2)  # 0 at the centre, −1 in the corners
        share = ROW_SHARE[wall]
        static = math.sqrt(share) * profile[:, None] + math.sqrt(1 - share) * smooth \
            + S2_VIGNETTE_WEIGHT * _unit(vignette)
    static = _unit(static)
    rows = static.mean(axis=1)
    return rows, static - rows[:, None]


def _static_counts(wall: str, rng: np.random.Generator, noise_share: float) -> np.ndarray:
    """(100, 100) float64: MEAN + p + t in counts, the static part scaled to the variance (1 − noise_share)·σ²."""
    rows, texture = _static(wall, rng)
    return MEAN[wall] + SIGMA[wall] * math.sqrt(1.0 - noise_share) * (rows[:, None] + texture)


def static_wall(wall: str, wall_seed: int, noise_share: float | None = None) -> np.ndarray:
    """(100, 100) float64: the static level MEAN + p(r) + t(r, c) of wall ``wall`` drawn from
    ``np.random.default_rng(wall_seed)`` (counts, not rounded; no drift, no noise): what every frame of that
    recording is, up to d_k + n_k and rounding.  ``noise_share`` None: NOISE_SHARE[wall]."""
    from .validate import whole

    check_guler2016(wall, 1, 1.0, None, noise_share)
    noise_share = NOISE_SHARE[wall] if noise_share is None else float(noise_share)
    return _static_counts(wall, np.random.default_rng(whole("wall_seed", wall_seed, 0)), noise_share)


def start_levels(wall: str, wall_seed: int, noise_share: float | None = None) -> np.ndarray:
    """(4,) float64: the static level minus the frame mean (counts) at START_PIXELS, the pixels the target lights
    in frames 0–2 (Motion 1: (0, 69), (1, 69); Motion 2: (0, 39), (1, 40); (x, y)).  RECORDING[wall] is the first
    wall seed where all four are within 1.5·σ_n of 0, σ_n = SIGMA[wall]·√noise_share (module docstring)."""
    level = static_wall(wall, wall_seed, noise_share)
    level -= level.mean()
    return np.array([level[y, x] for x, y in START_PIXELS])


def wall_background(wall: str, rng: np.random.Generator, frames: int = FRAMES,
                    noise_share: float | None = None, noise_rng: np.random.Generator | None = None) -> np.ndarray:
    """(frames, 100, 100) uint16: the wall ``wall`` alone (module docstring): the static profile and texture drawn
    from ``rng``, then the drift and the noise frame by frame from ``noise_rng`` (default ``rng``; the first
    frames do not depend on ``frames``).  :func:`simulate_guler2016` passes ``default_rng(wall_seed)`` and
    ``default_rng([seed, NOISE_STREAM])``."""
    from .validate import whole

    check_guler2016(wall, 1, 1.0, None, noise_share)
    noise_share = NOISE_SHARE[wall] if noise_share is None else float(noise_share)
    n = whole("frames", frames, 1)
    sigma = SIGMA[wall]
    static = _static_counts(wall, rng, noise_share)
    rng = rng if noise_rng is None else noise_rng
    amplitude = rng.uniform(*DRIFT_AMPLITUDE) * rng.choice((-1.0, 1.0))
    period = rng.uniform(*DRIFT_PERIOD)
    drift = amplitude * (1.0 - np.cos(2 * math.pi * np.arange(n) / period))
    noise_sd = sigma * math.sqrt(noise_share)
    out = np.empty((n,) + SHAPE, np.uint16)
    for f0 in range(0, n, NOISE_CHUNK):
        m = min(NOISE_CHUNK, n - f0)
        block = static + drift[f0:f0 + m, None, None] + noise_sd * rng.standard_normal((m,) + SHAPE)
        out[f0:f0 + m] = np.clip(np.rint(block), 0, MAX_VALUE)
    return out


def in_view(path: np.ndarray) -> np.ndarray:
    """Whether each (x, y) of ``path`` is a pixel of the 100 × 100 frame."""
    h, w = SHAPE
    return (path[:, 0] >= 0) & (path[:, 0] < w) & (path[:, 1] >= 0) & (path[:, 1] < h)


def simulate_guler2016(wall: str = "S1", motion: int = 1, delta: float = DELTA, seed: int = 0,
                       frames: int | None = None, noise_share: float | None = None,
                       wall_seed: int | None = None) -> Scenario:
    """Frames (T, 100, 100) uint16 (14-bit counts), point truth and parameters of a wall ``wall`` with a
    one-pixel target of contrast ``delta`` on ``motion`` (module docstring); T = ``frames`` (default 134).  The
    wall's static part is drawn from ``np.random.default_rng(wall_seed)`` and its drift and noise from
    ``default_rng([seed, NOISE_STREAM])`` (:func:`wall_background`); ``wall_seed`` None: RECORDING[wall], the one
    recording of each sensor (as the thesis had) that runs of different ``seed`` see with other noise.
    ``noise_share`` None: NOISE_SHARE[wall].  The same seeds give the same frames, and the same wall for every
    motion and Δ; ``params`` records ``wall_seed`` (the recording's when None) and ``noise_share``."""
    from .validate import whole

    check_guler2016(wall, motion, delta, frames, noise_share)
    noise_share = NOISE_SHARE[wall] if noise_share is None else float(noise_share)
    whole("seed", seed, 0)
    wall_seed = RECORDING[wall] if wall_seed is None else whole("wall_seed", wall_seed, 0)
    n = FRAMES if frames is None else int(frames)
    motion, delta = int(motion), float(delta)
    images = wall_background(wall, np.random.default_rng(wall_seed), n, noise_share,
                             np.random.default_rng([seed, NOISE_STREAM]))
    sigma = float(images[0].std(dtype=np.float64))  # frame 0 without the target
    path = truth_path(motion, n)
    vx, vy = VELOCITY[motion]
    rows = []
    for k in np.flatnonzero(in_view(path)):
        x, y = (int(v) for v in path[k])
        level = images[k].mean(dtype=np.float64) + delta
        images[k, y, x] = min(max(int(np.floor(level + 0.5)), 0), MAX_VALUE)
        rows.append((int(k), 0, float(x), float(y), vx, vy, delta))
    params = dict(scenario="guler2016", wall=wall, motion=motion, delta=delta, seed=seed, wall_seed=wall_seed,
                  frames=n, shape=list(SHAPE), fps=FPS, bits=BITS, noise_share=float(noise_share), sigma=sigma,
                  snr=delta / sigma, snr_thesis=delta / (100.0 * sigma), frames_in_view=len(rows))
    return Scenario(images, make_table(rows, TRUTH_DTYPE), params)
