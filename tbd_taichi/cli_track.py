"""``tbd-taichi track``: its options, every check made before the work (:func:`plan_track`), the run, and the
summary line it ends with."""
from __future__ import annotations

import json
import os
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from . import methods, metrics, tables, validate
from .background import BACKGROUNDS
from .errors import TBDError
from .methods.sgds.params import PAPER_SALIENCY
from .profiles import PROFILES, check_real_video_needs, describe, profile_settings, resolved_profile

IMPORTED_AT = time.monotonic()
COMPILE_NOTE_S = 10.0  # a run that compiled longer than this says how to avoid it
FLAG_NAMES = {"snr": "--snr", "particles": "--particles", "threshold": "--threshold", "min_peak_z": "--min-peak-z"}
FRONTEND_PROCESS_HELP = ("run normalisation and saliency in a second process, one frame ahead of the particle "
                         "filters (a second CPU core; the same tracks, online rows one frame later)")
FALLBACK_FPS = 15.0  # the overlay video's rate when the input has none and --fps is not given


def add_track_parser(sub, common) -> None:
    """The ``track`` sub-command and its options."""
    tr = sub.add_parser("track", help="detect and track dim targets in a sequence",
                        description="Run a track-before-detect filter over INPUT and write the tracks CSV "
                                    "(frame,track_id,x,y,vx,vy,intensity,confidence; x = column, y = row, 0-based).")
    number, whole = validate.cli_number, validate.whole
    real = {spec.name: profile_settings(spec, "real-video") for spec in methods.specs()}
    guarded = {name: values["min_peak_z"] for name, values in real.items() if "min_peak_z" in values}
    tr.add_argument("input", metavar="INPUT", nargs="?", help="a .npy/.npz file, a video, or a folder of PNG/TIFF/BMP images")
    tr.add_argument("--method", choices=methods.names(), default="sgds",
                    help="the tracking method (default sgds); `tbd-taichi methods` lists them")
    tr.add_argument("--profile", choices=PROFILES, default=None,
                    help="settings profile: auto (default) picks real-video for videos, image folders and integer "
                         "arrays (camera data) and paper for float arrays (simulated); paper = the method's paper "
                         "defaults; real-video = settings for real still-camera video. Flags override either")
    tr.add_argument("--real-video", action="store_true", help="the same as --profile real-video")
    tr.add_argument("--param", action="append", default=[], metavar="KEY=VALUE",
                    help="set any parameter of the method (repeatable); --help-params lists them")
    tr.add_argument("--help-params", action="store_true",
                    help="print the method's parameters (default, unit, valid range, paper symbol), what its "
                         "defaults assume, and exit")
    tr.add_argument("--init-box", default=None, metavar="X,Y,W,H",
                    help="the target's first-frame box, for methods that need one: left column X, top row Y, width, "
                         "height (px, 0-based, pixel centres at integers)")
    tr.add_argument("--snr", type=number(validate.positive), default=None,
                    help="the lowest target SNR to detect (default 1.4; 5 under the real-video profile)")
    tr.add_argument("--seed", type=number(whole, 0, validate.MAX_SEED), default=0,
                    help="random seed, a whole number ≥ 0; the same seed gives the same file (default 0)")
    tr.add_argument("--engine", choices=("taichi", "numpy"), default="taichi", help="kernel engine (default taichi)")
    tr.add_argument("--particles", type=number(whole, 1), default=None,
                    help="pf only: particle count ≥ 1 (default: the SGDS-PF paper's Table 3 for the image size and SNR)")
    tr.add_argument("--threshold", type=number(validate.positive), default=None,
                    help="pf only: existence probability in (0, 1) above which a target is declared (default 0.5)")
    tr.add_argument("--out", default=None, help="output tracks CSV (required; its folder must exist)")
    tr.add_argument("--paths", choices=("whole", "online"), default=None,
                    help="sgds, tophat-pf: whole = each confirmed track's whole path, from before its confirmation "
                         "(default); online = the rows as output online, from confirmation on")
    tr.add_argument("--report", type=int, choices=(1, 2), default=None,
                    help="tophat-pf: tracks reported: 1 (default: the confirmed survivor) or 2 (and the next-strongest "
                         "survivor)")
    tr.add_argument("--diagnostics", default=None, metavar="CSV",
                    help="tophat-pf: write each window's candidates, trajectory costs J, evidence and decisions (Alg. 5) "
                         "to this CSV")
    tr.add_argument("--truth", default=None,
                    help="truth CSV, points (frame,target_id,x,y,...: DSR, EDT, false tracks, OSPA) or boxes "
                         "(frame,x,y,w,h[,target_id]: detection rate, false points per frame, centre error, IoU)")
    tr.add_argument("--box-margin", type=number(validate.positive, 0.0, True), default=metrics.BOX_MARGIN,
                    help="with box truth: a hit is a track point inside the box grown by this, px (default 2)")
    tr.add_argument("--video", default=None, help="write the input with each track's box, id and trail, and the --truth boxes or points in green (.mp4 or .avi)")
    tr.add_argument("--fps", type=number(validate.within, 0.01, 1000), default=None,
                    help="the overlay video's frame rate, in [0.01, 1000] (default: the input video's, else 15)")
    tr.add_argument("--plot", default=None,
                    help="picture of the tracks over the max-projection, with the truth if given (.png, .pdf or .svg)")
    tr.add_argument("--background", choices=BACKGROUNDS, default=None,
                    help="background suppression before the filters: none (global median and σ, as in the paper; "
                         "the paper profile), mean, spatial (hollow local mean), temporal (running mean) or "
                         "spatiotemporal (the spatial residual minus its running mean; the real-video profile), all "
                         "but none with a local noise σ")
    tr.add_argument("--min-peak-z", type=number(validate.positive, 0.0, True), default=None,
                    help=f"{', '.join(guarded)}: report a confirmed track only while its running peak z (largest "
                         f"normalised value within 1 px) is at least this; below it pf restarts its search and mm-phd "
                         f"frees the tracker for a waiting capture (paper profile 0: off; real-video profile "
                         f"{', '.join(f'{v:g} ({m})' for m, v in guarded.items())})")
    tr.add_argument("--no-bad-pixels", action="store_true",
                    help="keep persistent single-pixel outliers (hot, dead, blinking pixels) instead of zeroing them")
    tr.add_argument("--progress", nargs="?", const="bar", default="auto", choices=("auto", "bar", "lines", "off"),
                    help="auto (default): a bar on a terminal, else a plain line every few seconds; bar; lines; off")
    tr.add_argument("--json", action="store_true",
                    help="print the run summary (and scores) as one JSON object on stdout; other lines go to stderr")
    tr.add_argument("--frontend-process", action="store_true", help="(sgds) " + FRONTEND_PROCESS_HELP)
    tr.add_argument("--paper-saliency", action="store_true",
                    help="(sgds) the paper's Eq. 29 weight (single-frame LEF) and Eq. 40's MSW (the searching particles' "
                         "largest weight) instead of the multi-frame LEF and the candidates' best LEF")
    common(tr)
    tr.set_defaults(func=cmd_track, check=plan_track)


