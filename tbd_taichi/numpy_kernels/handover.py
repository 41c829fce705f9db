"""NumPy twin of ``tbd_taichi.kernels.handover`` (same arguments, output written in place)."""
from __future__ import annotations

import numpy as np

from ..kernels.models.likelihood import PAD
from .models import point_psf_log_ratio


def retrodicted_log_ratio(state, frames, back, slots, constants, h: int, out) -> None:
    """Twin of the kernel: Eq. 15's ratios of all particles on all frames at once (f32), summed over the frames in
    order in f64."""
    w = np.asarray(frames).shape[1] - 2 * PAD
    x, y, vx, vy, inten = (np.asarray(row, np.float32) for row in state)
    k, n = len(back), len(x)
    stack = np.asarray(frames).reshape(-1, h + 2 * PAD, w + 2 * PAD)[:, PAD:-PAD, PAD:-PAD]
    steps = np.asarray(back, np.float32)[:, None]
    ratios = point_psf_log_ratio((x - steps * vx).ravel(), (y - steps * vy).ravel(), np.tile(inten, k), stack,
                                 tuple(np.float32(c) for c in constants), np.repeat(np.asarray(slots), n))
    out[...] = 0.0
    for row in ratios.reshape(k, n):
        out += row
