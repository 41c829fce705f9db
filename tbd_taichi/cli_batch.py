"""``tbd-taichi batch-track``: track every video, array and image folder of INPUTS into one folder, here or on a
Dask cluster, with a summary.csv; a bad input is recorded and the batch goes on (:mod:`.batch`)."""
from __future__ import annotations

import sys
import uuid
from pathlib import Path

import numpy as np

from . import batch, io, methods, validate
from .errors import TBDError
from .executor import SCHEDULER_HELP, Fanout, check_scheduler
from .profiles import PROFILES, check_real_video_needs, resolved_profile


def add_batch_parser(sub, common) -> None:
    """The ``batch-track`` sub-command and its options."""
    number, whole = validate.cli_number, validate.whole
    bt = sub.add_parser("batch-track", help="track every clip of a set of files, folders or globs",
                        description="Run `track` on each input (videos, .npy/.npz files, image folders; folders are "
                                    "searched one level; quote globs) and write OUT_DIR/<name>.csv, and with --video "
                                    "and --plot <name>.mp4 and <name>.png, each under a temporary name renamed when "
                                    "whole; OUT_DIR/summary.csv has input, frames, tracks, tracker frames/s, wall "
                                    "seconds, status and error per input. A bad input is recorded and the rest go "
                                    "on; the exit status is 1 if any failed. A rerun skips inputs whose outputs are "
                                    "all there.")
    bt.add_argument("inputs", metavar="INPUTS", nargs="+", help="files, folders or quoted globs")
    bt.add_argument("--out-dir", required=True, help="the output folder (made if its parent exists)")
    bt.add_argument("--method", choices=methods.names(), default="sgds", help="the tracking method (default sgds)")
    bt.add_argument("--param", action="append", default=[], metavar="KEY=VALUE",
                    help="a parameter of the method for every input (repeatable; track --help-params lists them)")
    bt.add_argument("--profile", choices=PROFILES, default="auto",
                    help="settings profile per input, as track's (default auto: real-video for videos, image "
                         "folders and integer arrays, paper for float arrays)")
    bt.add_argument("--seed", type=number(whole, 0, validate.MAX_SEED), default=0, help="random seed of every run (default 0)")
    bt.add_argument("--engine", choices=("taichi", "numpy"), default="taichi", help="kernel engine (default taichi)")
    bt.add_argument("--video", action="store_true", help="also write each input's overlay video, <name>.mp4")
    bt.add_argument("--plot", action="store_true", help="also write each input's track picture, <name>.png")
    bt.add_argument("--workers", type=number(whole, 1), default=1,
                    help="inputs tracked at once: processes here (one Taichi thread each when > 1) or in "
                         "--scheduler local-dask (default 1: this process, all threads)")
    bt.add_argument("--scheduler", default=None, metavar="ADDRESS", help=SCHEDULER_HELP)
    bt.add_argument("--no-progress", action="store_true", help="no progress bar")
    common(bt)
    bt.set_defaults(func=cmd_batch_track, check=check_batch_track,
                    fans_out=lambda args: bool(args.scheduler) or args.workers > 1)


def check_batch_track(args) -> list[batch.BatchItem]:
    """Every input found, the method's parameters parsed, the output folder writable and the scheduler usable,
    before any input is opened: the batch's items."""
    spec = methods.get(args.method)
    if spec.needs_init_box:
        raise TBDError(f"--method {spec.name} needs each clip's first-frame box; track those clips one by one "
                       "with track --init-box")
    given = spec.parse_assignments(args.param)
    check_scheduler(args.scheduler)
    out_dir = Path(args.out_dir).expanduser()
    if out_dir.exists() and not out_dir.is_dir():
        raise TBDError(f"--out-dir {out_dir}: is a file; give a folder")
    validate.output_path("--out-dir", out_dir / batch.SUMMARY if out_dir.is_dir() else out_dir)
    paths = batch.expand_inputs(args.inputs)
    names = batch.output_names(paths)
    if args.profile == "real-video" or (args.profile == "auto" and any(camera_input(p) for p in paths)):
        check_real_video_needs(spec, "real-video", given)
    batch.check_settings(out_dir, batch_settings(args))
    options = ["--method", args.method, "--profile", args.profile, "--seed", str(args.seed), "--engine", args.engine]
    options += [item for assignment in args.param for item in ("--param", assignment)]
    extras = tuple(extra for extra in batch.EXTRAS if getattr(args, extra))
    tag = uuid.uuid4().hex[:8]
    items = [batch.plan_item(path, name, out_dir, options, extras, tag) for path, name in zip(paths, names)]
    batch.check_outputs_apart(items, paths, out_dir)
    return items


