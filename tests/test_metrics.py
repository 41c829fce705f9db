"""Metrics on hand-computed cases; OSPA against brute force."""
import math

import numpy as np
import pytest

from tbd_taichi import metrics
from tbd_taichi.tables import TRACK_DTYPE, TRUTH_DTYPE, make_table


def truth_line(n=10, target=0, x0=10.0, y0=20.0):
    return make_table([(f, target, x0 + f, y0, 1.0, 0.0, 5.0) for f in range(n)], TRUTH_DTYPE)


def tracks_from(points):
    """points: (frame, track_id, x, y)."""
    return make_table([(f, k, x, y, 0, 0, 0, 1) for f, k, x, y in points], TRACK_DTYPE)


def test_edt_eq47():
    assert metrics.edt(3.0, 4.0, 0.0, 0.0) == pytest.approx(5.0)


def test_dsr_hand_case():
    truth = truth_line(10)
    # frames 0-5 within 1 px, frame 6 at exactly 2 px (not < T0), frames 7-9 missing
    pts = [(f, 1, 10.0 + f, 21.0) for f in range(6)] + [(6, 1, 16.0, 22.0)]
    tracks = tracks_from(pts)
    assert metrics.dsr(tracks, truth) == pytest.approx(0.6)
    s = metrics.evaluate(tracks, truth)
    assert s["edt_mean"] == pytest.approx((6 * 1 + 2) / 7)
    assert s["false_tracks"] == 1 - 1  # 6 of 7 points match


def test_nearest_track_is_scored():
    truth = truth_line(4)
    pts = [(f, 1, 10.0 + f, 20.5) for f in range(4)] + [(f, 2, 0.0, 0.0) for f in range(4)]
    tracks = tracks_from(pts)
    s = metrics.evaluate(tracks, truth)
    assert s["dsr"] == 1.0 and s["edt_mean"] == pytest.approx(0.5)
    assert s["false_tracks"] == 1 and s["tracks"] == 2


def test_false_track_majority_rule():
    truth = truth_line(4)
    half = tracks_from([(0, 3, 10.0, 20.0), (1, 3, 11.0, 20.0), (2, 3, 50, 50), (3, 3, 50, 50)])
    mostly_off = tracks_from([(0, 4, 10.0, 20.0), (1, 4, 50, 50), (2, 4, 50, 50)])
    assert metrics.false_tracks(half, truth) == 0
    assert metrics.false_tracks(mostly_off, truth) == 1
    assert metrics.false_tracks(tracks_from([(9, 5, 1.0, 1.0)]), truth) == 1  # frame with no target


def test_tsr_eq49_strict():
    assert metrics.tsr([0.2, 0.21, 0.9, 0.0]) == pytest.approx(0.5)


def test_multiple_targets_average_dsr():
    truth = np.concatenate([truth_line(10, 0), truth_line(10, 1, x0=100.0)])
    tracks = tracks_from([(f, 1, 10.0 + f, 20.0) for f in range(10)])
    s = metrics.evaluate(tracks, truth)
    assert s["targets"]["0"]["dsr"] == 1.0 and s["targets"]["1"]["dsr"] == 0.0
    assert s["dsr"] == 0.5


def test_ospa_hand_cases():
    assert metrics.ospa([], []) == 0.0
    assert metrics.ospa([[0, 0]], []) == 5.0
    assert metrics.ospa([[0, 0]], [[3, 4]], c=10, p=1) == pytest.approx(5.0)
    # one matched at distance 1, one unmatched (cut-off c=5): ((1 + 25)/2)^(1/2)
    assert metrics.ospa([[0, 0]], [[1, 0], [40, 40]], c=5, p=2) == pytest.approx(math.sqrt(13))


@pytest.mark.parametrize("p", [1.0, 2.0])
def test_ospa_against_brute_force(rng, p):
    for _ in range(60):
        a = rng.uniform(0, 12, size=(rng.integers(0, 5), 2))
        b = rng.uniform(0, 12, size=(rng.integers(0, 5), 2))
        assert metrics.ospa(a, b, 4.0, p) == pytest.approx(metrics.ospa_brute_force(a, b, 4.0, p), rel=1e-12, abs=1e-12)


def test_mean_ospa_counts_empty_frames():
    truth = truth_line(2)
    tracks = tracks_from([(0, 1, 10.0, 20.0), (1, 1, 11.0, 20.0)])
    assert metrics.mean_ospa(tracks, truth, n_frames=4) == 0.0
    assert metrics.mean_ospa(tracks_from([(0, 1, 10.0, 20.0)]), truth, c=5) == pytest.approx(2.5)


def test_thesis_errors_by_hand():
    """Güler's Eq. 4.1b on a 4-frame line: the matched track is the one with the most rows within 5 px (track 2,
    3 rows; track 1 has 2), scored over the frames where both have a row, its far frame included."""
    truth = truth_line(4)  # (10, 20), (11, 20), (12, 20), (13, 20)
    tracks = tracks_from([(0, 1, 10.0, 20.0), (1, 1, 11.0, 20.0),
                          (1, 2, 11.0, 21.0), (2, 2, 12.0, 22.0), (3, 2, 16.0, 24.0), (7, 2, 0.0, 0.0),
                          (0, 3, 60.0, 60.0)])
    e = metrics.thesis_errors(tracks, truth)
    assert e["track_id"] == 2 and e["frames"] == 3  # frame 7 has no truth
    assert e["mse"] == pytest.approx((1 + 4 + 25) / 3) and e["max_error"] == pytest.approx(5.0)
    s = metrics.evaluate(tracks, truth)
    assert s["mse"] == pytest.approx(10.0) and s["max_error"] == pytest.approx(5.0)
    assert s["targets"]["0"]["matched_track"] == 2


def test_thesis_errors_without_a_match():
    truth = truth_line(3)
    e = metrics.thesis_errors(tracks_from([(0, 1, 10.0, 26.0), (1, 1, 50.0, 20.0)]), truth)
    assert e["track_id"] is None and e["frames"] == 0 and math.isnan(e["mse"]) and math.isnan(e["max_error"])
    s = metrics.evaluate(tracks_from([(0, 1, 10.0, 26.0)]), truth)
    assert math.isnan(s["mse"]) and math.isnan(s["max_error"])
    tie = tracks_from([(0, 4, 10.0, 21.0), (1, 3, 11.0, 22.0)])  # one row each within 5 px: the lower id
    assert metrics.thesis_errors(tie, truth)["track_id"] == 3
