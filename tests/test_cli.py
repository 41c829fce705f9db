"""The tbd-taichi command line: simulate, evaluate, --help and errors."""
import json
import re
import subprocess
import sys

import numpy as np
import pytest

from tbd_taichi import cli, tables


def run_cli(*args):
    return subprocess.run([sys.executable, "-m", "tbd_taichi", *map(str, args)], capture_output=True, text=True)


def truth_as_tracks(truth_csv, tracks_csv):
    t = tables.read_truth(truth_csv)
    rows = [(r["frame"], r["target_id"], r["x"], r["y"], r["vx"], r["vy"], r["intensity"], 1.0) for r in t]
    tables.write_csv(tables.make_table(rows, tables.TRACK_DTYPE), tracks_csv)


def test_simulate_then_evaluate_truth_gives_perfect_scores(tmp_path, capsys):
    out = tmp_path / "seq.npz"
    assert cli.main(["simulate", "--shape", "40", "50", "--frames", "12", "--snr", "2", "--targets", "2",
                     "--seed", "3", "--out", str(out)]) == 0
    with np.load(out) as npz:
        assert npz["frames"].shape == (12, 40, 50) and npz["frames"].dtype == np.float32
        assert len(npz["truth"]) == 24
    truth_csv = tmp_path / "seq_truth.csv"
    assert truth_csv.read_text().splitlines()[0] == "frame,target_id,x,y,vx,vy,intensity"
    truth_as_tracks(truth_csv, tmp_path / "tracks.csv")
    capsys.readouterr()
    assert cli.main(["evaluate", "--tracks", str(tmp_path / "tracks.csv"), "--truth", str(truth_csv), "--json"]) == 0
    scores = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert scores["dsr"] == 1.0 and scores["edt_mean"] < 1e-4
    assert scores["false_tracks"] == 0 and scores["ospa"] < 1e-4


def test_evaluate_table_output(tmp_path):
    tables.write_csv(tables.make_table([(0, 0, 1.0, 1.0, 0, 0, 5)], tables.TRUTH_DTYPE), tmp_path / "t.csv")
    tables.write_csv(tables.make_table([(0, 7, 1.0, 2.0, 0, 0, 5, 1)], tables.TRACK_DTYPE), tmp_path / "k.csv")
    res = run_cli("evaluate", "--tracks", tmp_path / "k.csv", "--truth", tmp_path / "t.csv")
    assert res.returncode == 0, res.stderr
    assert re.search(r"DSR \(T0=2 px\)\s+1\.000", res.stdout) and re.search(r"mean EDT \(px\)\s+1\.000", res.stdout)


def test_bad_input_is_a_clear_error(tmp_path):
    res = run_cli("evaluate", "--tracks", tmp_path / "none.csv", "--truth", tmp_path / "none.csv")
    assert res.returncode == 2 and "none.csv: no such file" in res.stderr and "Traceback" not in res.stderr
    (tmp_path / "bad.csv").write_text("frame,x\n0,1\n")
    res = run_cli("evaluate", "--tracks", tmp_path / "bad.csv", "--truth", tmp_path / "bad.csv")
    assert res.returncode == 2 and "missing column(s) track_id" in res.stderr


def test_missing_backend_is_a_clear_error(tmp_path):
    import tbd_taichi

    if "cuda" in tbd_taichi.available_archs():
        pytest.skip("CUDA is present")
    res = run_cli("simulate", "--shape", "8", "8", "--frames", "2", "--snr", "1", "--out", tmp_path / "a.npz", "--arch", "cuda")
    assert res.returncode == 2 and "'cuda' is not available" in res.stderr and "available: cpu" in res.stderr


@pytest.mark.parametrize("command", ["simulate", "evaluate", "track", "bench"])
def test_help_explains_every_option(command):
    res = run_cli(command, "--help")
    assert res.returncode == 0
    parser = cli.build_parser()
    sub = parser._subparsers._group_actions[0].choices[command]
    for action in sub._actions:
        for flag in action.option_strings:
            assert flag in res.stdout
        assert action.help, f"{command} {action.option_strings} has no help"


def test_console_script_and_module_agree():
    from pathlib import Path

    exe = Path(sys.executable).parent / "tbd-taichi"
    assert exe.exists(), "the tbd-taichi console script is not installed beside python"
    a = subprocess.run([exe, "--help"], capture_output=True, text=True).stdout
    b = run_cli("--help").stdout
    assert a.replace("tbd-taichi", "") == b.replace("tbd-taichi", "") and "simulate" in a


def test_track_real_video_preset_and_overrides(tmp_path, capsys):
    """--real-video applies the REAL_VIDEO settings; an option given explicitly wins over the preset."""
    from pathlib import Path

    from tbd_taichi import io

    data = Path(__file__).parent / "data"
    np.save(tmp_path / "clip.npy", io.read_frames(data / "IR_DRONE_021.mp4")[:40])
    boxes = tables.read_boxes(data / "IR_DRONE_021.csv")
    out = tmp_path / "t.csv"
    assert cli.main(["track", str(tmp_path / "clip.npy"), "--real-video", "--paths", "online", "--out", str(out)]) == 0
    t = tables.read_tracks(out)
    assert len(t) >= 15  # confirmed at frame 17 (test_background's regression), then held
    box = {int(b["frame"]): b for b in boxes}
    inside = [box[f]["x"] - 2 <= x <= box[f]["x"] + box[f]["w"] + 2 and box[f]["y"] - 2 <= y <= box[f]["y"] + box[f]["h"] + 2
              for f, x, y in zip(t["frame"].tolist(), t["x"].tolist(), t["y"].tolist())]
    assert np.mean(inside) > 0.9
    assert cli.main(["track", str(tmp_path / "clip.npy"), "--real-video", "--min-peak-z", "500", "--out", str(out)]) == 0
    assert len(tables.read_tracks(out)) == 0  # the drone's peak z is far below 500


def test_track_paper_saliency_matches_the_api(tmp_path):
    """--paper-saliency gives the API's SGDSPF(..., **PAPER_SALIENCY) rows; with --method pf it is an error."""
    import tbd_taichi as tbd

    scene = tbd.simulate((48, 48), 30, 2.5, seed=4)
    np.save(tmp_path / "seq.npy", scene.frames)
    out = tmp_path / "t.csv"
    assert cli.main(["track", str(tmp_path / "seq.npy"), "--paper-saliency", "--out", str(out)]) == 0
    expected = tbd.track(scene.frames, method="sgds", **tbd.PAPER_SALIENCY)
    got = tables.read_tracks(out)
    assert len(got) == len(expected) > 0
    np.testing.assert_allclose(got["x"], expected["x"], atol=1e-4)
    res = run_cli("track", tmp_path / "seq.npy", "--method", "pf", "--paper-saliency", "--out", out)
    assert res.returncode == 2 and "--paper-saliency applies to --method sgds only" in res.stderr
