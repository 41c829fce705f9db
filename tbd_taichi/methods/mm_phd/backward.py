"""The backward recursion of SMC-PHD (Long et al. 2012, §3.2 item 3, Eqs. 25–27): once a track is confirmed, its
gated capture particles are run back over the frames before the capture, and the estimates are prepended."""
from __future__ import annotations

import numpy as np

from ...motion_models import VX, VY, X, Y
from .estimation import Capture, gated, live_dims, unpack
from .params import Derived, MMPHDParams
from .pool import PhdPool

BACKWARD_KEY = 1 << 30  # frame keys of the backward passes: BACKWARD_KEY + track_id·4096 + step


class BackwardRecursion:
    """A one-group pool of L_max slots that runs Eqs. 26–27 (F⁻¹ dynamics, w ← e·w, model switches by Π) and
    Eqs. 14–24 on earlier frames."""

    def __init__(self, shape, p: MMPHDParams, d: Derived, seed: int, engine: str, arch: str | None):
        self.p, self.d = p, d
        self.pool = PhdPool(shape, p, d, p.max_particles, 1, seed, engine, arch)
        self.dims = live_dims(d.models)

    def rows(self, capture: Capture, frames: list[tuple[int, np.ndarray]], track_id: int) -> list[tuple]:
        """(frame, mean, model probabilities, peak-cell mass) for each frame the target is tracked going back
        through ``frames`` = [(frame index, z), …] (newest first, the capture's frame excluded), until
        ``halt_drops`` consecutive drops (peak-cell mass < confirm_above: going back is as speculative as a new track)."""
        p, pool = self.p, self.pool
        keep = gated(capture, self.dims, p.gate_probability)  # Eq. 25
        state, model = capture.state[keep], capture.model[keep]
        n = len(state)
        pool.load(0, state, model, 1.0 / n, 0)
        out, drops = [], 0
        T, r0 = p.frame_interval, self.d.class_radius
        mean, cov = capture.mean, capture.cov
        for step, (frame, z) in enumerate(frames):
            key = BACKWARD_KEY + (track_id % (1 << 18)) * 4096 + step % 4096
            pool.set_frame(z, births=False)
            sd = np.sqrt(max(cov[VX, VX], cov[VY, VY], 0.0))
            pool.layout([n], [0], [1.0], [mean[[X, Y]] - mean[[VX, VY]] * T], [r0 + p.gate_sigmas * sd * T])
            pool.propagate(key, n, 0, backward=True)  # Eqs. 26–27
            pool.weigh(0, 1, estimate=True)
            e = unpack(pool.estimates()[0], len(self.d.models))
            if e.peak >= p.confirm_above:
                drops = 0
                mean, cov = e.mean, e.cov
                out.append((frame, e.mean, e.probs, e.peak))
            else:
                drops += 1
                if drops >= p.halt_drops:
                    break
                mean = mean.copy()
                mean[[X, Y]] -= mean[[VX, VY]] * T  # the gate moves on by the prediction
            n = pool.resample(key, [p.max_particles], [1.0 / p.max_particles], [True])
        return out
