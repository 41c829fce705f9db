"""The simulator scenario ``long2012``: the scenes of Long, Xu, An & Liu 2012 (MM-PHD TBD), §5.

* sensor: Eq. 4, the Gaussian PSF (Σ px) integrated over each pixel, shifted by a jitter u_k ~ N(0, 0.5²) px
  per axis common to every target of frame k (Eq. 3), plus white N(0, 1) noise (σ_n = 1);
* intensity: Eq. 37, I = 2π·σ_n·Σ²·10^(SNR/20) (SNR of Eq. 5, the continuous PSF's peak);
* truth: the states without jitter (Eq. 38), propagated exactly (no process noise) by the model matrices of
  ``tbd_taichi.motion_models``; a ``model`` column gives the index (in ``MODELS``) of the model that moves the
  target on from that frame.  Velocities in the truth are px/frame (the state's px/s times T), as elsewhere.

Coordinates: the paper's cell (i, j) (1-based, i the column) is centred at (i − ½, j − ½) and its frames count
from 1; here x = column and y = row, 0-based with pixel centres at integers, and frames count from 0, so
x = x_paper − ½, y = y_paper − ½, frame = frame_paper − 1.  AC-CT turns by +ω (the velocity from +x toward
+y, y pointing down the rows), C-CT by −ω.

Cases (``CASES``):

* ``5.1``: one CV target, 40×40 px, Σ 0.7, T 1 s, 30 frames, paper state [5, 0.9, 5, 0.2] at paper frame 5,
  CV for 20 s (present frames 4–23); SNR 10 dB unless ``snr_db`` (the paper runs 12, 10 and 8 dB);
* ``5.2`` (default): §5.2's three targets, 40×40, 40 frames, T 1 s, Σ 0.7, 10 dB, ω = π/10 rad/s.  Targets 1
  and 2 are present at paper frames 5–34 ("vanishes at the 35th frame"): CV 10 s, a turn (AC-CT for 1, C-CT
  for 2) 10 s, CV 10 s; target 3 moves CV at paper frames 10–29;
* ``5.3``: §5.3's STK paths are not published; this substitute keeps its frame (80 columns × 100 rows),
  T = 2 s, Σ = 0.6, 42 frames, launch frames (paper 8, 8 and 15: 7, 7 and 14 here) and SNRs (13, 13 and
  11 dB).  Each launch accelerates (CA, 0.04 px/s² upwards), turns at ω = π/20 rad/s (ωT = π/10 per frame,
  the same turn per frame as §5.2; target 1 clockwise, 2 and 3 anticlockwise), then coasts (CA with zero
  acceleration).  Targets 1–2 are present to frame 28 and target 3 to frame 33 (Table 4's halt times 31.2,
  31.3 and 36.3, less the tracker's two dropped frames, 1-based): at least 3 px inside the image and ≥ 10 px
  apart, well beyond Eq. 12's 6Σ.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .errors import ParameterError
from .motion_models import DIM, MODELS, transition
from .simulate import Scenario
from .tables import TRUTH_COLUMNS, _dtype, make_table

JITTER_SD = 0.5  # §5.1: the imaging position error, px per axis
LONG2012_TRUTH_COLUMNS = TRUTH_COLUMNS + ("model",)
RENDER_SIGMAS = 4.0  # Eq. 4 is rendered out to 4Σ + 1 px from the target


@dataclass(frozen=True)
class Leg:
    """``frames`` frames moved by ``model``; ``acceleration`` (ẍ, ÿ) px/s² set at its start (None: kept)."""

    model: str
    frames: int
    acceleration: tuple | None = None


@dataclass(frozen=True)
class TargetPlan:
    """A target: its state at its first frame (paper units, 0-based pixels: x, ẋ, y, ẏ px and px/s), the frame
    it appears (0-based), its SNR (dB) and its legs (their frames add up to its present frames)."""

    start: tuple
    first: int
    snr_db: float
    legs: tuple


@dataclass(frozen=True)
class Case:
    """A scene: shape (H, W), frames, T (s), Σ (px), ω (rad/s) and its targets."""

    shape: tuple
    frames: int
    T: float
    psf_sigma: float
    omega: float
    targets: tuple


def _paper(x: float, vx: float, y: float, vy: float) -> tuple:
    """A paper state [x, ẋ, y, ẏ] (cell centres at i − ½) in this project's pixels (centres at integers)."""
    return (x - 0.5, vx, y - 0.5, vy)


CASES = {
    "5.1": Case((40, 40), 30, 1.0, 0.7, math.pi / 10, (
        TargetPlan(_paper(5, 0.9, 5, 0.2), 4, 10.0, (Leg("cv", 20),)),)),
    "5.2": Case((40, 40), 40, 1.0, 0.7, math.pi / 10, (
        TargetPlan(_paper(15, 1.5, 10, 0), 4, 10.0, (Leg("cv", 10), Leg("ac-ct", 10), Leg("cv", 10))),
        TargetPlan(_paper(25, -1.3, 18, 0), 4, 10.0, (Leg("cv", 10), Leg("c-ct", 10), Leg("cv", 10))),
        TargetPlan(_paper(20, 0, 35, -1.5), 9, 10.0, (Leg("cv", 20),)))),
    "5.3": Case((100, 80), 42, 2.0, 0.6, math.pi / 20, (
        TargetPlan((32.0, 0.1, 88.0, -0.6), 7, 13.0,
                   (Leg("ca", 8, (0.01, -0.04)), Leg("c-ct", 4), Leg("ca", 10, (0.0, 0.0)))),
        TargetPlan((48.0, -0.1, 90.0, -0.6), 7, 13.0,
                   (Leg("ca", 8, (-0.01, -0.04)), Leg("ac-ct", 4), Leg("ca", 10, (0.0, 0.0)))),
        TargetPlan((40.0, 0.0, 93.0, -0.5), 14, 11.0,
                   (Leg("ca", 8, (0.0, -0.04)), Leg("ac-ct", 5), Leg("ca", 7, (0.0, 0.0)))))),
}


