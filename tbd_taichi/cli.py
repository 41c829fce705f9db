"""The ``tbd-taichi`` command line (also ``python -m tbd_taichi``).

Every sub-command checks its arguments, paths and files (``check``, run before the Taichi backend starts) and
then does its work (``func``); a bad argument is one line naming it and what is allowed, exit status 2."""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from . import backend, methods, metrics, tables, validate
from .cli_batch import add_batch_parser
from .cli_simulate import add_simulate_parser
from .cli_track import FRONTEND_PROCESS_HELP, add_track_parser, format_scores
from .cli_warmup import add_warmup_parser
from .errors import TBDError
from .executor import SCHEDULER_HELP, check_scheduler, start_backend

ARCH_HELP = ("Taichi backend: cpu (default), cuda, vulkan, metal, gpu (first GPU found) or auto "
             "(a GPU if there is one, else the CPU)")
number, whole, positive = validate.cli_number, validate.whole, validate.positive


class OneLineParser(argparse.ArgumentParser):
    """argparse whose usage errors are one line (``tbd-taichi track: error: argument --seed: …``), exit 2."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def _common(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--arch", default="cpu", choices=backend.ARCH_NAMES, help=ARCH_HELP)
    parser.add_argument("--threads", type=number(whole, 1, validate.MAX_THREADS), default=None,
                        help="CPU threads for Taichi (default: all cores, each worker pinned to one; fewer: unpinned)")


def check_evaluate(args) -> tuple[np.ndarray, tuple[str, np.ndarray]]:
    """Both files read and checked: (tracks, (truth kind, truth))."""
    tracks = tables.read_tracks(validate.input_file("--tracks", args.tracks))
    kind, truth = tables.read_any_truth(validate.input_file("--truth", args.truth))
    last = max(int(t["frame"].max()) for t in (tracks, truth) if len(t)) if len(tracks) or len(truth) else -1
    if args.frames is not None and args.frames <= last:
        raise TBDError(f"--frames {args.frames}: the files have rows up to frame {last} (0-based); give at least "
                       f"{last + 1}, or leave it out")
    return tracks, (kind, truth)


def cmd_evaluate(args) -> int:
    tracks, (kind, truth) = args.checked
    scores = metrics.truth_scores(kind, tracks, truth, args.frames, box_margin=args.box_margin, t0=args.t0,
                                  ospa_c=args.ospa_c, ospa_p=args.ospa_p)
    print(json.dumps(scores, allow_nan=True) if args.json else format_scores(scores))
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


def check_bench(args) -> list[str]:
    """The engines, the pool split, the shape and the memory the run needs: the engines to time."""
    engines = [e.strip() for e in args.engines.split(",") if e.strip()]
    unknown = [e for e in engines if e not in ("taichi", "numpy")]
    if unknown or not engines:
        raise TBDError(f"--engines takes a comma list of taichi,numpy; got {args.engines!r}")
    if args.particles and args.particles < args.groups:
        raise TBDError(f"--particles {args.particles} must be at least --groups {args.groups} (or 0: off)")
    shape = validate.frame_shape("--shape", args.shape)
    spec = methods.get(args.method)
    args.settings = spec.parse_assignments(args.param)
    keywords = {**spec.bench_keywords(args.snr), **args.settings}
    keywords.pop("init_box", None)  # a box tracker's first box: make_tracker's, not a parameter
    params, _ = methods.checked_settings(spec, shape, keywords)
    frames_as_particles = shape[0] * shape[1] * args.frames * 4 // validate.PARTICLE_BYTES  # the simulated frames
    validate.tracker_memory(f"bench --shape {shape[0]} {shape[1]} ({len(engines)} engine(s))", shape,
                            lambda: spec.slots(shape, params) * len(engines)
                            + args.particles + frames_as_particles)
    return engines


def cmd_bench(args) -> int:
    from .bench import format_table, run_bench

    result = run_bench(args.shape, snr=args.snr, n_frames=args.frames, engines=args.checked, arch=args.arch,
                       particles=args.particles, groups=args.groups, pipeline=not args.no_pipeline,
                       frontend_process=args.frontend_process, runs=args.runs, paired=args.paired,
                       method=args.method, settings=args.settings, threads=args.threads)
    print(json.dumps(result) if args.json else format_table(result))
    return 0


def _float_list(text: str, name: str) -> tuple[float, ...]:
    try:
        values = tuple(float(v) for v in text.split(",") if v.strip())
    except ValueError:
        raise TBDError(f"{name} takes a comma list of numbers, got {text!r}") from None
    if not values or not all(np.isfinite(v) and v > 0 for v in values):
        raise TBDError(f"{name} needs finite numbers > 0, got {text!r}")
    return values


def check_evaluate_suite(args) -> dict:
    """The methods, SNRs, sizes, output folder, scheduler and workers: the suite's plan."""
    import os

    from . import suite

    chosen = tuple(m.strip() for m in args.methods.split(",") if m.strip())
    if not chosen or set(chosen) - set(methods.names()):
        raise TBDError(f"--methods takes a comma list of {','.join(methods.names())}, got {args.methods!r}")
    scenarios = {methods.get(m).scenario for m in chosen}
    if args.scenario == "long2012" and chosen != ("mm-phd",):
        raise TBDError(f"--scenario long2012 evaluates --methods mm-phd (and its ablations), got {args.methods!r}")
    if args.scenario == "bruno2008" and not set(chosen) <= {"ma-rs", "ma-apf"}:
        raise TBDError(f"--scenario bruno2008 evaluates --methods ma-rs,ma-apf (both run), got {args.methods!r}")
    if args.scenario == "guler2016":
        from .suite_guler2016 import METHODS as GULER_METHODS

        if set(chosen) - set(GULER_METHODS):
            raise TBDError(f"--scenario guler2016 evaluates --methods of {','.join(GULER_METHODS)}, got "
                           f"{args.methods!r}")
    elif args.compare_runs is not None:
        raise TBDError("--compare-runs applies to --scenario guler2016")
    if args.scenario == "jia2022" and scenarios != {"jia2022"}:
        raise TBDError(f"--methods {args.methods} is evaluated on --scenario {scenarios.pop()}; give it")
    if args.explain and (args.scenario != "jia2022" or "sgds" not in chosen):
        raise TBDError("--explain applies to --scenario jia2022 with sgds among --methods")
    if args.scheduler is not None and args.scenario != "jia2022":
        raise TBDError(f"--scheduler applies to --scenario jia2022; the {args.scenario} scenario runs in this process")
    scheduler = check_scheduler(args.scheduler)
    given = [f for f, v in (("--snrs", args.snrs), ("--size", args.size), ("--tracker-snr", args.tracker_snr))
             if v is not None]
    if given and args.scenario != "jia2022":
        raise TBDError(f"{given[0]} applies to --scenario jia2022; the {args.scenario} scenario sets its own")
    args.size = args.size or "all"
    snrs = _float_list(args.snrs, "--snrs") if args.snrs else (suite.QUICK["snrs"] if args.quick else suite.SNRS)
    sizes = tuple(s for s in suite.SIZES if args.size in ("all", str(s[0])))
    if args.tests is not None:
        tests = args.tests
    elif args.scenario == "guler2016":
        from .suite_guler2016 import QUICK as GULER_QUICK, RUNS

        tests = GULER_QUICK["runs"] if args.quick else RUNS
    else:
        tests = suite.QUICK["tests"] if args.quick else 100
    if args.seed + tests - 1 > validate.MAX_SEED:
        raise TBDError(f"--seed {args.seed} with {tests} tests: the runs' seeds SEED…SEED+{tests - 1} must stay "
                       f"≤ {validate.MAX_SEED}")
    out_dir = Path(args.out_dir or ("docs/results/guler2016" if args.scenario == "guler2016" else "suite-results"))
    if out_dir.exists() and not out_dir.is_dir():
        raise TBDError(f"--out-dir {out_dir}: is a file; give a folder")
    validate.output_path("--out-dir", out_dir / "suite_runs.jsonl") if out_dir.is_dir() else \
        validate.output_path("--out-dir", out_dir)  # a new folder: its parent must exist and be writable
    workers = args.workers or os.cpu_count() or 1
    return dict(chosen=chosen, snrs=snrs, sizes=sizes, tests=tests, out_dir=out_dir, scheduler=scheduler,
                workers=workers, params=checked_suite_params(args, chosen, snrs, sizes))


