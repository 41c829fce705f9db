"""``tbd-taichi warmup``: compile methods' kernels ahead of time for one frame size, so that later runs (a
container's, a cluster job's) load them from Taichi's offline cache instead of compiling them (~25 s each).

Each method runs over a short simulated sequence (the bench's frames where the method has its own) under each
requested profile, with the same defaults ``tbd-taichi track`` uses, so its searching and tracking kernels are
built.  Each run has a runtime of its own, ended after it (which writes the offline cache): the cache's keys
depend on the fields made before in the runtime, so a kernel built after another method's would be stored under
a key that a ``track`` process, which makes one tracker, never asks for."""
from __future__ import annotations

import json
import sys
import time

import numpy as np

from . import compile_stats, methods, validate
from .errors import TBDError
from .profiles import profile_settings

number, whole = validate.cli_number, validate.whole
PROFILE_CHOICES = ("paper", "real-video", "both")
DEFAULT_FRAMES = 40  # enough for a target to be confirmed, so the tracking kernels are built too
FRAME_SNR = 4.0  # the simulated target's SNR (unless the method's bench scene sets one): bright enough to confirm
BOX_SIDE = 9.0  # a box tracker's first box, px


def add_warmup_parser(sub, common) -> None:
    """Register ``warmup`` with its options (``common``: --arch, --threads)."""
    wa = sub.add_parser("warmup", help="compile methods' kernels ahead of time for a frame size",
                        description="Run each method over a short simulated sequence of frames of --shape under "
                                    "each --profile, so that Taichi compiles its kernels, and write them to the "
                                    "offline cache: later runs at that frame size load them instead of compiling "
                                    "(for container builds and cluster job prologues). Every method compiles per "
                                    "size class, so the default 256 x 320 serves every frame up to that size "
                                    "(SGDS-PF: of up to 8 search blocks).")
    wa.add_argument("--method", action="append", default=None, metavar="NAME",
                    help=f"a method to compile, repeatable or a comma list, of {','.join(methods.names())} "
                         "(default: all)")
    wa.add_argument("--shape", type=number(whole, validate.MIN_SIDE), nargs=2, metavar=("H", "W"), default=[256, 320],
                    help="frame height and width, px (default 256 320)")
    wa.add_argument("--profile", choices=PROFILE_CHOICES, default="both",
                    help="the settings profile(s) to compile for: paper, real-video or both (default); a method "
                         "whose profiles give the same settings runs once (profile 'any')")
    wa.add_argument("--frames", type=number(whole, 1), default=DEFAULT_FRAMES, metavar="N",
                    help=f"frames per run, at least the method's minimum (default {DEFAULT_FRAMES})")
    wa.add_argument("--json", action="store_true", help="print one JSON object as the last line (the lines to "
                    "stderr): shape, runs (method, profile, kernels, compile_s, seconds), cache (path, files, "
                    "new_files: written by this warmup)")
    common(wa)
    wa.set_defaults(func=cmd_warmup, check=check_warmup)


def chosen_methods(given: list[str] | None) -> list[str]:
    """The --method values (repeated and comma lists) in order, each once; all methods when none is given."""
    if given is None:
        return methods.names()
    chosen = list(dict.fromkeys(n.strip() for item in given for n in item.split(",") if n.strip()))
    known = methods.names()
    unknown = [n for n in chosen if n not in known]
    if not chosen:
        raise TBDError(f"--method needs a method name; choose from {', '.join(known)}")
    if unknown:
        raise TBDError(f"--method {unknown[0]!r} is not a method; choose from {', '.join(known)}")
    return chosen


def profile_runs(spec, requested: str) -> list[tuple[str, str]]:
    """(label, profile) of each run of method ``spec`` for ``--profile requested``: one run labelled "any", under
    the paper profile, where the paper and real-video profiles give the method the same settings (the same
    kernels; the real-video profile may also want parameters given, ``MethodSpec.real_video_needs``)."""
    if profile_settings(spec, "paper") == profile_settings(spec, "real-video"):
        return [("any", "paper")]
    return [(p, p) for p in (("paper", "real-video") if requested == "both" else (requested,))]


