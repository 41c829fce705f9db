"""``batch-track``'s work: the inputs found from files, folders and globs, one ``track`` run per input (any
worker, :mod:`.executor`), each output written under a temporary name and renamed when whole, and
``summary.csv``: one row per input with its frames, tracks, tracker frames/s, wall seconds, status and error.

An input counts as done when every output asked of it exists (the tracks CSV is renamed last), so a rerun
skips it and keeps its earlier summary row; a failed input leaves no output and is run again.
"""
from __future__ import annotations

import csv
import glob
import json
import os
import time
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

from . import io
from .errors import TBDError
from .validate import apart_from_inputs

SUMMARY = "summary.csv"
SETTINGS = "batch_settings.json"  # the settings the outputs in the folder were made with
PARTIAL = ".partial"  # in a temporary output's name
SUMMARY_COLUMNS = ("input", "name", "frames", "tracks", "tracker_fps", "wall_s", "status", "error")
EXTRAS = {"video": ".mp4", "plot": ".png"}  # optional outputs beside each tracks CSV
SEQUENCE_SUFFIXES = io.VIDEO_SUFFIXES + io.ARRAY_SUFFIXES


def is_image_folder(path: Path) -> bool:
    return path.is_dir() and any(p.suffix.lower() in io.IMAGE_SUFFIXES for p in path.iterdir() if p.is_file())


def is_sequence(path: Path) -> bool:
    """A video, a .npy/.npz file or a folder of images."""
    return (path.is_file() and path.suffix.lower() in SEQUENCE_SUFFIXES) or is_image_folder(path)


def folder_inputs(folder: Path) -> list[Path]:
    """A folder given as an input: itself if it holds images, else its videos and arrays and its image
    subfolders (one level), naturally sorted."""
    if is_image_folder(folder):
        return [folder]
    found = [p for p in folder.iterdir() if is_sequence(p)]
    if not found:
        raise TBDError(f"INPUTS: folder {folder} holds no videos, .npy/.npz files or image folders")
    return sorted(found, key=lambda p: io.natural_key(p.name))


def expand_inputs(patterns) -> list[Path]:
    """Files, folders and globs as a list of sequences (resolved, each once, in the order given).  A path that
    does not exist, a glob that matches no sequence, or a named file of another kind is an error now."""
    found: list[Path] = []
    for text in patterns:
        if glob.has_magic(text):
            matches = [Path(m) for m in sorted(glob.glob(os.path.expanduser(text), recursive=True),
                                               key=io.natural_key) if is_sequence(Path(m))]
            if not matches:
                raise TBDError(f"INPUTS: {text!r} matches no video, .npy/.npz file or image folder")
            found += matches
            continue
        path = Path(text).expanduser()
        if path.is_dir():
            found += folder_inputs(path)
        elif path.is_file():
            if path.suffix.lower() not in SEQUENCE_SUFFIXES:
                raise TBDError(f"INPUTS: {path} is not {io.SUPPORTED}")
            found.append(path)
        else:
            raise TBDError(f"INPUTS: {path} does not exist")
    return list(dict.fromkeys(path.resolve() for path in found))


def output_names(paths: list[Path]) -> list[str]:
    """Each input's output name: its file stem (a folder's name).  Inputs whose names clash (case-folded, as on
    a case-insensitive filesystem) take their path below the inputs' common folder, with ``__`` for ``/``, and
    where that still clashes, their suffix too (``clip_npz``); the others keep theirs."""
    root = Path(os.path.commonpath([str(p.parent) for p in paths])) if paths else Path(".")

    def relative(p: Path, suffix: bool) -> str:
        rel = p.relative_to(root)
        text = str(rel if (suffix or not p.is_file()) else rel.with_suffix("")).replace(os.sep, "__")
        return text.replace(".", "_") if suffix else text

    names = [p.stem if p.is_file() else p.name for p in paths]
    for suffix in (False, True):
        folded = Counter(n.casefold() for n in names)
        names = [relative(p, suffix) if folded[n.casefold()] > 1 else n for p, n in zip(paths, names)]
    clashes = [n for n, k in Counter(n.casefold() for n in names).items() if k > 1]
    if clashes:
        raise TBDError(f"INPUTS: more than one input would write {clashes[0]}.csv; rename one")
    if Path(SUMMARY).stem.casefold() in {n.casefold() for n in names}:
        raise TBDError(f"INPUTS: an input named {Path(SUMMARY).stem!r} would overwrite the batch's {SUMMARY}; "
                       "rename it")
    return names


@dataclass(frozen=True)
class BatchItem:
    """One input: its path, output name, the ``track`` command line that writes its temporary outputs, and
    each output's (temporary, final) paths, the tracks CSV last."""

    input: str
    name: str
    argv: tuple[str, ...]
    outputs: tuple[tuple[str, str], ...]

    def complete(self) -> bool:
        return all(Path(final).is_file() for _, final in self.outputs)


