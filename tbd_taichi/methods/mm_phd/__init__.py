"""MM-PHD track-before-detect (Long, Xu, An & Liu, Chinese J. Aeronautics 2012): many dim manoeuvring targets
with a multiple-model particle PHD filter on the pixels, a detector/tracker architecture and a backward
recursion.  Equations → code: docs/methods/mm-phd.md."""
from ...tables import TRACK_COLUMNS
from ..registry import MethodSpec, keyword_factory
from .params import MMPHDParams, mm_phd_params, pool_capacity
from .params import derived
from .tracker import MIN_FRAMES, MMPHDTracker, track_columns

__all__ = ["MMPHDTracker", "MMPHDParams", "SPEC"]

SPEC = MethodSpec(
    name="mm-phd", title="MM-PHD TBD",
    paper="Long, Xu, An & Liu 2012",
    kind="point-tbd",
    description="multiple-model particle PHD filter on the pixels for a changing number of dim manoeuvring "
                "targets: a detector with births, one tracker per captured target, backward recursion",
    params=MMPHDParams, factory=keyword_factory(MMPHDTracker), make_params=mm_phd_params,
    scenario="long2012", min_frames=MIN_FRAMES,
    options=("background", "bad_pixels", "history"),
    aliases={"particles": "max_particles"},
    rank=2, particle_count=lambda shape, params: pool_capacity(params),
    extra_columns=lambda params: track_columns(derived(params).models)[len(TRACK_COLUMNS):],
    assumes=("point targets (Gaussian PSF, Σ = 0.7 px) of peak SNR ≥ 10 dB (Eq. 5) in white Gaussian noise, "
             "≥ 6Σ apart, moving CV or turning at ω = π/10 rad/s per frame interval T = 1 s, ≤ 4 px/s; "
             "background: the frame's median, σ from the MAD"),
)