def check_warmup(args) -> tuple[tuple, list[tuple]]:
    """Every argument before any work: the methods, the shape, --frames against each method's minimum, the
    memory of the frames and of each tracker.  (The shape, the runs: [(spec, label, profile)])."""
    from .simulate import check_memory

    shape = validate.frame_shape("--shape", args.shape)
    runs = []
    for name in chosen_methods(args.method):
        spec = methods.get(name)
        if args.frames < spec.min_frames:
            raise TBDError(f"--frames {args.frames} is too few for --method {name}: it needs at least "
                           f"{spec.min_frames}")
        for label, profile in profile_runs(spec, args.profile):
            methods.checked_settings(spec, shape, profile_settings(spec, profile))
            runs.append((spec, label, profile))
    check_memory(shape, args.frames)
    return shape, runs


def warmup_sequence(spec, shape, n_frames: int) -> tuple[np.ndarray, tuple | None]:
    """(frames, a box tracker's first box or None): the method's bench frames if it has them (the box its bench
    settings give), else a simulated target crossing the frame (a BOX_SIDE box around its first position)."""
    if spec.bench_frames:
        return np.asarray(spec.bench_frames(tuple(shape), n_frames, 0)), spec.bench_keywords(FRAME_SNR).get("init_box")
    from .simulate import simulate

    scenario = simulate(tuple(shape), frames=n_frames, seed=0, **{"snr": FRAME_SNR, "motion": "transit",
                                                                    **spec.bench_scene})
    first = scenario.truth[0] if len(scenario.truth) else None  # the first target's first visible position
    box = None if first is None else (float(first["x"]) - BOX_SIDE / 2, float(first["y"]) - BOX_SIDE / 2,
                                      BOX_SIDE, BOX_SIDE)
    return scenario.frames, box


def first_box(spec, shape, box) -> tuple | None:
    """The box to start a box tracker with (None for the others): ``box`` if it lies in the frame, else a
    BOX_SIDE box in its middle."""
    if not spec.needs_init_box:
        return None
    try:
        return methods.checked_init_box(spec, box, shape)
    except TBDError:
        h, w = shape
        return ((w - 1) / 2 - BOX_SIDE / 2, (h - 1) / 2 - BOX_SIDE / 2, BOX_SIDE, BOX_SIDE)


def camera_frames(frames: np.ndarray) -> np.ndarray:
    """``frames`` as a camera gives them (uint16 counts) for the real-video profile; integer frames as they are."""
    from .simulate import to_camera

    return frames if frames.dtype.kind in "iu" else to_camera(frames)


def warm_one(spec, profile: str, shape, n_frames: int) -> float:
    """Build method ``spec``'s tracker under ``profile`` as ``track`` does and run it over a warm-up sequence;
    the seconds it took."""
    started = time.perf_counter()
    frames, box = warmup_sequence(spec, shape, n_frames)
    if profile == "real-video":
        frames = camera_frames(frames)
    tracker = methods.make_tracker(spec.name, shape, seed=0, engine="taichi", profile=profile,
                                   init_box=first_box(spec, shape, box))
    for frame in frames:
        tracker.update(frame)
    tracker.finish()
    return time.perf_counter() - started


def cmd_warmup(args) -> int:
    """Warm each planned run in a fresh runtime, ended after it so that the offline cache is written; report
    what each built and the files the cache gained."""
    from . import backend

    shape, planned = args.checked
    say = (lambda line: print(line, file=sys.stderr, flush=True)) if args.json else print
    cache = compile_stats.cache_directory()
    started = time.time() - 1.0  # file times come from a coarse clock that can lag time.time() by a tick
    runs = []
    for spec, label, profile in planned:
        backend.shutdown()  # a fresh runtime for each run, as a `track` process has
        backend.init(args.arch, threads=args.threads)
        before = compile_stats.compile_totals()
        seconds = warm_one(spec, profile, shape, args.frames)
        built = compile_stats.compile_totals().since(before)
        backend.shutdown()  # Taichi writes the offline cache when its runtime ends
        say(f"warmup {spec.name} ({label}, {shape[0]}x{shape[1]}): {built.kernels} kernel(s) built in "
            f"{built.seconds:.1f} s")
        runs.append({"method": spec.name, "profile": label, "kernels": built.kernels,
                     "compile_s": round(built.seconds, 3), "seconds": round(seconds, 3)})
    backend.init(args.arch, threads=args.threads)  # the runtime the command started with, for callers in-process
    files, written = compile_stats.cache_file_count(cache), compile_stats.cache_file_count(cache, since=started)
    say(f"offline cache: {cache or 'none'}, {files} files (+{written} new)")
    if args.json:
        print(json.dumps({"shape": [shape[0], shape[1]], "runs": runs,
                          "cache": {"path": cache, "files": files, "new_files": written}}))
    return 0
