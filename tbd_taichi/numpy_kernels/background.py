"""NumPy twins of ``tbd_taichi.kernels.background`` (same signatures, outputs written in place;
``serial``, the kernels' loop mode, changes nothing here)."""
from __future__ import annotations

import numpy as np


def _box_sum_axis(src: np.ndarray, dst: np.ndarray, r: int, axis: int) -> None:
    n = src.shape[axis]
    idx = np.clip(np.arange(-r, n + r), 0, n - 1)
    padded = np.take(src.astype(np.float64), idx, axis=axis)
    c = np.cumsum(padded, axis=axis)
    c = np.concatenate([np.zeros_like(np.take(c, [0], axis=axis)), c], axis=axis)
    hi = np.take(c, np.arange(2 * r + 1, n + 2 * r + 1), axis=axis)
    lo = np.take(c, np.arange(0, n), axis=axis)
    dst[...] = (hi - lo).astype(np.float32)


def box_sum_rows(src: np.ndarray, dst: np.ndarray, r: int, serial: bool = False) -> None:
    _box_sum_axis(src, dst, r, 1)


def box_sum_cols(src: np.ndarray, dst: np.ndarray, r: int, acc=None, serial: bool = False) -> None:
    _box_sum_axis(src, dst, r, 0)


def hollow_residual(x, outer, inner, n_outer: float, n_inner: float, out, serial: bool = False) -> None:
    out[...] = x - (outer - inner) / np.float32(np.float32(n_outer) - np.float32(n_inner))


def running_residual(x, bg, alpha: float, first: int, out, serial: bool = False) -> None:
    if first:
        bg[...] = x
    out[...] = x - bg
    bg += np.float32(alpha) * (x - bg)


def rebase_background(s, prev_r, bg, serial: bool = False) -> None:
    bg[...] = s - prev_r


def row_abs_difference_sums(a, b, out, serial: bool = False) -> None:
    out[...] = np.abs(a.astype(np.float64) - b.astype(np.float64)).sum(axis=1)


def clipped_abs(r, clip: float, out, serial: bool = False) -> None:
    out[...] = np.minimum(np.abs(r), np.float32(clip))


def standardise(r, abs_sum, n: float, to_sigma: float, floor: float, out, serial: bool = False) -> None:
    out[...] = r / np.maximum(np.float32(to_sigma) * abs_sum / np.float32(n), np.float32(floor))


def isolated_spikes(z, rate, rho: float, z_hi: float, ratio: float, rate_max: float, out, serial: bool = False) -> None:
    a = np.abs(z)
    padded = np.pad(a, 1, constant_values=0)
    h, w = z.shape
    neighbours = np.zeros_like(a)
    for di in (-1, 0, 1):
        for dj in (-1, 0, 1):
            if di or dj:
                neighbours = np.maximum(neighbours, padded[1 + di:1 + di + h, 1 + dj:1 + dj + w])
    spike = ((a > np.float32(z_hi)) & (neighbours < np.float32(ratio) * a)).astype(np.float32)
    rate[...] = np.float32(1.0 - rho) * rate + np.float32(rho) * spike
    out[...] = np.where(rate > np.float32(rate_max), np.float32(0), z)