def parse_init_box(text: str | None):
    """``--init-box X,Y,W,H`` as four floats (checked against the method and frame by the registry)."""
    if text is None:
        return None
    try:
        box = tuple(float(p) for p in text.split(","))
    except ValueError:
        box = ()
    if len(box) != 4:
        raise TBDError(f"--init-box takes X,Y,W,H (four numbers, 0-based, x = column of the left edge), got {text!r}")
    return box


def flag_settings(args, spec) -> dict:
    """The method's parameters and run options the track flags set: the method flags (``spec.aliases``),
    --param, and the sgds-only switches.  A flag the method does not take is an error naming the methods that do."""
    declared = {p.name for p in spec.param_infos()} | set(spec.options)
    flagged = {}
    for dest, flag in FLAG_NAMES.items():
        value = getattr(args, dest)
        if value is None:
            continue
        if dest not in spec.aliases:
            takers = [s.name for s in methods.specs() if dest in s.aliases]
            raise TBDError(f"{flag} applies to --method {' or '.join(takers)}, not {spec.name} "
                           f"(see --method {spec.name} --help-params)")
        flagged[spec.aliases[dest]] = value
    given = spec.parse_assignments(args.param)
    clash = sorted(k for k in given if k in flagged and flagged[k] != given[k])
    if clash:
        raise TBDError(f"--param {clash[0]}={given[clash[0]]} contradicts the flag that sets {clash[0]} to "
                       f"{flagged[clash[0]]}; give it once")
    chosen = {**flagged, **given}
    if args.background is not None:
        chosen["background"] = args.background
    for option, value in (("report", args.report), ("diagnostics", args.diagnostics)):
        if value is not None:
            if option not in declared:
                raise TBDError(f"--{option} applies to --method tophat-pf only")
            chosen[option] = value
    if "paths" in declared and args.paths is not None:
        chosen["paths"] = args.paths
    switches = {"--paths online": args.paths == "online" and "paths" not in declared,
                "--frontend-process": args.frontend_process,
                "--paper-saliency": args.paper_saliency}
    needs = {"--paths online": {"history"}, "--frontend-process": {"frontend_process"},
             "--paper-saliency": set(PAPER_SALIENCY)}
    for flag, on in switches.items():
        if on and not needs[flag] <= declared:
            raise TBDError(f"{flag} applies to --method sgds{' or tophat-pf' if flag == '--paths online' else ''} only")
    if args.paths == "online" and "history" in declared:
        chosen["history"] = False  # rows go to the CSV as they come: constant memory
    if args.frontend_process:
        chosen["frontend_process"] = True
    if args.paper_saliency:
        chosen.update(PAPER_SALIENCY)
    if "bad_pixels" in declared and args.no_bad_pixels:
        chosen["bad_pixels"] = False
    return chosen


