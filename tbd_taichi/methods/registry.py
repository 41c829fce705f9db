"""The method registry's parts: a method's description (:class:`MethodSpec`), its parameters declared once
(:func:`param` fields of a frozen dataclass: type, default, unit, valid range, the paper's symbol), their
validation and their conversion from ``KEY=VALUE`` text, and the :class:`Tracker` protocol every method's
tracker implements.  The registry itself (which methods exist) is :mod:`tbd_taichi.methods`."""
from __future__ import annotations

import dataclasses
import math
import typing
from dataclasses import dataclass, field
from typing import Any, Callable, Mapping, Protocol, runtime_checkable

import numpy as np

from ..errors import ParameterError

KINDS = ("point-tbd", "extended-tbd", "box-tracker")
TRUE_WORDS, FALSE_WORDS = ("1", "true", "yes", "on"), ("0", "false", "no", "off")


@runtime_checkable
class Tracker(Protocol):
    """What every method's tracker offers: frames in one at a time, rows of the tracks CSV contract out
    (``tbd_taichi.tables.TRACK_COLUMNS``: frame, track_id, x, y, vx, vy, intensity, confidence)."""

    def update(self, frame: np.ndarray) -> list[tuple]:
        """Take one raw frame; return the rows the tracker reports now (possibly for an earlier frame)."""

    def finish(self) -> np.ndarray:
        """Flush what is pending and return the tracks table (a structured array of TRACK_DTYPE)."""

    @property
    def frames_in(self) -> int:
        """Raw frames taken so far."""

    @property
    def timings(self) -> Mapping[str, float]:
        """Cumulative wall seconds per stage (the benchmark's rows)."""


class OneSequence:
    """A tracker of one sequence: ``update`` after ``finish``, or a second ``finish``, is a ParameterError (the
    tracker's state is spent; a new sequence takes a new tracker).  ``frames_in`` and ``timings`` read ``frame`` and
    ``seconds``, which the tracker keeps."""

    _finished = False
    frame = 0  # raw frames taken so far
    seconds: dict = {}  # cumulative wall seconds per stage (the tracker's STAGES)

    @property
    def frames_in(self) -> int:
        """Raw frames taken so far."""
        return self.frame

    @property
    def timings(self) -> dict:
        """Cumulative wall seconds per stage (the tracker's STAGES: the benchmark's rows)."""
        return dict(self.seconds)

    def _check_open(self, what: str) -> None:
        if self._finished:
            raise ParameterError(f"{type(self).__name__}: {what} after finish; make a new tracker for a new sequence")

    def _close_sequence(self) -> None:
        self._check_open("finish")
        self._finished = True


MAGNITUDE = 1e9  # a real (float) parameter whose range has an open end must still lie within ±this (1e300 is a typo)


@dataclass(frozen=True)
class Range:
    """The valid values of a parameter: an interval (ends open or closed, either may be absent), optionally
    whole numbers only, or a list of choices."""

    low: float | None = None
    high: float | None = None
    low_closed: bool = True
    high_closed: bool = True
    integer: bool = False
    choices: tuple = ()

    def contains(self, value) -> bool:
        if self.choices:
            return value in self.choices
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            return False
        if self.integer and not (isinstance(value, (int, np.integer)) or float(value).is_integer()):
            return False
        if not math.isfinite(value):
            return False
        if self.low is not None and (value < self.low or (value == self.low and not self.low_closed)):
            return False
        return self.high is None or not (value > self.high or (value == self.high and not self.high_closed))

    def __str__(self) -> str:
        if self.choices:
            return "one of " + ", ".join(map(str, self.choices))
        whole = "an integer " if self.integer else ""
        if self.low is not None and self.high is not None:
            return f"{whole}in {'[' if self.low_closed else '('}{self.low:g}, {self.high:g}{']' if self.high_closed else ')'}"
        if self.low is not None:
            return f"{whole}{'≥' if self.low_closed else '>'} {self.low:g}"
        if self.high is not None:
            return f"{whole}{'≤' if self.high_closed else '<'} {self.high:g}"
        return (whole or "any finite number ").strip()


def param(default, *, doc: str, symbol: str = "", unit: str = "", source: str = "", low=None, high=None,
          low_closed: bool = True, high_closed: bool = True, integer: bool = False, choices: tuple = (),
          optional: bool = False):
    """A parameter field: ``default``, what it is (``doc``), the paper's ``symbol`` and ``source`` (equation,
    table or "not in the paper"), its ``unit`` and its valid range; ``optional``: None is allowed (meaning
    "chosen from the input", as the doc says)."""
    rng = Range(low, high, low_closed, high_closed, integer, tuple(choices))
    return field(default=default, metadata=dict(doc=doc, symbol=symbol, unit=unit, source=source, range=rng,
                                                optional=optional))


