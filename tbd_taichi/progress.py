"""One rich progress bar for long loops (frames of a sequence, runs of the evaluation suite)."""
from __future__ import annotations

import contextlib


def progress_bar(label: str, enabled: bool, transient: bool = False):
    """A ``rich.progress.Progress`` context with ``label``, a bar, done/total and time left;
    a no-op context yielding None when disabled."""
    if not enabled:
        return contextlib.nullcontext(None)
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

    return Progress(TextColumn(label), BarColumn(), MofNCompleteColumn(), TimeRemainingColumn(), transient=transient)
