"""Per-frame normalisation ``z = (frame − background) / σ``.

Noise model (SGDS-PF Eqs. 12–13): every pixel is the target's PSF signal plus
zero-mean white Gaussian noise of standard deviation σ, independent across pixels
and frames.  The likelihood ratio of Eq. 15 and the thresholds of Eqs. 23 and 26
are only meaningful on data of that form, so raw camera frames (8-bit, 14-bit, any
offset and gain) are first brought to zero-mean, unit-variance noise:

* the background is the frame's median (default) or mean, one number per frame;
* σ is the median absolute deviation scaled by 1.4826, which equals the standard
  deviation for Gaussian noise and ignores the few bright target pixels.

After normalisation the filters use σ = 1.  These global estimates are the
``none`` and ``mean`` backgrounds of ``tbd_taichi.background.Preprocessor``, which
adds local (spatial) and temporal backgrounds with a local σ for cluttered video.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np

from .errors import ParameterError

MAD_TO_SIGMA = 1.4826  # σ = 1.4826·MAD for Gaussian noise
MAX_SAMPLES = 1 << 14  # robust statistics use at most this many pixels (a fixed stride); see stat_sample


def stat_sample(frame: np.ndarray, max_samples: int = MAX_SAMPLES) -> np.ndarray:
    """Flat float32 view of the frame, strided so it holds at most ``max_samples`` pixels.

    The stride is the smallest one that is small enough and shares no factor with the width W, so
    the samples visit every column (a stride that divides W would see only some columns, and
    alias column-periodic fixed-pattern noise).  With 2¹⁴ samples of Gaussian noise the median's
    standard error is 1.2533σ/√n ≈ 0.01σ and the MAD's about 0.9 % of σ, well below what moves a
    detection; the two medians of 2¹⁴ values cost about 30 µs by :func:`sample_median` (0.3 ms by
    ``np.median``; of 41,000 values, all even columns of a 320×256 frame, 0.9 ms)."""
    frame = np.asarray(frame, dtype=np.float32)
    flat = frame.reshape(-1)
    width = frame.shape[-1] if frame.ndim else 1
    stride = max(1, -(-flat.size // max_samples))
    while stride > 1 and math.gcd(stride, width) != 1:
        stride += 1
    return flat[::stride]


def sample_median(values: np.ndarray) -> float:
    """The median of a 1-D float32 sample, exactly as ``np.median`` gives it (the middle value, or the f32
    mean of the two middle ones), from one ``np.partition``: ``np.median`` spends about 0.1 ms more on
    checks around the same partition (2¹⁴ values: 14 µs against 110 µs).  The sample must be finite."""
    n = len(values)
    if n == 0:
        return math.nan
    k = n // 2
    if n % 2:
        return float(np.partition(values, k)[k])
    part = np.partition(values, (k - 1, k))
    return float((part[k - 1] + part[k]) / part.dtype.type(2))


def robust_sigma(frame: np.ndarray, median: float | None = None) -> float:
    """Noise standard deviation 1.4826·MAD (same units as the frame); ``median`` if already known.

    Coarsely quantised frames can have MAD = 0; the standard deviation is used then,
    and 1 for a constant frame (so z is 0 there, not NaN).
    """
    sample = stat_sample(frame)
    centre = sample_median(sample) if median is None else median
    mad = sample_median(np.abs(sample - centre))
    if mad > 0:
        return MAD_TO_SIGMA * mad
    std = float(sample.std())
    return std if std > 0 else 1.0


def median_background(frame: np.ndarray, median: float) -> float:
    """Global background: the frame's median."""
    return median


def mean_background(frame: np.ndarray, median: float) -> float:
    """Global background: the frame's mean."""
    return float(np.asarray(frame, dtype=np.float64).mean())


# background estimators get the frame and its (sampled) median, which σ needs anyway
BACKGROUNDS: dict[str, Callable[[np.ndarray, float], float]] = {
    "median": median_background,
    "mean": mean_background,
}


@dataclass
class Normalised:
    """A normalised frame and the statistics that made it (raw units)."""

    z: np.ndarray
    background: float
    sigma: float


def normalise_frame(frame: np.ndarray, background: str = "median") -> Normalised:
    """``z = (frame − background) / σ`` with σ = 1.4826·MAD (float32 result)."""
    try:
        estimate = BACKGROUNDS[background]
    except KeyError:
        raise ParameterError(f"unknown background {background!r}; choose one of {', '.join(BACKGROUNDS)}") from None
    frame = np.asarray(frame, dtype=np.float32)
    median = sample_median(stat_sample(frame))
    bg = estimate(frame, median)
    sigma = robust_sigma(frame, median)
    z = (frame - np.float32(bg)) * np.float32(1.0 / sigma)
    return Normalised(z.astype(np.float32, copy=False), bg, sigma)


def normalise_sequence(frames: np.ndarray, background: str = "median") -> np.ndarray:
    """Normalise every frame of a (T, H, W) sequence independently."""
    return np.stack([normalise_frame(f, background).z for f in frames])