@dataclass(frozen=True)
class ParamInfo:
    """One parameter as the CLI and docs show it."""

    name: str
    type: type
    default: Any
    doc: str
    symbol: str
    unit: str
    source: str
    range: Range
    optional: bool


def param_infos(params_cls) -> list[ParamInfo]:
    """The declared parameters of a parameter dataclass, in declaration order."""
    hints = typing.get_type_hints(params_cls)
    out = []
    for f in dataclasses.fields(params_cls):
        md = f.metadata
        kind = hints[f.name]
        base = next((t for t in typing.get_args(kind) if t is not type(None)), kind) if typing.get_args(kind) else kind
        out.append(ParamInfo(f.name, base, f.default, md.get("doc", ""), md.get("symbol", ""), md.get("unit", ""),
                             md.get("source", ""), md.get("range", Range()), md.get("optional", False)))
    return out


def validate_params(params, label: str):
    """``params`` (a parameter dataclass instance) if every value is of its type and in its range, else a
    ParameterError naming the first bad one: "<label> parameter NAME = VALUE must be RULE"."""
    for info in param_infos(type(params)):
        value = getattr(params, info.name)
        if value is None and info.optional:
            continue
        ok = _of_type(value, info.type) and info.range.contains(value) if info.type in (int, float) else \
            (_of_type(value, info.type) and (not info.range.choices or value in info.range.choices))
        if ok and info.type is float and abs(value) > MAGNITUDE and not info.range.choices and \
                (info.range.high is None or info.range.low is None):
            raise ParameterError(f"{label} parameter {info.name} = {value!r} is past any sensible value "
                                 f"(|value| ≤ {MAGNITUDE:g} for a real parameter with an open end)")
        if not ok:
            rng = dataclasses.replace(info.range, integer=True) if info.type is int else info.range
            rule = str(rng) if info.type in (int, float) or rng.choices else f"a {info.type.__name__}"
            if info.unit and info.type in (int, float) and not info.range.choices:
                rule += f" ({info.unit})"
            raise ParameterError(f"{label} parameter {info.name} = {value!r} must be {rule}")
    return params


def _of_type(value, kind: type) -> bool:
    if kind is bool:
        return isinstance(value, (bool, np.bool_))
    if kind is int:
        return isinstance(value, (int, np.integer)) and not isinstance(value, bool)
    if kind is float:
        return isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool)
    return isinstance(value, kind)


def convert_text(info: ParamInfo, text: str):
    """The value of ``info``'s type written as ``text`` (``--param KEY=VALUE``), or a ParameterError."""
    t = text.strip()
    if info.optional and t.lower() in ("none", "auto", ""):
        return None
    try:
        if info.type is bool:
            if t.lower() in TRUE_WORDS:
                return True
            if t.lower() in FALSE_WORDS:
                return False
            raise ValueError
        if info.type is int:
            v = float(t)
            if not v.is_integer():
                raise ValueError
            return int(v)
        if info.type is float:
            return float(t)
        return info.type(t)
    except ValueError:
        raise ParameterError(f"--param {info.name}={text}: {info.name} takes {_type_words(info)}") from None


def _type_words(info: ParamInfo) -> str:
    if info.type is bool:
        return "true or false"
    if info.type is int:
        return "a whole number"
    if info.type is float:
        return "a number"
    return str(info.range) if info.range.choices else f"a {info.type.__name__}"


def keyword_factory(tracker_cls) -> Callable:
    """A ``MethodSpec.factory`` for a tracker class that takes (shape, seed=, engine=, arch=, **options) and
    every parameter as a keyword argument of its own name."""
    def factory(shape, params, *, seed: int, engine: str, arch, init_box=None, **options):
        return tracker_cls(shape, seed=seed, engine=engine, arch=arch, **options, **dataclasses.asdict(params))
    factory.__doc__ = f"A {tracker_cls.__name__} from validated parameters."
    return factory


