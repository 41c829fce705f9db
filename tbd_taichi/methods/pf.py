"""The "original PF": single-target particle-filter track-before-detect (Ristic, Arulampalam &
Gordon, *Beyond the Kalman Filter*, 2004, ch. 11; SGDS-PF's reference [41]).

One filter of N particles with a Markov existence variable: births (E 0 → 1, P_b) are
uniform over the image, with speed U[0, 1] px/frame and intensity uniform over the range
of Eq. 26 converted to total intensity; deaths with P_d; NCV motion; the Eq. 15
likelihood ratio; multinomial resampling.  N comes from the SGDS-PF paper's Table 3 for
the image size and SNR band.  A target is declared while the existence probability
(the fraction of E = 1 particles) exceeds ``threshold`` (default 0.5: the posterior
says "present" more likely than not); each run of declared frames is one track.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from ..errors import ParameterError
from ..background import DEFAULT_BACKGROUND, Preprocessor
from .sgds.params import snr_band
from ..particles import ParticlePool
from ..peak_guard import SETTLE_FRAMES, running_peak_z
from ..simulate import intensity_for_snr
from ..tables import TRACK_DTYPE, make_table
from .registry import MethodSpec, OneSequence, keyword_factory, param, validate_params

# SGDS-PF Table 3, original PF particle numbers by SNR band [2,∞), [1.8,2), [1.6,1.8), [1.4,1.6), (0,1.4)
TABLE3 = {50: (10_000, 14_000, 18_000, 24_000, 30_000), 200: (14_000, 20_000, 25_000, 30_000, 60_000)}
# Table 5 (320×256 semi-physical), SNR 2, 1.6, 1.2
TABLE5 = (40_000, 82_000, 123_000)


# the real-video guard's level for the one filter (docs/methods/pf.md#real-video): the running peak starts from 0 at
# each declaration and holds 65 % of a steady peak after SETTLE_FRAMES frames, so a target must peak at ≈ 15.4σ to
# outlast the restart check (measured on the drone-ir clips against 8, 12 and 16)
REAL_VIDEO_MIN_PEAK_Z = 10.0


def table3_particles(shape, snr: float) -> int:
    """Particle count of the original PF for an image of ``shape`` (H, W) and SNR ``snr``.

    Up to 100×100 px: Table 3's 50×50 row; up to 250×250: its 200×200 row; larger: Table 5
    (320×256) scaled by the image area.
    """
    area = shape[0] * shape[1]
    if area <= 100 * 100:
        return TABLE3[50][snr_band(snr)]
    if area <= 250 * 250:
        return TABLE3[200][snr_band(snr)]
    n = TABLE5[0] if snr >= 2 else TABLE5[1] if snr >= 1.6 else TABLE5[2]
    return int(math.ceil(n * area / (320 * 256)))


def birth_intensity_range(snr: float, psf_sigma: float = 0.7) -> tuple[float, float]:
    """Eq. 26's [snr − 2, snr + 3] (in σ units of the peak) as total intensity, lower end ≥ SNR 0.5."""
    return intensity_for_snr(max(snr - 2.0, 0.5), psf_sigma), intensity_for_snr(snr + 3.0, psf_sigma)


