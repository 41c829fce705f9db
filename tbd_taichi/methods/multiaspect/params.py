"""The multiaspect filters' parameters (Bruno, Araújo & Pavlov 2008, §§2–4), declared once for ``ma-rs`` and
``ma-apf``, and what they resolve to: the template stack, G, the motion noise, the prior and f₀, the GMRF mode."""
from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from ...errors import ParameterError
from ...gmrf import check_gmrf
from ...multiaspect import (MOTION_FORMS, PAPER_PRIOR, PAPER_Q, PAPER_T, PAPER_ZETA, aspect_transition,
                            check_templates, check_transition, extended_grid, half_sizes, load_array, motion_noise,
                            noise_factor)
from ..registry import param, validate_params

PAPER_PARTICLES = {"rs": 8000, "apf": 5000}  # §4: N_p of the resample-move and auxiliary filters
PRIORS = ("image", "paper")
MIN_MEAN_WINDOW = 15  # px: the auto window for a small support (a 3×3 mean would hold a point target)


@dataclass(frozen=True)
class MultiaspectParams:
    """Bruno et al.'s parameters (§4) with the choices the paper leaves open."""

    n_particles: int | None = param(None, doc="particles (auto: the paper's 8000 for ma-rs, 5000 for ma-apf)",
                                    symbol="N_p", unit="particles", source="§4", low=1, high=50_000_000,
                                    optional=True)
    p_a: float = param(0.05, doc="probability that a target enters while none is present (not in the paper: "
                       "one entry in 20 frames; detection within a few frames, few false alarms on clutter)",
                       symbol="p_a",
                       source="Eq. 2", low=0, high=1)
    q: float = param(PAPER_Q, doc="power spectral density of the white-noise acceleration", symbol="q",
                     unit="m²/s³", source="§4, Eq. 4", low=0)
    T: float = param(PAPER_T, doc="time between frames", symbol="T", unit="s", source="§4", low=0,
                     low_closed=False, high=3600)
    zeta: float = param(PAPER_ZETA, doc="ground resolution (m per pixel, both axes)", symbol="ζ", unit="m/px",
                        source="§4, Eq. 3", low=0, low_closed=False)
    motion: str = param("continuous", doc="white-noise acceleration in continuous (CWNA, ref. [3]) or discrete "
                        "(DWNA) form", source="Eq. 4, ref. [3]", choices=MOTION_FORMS)
    G: str = param("auto", doc="aspect transition matrix: auto (§4's for K = 4, else 0.4 to each adjacent "
                   "aspect) or a .npy K×K column-stochastic file", symbol="G", source="Eq. 1, §4")
    templates: str = param("vehicle", doc="aspect templates: vehicle (the bruno2008 scenario's four, scaled by "
                           "ptcr) or a .npy (K, h, w) float stack, h, w odd, centroid at the centre, values in the "
                           "input's units; cut to the centred box of the non-zero pixels (§2's r, l)",
                           symbol="a_kl(z)", source="Eq. 8")
    ptcr: float = param(6.5, doc="the vehicle templates' peak over the clutter: max a = 10^(PTCR/20)·σ_c, σ_c "
                        "estimated on the first frame (templates=PATH: unused)", symbol="PTCR", unit="dB",
                        source="§4", low=-20, high=60)
    prior: str = param("image", doc="initial law and f₀: image (uniform over the frame or the extended grid, see "
                       "entry; speed ≤ vmax; P(z₀ = 0) = p_absent) or paper (§4: column U[10, 20], row U[50, 70], velocity N(2, 0.1²) "
                       "px/frame, z₀ uniform on 1..K)", symbol="p(s₀), f₀", source="§4, Eq. 5",
                       choices=PRIORS)
    entry: str = param("image", doc="image prior: where the initial law and f₀ put a target's centroid: image (the "
                       "frame's pixels) or grid (the extended grid: also partly visible targets, which give little "
                       "evidence either way)", source="§2, Eq. 5", choices=("image", "grid"))
    p_absent: float = param(0.5, doc="P(z₀ = 0) of the image prior", symbol="P(z₀ = 0)",
                            source="not in the paper (§4 has 0)", low=0, high=1)
    vmax: float = param(3.0, doc="image prior and f₀: each velocity U[−vmax, vmax]", unit="px/frame",
                        source="not in the paper", low=0, high=1000)
    births: str = param("auto", doc="where entering targets are drawn: prior (f₀ itself, the paper) or data (from "
                        "Remark 3's single-frame likelihood map mixed with f₀, weighted by f₀/q); auto: data with the "
                        "image prior, prior with the paper's", source="not in the paper (Eq. 5, Remark 3)",
                        choices=("auto", "prior", "data"))
    birth_share: float = param(0.9, doc="data births: the likelihood map's share of the proposal (the rest "
                               "uniform)", source="not in the paper", low=0, high=1, high_closed=False)
    mh_moves: int = param(1, doc="Metropolis–Hastings moves per frame (ma-rs)", source="§3.2, Eqs. 19–21", low=1,
                          high=100)
    mean_window: int | None = param(None, doc="side of the local-mean window removed before the GMRF (auto: 3 "
                                    "sides of the templates' support, made odd, at least 15)", unit="px",
                                    source="§2 (\"suitable preprocessing\")", low=3, high=10001, optional=True)
    gmrf: str = param("estimate", doc="clutter parameters: estimate (maximum likelihood of Eq. 13 every frame) or "
                      "BH,BV,SIGMA_C fixed", symbol="β_h, β_v, σ_c", source="Eqs. 9, 13, 14")
    log_det: str = param("exact", doc="ln det of Eq. 14 in the estimate: exact (DST-I eigenvalues) or "
                         "approximate (the large-grid integral, ref. [12])", source="Eq. 13",
                         choices=("exact", "approximate"))
    exit: str = param("literal", doc="present → absent: literal (with 1 − P_in, Eq. 6) or coupled (iff the drawn "
                      "centroid leaves the extended grid)", source="Eqs. 2, 6", choices=("literal", "coupled"))


