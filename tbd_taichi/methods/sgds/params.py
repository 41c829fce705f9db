"""SGDS-PF parameters, named as in the paper, with the Table 2 presets chosen by ``snr``.

``snr`` is the lowest SNR to be detected (Eq. 1), the input parameter of Eqs. 23 and 26;
the paper recommends 1.4 when the SNR is unknown.  Table 2 gives ranges; the presets
take a point inside each range (the middle, or the cheaper end where the paper's Fig. 9
shows little gain from more).  Parameters the paper leaves open get the defaults below,
each with its reason.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, fields, replace

from ...errors import ParameterError
from ..registry import param, validate_params
from ..still_tracks import still_frames_param, still_radius_param

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
HANDOVER_BELOW_SNR = 1.6  # the multi-frame hand-over is on in the presets below SNR 1.6 (docs/methods/sgds.md)
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
    """Every SGDS-PF parameter (units: px, frames, particles; intensities in σ units of the noise).
    Why each default where the paper is open: docs/methods/sgds.md."""

    snr: float = param(1.4, doc="lowest target SNR to detect; chooses the Table 2 preset", symbol="SNR",
                       source="Eqs. 1, 23, 26", low=0, low_closed=False)
    L_ib: int = param(150, doc="largest image-block side", symbol="L_ib", unit="px", source="Table 2", low=8)
    N_sump: int = param(8000, doc="particles per searching PF (one per block)", symbol="N_sump^b",
                        unit="particles", source="Table 2", low=10)
    T_PE: float = param(0.2, doc="potential target: PE > T_PE", symbol="T_PE", source="Table 2", low=0, high=1,
                        high_closed=False)
    T_PTp: float = param(4.0, doc="potential target: PTp > T_PTp", symbol="T_PTp", unit="frames",
                         source="Table 2", low=0)
    N_tpf: int = param(500, doc="particles per tracking PF", symbol="N_tpf", unit="particles",
                       source="§3.2, Fig. 11", low=10)
    T_ft: float = param(0.2, doc="a track below this confidence is false", symbol="T_ft", source="Table 2",
                        low=0, high=1, low_closed=False, high_closed=False)
    T_rt: int = param(6, doc="a track is real once N_rt > T_rt", symbol="T_rt", unit="frames", source="Table 2",
                      low=0)
    P_b: float = param(0.05, doc="birth probability", symbol="P_b", source="Eq. 7 (value open)", low=0, high=1)
    P_d_search: float = param(0.05, doc="death probability in the searching PFs", symbol="P_d",
                              source="Eq. 8 (value open)", low=0, high=1)
    P_d_track: float = param(0.02, doc="death probability in the tracking PFs", symbol="P_d",
                             source="Eq. 8 (value open)", low=0, high=1)
    mu: float = param(0.5, doc="existence probability of initial particles", symbol="μ", source="Eq. 34",
                      low=0, high=1)
    V_limit: float = param(1.0, doc="newborn speed U[0, V_limit]", symbol="V_limit", unit="px/frame",
                           source="Eq. 34", low=0)
    P_e: float = param(0.10, doc="fraction of a block's particles eliminated per frame", symbol="P_e",
                       source="Eqs. 35, 37 (range 0.05–0.15)", low=0, high=1, high_closed=False)
    q1: float = param(0.001, doc="process noise of the NCV motion", symbol="q1", unit="px²/frame³",
                      source="Eq. 46", low=0)
    q2: float = param(0.01, doc="process noise of the intensity random walk", symbol="q2", source="Eq. 46", low=0)
    psf_sigma: float = param(0.7, doc="standard deviation of the Gaussian PSF", symbol="Σ", unit="px",
                             source="Eq. 14", low=0, low_closed=False)
    noise_sigma: float = param(1.0, doc="noise standard deviation (1 after normalisation)", symbol="σ",
                               source="Eq. 13", low=0, low_closed=False)
    devr_radius: float = param(2.0, doc="radius of T_devr = radius/1.3", symbol="T_devr·1.3", unit="px",
                               source="Eq. 42 (range 1.5–2.5)", low=0, low_closed=False)
    max_tracks: int = param(32, doc="tracking PFs (tracks held at once)", unit="tracks", source="not in the paper",
                            low=1)
    min_peak_z: float = param(0.0, doc="report a confirmed track only while its running peak z is at least this "
                              "(0: off, as in the paper)", unit="σ", source="not in the paper", low=0)
    keep_peak_z: float = param(0.0, doc="a track reported in keep_after frames stays reported while its running "
                               "peak z is at least this (0: min_peak_z throughout)", unit="σ",
                               source="not in the paper", low=0)
    keep_after: int = param(0, doc="frames a track must have been reported in before keep_peak_z applies",
                            unit="frames", source="not in the paper", low=0)
    still_frames: int = still_frames_param()
    still_radius: float = still_radius_param()
    handover_frames: int = param(8, doc="draw a handed-over PP's particles into its tracking PF by their "
                                 "likelihood over this many earlier frames, each taken back along its velocity "
                                 "(0: Algorithm 2's uniform draw; the presets from SNR 1.6 up set 0)",
                                 unit="frames", source="not in the paper", low=0, high=50)
    backfill_frames: int = param(8, doc="a reported track's whole path begins up to this many frames before its "
                                 "first, on the line through its first 20 points (0: off, as in the paper; off "
                                 "under a min_peak_z gate)", unit="frames", source="not in the paper", low=0, high=50)
    handover_jitter: float = param(0.3, doc="velocity spread added to the PP before the multi-frame hand-over",
                                   unit="px/frame", source="not in the paper", low=0)
    icef_window: int = param(10, doc="ICEF = 1 also when MTW/MSW's geometric mean over this many frames is ≥ "
                             "icef_mean_ratio (1: Eq. 40 as printed)", unit="frames", source="not in the paper",
                             low=1, high=1000)
    icef_mean_ratio: float = param(0.05, doc="the ICEF window's threshold at 200×200 (scaled to the frame area)",
                                   source="not in the paper", low=0, high=1, low_closed=False)
    icef_area_exponent: float = param(0.45, doc="exponent of the ICEF thresholds' area scaling",
                                      source="not in the paper", low=0)
    confirm_window: int = param(30, doc="confirm a track whose cloud was compact this many frames (0: off)",
                                unit="frames", source="not in the paper", low=0, high=1000)
    confirm_mean_ratio: float = param(0.03, doc="the long window's MTW/MSW threshold at 200×200",
                                      source="not in the paper", low=0, high=1, low_closed=False)
    lef_memory: float = param(0.9, doc="memory of the multi-frame LEF (0: Eq. 29 as printed)",
                              source="not in the paper", low=0, high=1, high_closed=False)
    lef_scale: float = param(0.5, doc="scale of the multi-frame LEF in Eq. 29's weight", source="not in the paper",
                             low=0, low_closed=False)
    msw_reference: str = param("candidates", doc="ICEF's MSW: the best untracked candidate's LEF, or the searching "
                               "particles' largest weight (as printed)", symbol="MSW", source="Eq. 40",
                               choices=MSW_REFERENCES)

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
        params = cls(snr=float(snr), L_ib=l_ib, N_sump=n_sump, T_PE=t_pe, T_PTp=t_ptp, T_ft=t_ft, T_rt=t_rt,
                     **({} if snr < HANDOVER_BELOW_SNR else {"handover_frames": 0}))
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
        """Self, or a ParameterError naming the first value outside its declared range."""
        return validate_params(self, "SGDS-PF")

    def as_dict(self) -> dict:
        return asdict(self)
