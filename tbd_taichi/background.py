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
  the update; ``spatiotemporal``: the ``spatial`` residual s, minus its own running mean
  (α = 0.01 after a cumulative-mean warm-up, α_t = max(0.01, 1/(t+1))), so that everything that
  stays put in the image (tree tops, cloud texture, fixed-pattern noise, dark border rows) goes
  and moving targets stay; a frame whose mean |Δs| jumps above 4× its running level (and above
  0.1·mean|s|), such as a codec keyframe or a gain step, re-bases the background
  (B = s − previous residual), so the foreground carries over and the new texture does not
  light up.  Its σ is the local mean of min(|r|, 3σ_s) over 15×15 pixels, smoothed over time
  (α = 0.05, warm-up as above), times √(π/2), floored at 0.3·σ_s (σ_s: the global 1.4826·MAD of
  s): compressed video repeats static blocks exactly, so the temporal residual's own noise can
  be near zero there, and the floor keeps z on the scale of the scene's spatial noise.
* ``noise`` — ``mean``, ``spatial`` and ``temporal`` divide by a local σ: the mean of
  min(|r|, 3σ_global) over 15×15 pixels times √(π/2) (mean absolute deviation → σ for
  Gaussian noise), floored at 0.1·σ_global; so z is close to unit-variance noise wherever
  the background is smooth, and cloud edges are damped.  ``none`` keeps the global σ.
* ``bad_pixels`` — a pixel whose |z| exceeds 4 while all 8 neighbours stay below 0.35·|z|
  is a spike (a point target's PSF lights its neighbours: at Σ = 0.7 px a neighbour carries
  0.36 of the peak, before noise); a pixel that spikes persistently (exponential rate with
  ρ = 0.05 above 0.2: hot, dead or blinking pixels) is set to z = 0 from then on, until it
  stops spiking.

