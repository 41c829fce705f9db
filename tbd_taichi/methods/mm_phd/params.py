"""MM-PHD TBD's parameters (Long et al. 2012), declared once, and the quantities derived from them: the birth
threshold Th and clutter constant λ (§5.1), the birth intensity range, Π and β as arrays, the PSF window."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ...errors import ParameterError
from ...long2012 import intensity_for_db
from ...motion_models import check_models
from ..registry import param, validate_params
from ..still_tracks import still_frames_param, still_radius_param

PAPER_SWITCH = "0.8,0.1,0.1; 0.3,0.6,0.1; 0.3,0.1,0.6"  # Eq. 39, rows and columns (CV, C-CT, AC-CT)
PAPER_BIRTH_MODELS = "0.8,0.1,0.1"  # §5.2: β = θ
P_DETECT = 0.99  # §5.1: Th detects the weakest target with this probability per frame
LAM_FLOOR = 1e-30  # λ = Φ(−Th) at least this (below it for Th > 11.4): the update takes log λ in f32


@dataclass(frozen=True)
class MMPHDParams:
    """The parameters of Long et al. 2012 (Table 1, §§5.1–5.3) with the choices the paper leaves open."""

    snr_db: float = param(10.0, doc="peak SNR of the weakest target to detect (Eq. 5): sets Th and I_min",
                          symbol="SNR", unit="dB", source="§5.1, Eq. 5", low=0, low_closed=False, high=40)
    psf_sigma: float = param(0.7, doc="standard deviation of the Gaussian PSF; window ⌊3Σ⌋ px each side",
                             symbol="Σ", unit="px", source="Table 1, Eqs. 4, 18", low=0.2, high=1.5)
    frame_interval: float = param(1.0, doc="time between frames", symbol="T", unit="s", source="§5", low=0,
                                  low_closed=False, high=3600)
    models: str = param("cv,c-ct,ac-ct", doc="motion models (of cv, c-ct, ac-ct, ca), comma separated",
                        symbol="r", source="Eq. 1, §5.2")
    switch: str | None = param(None, doc="model transition matrix Π, rows ';'-separated, each summing to 1 "
                               "(auto: Eq. 39 for three models, the first in CV's place; 0.8 on the diagonal "
                               "otherwise)", symbol="Π", source="Eq. 39", optional=True)
    birth_models: str | None = param(None, doc="model probabilities of newborn particles, summing to 1 (auto: "
                                     "0.8 for the first model, the rest shared)", symbol="β",
                                     source="§5.2, Eqs. 28, 31", optional=True)
    omega: float = param(math.pi / 10, doc="turn rate of the coordinated-turn models (not in the paper: a half "
                         "turn in 10 s)", symbol="ω", unit="rad/s", source="not in the paper", low=-math.pi,
                         high=math.pi)
    q_s: float = param(0.001, doc="power spectral density of the position/velocity process noise (Q_min)",
                       symbol="q_s", unit="px²/s³", source="§5.1, refs. [7], [19]", low=0, low_closed=False)
    q_i: float = param(0.01, doc="power spectral density of the intensity random walk", symbol="q_i",
                       unit="intensity²/s", source="§5.1", low=0)
    q_max_ratio: float = param(50.0, doc="Q_max / Q_min of the adaptive process noise", symbol="Q_max/Q_min",
                               source="§3.2", low=1)
    vmax: float = param(4.0, doc="newborn speed U[−V_max, V_max] per axis", symbol="V_max", unit="px/s",
                        source="§5.1", low=0)
    i_min: float | None = param(None, doc="newborn intensity low end (auto: 0.8·I of snr_db, Eq. 37)",
                                symbol="I_min", source="§5.1", low=0, low_closed=False, optional=True)
    i_max: float | None = param(None, doc="newborn intensity high end (auto: 1.2·I of snr_db + 3 dB)",
                                symbol="I_max", source="§5.1", low=0, low_closed=False, optional=True)
    intensity_floor: float | None = param(None, doc="a particle's intensity is kept at least this (auto: I_min; "
                                          "without it a tracker on noise sinks to I ≈ 0, where ℓ ≈ 1 holds n̂ up)",
                                          symbol="I_floor", source="not in the paper", low=0, optional=True)
    threshold: float | None = param(None, doc="birth cells: z ≥ Th (auto: A − 2.326, detecting the weakest "
                                    "target with p_d = 0.99)", symbol="Th", unit="σ_n", source="§5.1",
                                    optional=True, low=-10, high=100)
    births: int = param(2000, doc="newborn particles per frame", symbol="J_k", unit="particles", source="Table 1",
                        low=1, high=1_000_000)
    max_particles: int = param(4000, doc="particles of each filter after resampling", symbol="L_max",
                               unit="particles", source="Table 1", low=1, high=1_000_000)
    survival: float = param(0.99, doc="survival probability", symbol="e_k", source="Table 1", low=0, high=1,
                            low_closed=False)
    birth_mass: float = param(0.05, doc="expected new targets per frame (birth PHD mass)", symbol="γ_k",
                              source="Table 1", low=0, low_closed=False, high=10)
    mask_value: float = param(-3.0, doc="detector frame value over tracked windows", symbol="I_0", unit="σ_n",
                              source="Eq. 36", low=-100, high=0)
    mask_margin: int = param(1, doc="the masked window reaches this much beyond Eq. 18's ⌊3Σ⌋ (the tracked "
                             "estimate lags the jittering target)", unit="px", source="not in the paper", low=0,
                             high=10)
    fresh_velocity: float = param(0.5, doc="share of a new tracker's particles whose velocity is drawn anew "
                                  "from U[−V_max, V_max]", source="not in the paper", low=0, high=1)
    gate_sigmas: float = param(4.0, doc="a tracker looks for its target within 3Σ + this many velocity standard "
                               "deviations × T of its predicted position", source="not in the paper", low=0,
                               high=100)
    confirm_frames: int = param(3, doc="consecutive tracked frames that confirm a track", source="§4.2", low=1,
                                high=100)
    halt_drops: int = param(2, doc="consecutive dropped frames that halt a tracker", source="§4.2", low=1, high=100)
    revive_frames: int = param(3, doc="a capture near a lost confirmed track whose last tracked frame is at most "
                               "this many frames before continues that track (its id, confirmed) instead of "
                               "starting a tentative one; 0: every capture is a new track, as in the paper",
                               unit="frames", source="not in the paper", low=0, high=100)
    drop_below: float = param(0.5, doc="a tracker drops the frame when its class's peak cell holds PHD mass "
                              "Ψ/(λ + Ψ) below this; a detector class below it is no capture", symbol="n̂",
                              source="not in the paper", low=0, high=1, low_closed=False, high_closed=False)
    capture_above: float = param(0.8, doc="a detector class becomes a tracker when its peak cell holds at least "
                                 "this PHD mass", source="not in the paper", low=0, high=1, low_closed=False,
                                 high_closed=False)
    confirm_above: float = param(0.95, doc="a tentative tracker (and the backward recursion) counts a frame as "
                                 "tracked only when its class's peak cell holds at least this PHD mass (hysteresis: "
                                 "confirmed trackers hold on down to drop_below)", source="not in the paper", low=0,
                                 high=1, low_closed=False, high_closed=False)
    confirm_share: float = param(0.5, doc="a tentative tracker's frame counts toward confirmation only when its "
                                 "class holds at least this share of its PHD mass n̂ (on noise the mass is spread "
                                 "over several bright cells)", source="not in the paper", low=0, high=1)
    min_peak_z: float = param(0.0, doc="report a confirmed track only while its running peak z (the largest z "
                              "within 1 px of its estimate, running mean with weight 0.1 a frame) is at least this, and let trackers "
                              "settled below it make room for waiting captures (0: off, as in the paper; the "
                              "real-video profile's guard against clutter)", unit="σ",
                              source="not in the paper", low=0)
    still_frames: int = still_frames_param()
    still_radius: float = still_radius_param()
    max_tracks: int = param(16, doc="trackers alive at once (pool size; a capture beyond it waits)",
                            source="not in the paper", low=1, high=1024)
    adaptive_q: bool = param(True, doc="adaptive process noise (Eq. 21); off: Q = Q_min", source="§3.2, Fig. 2")
    start_q_max: bool = param(True, doc="with adaptive_q, a new tracker's first predictions use Q_max (its velocity is "
                              "still the prior's; Eq. 21 adapts Q from its second tracked frame on); off: Q_min",
                              source="not in the paper")
    likelihood_resampling: bool = param(True, doc="trackers resample ∝ ℓ (Eq. 24); off: ∝ w̃ (standard SMC-PHD)",
                                        source="§3.2, Eq. 24")
    detector_resampling: str = param("phd", doc="the detector resamples ∝ w̃ (phd: keeps its PHD's mass where it "
                                     "is) or ∝ ℓ (likelihood, Eq. 24 literally)", source="§3.2, Eq. 24",
                                     choices=("phd", "likelihood"))
    backward: bool = param(True, doc="backward recursion over the frames before a capture (Eqs. 25–27)",
                           source="§3.2")
    backward_frames: int = param(40, doc="frames kept for the backward recursion", unit="frames",
                                 source="not in the paper", low=1, high=10_000)
    gate_probability: float = param(0.99, doc="backward gate ξ = χ²_d quantile of this probability (Eq. 25)",
                                    symbol="ξ", source="not in the paper", low=0, high=1, low_closed=False,
                                    high_closed=False)


@dataclass(frozen=True)
class Derived:
    """What the filter computes from its parameters once."""

    models: tuple
    switch: np.ndarray
    birth_models: np.ndarray
    threshold: float
    lam: float
    i_range: tuple
    i_floor: float
    half: int
    class_radius: float


def parse_matrix(text: str, name: str, n: int, rows: int) -> np.ndarray:
    """``text`` ("a,b,c; d,e,f" rows) as a (rows, n) array of probabilities each row summing to 1, or a
    ParameterError naming ``name``."""
    try:
        out = np.array([[float(v) for v in row.split(",")] for row in text.split(";")], dtype=float)
    except ValueError:
        raise ParameterError(f"{name} = {text!r} must be numbers, ',' between columns and ';' between rows") from None
    if out.shape != (rows, n):
        raise ParameterError(f"{name} = {text!r} must be {rows} row(s) of {n} probabilities (one per model)")
    if not np.all(np.isfinite(out)) or np.any(out < 0) or not np.allclose(out.sum(axis=1), 1.0, atol=1e-6):
        raise ParameterError(f"{name} = {text!r}: every row must be probabilities ≥ 0 summing to 1")
    return out


def default_switch(n: int) -> str:
    """Π for ``n`` models: Eq. 39 for three; otherwise 0.8 to stay and the rest shared (1 for one model)."""
    if n == 3:
        return PAPER_SWITCH
    if n == 1:
        return "1"
    off = 0.2 / (n - 1)
    return "; ".join(",".join(f"{0.8 if i == j else off:.12g}" for j in range(n)) for i in range(n))


def default_birth_models(n: int) -> str:
    """β for ``n`` models: §5.2's (0.8, 0.1, 0.1) pattern, 0.8 for the first and the rest shared (1 for one)."""
    return "1" if n == 1 else ",".join(f"{0.8 if j == 0 else 0.2 / (n - 1):.12g}" for j in range(n))


