"""Checks of arguments and paths made before any work starts (frames read, kernels compiled, files written).

Each check raises the project's own error (:class:`~tbd_taichi.errors.ParameterError` for values,
:class:`~tbd_taichi.errors.InputError` for paths and files) with one line naming the argument, the value or path,
and what is allowed.
"""
from __future__ import annotations

import argparse
import math
import os
from pathlib import Path

import numpy as np

from .errors import InputError, ParameterError

VIDEO_OUT = (".mp4", ".avi")
PLOT_OUT = (".png", ".pdf", ".svg")
MIN_SIDE = 8  # the smallest frame side a tracker or the simulator takes, px
MAX_SEED = 2**32 - 1  # the trackers' counter-based generator keys on a 32-bit seed: a larger one would repeat a smaller
MAX_THREADS = max(8, 4 * (os.cpu_count() or 1))  # CPU threads a run may ask for (more only oversubscribe the cores)


def whole(name: str, value, low: int = 0, high: int | None = None) -> int:
    """``value`` as an int in [low, high] (a bool or a fraction is refused)."""
    ok = isinstance(value, (int, np.integer)) and not isinstance(value, bool) and value >= low and (high is None or value <= high)
    if not ok:
        span = f"≥ {low}" if high is None else f"in [{low}, {high}]"
        raise ParameterError(f"{name} must be a whole number {span}, got {value!r}".lstrip())
    return int(value)


def finite_number(value) -> bool:
    """Whether ``value`` is a finite real number (a Python or NumPy int or float; not a bool)."""
    return isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool) and \
        math.isfinite(value)


def positive(name: str, value, low: float = 0.0, closed: bool = False) -> float:
    """``value`` as a finite float > low (≥ low with ``closed``)."""
    ok = finite_number(value) and (value >= low if closed else value > low)
    if not ok:
        raise ParameterError(f"{name} must be a finite number {'≥' if closed else '>'} {low:g}, got {value!r}".lstrip())
    return float(value)


def within(name: str, value, low: float, high: float) -> float:
    """``value`` as a finite float in [low, high]."""
    ok = finite_number(value) and low <= value <= high
    if not ok:
        raise ParameterError(f"{name} must be a number in [{low:g}, {high:g}], got {value!r}".lstrip())
    return float(value)


def output_path(name: str, path, suffixes: tuple[str, ...] | None = None) -> Path:
    """An output file path whose folder exists and is writable, with one of ``suffixes`` (any if None); the
    file itself, if there, must be a writable file."""
    path = Path(path)
    if suffixes and path.suffix.lower() not in suffixes:
        raise InputError(f"{name} {path}: the file must end in {' or '.join(suffixes)}")
    folder = path.parent if str(path.parent) else Path(".")
    if not folder.is_dir():
        raise InputError(f"{name} {path}: folder {folder} does not exist")
    if path.is_dir():
        raise InputError(f"{name} {path}: is a folder; give a file name")
    if not os.access(folder, os.W_OK) or (path.exists() and not os.access(path, os.W_OK)):
        raise InputError(f"{name} {path}: not writable")
    created = not path.exists()
    try:  # os.access answers for the permission bits only (root, /proc, a read-only mount): open it, write nothing
        with open(path, "ab"):
            pass
    except OSError as exc:
        raise InputError(f"{name} {path}: cannot be written ({exc.strerror})") from None
    if created:
        path.unlink(missing_ok=True)
    return path


def apart_from_inputs(outputs, inputs, frame_suffixes: tuple = ()) -> None:
    """Refuse outputs ((flag, path or None) pairs) that would overwrite an input ((name, path or None) pairs: a
    file, or a folder whose ``frame_suffixes`` files are read as frames) or each other (set look-ups: a batch's
    thousands of inputs cost one pass)."""
    sources = {Path(p).resolve(): name for name, p in inputs if p is not None}
    folders = {source for source in sources if source.is_dir()}
    seen = {}
    for flag, path in ((f, Path(p).resolve()) for f, p in outputs if p is not None):
        if path in seen:
            raise InputError(f"{flag} {path} is the {seen[path]} file too; give two paths")
        seen[path] = flag
        if path in sources:
            raise InputError(f"{flag} {path} is the {sources[path]} file; writing it would overwrite the input")
        if path.parent in folders and path.suffix.lower() in frame_suffixes:
            raise InputError(f"{flag} {path} lies in the {sources[path.parent]} folder with its frames; give a path "
                             "outside it")


def input_file(name: str, path) -> Path:
    """An existing, readable, non-empty file."""
    path = Path(path)
    if path.is_dir():
        raise InputError(f"{name} {path}: is a folder; give a file")
    if not path.is_file():
        raise InputError(f"{name} {path}: no such file")
    if not os.access(path, os.R_OK):
        raise InputError(f"{name} {path}: not readable")
    if path.stat().st_size == 0:
        raise InputError(f"{name} {path}: file is empty")
    return path


def available_memory() -> int:
    """Bytes of memory available to a new allocation (Linux MemAvailable; else the physical total)."""
    try:
        with open("/proc/meminfo") as handle:
            for line in handle:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):
        return 1 << 62


def memory_guard(what: str, needed: int) -> None:
    """Refuse a request whose estimated memory ``needed`` (bytes) exceeds what is available."""
    free = available_memory()
    if needed > free:
        raise ParameterError(f"{what} needs about {needed / 2**30:.1f} GiB of memory, but {free / 2**30:.1f} GiB "
                             "are available; ask for less")


def frame_shape(name: str, shape) -> tuple[int, int]:
    """(H, W), each a whole number ≥ MIN_SIDE."""
    values = tuple(shape)
    if len(values) != 2:
        raise ParameterError(f"{name} must be two numbers H W, got {shape!r}")
    for v in values:
        whole(f"{name} side", v, MIN_SIDE)
    return values[0], values[1]


def cli_number(check, *bounds):
    """An argparse ``type`` for a command-line number: the text converted (to int when ``check`` is :func:`whole`,
    else float) and checked by ``check(name, value, *bounds)``; a bad one is one line, "argument --x: …"."""
    convert, kind = (int, "a whole number") if check is whole else (float, "a number")

    def parse(text: str):
        try:
            value = convert(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {kind}, got {text!r}") from None
        try:
            return check("", value, *bounds)
        except ParameterError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None

    parse.__name__ = kind  # argparse names the type in its own messages
    return parse


PIXEL_BYTES = 4 * 48  # a tracker's per-pixel fields (normalised frame, background, saliency layers, rings), bytes
PARTICLE_BYTES = 160  # a particle's state, weights and double buffers on both engines, bytes


def tracker_memory(what: str, shape, particles) -> int:
    """Refuse a tracker for frames of ``shape`` with ``particles`` particles (a count, or a function giving it,
    called only once the frames' own fields are known to fit) that cannot fit in memory; its estimated bytes
    otherwise."""
    pixels = int(shape[0]) * int(shape[1]) * PIXEL_BYTES
    memory_guard(what, pixels)
    needed = pixels + int(particles() if callable(particles) else particles) * PARTICLE_BYTES
    memory_guard(what, needed)
    return needed
