"""SGDS-PF's multi-frame hand-over (issue 43; not in the paper): a handed-over particle population (PP) is drawn
into its tracking PF by its likelihood over the frames before the hand-over, not uniformly.

Algorithm 2 hands a potential target's PP to a tracking PF "by random eliminating or copying" (uniform draws,
:func:`~.populations.resize_population`).  At SNR 1.2 the PP's particles still disagree on the velocity by 0.2–1.3
px/frame and on the position by 0.5–4 px, and one frame's likelihood cannot pull the tracking PF's cloud back onto
the target: the track drifts off before it can be confirmed (docs/results/sgds_explain.md).  Here each particle of
the PP with E = 1 is taken back along its own velocity (constant velocity, Eq. 9 without noise) to the K frames
before the hand-over, and Eq. 15's log-likelihood ratio is summed over them,

    s_i = Σ_{j=1…K} log ω̃(z_{f−j} | x_i − j·vx_i, y_i − j·vy_i, I_i),

so a hypothesis whose path does not follow the target over those frames gets little weight; the tracking PF's
N_tpf particles are then drawn ∝ exp(s_i) (systematic resampling).  With ``jitter`` σ_v > 0, each velocity first
gets N(0, σ_v²) px/frame per axis, so the draw can choose among more velocities than the searching PF kept.
Frame f itself is not summed again: the PP's particles were resampled on it in the searching PF's step.

The sum is one kernel launch a frame for every PP handed over in it (``kernels/handover.py``, NumPy twin
``numpy_kernels/handover.py``), over the frames kept in a ring (:class:`RecentFrames`).  The draw's randomness comes
from a NumPy generator keyed on (seed, frame, HANDOVER_STREAM, draw), the draw counting the tracks begun at the
frame from 1, so the tracker's other draws are the same as without it.
"""
from __future__ import annotations

import numpy as np

from ...engines import kernel_module
from ...kernels.models.likelihood import PAD
from ...numpy_kernels.models import psf_constants

HANDOVER_STREAM = 77  # the key of the multi-frame hand-over's generator, beside (seed, frame)


def engine_kernels(engine: str):
    """The ``handover`` kernels of ``engine`` (Taichi's through the lean launch path of ``tbd_taichi.launch``)."""
    kernels = kernel_module(engine, "handover")
    if engine == "taichi":
        from ...launch import Launcher

        kernels = Launcher(kernels)
    return kernels


class RecentFrames:
    """The normalised frames of the last ``k`` frames before the current one (and the current one), each with its
    zero border of PAD pixels, in a ring of k + 1 slots stacked one above the other (the kernel's layout)."""

    def __init__(self, k: int, shape):
        self.k, self.shape = int(k), (int(shape[0]), int(shape[1]))
        h, w = self.shape
        self.frames = np.zeros(((self.k + 1) * (h + 2 * PAD) if self.k else 0, w + 2 * PAD), np.float32)
        self.frame_of_slot = [-1] * (self.k + 1)

    def add(self, frame: int, z: np.ndarray) -> None:
        """Frame ``frame``'s z (H, W), copied into its slot (frame mod k + 1)."""
        if self.k > 0:
            slot, rows = frame % (self.k + 1), self.shape[0] + 2 * PAD
            np.copyto(self.frames[slot * rows + PAD:(slot + 1) * rows - PAD, PAD:-PAD], z, casting="unsafe")
            self.frame_of_slot[slot] = int(frame)

    def before(self, frame: int) -> tuple:
        """(frames back j, their slots) of the stored frames 1 ≤ j ≤ k before ``frame``, oldest first."""
        kept = sorted((g, slot) for slot, g in enumerate(self.frame_of_slot) if 1 <= frame - g <= self.k)
        return np.array([frame - g for g, _ in kept], np.float32), np.array([slot for _, slot in kept], np.int32)


def retrodicted_log_ratio(kernels, state: dict, recent: RecentFrames, frame: int, sigmas) -> np.ndarray:
    """s_i = Σ_j Eq. 15's log ratio of particle i at (x − j·vx, y − j·vy) with its intensity on z_{frame−j}, over
    the frames ``recent`` holds before ``frame``, oldest first, in f64 (0 where it holds none).  ``state``: float32
    arrays x, y, vx, vy, inten (px, px/frame, σ units); ``sigmas``: (Σ, σ); ``kernels``: the engine's
    ``handover`` module."""
    back, slots = recent.before(frame)
    rows = np.stack([np.asarray(state[k], np.float32) for k in ("x", "y", "vx", "vy", "inten")])
    out = np.zeros(rows.shape[1], np.float64)
    if len(back) and rows.shape[1]:
        constants = np.array(psf_constants(*sigmas), np.float32)
        kernels.retrodicted_log_ratio(rows, recent.frames, back, slots, constants, recent.shape[0], out)
    return out


def multi_frame_draws(kernels, members: dict, pps: list, size: int, recent: RecentFrames, frame: int, sigmas,
                      rngs: list, jitter: float = 0.0) -> list:
    """For each PP (start, n) of ``pps`` (``members[…][start:start + n]``), the indices (from start) of ``size``
    particles drawn ∝ exp(s_i) (:func:`retrodicted_log_ratio` before ``frame``, one launch for all PPs) by
    systematic resampling with its generator in ``rngs``; only E = 1 particles are drawn where the PP has any.
    With ``jitter`` > 0 each PP's velocities first get N(0, jitter²) px/frame per axis from its generator, written
    into ``members``."""
    picked = []
    for (start, n), rng in zip(pps, rngs):
        part = slice(start, start + n)
        if jitter > 0:
            for name in ("vx", "vy"):
                members[name][part] = members[name][part] + \
                    np.float32(jitter) * rng.standard_normal(n).astype(np.float32)
        e = members["e"][part] == 1
        picked.append(start + np.flatnonzero(e if e.any() else np.ones(n, bool)))
    every = np.concatenate(picked) if picked else np.zeros(0, np.int64)
    scores = retrodicted_log_ratio(kernels, {k: members[k][every] for k in ("x", "y", "vx", "vy", "inten")}, recent,
                                   frame, sigmas)
    draws, first = [], 0
    for (start, n), rng, pick in zip(pps, rngs, picked):
        s = np.full(n, -np.inf)
        s[pick - start] = scores[first:first + len(pick)]
        first += len(pick)
        w = np.exp(s - s.max())
        cdf = np.cumsum(w / w.sum())
        positions = (rng.random() + np.arange(size)) / size
        draws.append(start + np.minimum(np.searchsorted(cdf, positions), n - 1))
    return draws