def derived(p: MMPHDParams) -> Derived:
    """Th = A − Φ⁻¹(0.99) with A = 10^(SNR/20) (σ_n = 1) and λ = 1 − Φ(Th) ≥ LAM_FLOOR (§5.1); I range
    [0.8·I(SNR), 1.2·I(SNR + 3 dB)] unless given; Π, β parsed; the window half-width ⌊3Σ⌋ (Eq. 18)."""
    models = check_models(p.models)
    n = len(models)
    switch = parse_matrix(p.switch or default_switch(n), "switch (Π)", n, n)
    birth = parse_matrix(p.birth_models or default_birth_models(n), "birth_models (β)", n, 1)[0]
    # Φ and Φ⁻¹ (scipy.stats, 0.7 s to import, calls the same); imported here, not by listing the methods
    from scipy.special import ndtr, ndtri

    th = p.threshold if p.threshold is not None else 10 ** (p.snr_db / 20.0) - ndtri(P_DETECT)
    i_min = p.i_min if p.i_min is not None else 0.8 * intensity_for_db(p.snr_db, p.psf_sigma)
    i_max = p.i_max if p.i_max is not None else 1.2 * intensity_for_db(p.snr_db + 3.0, p.psf_sigma)
    if i_min > i_max:
        raise ParameterError(f"i_min = {i_min:g} must not exceed i_max = {i_max:g}")
    if p.omega == 0 and any(m.endswith("ct") for m in models):
        raise ParameterError("omega = 0 with a coordinated-turn model (c-ct, ac-ct); a turn needs ω ≠ 0")
    i_floor = p.intensity_floor if p.intensity_floor is not None else i_min
    return Derived(models, switch, birth, float(th), max(float(ndtr(-th)), LAM_FLOOR), (float(i_min), float(i_max)),
                   float(i_floor), int(math.floor(3.0 * p.psf_sigma + 1e-9)), 3.0 * p.psf_sigma)


def mm_phd_params(shape, **overrides) -> MMPHDParams:
    """Validated parameters (each in its range, Π and β well formed, I_min ≤ I_max, ω ≠ 0 with a CT model, the
    frame at least the PSF window)."""
    p = validate_params(MMPHDParams(**overrides), "MM-PHD")
    d = derived(p)
    side = 2 * d.half + 1
    if shape is not None and min(shape) < side:
        raise ParameterError(f"frames of {shape[0]}×{shape[1]} px are smaller than the {side}×{side} px PSF window "
                             f"of psf_sigma = {p.psf_sigma:g} (Eq. 18)")
    return p


def pool_capacity(p: MMPHDParams) -> int:
    """Slots of the pool: the detector's L_max + J_k and L_max for each tracker (a new tracker takes at most
    L_max particles from the detector)."""
    return p.max_particles + p.births + p.max_tracks * p.max_particles