def camera_input(path: Path) -> bool:
    """Whether ``auto`` takes the real-video profile for ``path`` (:func:`~tbd_taichi.profiles.resolved_profile`
    on its kind and, for a .npy, the dtype in its header; a .npz, or a file that cannot be read, decides when it
    is tracked)."""
    if path.is_dir() or path.suffix.lower() in io.VIDEO_SUFFIXES:
        kind, dtype = ("folder" if path.is_dir() else "video"), None
    elif path.suffix.lower() == ".npy":
        try:
            kind, dtype = "array", np.load(path, mmap_mode="r").dtype
        except (OSError, ValueError):
            return False
    else:
        return False
    return resolved_profile("auto", kind, dtype)[0] == "real-video"


def batch_settings(args) -> dict:
    """What the outputs depend on besides the input: a rerun into the same folder must match."""
    return dict(method=args.method, params=sorted(args.param), profile=args.profile, seed=args.seed,
                engine=args.engine)


def cmd_batch_track(args) -> int:
    from .progress import progress_bar

    items = args.checked
    out_dir = Path(args.out_dir).expanduser()
    out_dir.mkdir(exist_ok=True)
    batch.write_settings(out_dir, batch_settings(args))
    stale = batch.remove_stale_partials(out_dir)
    if stale:
        print(f"removed {stale} temporary file(s) that an interrupted batch left in {out_dir}")
    earlier = batch.read_summary(out_dir)
    todo = [item for item in items if not item.complete()]
    pending = {item.input for item in todo}

    def first_row(item) -> dict:  # an earlier run's row where its outputs are whole (a bare one if it has none)
        if item.input in pending:
            return batch.summary_row(item, "pending")
        row = earlier.get(item.input)
        return row if row and row.get("status") == "ok" else batch.summary_row(item, "ok")

    rows = {item.input: first_row(item) for item in items}
    failed, completed = 0, True
    with Fanout(args.workers, args.arch, args.threads, args.scheduler) as fanout:
        print(f"{len(items)} input(s), {len(items) - len(todo)} already done; {len(todo)} to track with {args.method} "
              f"on {fanout.describe()} -> {out_dir}", flush=True)
        with progress_bar("batch-track", not args.no_progress, rate_unit="inputs") as bar:
            task = bar.add_task("inputs", total=len(items), completed=len(items) - len(todo)) if bar else None
            try:
                for outcome in fanout.run(batch.track_one, todo):
                    row = outcome.value if outcome.error is None else \
                        batch.summary_row(outcome.item, "failed", outcome.error)
                    failed += row["status"] != "ok"
                    rows[outcome.item.input] = row
                    batch.write_summary(out_dir, list(rows.values()))
                    if bar is not None:
                        bar.advance(task)
            except KeyboardInterrupt:
                completed = False
    summary = batch.write_summary(out_dir, list(rows.values()))
    tracked = sum(rows[item.input]["status"] == "ok" for item in todo)
    print(f"{tracked} tracked, {failed} failed, {len(items) - len(todo)} skipped (done earlier); "
          f"summary -> {summary}" + ("" if completed else " (interrupted; finished inputs kept)"))
    for row in rows.values():
        if row["status"] == "failed":
            print(f"  failed: {row['input']}: {row['error']}", file=sys.stderr)
    return 130 if not completed else (1 if failed else 0)


__all__ = ["add_batch_parser", "check_batch_track", "cmd_batch_track"]
