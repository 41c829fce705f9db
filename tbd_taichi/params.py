"""SGDS-PF parameters, named as in the paper, with the Table 2 presets chosen by ``snr``.

``snr`` is the lowest SNR to be detected (Eq. 1), the input parameter of Eqs. 23 and 26;
the paper recommends 1.4 when the SNR is unknown.  Table 2 gives ranges; the presets
take a point inside each range (the middle, or the cheaper end where the paper's Fig. 9
shows little gain from more).  Parameters the paper leaves open get the defaults below,
each with its reason.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, fields, replace

from .errors import ParameterError

ICEF_REFERENCE_PIXELS = 200 * 200  # frame area at which icef_mean_ratio was chosen
PAPER_SALIENCY = dict(lef_memory=0.0, msw_reference="search")  # Eq. 29 and Eq. 40's MSW as printed
MSW_REFERENCES = ("candidates", "search")  # ICEF's MSW (Eq. 40): the best untracked candidate's LEF, or the searching PFs' best weight
SNR_BANDS = (2.0, 1.8, 1.6, 1.4)  # lower edges of Table 2's columns [2,∞), [1.8,2), [1.6,1.8), [1.4,1.6); then (0,1.4)

# Table 2 point values per band: L_ib (px), N_sump^b, T_PE, T_PTp, T_ft, T_rt
TABLE2 = (
    (256, 4000, 0.1, 5, 0.7, 9),
    (200, 6000, 0.1, 5, 0.5, 9),  # [1.6, 2): N_sump at the range's top, L_ib lower: see below
    (150, 6000, 0.1, 5, 0.5, 8),
    (150, 8000, 0.2, 4, 0.2, 6),  # T_ft, T_rt at the lenient ends: 0.3, 7 dropped real targets at 200×200
    (100, 8000, 0.2, 4, 0.11, 5),
)
# [1.6, 2): with 4000 particles in one 200- or 256-px block the 100-test suite at 200×200 gave
# TSR 0.85 (SNR 1.6) and 0.93 (1.8); every failed run was a target never handed over (no false
# track).  6000 per 150-px block (1.6: 24,000 at 200×200) and per 200-px block (1.8: 6,000)
# recovered 11 of 13 and 7 of 7 of those runs, still below the original PF's Table 3 counts.


def snr_band(snr: float) -> int:
    """Index of the Table 2/3 column for ``snr``: 0 for [2, ∞) … 4 for (0, 1.4)."""
    for k, lower in enumerate(SNR_BANDS):
        if snr >= lower:
            return k
    return len(SNR_BANDS)


@dataclass(frozen=True)
class SGDSParams:
    """Every SGDS-PF parameter (units: px, frames, particles; intensities in σ units)."""

    snr: float = 1.4  # lowest SNR to detect (Eqs. 23, 26)
    L_ib: int = 150  # largest image-block side (Table 2)
    N_sump: int = 8000  # particles per searching PF, i.e. per block (Table 2)
    T_PE: float = 0.2  # potential target: PE > T_PE (Table 2)
    T_PTp: float = 4.0  # potential target: PTp > T_PTp (Table 2)
    N_tpf: int = 500  # particles per tracking PF (section 3.2, Fig. 11)
    T_ft: float = 0.2  # false target below this confidence (Table 2)
    T_rt: int = 6  # real target once N_rt > T_rt (Table 2)
    # open in the paper; reasons in the README's parameter table
    P_b: float = 0.05  # birth probability (Eq. 7), typical of Ristic-style PF-TBD
    P_d_search: float = 0.05  # death probability (Eq. 8) in the searching PFs
    P_d_track: float = 0.02  # lower in tracking PFs, so E = 0 particles do not take over weak tracks
    mu: float = 0.5  # initial existence probability of initial particles (Eq. 34)
    V_limit: float = 1.0  # newborn speed U[0, V_limit] px/frame (Eq. 34); targets move ≤ 1 px/frame
    P_e: float = 0.10  # fraction of particles eliminated per iteration (Eqs. 35, 37); paper range 0.05–0.15
    q1: float = 0.001  # process noise of the particles' NCV motion (Eq. 46), the simulator's value
    q2: float = 0.01  # process noise of the intensity random walk (Eq. 46)
    psf_sigma: float = 0.7  # Σ of the PSF (Eq. 14), px; the simulation value
    noise_sigma: float = 1.0  # σ of the noise (Eq. 13); 1 after normalisation
    devr_radius: float = 2.0  # radius of T_devr = radius/1.3 (Eq. 42); paper range 1.5–2.5 px
    min_peak_z: float = 0.0  # report a confirmed track only while its running peak z ≥ this (0: off, the paper)
    # not in the paper: ICEF = 1 also when the geometric mean of MTW/MSW over the track's last
    # icef_window frames is ≥ icef_mean_ratio (Eq. 40 alone starves confirmation at SNR ≤ 1.6;
    # docs/results/suite_analysis.md); icef_window = 1 is Eq. 40 as printed.  icef_mean_ratio holds
    # for a 200×200 frame; other frames use it × (40,000 px / H·W)^icef_area_exponent, because MSW, an
    # extreme of the noise, grows with the searched area (measured: ln MSW ≈ 0.45·ln(H·W) + const)
    icef_window: int = 10
    icef_mean_ratio: float = 0.05
    icef_area_exponent: float = 0.45
    # not in the paper: a track is also confirmed once its cloud has been compact (SCEF = 1.1, Eq. 42) in
    # each of its last confirm_window frames with a geometric mean of MTW/MSW ≥ confirm_mean_ratio
    # (scaled to the frame area like icef_mean_ratio).  At SNR 1.2 a target held that long by a compact
    # cloud often stays below the ICEF window's 0.05, so C decays by 0.9·1.1 per frame and never returns to 1
    # (docs/results/suite_analysis.md); confirm_window = 0 is the paper's confirmation (Eq. 43's N_rt) alone
    confirm_window: int = 30
    confirm_mean_ratio: float = 0.03
    # not in the paper: Eq. 29's weight from the multi-frame LEF, lef_scale·L with
    # L(f) = log ω̌⁺(f) + lef_memory·max3×3 L(f − 1) (a velocity-free dynamic-programming sum over about
    # 1/(1 − lef_memory) frames); lef_memory = 0 is Eq. 29 as printed.  At SNR 1.2 it puts about 8×
    # more of the proposal on the target (docs/results/suite_analysis.md)
    lef_memory: float = 0.9
    lef_scale: float = 0.5
    # ICEF's MSW (Eq. 40): "candidates" = the largest Eq. 28 LEF over Eq. 24's candidates away from the active
    # tracks, plus MSW_LEF_OFFSET (sgds.msw_from_candidates); "search" = the largest searching-particle weight, as printed.  The printed MSW
    # falls when the multi-frame LEF concentrates the searching particles, and noise tracks pass ICEF
    msw_reference: str = "candidates"

    @classmethod
    def for_snr(cls, snr: float = 1.4, **overrides) -> "SGDSParams":
        """Table 2's preset for ``snr``, then ``overrides`` (names as in the paper); validated."""
        if not isinstance(snr, (int, float)) or not snr > 0:
            raise ParameterError(f"snr must be a number > 0, got {snr!r}")
        l_ib, n_sump, t_pe, t_ptp, t_ft, t_rt = TABLE2[snr_band(snr)]
        names = {f.name for f in fields(cls)}
        unknown = sorted(set(overrides) - names)
        if unknown:
            raise ParameterError(f"unknown SGDS-PF parameter(s) {', '.join(unknown)}; known: {', '.join(sorted(names))}")
        params = cls(snr=float(snr), L_ib=l_ib, N_sump=n_sump, T_PE=t_pe, T_PTp=t_ptp, T_ft=t_ft, T_rt=t_rt)
        return replace(params, **overrides).validated()

    def icef_ratio_for(self, pixels: int, ratio: float | None = None) -> float:
        """An ICEF threshold on MTW/MSW for a frame of ``pixels`` px: ``ratio`` (default icef_mean_ratio, the
        window's) × (ICEF_REFERENCE_PIXELS / pixels)^icef_area_exponent, at most 1.  MSW, an extreme of the
        noise, grows with the searched area, so a ratio chosen at 200×200 is scaled to the frame."""
        ratio = self.icef_mean_ratio if ratio is None else ratio
        return min(ratio * (ICEF_REFERENCE_PIXELS / pixels) ** self.icef_area_exponent, 1.0)

    @property
    def T_devr(self) -> float:
        """Standard-deviation threshold of Eq. 42: radius/1.3 px."""
        return self.devr_radius / 1.3

    def validated(self) -> "SGDSParams":
        """Self, or a ParameterError naming the first invalid value."""
        checks = [
            ("snr", self.snr > 0, "> 0"), ("L_ib", self.L_ib >= 8, "≥ 8 px"), ("N_sump", self.N_sump >= 10, "≥ 10"),
            ("T_PE", 0 <= self.T_PE < 1, "in [0, 1)"), ("T_PTp", self.T_PTp >= 0, "≥ 0"),
            ("N_tpf", self.N_tpf >= 10, "≥ 10"), ("T_ft", 0 < self.T_ft < 1, "in (0, 1)"), ("T_rt", self.T_rt >= 0, "≥ 0"),
            ("P_b", 0 <= self.P_b <= 1, "in [0, 1]"), ("P_d_search", 0 <= self.P_d_search <= 1, "in [0, 1]"),
            ("P_d_track", 0 <= self.P_d_track <= 1, "in [0, 1]"), ("mu", 0 <= self.mu <= 1, "in [0, 1]"),
            ("V_limit", self.V_limit >= 0, "≥ 0"), ("P_e", 0 <= self.P_e < 1, "in [0, 1)"),
            ("q1", self.q1 >= 0, "≥ 0"), ("q2", self.q2 >= 0, "≥ 0"), ("psf_sigma", self.psf_sigma > 0, "> 0"),
            ("noise_sigma", self.noise_sigma > 0, "> 0"), ("devr_radius", self.devr_radius > 0, "> 0"),
            ("min_peak_z", self.min_peak_z >= 0, "≥ 0"),
            ("icef_window", isinstance(self.icef_window, int) and self.icef_window >= 1, "an integer ≥ 1"),
            ("icef_mean_ratio", 0 < self.icef_mean_ratio <= 1, "in (0, 1]"),
            ("icef_area_exponent", self.icef_area_exponent >= 0, "≥ 0"),
            ("confirm_window", isinstance(self.confirm_window, int) and self.confirm_window >= 0, "an integer ≥ 0"),
            ("confirm_mean_ratio", 0 < self.confirm_mean_ratio <= 1, "in (0, 1]"),
            ("lef_memory", 0 <= self.lef_memory < 1, "in [0, 1)"), ("lef_scale", self.lef_scale > 0, "> 0"),
            ("msw_reference", self.msw_reference in MSW_REFERENCES, f"one of {', '.join(MSW_REFERENCES)}"),
        ]
        for name, ok, rule in checks:
            if not ok:
                raise ParameterError(f"SGDS-PF parameter {name} = {getattr(self, name)!r} must be {rule}")
        return self

    def as_dict(self) -> dict:
        return asdict(self)
