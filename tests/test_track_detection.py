"""Long et al. 2012's track-detection measures (tbd_taichi.track_detection) on small hand-built tables: the
cardinality error, the one-to-one association, the 5 px initialisation test, detection and halt frames, false
tracks, the Monte Carlo pooling of Tables 2–4, and what ``tbd-taichi evaluate`` reports."""
import json

import numpy as np
import pytest

from tbd_taichi import cli, tables
from tbd_taichi.track_detection import (TRACK_GATE, associate_tracks, cardinality_error, paper_frame, pool_runs,
                                        track_detection)


def tracks_table(rows):
    """Tracks from (frame, track_id, x, y) rows."""
    return tables.make_table([(f, i, x, y, 0.0, 0.0, 1.0, 1.0) for f, i, x, y in rows], tables.TRACK_DTYPE)


def truth_table(rows):
    """Point truth from (frame, target_id, x, y) rows."""
    return tables.make_table([(f, i, x, y, 0.0, 0.0, 1.0) for f, i, x, y in rows], tables.TRUTH_DTYPE)


def path(ident, frames, x0, y0, vx=1.0, vy=0.0, dx=0.0, dy=0.0):
    """(frame, ident, x, y) rows of a straight path x0 + vx·f, y0 + vy·f, shifted by (dx, dy)."""
    return [(f, ident, x0 + vx * f + dx, y0 + vy * f + dy) for f in frames]


def three_targets():
    """Targets 0 and 1 in frames 2..11, target 2 in frames 5..11, 15 px or more apart."""
    return truth_table(path(0, range(2, 12), 5, 5) + path(1, range(2, 12), 5, 25) + path(2, range(5, 12), 5, 45))


def test_cardinality_error_by_hand():
    """Per frame 0..3: truth 1, 2, 2, 0 rows; tracks 0, 2, 5, 1 rows → |diff| 1, 0, 3, 1 → 5/4; frames past
    n_frames are left out, and frames 4, 5 with no rows add 0 to the sum."""
    truth = truth_table([(0, 0, 1, 1), (1, 0, 2, 1), (1, 1, 9, 9), (2, 0, 3, 1), (2, 1, 9, 8)])
    tracks = tracks_table([(1, 1, 2, 1), (1, 2, 9, 9)] + [(2, k, k, 1) for k in range(5)]
                          + [(3, 1, 4, 1), (7, 1, 8, 1)])
    assert cardinality_error(tracks, truth, 4) == pytest.approx(5 / 4)
    assert cardinality_error(tracks, truth, 6) == pytest.approx(5 / 6)
    assert cardinality_error(tracks_table([]), truth_table([]), 3) == 0.0


def test_association_follows_two_crossing_targets():
    """Targets 0 and 1 cross at frame 10 (y = f and y = 20 − f); tracks start at frame 9, track 7 on target 0
    and track 3 on target 1, each 1.5 px off towards the other before the crossing, so that at their first frame
    each target's nearest track is the wrong one; the mean distance over the common frames picks the right
    pairs."""
    truth = truth_table(path(0, range(4, 17), 0, 0, 2, 1) + path(1, range(4, 17), 0, 20, 2, -1))
    frames = range(9, 17)
    tracks = tracks_table(path(7, frames, 0, 0, 2, 1, dy=1.5) + path(3, frames, 0, 20, 2, -1, dy=-1.5))
    assert associate_tracks(tracks, truth) == {0: 7, 1: 3}


def test_association_pairs_out_of_the_gate_are_dropped_and_do_not_displace_others():
    """Static targets 0 at (0, 0) and 1 at (4, 0); track 1 at (0, 0), track 2 at 4.8 px from target 0 and 6 px
    from target 1.  The least raw total (1→0 at 0 px + 2→1 at 6 px) would leave target 1 without a track; the
    gated assignment gives each target a track within 5 px.  A far track and a track on no common frame are
    never associated."""
    y = np.sqrt(4.8 ** 2 - 0.38 ** 2)
    frames = range(3)
    truth = truth_table([(f, 0, 0.0, 0.0) for f in frames] + [(f, 1, 4.0, 0.0) for f in frames])
    tracks = tracks_table([(f, 1, 0.0, 0.0) for f in frames] + [(f, 2, 0.38, y) for f in frames])
    assert associate_tracks(tracks, truth) == {0: 2, 1: 1}
    far = tracks_table([(f, 1, 0.0, 30.0) for f in frames] + [(9, 2, 0.0, 0.0)])  # 30 px off; no common frame
    assert associate_tracks(far, truth) == {}


@pytest.mark.parametrize("offset, detected", [(6.0, False), (4.0, True), (TRACK_GATE, True)])
def test_a_track_initialised_more_than_5_px_off_is_not_detected(offset, detected):
    """The track's first row lies ``offset`` px from the target, its later rows on it (mean distance < 5 px, so
    it is associated): detected only within 5 px.  Confirmed at frame 4, where it is on the target, it is."""
    truth = truth_table(path(0, range(10), 10, 10))
    tracks = tracks_table([(2, 5, 12.0, 10.0 + offset)] + path(5, range(3, 10), 10, 10))
    entry = track_detection(tracks, truth, 10)["targets"][0]
    assert entry["detected"] is detected and entry["detection_frame"] == 2
    assert track_detection(tracks, truth, 10, confirmed={5: 4})["targets"][0]["detected"]


