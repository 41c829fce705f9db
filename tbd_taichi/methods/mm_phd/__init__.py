"""MM-PHD track-before-detect (Long, Xu, An & Liu, Chinese J. Aeronautics 2012): many dim manoeuvring targets
with a multiple-model particle PHD filter on the pixels, a detector/tracker architecture and a backward
recursion.  Equations → code: docs/methods/mm-phd.md."""
import math

from ...tables import TRACK_COLUMNS
from ..registry import MethodSpec, keyword_factory
from ..still_tracks import REAL_VIDEO_STILL_FRAMES
from .params import MMPHDParams, mm_phd_params, pool_capacity
from .params import derived
from .tracker import MIN_FRAMES, MMPHDTracker, track_columns

__all__ = ["MMPHDTracker", "MMPHDParams", "SECTION_5_3", "SPEC"]

# §5.3's settings (Σ 0.6, T = 2 s, J_k = 5000, CA + the two turns; ω: a tenth of a half turn per frame), the
# weakest target at 11 dB, and the scene's velocity range [−3, 3] px/s per axis as V_max (§5.3 states it with
# the Viterbi-like baseline; docs/methods/mm-phd.md#choices): the bench's and evaluate-suite's 5.3 runs
SECTION_5_3 = {"psf_sigma": 0.6, "frame_interval": 2.0, "births": 5000, "models": "ca,c-ct,ac-ct",
               "omega": math.pi / 20, "snr_db": 11.0, "vmax": 3.0}

# real still-camera video (drone-ir; docs/methods/mm-phd.md#real-video): Th = 7.7σ and I from 20 dB, where the
# spatio-temporal z of clutter reaches tens of σ (at 10 dB the detector's n̂ ran to hundreds); the peak-z guard at
# 18 (SGDS-PF's 16 let a bright clutter track through once faint trackers are evicted); whole paths take a still
# track once it has been reported in 50 frames (methods/still_tracks.py)
REAL_VIDEO_SNR_DB, REAL_VIDEO_MIN_PEAK_Z = 20.0, 18.0

SPEC = MethodSpec(
    name="mm-phd", title="MM-PHD TBD",
    paper="Long, Xu, An & Liu 2012",
    kind="point-tbd",
    description="multiple-model particle PHD filter on the pixels for a changing number of dim manoeuvring "
                "targets: a detector with births, one tracker per captured target, backward recursion",
    params=MMPHDParams, factory=keyword_factory(MMPHDTracker), make_params=mm_phd_params,
    scenario="long2012", min_frames=MIN_FRAMES,
    options=("background", "bad_pixels", "history"),
    aliases={"particles": "max_particles", "min_peak_z": "min_peak_z"},
    real_video={"snr_db": REAL_VIDEO_SNR_DB, "min_peak_z": REAL_VIDEO_MIN_PEAK_Z,
                "still_frames": REAL_VIDEO_STILL_FRAMES},
    rank=2, particle_count=lambda shape, params: pool_capacity(params),
    extra_columns=lambda params: track_columns(derived(params).models)[len(TRACK_COLUMNS):],
    bench_settings=lambda snr: dict(SECTION_5_3), bench_scene={"targets": 3, "snr": 4.5, "motion": "stay"},
    assumes=("point targets (Gaussian PSF, Σ = 0.7 px) of peak SNR ≥ 10 dB (Eq. 5) in white Gaussian noise, "
             "≥ 6Σ apart, moving CV or turning at ω = π/10 rad/s per frame interval T = 1 s, ≤ 4 px/s; "
             "background: the frame's median, σ from the MAD"),
)
