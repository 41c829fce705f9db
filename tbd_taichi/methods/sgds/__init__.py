"""SGDS-PF, the saliency-guided double-stage particle filter (Jia et al., Sensors 2022): the method's
registry entry.  The tracker is :mod:`.tracker`, its parameters :mod:`.params`, its tracking-mode bookkeeping
:mod:`.confirmation` and its particle populations :mod:`.populations`; docs/methods/sgds.md maps the paper's
equations to them."""
from __future__ import annotations

from ..registry import MethodSpec, keyword_factory
from ..still_tracks import REAL_VIDEO_STILL_FRAMES
from .params import PAPER_SALIENCY, SGDSParams
from .tracker import MIN_FRAMES, PIPELINE_STAGES, SGDSPF


# real still-camera video (drone-ir; docs/methods/sgds.md#real-video): a track reported for 50 frames (five
# times the running peak z's settling time) stays reported down to a running peak z of 12 (the profile's gate,
# REAL_VIDEO's min_peak_z, is 16): a target proven bright is not cut where it fades for a while
REAL_VIDEO_KEEP_PEAK_Z, REAL_VIDEO_KEEP_AFTER = 12.0, 50


def sgds_params(shape, snr: float | None = None, **overrides) -> SGDSParams:
    """Table 2's preset for ``snr`` (default 1.4, the paper's choice for an unknown SNR), then ``overrides``."""
    return SGDSParams.for_snr(SGDSParams.snr if snr is None else snr, **overrides)


def sgds_particles(shape, params: SGDSParams) -> int:
    """Searching particles N_sump × blocks (Table 2; each potential target adds N_tpf)."""
    from ...saliency import block_grid

    return params.N_sump * block_grid(shape, params.L_ib).n_blocks


def sgds_slots(shape, params: SGDSParams) -> int:
    """The slots both pools allocate: the searching particles and N_tpf for each of the max_tracks tracking PFs."""
    return sgds_particles(shape, params) + params.N_tpf * params.max_tracks


SPEC = MethodSpec(
    name="sgds", title="SGDS-PF",
    paper="Jia et al., Sensors 2022",
    kind="point-tbd",
    description="saliency-guided double-stage PF: saliency proposals feed one searching PF per image block; "
                "potential targets move to tracking PFs with confidence-based confirmation (many targets)",
    params=SGDSParams, factory=keyword_factory(SGDSPF), make_params=sgds_params,
    min_frames=MIN_FRAMES,
    options=("background", "bad_pixels", "history", "frontend_process"),
    aliases={"snr": "snr", "min_peak_z": "min_peak_z"},
    rank=0, particle_count=sgds_particles, slot_count=sgds_slots,
    real_video={"keep_peak_z": REAL_VIDEO_KEEP_PEAK_Z, "keep_after": REAL_VIDEO_KEEP_AFTER,
                "still_frames": REAL_VIDEO_STILL_FRAMES},
    assumes=("point targets, any number (Gaussian PSF, Σ = 0.7 px), nearly constant velocity ≤ 1 px/frame; peak "
             "SNR ≥ snr (1.4, the Table 2 preset); background: paper profile the frame's median, white Gaussian "
             "noise of σ from the MAD; real-video profile a spatiotemporal background and local σ, snr 5, tracks "
             "reported while their peak z ≥ 16 (≥ 12 once reported for 50 frames); whole paths take a still "
             "track (within 3 px) once reported for 50 frames"),
)

__all__ = ["MIN_FRAMES", "PAPER_SALIENCY", "PIPELINE_STAGES", "SGDSPF", "SGDSParams", "SPEC"]
