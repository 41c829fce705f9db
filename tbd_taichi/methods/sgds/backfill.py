"""SGDS-PF's backfill (issue 43; not in the paper): a reported track's whole path begins up to K frames before its
first row, on the line through its first points.

A potential target (PP) is handed over only once PTp > T_PTp (Algorithm 1), so the target was in view for several
frames before its track's first row (and below SNR 1.6 the multi-frame hand-over, handover.py, has just weighed
the PP's particles over the 8 frames before).  With (x̂0, v̂x) and (ŷ0, v̂y) the least-squares line through the
path's first L = 20 points (constant velocity, Eq. 9 without noise; px, px/frame, frames counted from the first row
f0), the backfilled rows are

    x(g) = x̂0 + (g − f0)·v̂x,   y(g) = ŷ0 + (g − f0)·v̂y,   g = f0 − K … f0 − 1,

none before frame 0 or outside the image, and none within DUPLICATE_RADIUS of another track's row in the same frame
(one target, one track).  A path of fewer than MIN_POINTS points is not backfilled: its line rests on the tracking
PF's converging first points.  The line's value at f0 is not the first row itself, so the path may step by up to
about a pixel there.  Only the whole paths change; the tracks, their confirmation and the online rows do not
(docs/methods/sgds.md#searching-and-tracking-modes).
"""
from __future__ import annotations

from collections import defaultdict

import numpy as np

from ...tables import in_image
from .confirmation import near_any

FIT_POINTS = 20  # L: path points the line is fitted to
MIN_POINTS = 10  # paths with fewer points are not backfilled


def backfilled(path, frames: int, shape: tuple, fit: int = FIT_POINTS) -> list:
    """Up to ``frames`` rows before a path's first (rows (frame, x, y, vx, vy, intensity, confidence), oldest first),
    on the line through its first ``fit`` points (module docstring), with the line's velocity (px/frame) and the
    first row's intensity and confidence; none before frame 0 or outside the image of ``shape`` (rows, columns),
    and none for a path of fewer than MIN_POINTS points."""
    head = list(path)[:fit]
    if frames <= 0 or len(head) < min(MIN_POINTS, fit):
        return []
    f0, *_, inten, conf = head[0]
    f = np.array([row[0] for row in head], np.float64) - f0
    vx, x0 = np.polyfit(f, [row[1] for row in head], 1)
    vy, y0 = np.polyfit(f, [row[2] for row in head], 1)
    rows = []
    for g in range(max(f0 - frames, 0), f0):
        x, y = x0 + (g - f0) * vx, y0 + (g - f0) * vy
        if in_image(x, y, shape):
            rows.append((g, float(x), float(y), float(vx), float(vy), inten, conf))
    return rows


def backfilled_paths(paths: dict, frames: int, shape: tuple, fit: int = FIT_POINTS) -> dict:
    """{track id: its :func:`backfilled` rows} for ``paths`` {track id: path rows}, less the rows within
    DUPLICATE_RADIUS of another track's path row in the same frame."""
    by_frame = defaultdict(list)
    for track, rows in paths.items():
        for f, x, y, *_ in rows:
            by_frame[f].append((track, x, y))
    return {track: [row for row in backfilled(rows, frames, shape, fit)
                    if not near_any([(x, y) for other, x, y in by_frame.get(row[0], ()) if other != track],
                                    row[1], row[2])]
            for track, rows in paths.items()}
