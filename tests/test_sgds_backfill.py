"""SGDS-PF's backfill (methods/sgds/backfill.py, not in the paper): a reported track's whole path begins up to
backfill_frames frames before its first, on the line through its first points."""
from dataclasses import replace

import numpy as np
import pytest

import tbd_taichi as tbd
from tbd_taichi.methods.sgds import SGDSPF
from tbd_taichi.methods.sgds.backfill import FIT_POINTS, MIN_POINTS, backfilled, backfilled_paths
from tbd_taichi.methods.sgds.params import SGDSParams


def line_path(first: int, n: int, x0=10.0, y0=30.0, vx=0.5, vy=-0.25, wobble=0.0, seed=0):
    """Rows (frame, x, y, vx, vy, intensity, confidence) on a constant-velocity line from frame ``first``, the
    points after the first FIT_POINTS moved by up to ``wobble`` px."""
    rng = np.random.default_rng(seed)
    rows = []
    for k in range(n):
        off = rng.uniform(-wobble, wobble, 2) if k >= FIT_POINTS else (0.0, 0.0)
        rows.append((first + k, x0 + k * vx + off[0], y0 + k * vy + off[1], 9.0, 9.0, 2.5, 0.8))
    return rows


def test_backfilled_rows_lie_on_the_line_through_the_first_points():
    rows = backfilled(line_path(20, 30, wobble=3.0), 8, (64, 64))
    assert [r[0] for r in rows] == list(range(12, 20))
    for f, x, y, vx, vy, inten, conf in rows:
        assert x == pytest.approx(10.0 + 0.5 * (f - 20), abs=1e-9) and y == pytest.approx(30.0 - 0.25 * (f - 20))
        assert (vx, vy, inten, conf) == (pytest.approx(0.5), pytest.approx(-0.25), 2.5, 0.8)


def test_backfill_stops_at_frame_0_and_at_the_image_border():
    assert [r[0] for r in backfilled(line_path(3, 12), 8, (64, 64))] == [0, 1, 2]
    leaving = backfilled(line_path(30, 12, x0=1.2, vx=0.5), 8, (64, 64))  # x = 1.2 + 0.5 (f − 30)
    assert [r[0] for r in leaving] == [27, 28, 29] and min(r[1] for r in leaving) >= -0.5
    assert backfilled(line_path(30, 12), 8, (30, 64)) == []  # y = 30 + 0.25 j: below the last row
    assert backfilled(line_path(30, 12), 0, (64, 64)) == [] and backfilled([], 8, (64, 64)) == []


def test_short_paths_are_not_backfilled_and_gaps_in_the_first_frames_are_fitted():
    """A path of fewer than MIN_POINTS points has no reliable line; frames missing among the first points (a
    track's frames without an estimate) still give the line of the frames it has."""
    assert backfilled(line_path(20, MIN_POINTS - 1), 8, (64, 64)) == []
    assert len(backfilled(line_path(20, MIN_POINTS), 8, (64, 64))) == 8
    gappy = [row for row in line_path(20, 30) if row[0] % 3]  # frames 20, 21, 23, 24, 26, …
    rows = backfilled(gappy, 4, (64, 64))
    assert [r[0] for r in rows] == [16, 17, 18, 19]  # from the path's first frame, 20
    assert rows[0][1] == pytest.approx(10.0 + 0.5 * (16 - 20)) and rows[0][3] == pytest.approx(0.5)


def test_the_image_bounds_are_those_of_the_pixel_centres():
    """−0.5 ≤ x < W − 0.5 (and likewise y), as the tracker's own lost test: 1e-6 px either side of each edge."""
    def frames_kept(x0, vx, width=10):  # the line x = x0 + vx (f − 10), y = 5; 3 frames backfilled
        return [r[0] for r in backfilled(line_path(10, 20, x0=x0, vx=vx, y0=5.0, vy=0.0), 3, (10, width))]

    assert frames_kept(1.5 + 1e-6, 1.0) == [8, 9]  # x(8) = −0.5 + 1e-6: inside
    assert frames_kept(1.5 - 1e-6, 1.0) == [9]  # x(8) = −0.5 − 1e-6: outside
    assert frames_kept(7.5 - 1e-6, -1.0) == [8, 9]  # x(8) = 9.5 − 1e-6 < W − 0.5
    assert frames_kept(7.5, -1.0) == [9]  # x(8) = 9.5 = W − 0.5: outside