def checked_suite_params(args, chosen, snrs, sizes) -> dict:
    """evaluate-suite's --param settings ({name: value}), checked for every method, size and SNR preset before any
    run (a ParameterError naming the problem); only the jia2022 suite takes them."""
    if not args.param:
        return {}
    if args.scenario != "jia2022":
        raise TBDError(f"--param applies to --scenario jia2022, not {args.scenario}")
    settings = {}
    for method in chosen:
        spec = methods.get(method)
        settings = spec.parse_assignments(args.param)
        if "snr" in settings:
            raise TBDError("--param snr: the suite gives each tracker its condition's SNR preset; set another "
                           "with --tracker-snr")
        for (side, _), snr in ((size, snr) for size in sizes for snr in snrs):
            methods.checked_settings(spec, (side, side), {"snr": args.tracker_snr or snr, **settings})
    return settings


def suite_fans_out(args) -> bool:
    """evaluate-suite's runs go to worker processes: the jia2022 suite on a scheduler or on more than one worker."""
    return args.scenario == "jia2022" and bool(args.scheduler or args.checked["workers"] > 1)


def cmd_evaluate_suite(args) -> int:
    from . import suite

    plan = args.checked
    if args.scenario == "long2012":
        return run_long2012_suite(args, plan["tests"], plan["out_dir"])
    if args.scenario == "bruno2008":
        return run_bruno2008_suite(args, plan["tests"], plan["out_dir"])
    if args.scenario == "guler2016":
        return run_guler2016_suite(args, plan["chosen"], plan["tests"], plan["out_dir"])
    chosen, snrs, sizes, tests, out_dir = (plan[k] for k in ("chosen", "snrs", "sizes", "tests", "out_dir"))
    runs = suite.plan(snrs, sizes, chosen, tests, args.seed, args.tracker_snr or 0.0, explain=args.explain,
                      params=plan["params"])
    out_dir.mkdir(exist_ok=True)
    workers = plan["workers"]
    where = plan["scheduler"] or f"{workers} worker(s)"
    print(f"{len(runs)} runs ({len(chosen)} method(s) x {len(sizes)} size(s) x {len(snrs)} SNR(s) x {tests} test(s)), "
          f"{where} -> {out_dir}")
    results, completed = suite.execute(runs, out_dir / "suite_runs.jsonl", workers, args.arch, args.threads,
                                       progress=not args.no_progress, scheduler=plan["scheduler"],
                                       say=lambda text: print(text, flush=True))
    command = (f"tbd-taichi evaluate-suite --tests {tests} --snrs {','.join(f'{v:g}' for v in snrs)} "
               f"--size {args.size} --methods {','.join(chosen)} --seed {args.seed} "
               + (f"--tracker-snr {args.tracker_snr:g} " if args.tracker_snr else "")
               + "".join(f"--param {item} " for item in args.param) + f"--out-dir {out_dir}")
    report = suite.write_report(results, out_dir, command, completed, len(runs))
    print(suite.markdown_table(suite.summarise(results)))
    if args.explain:
        print(f"explained: {suite.write_explained(results, out_dir, command + ' --explain')}")
    print(f"report -> {report}" + ("" if completed else " (interrupted; finished runs kept)"))
    return 0 if completed else 130