def plan_item(path: Path, name: str, out_dir: Path, track_options: list[str], extras: tuple[str, ...],
              tag: str) -> BatchItem:
    """The ``track`` run of one input, its outputs under temporary names in ``out_dir`` that carry ``tag`` (one
    per batch command: a run still finishing from an interrupted batch never shares a file with a rerun)."""
    outputs, argv = [], ["track", str(path), "--progress", "off", *track_options]
    for extra, suffix in [(e, EXTRAS[e]) for e in extras] + [("out", ".csv")]:  # the tracks CSV last
        final = out_dir / f"{name}{suffix}"
        temporary = out_dir / f".{name}.{tag}{PARTIAL}{suffix}"
        argv += [f"--{extra}", str(temporary)]
        outputs.append((str(temporary), str(final)))
    return BatchItem(str(path), name, tuple(argv), tuple(outputs))


def check_outputs_apart(items: list, paths: list, out_dir: Path) -> None:
    """No item's final output is one of the inputs (a clip in ``out_dir`` with --video would be replaced by its
    own overlay: ``validate.apart_from_inputs``), and no input folder of frames is ``out_dir`` (the pictures
    would join its frames)."""
    if out_dir.resolve() in {Path(p).resolve() for p in paths}:
        raise TBDError(f"--out-dir {out_dir} is an input folder of frames; give another folder")
    apart_from_inputs([("--out-dir", final) for item in items for _, final in item.outputs],
                      [("input", p) for p in paths])


def remove_stale_partials(out_dir: Path) -> int:
    """Delete the temporary outputs that killed or terminated runs left in ``out_dir``; how many."""
    stale = [p for p in out_dir.glob(f".*{PARTIAL}.*") if p.is_file()] if out_dir.is_dir() else []
    for path in stale:
        path.unlink(missing_ok=True)
    return len(stale)


def check_settings(out_dir: Path, settings: dict) -> None:
    """The batch's settings (method, parameters, profile, seed, engine) are those of the outputs already in
    ``out_dir`` (recorded in SETTINGS), so a rerun never keeps outputs made otherwise; a TBDError if not."""
    path = out_dir / SETTINGS
    try:
        earlier = json.loads(path.read_text()) if path.is_file() else None
    except (OSError, ValueError):
        earlier = None
    if earlier is not None and earlier != settings:
        changed = sorted(k for k in set(settings) | set(earlier) if settings.get(k) != earlier.get(k))
        raise TBDError(f"--out-dir {out_dir} holds outputs made with other settings ({', '.join(changed)}: "
                       f"{', '.join(str(earlier.get(k)) for k in changed)}); give another folder or empty it")


def write_settings(out_dir: Path, settings: dict) -> None:
    (out_dir / SETTINGS).write_text(json.dumps(settings, indent=1) + "\n")


def track_one(item: BatchItem) -> dict:
    """Track one input in this worker (its backend started) and rename its outputs into place: its summary row.
    Any failure leaves no output and raises (the executor records it)."""
    from .cli import build_parser
    from .cli_track import execute_track, plan_track

    started = time.perf_counter()
    try:
        args = build_parser().parse_args(list(item.argv))
        summary = execute_track(plan_track(args), args, lambda text, err=False: None)
        for temporary, final in item.outputs:
            os.replace(temporary, final)
    finally:
        for temporary, _ in item.outputs:
            Path(temporary).unlink(missing_ok=True)
    return dict(input=item.input, name=item.name, frames=summary["frames"], tracks=summary["tracks"],
                tracker_fps=round(summary["tracker_fps"], 2), wall_s=round(time.perf_counter() - started, 2),
                status="ok", error="")


def summary_row(item: BatchItem, status: str, error: str = "") -> dict:
    """A summary row without figures: ``pending``, ``failed`` (with its error) or ``ok`` from an earlier run."""
    return dict(input=item.input, name=item.name, frames="", tracks="", tracker_fps="", wall_s="", status=status,
                error=error)


def read_summary(out_dir: Path) -> dict[str, dict]:
    """An earlier run's summary rows by input (none if there is no readable summary)."""
    path = out_dir / SUMMARY
    try:
        with open(path, newline="") as handle:
            return {row["input"]: row for row in csv.DictReader(handle) if "input" in row}
    except (OSError, UnicodeDecodeError, csv.Error):
        return {}


def write_summary(out_dir: Path, rows: list[dict]) -> Path:
    """``summary.csv``, replaced whole (a temporary file, then a rename)."""
    path, temporary = out_dir / SUMMARY, out_dir / f".{SUMMARY}{PARTIAL}"
    with open(temporary, "w", newline="") as handle:
        writer = csv.DictWriter(handle, SUMMARY_COLUMNS, extrasaction="ignore")
        writer.writeheader()
        writer.writerows(rows)
    os.replace(temporary, path)
    return path


__all__ = ["BatchItem", "SETTINGS", "SUMMARY", "check_settings", "expand_inputs", "output_names",
           "plan_item", "read_summary", "remove_stale_partials", "summary_row", "track_one", "write_settings", "write_summary"]
