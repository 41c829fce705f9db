"""Scenario simulator (SGDS-PF section 3.1, Eqs. 1, 14, 44–46).

Target state [x, vx, y, vy, I] in pixels, pixels/frame and total intensity:

* motion: nearly constant velocity, X_f = F·X_{f−1} + n_f (Eqs. 44–45), with
  n_f ~ N(0, Q) and Q = blockdiag(q1·[[T³/3, T²/2], [T²/2, T]] ×2, q2·T) (Eq. 46),
  T = 1 frame.  q1 = 0.001 px²/frame³, q2 = 0.01 (intensity units)²/frame;
* sensor: a circular Gaussian PSF of width Σ = 0.7 px point-sampled at pixel
  centres, h = I/(2πΣ²)·exp(−((i−x)² + (j−y)²)/(2Σ²)) (Eq. 14), plus white
  N(0, σ²) noise with σ = 1;
* SNR (Eq. 1) is the centre-pixel signal over the noise std, so the initial
  total intensity is I = SNR·σ·2πΣ² (I clamped at ≥ 0 as it random-walks).

Initial speed is U[0.5, 1] px/frame in a random direction.  With
``motion="stay"`` (default) whole trajectories are redrawn until every position is
at least ``margin`` px inside the image; with ``motion="transit"`` a target starts
just outside an edge, crosses, and has truth rows only for the frames in which its
centre is in view (x in [−0.5, W−0.5), y in [−0.5, H−0.5)).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .errors import ParameterError
from .tables import TRUTH_DTYPE, in_image, make_table

MAX_TRIES = 500
PSF_RADIUS_SIGMAS = 4.0  # render the PSF out to 4Σ; beyond it h < 4e-4 of the peak


@dataclass
class Scenario:
    """Simulated frames (T, H, W) float32, their truth table and the generating parameters."""

    frames: np.ndarray
    truth: np.ndarray
    params: dict = field(default_factory=dict)


def intensity_for_snr(snr: float, psf_sigma: float = 0.7, noise_sigma: float = 1.0) -> float:
    """Total intensity I whose pixel-centred peak is ``snr``·σ (Eq. 1 with Eq. 14)."""
    return snr * noise_sigma * 2.0 * math.pi * psf_sigma ** 2


def process_noise_factor(q1: float) -> np.ndarray:
    """Cholesky factor L of one axis' q1·[[1/3, 1/2], [1/2, 1]] (Eq. 46, T = 1): n = L·N(0, I)."""
    return np.linalg.cholesky(q1 * np.array([[1.0 / 3.0, 0.5], [0.5, 1.0]]))


def ncv_trajectory(rng: np.random.Generator, start: np.ndarray, n_frames: int, q1: float, q2: float) -> np.ndarray:
    """(n_frames, 5) states [x, vx, y, vy, I] from ``start`` by Eqs. 44–46, I clamped at ≥ 0."""
    chol = process_noise_factor(q1) if q1 > 0 else np.zeros((2, 2))
    noise = rng.standard_normal((n_frames - 1, 5))
    states = np.empty((n_frames, 5))
    states[0] = start
    for f in range(1, n_frames):
        x, vx, y, vy, inten = states[f - 1]
        dx, dvx = chol @ noise[f - 1, 0:2]
        dy, dvy = chol @ noise[f - 1, 2:4]
        states[f] = (x + vx + dx, vx + dvx, y + vy + dy, vy + dvy,
                     max(inten + math.sqrt(q2) * noise[f - 1, 4], 0.0))
    return states


def in_view(states: np.ndarray, shape: tuple[int, int], margin: float) -> np.ndarray:
    """Per row of ``states`` ([x, vx, y, vy, I] …): the centre at least ``margin`` px inside the image (pixel
    centres at integers, so the image spans [−0.5, W − 0.5) × [−0.5, H − 0.5))."""
    return in_image(states[:, 0], states[:, 2], shape, margin)