def requested_profile(args) -> str:
    """--profile, with --real-video as its alias (the two must agree)."""
    if args.real_video and args.profile not in (None, "real-video"):
        raise TBDError(f"--real-video contradicts --profile {args.profile}; give one")
    return "real-video" if args.real_video else (args.profile or "auto")


@dataclass
class TrackPlan:
    """Everything ``track`` needs, checked: the method, the opened input, the settings, the profile and why, the
    truth (kind "points" or "boxes") and the output paths."""

    spec: methods.MethodSpec
    source: object
    settings: dict
    profile: str
    why: str
    init_box: tuple | None
    out: Path
    truth: tuple[str, np.ndarray] | None = None
    outputs: dict = field(default_factory=dict)
    given: dict = field(default_factory=dict)  # the settings the flags gave (over the profile's)

    @property
    def streamed(self) -> bool:
        return self.settings.get("history") is False

    @property
    def columns(self) -> tuple[str, ...]:
        """The tracks CSV's columns (the method's own after the common ones)."""
        params, _ = methods.checked_settings(self.spec, self.source.shape, self.settings)
        return self.spec.track_columns(params)


def plan_track(args) -> TrackPlan | None:
    """Check every argument, path and file of ``track`` before a frame is read or a kernel compiled (the input's
    header is opened; the truth file is parsed whole).  None for --help-params."""
    from . import io

    spec = methods.get(args.method)
    if args.help_params:
        return None
    if args.input is None or args.out is None:
        raise TBDError("track needs INPUT and --out (or --help-params)")
    flagged = flag_settings(args, spec)
    init_box = parse_init_box(args.init_box)
    out = validate.output_path("--out", args.out)
    outputs = {"video": validate.output_path("--video", args.video, validate.VIDEO_OUT) if args.video else None,
               "plot": validate.output_path("--plot", args.plot, validate.PLOT_OUT) if args.plot else None,
               "diagnostics": validate.output_path("--diagnostics", args.diagnostics, (".csv",))
               if args.diagnostics else None}
    validate.apart_from_inputs([("--out", out)] + [(f"--{k}", v) for k, v in outputs.items()],
                               [("INPUT", args.input), ("--truth", args.truth)], io.IMAGE_SUFFIXES)
    truth = tables.read_any_truth(validate.input_file("--truth", args.truth)) if args.truth else None
    source = io.open_frames(args.input)
    validate.frame_shape(f"{source.name}: frame size", source.shape)
    io.check_length(source, spec.min_frames)
    if truth is not None and len(truth[1]) and not tables.rows_inside(*truth, source.shape):
        raise TBDError(f"--truth {args.truth}: none of its {len(truth[1])} rows lies inside the input's "
                       f"{source.shape[0]}x{source.shape[1]} (HxW) frames; is it the truth of another sequence?")
    profile, why = resolved_profile(requested_profile(args), source.kind, source.dtype)
    check_real_video_needs(spec, profile, flagged)
    settings = {**profile_settings(spec, profile), **flagged}
    methods.checked_init_box(spec, init_box, source.shape)
    methods.checked_settings(spec, source.shape, settings)  # every value in range, and the memory, before any work
    return TrackPlan(spec, source, settings, profile, why, init_box, out, truth, outputs, flagged)


