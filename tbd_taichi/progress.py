"""One rich progress bar for long loops (frames of a sequence, runs of the evaluation suite)."""
from __future__ import annotations

import contextlib


def progress_bar(label: str, enabled: bool, transient: bool = False, rate_unit: str | None = None):
    """A ``rich.progress.Progress`` context with ``label``, a bar, done/total, the rate in ``rate_unit`` per
    minute (if given) and time left; a no-op context yielding None when disabled."""
    if not enabled:
        return contextlib.nullcontext(None)
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

    rate = [_per_minute_column(rate_unit)] if rate_unit else []
    return Progress(TextColumn(label), BarColumn(), MofNCompleteColumn(), *rate, TimeRemainingColumn(),
                    transient=transient)


def _per_minute_column(unit: str):
    """A rich column showing the task's speed as ``unit``/min (blank until rich has measured one)."""
    from rich.progress import ProgressColumn
    from rich.text import Text

    class PerMinute(ProgressColumn):
        def render(self, task) -> Text:
            speed = task.finished_speed or task.speed
            return Text("" if speed is None else f"{speed * 60:.1f} {unit}/min")

    return PerMinute()


PLAIN_EVERY = 5.0  # s between plain progress lines


class PlainProgress:
    """Progress for a log file: one line on ``stream`` every :data:`PLAIN_EVERY` seconds (done/total, the rate
    over the last interval, time left at that rate), nothing for a run shorter than that."""

    def __init__(self, label: str, total: int | None, stream=None, every: float = PLAIN_EVERY):
        import sys
        import time

        self.label, self.total, self.every = label, total, every
        self.stream = stream if stream is not None else sys.stderr
        self._clock = time.monotonic
        self.started = self.last = self._clock()
        self.done = self._last_done = 0

    def advance(self, n: int = 1) -> None:
        self.done += n
        now = self._clock()
        if now - self.last < self.every:
            return
        rate = (self.done - self._last_done) / max(now - self.last, 1e-9)  # over the last interval: start-up excluded
        self.last, self._last_done = now, self.done
        of = f"/{self.total}" if self.total else ""
        left = f", {(self.total - self.done) / rate:.0f} s left" if self.total and rate > 0 else ""
        print(f"{self.label}: {self.done}{of} frames, {rate:.1f} frames/s{left}", file=self.stream, flush=True)


@contextlib.contextmanager
def frame_progress(label: str, total: int | None, mode: str = "auto"):
    """Progress over ``total`` frames as an object with ``advance()``: ``bar`` a rich bar, ``lines`` plain lines
    (:class:`PlainProgress`), ``off`` nothing, ``auto`` a bar when stderr is a terminal and lines otherwise."""
    import sys

    if mode == "auto":
        mode = "bar" if sys.stderr.isatty() else "lines"
    if mode == "off":
        yield PlainProgress(label, total, every=float("inf"))
    elif mode == "lines":
        yield PlainProgress(label, total)
    else:
        with progress_bar(label, True, transient=True) as bar:
            task = bar.add_task("frames", total=total)
            yield _BarAdvance(bar, task)


class _BarAdvance:
    def __init__(self, bar, task):
        self.bar, self.task = bar, task

    def advance(self, n: int = 1) -> None:
        self.bar.advance(self.task, n)
