"""The candidate stage of Güler (2016, §3.4.1) on the host: the top-hat of each of the first m = 3 frames
(``kernels.tophat``: Eqs. 3.4–3.10), their projection I_c (Eq. 3.12), the adaptive threshold T = μ + ασ
(Eq. 3.13) and one candidate per 8-connected component of I_c > T, at its maximum.

Coordinates: x = column, y = row, 0-based.  I_c is dimensionless (a sum of frames each divided by its std)."""
from __future__ import annotations

import numbers

import numpy as np

from .engines import kernel_module
from .errors import InputError, ParameterError

SE_SHAPES = ("square", "disk")
EIGHT_CONNECTED = np.ones((3, 3), bool)


def check_structuring_element(se_size, se_shape, shape) -> None:
    """ParameterError unless ``se_size`` is an odd integer with 3 ≤ se_size ≤ min(H, W) of ``shape`` and
    ``se_shape`` is "square" or "disk"."""
    limit = min(int(shape[0]), int(shape[1]))
    if isinstance(se_size, bool) or not isinstance(se_size, numbers.Integral):
        raise ParameterError(f"se_size must be an odd integer from 3 to {limit}, got {se_size!r}")
    if se_size % 2 == 0:
        raise ParameterError(f"se_size must be odd (3, 5, 7, ...), got {se_size}")
    if se_size < 3:
        raise ParameterError(f"se_size must be at least 3 (larger than a 1-px target), got {se_size}")
    if se_size > limit:
        raise ParameterError(f"se_size must be at most min(H, W) = {limit}, got {se_size}")
    if se_shape not in SE_SHAPES:
        raise ParameterError(f"se_shape must be one of {', '.join(SE_SHAPES)}, got {se_shape!r}")


def _check_frames(frames, name: str) -> np.ndarray:
    """``frames`` as an (m, H, W) array with m ≥ 1 and finite values, else InputError."""
    frames = np.asarray(frames)
    if frames.ndim != 3 or min(frames.shape) < 1:
        raise InputError(f"{name} must be an (m, H, W) stack of frames, got shape {frames.shape}")
    if not np.issubdtype(frames.dtype, np.number) or not np.isfinite(frames).all():
        raise InputError(f"{name} must hold finite numbers")
    return frames


def projection(tophats) -> np.ndarray:
    """I_c = Σ_k D_k / σ_k (Eq. 3.12) of the (m, H, W) top-hatted frames D_k (m = 3 in the thesis), σ_k the
    population std of D_k over the frame; (H, W) float64, dimensionless.  A frame with σ_k = 0 is a
    ParameterError."""
    d = _check_frames(tophats, "tophats").astype(np.float64)
    sigma = d.std(axis=(1, 2))
    if (sigma == 0).any():
        raise ParameterError(f"frame {int(np.argmax(sigma == 0))} is constant after the top-hat (σ_k = 0 in Eq. 3.12)")
    return (d / sigma[:, None, None]).sum(axis=0)


def threshold(ic, alpha: float) -> float:
    """T = μ + α·σ (Eq. 3.13), μ and σ the mean and population std of I_c."""
    if isinstance(alpha, bool) or not isinstance(alpha, numbers.Real) or not np.isfinite(alpha):
        raise ParameterError(f"alpha must be a finite real number, got {alpha!r}")
    ic = np.asarray(ic, np.float64)
    return float(ic.mean() + alpha * ic.std())


def candidates(ic, thr: float, max_candidates: int) -> np.ndarray:
    """(K, 3) float64 rows [x, y, score]: one per 8-connected component of I_c > thr, at its maximum pixel
    (the first in row-major order on a tie), score = I_c there; strongest first (ties: by row, then column),
    at most ``max_candidates`` (the strongest kept)."""
    if isinstance(max_candidates, bool) or not isinstance(max_candidates, numbers.Integral) or max_candidates < 1:
        raise ParameterError(f"max_candidates must be an integer >= 1, got {max_candidates!r}")
    from scipy import ndimage  # imported here: listing the methods does not pay for scipy.ndimage (0.2 s)

    ic = np.asarray(ic, np.float64)
    labels, n = ndimage.label(ic > thr, structure=EIGHT_CONNECTED)
    if n == 0:
        return np.zeros((0, 3))
    peaks = np.asarray(ndimage.maximum(ic, labels, np.arange(1, n + 1)), np.float64)
    at_peak = (labels > 0) & (ic == np.concatenate([[np.inf], peaks])[labels])
    # the first peak pixel of each label in row-major order (scipy's maximum_position leaves ties unspecified)
    _, first = np.unique(labels[at_peak], return_index=True)
    rows, cols = np.nonzero(at_peak)
    rows, cols = rows[first], cols[first]
    scores = ic[rows, cols]
    order = np.lexsort((cols, rows, -scores))[:max_candidates]
    return np.column_stack([cols[order], rows[order], scores[order]]).astype(np.float64)


def tophat_frames(frames, se_size: int, se_shape: str, engine: str = "taichi", kernels=None) -> np.ndarray:
    """(m, H, W) float32 top-hats D_k of the frames (Eqs. 3.4–3.10) on ``engine`` (with ``kernels``, a
    ``TophatKernels`` of that frame shape and element, when the caller keeps one)."""
    frames = _check_frames(frames, "frames")
    shape = frames.shape[1:]
    check_structuring_element(se_size, se_shape, shape)
    if kernels is None:
        kernels = kernel_module(engine, "tophat").TophatKernels(shape, se_size, se_shape)
    out = np.zeros(frames.shape, np.float32)
    for k, frame in enumerate(frames):
        kernels.tophat(np.ascontiguousarray(frame, np.float32), out[k])  # out[k]: a contiguous view
    return out


def find_candidates(frames, alpha: float, se_size: int, se_shape: str, max_candidates: int,
                    engine: str = "taichi", kernels=None) -> tuple[np.ndarray, np.ndarray, float]:
    """The candidate stage on the 3 raw (3, H, W) frames: top-hats, I_c (Eq. 3.12), T (Eq. 3.13) and the
    candidates; returns (candidates (K, 3) [x, y, score], I_c (H, W) float64, T).  ``kernels``: see
    :func:`tophat_frames`."""
    frames = _check_frames(frames, "frames")
    if frames.shape[0] != 3:
        raise InputError(f"frames must be the first 3 frames (m = 3, Eq. 3.12), got {frames.shape[0]}")
    ic = projection(tophat_frames(frames, se_size, se_shape, engine, kernels))
    thr = threshold(ic, alpha)
    return candidates(ic, thr, max_candidates), ic, thr
