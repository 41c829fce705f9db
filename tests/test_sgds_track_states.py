"""SGDS-PF's per-track numbers for all tracks at once (track_states.py) against a track-by-track reference of
Algorithm 2's bookkeeping (Eqs. 39–43 with the ICEF and long windows), and the running peak z's array form
against scipy's maximum filter."""
import math
from collections import deque

import numpy as np
import pytest
import scipy.ndimage as ndi

from tbd_taichi.methods.sgds.track_states import TrackStates
from tbd_taichi.peak_guard import PEAK_RHO, peak_z, running_peak_z

H, W = 23, 31
RULE = ((H, W), 0.2, 6, 0.1, 0.05, math.log(0.03))  # T_ft, T_rt, ICEF's 0.1, the windows' ratios


class ReferenceTrack:
    """One track's Eqs. 40–43 written out scalar by scalar, frame by frame (the deques hold the windows)."""

    def __init__(self, x, y, icef_window, confirm_window):
        self.c, self.n_rt, self.confirmed, self.without_e, self.xy = 1.0, 0, False, 0, (x, y)
        self.ratios, self.held = deque(maxlen=icef_window), deque(maxlen=max(confirm_window, 1))
        self.icef_window, self.confirm_window = icef_window, confirm_window

    def step(self, finite, xy, log_mtw, log_msw, scef_value) -> bool:
        (h, w), t_ft, t_rt, lower, ratio, confirm_log = RULE
        self.without_e = 0 if finite else self.without_e + 1
        if not math.isfinite(log_mtw) or log_mtw <= -1e37:
            log_r = -50.0
        elif not math.isfinite(log_msw) or log_msw <= -1e37:
            log_r = 0.0
        else:
            log_r = min(max(log_mtw - log_msw, -50.0), 50.0)
        self.ratios.append(log_r)
        r = math.exp(log_r)
        icef = r if r >= 1 else (1.0 if r >= lower else 0.9)
        if icef == 0.9 and self.icef_window > 1 and len(self.ratios) == self.icef_window \
                and sum(self.ratios) / self.icef_window >= math.log(ratio):
            icef = 1.0
        v = self.c * icef * scef_value
        self.c = 1.0 if v >= 1.0 else v
        if finite:
            self.xy = xy
        x, y = self.xy
        if self.c < t_ft or self.without_e >= 3 or not (-0.5 <= x < w - 0.5 and -0.5 <= y < h - 0.5):
            return True
        if self.c == 1.0:
            self.n_rt += 1
            self.confirmed |= self.n_rt > t_rt
        self.held.append((log_r, scef_value > 1.0))
        if self.confirm_window >= 1 and len(self.held) == self.confirm_window and all(c for _, c in self.held) \
                and sum(r for r, _ in self.held) / self.confirm_window >= confirm_log:
            self.confirmed = True
        return False


@pytest.mark.parametrize("icef_window, confirm_window", [(10, 30), (1, 0), (4, 6)])
def test_track_states_equal_the_track_by_track_reference(icef_window, confirm_window):
    """24 groups over 400 frames with random ln MTW near the ICEF bounds (some −3e38 or NaN: no E = 1), SCEF 1.1
    or below, positions that sometimes leave the image, ln MSW sometimes absent; a group whose track ends starts
    a new one a few frames later.  C, N_rt, the confirmations, the ends and the last positions equal the
    reference's bit for bit; every kind of end and both confirmations occur."""
    rng = np.random.default_rng(11)
    n = 24  # the groups (tracking PFs); about a sixth are idle at a time
    states, ref, idle = TrackStates(n, icef_window, confirm_window), {}, {}
    seen = {"ended_c": 0, "ended_lost": 0, "confirmed": 0}
    for f in range(400):
        for g in [g for g in range(n) if g not in ref and idle.get(g, 0) <= f]:
            x, y = rng.uniform(0, W - 1), rng.uniform(0, H - 1)
            states.start(g, f, x, y)
            ref[g] = ReferenceTrack(x, y, icef_window, confirm_window)
        finite = rng.random(n) > 0.15
        xy = np.column_stack([rng.uniform(-0.5, W - 0.5, n), rng.uniform(-0.5, H - 0.5, n)])
        edge = rng.random(n) < 0.03  # just out of the image across one of its four edges, or on its closed ones
        xy[edge] = np.array([(W - 0.5, 5.0), (5.0, H - 0.5), (np.nextafter(-0.5, -1), 5.0), (5.0, -0.6),
                             (-0.5, 5.0), (5.0, -0.5)])[rng.integers(0, 6, edge.sum())]
        xy[~finite] = np.nan
        log_mtw = np.log(rng.uniform(0.01, 1.5, n))
        log_mtw[rng.random(n) < 0.05] = -3.0e38
        log_mtw[~finite & (rng.random(n) < 0.5)] = np.nan
        log_msw = 0.0 if rng.random() > 0.05 else -3.0e38
        scefs = np.where(rng.random(n) < 0.9, 1.1, rng.uniform(0.3, 1.0, n))
        ended = states.step(f, finite, xy, log_mtw, log_msw, scefs, RULE)
        for i in sorted(ref):  # the groups with a track; the others' rows are not read
            t = ref[i]
            assert ended[i] == t.step(bool(finite[i]), tuple(xy[i]), float(log_mtw[i]), log_msw, float(scefs[i]))
            assert (states.confidence[i], states.xy[i].tolist()) == (t.c, list(t.xy))
            if ended[i]:
                seen["ended_c" if t.c < RULE[1] else "ended_lost"] += 1
                del ref[i]
                idle[i] = f + int(rng.integers(1, 6))
                continue
            assert (states.n_rt[i], states.confirmed[i]) == (t.n_rt, t.confirmed)
            seen["confirmed"] += t.confirmed
    assert min(seen.values()) > 0, seen


def test_peak_z_arrays_equal_the_maximum_filter_and_the_cut_windows():
    """The 3×3 peak at each position: scipy's 3×3 maximum filter at the nearest pixel where that lies in the image;
    for every position the maximum over the window's slice cut at the border (NaN where it is empty), and the same
    value one position at a time; the running peak moves by PEAK_RHO towards it and stays where it is NaN."""
    rng = np.random.default_rng(4)
    z = rng.normal(size=(H, W)).astype(np.float32)
    x, y = rng.uniform(-3.0, W + 2.0, 500), rng.uniform(-3.0, H + 2.0, 500)
    got = peak_z(z, x, y)
    cx, cy = np.floor(x + 0.5).astype(int), np.floor(y + 0.5).astype(int)
    image = (0 <= cx) & (cx < W) & (0 <= cy) & (cy < H)
    filtered = ndi.maximum_filter(z, size=3, mode="nearest")
    np.testing.assert_array_equal(got[image], filtered[cy[image], cx[image]])
    cut = [z[max(b - 1, 0):max(b + 2, 0), max(a - 1, 0):max(a + 2, 0)] for a, b in zip(cx, cy)]
    want = np.array([float(c.max()) if c.size else np.nan for c in cut])
    np.testing.assert_array_equal(got, want)
    assert 0 < image.sum() < np.isfinite(want).sum() < len(x)  # inside, on the border band, outside
    np.testing.assert_array_equal(got, [peak_z(z, a, b) for a, b in zip(x.tolist(), y.tolist())])
    previous = rng.uniform(0, 3, len(x))
    moved = running_peak_z(previous, z, x, y)
    inside = np.isfinite(want)
    np.testing.assert_array_equal(moved, np.where(inside, previous + PEAK_RHO * (want - previous), previous))
    assert isinstance(running_peak_z(1.0, z, 3.0, 4.0), float)