@dataclass(frozen=True)
class PFParams:
    """The original PF's parameters (Ristic et al. 2004, ch. 11, as SGDS-PF's §3 runs it)."""

    snr: float = param(1.4, doc="lowest target SNR to detect: the newborn intensity range and Table 3's count",
                       symbol="SNR", source="SGDS-PF Eqs. 1, 26", low=0, low_closed=False)
    n_particles: int | None = param(None, doc="particles (auto: SGDS-PF Table 3 for the image size and SNR)",
                                    symbol="N", unit="particles", source="SGDS-PF Tables 3, 5", low=1,
                                    optional=True)
    pb: float = param(0.05, doc="birth probability (E 0 → 1)", symbol="P_b", source="Eq. 7", low=0, high=1)
    pd: float = param(0.05, doc="death probability (E 1 → 0)", symbol="P_d", source="Eq. 8", low=0, high=1)
    threshold: float = param(0.5, doc="declare a target while the existence probability exceeds this",
                             symbol="P_E threshold", source="not in the paper", low=0, high=1, low_closed=False,
                             high_closed=False)
    q1: float = param(0.001, doc="process noise of the NCV motion", symbol="q1", unit="px²/frame³",
                      source="SGDS-PF Eq. 46", low=0)
    q2: float = param(0.01, doc="process noise of the intensity random walk", symbol="q2",
                      source="SGDS-PF Eq. 46", low=0)
    psf_sigma: float = param(0.7, doc="standard deviation of the Gaussian PSF", symbol="Σ", unit="px",
                             source="SGDS-PF Eq. 14", low=0, low_closed=False)
    vmax: float = param(1.0, doc="newborn speed U[0, vmax]", unit="px/frame", source="not in the paper", low=0)
    systematic: bool = param(False, doc="systematic instead of multinomial resampling", source="Eq. 18")
    min_peak_z: float = param(0.0, doc="real-video guard: a declared target is reported only while its running "
                              "peak z is at least this, and the search restarts (every particle absent) when it is "
                              "below this after 10 or more declared frames (0: off; docs/methods/pf.md#real-video)",
                              unit="σ", source="not in the paper", low=0)


class OriginalPF(OneSequence):
    """Single-target PF-TBD over a frame stream.

    ``update(frame)`` takes one raw frame, normalises it, steps the filter and returns the
    tracks rows declared for that frame (0 or 1).  ``finish()`` returns all rows.
    """

    def __init__(self, shape, snr: float = 1.4, seed: int = 0, engine: str = "taichi", arch: str | None = None,
                 n_particles: int | None = None, pb: float = 0.05, pd: float = 0.05, threshold: float = 0.5,
                 q1: float = 0.001, q2: float = 0.01, psf_sigma: float = 0.7, vmax: float = 1.0,
                 background: str = DEFAULT_BACKGROUND, bad_pixels: bool = True, systematic: bool = False,
                 min_peak_z: float = 0.0):
        if len(shape) != 2 or min(shape) < 5:
            raise ParameterError(f"shape must be (H, W) with H, W ≥ 5, got {shape}")
        self.params = validate_params(PFParams(snr=snr, n_particles=n_particles, pb=pb, pd=pd, threshold=threshold,
                                               q1=q1, q2=q2, psf_sigma=psf_sigma, vmax=vmax, systematic=systematic,
                                               min_peak_z=min_peak_z), "original PF")
        self.shape = (int(shape[0]), int(shape[1]))
        self.n_particles = int(n_particles or table3_particles(self.shape, snr))
        self.threshold, self.systematic = threshold, systematic
        self.pool = ParticlePool([self.n_particles], self.shape, engine=engine, seed=seed, q1=q1, q2=q2,
                                 psf_sigma=psf_sigma, arch=arch)
        self.pool.configure_groups([0], "uniform", pb=pb, pd=pd, vmax=vmax,
                                   intensity=birth_intensity_range(snr, psf_sigma))
        self.pool.set_counts([self.n_particles])  # all particles start absent (E = 0)
        self.preprocess = Preprocessor(self.shape, background, bad_pixels, engine)
        self.frame = 0
        self.track_id = 0
        self.declared = False
        self.peak_z, self.declared_frames, self.restarts = 0.0, 0, 0  # the real-video guard (min_peak_z)
        self.rows: list[tuple] = []
        self.p_exist: list[float] = []
        self.seconds = {"normalise": 0.0, "filter": 0.0}

    def update(self, frame: np.ndarray) -> list[tuple]:
        """Step on one raw frame; returns [(frame, track_id, x, y, vx, vy, intensity, p_exist)] if declared."""
        self._check_open("update")
        t0 = time.perf_counter()
        z = self.preprocess(frame, self.frame)
        t1 = time.perf_counter()
        self.pool.step(self.frame, z, systematic=self.systematic)
        est = self.pool.estimates()
        self.seconds["normalise"] += t1 - t0
        self.seconds["filter"] += time.perf_counter() - t1
        p = float(est.p_exist[0])
        self.p_exist.append(p)
        out = []
        if p > self.threshold and np.isfinite(est.x[0]):
            if not self.declared:
                self.track_id += 1
                self.declared, self.peak_z, self.declared_frames = True, 0.0, 0
            row = (self.frame, self.track_id, float(est.x[0]), float(est.y[0]), float(est.vx[0]), float(est.vy[0]),
                   float(est.intensity[0]), p)
            out = self._guarded(row, z)
        else:
            self.declared = False
        self.rows.extend(out)
        self.frame += 1
        return out

    def _guarded(self, row: tuple, z: np.ndarray) -> list[tuple]:
        """The declared ``row`` as reported under the real-video guard (min_peak_z > 0): kept while the running
        peak z at the estimate (:func:`~tbd_taichi.peak_guard.running_peak_z`, from 0 at each declaration) is at
        least min_peak_z; a target declared SETTLE_FRAMES frames or more and below it in this frame is dropped and
        the search restarts with every particle absent, so the one filter is not held by faint clutter for good.
        The running peak then holds 65 % of a steady peak: a target needs a peak of ≈ min_peak_z/0.65 to outlast
        the check, and one whose declaration breaks off within every 10 frames is never checked."""
        limit = self.params.min_peak_z
        if limit <= 0:
            return [row]
        self.peak_z = running_peak_z(self.peak_z, z, row[2], row[3])
        self.declared_frames += 1
        if self.peak_z >= limit:
            return [row]
        if self.declared_frames >= SETTLE_FRAMES:
            self.pool.set_state({0: {"x": np.zeros(self.n_particles, np.float32)}})  # E = 0 everywhere
            self.declared, self.restarts = False, self.restarts + 1
        return []

    def finish(self) -> np.ndarray:
        """Every declared row as a tracks table."""
        self._close_sequence()
        return make_table(self.rows, TRACK_DTYPE)


