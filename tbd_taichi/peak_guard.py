"""The real-video reporting guard shared by the point trackers: a track's running peak z.

Confirmed clutter in real still-camera video is fainter in z than the targets (docs/results/drone_ir.md), so
under the real-video profile a confirmed track is reported only while the running mean of the largest z near
its estimate is at least ``min_peak_z`` (docs/input-and-background.md).  Not in any of the papers."""
from __future__ import annotations


import numpy as np

PEAK_RHO = 0.1  # a track's running peak z: exponential mean from 0, this weight on the newest frame
SETTLE_FRAMES = 10  # 1/PEAK_RHO: frames after which the running mean holds 65 % of a steady peak (1 − 0.9¹⁰)


def peak_z(z: np.ndarray, x, y):
    """The largest z in the 3×3 pixels around (x, y), the window cut at the image's border (σ units; NaN where
    the window lies outside the image); ``x``, ``y``: one position (a float comes back) or arrays of them."""
    cx, cy = (np.floor(np.asarray(v, np.float64) + 0.5).astype(np.int64) for v in (x, y))
    h, w = z.shape
    side = np.arange(-1, 2)
    rows = np.clip(cy[..., None] + side, 0, h - 1)  # a cut window's rows and columns repeat its border ones
    columns = np.clip(cx[..., None] + side, 0, w - 1)
    cells = (rows[..., :, None] * w + columns[..., None, :]).reshape(cx.shape + (9,))
    value = z.ravel()[cells].max(axis=-1).astype(np.float64)
    value = np.where((-1 <= cx) & (cx <= w) & (-1 <= cy) & (cy <= h), value, np.nan)
    return value if value.ndim else float(value)


def running_peak_z(previous, z: np.ndarray, x, y):
    """The running peak z after frame ``z`` with the track at (x, y): previous + ρ·(peak − previous), ρ =
    PEAK_RHO (σ units; unchanged where the 3×3 window is outside the image); one track or arrays of them."""
    value = peak_z(z, x, y)
    out = np.where(np.isfinite(value), previous + PEAK_RHO * (value - previous), previous)
    return out if out.ndim else float(out)
