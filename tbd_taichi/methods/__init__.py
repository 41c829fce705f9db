"""The method registry: every tracking method tbd-taichi offers, each a module of this package with a
``SPEC`` (:class:`~tbd_taichi.methods.registry.MethodSpec`).  The CLI, the Python API, the evaluation suite,
the benchmark and the README's methods table all learn of methods from here.

    >>> import tbd_taichi as tbd
    >>> tbd.methods.names()
    ['sgds', 'pf']
    >>> tracker = tbd.make_tracker("sgds", (256, 320), seed=0, N_sump=6000)

A method outside this package is added with :func:`register` (docs/adding-a-method.md)."""
from __future__ import annotations

import importlib
import math
import pkgutil

import numpy as np

from ..engines import check_engine
from ..errors import ParameterError
from .registry import KINDS, MethodSpec, ParamInfo, Tracker, param

_REGISTRY: dict[str, MethodSpec] = {}
_DISCOVERED = False


def _discover() -> None:
    """Import each module of this package once and register the ``SPEC`` it declares."""
    global _DISCOVERED
    if _DISCOVERED:
        return
    _DISCOVERED = True
    for info in pkgutil.iter_modules(__path__):
        if info.name == "registry":
            continue
        spec = getattr(importlib.import_module(f"{__name__}.{info.name}"), "SPEC", None)
        if spec is not None:
            register(spec)


def register(spec: MethodSpec) -> MethodSpec:
    """Add ``spec`` to the registry (a second method of the same name is an error)."""
    known = _REGISTRY.get(spec.name)
    if known is not None and known is not spec:
        raise ParameterError(f"a method named {spec.name!r} is registered already")
    _REGISTRY[spec.name] = spec
    return spec


def unregister(name: str) -> None:
    """Remove method ``name`` (one added with :func:`register`) from the registry."""
    _discover()
    get(name)
    del _REGISTRY[name]


def names() -> list[str]:
    """The registered methods' names, in listing order (the flagship first, then by name)."""
    _discover()
    return sorted(_REGISTRY, key=lambda n: (_REGISTRY[n].rank, n))


def get(name: str) -> MethodSpec:
    """The spec of method ``name``, or a ParameterError listing the known ones."""
    _discover()
    if name not in _REGISTRY:
        raise ParameterError(f"unknown method {name!r}; choose one of {', '.join(names())}")
    return _REGISTRY[name]


def specs() -> list[MethodSpec]:
    """Every registered spec, in listing order."""
    return [get(n) for n in names()]


def split_options(spec: MethodSpec, kw: dict) -> tuple[dict, dict]:
    """``kw`` as (the method's parameters, its run options); anything else is a ParameterError naming it."""
    declared = {p.name for p in spec.param_infos()}
    unknown = sorted(set(kw) - declared - set(spec.options))
    if unknown:
        raise ParameterError(f"unknown {spec.title} parameter(s) {', '.join(unknown)}; parameters: "
                             f"{', '.join(sorted(declared))}" + (f"; options: {', '.join(spec.options)}" if spec.options
                                                                else ""))
    return {k: v for k, v in kw.items() if k in declared}, {k: v for k, v in kw.items() if k not in declared}


def checked_settings(spec: MethodSpec, shape: tuple[int, int], settings: dict) -> tuple:
    """``settings`` as (params, run options) for frames of ``shape``: names known, values in range, and the
    tracker's estimated memory within what there is (a ParameterError naming the problem otherwise)."""
    from ..validate import tracker_memory

    overrides, options = split_options(spec, settings)
    params = spec.make_params(shape, **overrides)
    tracker_memory(f"a {spec.name} tracker for {shape[0]}x{shape[1]} frames", shape,
                   lambda: spec.slots(shape, params))
    return params, options


