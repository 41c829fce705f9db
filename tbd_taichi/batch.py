"""``batch-track``'s work: the inputs found from files, folders and globs, one ``track`` run per input (any
worker, :mod:`.executor`), each output written under a temporary name and renamed when whole, and
``summary.csv``: one row per input with its frames, tracks, tracker frames/s, wall seconds, status and error.

An input counts as done when every output asked of it exists (the tracks CSV is renamed last), so a rerun
skips it and keeps its earlier summary row; a failed input leaves no output and is run again.
"""
from __future__ import annotations

import csv
import glob
import os
import time
from dataclasses import dataclass
from pathlib import Path

from . import io
from .errors import TBDError

SUMMARY = "summary.csv"
SUMMARY_COLUMNS = ("input", "name", "frames", "tracks", "tracker_fps", "wall_s", "status", "error")
EXTRAS = {"video": ".mp4", "plot": ".png"}  # optional outputs beside each tracks CSV
SEQUENCE_SUFFIXES = io.VIDEO_SUFFIXES + io.ARRAY_SUFFIXES


def is_image_folder(path: Path) -> bool:
    return path.is_dir() and any(p.suffix.lower() in io.IMAGE_SUFFIXES for p in path.iterdir() if p.is_file())


def folder_inputs(folder: Path) -> list[Path]:
    """A folder given as an input: itself if it holds images, else its videos and arrays and its image
    subfolders (one level), naturally sorted."""
    if is_image_folder(folder):
        return [folder]
    found = [p for p in folder.iterdir()
             if (p.is_file() and p.suffix.lower() in SEQUENCE_SUFFIXES) or is_image_folder(p)]
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
                                               key=io.natural_key)]
            matches = [m for m in matches if (m.is_file() and m.suffix.lower() in SEQUENCE_SUFFIXES)
                       or is_image_folder(m)]
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
    unique: dict[Path, None] = {}
    for path in found:
        unique.setdefault(path.resolve(), None)
    return list(unique)


def output_names(paths: list[Path]) -> list[str]:
    """Each input's output name: its file stem (a folder's name); where two share one, their paths below the
    inputs' common folder, with ``__`` for ``/``."""
    stems = [p.stem if p.is_file() else p.name for p in paths]
    if len(set(stems)) == len(stems):
        names = stems
    else:
        root = Path(os.path.commonpath([str(p.parent) for p in paths]))
        names = [str(p.relative_to(root).with_suffix("") if p.is_file() else p.relative_to(root)).replace(os.sep, "__")
                 for p in paths]
    if Path(SUMMARY).stem in names:
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


def plan_item(path: Path, name: str, out_dir: Path, track_options: list[str], extras: tuple[str, ...]) -> BatchItem:
    """The ``track`` run of one input, its outputs under temporary names in ``out_dir``."""
    outputs, argv = [], ["track", str(path), "--progress", "off", *track_options]
    for extra in extras:
        final = out_dir / f"{name}{EXTRAS[extra]}"
        temporary = out_dir / f".{name}.partial{EXTRAS[extra]}"
        argv += [f"--{extra}", str(temporary)]
        outputs.append((str(temporary), str(final)))
    final = out_dir / f"{name}.csv"
    temporary = out_dir / f".{name}.partial.csv"
    argv += ["--out", str(temporary)]
    outputs.append((str(temporary), str(final)))
    return BatchItem(str(path), name, tuple(argv), tuple(outputs))


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


def failed_row(item: BatchItem, error: str) -> dict:
    return dict(input=item.input, name=item.name, frames="", tracks="", tracker_fps="", wall_s="", status="failed",
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
    path, temporary = out_dir / SUMMARY, out_dir / f".{SUMMARY}.partial"
    with open(temporary, "w", newline="") as handle:
        writer = csv.DictWriter(handle, SUMMARY_COLUMNS, extrasaction="ignore")
        writer.writeheader()
        writer.writerows(rows)
    os.replace(temporary, path)
    return path


__all__ = ["BatchItem", "SUMMARY", "expand_inputs", "failed_row", "output_names", "plan_item", "read_summary",
           "track_one", "write_summary"]