def run_long2012_suite(args, tests: int, out_dir: Path) -> int:
    """evaluate-suite --scenario long2012: Long et al.'s Tables 2–4 and Figs. 2, 4, 5, 7 (suite_long2012)."""
    from . import suite_long2012
    from .progress import frame_progress

    out_dir.mkdir(exist_ok=True)
    runs = suite_long2012.plan(tests, args.seed)
    print(f"{len(runs)} runs (§5.3 and §5.2 x MM-PHD, SMC-PHD; §5.1 x 3 SNRs x standard, improved; {tests} each) "
          f"-> {out_dir}")
    with frame_progress("runs", len(runs), "off" if args.no_progress else "auto") as progress:
        results = suite_long2012.execute(tests, out_dir, args.seed, progress)
    command = (f"tbd-taichi evaluate-suite --methods mm-phd --scenario long2012 --tests {tests} --seed {args.seed} "
               f"--out-dir {out_dir}")
    print(f"report -> {suite_long2012.write_report(results, out_dir, command)}")
    return 0


def run_bruno2008_suite(args, tests: int, out_dir: Path) -> int:
    """evaluate-suite --scenario bruno2008: Bruno et al.'s §4 Monte Carlo table, Fig. 6 and the exit/re-entry runs
    (suite_bruno2008), both filters on the same realisations."""
    from . import suite_bruno2008
    from .progress import frame_progress

    out_dir.mkdir(exist_ok=True)
    runs = suite_bruno2008.plan(tests, args.seed)
    print(f"{len(runs)} runs (ma-apf, ma-rs x PTCR 6.5, 8.1 dB x {tests}; exit/re-entry) -> {out_dir}")
    with frame_progress("runs", len(runs), "off" if args.no_progress else "auto") as progress:
        results = suite_bruno2008.execute(tests, out_dir, args.seed, progress)
    command = (f"tbd-taichi evaluate-suite --methods ma-rs,ma-apf --scenario bruno2008 --tests {tests} "
               f"--seed {args.seed} --out-dir {out_dir}")
    print(suite_bruno2008.tables_markdown(results, command))
    print(f"report -> {suite_bruno2008.write_report(results, out_dir, command)}")
    return 0


