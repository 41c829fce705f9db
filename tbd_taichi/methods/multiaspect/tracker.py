"""The multiaspect detector/tracker over a frame stream (Bruno et al. 2008): per frame the local mean is removed,
the GMRF parameters are estimated (Eq. 13; or fixed), d = A·y is computed (Eq. 16) and one resample-move (§3.2) or
auxiliary (§3.3) step runs; the target is declared present iff P̂(z = 0) < ½ (Eq. 26) and reported as the mean of
the present particles with their most frequent aspect (§3.4)."""
from __future__ import annotations

import time

import numpy as np

from ...gmrf import GmrfParams, estimate_gmrf
from ...multiaspect import LocalPlane
from ...io import stream_frame
from ...tables import TRACK_COLUMNS, _dtype, make_table
from ..registry import OneSequence
from .params import multiaspect_params, particles, resolve
from .pool import FILTERS, MultiaspectPool

EXTRA_COLUMNS = ("aspect",)
STAGES = ("local_mean", "gmrf", "particles")  # local mean; GMRF estimate; d-map and the filter step


def entry_cells(shape, template_shape, entry: str) -> np.ndarray | None:
    """The extended grid's cells f₀ covers: those whose centroid is a pixel of the frame (``image``), or all."""
    if entry != "image":
        return None
    hh, hw = (template_shape[1] - 1) // 2, (template_shape[2] - 1) // 2
    out = np.zeros((shape[0] + 2 * hh, shape[1] + 2 * hw), bool)
    out[hh:hh + shape[0], hw:hw + shape[1]] = True
    return out


def track_dtype() -> np.dtype:
    """The tracks table: TRACK_COLUMNS and ``aspect`` (1..K)."""
    return _dtype(TRACK_COLUMNS + EXTRA_COLUMNS)


class MultiaspectTracker(OneSequence):
    """``update(frame)`` returns [(frame, track_id, x, y, vx, vy, intensity, confidence, aspect)] when the target is
    declared present (confidence = 1 − P̂(z = 0); intensity = the peak of the aspect's template, input units), else
    []; a new track id starts at every absent → present decision.  ``p_absent`` keeps P̂(z = 0) per frame."""

    def __init__(self, shape, filter: str = "rs", seed: int = 0, engine: str = "taichi", arch: str | None = None,
                 **params):
        if filter not in FILTERS:
            raise ValueError(f"filter must be one of {FILTERS}")
        self.shape = (int(shape[0]), int(shape[1]))
        self.p = multiaspect_params(self.shape, **params)
        self.r = resolve(self.p, self.shape)
        self.filter = filter
        self.n_particles = particles(filter, self.p)
        self.pool = MultiaspectPool(self.shape, self.r.templates.shape, self.r.G, 1, self.n_particles, seed, engine,
                                    arch)
        self.pool.start(self.r.p_absent, self.r.prior_law, self.r.motion)
        self.local_mean = LocalPlane(self.shape, self.r.mean_window)
        self.birth_support = entry_cells(self.shape, self.r.templates.shape, self.p.entry)
        self.peaks = np.zeros(len(self.r.templates))
        self.gmrf: GmrfParams | None = None
        self.gmrf_history: list[GmrfParams] = []
        self.p_absent: list[float] = []
        self.rows: list[tuple] = []
        self.frame, self.track_id, self.declared = 0, 0, False
        self.seconds = {s: 0.0 for s in STAGES}

    def clutter(self, y: np.ndarray) -> np.ndarray:
        """(β_h, β_v, σ_c²) of this frame: fixed, or Eq. 13's maximum likelihood warm-started at the last frame's."""
        if self.r.fixed_gmrf is not None:
            return np.array(self.r.fixed_gmrf, np.float32)
        self.gmrf = estimate_gmrf(y, approximate=self.p.log_det == "approximate", start=self.gmrf)
        self.gmrf_history.append(self.gmrf)
        return np.array([self.gmrf.beta_h, self.gmrf.beta_v, self.gmrf.sigma_c2], np.float32)

    def set_templates(self, sigma_c: float) -> None:
        """The templates in the input's units: a file's as they are, the vehicle's with peak 10^(PTCR/20)·σ_c."""
        t = self.r.templates * (10.0 ** (self.p.ptcr / 20.0) * sigma_c if self.r.relative else 1.0)
        self.templates = t
        self.pool.set_templates(t)
        self.peaks = t.reshape(len(t), -1).max(axis=1)

    def update(self, frame: np.ndarray) -> list[tuple]:
        """Step on one raw frame; the rows declared for it (0 or 1)."""
        self._check_open("update")
        t0 = time.perf_counter()
        x = stream_frame(frame, self.shape, self.frame, "tracker").astype(np.float64)
        y = (x - self.local_mean(x)).astype(np.float32)
        t1 = time.perf_counter()
        gmrf = self.clutter(y)
        t2 = time.perf_counter()
        if self.frame == 0:
            self.set_templates(float(np.sqrt(gmrf[2])))
        self.pool.set_frames(y[None], gmrf[None])
        if self.r.data_births:
            self.pool.set_births(self.p.birth_share, self.birth_support)
        self.pool.step(self.filter, self.frame, self.p.p_a, self.p.exit == "coupled", self.p.mh_moves,
                       self.r.data_births)
        est = self.pool.presence()[0]
        t3 = time.perf_counter()
        for stage, dt in zip(STAGES, (t1 - t0, t2 - t1, t3 - t2)):
            self.seconds[stage] += dt
        self.p_absent.append(est.p_absent)
        out = []
        if est.present:
            if not self.declared:
                self.track_id += 1
            m = est.mean
            out.append((self.frame, self.track_id, float(m[0]), float(m[2]), float(m[1]), float(m[3]),
                        float(self.peaks[est.aspect - 1]), 1.0 - est.p_absent, est.aspect))
        self.declared = est.present
        self.rows.extend(out)
        self.frame += 1
        return out

    def finish(self) -> np.ndarray:
        """Every declared row as a tracks table (with ``aspect``)."""
        self._close_sequence()
        return make_table(self.rows, track_dtype())
