"""The multiaspect joint detector/trackers of Bruno, Araújo & Pavlov (EURASIP JASP 2008): one small extended
target whose shape switches among K templates, in GMRF clutter, detected and tracked from the pixels.  Two
registry methods share this package: ``ma-rs`` (resample-move, §3.2) and ``ma-apf`` (auxiliary PF, §3.3).
Equations → code: docs/methods/multiaspect.md."""
from __future__ import annotations

from ..registry import MethodSpec
from .params import MultiaspectParams, multiaspect_params, particles
from .tracker import EXTRA_COLUMNS, MultiaspectTracker

ASSUMES = ("one extended target at a time whose shapes are the templates (default: the bruno2008 scenario's "
           "9x9 vehicle), added to a smooth background (removed by a local mean) in first-order GMRF clutter "
           "estimated every frame; the default image prior lets it be anywhere, moving ≤ 3 px/frame")


def _bench_frames(shape, n_frames: int, seed: int):
    from ...bruno2008 import bench_frames

    return bench_frames(shape, n_frames, seed)


def method_spec(kind: str, name: str, title: str, section: str, rank: int) -> MethodSpec:
    """The registry entry of filter ``kind`` (rs, apf)."""
    def factory(shape, params, *, seed: int, engine: str, arch, init_box=None, **options):
        import dataclasses

        return MultiaspectTracker(shape, kind, seed=seed, engine=engine, arch=arch, **dataclasses.asdict(params))

    return MethodSpec(
        name=name, title=title, paper="Bruno, Araújo & Pavlov 2008", kind="extended-tbd",
        description=f"{section} for one multiaspect extended target (K templates switching by a Markov chain) in "
                    "GMRF clutter: says when it is absent, and its position, velocity and aspect when present",
        params=MultiaspectParams, factory=factory, make_params=multiaspect_params, scenario="bruno2008",
        aliases={"particles": "n_particles"}, rank=rank,
        particle_count=lambda shape, params: particles(kind, params),
        extra_columns=lambda params: EXTRA_COLUMNS,
        bench_settings=lambda snr: {"prior": "paper"}, bench_frames=_bench_frames,
        assumes=ASSUMES, real_video_needs={"templates": REAL_VIDEO_TEMPLATES})


# why the real-video profile wants the templates given (docs/methods/multiaspect.md#real-video)
REAL_VIDEO_TEMPLATES = ("the default, vehicle, is the bruno2008 simulator's target, not a real one (on "
                        "9 of the 12 drone-ir clips it held a false track in every frame); pass --param "
                        "templates=PATH, a .npy (K, h, w) stack of the target's shapes in the input's units, or "
                        "templates=vehicle to use the simulator's anyway (templates=... in make_tracker)")


__all__ = ["MultiaspectParams", "MultiaspectTracker", "method_spec"]