def run_guler2016_suite(args, chosen: tuple, runs: int, out_dir: Path) -> int:
    """evaluate-suite --scenario guler2016: Güler's Tables 4.6–4.8 (all methods) and 4.9–4.11 (tophat-pf) beside
    the thesis's values (suite_guler2016)."""
    import time

    from . import suite_guler2016
    from .progress import frame_progress

    out_dir.mkdir(exist_ok=True)
    todo = suite_guler2016.plan(chosen, runs, args.compare_runs, args.seed, args.quick)
    cells = len(suite_guler2016.cells(args.quick))
    print(f"{len(todo)} runs ({','.join(chosen)} x {cells} wall/motion/Δ cell(s) x {runs} run(s)"
          + (f", {args.compare_runs} for the others" if args.compare_runs is not None else "")
          + ("; tophat-pf's N, S, C sweeps" if suite_guler2016.FLAGSHIP in chosen else "") + f") -> {out_dir}")
    command = (f"tbd-taichi evaluate-suite --methods {','.join(chosen)} --scenario guler2016 --runs {runs} "
               + (f"--compare-runs {args.compare_runs} " if args.compare_runs is not None else "")
               + ("--quick " if args.quick else "") + f"--seed {args.seed} --out-dir {out_dir}")
    started = time.perf_counter()
    with frame_progress("runs", len(todo), "off" if args.no_progress else "auto") as progress:
        results = suite_guler2016.execute(todo, out_dir, progress, meta=dict(command=command))
    seconds = time.perf_counter() - started
    report = suite_guler2016.write_report(results, out_dir, command, chosen, runs, args.compare_runs, seconds,
                                          args.seed)
    print("\n".join(suite_guler2016.overview_table(results)) if suite_guler2016.FLAGSHIP in chosen else "")
    print(f"report -> {report} ({seconds:.0f} s)")
    return 0


def suite_defaults() -> tuple:
    from .suite import DEFAULT_METHODS

    return DEFAULT_METHODS


