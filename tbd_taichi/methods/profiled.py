"""The tracker :func:`~tbd_taichi.methods.make_tracker` returns: a method's tracker under a settings profile
(:mod:`tbd_taichi.profiles`), which refuses frames after ``finish``.

With ``profile="auto"`` the method's tracker is built at the first frame, with the real-video settings when that
frame is integer-typed (raw camera data) and the paper's otherwise (an attribute read before the first frame builds
it with the paper's settings; an integer first frame then rebuilds it).  Every other attribute is the method
tracker's own (``tracker.online()``, ``tracker.p`` …).
"""
from __future__ import annotations

import numpy as np

from ..profiles import resolved_profile
from .registry import OneSequence


class ProfiledTracker(OneSequence):
    """``build(profile)`` → the method's tracker; ``requested``: ``auto``, ``paper`` or ``real-video``."""

    def __init__(self, build, requested: str, method: str):
        self._build, self.requested, self.method = build, requested, method
        self._undecided = requested == "auto"
        self.profile, self.profile_reason = ("paper", "no frame seen yet") if self._undecided else \
            resolved_profile(requested, "array")
        self._built = None if self._undecided else build(self.profile)

    @property
    def _tracker(self):
        if self._built is None:
            self._built = self._build(self.profile)
        return self._built

    def update(self, frame) -> list[tuple]:
        """The method's ``update``; the first frame settles an ``auto`` profile (by its dtype)."""
        self._check_open("update")
        if self._undecided:
            self._undecided = False
            dtype = frame.dtype if isinstance(frame, np.ndarray) else np.asarray(frame).dtype
            profile, self.profile_reason = resolved_profile("auto", "array", dtype)
            if profile != self.profile and self._built is not None:
                getattr(self._built, "close", lambda: None)()
                self._built = None
            self.profile = profile
        return self._tracker.update(frame)

    def finish(self) -> np.ndarray:
        """The method's ``finish``; a second call, or an ``update`` after it, is a ParameterError."""
        self._close_sequence()
        return self._tracker.finish()

    @property
    def frames_in(self) -> int:
        return self._tracker.frames_in

    @property
    def timings(self) -> dict:
        return self._tracker.timings

    @property
    def tracker(self):
        """The method's own tracker object."""
        return self._tracker

    def __getattr__(self, name: str):
        if name.startswith("_"):
            raise AttributeError(name)
        return getattr(self._tracker, name)
