"""Track and truth tables: structured NumPy arrays and their CSV files.

Coordinates everywhere: x = column, y = row, 0-based, pixel centres at integers;
``frame`` is the 0-based index into the input sequence.

* tracks: ``frame,track_id,x,y,vx,vy,intensity,confidence`` — one row per
  confirmed track per frame (a box tracker's add ``w,h``, the box size, x, y being its centre);
* truth: ``frame,target_id,x,y,vx,vy,intensity`` — one row per target per frame
  in which it is in view (the long2012 simulator's adds ``model``, an index into
  ``motion_models.MODELS``; the bruno2008 simulator's ``aspect``, the template 1..K).
"""
from __future__ import annotations

import contextlib
import csv
from pathlib import Path

import numpy as np

from .errors import InputError

TRACK_COLUMNS = ("frame", "track_id", "x", "y", "vx", "vy", "intensity", "confidence")
TRUTH_COLUMNS = ("frame", "target_id", "x", "y", "vx", "vy", "intensity")
BOX_SIZE_COLUMNS = ("w", "h")  # a box tracker's tracks carry these after TRACK_COLUMNS: box size, px
BOX_COLUMNS = ("frame", "x", "y", "w", "h")  # labelled target boxes (drone-ir): corner x = column, y = row
INTEGER_COLUMNS = ("frame", "track_id", "target_id", "model", "aspect")  # int64 in a table, written without decimals
MAX_FRAME = 10**7 - 1  # the largest frame index a table may hold (ten million frames: days of video)
MAX_ID = 2**53  # the largest |id| a table may hold (whole numbers are exact in a CSV's float up to here)


def _dtype(columns: tuple[str, ...]) -> np.dtype:
    return np.dtype([(c, np.int64 if c in INTEGER_COLUMNS else np.float64) for c in columns])


TRACK_DTYPE = _dtype(TRACK_COLUMNS)
TRUTH_DTYPE = _dtype(TRUTH_COLUMNS)


def empty_tracks() -> np.ndarray:
    """A tracks table with no rows."""
    return np.zeros(0, dtype=TRACK_DTYPE)


def make_table(rows, dtype: np.dtype) -> np.ndarray:
    """Structured array from an iterable of tuples in column order, sorted by (frame, id)."""
    table = np.array([tuple(r) for r in rows], dtype=dtype)
    return np.sort(table, order=list(dtype.names[:2]))


class CsvTableWriter:
    """Write table rows to a CSV as they come (constant memory); floats with 4 decimals.

    ``with CsvTableWriter(path, TRACK_COLUMNS) as out: out.write(rows)`` where ``rows`` are
    tuples in column order or a structured array."""

    def __init__(self, path, columns: tuple[str, ...]):
        self.columns = tuple(columns)
        self.integer = [c in INTEGER_COLUMNS for c in self.columns]
        self.handle = open(path, "w", newline="")
        self.writer = csv.writer(self.handle)
        self.writer.writerow(self.columns)
        self.n_rows = 0

    def write(self, rows) -> None:
        for row in rows:
            self.writer.writerow([int(v) if i else f"{float(v):.4f}" for v, i in zip(tuple(row), self.integer)])
            self.n_rows += 1

    def close(self) -> None:
        self.handle.close()

    def __enter__(self) -> "CsvTableWriter":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def write_csv(table: np.ndarray, path) -> None:
    """Write a tracks or truth table with its header; floats with 4 decimals."""
    with CsvTableWriter(path, table.dtype.names) as out:
        out.write(table)