def seconds_since_start() -> float:
    """Wall seconds since this process started (Linux /proc; else since this module was imported)."""
    try:
        with open("/proc/self/stat") as handle:
            started = int(handle.read().rsplit(")", 1)[1].split()[19]) / os.sysconf("SC_CLK_TCK")
        with open("/proc/uptime") as handle:
            return float(handle.read().split()[0]) - started
    except (OSError, ValueError, IndexError):
        return time.monotonic() - IMPORTED_AT


def run_tracker(plan: TrackPlan, args, writer, say) -> tuple[np.ndarray, int, RunTiming, np.ndarray | None]:
    """Stream the input through the tracker: (tracks, frames, its timing, the max-projection if a plot is
    wanted).  Streamed rows go to ``writer`` as they come."""
    from . import io
    from .compile_stats import compile_totals
    from .progress import frame_progress

    before = compile_totals()
    tracker = methods.make_tracker(args.method, plan.source.shape, seed=args.seed, engine=args.engine,
                                   init_box=plan.init_box, profile=plan.profile, **plan.settings)
    max_projection, frames, busy, first_frame_at = None, 0, 0.0, None
    in_updates = compile_totals()  # kernels built by the tracker's constructor are start-up's
    with frame_progress("tracking", plan.source.n_frames, args.progress) as progress:
        for frame in io.prefetched(io.iter_frames(plan.source, min_frames=plan.spec.min_frames)):
            first_frame_at = seconds_since_start() if first_frame_at is None else first_frame_at
            started = time.perf_counter()
            rows = tracker.update(frame)
            busy += time.perf_counter() - started
            if plan.streamed:
                writer.write(rows)
            if plan.outputs["plot"]:  # the plot's backdrop; not needed otherwise
                max_projection = frame if max_projection is None else np.maximum(max_projection, frame)
            frames += 1
            progress.advance()
    started = time.perf_counter()
    final = tracker.finish()
    busy += time.perf_counter() - started
    writer.write(final)
    if plan.source.kind == "video" and plan.source.n_frames and frames < plan.source.n_frames:
        say(f"warning: {plan.source.name} declares {plan.source.n_frames} frames but only {frames} could be "
            "decoded (a truncated or damaged file?)", err=True)
    after = compile_totals()
    timing = RunTiming(frames, first_frame_at or seconds_since_start(), after.since(before), busy,
                       after.since(in_updates).seconds)
    return final, frames, timing, max_projection