def _start_stay(rng, shape, n_frames, speed, intensity, margin):
    """Start state whose straight path stays ≥ margin inside the image."""
    h, w = shape
    room = math.hypot(w - 1 - 2 * margin, h - 1 - 2 * margin) / max(n_frames - 1, 1)
    hi = min(speed[1], 0.95 * room)
    v = rng.uniform(min(speed[0], hi), hi)
    theta = rng.uniform(0, 2 * math.pi)
    vx, vy = v * math.cos(theta), v * math.sin(theta)
    dx, dy = vx * (n_frames - 1), vy * (n_frames - 1)
    lo_x, hi_x = margin - min(dx, 0), w - 1 - margin - max(dx, 0)
    lo_y, hi_y = margin - min(dy, 0), h - 1 - margin - max(dy, 0)
    if lo_x > hi_x or lo_y > hi_y:
        return None
    return np.array([rng.uniform(lo_x, hi_x), vx, rng.uniform(lo_y, hi_y), vy, intensity])


def _start_transit(rng, shape, speed, intensity):
    """Start state one pixel outside a random edge, heading inwards within ±60° of the normal."""
    h, w = shape
    edge = rng.integers(4)
    normal = [0.0, math.pi, 0.5 * math.pi, 1.5 * math.pi][edge]  # from left, right, top, bottom
    theta = normal + rng.uniform(-math.pi / 3, math.pi / 3)
    v = rng.uniform(*speed)
    x = [-1.5, w - 0.5 + 1.0, rng.uniform(0, w - 1), rng.uniform(0, w - 1)][edge]
    y = [rng.uniform(0, h - 1), rng.uniform(0, h - 1), -1.5, h - 0.5 + 1.0][edge]
    return np.array([x, v * math.cos(theta), y, v * math.sin(theta), intensity])


def target_trajectory(rng, shape, n_frames, intensity, speed, q1, q2, motion, margin) -> tuple[np.ndarray, np.ndarray]:
    """States (T, 5) of one target and the boolean in-view mask (T,)."""
    for _ in range(MAX_TRIES):
        if motion == "stay":
            start = _start_stay(rng, shape, n_frames, speed, intensity, margin)
            if start is None:
                continue
            states = ncv_trajectory(rng, start, n_frames, q1, q2)
            if in_view(states, shape, margin).all():
                return states, np.ones(n_frames, bool)
        else:
            states = ncv_trajectory(rng, _start_transit(rng, shape, speed, intensity), n_frames, q1, q2)
            visible = in_view(states, shape, 0.0)
            if visible.sum() >= min(5, max(n_frames - 4, 0)):  # entering can take 4 frames
                return states, visible
    raise ParameterError(f"could not keep a target in a {shape[0]}x{shape[1]} image for {n_frames} frames "
                         f"after {MAX_TRIES} tries; use a smaller speed, fewer frames or motion='transit'")


def render_psf(image: np.ndarray, x: float, y: float, intensity: float, psf_sigma: float) -> None:
    """Add the point-sampled Gaussian PSF of Eq. 14 at (x, y) to ``image`` in place."""
    h, w = image.shape
    r = int(math.ceil(PSF_RADIUS_SIGMAS * psf_sigma))
    cx, cy = int(math.floor(x + 0.5)), int(math.floor(y + 0.5))
    x0, x1, y0, y1 = max(cx - r, 0), min(cx + r + 1, w), max(cy - r, 0), min(cy + r + 1, h)
    if x0 >= x1 or y0 >= y1:
        return
    jj, ii = np.mgrid[y0:y1, x0:x1]
    d2 = (ii - x) ** 2 + (jj - y) ** 2
    image[y0:y1, x0:x1] += (intensity / (2 * math.pi * psf_sigma ** 2) * np.exp(-d2 / (2 * psf_sigma ** 2))).astype(image.dtype)