def test_detection_start_and_halt_frames_by_hand():
    """Target in frames 2..15; its track in frames 3..12, confirmed at frame 5: detection 5, start 3, halt 12 + 2
    = 14 (the second consecutive drop); without confirmations detection = start = 3.  Paper frames are + 1."""
    truth = truth_table(path(0, range(2, 16), 5, 5))
    tracks = tracks_table(path(4, range(3, 13), 5, 5, dx=0.3))
    entry = track_detection(tracks, truth, 16, confirmed={4: 5})["targets"][0]
    assert entry == dict(first=2, last=15, detected=True, detection_frame=5, start_frame=3, halt_frame=14)
    assert track_detection(tracks, truth, 16)["targets"][0]["detection_frame"] == 3
    assert track_detection(tracks, truth, 16, halt_drops=3)["targets"][0]["halt_frame"] == 15
    assert paper_frame(entry["detection_frame"]) == 6 and paper_frame(np.array([0, 41])).tolist() == [1, 42]


def test_false_track_counted_and_the_number_of_targets_checked():
    """Two tracks on targets 0 and 1 and one on noise (20 px from every target): 1 false track, target 2 not
    detected, the number of targets wrong.  All three targets tracked and no noise track: the number is right.
    A second, later track of target 0 (a re-acquired fragment) is not associated but not false either."""
    truth = three_targets()
    on = path(1, range(3, 12), 5, 5, dx=0.5) + path(2, range(3, 12), 5, 25)
    noise = path(9, range(4, 10), 5, 65)
    res = track_detection(tracks_table(on + noise), truth, 12)
    assert res["false_tracks"] == 1 and res["detected"] == 2 and res["n_targets"] == 3
    assert res["p_td"] == pytest.approx(2 / 3) and not res["correct_number"]
    assert res["targets"][2]["detected"] is False and res["targets"][2]["halt_frame"] is None
    full = on + path(3, range(6, 12), 5, 45)
    res = track_detection(tracks_table(full), truth, 12)
    assert res["false_tracks"] == 0 and res["correct_number"] and res["p_td"] == 1.0
    res = track_detection(tracks_table(full + path(4, range(10, 12), 5, 5, dy=1.0)), truth, 12)
    assert res["false_tracks"] == 0 and res["unassociated_tracks"] == 1 and res["correct_number"]
    assert res["targets"][0]["start_frame"] == 3


def test_pool_runs_over_run_times_target():
    """Run A detects targets 0, 1, 2 (at frames 3, 4, 6; halts 13); run B targets 0 and 1 (at 5, 6; halts 11) and
    has a false track: P_TD = 5 / 6 = 83.33 %, 1 false track, target 2's means from run A alone."""
    truth = three_targets()
    run_a = path(1, range(3, 12), 5, 5) + path(2, range(4, 12), 5, 25) + path(3, range(6, 12), 5, 45)
    run_b = path(1, range(5, 10), 5, 5) + path(2, range(6, 10), 5, 25) + path(8, range(2, 9), 30, 60)
    results = [track_detection(tracks_table(t), truth, 12) for t in (run_a, run_b)]
    pooled = pool_runs(results)
    assert pooled["runs"] == 2 and pooled["n_targets"] == 6 and pooled["detected"] == 5
    assert pooled["p_td"] == pytest.approx(500 / 6) and round(pooled["p_td"], 2) == 83.33
    assert pooled["false_tracks"] == 1
    assert pooled["detection_frame"] == {0: 4.0, 1: 5.0, 2: 6.0}
    assert pooled["start_frame"] == {0: 4.0, 1: 5.0, 2: 6.0}
    assert pooled["halt_frame"] == {0: 12.0, 1: 12.0, 2: 13.0}
    assert pooled["cardinality_error"] == pytest.approx(np.mean([r["cardinality_error"] for r in results]))
    assert np.isnan(pool_runs(results[1:])["detection_frame"][2])


def test_evaluate_reports_track_detection_with_json_and_in_its_summary(tmp_path, capsys):
    """Point truth: 3 targets; tracks on targets 0 (confirmed at its first frame 3, last 11) and 1 (first row
    6 px off) and one on noise.  Frames 0..11 hold 0, 0, 2, 2, 2, 3, 3, 3, 3, 3, 3, 3 truth rows and 0, 0, 0, 1,
    3, 3, 3, 3, 3, 3, 2, 2 track rows → |cardinality error| = (2 + 1 + 1 + 1 + 1) / 12."""
    truth = three_targets()
    tracks = tracks_table(path(1, range(3, 12), 5, 5) + [(4, 2, 9.0, 31.0)] + path(2, range(5, 12), 5, 25)
                          + path(9, range(4, 10), 5, 65))
    tables.write_csv(truth, tmp_path / "truth.csv")
    tables.write_csv(tracks, tmp_path / "tracks.csv")
    args = ["evaluate", "--tracks", str(tmp_path / "tracks.csv"), "--truth", str(tmp_path / "truth.csv")]
    capsys.readouterr()
    assert cli.main(args + ["--json"]) == 0
    scores = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert {"dsr", "edt_mean", "false_tracks", "ospa", "targets"} <= set(scores)  # the existing keys stay
    assert scores["cardinality_error"] == pytest.approx(6 / 12)
    assert scores["p_td"] == pytest.approx(1 / 3)
    assert scores["detection_frame"] == {"0": 3, "1": None, "2": None}
    assert scores["halt_frame"] == {"0": 13, "1": None, "2": None}
    assert cli.main(args) == 0
    out = capsys.readouterr().out
    assert "|cardinality error| 0.500" in out and "P_TD (5 px)        0.333" in out and "0: 3/13" in out
