"""What a run says and writes: the settings profile it picks (CLI and API), the summary line and --json, plain
progress lines, box truth, the overlay video's frame rate, a truncated video's warning, and the plot's legend."""
import io as stdio
import json
from pathlib import Path

import cv2
import numpy as np
import pytest

import tbd_taichi as tbd
from tbd_taichi import cli, metrics, tables
from tbd_taichi.background import REAL_VIDEO
from tbd_taichi.profiles import describe, profile_settings, resolved_profile
from tbd_taichi.progress import PlainProgress

DATA = Path(__file__).parent / "data"


@pytest.mark.parametrize("kind, dtype, expected", [
    ("video", np.uint8, "real-video"), ("folder", np.uint16, "real-video"), ("array", np.uint16, "real-video"),
    ("array", np.int16, "real-video"), ("array", np.float32, "paper"), ("array", np.float64, "paper")])
def test_auto_picks_the_profile_by_the_input(kind, dtype, expected):
    assert resolved_profile("auto", kind, dtype)[0] == expected
    assert resolved_profile("paper", kind, dtype)[0] == "paper"  # an explicit choice is kept


def test_a_profile_gives_a_method_only_the_settings_it_declares():
    sgds, pf, tophat = tbd.methods.get("sgds"), tbd.methods.get("pf"), tbd.methods.get("tophat-pf")
    assert profile_settings(sgds, "real-video") == {**REAL_VIDEO, "keep_peak_z": 12.0, "keep_after": 50, "still_frames": 50}
    assert profile_settings(pf, "real-video") == {**REAL_VIDEO, "min_peak_z": 10.0}  # its own level over the shared
    assert profile_settings(tophat, "real-video") == {}  # declares none of REAL_VIDEO's keys
    assert profile_settings(sgds, "paper") == {}
    line = describe("real-video", "why", REAL_VIDEO, {"snr": 3.0, "history": False})
    assert "min_peak_z=16" in line and "given instead: snr=3" in line and "history" not in line


def test_make_tracker_settles_auto_at_the_first_frame():
    """Integer frames get the real-video settings, float frames the paper's; keyword arguments win."""
    rng = np.random.default_rng(1)
    raw = (1000 + 20 * rng.standard_normal((24, 28))).astype(np.uint16)
    camera = tbd.make_tracker("pf", (24, 28), n_particles=64)
    camera.update(raw)
    assert camera.profile == "real-video" and camera.tracker.params.snr == REAL_VIDEO["snr"]
    simulated = tbd.make_tracker("pf", (24, 28), n_particles=64)
    simulated.update(raw.astype(np.float32))
    assert simulated.profile == "paper" and simulated.tracker.params.snr == 1.4
    given = tbd.make_tracker("pf", (24, 28), n_particles=64, snr=2.5)
    given.update(raw)
    assert given.profile == "real-video" and given.tracker.params.snr == 2.5
    forced = tbd.make_tracker("pf", (24, 28), n_particles=64, profile="paper")
    forced.update(raw)
    assert forced.profile == "paper" and forced.tracker.params.snr == 1.4


def test_plain_progress_prints_a_line_per_interval():
    out = stdio.StringIO()
    progress = PlainProgress("tracking", 10, stream=out, every=5.0)
    clock = iter([0.0, 1.0, 6.0, 7.0, 12.0])
    progress._clock = lambda: next(clock)
    progress.started = progress.last = progress._clock()
    for _ in range(4):
        progress.advance()
    lines = out.getvalue().splitlines()
    assert lines == ["tracking: 2/10 frames, 0.3 frames/s, 24 s left", "tracking: 4/10 frames, 0.3 frames/s, 18 s left"]


@pytest.fixture(scope="module")
def clip(tmp_path_factory):
    """40 raw frames of the drone-ir test clip as a 12 fps MJPG .avi and an int16 .npy, with its boxes."""
    d = tmp_path_factory.mktemp("runs")
    frames = tbd.io.read_frames(DATA / "IR_DRONE_021.mp4")[:40].astype(np.uint8)
    writer = cv2.VideoWriter(str(d / "clip.avi"), cv2.VideoWriter_fourcc(*"MJPG"), 12.0,
                             (frames.shape[2], frames.shape[1]), False)
    for frame in frames:
        writer.write(frame)
    writer.release()
    np.save(d / "clip.npy", frames.astype(np.int16))
    boxes = tables.read_boxes(DATA / "IR_DRONE_021.csv")
    tables.write_csv(boxes[boxes["frame"] < 40], d / "boxes.csv")
    return d