def checked_init_box(spec: MethodSpec, init_box, shape) -> tuple[float, float, float, float] | None:
    """The first-frame box (x, y, w, h) as floats (x = column of the left edge, 0-based), checked against the
    method and the frame ``shape``; a ParameterError if the method needs one and has none, or takes none."""
    if init_box is None:
        if spec.needs_init_box:
            raise ParameterError(f"method {spec.name} needs the target's first-frame box: --init-box X,Y,W,H "
                                 "(init_box=(x, y, w, h) in Python)")
        return None
    if not spec.needs_init_box:
        takers = [s.name for s in specs() if s.needs_init_box]
        raise ParameterError(f"method {spec.name} takes no --init-box (it finds targets itself); methods that do: "
                             f"{', '.join(takers) or 'none yet'}")
    try:
        x, y, w, h = (float(v) for v in init_box)
    except (TypeError, ValueError):
        raise ParameterError(f"init_box must be four numbers X,Y,W,H, got {init_box!r}") from None
    height, width = shape
    if not all(map(math.isfinite, (x, y, w, h))) or w <= 0 or h <= 0:
        raise ParameterError(f"init_box {init_box!r}: X, Y must be finite and W, H > 0")
    if x + w <= -0.5 or y + h <= -0.5 or x >= width - 0.5 or y >= height - 0.5:
        raise ParameterError(f"init_box {init_box!r} lies outside the {height}x{width} frame")
    return x, y, w, h


def make_tracker(name: str, shape, *, seed: int = 0, engine: str = "taichi", arch: str | None = None,
                 init_box=None, profile: str = "auto", **kw) -> Tracker:
    """A streaming tracker of method ``name`` for frames of ``shape`` (H, W).

    ``kw``: the method's parameters by name (``tbd-taichi track --method NAME --help-params`` lists them;
    ``snr`` chooses presets where the paper has them) and its run options (for sgds: background, bad_pixels,
    history, frontend_process).  ``profile`` (:mod:`tbd_taichi.profiles`): ``auto`` (the real-video settings for
    integer-typed frames, decided at the first frame), ``paper`` or ``real-video``; ``kw`` wins over it.  An
    unknown name, parameter or out-of-range value is a ParameterError."""
    from ..profiles import check_profile, check_real_video_needs, profile_settings
    from ..validate import MAX_SEED, whole
    from .profiled import ProfiledTracker

    spec = get(name)
    seed = whole("seed", seed, 0, MAX_SEED)
    check_engine(engine)
    check_profile(profile)
    if len(tuple(shape)) != 2:
        raise ParameterError(f"shape must be (H, W), got {shape!r}")
    shape = (int(shape[0]), int(shape[1]))
    if min(shape) < 1:
        raise ParameterError(f"shape must be (H, W) with H, W ≥ 1, got {shape!r}")
    box = checked_init_box(spec, init_box, shape)

    def checked(chosen: str) -> tuple:
        check_real_video_needs(spec, chosen, kw)
        return checked_settings(spec, shape, {**profile_settings(spec, chosen), **kw})

    def build(chosen: str):
        params, options = checked(chosen)
        return spec.factory(shape, params, seed=seed, engine=engine, arch=arch, init_box=box, **options)

    if profile == "auto":  # checked now, though the tracker is built at the first frame
        checked("paper")
    return ProfiledTracker(build, profile, name)


def track(frames_or_path, method: str = "sgds", **kw) -> np.ndarray:
    """Run method ``method`` over a whole sequence (array (T, H, W) or anything ``tbd_taichi.io`` reads) and
    return its tracks table; ``kw`` as :func:`make_tracker` takes them (``profile="auto"`` decides by the input:
    a video, a folder of images or integer frames get the real-video settings)."""
    from .. import io

    from ..profiles import resolved_profile

    spec = get(method)
    source = io.open_frames(frames_or_path)
    profile, _ = resolved_profile(kw.pop("profile", "auto"), source.kind, source.dtype)
    tracker = make_tracker(method, source.shape, profile=profile, **kw)
    for frame in io.iter_frames(source, min_frames=spec.min_frames):
        tracker.update(frame)
    return tracker.finish()


def methods_table() -> str:
    """The registered methods as a markdown table (the README's, checked by a test)."""
    lines = ["| method | kind | paper | what it does |", "|---|---|---|---|"]
    lines += [f"| `{s.name}` | {s.kind} | {s.paper} | {s.title}: {s.description} |" for s in specs()]
    return "\n".join(lines)


__all__ = ["KINDS", "MethodSpec", "ParamInfo", "Tracker", "get", "make_tracker", "methods_table", "names", "param",
           "register", "specs", "track", "unregister"]
