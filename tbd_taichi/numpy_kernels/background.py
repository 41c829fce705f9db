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


def ring_row_sums(x, rows_outer, rows_inner, r_outer: int, r_inner: int, serial: bool = False) -> None:
    _box_sum_axis(x, rows_outer, r_outer, 1)
    _box_sum_axis(x, rows_inner, r_inner, 1)


def hollow_residual(x, rows_outer, rows_inner, radii, acc, out, serial: bool = False) -> None:
    outer, inner = np.empty_like(x), np.empty_like(x)
    _box_sum_axis(rows_outer, outer, int(radii[0]), 0)
    _box_sum_axis(rows_inner, inner, int(radii[1]), 0)
    ring = np.float32((2 * int(radii[0]) + 1) ** 2) - np.float32((2 * int(radii[1]) + 1) ** 2)
    out[...] = x - (outer - inner) / ring


def clipped_abs_row_sums(r, clip: float, rows, radius: int, serial: bool = False) -> None:
    _box_sum_axis(np.minimum(np.abs(r), np.float32(clip)), rows, radius, 1)


def standardise(r, rows, noise, p, acc, out, serial: bool = False) -> None:
    radius, alpha, first, to_sigma, floor = int(p[0]), np.float32(p[1]), p[2] != 0, np.float32(p[3]), np.float32(p[4])
    abs_sum = np.empty_like(r)
    _box_sum_axis(rows, abs_sum, radius, 0)
    if first:
        noise[...] = abs_sum
    noise += alpha * (abs_sum - noise)
    out[...] = r / np.maximum(to_sigma * noise / np.float32((2 * radius + 1) ** 2), floor)


def running_residual(x, bg, alpha: float, first: int, out, serial: bool = False) -> None:
    if first:
        bg[...] = x
    out[...] = x - bg
    bg += np.float32(alpha) * (x - bg)


def rebase_background(s, prev_r, bg, serial: bool = False) -> None:
    bg[...] = s - prev_r


def row_abs_difference_sums(a, b, out, serial: bool = False) -> None:
    out[...] = np.abs(a.astype(np.float64) - b.astype(np.float64)).sum(axis=1)


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