def test_backfilled_rows_give_way_to_another_tracks_rows():
    """One target, one track: a backfilled row within DUPLICATE_RADIUS (2 px) of another track's row in the same
    frame is dropped (a target re-found by a new track after the old one lost it)."""
    new = line_path(30, 20)  # x = 10 + 0.5 (f − 30), y = 30 − 0.25 (f − 30) from frame 30
    old = [(f, 10.0 + 0.5 * (f - 30) + 1.0, 30.0 - 0.25 * (f - 30), 0.5, -0.25, 2.0, 0.5) for f in range(15, 26)]
    far = [(f, 40.0, 5.0, 0.0, 0.0, 2.0, 0.5) for f in range(0, 40)]
    before = backfilled_paths({1: old, 2: new, 3: far}, 8, (64, 64))
    assert [r[0] for r in before[2]] == [26, 27, 28, 29]  # 22–25 lie 1 px from track 1's rows
    assert before[1] == backfilled(old, 8, (64, 64)) and before[3] == []  # track 3 starts at frame 0


def test_backfill_is_on_in_every_preset_and_off_under_the_real_video_gate():
    assert [SGDSParams.for_snr(s).backfill_frames for s in (1.2, 1.4, 1.6, 2.0, 5.0)] == [8] * 5
    assert SGDSParams.for_snr(2.0, backfill_frames=4).backfill_frames == 4
    real = tbd.make_tracker("sgds", (32, 32), profile="real-video").tracker
    assert real.p.min_peak_z > 0  # the gate: whole_paths adds no rows (test_no_backfill_under_the_peak_gate)


def test_backfilled_whole_paths_add_rows_on_the_target_before_each_track():
    """50×50, SNR 1.4, seeds 0–3 (test_sgds's runs): the same tracks with and without the backfill (it only
    prepends rows to the whole paths), and the backfilled rows near the truth: measured 28 of 28 within T0 = 2 px
    (with a line through the first 10 points instead of 20: 11 of the 16 of seeds 0–1, the first points being
    the tracking PF's converging ones)."""
    near, extra = 0, 0
    for seed in range(4):
        scene = tbd.simulate((50, 50), 70, snr=1.4, seed=seed)
        tracker = SGDSPF((50, 50), snr=1.4, seed=seed)
        for frame in scene.frames:
            tracker.update(frame)
        with_backfill = tracker.finish()
        tracker.p = replace(tracker.p, backfill_frames=0)
        without = tracker.whole_paths()
        keys = set(map(tuple, without[["frame", "track_id"]].tolist()))
        added = [r for r in with_backfill.tolist() if (r[0], r[1]) not in keys]
        assert len(with_backfill) == len(without) + len(added)
        first = {t: without["frame"][without["track_id"] == t].min() for t in np.unique(without["track_id"])}
        assert all(first[r[1]] - 8 <= r[0] < first[r[1]] for r in added)
        truth = {int(r["frame"]): (r["x"], r["y"]) for r in scene.truth}
        near += sum(np.hypot(r[2] - truth[r[0]][0], r[3] - truth[r[0]][1]) < tbd.metrics.T0 for r in added)
        extra += len(added)
    assert extra >= 16 and near >= 0.9 * extra, (near, extra)


def test_no_backfill_under_the_peak_gate():
    """With min_peak_z > 0 the whole path runs over the reported frames only: the gate judged the frames before
    them too faint, so nothing is backfilled there; without the gate the same track starts 8 frames earlier."""
    from collections import deque

    from tbd_taichi.methods.sgds.confirmation import Track

    tracker = SGDSPF((40, 40), min_peak_z=16.0)
    path = deque((f, 5.0 + 0.5 * f, 20.0, 0.5, 0.0, 3.0, 1.0) for f in range(10, 30))
    tracker.active.append(Track(2, 1, confirmed=True, whole=True, reported_span=(20, 29), path=path))
    assert tracker.whole_paths()["frame"].tolist() == list(range(20, 30))
    tracker.p = replace(tracker.p, min_peak_z=0.0)
    rows = tracker.whole_paths()
    assert rows["frame"].tolist() == list(range(2, 30)) and rows["x"][0] == pytest.approx(6.0)


@pytest.mark.parametrize("value", [-1, 51, 2.5])
def test_a_bad_backfill_length_is_refused_before_tracking(value):
    from tbd_taichi.errors import ParameterError

    with pytest.raises(ParameterError, match="backfill_frames"):
        SGDSParams.for_snr(1.2, backfill_frames=value)