def intensity_for_db(snr_db: float, psf_sigma: float, noise_sigma: float = 1.0) -> float:
    """Eq. 37: I = 2π·σ_n·Σ²·10^(SNR/20)."""
    return 2.0 * math.pi * noise_sigma * psf_sigma ** 2 * 10.0 ** (snr_db / 20.0)


def target_states(plan: TargetPlan, T: float, omega: float, intensity: float) -> tuple[np.ndarray, list[str]]:
    """The target's 7-D states (frames, 7) over its present frames and the model moving it on from each."""
    x = np.zeros(DIM)
    x[:4], x[4] = plan.start, intensity
    states, models = [], []
    for leg in plan.legs:
        if leg.acceleration is not None:
            x[5], x[6] = leg.acceleration
        F = transition(leg.model, T, omega)
        for _ in range(leg.frames):
            states.append(x.copy())
            models.append(leg.model)
            x = F @ x
    return np.array(states), models


def pixel_integrated(shape, x: float, y: float, intensity: float, psf_sigma: float) -> tuple[slice, slice, np.ndarray]:
    """Eq. 4 for a target at (x, y): (rows, cols, values) of the window within RENDER_SIGMAS·Σ + 1 px, clipped
    to the image; values[r, c] = I·fy[r]·fx[c] with f the Gaussian's share of the pixel along each axis."""
    h, w = shape
    r = int(math.ceil(RENDER_SIGMAS * psf_sigma)) + 1
    cx, cy = int(math.floor(x + 0.5)), int(math.floor(y + 0.5))
    c0, c1, r0, r1 = max(cx - r, 0), min(cx + r + 1, w), max(cy - r, 0), min(cy + r + 1, h)
    if c0 >= c1 or r0 >= r1:
        return slice(0, 0), slice(0, 0), np.zeros((0, 0))
    from scipy.special import erf  # imported here: listing the methods does not pay for scipy.special

    s = math.sqrt(2.0) * psf_sigma
    cols, rows = np.arange(c0, c1), np.arange(r0, r1)
    fx = 0.5 * (erf((cols + 0.5 - x) / s) - erf((cols - 0.5 - x) / s))
    fy = 0.5 * (erf((rows + 0.5 - y) / s) - erf((rows - 0.5 - y) / s))
    return slice(r0, r1), slice(c0, c1), intensity * np.outer(fy, fx)


def check_case(case: str, snr_db) -> None:
    """A ParameterError for an unknown case or a bad SNR."""
    if case not in CASES:
        raise ParameterError(f"case must be one of {', '.join(CASES)} (Long et al. 2012 §5.1–5.3), got {case!r}")
    if snr_db is not None and (isinstance(snr_db, bool) or not isinstance(snr_db, (int, float))
                               or not math.isfinite(snr_db) or snr_db <= 0):
        raise ParameterError(f"snr_db must be a finite number > 0 dB (Eq. 5), got {snr_db!r}")


def simulate_long2012(case: str = "5.2", seed: int = 0, snr_db: float | None = None) -> Scenario:
    """The frames (T, H, W) float32, the truth (with ``model``) and the parameters of Long et al.'s §``case``
    scene; ``snr_db`` replaces every target's SNR.  The same seed gives the same frames (jitter and noise)."""
    from .validate import whole

    check_case(case, snr_db)
    whole("seed", seed, 0)
    c = CASES[case]
    rng = np.random.default_rng(seed)
    jitter = rng.normal(0.0, JITTER_SD, (c.frames, 2))
    frames = np.zeros((c.frames,) + c.shape)
    rows = []
    for tid, plan in enumerate(c.targets):
        db = plan.snr_db if snr_db is None else float(snr_db)
        states, models = target_states(plan, c.T, c.omega, intensity_for_db(db, c.psf_sigma))
        for i, (s, m) in enumerate(zip(states, models)):
            f = plan.first + i
            rs, cs, values = pixel_integrated(c.shape, s[0] + jitter[f, 0], s[2] + jitter[f, 1], s[4], c.psf_sigma)
            frames[f, rs, cs] += values
            rows.append((f, tid, s[0], s[2], s[1] * c.T, s[3] * c.T, s[4], MODELS.index(m)))
    frames += rng.standard_normal(frames.shape)
    params = dict(scenario="long2012", case=case, seed=seed, shape=list(c.shape), frames=c.frames, T=c.T,
                  psf_sigma=c.psf_sigma, omega=c.omega, jitter_sd=JITTER_SD, jitter=jitter.round(4).tolist(),
                  snr_db=[plan.snr_db if snr_db is None else float(snr_db) for plan in c.targets])
    return Scenario(frames.astype(np.float32), make_table(rows, _dtype(LONG2012_TRUTH_COLUMNS)), params)