@contextlib.contextmanager
def _csv_records(path):
    """(header, DictReader keyed by the stripped header) of a text CSV; a missing, binary, undecodable or
    malformed file is an InputError naming it."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: no such file")
    try:
        handle = open(path, newline="", encoding="utf-8")
        head = handle.read(4096)
    except UnicodeDecodeError:
        raise InputError(f"{path}: not a text CSV file (it holds binary data)") from None
    except OSError as exc:
        raise InputError(f"{path}: cannot be read ({exc.strerror})") from None
    with handle:
        if "\0" in head:
            raise InputError(f"{path}: not a text CSV file (it holds binary data)")
        handle.seek(0)
        reader = csv.DictReader(handle)
        try:
            reader.fieldnames = [c.strip() for c in (reader.fieldnames or [])]
            yield reader.fieldnames, reader
        except (UnicodeDecodeError, csv.Error) as exc:
            raise InputError(f"{path}: not a readable CSV file ({type(exc).__name__})") from None


def read_header(path) -> list[str]:
    """The column names of a CSV file (its first line)."""
    with _csv_records(path) as (header, _):
        return header


def read_csv(path, columns: tuple[str, ...], optional: tuple[str, ...] = ()) -> np.ndarray:
    """Read a CSV with (at least) ``columns``, in any order, and those of ``optional`` it has (0 where it has not);
    raises InputError naming the problem and the first bad line."""
    with _csv_records(path) as (header, reader):
        missing = [c for c in columns if c not in header]
        if missing:
            raise InputError(f"{path}: missing column(s) {', '.join(missing)}; expected header "
                             f"{','.join(columns + optional)}")
        present = columns + tuple(c for c in optional if c in header)
        rows = []
        for line, record in enumerate(reader, start=2):
            try:
                values = {c: float(record[c]) for c in present}
            except (TypeError, ValueError):
                raise InputError(f"{path}: line {line} has a value that is not a number") from None
            if not all(np.isfinite(v) for v in values.values()):
                raise InputError(f"{path}: line {line} has a NaN or infinite value")
            _check_whole_columns(values, path, line)
            rows.append(tuple(values.get(c, 0.0) for c in columns + optional))
    return make_table(rows, _dtype(columns + optional))


def _check_whole_columns(values: dict, path, line: int) -> None:
    """A row's frame a whole number in [0, MAX_FRAME], its ids and indices whole numbers with |v| ≤ MAX_ID, and a
    box's w and h > 0; else an InputError naming the line."""
    for column in INTEGER_COLUMNS:
        v = values.get(column)
        if v is None:
            continue
        high, low = (MAX_FRAME, 0) if column == "frame" else (MAX_ID, -MAX_ID)
        if not (float(v).is_integer() and low <= v <= high):
            raise InputError(f"{path}: line {line}: {column} {v:g} must be a whole number in [{low}, {high:g}]")
    for column in BOX_SIZE_COLUMNS:
        if column in values and values[column] <= 0:
            raise InputError(f"{path}: line {line}: box {column} {values[column]:g} must be > 0 px")


def read_tracks(path) -> np.ndarray:
    """Tracks CSV ``frame,track_id,x,y,vx,vy,intensity,confidence``, plus the box size ``w,h`` (px; x, y are then
    the box centre) when the file has both, as a box tracker's has; other columns are not read."""
    optional = BOX_SIZE_COLUMNS if set(BOX_SIZE_COLUMNS) <= set(read_header(path)) else ()
    return read_csv(path, TRACK_COLUMNS, optional)


def read_truth(path) -> np.ndarray:
    """Point truth CSV ``frame,target_id,x,y[,vx,vy,intensity][,model][,aspect]`` (a missing vx, vy or intensity
    reads as 0; ``model``, the long2012 simulator's motion-model index, and ``aspect``, the bruno2008 simulator's
    template 1..K, are columns of the table only when the file has them)."""
    header = read_header(path)
    optional = TRUTH_COLUMNS[4:] + tuple(c for c in ("model", "aspect") if c in header)
    return read_csv(path, TRUTH_COLUMNS[:4], optional)


def read_boxes(path) -> np.ndarray:
    """A target-box CSV (frame,x,y,w,h[,target_id,…]): one labelled box per row, corner and size in px."""
    return read_csv(path, BOX_COLUMNS, ("target_id",))


def read_any_truth(path) -> tuple[str, np.ndarray]:
    """("points", :func:`read_truth`) or ("boxes", :func:`read_boxes`), by the file's header: boxes have w and h."""
    header = set(read_header(path))
    if {"w", "h"} <= header:
        return "boxes", read_boxes(path)
    if not {"frame", "x", "y"} <= header:
        raise InputError(f"{path}: truth needs the columns frame,target_id,x,y (points) or frame,x,y,w,h (boxes); "
                         f"it has {','.join(sorted(header)) or 'no header'}")
    return "points", read_truth(path)


def in_image(x, y, shape, margin: float = 0.0):
    """Whether (x, y) lies at least ``margin`` px inside frames of ``shape`` (H, W): pixel centres at integers, so
    the image spans [−0.5, W − 0.5) × [−0.5, H − 0.5) (x = column, y = row).  Scalars or arrays."""
    h, w = shape
    return (x >= margin - 0.5) & (x < w - 0.5 - margin) & (y >= margin - 0.5) & (y < h - 0.5 - margin)


def rows_inside(kind: str, table: np.ndarray, shape) -> int:
    """How many rows of a truth ``table`` (``kind`` "points" or "boxes", as :func:`read_any_truth` gives) lie in
    frames of ``shape`` (H, W): a point within the pixels' extent [−0.5, W − 0.5) × [−0.5, H − 0.5), a box
    (corner x, y, size w, h) overlapping it."""
    h, w = shape
    if kind == "boxes":
        inside = (table["x"] + table["w"] > -0.5) & (table["x"] < w - 0.5) & \
            (table["y"] + table["h"] > -0.5) & (table["y"] < h - 0.5)
    else:
        inside = in_image(table["x"], table["y"], shape)
    return int(np.count_nonzero(inside))