def build_parser() -> argparse.ArgumentParser:
    parser = OneLineParser(prog="tbd-taichi", description=(
        "Track-before-detect of dim infrared point targets with Taichi particle filters. "
        "Coordinates: x = column, y = row, 0-based, pixel centres at integers; frames are 0-based."))
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    add_simulate_parser(sub, _common)

    ev = sub.add_parser("evaluate", help="score a tracks CSV against a truth CSV",
                        description="Point truth: mean EDT (Eq. 47), DSR (Eq. 48), false tracks, OSPA, Long et "
                                    "al. 2012's track detection (5 px): mean |cardinality error| per frame, P_TD, "
                                    "detection and halt frames (0-based), and Güler 2016's MSE (Eq. 4.1b, px²) and "
                                    "max error (px) of the track matched to each target (the one with the most rows "
                                    "within 5 px of it), over the frames where both have a row. "
                                    "Box truth: detection rate, false points "
                                    "per frame, centre error and IoU; for a box tracker's tracks (with w,h) also "
                                    "the OTB measures over the frames after the first labelled one (its init box): "
                                    "mean centre location error CLE, DP@20 and DP@5 (fraction of frames with CLE "
                                    "≤ 20, 5 px), mean IoU, success-plot AUC, scored and missed frames (a miss: "
                                    "IoU 0, CLE 100 px).")
    ev.add_argument("--tracks", required=True, help="tracks CSV: frame,track_id,x,y,vx,vy,intensity,confidence "
                    "[,w,h: a box tracker's box size, x, y its centre]")
    ev.add_argument("--truth", required=True, help="truth CSV: points (frame,target_id,x,y,...) or boxes "
                    "(frame,x,y,w,h[,target_id]; x, y = the top-left corner)")
    ev.add_argument("--t0", type=number(positive, 0.0, True), default=metrics.T0, help="DSR distance threshold T0, px (default 2)")
    ev.add_argument("--ospa-c", type=number(validate.within, 1e-3, 1e6), default=metrics.OSPA_C,
                    help="OSPA cut-off c, px, in [0.001, 1e6] (default 5)")
    ev.add_argument("--ospa-p", type=number(validate.within, 1.0, 20.0), default=metrics.OSPA_P,
                    help="OSPA order p in [1, 20] (default 2)")
    ev.add_argument("--frames", type=number(whole, 1, tables.MAX_FRAME + 1), default=None,
                    help="sequence length for the OSPA and cardinality-error averages (default: last frame in "
                         "either file + 1)")
    ev.add_argument("--json", action="store_true", help="print one JSON object (point truth: keys dsr, edt_mean, "
                    "false_tracks, ospa, mse, max_error, cardinality_error, p_td, detection_frame, halt_frame; "
                    "per target also mse, max_error, matched_track; box truth: "
                    "detection_rate, false_points, first_confirmation, centre_error, iou and, for tracks with w,h, "
                    "cle, dp20, dp5, dp_curve, mean_iou, success_curve, auc, scored_frames, missed_frames)")
    ev.add_argument("--box-margin", type=number(positive, 0.0, True), default=metrics.BOX_MARGIN,
                    help="with box truth: a hit is a track point inside the box grown by this, px (default 2)")
    _common(ev)
    ev.set_defaults(func=cmd_evaluate, check=check_evaluate)

    add_track_parser(sub, _common)

    me = sub.add_parser("methods", help="list the tracking methods", description="The registered methods: name, "
                        "kind, paper and what each does.  Parameters: tbd-taichi track --method NAME --help-params.")
    _common(me)
    me.set_defaults(func=cmd_methods)

    es = sub.add_parser("evaluate-suite", help="Monte Carlo evaluation of SGDS-PF and the original PF (paper Figs. 14-15)",
                        description="Simulate SNR x size x N test sequences, run each method, and write TSR, mean EDT, "
                                    "mean DSR, false tracks and ms/frame as a markdown table, JSON and PNG figures. "
                                    "Runs are appended to OUT_DIR/suite_runs.jsonl as they finish: Ctrl-C keeps them "
                                    "and a rerun skips them.")
    es.add_argument("--scenario", choices=("jia2022", "long2012", "bruno2008", "guler2016"), default="jia2022",
                    help="jia2022: SGDS-PF's SNR x size suite (default); long2012: Long et al.'s §5 scenes for "
                         "--methods mm-phd (Tables 2-4, Figs. 2, 4, 5, 7); bruno2008: Bruno et al.'s §4 Monte "
                         "Carlo and exit/re-entry runs for --methods ma-rs,ma-apf (Fig. 6); guler2016: Güler's "
                         "2016 Tables 4.6-4.8 (max error, MSE per wall x motion x delta) for --methods of "
                         "tophat-pf,sgds,pf and, with tophat-pf, its N, S, C sweeps (Tables 4.9-4.11), beside the "
                         "thesis's values")
    es.add_argument("--tests", "--runs", dest="tests", type=number(whole, 1), default=None, metavar="N",
                    help="sequences per condition (default 100; guler2016: 20 runs per cell, the sweeps at most 10)")
    es.add_argument("--compare-runs", type=number(whole, 1), default=None, metavar="N",
                    help="guler2016: runs per cell for the methods other than tophat-pf (default: --runs)")
    es.add_argument("--quick", action="store_true", help="a small version: SNR 1.4 and 2.0, 2 tests per condition; "
                    "guler2016: S1 Motion 1 delta 30 and one value per sweep, 2 runs")
    es.add_argument("--snrs", default=None, help="comma list of SNRs (default 1.2,1.4,1.6,1.8,2.0)")
    es.add_argument("--size", choices=("all", "50", "200"), default=None,
                    help="50 (50x50, 70 frames), 200 (200x200, 150 frames) or all (default)")
    es.add_argument("--methods", default=",".join(suite_defaults()),
                    help=f"comma list of methods, of {','.join(methods.names())} (default {','.join(suite_defaults())})")
    es.add_argument("--seed", type=number(whole, 0, validate.MAX_SEED), default=0, help="test k simulates scenario seed SEED+k (default 0)")
    es.add_argument("--tracker-snr", type=number(positive), default=None,
                    help="give every tracker this snr preset (default: the condition's SNR, as in the paper)")
    es.add_argument("--workers", type=number(whole, 1), default=None,
                    help="parallel processes, here or in --scheduler local-dask (default: the core count)")
    es.add_argument("--scheduler", default=None, metavar="ADDRESS", help=SCHEDULER_HELP)
    es.add_argument("--out-dir", "--out", dest="out_dir", default=None,
                    help="where the table, JSON, figures and runs go (made if its parent exists; default "
                         "suite-results, guler2016: docs/results/guler2016)")
    es.add_argument("--explain", action="store_true",
                    help="for each missed or late SGDS-PF run, the stage that lost the target (never a candidate, no "
                         "potential target, never confirmed, confirmed then dropped, or the slowest step); writes "
                         "OUT_DIR/explain.md")
    es.add_argument("--param", action="append", default=[], metavar="KEY=VALUE",
                    help="jia2022: a parameter of every --methods tracker over its SNR preset (repeatable; e.g. "
                         "N_sump=6000 with --methods sgds), to compare a setting on the same scenes (give it an "
                         "--out-dir of its own)")
    es.add_argument("--no-progress", action="store_true", help="no progress bar")
    _common(es)
    es.set_defaults(func=cmd_evaluate_suite, check=check_evaluate_suite, fans_out=suite_fans_out)

    be = sub.add_parser("bench", help="time each stage, Taichi against NumPy",
                        description="Median milliseconds per frame for each stage of SGDSPF.update (normalise, "
                                    "saliency, searching, tracking) after a warm-up, for each engine in the same run, "
                                    "on a simulated sequence with the --snr preset; fps and peak memory.")
    be.add_argument("--method", choices=methods.names(), default="sgds",
                    help="the method whose tracker is timed (default sgds)")
    be.add_argument("--shape", type=number(whole, validate.MIN_SIDE), nargs=2, metavar=("H", "W"), default=[256, 320],
                    help="frame height and width, px (default 256 320)")
    be.add_argument("--snr", type=number(positive), default=1.4, help="SNR preset: the lowest SNR to detect (default 1.4)")
    be.add_argument("--frames", type=number(whole, 1), default=20, help="timed frames per engine (default 20)")
    be.add_argument("--engines", default="taichi,numpy", help="comma list of engines (default taichi,numpy)")
    be.add_argument("--runs", type=number(whole, 1), default=1,
                    help="runs per engine, taken in turn in alternating order so that a VM's slow spells fall on "
                         "both; medians over all runs' frames, and each run's update time and ratio (default 1)")
    be.add_argument("--paired", action="store_true",
                    help="the engines take the frames in turn within each run, frame by frame, so that even a short "
                         "slow spell of the machine slows both")
    be.add_argument("--particles", type=number(whole, 0), default=0,
                    help="also time one particle-filter step of a pool this large (stage 'particles'; default 0: off)")
    be.add_argument("--groups", type=number(whole, 1), default=1, help="filters the pool is split into (default 1)")
    be.add_argument("--no-pipeline", action="store_true",
                    help="time only normalisation and saliency (and --particles), not the whole SGDSPF.update")
    be.add_argument("--param", action="append", default=[], metavar="KEY=VALUE",
                    help="a parameter of --method over its bench settings (repeatable; e.g. n_particles=1000000)")
    be.add_argument("--json", action="store_true", help="print one JSON object as the last line")
    be.add_argument("--frontend-process", action="store_true", help=FRONTEND_PROCESS_HELP)
    _common(be)
    be.set_defaults(func=cmd_bench, check=check_bench)

    add_batch_parser(sub, _common)
    add_warmup_parser(sub, _common)
    return parser


def main(argv=None) -> int:
    """Parse, check (before the backend starts), then run one sub-command; a TBDError is one line, exit 2."""
    args = build_parser().parse_args(argv)
    try:
        check = getattr(args, "check", None)
        args.checked = check(args) if check else None
        if not getattr(args, "fans_out", lambda a: False)(args):  # else the workers start their own backend
            start_backend(args.arch, args.threads)  # (--arch may name one this machine lacks)
        return args.func(args)
    except TBDError as exc:
        print(f"tbd-taichi {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:  # a file the checks passed that the system then refused (full disk, a vanished folder)
        print(f"tbd-taichi {args.command}: error: {exc.filename or ''}: {exc.strerror or exc}", file=sys.stderr)
        return 2
