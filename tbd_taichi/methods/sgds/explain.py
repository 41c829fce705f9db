"""Which SGDS-PF stage lost a target (issue 43, item 1): a recorder that watches a running tracker against
the truth, and the verdict on a missed or late run.

The recorder only reads the tracker's state after each of its steps (it wraps ``_process`` and ``_end_track``),
so the tracks are the same as without it.  Per run it notes, for the target (within T0 = 2 px of its true
position, Eq. 48's gate):

* the first frame with a **candidate**: a pixel of the saliency proposal map OPsal_N (Eq. 33), before the
  masking around active tracks, within T0;
* the first **hand-over**: a potential target (Algorithm 1: PTp > T_PTp, PE > T_PE) that started a tracking PF
  whose path comes within T0 of the target (its start frame);
* the first **confirmation** (N_rt > T_rt, Eq. 43, or the long window) of such a track;
* each **drop**: a confirmed track within T0 that ended (confidence below T_ft, lost, or merged) while the
  target was still in view.

A run is *missed* when its DSR ≤ T1 (Eq. 49's failure) and *late* when its tracks first come within T0 more
than LATE_FRAMES frames after the target's first frame.  The verdict names the first stage the target never
reached, or for a late run the slowest step: to the first candidate, from it to the first hand-over, or from
that to the first detection (a track's whole path without the backfill is reported from its hand-over, so a gap
there means the early hand-overs were never confirmed).
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np

from ... import metrics

LATE_FRAMES = 10  # a run is late when its first detection comes more than this many frames after the target's first
STAGES = ("never a candidate", "candidate, no potential target", "handed over, never confirmed",
          "confirmed, then dropped", "late candidate", "late hand-over", "late confirmation", "detected")


@dataclass
class StageFrames:
    """The first frame of each stage (None: never) and the frames confirmed tracks on the target were dropped."""

    truth_first: int | None = None
    candidate: int | None = None
    handover: int | None = None
    confirmed: int | None = None
    dropped: list = field(default_factory=list)


class StageRecorder:
    """Watches ``tracker`` (an SGDSPF with ``history``) against ``truth`` rows (frame, target_id, x, y, ...), any
    number of targets: a stage counts when it is within ``radius`` px of any target in that frame.  A track is
    on the target when a point of its path is; its hand-over is its first frame (the Eq. 38 estimate it starts
    from may still be off by more than the radius)."""

    def __init__(self, tracker, truth: np.ndarray, radius: float = metrics.T0):
        self.tracker, self.radius = tracker, float(radius)
        self.truth: dict[int, np.ndarray] = {}
        for f in np.unique(truth["frame"]):
            rows = truth[truth["frame"] == f]
            self.truth[int(f)] = np.stack([rows["x"], rows["y"]], axis=1).astype(float)
        self.candidate: int | None = None
        self.started: list = []  # (track, frame it started)
        self.confirmed_at: dict[int, int] = {}  # track id → the frame it was confirmed
        self.dropped: list[int] = []
        self._process, self._end_track = tracker._process, tracker._end_track
        tracker._process, tracker._end_track = self._watch_process, self._watch_end

    def near(self, f: int, x: float, y: float) -> bool:
        """(x, y) within the radius of a target at frame f."""
        where = self.truth.get(int(f))
        return where is not None and bool((np.hypot(where[:, 0] - x, where[:, 1] - y) < self.radius).any())

    def on_target(self, track) -> bool:
        return any(self.near(f, x, y) for f, x, y, *_ in track.path)

    @property
    def frames(self) -> StageFrames:
        """Each stage's first frame for the target, from what was watched so far."""
        on = [(t, f) for t, f in self.started if self.on_target(t)]
        confirmed = [self.confirmed_at[t.track_id] for t, _ in on if t.track_id in self.confirmed_at]
        return StageFrames(truth_first=min(self.truth) if self.truth else None, candidate=self.candidate,
                           handover=min((f for _, f in on), default=None), confirmed=min(confirmed, default=None),
                           dropped=list(self.dropped))

    def _candidate_at(self, f: int, proposal: np.ndarray) -> bool:
        """A proposal pixel within the radius of a target (the pixels in a ±radius square, then the exact gate)."""
        where = self.truth.get(f)
        if where is None:
            return False
        h, w = proposal.shape
        r = int(np.ceil(self.radius))
        for x, y in where:
            cx, cy = int(np.floor(x + 0.5)), int(np.floor(y + 0.5))
            y0, y1, x0, x1 = max(cy - r, 0), min(cy + r + 1, h), max(cx - r, 0), min(cx + r + 1, w)
            ys, xs = np.nonzero(proposal[y0:y1, x0:x1] > 0)
            if ys.size and (np.hypot(xs + x0 - x, ys + y0 - y) < self.radius).any():
                return True
        return False

    def _watch_process(self, front):
        f = front.frame
        if self.candidate is None and self._candidate_at(f, front.proposal):  # before the tracks' masking
            self.candidate = f
        first_new = self.tracker.next_track_id
        rows = self._process(front)
        for t in self.tracker.active:
            if t.track_id >= first_new:
                self.started.append((t, f))
            if t.confirmed and t.track_id not in self.confirmed_at:
                self.confirmed_at[t.track_id] = f
        return rows

    def _watch_end(self, track) -> None:
        f = track.path[-1][0]
        if track.confirmed:
            self.confirmed_at.setdefault(track.track_id, f)
            if self.near(f, *track.last_xy()) and max(self.truth, default=-1) > f:
                self.dropped.append(int(f))
        self._end_track(track)