def rate(frames: int, seconds: float) -> float:
    """Frames per second (NaN for no time)."""
    return frames / seconds if seconds > 0 else float("nan")


@dataclass(frozen=True)
class RunTiming:
    """Where a ``track`` run's time went: ``startup_s`` from the process start to the first frame's update
    (imports, checks, the backend, the tracker; kernels built there included); ``compiled``: the kernels built
    in the run (:mod:`.compile_stats`); ``busy_s``: the tracker's update and finish calls, of which
    ``compile_in_updates_s`` built kernels (Taichi compiles a kernel at its first call)."""

    frames: int
    startup_s: float
    compiled: object
    busy_s: float
    compile_in_updates_s: float

    @property
    def steady_fps(self) -> float:
        """Frames per second of the tracker without building kernels."""
        return rate(self.frames, self.busy_s - self.compile_in_updates_s)

    def summary(self, wall_s: float) -> dict:
        """The JSON fields: start-up, compile, tracker and end-to-end rates."""
        return {"startup_s": round(self.startup_s, 3), **self.compiled.as_dict(),
                "tracker_fps": rate(self.frames, self.busy_s), "steady_fps": self.steady_fps, "wall_s": wall_s,
                "end_to_end_fps": rate(self.frames, wall_s)}

    def compile_note(self, shape) -> str | None:
        """A hint after a run that spent over COMPILE_NOTE_S building kernels (a frame size or method not seen before
        on this machine): later runs load them from the cache, and ``warmup`` can build them ahead of time."""
        if self.compiled.seconds <= COMPILE_NOTE_S:
            return None
        return (f"note: {self.compiled.seconds:.0f} s went to compiling kernels for {shape[0]}x{shape[1]} frames; "
                "later runs at this size load them from Taichi's offline cache (tbd-taichi warmup --shape "
                f"{shape[0]} {shape[1]} builds them ahead of time)")

    def line(self, wall_s: float) -> str:
        """The timing line ``track`` prints."""
        c = self.compiled
        return (f"timing: start-up {self.startup_s:.1f} s; {c.kernels} kernel(s) built in {c.seconds:.1f} s "
                f"(front end {c.front_end_s:.1f} s, machine code or cache {c.first_launch_s:.1f} s); tracker "
                f"{self.steady_fps:.0f} frames/s without them; end to end {wall_s:.1f} s "
                f"({rate(self.frames, wall_s):.1f} frames/s)")


def box_centres(boxes: np.ndarray) -> np.ndarray:
    """Box truth as point truth for the plot: each box's centre (x + w/2, y + h/2, as box_scores takes it)."""
    ids = boxes["target_id"] if "target_id" in boxes.dtype.names else np.zeros(len(boxes))
    rows = zip(boxes["frame"], ids, boxes["x"] + boxes["w"] / 2, boxes["y"] + boxes["h"] / 2, *[np.zeros(len(boxes))] * 3)
    return tables.make_table(rows, tables.TRUTH_DTYPE)


def _frame(value) -> str:
    return "-" if value is None else str(value)


def _px(value: float) -> str:
    return "n/a" if value != value else f"{value:.4f}"


def format_scores(scores: dict) -> str:
    """The scores as the lines ``track`` and ``evaluate`` print."""
    if scores.get("truth") == "boxes":
        def px(v):
            return "n/a" if v != v else f"{v:.2f}"
        from .otb import format_otb

        otb = format_otb(scores) if "cle" in scores else []  # a box tracker's OTB measures
        return "\n".join([f"detection rate (box + {scores['box_margin']:g} px)  {scores['detection_rate']:.3f}",
                          f"false points / frame       {scores['false_points']:.3f}",
                          f"centre error (px)          {px(scores['centre_error'])}",
                          f"IoU                        {px(scores['iou'])}"] + otb)
    return "\n".join([f"DSR (T0={scores['t0']:g} px)   {scores['dsr']:.3f}",
                      f"mean EDT (px)      {scores['edt_mean']:.3f}",
                      f"false tracks       {scores['false_tracks']}",
                      f"OSPA (c={scores['ospa_c']:g}, p={scores['ospa_p']:g})  {scores['ospa']:.3f}",
                      f"MSE / max error    {_px(scores['mse'])} px² / {_px(scores['max_error'])} px "
                      f"(Güler Eq. 4.1b, the track matched within {metrics.MATCH_GATE:g} px)",
                      f"|cardinality error| {scores['cardinality_error']:.3f} per frame",
                      f"P_TD (5 px)        {scores['p_td']:.3f}",
                      "detected / halted  " + ", ".join(f"{t}: {_frame(scores['detection_frame'][t])}/"
                                                        f"{_frame(scores['halt_frame'][t])}"
                                                        for t in scores["detection_frame"]),
                      f"tracks / targets   {scores['tracks']} / {len(scores['targets'])}"])


