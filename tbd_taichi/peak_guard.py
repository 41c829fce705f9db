"""The real-video reporting guard shared by the point trackers: a track's running peak z.

Confirmed clutter in real still-camera video is fainter in z than the targets (docs/results/drone_ir.md), so
under the real-video profile a confirmed track is reported only while the running mean of the largest z near
its estimate is at least ``min_peak_z`` (docs/input-and-background.md).  Not in any of the papers."""
from __future__ import annotations

import math

import numpy as np

PEAK_RHO = 0.1  # a track's running peak z: exponential mean from 0, this weight on the newest frame
SETTLE_FRAMES = 10  # 1/PEAK_RHO: frames after which the running mean holds 65 % of a steady peak (1 − 0.9¹⁰)


def nearest_pixel(x: float, y: float) -> tuple[int, int]:
    """The pixel (column, row) whose centre is nearest to (x, y) (centres at integers)."""
    return int(math.floor(x + 0.5)), int(math.floor(y + 0.5))


def peak_z(z: np.ndarray, x: float, y: float) -> float:
    """The largest z in the 3×3 pixels around (x, y) (σ units; NaN outside the image)."""
    cx, cy = nearest_pixel(x, y)
    window = z[max(cy - 1, 0):max(cy + 2, 0), max(cx - 1, 0):max(cx + 2, 0)]
    return float(window.max()) if window.size else float("nan")


def running_peak_z(previous: float, z: np.ndarray, x: float, y: float) -> float:
    """The running peak z after frame ``z`` with the track at (x, y): previous + ρ·(peak − previous), ρ =
    PEAK_RHO (σ units; unchanged where the 3×3 window is outside the image)."""
    value = peak_z(z, x, y)
    return previous + PEAK_RHO * (value - previous) if math.isfinite(value) else previous