def run_json(args, capsys) -> tuple[dict, str]:
    capsys.readouterr()
    assert cli.main([str(a) for a in args]) == 0
    captured = capsys.readouterr()
    return json.loads(captured.out.strip().splitlines()[-1]), captured.err


def test_track_summarises_the_run_and_scores_box_truth(clip, capsys):
    summary, err = run_json(["track", clip / "clip.npy", "--method", "pf", "--out", clip / "t.csv", "--truth",
                             clip / "boxes.csv", "--json", "--progress", "off"], capsys)
    assert err.splitlines()[0].startswith("profile real-video (the frames are int16 integers")
    assert summary["frames"] == 40 and summary["profile"] == "real-video"
    assert summary["tracks"] == len(np.unique(tables.read_tracks(clip / "t.csv")["track_id"]))
    assert summary["tracker_fps"] > 0 and summary["wall_s"] > 0
    assert summary["startup_s"] > 0 and summary["kernels"] >= 0 and summary["compile_s"] >= 0
    assert summary["steady_fps"] >= summary["tracker_fps"]  # without the kernels built in the updates
    assert summary["end_to_end_fps"] == pytest.approx(40 / summary["wall_s"])
    assert any(line.startswith("timing: start-up ") and "kernel(s) built" in line for line in err.splitlines())
    scores = summary["scores"]
    assert scores["truth"] == "boxes" and scores["detection_rate"] > 0.5 and scores["false_points"] < 0.1
    assert scores["centre_error"] < 3 and np.isnan(scores["iou"])  # a point tracker has no box
    capsys.readouterr()
    assert cli.main(["track", str(clip / "clip.npy"), "--method", "pf", "--profile", "paper",
                     "--out", str(clip / "p.csv"), "--progress", "off"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0].startswith("profile paper (chosen explicitly)")
    assert out[-1].startswith("pf: 40 frames,") and "frames/s" in out[-1] and out[-1].endswith("profile paper")


def test_a_long_compile_gets_a_note_naming_warmup():
    from tbd_taichi.cli_track import COMPILE_NOTE_S, RunTiming
    from tbd_taichi.compile_stats import CompileCounts

    quick = RunTiming(10, 1.0, CompileCounts(5, 1.0, 5, COMPILE_NOTE_S - 1.5), 2.0, 1.0)
    slow = RunTiming(10, 1.0, CompileCounts(40, 2.0, 40, COMPILE_NOTE_S), 20.0, 11.0)
    assert quick.compile_note((64, 80)) is None
    assert "tbd-taichi warmup --shape 64 80" in slow.compile_note((64, 80))
    assert slow.steady_fps == pytest.approx(10 / 9.0) and "12 s went to compiling" in slow.compile_note((64, 80))


def test_evaluate_scores_box_truth_and_its_margin(clip, capsys):
    boxes = tables.read_boxes(clip / "boxes.csv")
    centre = [(b["frame"], 1, b["x"] + b["w"] / 2, b["y"] + b["h"] / 2, 0, 0, 1, 1) for b in boxes]
    beside = [(b["frame"], 2, b["x"] + b["w"] + 1.5, b["y"], 0, 0, 1, 1) for b in boxes]  # 1.5 px right of the box
    tables.write_csv(tables.make_table(centre + beside, tables.TRACK_DTYPE), clip / "k.csv")
    scores, _ = run_json(["evaluate", "--tracks", clip / "k.csv", "--truth", clip / "boxes.csv", "--json"], capsys)
    assert scores["detection_rate"] == 1.0 and scores["false_points"] == 0.0 and scores["centre_error"] < 1e-9
    scores, _ = run_json(["evaluate", "--tracks", clip / "k.csv", "--truth", clip / "boxes.csv", "--json",
                          "--box-margin", "1"], capsys)
    assert scores["false_points"] == pytest.approx(len(boxes) / 40)  # every "beside" point is now outside


def test_box_scores_for_two_targets_and_a_box_tracker():
    boxes = tables.make_table([(0, 10, 10, 4, 4, 0), (0, 30, 30, 6, 6, 1), (1, 11, 10, 4, 4, 0)],
                              tables._dtype(("frame", "x", "y", "w", "h", "target_id")))
    tracks = {"frame": [0, 0, 1], "track_id": [1, 2, 1], "x": [12, 33, 13], "y": [12, 33, 12], "w": [4, 6, 2],
              "h": [4, 6, 4]}
    scores = metrics.box_scores(tracks, boxes, 2)
    assert scores["detection_rate"] == 1.0 and scores["false_points"] == 0.0
    assert scores["iou"] == pytest.approx((1 + 1 + 0.5) / 3)
    scores = metrics.box_scores({k: v[:1] for k, v in tracks.items()}, boxes, 2)
    assert scores["detection_rate"] == pytest.approx(1 / 3)


def test_the_overlay_video_keeps_the_input_frame_rate(clip, capsys):
    cli.main(["track", str(clip / "clip.avi"), "--method", "pf", "--out", str(clip / "v.csv"), "--video",
              str(clip / "o.avi"), "--progress", "off"])
    cli.main(["track", str(clip / "clip.npy"), "--method", "pf", "--out", str(clip / "n.csv"), "--video",
              str(clip / "n.avi"), "--fps", "7", "--progress", "off"])
    rates = []
    for name in ("o.avi", "n.avi"):
        capture = cv2.VideoCapture(str(clip / name))
        rates.append((capture.get(cv2.CAP_PROP_FPS), int(capture.get(cv2.CAP_PROP_FRAME_COUNT))))
        capture.release()
    assert rates == [(12.0, 40), (7.0, 40)]


def test_a_truncated_video_is_tracked_with_a_warning(clip, capsys):
    data = (clip / "clip.avi").read_bytes()
    (clip / "cut.avi").write_bytes(data[: len(data) * 6 // 10])
    capsys.readouterr()
    assert cli.main(["track", str(clip / "cut.avi"), "--method", "pf", "--out", str(clip / "c.csv"),
                     "--progress", "off"]) == 0
    err = capsys.readouterr().err
    assert "declares 40 frames but only" in err and "truncated" in err


def test_the_plot_legend_names_the_longest_tracks_only(tmp_path, monkeypatch):
    import matplotlib.pyplot as plt

    from tbd_taichi import plots

    rows = [(f, tid, 5.0 + tid, 5.0 + f, 0, 0, 1, 1) for tid in range(1, 21) for f in range(tid)]
    seen = {}
    monkeypatch.setattr(plt, "close", lambda fig: seen.setdefault("fig", fig))
    plots.plot_tracks(np.zeros((40, 40)), tables.make_table(rows, tables.TRACK_DTYPE), tmp_path / "p.png")
    labels = [t.get_text() for t in seen["fig"].axes[0].get_legend().get_texts()]
    assert set(labels[:-1]) == {f"track {t} ({t} frames)" for t in range(20, 20 - plots.LEGEND_TRACKS, -1)}
    assert labels[-1] == f"+ {20 - plots.LEGEND_TRACKS} shorter tracks (ids on the image)"
    assert len(seen["fig"].axes[0].texts) == 20  # every id beside its trail


README = Path(__file__).parent.parent / "README.md"
CHECKED_ONLY = ("evaluate-suite", "bench", "warmup", "batch-track")  # long work (test_warmup, test_batch and
# test_cluster run warmup and batch-track): checked, not run


def readme_commands() -> list[list[str]]:
    """The ``tbd-taichi …`` lines of the README's bash blocks, split as the shell would (comments dropped)."""
    import re
    import shlex

    blocks = re.findall(r"```bash\n(.*?)```", README.read_text(), flags=re.S)
    return [shlex.split(line, comments=True)[1:] for block in blocks for line in block.splitlines()
            if line.startswith("tbd-taichi ")]


def test_the_readme_examples_work_as_written(tmp_path, monkeypatch, capsys):
    """Each example in order, in a fresh folder with tests/data beside it; the drone clip's tracks are scored
    against its labels (the PF baseline example once gave a false track), the suite, the bench and the warm-up are
    checked."""
    commands = readme_commands()
    assert len(commands) >= 8 and any(c[0] == "track" and "tests/data/IR_DRONE_021.mp4" in c for c in commands)
    (tmp_path / "tests").mkdir()
    (tmp_path / "tests" / "data").symlink_to(DATA)
    monkeypatch.chdir(tmp_path)
    boxes = tables.read_boxes(DATA / "IR_DRONE_021.csv")
    for args in commands:
        if args[0] in CHECKED_ONLY:
            parsed = cli.build_parser().parse_args(args)
            parsed.check(parsed)
            continue
        assert cli.main(args) == 0, args
        if args[0] == "track" and "IR_DRONE_021.mp4" in args[1]:
            tracks = tables.read_tracks(args[args.index("--out") + 1])
            scores = metrics.box_scores(tracks, boxes, 303)
            assert len(np.unique(tracks["track_id"])) == 1, args
            assert scores["detection_rate"] > 0.8 and scores["false_points"] == 0.0, (args, scores)
    assert (tmp_path / "overlay.mp4").stat().st_size > 0 and (tmp_path / "tracks.png").stat().st_size > 0
    assert "N_sump" in capsys.readouterr().out