def pf_params(shape, **overrides) -> PFParams:
    """The original PF's parameters (``n_particles`` None: Table 3 for ``shape`` and ``snr``), validated."""
    return validate_params(PFParams(**overrides), "original PF")


def pf_particles(shape, params: PFParams) -> int:
    """The configured count, or Table 3's for ``shape`` and ``snr``."""
    return params.n_particles or table3_particles(shape, params.snr)


SPEC = MethodSpec(
    name="pf", title="original PF",
    paper="Ristic, Arulampalam & Gordon 2004",
    kind="point-tbd",
    description="single-target particle-filter TBD with a Markov existence variable over the whole image; "
                "the baseline of SGDS-PF's comparisons",
    params=PFParams, factory=keyword_factory(OriginalPF), make_params=pf_params,
    options=("background", "bad_pixels"),
    aliases={"snr": "snr", "particles": "n_particles", "threshold": "threshold", "min_peak_z": "min_peak_z"},
    rank=1, particle_count=pf_particles, real_video={"min_peak_z": REAL_VIDEO_MIN_PEAK_Z},
    assumes=("one point target at a time (Gaussian PSF, Σ = 0.7 px), nearly constant velocity ≤ 1 px/frame; peak "
             "SNR ≥ snr (1.4; Table 3 particles for it); background: paper profile the frame's median, white "
             "Gaussian noise of σ from the MAD; real-video profile a spatiotemporal background and local σ, snr 5, "
             f"the peak-z guard at {REAL_VIDEO_MIN_PEAK_Z:g}"),
)