Default: ``none`` with bad-pixel suppression (the paper's model, with which the simulated
suite was run).  Real still-camera video: :data:`REAL_VIDEO` (``spatiotemporal`` with the snr 5
preset, and tracks reported only while their running peak z is ≥ 15, since confirmed clutter
is fainter in z than the targets): ``spatial`` alone keeps still point-like clutter, which SGDS-PF confirms (drone-ir:
11.65 false points per frame), and the temporal residual of real video is heavy-tailed, so the
snr 1.4 preset confirms its tail (see docs/results/drone_ir.md).  ``temporal`` (a running mean
of the raw frame) fails on the simulator (DSR 0).
"""
from __future__ import annotations

import math

import numpy as np

from . import backend
from .engines import kernel_module
from .errors import ParameterError
from .io import stream_frame
from .normalize import mean_background, normalise_frame, robust_sigma

BACKGROUNDS = ("none", "mean", "spatial", "temporal", "spatiotemporal")
DEFAULT_BACKGROUND = "none"  # see the module notes; real video: REAL_VIDEO
REAL_VIDEO = dict(background="spatiotemporal", snr=5.0, min_peak_z=16.0)  # SGDSPF settings for real still-camera video (README)
OUTER_RADIUS, GUARD_RADIUS = 5, 2  # hollow window: 11×11 minus the central 5×5
RING_RADII = (OUTER_RADIUS, GUARD_RADIUS)  # hollow_residual's compile-time radii
NOISE_RADIUS = 7  # 15×15 local noise window
NOISE_CLIP = 3.0  # residuals clipped at 3σ_global before the local noise mean
NOISE_FLOOR = 0.1  # local σ ≥ 0.1·σ_global
MEAN_ABS_TO_SIGMA = math.sqrt(math.pi / 2)  # σ = √(π/2)·E|r| for Gaussian noise
TEMPORAL_ALPHA = 0.05
ST_ALPHA, ST_NOISE_ALPHA = 0.01, 0.05  # spatiotemporal: background and noise time constants (frames⁻¹)
ST_FLOOR = 0.3  # its σ floored at 0.3·σ_s
JUMP_RATIO, JUMP_MIN = 4.0, 0.1  # global change: mean|Δs| > 4× its running level and > 0.1·mean|s|
JUMP_LEVEL_RHO = 0.1  # running level of mean|Δs| (exponential, frames without a jump)
SPIKE_Z, SPIKE_RATIO, SPIKE_RHO, SPIKE_RATE = 4.0, 0.35, 0.05, 0.2


class Preprocessor:
    """Raw frames → z, one frame at a time (it keeps the temporal background and the bad-pixel rates).

    ``background`` in :data:`BACKGROUNDS`; ``bad_pixels`` switches the bad-pixel suppression;
    ``engine`` "taichi" or "numpy" picks the kernels.
    """

    def __init__(self, shape, background: str = DEFAULT_BACKGROUND, bad_pixels: bool = True, engine: str = "taichi"):
        if background not in BACKGROUNDS:
            raise ParameterError(f"unknown background {background!r}; choose one of {', '.join(BACKGROUNDS)}")
        k = kernel_module(engine, "background")
        if engine == "taichi":
            from .launch import Launcher

            k = Launcher(k)
        self.k, self.shape = k, (int(shape[0]), int(shape[1]))
        self.serial = engine == "taichi" and backend.serial_loops(self.shape[0] * self.shape[1])
        self.background, self.bad_pixels = background, bool(bad_pixels)
        new = lambda: np.zeros(self.shape, np.float32)  # noqa: E731
        self.residual, self.tmp, self.sum_a, self.sum_b = new(), new(), new(), new()
        self.temporal_bg, self.spike_rate = new(), new()
        self.column_sums = np.zeros((2, self.shape[1]), np.float64)  # running column sums of the box filters
        if background == "spatiotemporal":
            self.st_bg, self.st_noise, self.prev_s, self.prev_r, self.zeros = new(), new(), new(), new(), new()
            self.row_sums = np.zeros(self.shape[0], np.float64)
            self.change_level = None
        self.global_changes: list[int] = []  # frames that re-based the spatiotemporal background
        self.n_frames = 0

    def __call__(self, frame, index: int | None = None) -> np.ndarray:
        """z (float32, H × W) of the next raw frame; InputError for a wrong shape, NaN or inf."""
        index = self.n_frames if index is None else index
        x = np.ascontiguousarray(stream_frame(frame, self.shape, index, "tracker"), dtype=np.float32)
        if self.background == "none":
            z = np.ascontiguousarray(normalise_frame(x, "median").z)
        elif self.background == "spatiotemporal":
            z = self.moving_standardised(x)
        else:
            z = self.standardised(self.residual_of(x))
        self.n_frames += 1
        if self.bad_pixels:
            out = np.empty_like(z)
            self.k.isolated_spikes(z, self.spike_rate, SPIKE_RHO, SPIKE_Z, SPIKE_RATIO, SPIKE_RATE, out, self.serial)
            z = out
        return z

    def residual_of(self, x: np.ndarray) -> np.ndarray:
        """frame − background (raw units) for the mean, spatial and temporal backgrounds."""
        r = self.residual
        if self.background == "mean":
            r[...] = x - np.float32(mean_background(x, 0.0))
        elif self.background in ("spatial", "spatiotemporal"):
            self.k.ring_row_sums(x, self.sum_a, self.sum_b, *RING_RADII, self.serial)
            self.k.hollow_residual(x, self.sum_a, self.sum_b, RING_RADII, self.column_sums, r, self.serial)
        else:
            self.k.running_residual(x, self.temporal_bg, TEMPORAL_ALPHA, int(self.n_frames == 0), r, self.serial)
        return r

    def mean_abs_difference(self, a: np.ndarray, b: np.ndarray) -> float:
        """mean |a − b| over the image (f64 row sums, added in row order: deterministic)."""
        self.k.row_abs_difference_sums(a, b, self.row_sums, self.serial)
        return float(self.row_sums.sum()) / a.size

    def is_global_change(self, s: np.ndarray) -> bool:
        """A frame whose mean |Δs| jumps above JUMP_RATIO× its running level and JUMP_MIN·mean|s|
        (codec keyframe, gain step); the level follows the frames without a jump."""
        change = self.mean_abs_difference(s, self.prev_s)
        level = self.change_level
        if level is not None and change > JUMP_RATIO * level and change > JUMP_MIN * self.mean_abs_difference(s, self.zeros):
            return True
        self.change_level = change if level is None else (1 - JUMP_LEVEL_RHO) * level + JUMP_LEVEL_RHO * change
        return False

    def moving_residual(self, s: np.ndarray) -> np.ndarray:
        """r = s − B, B the running mean of the spatial residual s (cumulative over the first
        1/ST_ALPHA frames); re-based after a global change (module notes)."""
        t = self.n_frames
        if t > 0 and self.is_global_change(s):
            self.k.rebase_background(s, self.prev_r, self.st_bg, self.serial)
            self.global_changes.append(t)
        r = self.prev_r  # read by the re-base above; now this frame's residual
        self.k.running_residual(s, self.st_bg, max(ST_ALPHA, 1.0 / (t + 1)), int(t == 0), r, self.serial)
        np.copyto(self.prev_s, s)
        return r

    def moving_standardised(self, x: np.ndarray) -> np.ndarray:
        """z of the ``spatiotemporal`` background: moving residual over its time-smoothed local σ."""
        s = self.residual_of(x)  # the spatial residual
        sigma_s = robust_sigma(s)
        r = self.moving_residual(s)
        t = self.n_frames
        return self.over_local_sigma(r, NOISE_CLIP * sigma_s, self.st_noise, max(ST_NOISE_ALPHA, 1.0 / max(t, 1)),
                                     t == 0, ST_FLOOR * sigma_s)

    def standardised(self, r: np.ndarray) -> np.ndarray:
        """r / local σ (see the module notes); global σ from the residual's MAD."""
        sigma = robust_sigma(r)
        return self.over_local_sigma(r, NOISE_CLIP * sigma, self.tmp, 0.0, True, NOISE_FLOOR * sigma)

    def over_local_sigma(self, r: np.ndarray, clip: float, noise: np.ndarray, alpha: float, first: bool,
                         floor: float) -> np.ndarray:
        """z = r / max(√(π/2)·N/window, floor): the residual over its local σ, N the running mean (rate ``alpha``;
        this frame's value where ``first``) of Σ min(|r|, clip) over the (2·NOISE_RADIUS + 1)² window around each
        pixel, kept in ``noise``.  A new array: callers keep recent frames."""
        z = np.empty(self.shape, np.float32)
        self.k.clipped_abs_row_sums(r, clip, self.sum_a, NOISE_RADIUS, self.serial)
        params = np.array([NOISE_RADIUS, alpha, float(first), MEAN_ABS_TO_SIGMA, floor], np.float64)
        self.k.standardise(r, self.sum_a, noise, params, self.column_sums, z, self.serial)
        return z

    def bad_pixel_map(self) -> np.ndarray:
        """Pixels currently neutralised as bad (bool, H × W)."""
        return self.spike_rate > SPIKE_RATE