def first_detection(tracks: np.ndarray, truth: np.ndarray, radius: float = metrics.T0) -> int | None:
    """The first frame at which a track point lies within ``radius`` of a target (None: never)."""
    d = metrics.nearest_edt(tracks, truth)
    hit = np.isfinite(d) & (d < radius)
    return int(truth["frame"][hit].min()) if hit.any() else None


def verdict(frames: StageFrames, dsr: float, detected_at: int | None) -> str:
    """One of STAGES for a run: where a missed run lost the target, or the slowest step of a late one."""
    start = frames.truth_first or 0
    if dsr > metrics.T1 and detected_at is not None and detected_at - start <= LATE_FRAMES:
        return "detected"
    for stage, reached in zip(STAGES[:3], (frames.candidate, frames.handover, frames.confirmed)):
        if reached is None:  # the first stage the target never reached
            return stage
    if dsr <= metrics.T1 and frames.dropped:
        return "confirmed, then dropped"
    # a confirmed track's whole path is reported from its hand-over, so a late first detection is a late candidate,
    # a late hand-over, or early hand-overs that were never confirmed (the detection starts at a later one's)
    detected = detected_at if detected_at is not None else frames.confirmed
    steps = {"late candidate": frames.candidate - start, "late hand-over": frames.handover - frames.candidate,
             "late confirmation": detected - frames.handover}
    return max(steps, key=steps.get)


def explained_fields(recorder: StageRecorder, truth: np.ndarray, dsr: float) -> dict:
    """The suite row's fields: the verdict (``stage``) and each stage's first frame.  The first detection is taken
    from the whole paths without the backfill (backfill.py), whose rows before the hand-over are retrodicted."""
    detected_at = first_detection(recorder.tracker.whole_paths(backfill=False), truth)
    frames = recorder.frames
    return dict(stage=verdict(frames, dsr, detected_at), detected_at=detected_at,
                **{f"{k}_at": v for k, v in asdict(frames).items() if k not in ("dropped", "truth_first")},
                drops=len(frames.dropped))


def stage_table(results: list[dict]) -> str:
    """Markdown: per size and SNR, SGDS-PF's explained runs, how many were missed (DSR ≤ T1) or late, and the
    split of those by the stage that lost the target."""
    rows = [r for r in results if r.get("stage")]
    lost = STAGES[:-1]
    lines = ["| size | SNR | runs | missed | late | " + " | ".join(lost) + " |",
             "|---|---:|---:|---:|---:|" + "---:|" * len(lost)]
    for side, frames, snr in sorted({(r["side"], r["frames"], r["snr"]) for r in rows}):
        sel = [r for r in rows if (r["side"], r["frames"], r["snr"]) == (side, frames, snr)]
        missed = sum(r["dsr"] <= metrics.T1 for r in sel)
        late = sum(r["stage"] != "detected" and r["dsr"] > metrics.T1 for r in sel)
        counts = [sum(r["stage"] == stage for r in sel) for stage in lost]
        lines.append(f"| {side}×{side}×{frames} | {snr:g} | {len(sel)} | {missed} | {late} | "
                     + " | ".join(str(c) for c in counts) + " |")
    return "\n".join(lines)


__all__ = ["LATE_FRAMES", "STAGES", "StageFrames", "StageRecorder", "explained_fields", "first_detection", "stage_table", "verdict"]
