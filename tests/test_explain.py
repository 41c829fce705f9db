"""evaluate-suite --explain: the stage that lost SGDS-PF's target (issue 43, item 1)."""
import numpy as np
import pytest

from tbd_taichi import cli, suite
from tbd_taichi.methods import make_tracker
from tbd_taichi.methods.sgds.explain import LATE_FRAMES, StageFrames, StageRecorder, first_detection, verdict
from tbd_taichi.simulate import simulate


@pytest.mark.parametrize("frames, dsr, detected_at, expected", [
    (StageFrames(0, None, None, None), 0.0, None, "never a candidate"),
    (StageFrames(0, 3, None, None), 0.0, None, "candidate, no potential target"),
    (StageFrames(0, 3, 5, None), 0.0, None, "handed over, never confirmed"),
    (StageFrames(0, 3, 5, 12, [20]), 0.1, 5, "confirmed, then dropped"),
    (StageFrames(0, 3, 5, 12), 0.9, 5, "detected"),
    (StageFrames(4, 4 + LATE_FRAMES + 2, 4 + LATE_FRAMES + 3, 40), 0.7, 4 + LATE_FRAMES + 3, "late candidate"),
    (StageFrames(0, 1, 20, 30), 0.7, 20, "late hand-over"),
    (StageFrames(0, 1, 3, 40), 0.6, 28, "late confirmation"),  # the early hand-over was never confirmed
    (StageFrames(0, 1, 3, 40), 0.1, 28, "late confirmation"),  # missed: confirmed, too late to matter
])
def test_verdict_names_the_first_stage_never_reached_or_the_slowest_step(frames, dsr, detected_at, expected):
    assert verdict(frames, dsr, detected_at) == expected


def test_the_recorder_only_watches():
    """With the recorder the tracks are the same bytes; on an easy sequence every stage is reached early, in
    order, and the run is 'detected'."""
    scene = simulate((48, 48), frames=40, snr=3.0, seed=4)
    plain = make_tracker("sgds", (48, 48), snr=3.0, seed=1, profile="paper")
    watched = make_tracker("sgds", (48, 48), snr=3.0, seed=1, profile="paper")
    recorder = StageRecorder(watched.tracker, scene.truth)
    for frame in scene.frames:
        plain.update(frame)
        watched.update(frame)
    tracks = watched.finish()
    assert tracks.tobytes() == plain.finish().tobytes() and len(tracks)
    s = recorder.frames
    assert s.truth_first == 0 and 0 <= s.candidate <= s.handover <= s.confirmed < 20
    detected = first_detection(tracks, scene.truth)
    assert detected is not None and detected <= s.handover + 2
    assert verdict(s, 0.9, detected) == "detected"


def test_a_place_without_a_target_gets_no_hand_over():
    """Truth placed where the sequence has no target (the mirror image of its path): no hand-over, no confirmation
    and no detection there."""
    scene = simulate((48, 48), frames=30, snr=3.0, seed=4)
    truth = scene.truth.copy()
    truth["x"] = np.clip(47 - truth["x"], 0, 47)  # the mirror image of the path
    truth["y"] = np.clip(47 - truth["y"], 0, 47)
    tracker = make_tracker("sgds", (48, 48), snr=3.0, seed=1, profile="paper")
    recorder = StageRecorder(tracker.tracker, truth)
    for frame in scene.frames:
        tracker.update(frame)
    tracks = tracker.finish()
    assert first_detection(tracks, truth) is None
    assert recorder.frames.handover is None and recorder.frames.confirmed is None


def test_explained_runs_in_the_suite(tmp_path):
    run = suite.plan(snrs=(3.0,), sizes=((48, 30),), methods=("sgds", "pf"), tests=1, explain=True)
    assert [r.explain for r in run] == [True, False] and run[0].key.endswith("/explain")
    row = suite.run_one(run[0])
    assert row["stage"] == "detected" and row["candidate_at"] is not None and row["detected_at"] is not None
    assert "stage" not in suite.run_one(run[1])
    report = suite.write_explained([row, dict(row, key="x", dsr=0.0, stage="never a candidate")], tmp_path, "cmd")
    text = report.read_text()
    assert "| 48×48×30 | 3 | 2 | 1 | 0 | 1 |" in text and "| x | 0.00 | never a candidate |" in text


def test_explain_needs_the_sgds_suite(tmp_path, capsys):
    assert cli.main(["evaluate-suite", "--methods", "pf", "--explain", "--out-dir", str(tmp_path / "o")]) == 2
    assert "--explain applies to" in capsys.readouterr().err
