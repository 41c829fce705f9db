"""Background suppression and bad-pixel suppression before the filters (real infrared video).

SGDS-PF models every pixel as a point target's PSF plus zero-mean white noise (Eqs. 12–13).
Real frames add sky gradients, cloud and treeline clutter, nonuniformity and compression
noise; on raw frames that clutter, not the target, becomes the saliency.  The
:class:`Preprocessor` turns each raw frame into ``z = (frame − background) / σ``:

* ``background`` — ``none``: the frame's median, σ the global 1.4826·MAD (the paper's
  world: no suppression); ``mean``: the frame's mean; ``spatial``: the mean of a hollow
  window around each pixel (11×11 minus the central 5×5 guard that holds the target's own
  light), i.e. subtraction of a local mean filter; ``temporal``: a running mean over recent
  frames, B ← B + α(frame − B), α = 0.05 (about 20 frames), with frame − B taken before
  the update.
* ``noise`` — every background except ``none`` divides by a local σ: the mean of
  min(|r|, 3σ_global) over 15×15 pixels times √(π/2) (mean absolute deviation → σ for
  Gaussian noise), floored at 0.1·σ_global; so z is close to unit-variance noise wherever
  the background is smooth, and cloud edges are damped.  ``none`` keeps the global σ.
* ``bad_pixels`` — a pixel whose |z| exceeds 4 while all 8 neighbours stay below 0.35·|z|
  is a spike (a point target's PSF lights its neighbours: at Σ = 0.7 px a neighbour carries
  0.36 of the peak, before noise); a pixel that spikes persistently (exponential rate with
  ρ = 0.05 above 0.2: hot, dead or blinking pixels) is set to z = 0 from then on, until it
  stops spiking.

Default: ``none`` with bad-pixel suppression.  ``spatial`` is what real clips need (on the
drone-ir clips ``none`` finds no target at all; see docs/results/drone_ir.md), but on the
simulator it costs detection (SGDS-PF, SNR 2, 200×200, seeds 0–2: mean DSR 0.95 with
``none``, 0.70 with ``spatial``), so it is not the default until that loss is understood;
``temporal`` fails on the simulator (DSR 0) and is for still cameras only.
"""
from __future__ import annotations

import math

import numpy as np

from . import backend
from .errors import ParameterError
from .io import stream_frame
from .normalize import mean_background, normalise_frame, robust_sigma

BACKGROUNDS = ("none", "mean", "spatial", "temporal")
DEFAULT_BACKGROUND = "none"  # see the module notes; real video: "spatial"
OUTER_RADIUS, GUARD_RADIUS = 5, 2  # hollow window: 11×11 minus the central 5×5
NOISE_RADIUS = 7  # 15×15 local noise window
NOISE_CLIP = 3.0  # residuals clipped at 3σ_global before the local noise mean
NOISE_FLOOR = 0.1  # local σ ≥ 0.1·σ_global
MEAN_ABS_TO_SIGMA = math.sqrt(math.pi / 2)  # σ = √(π/2)·E|r| for Gaussian noise
TEMPORAL_ALPHA = 0.05
SPIKE_Z, SPIKE_RATIO, SPIKE_RHO, SPIKE_RATE = 4.0, 0.35, 0.05, 0.2


class Preprocessor:
    """Raw frames → z, one frame at a time (it keeps the temporal background and the bad-pixel rates).

    ``background`` in :data:`BACKGROUNDS`; ``bad_pixels`` switches the bad-pixel suppression;
    ``engine`` "taichi" or "numpy" picks the kernels.
    """

    def __init__(self, shape, background: str = DEFAULT_BACKGROUND, bad_pixels: bool = True, engine: str = "taichi"):
        if background not in BACKGROUNDS:
            raise ParameterError(f"unknown background {background!r}; choose one of {', '.join(BACKGROUNDS)}")
        if engine == "taichi":
            backend.ensure_init()
            from .kernels import background as k
        elif engine == "numpy":
            from .numpy_kernels import background as k
        else:
            raise ParameterError(f"engine must be 'taichi' or 'numpy', got {engine!r}")
        self.k, self.shape = k, (int(shape[0]), int(shape[1]))
        self.background, self.bad_pixels = background, bool(bad_pixels)
        new = lambda: np.zeros(self.shape, np.float32)  # noqa: E731
        self.residual, self.tmp, self.sum_a, self.sum_b = new(), new(), new(), new()
        self.temporal_bg, self.spike_rate = new(), new()
        self.n_frames = 0

    def __call__(self, frame, index: int | None = None) -> np.ndarray:
        """z (float32, H × W) of the next raw frame; InputError for a wrong shape, NaN or inf."""
        index = self.n_frames if index is None else index
        x = np.ascontiguousarray(stream_frame(frame, self.shape, index, "tracker"), dtype=np.float32)
        if self.background == "none":
            z = np.ascontiguousarray(normalise_frame(x, "median").z)
        else:
            z = self.standardised(self.residual_of(x))
        self.n_frames += 1
        if self.bad_pixels:
            out = np.empty_like(z)
            self.k.isolated_spikes(z, self.spike_rate, SPIKE_RHO, SPIKE_Z, SPIKE_RATIO, SPIKE_RATE, out)
            z = out
        return z

    def box_sum(self, src: np.ndarray, dst: np.ndarray, r: int) -> None:
        """(2r+1)² box sum with replicated borders (separable: rows, then columns)."""
        self.k.box_sum_rows(src, self.tmp, r)
        self.k.box_sum_cols(self.tmp, dst, r)

    def residual_of(self, x: np.ndarray) -> np.ndarray:
        """frame − background (raw units) for the mean, spatial and temporal backgrounds."""
        r = self.residual
        if self.background == "mean":
            r[...] = x - np.float32(mean_background(x, 0.0))
        elif self.background == "spatial":
            self.box_sum(x, self.sum_a, OUTER_RADIUS)
            self.box_sum(x, self.sum_b, GUARD_RADIUS)
            self.k.hollow_residual(x, self.sum_a, self.sum_b, float((2 * OUTER_RADIUS + 1) ** 2),
                                   float((2 * GUARD_RADIUS + 1) ** 2), r)
        else:
            self.k.running_residual(x, self.temporal_bg, TEMPORAL_ALPHA, int(self.n_frames == 0), r)
        return r

    def standardised(self, r: np.ndarray) -> np.ndarray:
        """r / local σ (see the module notes); global σ from the residual's MAD."""
        sigma = robust_sigma(r)
        self.k.clipped_abs(r, NOISE_CLIP * sigma, self.sum_a)
        self.box_sum(self.sum_a, self.sum_b, NOISE_RADIUS)
        z = np.empty(self.shape, np.float32)  # a new array: callers keep recent frames
        self.k.standardise(r, self.sum_b, float((2 * NOISE_RADIUS + 1) ** 2), MEAN_ABS_TO_SIGMA, NOISE_FLOOR * sigma, z)
        return z

    def bad_pixel_map(self) -> np.ndarray:
        """Pixels currently neutralised as bad (bool, H × W)."""
        return self.spike_rate > SPIKE_RATE