def _check(shape, n_frames, snr, targets, speed, q1, q2, psf_sigma, noise_sigma, motion):
    from .validate import positive, whole

    if len(shape) != 2 or min(shape) < 1:
        raise ParameterError(f"shape must be (H, W) with H, W ≥ 1, got {shape}")
    whole("frames", n_frames, 1)
    whole("targets", targets, 0)
    for name, value in (("snr", snr), ("q1", q1), ("q2", q2)):
        positive(name, value, 0.0, closed=True)
    positive("psf_sigma", psf_sigma)
    positive("noise_sigma", noise_sigma)
    if not 0 <= speed[0] <= speed[1]:
        raise ParameterError(f"speed must be (low, high) with 0 ≤ low ≤ high px/frame, got {speed}")
    if motion not in ("stay", "transit"):
        raise ParameterError(f"motion must be 'stay' or 'transit', got {motion!r}")
    check_memory(shape, n_frames)


PIXEL_BYTES = 12  # a simulated pixel: the float32 frames plus the noise and the signal being summed, bytes


def check_memory(shape, n_frames: int) -> None:
    """Refuse a sequence of ``n_frames`` frames of ``shape`` that cannot fit in memory (before any is made)."""
    from .validate import memory_guard

    memory_guard(f"simulating {n_frames} frames of {shape[0]}x{shape[1]}", n_frames * shape[0] * shape[1] * PIXEL_BYTES)


def simulate(shape=(200, 200), frames: int = 150, snr: float = 2.0, targets: int = 1, seed: int = 0, *,
             speed=(0.5, 1.0), q1: float = 0.001, q2: float = 0.01, psf_sigma: float = 0.7,
             noise_sigma: float = 1.0, motion: str = "stay", margin: float = 2.0) -> Scenario:
    """Simulate ``frames`` frames of size ``shape`` = (H, W) with ``targets`` dim targets.

    Returns a :class:`Scenario` with float32 frames (T, H, W) and the truth table
    (frame, target_id, x, y, vx, vy, intensity).  The same seed gives the same scenario.
    """
    shape = tuple(int(s) for s in shape)
    speed = (float(speed[0]), float(speed[1]))
    _check(shape, frames, snr, targets, speed, q1, q2, psf_sigma, noise_sigma, motion)
    rng = np.random.default_rng(seed)
    intensity = intensity_for_snr(snr, psf_sigma, noise_sigma)
    paths = [target_trajectory(rng, shape, frames, intensity, speed, q1, q2, motion, margin) for _ in range(targets)]
    images, truth = render_scene(paths, shape, frames, psf_sigma, noise_sigma, rng)
    params = dict(shape=list(shape), frames=frames, snr=snr, targets=targets, seed=seed, speed=list(speed),
                  q1=q1, q2=q2, psf_sigma=psf_sigma, noise_sigma=noise_sigma, motion=motion, margin=margin)
    return Scenario(images, truth, params)


def render_scene(paths, shape, frames: int, psf_sigma: float, noise_sigma: float,
                 rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Frames (T, H, W) float32 and their truth table from ``paths``, one (states (T, 5), in-view mask (T,))
    per target (its index the target id): each target's PSF (Eq. 14) at every frame, then N(0, σ²) noise drawn
    from ``rng``; truth rows for the frames in view."""
    images = np.zeros((frames,) + tuple(shape), dtype=np.float32)
    rows = []
    for target, (states, visible) in enumerate(paths):
        for f in range(frames):
            x, vx, y, vy, inten = states[f]
            render_psf(images[f], x, y, inten, psf_sigma)
            if visible[f]:
                rows.append((f, target, x, y, vx, vy, inten))
    images += rng.standard_normal(images.shape, dtype=np.float32) * np.float32(noise_sigma)
    return images, make_table(rows, TRUTH_DTYPE)


def to_camera(frames: np.ndarray, offset: float = 1000.0, gain: float = 20.0, bits: int = 14) -> np.ndarray:
    """Raw-camera-like integers: round(offset + gain·frames) clipped to [0, 2^bits − 1] (uint8 or uint16)."""
    dtype = np.uint8 if bits <= 8 else np.uint16
    return np.clip(np.rint(offset + gain * frames), 0, 2 ** bits - 1).astype(dtype)