@dataclass(frozen=True)
class Resolved:
    """What the parameters resolve to for frames of ``shape``."""

    templates: np.ndarray  # (K, h, w) float64; the vehicle's with peak 1 (scaled to the clutter by ptcr)
    relative: bool  # templates in units of 10^(PTCR/20)·σ_c (the vehicle) rather than the input's
    G: np.ndarray  # (K, K) column-stochastic
    motion: tuple  # (a, b, c): one axis' Q Cholesky factor, px and px/frame
    prior_law: np.ndarray  # LAW vector of the initial draw, and of an entering target (f₀, Eq. 5): the same law
    p_absent: float  # P(z₀ = 0)
    mean_window: int
    fixed_gmrf: tuple | None  # (β_h, β_v, σ_c²) or None: estimated every frame
    data_births: bool  # entering targets from the data-driven proposal (births.py)


def law_vector(box, v_mean: float, v_sd: float, v_spread: float) -> np.ndarray:
    """kernels.multiaspect.LAW: U[x0, x1] × U[y0, y1], velocity v_mean + v_sd·n + v_spread·(2u − 1) per axis."""
    return np.array([*box, v_mean, v_sd, v_spread], np.float32)


def _templates(spec: str) -> np.ndarray:
    if spec == "vehicle":
        from ...bruno2008 import vehicle_templates

        return check_templates(vehicle_templates())  # cropped, peak 1: scaled by 10^(PTCR/20)·σ_c at the first frame
    return check_templates(load_array("templates", spec))


def _transition(spec: str, k: int) -> np.ndarray:
    if spec == "auto":
        return aspect_transition(k)
    return check_transition(load_array("G", spec), k)


def _fixed_gmrf(spec: str, shape) -> tuple | None:
    if spec == "estimate":
        return None
    try:
        bh, bv, sc = (float(v) for v in spec.split(","))
    except ValueError:
        raise ParameterError(f"--param gmrf={spec}: give estimate or BH,BV,SIGMA_C (three numbers)") from None
    check_gmrf(shape, bh, bv, sc)
    return bh, bv, sc * sc


@functools.lru_cache(maxsize=16)
def resolve(p: MultiaspectParams, shape: tuple[int, int]) -> Resolved:
    """The arrays and laws of ``p`` for frames of ``shape``; a bad file, stack, matrix or value is an error
    naming it."""
    if min(shape) < 3:
        raise ParameterError(f"frames of {shape[0]}x{shape[1]} px are too small for the multiaspect filters: "
                             "H, W ≥ 3")
    t = _templates(p.templates)
    k, th, tw = t.shape
    if th > shape[0] or tw > shape[1]:
        raise ParameterError(f"templates of {th}x{tw} px are larger than the {shape[0]}x{shape[1]} frame")
    g = _transition(p.G, k)
    halves = half_sizes(t)
    grid = extended_grid(shape, halves)
    if p.prior == "paper":
        prior = law_vector((*PAPER_PRIOR["x"], *PAPER_PRIOR["y"]), PAPER_PRIOR["v_mean"], PAPER_PRIOR["v_sd"], 0.0)
        p_absent = 0.0
    else:
        box = (-0.5, shape[1] - 0.5, -0.5, shape[0] - 0.5) if p.entry == "image" else grid
        prior, p_absent = law_vector(box, 0.0, 0.0, p.vmax), p.p_absent
    if p.births == "data" and p.prior == "paper":
        raise ParameterError("births=data needs prior=image (its f₀ is uniform over cells, which the proposal's "
                             "weight f₀/q assumes); §4's prior draws births from its own law (births=prior)")
    window = p.mean_window or max(3 * max(th, tw) // 2 * 2 + 1, MIN_MEAN_WINDOW)
    if window % 2 == 0:
        raise ParameterError(f"mean_window = {window} must be odd (a centred window)")
    return Resolved(t, p.templates == "vehicle", g, noise_factor(motion_noise(p.q, p.T, p.zeta, p.motion)), prior,
                    p_absent, window, _fixed_gmrf(p.gmrf, shape),
                    p.births == "data" or (p.births == "auto" and p.prior == "image"))


def multiaspect_params(shape, **overrides) -> MultiaspectParams:
    """The parameters with ``overrides``, validated, their files read and checked against frames of ``shape``."""
    p = validate_params(MultiaspectParams(**overrides), "multiaspect")
    resolve(p, (int(shape[0]), int(shape[1])))
    return p


def particles(kind: str, p: MultiaspectParams) -> int:
    """N_p: the configured count or the paper's for filter ``kind`` (rs, apf)."""
    return p.n_particles or PAPER_PARTICLES[kind]

