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

The sums and the draws are one kernel launch a frame for every PP handed over in it (``kernels/handover.py``, NumPy
twin ``numpy_kernels/handover.py``), over the frames kept in a ring (:class:`RecentFrames`).  The jitter and each
draw's offset come from a NumPy generator keyed on (seed, frame, HANDOVER_STREAM, draw), the draw counting the tracks
begun at the frame from 1, so the tracker's other draws are the same as without it.
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


def multi_frame_draws(kernels, members: dict, pps: list, size: int, recent: RecentFrames, frame: int, sigmas,
                      rngs: list, jitter: float = 0.0) -> list:
    """For each PP (start, n) of ``pps`` (``members[…][start:start + n]``), the indices (into ``members``) of
    ``size`` particles drawn ∝ exp(s_i), s_i the retrodicted sum over the frames ``recent`` holds before ``frame``,
    by systematic resampling with an offset from its generator in ``rngs``; only E = 1 particles are drawn where the
    PP has any.  With ``jitter`` > 0 each PP's velocities first get N(0, jitter²) px/frame per axis from its
    generator, written into ``members``.  The sums and the draws of all PPs are one launch of the engine's
    ``multi_frame_draws``."""
    if not len(pps):
        return []
    for (start, n), rng in zip(pps, rngs):
        if jitter > 0:
            for name in ("vx", "vy"):
                part = members[name][start:start + n]
                part[...] = part + np.float32(jitter) * rng.standard_normal(n).astype(np.float32)
    state = np.stack([np.asarray(members[k], np.float32) for k in ("x", "y", "vx", "vy", "inten")]
                     + [np.asarray(members["e"] == 1, np.float32)])
    table = np.zeros((3, len(pps)), np.int32)
    table[:2] = np.array(pps, np.int64).reshape(-1, 2).T
    back, slots = recent.before(frame)
    values = np.array([*psf_constants(*sigmas), recent.shape[0], size] + [rng.random() for rng in rngs], np.float64)
    picks = np.empty(len(pps) * size, np.int32)
    scores = np.zeros((2, state.shape[1]), np.float64)
    kernels.multi_frame_draws(state, table, recent.frames, np.stack([back, slots.astype(np.float32)]), values,
                              picks, scores)
    return list(picks.reshape(len(pps), size))
