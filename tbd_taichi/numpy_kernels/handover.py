"""NumPy twin of ``tbd_taichi.kernels.handover`` (same arguments, outputs written in place)."""
from __future__ import annotations

import numpy as np

from ..kernels.handover import ANY_E, DRAWS, E, H_ROWS, INTEN, NOT_DRAWN, OFFSETS, SIZE, START, VX, VY, X, Y
from ..kernels.models.likelihood import PAD
from .models import point_psf_log_ratio


def multi_frame_draws(state, pps, frames, window, values, picks, scores) -> None:
    """Twin of the kernel: the members of all populations as one vector (their population ``owner``, their place
    ``j`` in it), Eq. 15's ratios on all frames at once (f32) summed over the frames in order in f64, each
    population's cumulative weights along the rows of a padded table (sequential sums, as the kernel's loop), and
    the draws as counts per member (:func:`draws_below`)."""
    h, size = int(values[H_ROWS]), int(values[DRAWS])
    n = pps[SIZE].astype(np.int64)
    owner = np.repeat(np.arange(len(n)), n)
    j = np.arange(n.sum()) - np.repeat(np.cumsum(n) - n, n)
    i = pps[START][owner] + j
    e = state[E, i] == 1.0
    pps[ANY_E] = np.bincount(owner, weights=e, minlength=len(n)) > 0
    drawn = e | (pps[ANY_E][owner] == 0)
    s = np.where(drawn, 0.0, NOT_DRAWN)
    s[drawn] = retrodicted_sums(state[:, i[drawn]], frames, window, values[:4].astype(np.float32), h)
    scores[0, i] = s
    top = np.full(len(n), NOT_DRAWN)
    np.maximum.at(top, owner, s)
    table = np.zeros((len(n), max(int(n.max(initial=0)), 1)))
    table[owner, j] = np.where(drawn, np.exp(s - top[owner]), 0.0)
    cumulative = np.cumsum(table, axis=1)
    scores[1, i] = cumulative[owner, j]
    total = cumulative[np.arange(len(n)), np.maximum(n - 1, 0)]
    below = draws_below(cumulative[owner, j], total[owner], size, values[OFFSETS:OFFSETS + len(n)][owner])
    counts = below - np.where(j > 0, np.concatenate([[0], below[:-1]]), 0)
    picks[:counts.sum()] = np.repeat(i, counts)


def draws_below(cumulative, total, size: int, u) -> np.ndarray:
    """Twin of the kernel's ``draws_below``: min(max(⌈cumulative/total·size − u⌉, 0), size)."""
    return np.clip(np.ceil(cumulative / total * np.float64(size) - u), 0, size).astype(np.int64)


def retrodicted_sums(state, frames, window, constants, h: int) -> np.ndarray:
    """s_i = Σ_k Eq. 15's ratio of particle i (columns of ``state``, rows as the kernel's) at
    (x − back_k·vx, y − back_k·vy) on z_k, the ratios f32, summed over k in order in f64."""
    w = np.asarray(frames).shape[1] - 2 * PAD
    x, y, vx, vy, inten = (np.asarray(state[row], np.float32) for row in (X, Y, VX, VY, INTEN))
    back, slots = np.asarray(window[0], np.float32), np.asarray(window[1]).astype(np.int64)
    out = np.zeros(len(x), np.float64)
    if not len(back) or not len(x):
        return out
    stack = np.asarray(frames).reshape(-1, h + 2 * PAD, w + 2 * PAD)[:, PAD:-PAD, PAD:-PAD]
    steps = back[:, None]
    ratios = point_psf_log_ratio((x - steps * vx).ravel(), (y - steps * vy).ravel(), np.tile(inten, len(back)),
                                 stack, tuple(np.float32(c) for c in constants), np.repeat(slots, len(x)))
    for row in ratios.reshape(len(back), len(x)):
        out += row
    return out
