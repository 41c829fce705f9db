"""Settings profiles: which defaults suit the input.

The methods' own defaults are their papers' settings, for simulated sequences of a point target in white
Gaussian noise.  Camera recordings (real infrared video) carry still clutter and heavy-tailed residual noise that
those settings confirm as false tracks, so they get the real-video settings (:data:`~.background.REAL_VIDEO`,
measured on the drone-ir clips: docs/methods/sgds.md#real-video).

* ``paper``: the method's defaults;
* ``real-video``: the method's defaults with the real-video settings it declares (a method takes those of
  :data:`~.background.REAL_VIDEO` that are among its parameters and options, and its spec's own ``real_video``);
* ``auto`` (the default): ``real-video`` for camera recordings (a video file, a folder of images, integer-typed
  frames), ``paper`` for floating-point frames (the simulator's, or data normalised already).

Settings given explicitly (flags, ``--param``, keyword arguments) always win over the profile's.
"""
from __future__ import annotations

import numpy as np

from .background import REAL_VIDEO
from .errors import ParameterError

PROFILES = ("auto", "paper", "real-video")


def check_profile(name: str) -> str:
    """``name`` if it is a profile, else a ParameterError listing them."""
    if name not in PROFILES:
        raise ParameterError(f"unknown profile {name!r}; choose one of {', '.join(PROFILES)}")
    return name


def resolved_profile(name: str, kind: str, dtype=None) -> tuple[str, str]:
    """(profile, why) for requested profile ``name`` and an input of ``kind`` ("video", "folder", "array") whose
    frames have ``dtype``: ``auto`` becomes ``real-video`` for camera recordings, else ``paper``."""
    check_profile(name)
    if name != "auto":
        return name, "chosen explicitly"
    if kind in ("video", "folder"):
        return "real-video", f"the input is a {'video' if kind == 'video' else 'folder of images'}: a camera recording"
    dtype = np.dtype(dtype) if dtype is not None else np.dtype(np.float32)
    if dtype.kind in "iub":
        return "real-video", f"the frames are {dtype} integers: raw camera data"
    return "paper", f"the frames are {dtype} floats: a simulated or normalised sequence"


def profile_settings(spec, profile: str) -> dict:
    """The settings ``profile`` (``paper`` or ``real-video``) gives method ``spec``: only those it declares."""
    if profile == "paper":
        return {}
    declared = {p.name for p in spec.param_infos()} | set(spec.options)
    return {**{k: v for k, v in REAL_VIDEO.items() if k in declared}, **spec.real_video}


def check_real_video_needs(spec, profile: str, given) -> None:
    """Under the ``real-video`` profile, a ParameterError naming the first parameter of ``spec.real_video_needs``
    not among the names ``given`` explicitly, and why camera data needs it (a method whose defaults model the
    simulator's target only, as the multiaspect filters' vehicle templates)."""
    if profile != "real-video":
        return
    for name, why in spec.real_video_needs.items():
        if name not in given:
            raise ParameterError(f"{spec.name} on real video needs {name} given: {why}")


def describe(profile: str, why: str, settings: dict, given: dict | None = None) -> str:
    """One line for the user: the profile, why, the settings it chose, and those ``given`` explicitly instead."""
    def show(values: dict) -> str:
        return ", ".join(f"{k}={v:g}" if isinstance(v, float) else f"{k}={v}" for k, v in values.items())

    given = {k: v for k, v in (given or {}).items() if k in settings}
    chosen = {k: v for k, v in settings.items() if k not in given}
    other = "paper" if profile == "real-video" else "real-video"
    text = show(chosen) or ("the paper defaults" if profile == "paper" else "no setting of its own for this method")
    if given:
        text += f" (given instead: {show(given)})"
    return f"profile {profile} ({why}): {text}; --profile {other} for the other defaults"
