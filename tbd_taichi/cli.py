"""The ``tbd-taichi`` command line (also ``python -m tbd_taichi``)."""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from . import backend, methods, metrics, tables
from .background import BACKGROUNDS, REAL_VIDEO
from .errors import TBDError
from .methods.sgds.params import PAPER_SALIENCY
from .progress import progress_bar

ARCH_HELP = ("Taichi backend: cpu (default), cuda, vulkan, metal, gpu (first GPU found) or auto "
             "(a GPU if there is one, else the CPU)")


FRONTEND_PROCESS_HELP = ("run normalisation and saliency in a second process, one frame ahead of the particle "
                         "filters (a second CPU core; the same tracks, online rows one frame later)")


def _common(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--arch", default="cpu", choices=backend.ARCH_NAMES, help=ARCH_HELP)
    parser.add_argument("--threads", type=int, default=None,
                        help="CPU threads for Taichi (default: all cores, each worker pinned to one; fewer: unpinned)")


def _truth_csv_path(out: Path) -> Path:
    return out.with_name(out.stem + "_truth.csv")


def cmd_simulate(args) -> int:
    from .simulate import simulate

    scene = simulate((args.shape[0], args.shape[1]), frames=args.frames, snr=args.snr, targets=args.targets,
                     seed=args.seed, motion=args.motion)
    out = Path(args.out)
    if out.suffix != ".npz":
        raise TBDError(f"{out}: --out must end in .npz")
    out.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(out, frames=scene.frames, truth=scene.truth, params=json.dumps(scene.params))
    truth_csv = _truth_csv_path(out)
    tables.write_csv(scene.truth, truth_csv)
    print(f"wrote {out} ({args.frames} frames of {args.shape[0]}x{args.shape[1]}, {args.targets} target(s), "
          f"SNR {args.snr}) and {truth_csv}")
    return 0


def _format_scores(scores: dict) -> str:
    lines = [f"DSR (T0={scores['t0']:g} px)   {scores['dsr']:.3f}",
             f"mean EDT (px)      {scores['edt_mean']:.3f}",
             f"false tracks       {scores['false_tracks']}",
             f"OSPA (c={scores['ospa_c']:g}, p={scores['ospa_p']:g})  {scores['ospa']:.3f}",
             f"tracks / targets   {scores['tracks']} / {len(scores['targets'])}"]
    return "\n".join(lines)


def cmd_evaluate(args) -> int:
    tracks = tables.read_tracks(args.tracks)
    truth = tables.read_truth(args.truth)
    scores = metrics.evaluate(tracks, truth, t0=args.t0, ospa_c=args.ospa_c, ospa_p=args.ospa_p,
                              n_frames=args.frames)
    scores.update(t0=args.t0, ospa_c=args.ospa_c, ospa_p=args.ospa_p)
    if args.json:
        print(json.dumps(scores, allow_nan=True))
    else:
        print(_format_scores(scores))
    return 0


FLAG_NAMES = {"snr": "--snr", "particles": "--particles", "threshold": "--threshold", "min_peak_z": "--min-peak-z"}


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


def method_settings(args, spec) -> dict:
    """The method's parameters and run options from the track flags: the --real-video preset (keys the
    method declares), the method flags (``spec.aliases``), --param, and the sgds-only switches.  A flag the
    method does not take is an error naming the methods that do."""
    from . import methods

    declared = {p.name for p in spec.param_infos()} | set(spec.options)
    chosen = {k: v for k, v in REAL_VIDEO.items() if k in declared} if args.real_video else {}
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
    chosen.update(flagged)
    chosen.update(given)
    if args.background is not None:
        chosen["background"] = args.background
    switches = {"--paths online": args.paths == "online", "--frontend-process": args.frontend_process,
                "--paper-saliency": args.paper_saliency}
    needs = {"--paths online": {"history"}, "--frontend-process": {"frontend_process"},
             "--paper-saliency": set(PAPER_SALIENCY)}
    for flag, on in switches.items():
        if on and not needs[flag] <= declared:
            raise TBDError(f"{flag} applies to --method sgds only")
    if args.paths == "online":
        chosen["history"] = False  # rows go to the CSV as they come: constant memory
    if args.frontend_process:
        chosen["frontend_process"] = True
    if args.paper_saliency:
        chosen.update(PAPER_SALIENCY)
    if "bad_pixels" in declared:
        chosen["bad_pixels"] = not args.no_bad_pixels
    return chosen


def cmd_track(args) -> int:
    from . import io, methods

    spec = methods.get(args.method)
    if args.help_params:
        print(spec.help_text())
        return 0
    if args.input is None or args.out is None:
        raise TBDError("track needs INPUT and --out (or --help-params)")
    settings = method_settings(args, spec)
    init_box = parse_init_box(args.init_box)
    stream = settings.get("history") is False
    source = io.open_frames(args.input)
    tracker = methods.make_tracker(args.method, source.shape, seed=args.seed, engine=args.engine, init_box=init_box,
                                   **settings)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    max_projection = None
    with progress_bar("tracking", args.progress, transient=True) as bar, \
            tables.CsvTableWriter(out, tables.TRACK_COLUMNS) as writer:
        task = bar.add_task("frames", total=source.n_frames) if bar else None
        for frame in io.iter_frames(source, min_frames=spec.min_frames):
            rows = tracker.update(frame)
            if stream:
                writer.write(rows)
            if args.plot:  # the plot's backdrop; not needed otherwise
                max_projection = frame if max_projection is None else np.maximum(max_projection, frame)
            if bar:
                bar.advance(task)
        final = tracker.finish()
        writer.write(final)
    tracks = tables.read_tracks(out) if stream else final  # streamed rows live only in the file
    n_tracks = len(np.unique(tracks["track_id"]))
    print(f"{args.method}: {len(tracks)} rows of {n_tracks} track(s) -> {out}")
    truth = tables.read_truth(args.truth) if args.truth else None
    if truth is not None:
        scores = metrics.evaluate(tracks, truth)
        scores.update(t0=metrics.T0, ospa_c=metrics.OSPA_C, ospa_p=metrics.OSPA_P)
        print(_format_scores(scores))
    if args.plot:
        from .plots import plot_tracks

        plot_tracks(max_projection, tracks, args.plot, truth, title=f"{args.method} tracks on {Path(args.input).name}")
        print(f"plot -> {args.plot}")
    if args.video:
        from .plots import write_overlay_video

        n = write_overlay_video(io.iter_frames(source), tracks, args.video)
        print(f"video ({n} frames) -> {args.video}")
    return 0


def cmd_methods(args) -> int:
    """The registered methods: name, kind, paper and what each does."""
    rows = [("method", "kind", "paper", "what it does")]
    rows += [(spec.name, spec.kind, spec.paper, f"{spec.title}: {spec.description}") for spec in methods.specs()]
    widths = [max(len(r[k]) for r in rows) for k in range(3)]
    for r in rows:
        print("  ".join(c.ljust(w) for c, w in zip(r[:3], widths)) + "  " + r[3])
    print("\nParameters of one method: tbd-taichi track --method NAME --help-params")
    return 0


def cmd_bench(args) -> int:
    from .bench import format_table, run_bench

    engines = [e.strip() for e in args.engines.split(",") if e.strip()]
    unknown = [e for e in engines if e not in ("taichi", "numpy")]
    if unknown or not engines:
        raise TBDError(f"--engines takes a comma list of taichi,numpy; got {args.engines!r}")
    if args.particles < 0 or args.groups < 1 or (args.particles and args.particles < args.groups):
        raise TBDError("--particles must be ≥ 0 and, if > 0, at least --groups (≥ 1)")
    result = run_bench(args.shape, snr=args.snr, n_frames=args.frames, engines=engines, arch=args.arch,
                       particles=args.particles, groups=args.groups, pipeline=not args.no_pipeline,
                       frontend_process=args.frontend_process, runs=args.runs, paired=args.paired,
                       method=args.method)
    print(json.dumps(result) if args.json else format_table(result))
    return 0


def _float_list(text: str, name: str) -> tuple[float, ...]:
    try:
        values = tuple(float(v) for v in text.split(",") if v.strip())
    except ValueError:
        raise TBDError(f"{name} takes a comma list of numbers, got {text!r}") from None
    if not values or min(values) <= 0:
        raise TBDError(f"{name} needs at least one number > 0, got {text!r}")
    return values


def cmd_evaluate_suite(args) -> int:
    import os

    from . import suite

    chosen = tuple(m.strip() for m in args.methods.split(",") if m.strip())
    if not chosen or set(chosen) - set(methods.names()):
        raise TBDError(f"--methods takes a comma list of {','.join(methods.names())}, got {args.methods!r}")
    if args.tests < 1 or (args.workers is not None and args.workers < 1):
        raise TBDError("--tests and --workers must be ≥ 1")
    snrs = _float_list(args.snrs, "--snrs") if args.snrs else (suite.QUICK["snrs"] if args.quick else suite.SNRS)
    sizes = tuple(s for s in suite.SIZES if args.size in ("all", str(s[0])))
    tests = suite.QUICK["tests"] if args.quick and args.tests == 100 else args.tests
    if args.tracker_snr is not None and args.tracker_snr <= 0:
        raise TBDError(f"--tracker-snr must be > 0, got {args.tracker_snr}")
    runs = suite.plan(snrs, sizes, chosen, tests, args.seed, args.tracker_snr or 0.0)
    out_dir = Path(args.out_dir)
    workers = args.workers or os.cpu_count() or 1
    print(f"{len(runs)} runs ({len(chosen)} method(s) x {len(sizes)} size(s) x {len(snrs)} SNR(s) x {tests} test(s)), "
          f"{workers} worker(s) -> {out_dir}")
    results, completed = suite.execute(runs, out_dir / "suite_runs.jsonl", workers, args.arch, args.threads,
                                       progress=not args.no_progress)
    command = (f"tbd-taichi evaluate-suite --tests {tests} --snrs {','.join(f'{v:g}' for v in snrs)} "
               f"--size {args.size} --methods {','.join(chosen)} --seed {args.seed} "
               + (f"--tracker-snr {args.tracker_snr:g} " if args.tracker_snr else "") + f"--out-dir {out_dir}")
    report = suite.write_report(results, out_dir, command, completed, len(runs))
    print(suite.markdown_table(suite.summarise(results)))
    print(f"report -> {report}" + ("" if completed else " (interrupted; finished runs kept)"))
    return 0 if completed else 130


def suite_defaults() -> tuple:
    from .suite import DEFAULT_METHODS

    return DEFAULT_METHODS


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="tbd-taichi", description=(
        "Track-before-detect of dim infrared point targets with Taichi particle filters. "
        "Coordinates: x = column, y = row, 0-based, pixel centres at integers; frames are 0-based."))
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    sim = sub.add_parser("simulate", help="simulate a sequence (SGDS-PF section 3.1)",
                         description="Simulate dim targets in white Gaussian noise (SGDS-PF Eqs. 1, 14, 44-46). "
                                     "Writes OUT (.npz with arrays 'frames' and 'truth') and OUT_truth.csv beside it.")
    sim.add_argument("--shape", type=int, nargs=2, metavar=("H", "W"), required=True, help="frame height and width, px")
    sim.add_argument("--frames", type=int, required=True, help="number of frames T")
    sim.add_argument("--snr", type=float, required=True, help="target SNR of Eq. 1: centre-pixel signal / noise std")
    sim.add_argument("--targets", type=int, default=1, help="number of targets (default 1)")
    sim.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    sim.add_argument("--motion", choices=("stay", "transit"), default="stay",
                     help="stay: targets stay in view (default); transit: they enter and leave")
    sim.add_argument("--out", required=True, help="output .npz path")
    _common(sim)
    sim.set_defaults(func=cmd_simulate)

    ev = sub.add_parser("evaluate", help="score a tracks CSV against a truth CSV",
                        description="Print mean EDT (Eq. 47), DSR (Eq. 48), false tracks and OSPA.")
    ev.add_argument("--tracks", required=True, help="tracks CSV: frame,track_id,x,y,vx,vy,intensity,confidence")
    ev.add_argument("--truth", required=True, help="truth CSV: frame,target_id,x,y,vx,vy,intensity")
    ev.add_argument("--t0", type=float, default=metrics.T0, help="DSR distance threshold T0, px (default 2)")
    ev.add_argument("--ospa-c", type=float, default=metrics.OSPA_C, help="OSPA cut-off c, px (default 5)")
    ev.add_argument("--ospa-p", type=float, default=metrics.OSPA_P, help="OSPA order p (default 2)")
    ev.add_argument("--frames", type=int, default=None,
                    help="sequence length for the OSPA average (default: last frame in either file + 1)")
    ev.add_argument("--json", action="store_true", help="print one JSON object (keys dsr, edt_mean, false_tracks, ospa)")
    _common(ev)
    ev.set_defaults(func=cmd_evaluate)

    tr = sub.add_parser("track", help="detect and track dim targets in a sequence",
                        description="Run a track-before-detect filter over INPUT and write the tracks CSV "
                                    "(frame,track_id,x,y,vx,vy,intensity,confidence; x = column, y = row, 0-based).")
    tr.add_argument("input", metavar="INPUT", nargs="?", help="a .npy/.npz file, a video, or a folder of PNG/TIFF/BMP images")
    tr.add_argument("--method", choices=methods.names(), default="sgds",
                    help="the tracking method (default sgds); `tbd-taichi methods` lists them")
    tr.add_argument("--param", action="append", default=[], metavar="KEY=VALUE",
                    help="set any parameter of the method (repeatable); --help-params lists them")
    tr.add_argument("--help-params", action="store_true",
                    help="print the method's parameters (default, unit, valid range, paper symbol) and exit")
    tr.add_argument("--init-box", default=None, metavar="X,Y,W,H",
                    help="the target's first-frame box, for methods that need one: left column X, top row Y, width, "
                         "height (px, 0-based, pixel centres at integers)")
    tr.add_argument("--snr", type=float, default=None, help="the lowest target SNR to detect (default 1.4; 5 with --real-video)")
    tr.add_argument("--seed", type=int, default=0, help="random seed; the same seed gives the same file (default 0)")
    tr.add_argument("--engine", choices=("taichi", "numpy"), default="taichi", help="kernel engine (default taichi)")
    tr.add_argument("--particles", type=int, default=None,
                    help="pf only: particle count (default: the SGDS-PF paper's Table 3 for the image size and SNR)")
    tr.add_argument("--threshold", type=float, default=None,
                    help="pf only: existence probability above which a target is declared (default 0.5)")
    tr.add_argument("--out", default=None, help="output tracks CSV (required)")
    tr.add_argument("--paths", choices=("whole", "online"), default=None,
                    help="sgds: whole = each confirmed track's whole path, from before its confirmation (default); "
                         "online = the rows as output online, from confirmation on")
    tr.add_argument("--truth", default=None, help="truth CSV (frame,target_id,x,y,...): print DSR, EDT, false tracks, OSPA")
    tr.add_argument("--video", default=None, help="write the input with each track's box, id and trail (.mp4 or .avi)")
    tr.add_argument("--plot", default=None, help="PNG of the tracks over the max-projection (with the truth if given)")
    tr.add_argument("--background", choices=BACKGROUNDS, default=None,
                    help="background suppression before the filters: none (global median and σ, as in the paper; "
                         "default), mean, spatial (hollow local mean), temporal (running mean) or spatiotemporal (the spatial "
                         "residual minus its running mean; the --real-video choice), all but none with a local noise σ")
    tr.add_argument("--min-peak-z", type=float, default=None,
                    help="sgds: report a confirmed track only while its running peak z (largest normalised value "
                         "within 1 px) is at least this (default 0: off, as in the paper; 15 with --real-video)")
    tr.add_argument("--real-video", action="store_true",
                    help="settings for real still-camera infrared video: --background spatiotemporal --snr 5 "
                         "--min-peak-z 15 (each can still be given); see the README's real-video section")
    tr.add_argument("--no-bad-pixels", action="store_true",
                    help="keep persistent single-pixel outliers (hot, dead, blinking pixels) instead of zeroing them")
    tr.add_argument("--progress", action="store_true", help="show a progress bar")
    tr.add_argument("--frontend-process", action="store_true",
                    help="(sgds) " + FRONTEND_PROCESS_HELP)
    tr.add_argument("--paper-saliency", action="store_true",
                    help="(sgds) the paper's Eq. 29 weight (single-frame LEF) and Eq. 40's MSW (the searching particles' "
                         "largest weight) instead of the multi-frame LEF and the candidates' best LEF")
    _common(tr)
    tr.set_defaults(func=cmd_track)

    me = sub.add_parser("methods", help="list the tracking methods", description="The registered methods: name, "
                        "kind, paper and what each does.  Parameters: tbd-taichi track --method NAME --help-params.")
    _common(me)
    me.set_defaults(func=cmd_methods)

    es = sub.add_parser("evaluate-suite", help="Monte Carlo evaluation of SGDS-PF and the original PF (paper Figs. 14-15)",
                        description="Simulate SNR x size x N test sequences, run each method, and write TSR, mean EDT, "
                                    "mean DSR, false tracks and ms/frame as a markdown table, JSON and PNG figures. "
                                    "Runs are appended to OUT_DIR/suite_runs.jsonl as they finish: Ctrl-C keeps them "
                                    "and a rerun skips them.")
    es.add_argument("--tests", type=int, default=100, help="sequences per condition (default 100)")
    es.add_argument("--quick", action="store_true", help="a small version: SNR 1.4 and 2.0, 2 tests per condition")
    es.add_argument("--snrs", default=None, help="comma list of SNRs (default 1.2,1.4,1.6,1.8,2.0)")
    es.add_argument("--size", choices=("all", "50", "200"), default="all",
                    help="50 (50x50, 70 frames), 200 (200x200, 150 frames) or all (default)")
    es.add_argument("--methods", default=",".join(suite_defaults()),
                    help=f"comma list of methods, of {','.join(methods.names())} (default {','.join(suite_defaults())})")
    es.add_argument("--seed", type=int, default=0, help="test k simulates scenario seed SEED+k (default 0)")
    es.add_argument("--tracker-snr", type=float, default=None,
                    help="give every tracker this snr preset (default: the condition's SNR, as in the paper)")
    es.add_argument("--workers", type=int, default=None, help="parallel processes (default: the core count)")
    es.add_argument("--out-dir", default="suite-results", help="where the table, JSON, figures and runs go")
    es.add_argument("--no-progress", action="store_true", help="no progress bar")
    _common(es)
    es.set_defaults(func=cmd_evaluate_suite)

    be = sub.add_parser("bench", help="time each stage, Taichi against NumPy",
                        description="Median milliseconds per frame for each stage of SGDSPF.update (normalise, "
                                    "saliency, searching, tracking) after a warm-up, for each engine in the same run, "
                                    "on a simulated sequence with the --snr preset; fps and peak memory.")
    be.add_argument("--method", choices=methods.names(), default="sgds",
                    help="the method whose tracker is timed (default sgds)")
    be.add_argument("--shape", type=int, nargs=2, metavar=("H", "W"), default=[256, 320],
                    help="frame height and width, px (default 256 320)")
    be.add_argument("--snr", type=float, default=1.4, help="SNR preset: the lowest SNR to detect (default 1.4)")
    be.add_argument("--frames", type=int, default=20, help="timed frames per engine (default 20)")
    be.add_argument("--engines", default="taichi,numpy", help="comma list of engines (default taichi,numpy)")
    be.add_argument("--runs", type=int, default=1,
                    help="runs per engine, taken in turn in alternating order so that a VM's slow spells fall on "
                         "both; medians over all runs' frames, and each run's update time and ratio (default 1)")
    be.add_argument("--paired", action="store_true",
                    help="the engines take the frames in turn within each run, frame by frame, so that even a short "
                         "slow spell of the machine slows both")
    be.add_argument("--particles", type=int, default=0,
                    help="also time one particle-filter step of a pool this large (stage 'particles'; default 0: off)")
    be.add_argument("--groups", type=int, default=1, help="filters the pool is split into (default 1)")
    be.add_argument("--no-pipeline", action="store_true",
                    help="time only normalisation and saliency (and --particles), not the whole SGDSPF.update")
    be.add_argument("--json", action="store_true", help="print one JSON object as the last line")
    be.add_argument("--frontend-process", action="store_true", help=FRONTEND_PROCESS_HELP)
    _common(be)
    be.set_defaults(func=cmd_bench)
    return parser


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if getattr(args, "frames", 1) is not None and getattr(args, "frames", 1) < 1:
        parser.error("--frames must be ≥ 1")
    try:
        backend.keep_freed_memory()
        backend.init(args.arch, threads=args.threads)
        return args.func(args)
    except TBDError as exc:
        print(f"tbd-taichi {args.command}: error: {exc}", file=sys.stderr)
        return 2
