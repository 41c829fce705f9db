"""SGDS-PF's per-track numbers of Algorithm 2 for all tracking PFs at once (Jia et al. 2022, Eqs. 39–43): one row
per tracking-PF group, so that a frame's confidences, confirmations and ends are array operations over the active
groups instead of a loop over the tracks (issue 41, item 2).  The Track objects (confirmation.py) keep what is
per track and changes only at events: the id, the path rows, the reporting state."""
from __future__ import annotations

import numpy as np

from ...tables import in_image
from .confirmation import (LOST_FRAMES, held_compact, icef_of_log_ratio, log_weight_ratio, update_confidence,
                           windowed_icef)


class RecentValues:
    """The last ``window`` values of each of ``n`` rows (the newest last), oldest first, and how many each row has
    had since its start (a row is full when it has ``window``).  Stored window × rows, so a row's sum over axis 0
    adds its values oldest first, in the order of Python's ``sum``."""

    def __init__(self, n: int, window: int, dtype=np.float64):
        self.window = int(window)
        self.values = np.zeros((max(self.window, 1), n), dtype)
        self.count = np.zeros(n, np.int64)

    def start(self, rows) -> None:
        self.count[rows] = 0

    def push(self, values: np.ndarray) -> None:
        """Append one value to every row, dropping its oldest."""
        self.values[:-1] = self.values[1:]
        self.values[-1] = values
        self.count += 1

    def full(self) -> np.ndarray:
        return self.count >= self.window

    def sums(self) -> np.ndarray:
        return self.values.sum(axis=0)


class TrackStates:
    """Per tracking-PF group (``n_groups``): the confidence C (Eq. 43), N_rt, the confirmed flag, frames without
    an E = 1 particle, the path's last position and frame (Eq. 39), the real-video guard's running peak z, the last
    ``icef_window`` values of ln(MTW/MSW) (the ICEF window) and the last ``confirm_window`` (ln r, SCEF = 1.1)
    pairs (the long-window confirmation).  A frame's step runs over every group, a track's or not: a group's row
    is reset when a track starts in it and read only while the track is active."""

    def __init__(self, n_groups: int, icef_window: int, confirm_window: int):
        self.confidence = np.ones(n_groups)
        self.n_rt = np.zeros(n_groups, np.int64)
        self.confirmed = np.zeros(n_groups, bool)
        self.without_e = np.zeros(n_groups, np.int64)
        self.xy = np.zeros((n_groups, 2))
        self.last_frame = np.full(n_groups, -1, np.int64)
        self.peak_z = np.zeros(n_groups)
        self.ratios = RecentValues(n_groups, icef_window)
        self.held_ratios = RecentValues(n_groups, confirm_window)
        self.held_compact = RecentValues(n_groups, confirm_window, bool)

    def start(self, group: int, frame: int, x: float, y: float) -> None:
        """A new track in ``group``, its path begun at (``x``, ``y``) in ``frame`` with C = 1."""
        self.confidence[group], self.n_rt[group], self.confirmed[group], self.without_e[group] = 1.0, 0, False, 0
        self.xy[group], self.last_frame[group], self.peak_z[group] = (x, y), frame, 0.0
        for recent in (self.ratios, self.held_ratios, self.held_compact):
            recent.start(group)

    def step(self, frame: int, finite: np.ndarray, xy: np.ndarray, log_mtw: np.ndarray, log_msw: float,
             scefs: np.ndarray, rule) -> np.ndarray:
        """Algorithm 2's bookkeeping of frame ``frame`` for every group (their estimates: ``finite``, the positions
        ``xy``, ln MTW ``log_mtw`` and SCEF ``scefs``; the frame's ln MSW ``log_msw``); ``rule``: (the frame's
        (H, W), T_ft, T_rt, ICEF's scaled 0.1, the ICEF window's ratio, the long window's ln ratio).  Eq. 39 moves
        the path's end where the estimate is finite; C by Eqs. 40–43 (with the ICEF window); a track ends where
        C < T_ft, after LOST_FRAMES frames without E = 1, or out of the image; the others count N_rt and are
        confirmed by N_rt > T_rt or the long window.  Returns the ended mask."""
        (h, w), t_ft, t_rt, icef_lower, icef_ratio, confirm_log_ratio = rule
        self.without_e = np.where(finite, 0, self.without_e + 1)
        log_r = log_weight_ratio(log_mtw, log_msw)
        self.ratios.push(log_r)
        icef = windowed_icef(icef_of_log_ratio(log_r, icef_lower), self.ratios.sums(), self.ratios.full(),
                             self.ratios.window, icef_ratio)
        self.confidence = update_confidence(self.confidence, icef, scefs)
        self.xy[finite], self.last_frame[finite] = xy[finite], frame
        inside = in_image(self.xy[:, 0], self.xy[:, 1], (h, w))
        ended = (self.confidence < t_ft) | (self.without_e >= LOST_FRAMES) | ~inside
        one = (self.confidence == 1.0) & ~ended  # an ended track's row is not read again
        self.n_rt += one
        self.held_ratios.push(log_r)
        self.held_compact.push(scefs > 1.0)
        compact = self.held_compact.values.all(axis=0)
        self.confirmed |= (one & (self.n_rt > t_rt)) | held_compact(
            compact, self.held_ratios.sums(), self.held_ratios.full(), self.held_ratios.window, confirm_log_ratio)
        return ended