@dataclass(frozen=True)
class MethodSpec:
    """A registered method.

    ``params``: its frozen parameter dataclass (every tunable, declared once with :func:`param`);
    ``make_params(snr, shape, **overrides)``: the dataclass instance for an input (presets by ``snr``, where the
    paper has them), validated; ``factory(shape, params, seed=, engine=, arch=, init_box=, **options)``: the
    tracker; ``options``: the run options (not the method's parameters) the factory also takes;
    ``aliases``: the CLI's method flags (dest names) that set a parameter, flag → parameter name; ``assumes``: what
    the defaults assume about the input; ``scenario``: the simulator scenario it is evaluated on by default;
    ``real_video``: its settings under the real-video profile beside the shared ones (:mod:`~tbd_taichi.profiles`);
    ``real_video_needs``: {parameter: why} that the real-video profile wants given explicitly, no default suiting
    camera data (:func:`~tbd_taichi.profiles.check_real_video_needs`)."""

    name: str
    title: str
    paper: str
    kind: str
    description: str
    params: type
    factory: Callable
    make_params: Callable
    needs_init_box: bool = False
    scenario: str = "jia2022"
    min_frames: int = 1
    options: tuple = ()
    aliases: Mapping[str, str] = field(default_factory=dict)
    assumes: str = ""
    rank: int = 100  # listing order (tables, --help): the flagship first
    particle_count: Callable | None = None  # (shape, params) -> particles the tracker is configured with
    slot_count: Callable | None = None  # (shape, params) -> particle slots it allocates (default: particle_count)
    extra_columns: Callable | None = None  # params -> columns its tracks rows carry after TRACK_COLUMNS
    bench_settings: Callable | None = None  # snr -> make_tracker keywords the bench uses (None: {"snr": snr})
    bench_scene: Mapping = field(default_factory=dict)  # the bench's simulate() keywords (targets, snr, motion)
    bench_frames: Callable | None = None  # (shape, n_frames, seed) -> the bench's frames, instead of simulate()
    real_video: Mapping = field(default_factory=dict)  # its own real-video profile settings, over REAL_VIDEO's
    real_video_needs: Mapping = field(default_factory=dict)  # parameter → why real video needs it given

    def __post_init__(self):
        if self.kind not in KINDS:
            raise ValueError(f"method {self.name}: kind must be one of {', '.join(KINDS)}")

    def param_infos(self) -> list[ParamInfo]:
        return param_infos(self.params)

    def track_columns(self, params) -> tuple[str, ...]:
        """The tracks CSV columns of a tracker of ``params``: TRACK_COLUMNS and the method's own after them."""
        from ..tables import TRACK_COLUMNS

        return TRACK_COLUMNS + (tuple(self.extra_columns(params)) if self.extra_columns else ())

    def bench_keywords(self, snr: float) -> dict:
        """The keywords ``tbd-taichi bench`` makes this method's tracker with for the SNR preset ``snr``."""
        return dict(self.bench_settings(snr)) if self.bench_settings else {"snr": snr}

    def particles(self, shape, params) -> int:
        """The particles a tracker of ``params`` for frames of ``shape`` is configured with (0 if it does not say)."""
        return self.particle_count(shape, params) if self.particle_count else 0

    def slots(self, shape, params) -> int:
        """The particle slots a tracker of ``params`` allocates (its memory), ≥ :meth:`particles`."""
        return self.slot_count(shape, params) if self.slot_count else self.particles(shape, params)

    def parse_assignments(self, assignments) -> dict:
        """``["KEY=VALUE", ...]`` (``--param``) as {name: value} of the declared types; an unknown key or
        a malformed item is a ParameterError naming it and the known keys."""
        infos = {p.name: p for p in self.param_infos()}
        out = {}
        for item in assignments or ():
            key, sep, text = str(item).partition("=")
            key = key.strip()
            if not sep or not key:
                raise ParameterError(f"--param takes KEY=VALUE, got {item!r}")
            if key not in infos:
                raise ParameterError(f"unknown {self.title} parameter {key!r} (--param); known: {', '.join(infos)}")
            out[key] = convert_text(infos[key], text)
        return out

    def help_text(self) -> str:
        """The parameters as a table: name, default, unit, valid values, paper symbol and source, description."""
        rows = [("parameter", "default", "unit", "valid", "paper", "what it is")]
        for p in self.param_infos():
            default = "auto" if p.default is None else f"{p.default:g}" if isinstance(p.default, float) else str(p.default)
            rng = dataclasses.replace(p.range, integer=True) if p.type is int else p.range
            valid = str(rng) if (p.type in (int, float) or rng.choices) else p.type.__name__
            if p.optional:
                valid += " or auto"
            paper = " ".join(s for s in (p.symbol, f"({p.source})" if p.source else "") if s)
            rows.append((p.name, default, p.unit, valid, paper, p.doc))
        widths = [max(len(r[k]) for r in rows) for k in range(5)]
        lines = [f"{self.name}: {self.title} ({self.paper})", self.description]
        if self.assumes:
            lines.append(f"defaults assume: {self.assumes}")
        from ..profiles import profile_settings

        real = profile_settings(self, "real-video")
        lines.append("profiles: paper = the defaults below; real-video (auto's choice for videos, image folders and "
                     "integer frames) = " + (", ".join(f"{k}={v}" for k, v in real.items()) or "the same")
                     + "".join(f"; {k} must be given" for k in self.real_video_needs))
        lines.append("")
        for r in rows:
            lines.append("  ".join(c.ljust(w) for c, w in zip(r[:5], widths)) + "  " + r[5])
        lines.append("\nSet any of them with --param NAME=VALUE (repeatable).")
        return "\n".join(lines)