def cmd_track(args) -> int:
    plan = args.checked
    if plan is None:
        print(methods.get(args.method).help_text())
        return 0

    def say(text: str, err: bool = False) -> None:
        print(text, file=sys.stderr if (err or args.json) else sys.stdout, flush=True)

    summary = execute_track(plan, args, say)
    if args.json:
        print(json.dumps(summary, allow_nan=True, default=_jsonable))
    return 0


def execute_track(plan: TrackPlan, args, say) -> dict:
    """Track, score, plot and write what ``plan`` asks; ``say(text, err=False)`` gets the lines ``track``
    prints.  Returns the run summary (frames, tracks, rows, timing, profile, scores)."""
    from . import io

    say(describe(plan.profile, plan.why, profile_settings(plan.spec, plan.profile), plan.given))
    with tables.CsvTableWriter(plan.out, plan.columns) as writer:
        final, frames, timing, max_projection = run_tracker(plan, args, writer, say)
    tracks = tables.read_tracks(plan.out) if plan.streamed else final  # streamed rows live only in the file
    n_tracks = len(np.unique(tracks["track_id"]))
    scores = None
    if plan.truth is not None:
        kind, truth = plan.truth
        scores = metrics.truth_scores(kind, tracks, truth, frames, box_margin=args.box_margin)
        say(format_scores(scores))
    if plan.outputs["plot"]:
        from .plots import plot_tracks

        truth = plan.truth and (plan.truth[1] if plan.truth[0] == "points" else box_centres(plan.truth[1]))
        plot_tracks(max_projection, tracks, plan.outputs["plot"], truth,
                    title=f"{args.method} tracks on {Path(args.input).name}")
        say(f"plot -> {plan.outputs['plot']}")
    if plan.outputs["video"]:
        from .plots import write_overlay_video

        fps = args.fps or plan.source.fps or FALLBACK_FPS
        n = write_overlay_video(io.iter_frames(plan.source), tracks, plan.outputs["video"], fps=fps,
                                truth=plan.truth and plan.truth[1])
        say(f"video ({n} frames, {fps:g} fps) -> {plan.outputs['video']}")
    wall = seconds_since_start()
    summary = dict(method=args.method, input=str(args.input), out=str(plan.out), frames=frames, tracks=n_tracks,
                   rows=int(len(tracks)), **timing.summary(wall), profile=plan.profile, profile_reason=plan.why)
    say(timing.line(wall))
    note = timing.compile_note(plan.source.shape)
    if note:
        say(note, err=True)
    say(f"{args.method}: {frames} frames, {n_tracks} track(s) ({len(tracks)} rows) -> {plan.out}; tracker "
        f"{summary['tracker_fps']:.1f} frames/s, wall {wall:.1f} s with start-up; profile {plan.profile}")
    return {**summary, "scores": scores}


def _jsonable(value):
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    raise TypeError(f"{type(value).__name__} is not JSON serialisable")


__all__ = ["add_track_parser", "cmd_track", "execute_track", "flag_settings", "format_scores", "parse_init_box", "plan_track",
           "requested_profile"]
