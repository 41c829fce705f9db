"""The whole paths' persistence test for still tracks (real video; not in any of the papers).

Under the real-video profile a point tracker's confirmed track is reported while its running peak z passes the
gate (:mod:`tbd_taichi.peak_guard`).  In real still-camera video the tracks that pass it and are false are still,
unlabelled hot spots that appear and go within a few tens of frames, while still targets (distant aircraft,
hovering helicopters) stay for hundreds (docs/results/drone_ir.md).  So the whole paths (the default output,
written at the end) take a reported track that has not moved more than ``still_radius`` px from where it was
first reported only once it has been reported in ``still_frames`` frames; a track that moves farther, or that
began within ``still_radius`` of where a track of the whole paths ended (the target found again), at once.
Online rows are not held back: they cannot know yet whether a still spot stays."""
from __future__ import annotations

import math

from .registry import param

# the real-video profiles' still_frames (SGDS-PF, MM-PHD): five times the running peak z's settling time; the false
# tracks on the drone-ir clips were reported in 4-37 frames, the still targets in 60-290
REAL_VIDEO_STILL_FRAMES = 50


def still_frames_param():
    """The ``still_frames`` parameter field (0: off, the paper profile)."""
    return param(0, doc="whole paths: a track that stays within still_radius of where it was first reported joins "
                 "them once reported in this many frames (0: at once)", unit="frames", source="not in the paper",
                 low=0)


def still_radius_param():
    """The ``still_radius`` parameter field."""
    return param(3.0, doc="whole paths: a track that moves farther from where it was first reported, or begins this "
                 "near where one of them ended, joins them at once", unit="px", source="not in the paper", low=0)


def joins_whole_paths(first_xy, xy, reported_frames: int, still_frames: int, still_radius: float, ends) -> bool:
    """Whether a reported track, first reported at ``first_xy`` and now at ``xy`` (x = column, y = row, px) after
    ``reported_frames`` reported frames, joins the whole paths: always with ``still_frames`` 0; else once it has been
    reported in still_frames frames, has moved more than ``still_radius`` px, or began within still_radius of one
    of ``ends`` (where tracks of the whole paths ended)."""
    if still_frames <= 0 or reported_frames >= still_frames:
        return True
    x0, y0 = first_xy
    return math.hypot(xy[0] - x0, xy[1] - y0) > still_radius or any(
        math.hypot(x0 - ex, y0 - ey) <= still_radius for ex, ey in ends)


class StillTrackRule:
    """:func:`joins_whole_paths` for one tracker's tracks, which carry ``reported_frames``, ``first_reported_at``
    and ``whole``; it keeps where the tracks of the whole paths ended."""

    def __init__(self, still_frames: int, still_radius: float):
        self.still_frames, self.still_radius = int(still_frames), float(still_radius)
        self.ends: list[tuple[float, float]] = []  # (x, y) where each track of the whole paths ended

    def reported(self, track, xy) -> None:
        """``track`` is reported at ``xy`` (its ``reported_frames`` counting this frame): it joins the whole paths
        if it has not yet and the rule says so now."""
        track.first_reported_at = track.first_reported_at or xy
        track.whole = track.whole or joins_whole_paths(track.first_reported_at, xy, track.reported_frames,
                                                       self.still_frames, self.still_radius, self.ends)

    def ended(self, track, xy) -> None:
        """``track`` ended (or halted) at ``xy``."""
        if track.whole:
            self.ends.append(xy)
