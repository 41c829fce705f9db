"""batch-track: inputs found from files, folders and globs; outputs written whole; a bad input recorded while the
rest go on; a rerun does only what is missing."""
import csv
import sys

import numpy as np
import pytest

from tbd_taichi import batch, cli
from tbd_taichi.errors import TBDError
from tbd_taichi.executor import Fanout, check_scheduler
from tbd_taichi.simulate import simulate


def write_clip(path, seed, shape=(48, 56), frames=24):
    scene = simulate(shape, frames=frames, snr=3.0, seed=seed)
    np.save(path, scene.frames)
    return scene


def summary_rows(out_dir):
    with open(out_dir / "summary.csv", newline="") as handle:
        return {row["name"]: row for row in csv.DictReader(handle)}


def test_corrupt_input_is_recorded_and_the_rerun_does_only_it(tmp_path, capsys):
    clips = tmp_path / "clips"
    clips.mkdir()
    write_clip(clips / "good1.npy", 1)
    write_clip(clips / "good2.npy", 2)
    (clips / "broken.npy").write_bytes(b"\x93NUMPY not really")
    (clips / "notes.txt").write_text("not a clip")  # not a sequence: ignored in a folder
    out = tmp_path / "out"
    argv = ["batch-track", str(clips), "--out-dir", str(out), "--no-progress", "--method", "pf", "--profile", "paper",
            "--param", "n_particles=2000"]
    assert cli.main(argv) == 1
    rows = summary_rows(out)
    assert set(rows) == {"good1", "good2", "broken"}
    assert rows["broken"]["status"] == "failed" and "broken.npy" in rows["broken"]["error"]
    for name in ("good1", "good2"):
        assert rows[name]["status"] == "ok" and int(rows[name]["frames"]) == 24 and float(rows[name]["wall_s"]) > 0
        assert (out / f"{name}.csv").read_text().startswith("frame,track_id,x,y")
    assert not (out / "broken.csv").exists()
    assert not list(out.glob(".*partial*")), "temporary files are renamed or removed"
    kept = {name: (out / f"{name}.csv").stat().st_mtime_ns for name in ("good1", "good2")}
    capsys.readouterr()
    assert cli.main(argv) == 1  # the broken one again; the good ones are skipped
    said = capsys.readouterr().out
    assert "1 to track" in said and "2 skipped" in said
    assert {name: (out / f"{name}.csv").stat().st_mtime_ns for name in kept} == kept
    assert summary_rows(out)["good1"] == rows["good1"]  # the earlier row is kept
    (clips / "broken.npy").unlink()
    write_clip(clips / "broken.npy", 3)  # repaired: the rerun tracks it and succeeds
    (out / ".broken.0123abcd.partial.csv").write_text("left by a killed run")
    assert cli.main(argv) == 0
    assert summary_rows(out)["broken"]["status"] == "ok"
    assert not list(out.glob(".*partial*")), "a killed run's temporary file is removed"
    capsys.readouterr()
    assert cli.main(argv[:-1] + ["n_particles=3000"]) == 2  # other settings: the folder's outputs are not theirs
    assert "other settings (params" in capsys.readouterr().err


def test_outputs_match_track_and_extras_are_written(tmp_path):
    clip = tmp_path / "clip.npy"
    write_clip(clip, 5)
    out = tmp_path / "out"
    out.mkdir()
    assert cli.main(["batch-track", str(clip), "--out-dir", str(out), "--no-progress", "--plot", "--seed", "3"]) == 0
    assert cli.main(["track", str(clip), "--out", str(tmp_path / "single.csv"), "--seed", "3", "--progress", "off"]) == 0
    assert (out / "clip.csv").read_bytes() == (tmp_path / "single.csv").read_bytes()
    assert (out / "clip.png").stat().st_size > 1000


def test_inputs_from_globs_folders_and_name_clashes(tmp_path):
    for day in ("day1", "day2"):
        (tmp_path / day).mkdir()
        np.save(tmp_path / day / "clip.npy", np.zeros((2, 8, 8), np.float32))
    frames = tmp_path / "frames"
    frames.mkdir()
    (frames / "f0.png").write_bytes(b"")
    paths = batch.expand_inputs([str(tmp_path / "day*" / "*.npy"), str(frames), str(tmp_path / "day1" / "clip.npy")])
    assert paths == [(tmp_path / "day1" / "clip.npy").resolve(), (tmp_path / "day2" / "clip.npy").resolve(),
                     frames.resolve()]  # each input once
    assert batch.output_names(paths) == ["day1__clip", "day2__clip", "frames"]
    assert batch.folder_inputs(tmp_path) == [frames]  # a folder of folders: its image folders
    np.savez(tmp_path / "day1" / "clip.npz", frames=np.zeros((2, 8, 8), np.float32))
    np.save(tmp_path / "day2" / "Other.npy", np.zeros((2, 8, 8), np.float32))
    np.save(tmp_path / "day1" / "other.npy", np.zeros((2, 8, 8), np.float32))
    paths = batch.expand_inputs([str(tmp_path / "day1"), str(tmp_path / "day2" / "Other.npy")])
    assert [p.name for p in paths] == ["clip.npy", "clip.npz", "other.npy", "Other.npy"]
    # only the clashing inputs are renamed: same stem (suffix kept), and names equal but for case
    assert batch.output_names(paths) == ["day1__clip_npy", "day1__clip_npz", "day1__other", "day2__Other"]


@pytest.mark.parametrize("inputs, message", [
    (["{tmp}/missing.mp4"], "does not exist"),
    (["{tmp}/*.mkv"], "matches no video"),
    (["{tmp}/notes.txt"], "is not a .npy"),
    (["{tmp}/empty"], "holds no videos"),
    (["{tmp}/summary.npy"], "would overwrite"),
])
def test_bad_inputs_are_errors_before_any_work(tmp_path, inputs, message):
    (tmp_path / "notes.txt").write_text("x")
    (tmp_path / "empty").mkdir()
    np.save(tmp_path / "summary.npy", np.zeros((2, 8, 8), np.float32))
    with pytest.raises(TBDError, match=message):
        batch.output_names(batch.expand_inputs([i.format(tmp=tmp_path) for i in inputs]))


@pytest.mark.parametrize("extra, message", [
    (["--out-dir", "{tmp}/no/such/dir"], "does not exist"),
    (["--out-dir", "{tmp}/file.txt"], "is a file"),
    (["--method", "feature-fusion"], "first-frame box"),
    (["--param", "nonsense=1"], "nonsense"),
    (["--scheduler", "http//bad"], "tcp://HOST:PORT"),
    (["--method", "ma-rs", "--profile", "real-video"], "ma-rs on real video needs templates given"),
])
def test_cli_checks_arguments_first(tmp_path, capsys, extra, message):
    clip = tmp_path / "clip.npy"
    np.save(clip, np.zeros((4, 16, 16), np.float32))
    (tmp_path / "file.txt").write_text("x")
    argv = ["batch-track", str(clip), "--out-dir", str(tmp_path / "out")]
    argv += [e.format(tmp=tmp_path) for e in extra]
    assert cli.main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and err.count("\n") == 0
    assert not (tmp_path / "out").exists()


def test_auto_profile_checks_the_real_video_needs_of_integer_inputs_first(tmp_path, capsys):
    """batch-track --method ma-rs under auto: an integer .npy among the inputs (camera data: the real-video profile)
    stops the batch before any input with the one-line need; float inputs alone (the paper profile) do not."""
    np.save(tmp_path / "raw.npy", np.zeros((4, 16, 16), np.uint16))
    np.save(tmp_path / "sim.npy", np.zeros((4, 16, 16), np.float32))
    out = tmp_path / "out"
    assert cli.main(["batch-track", str(tmp_path / "sim.npy"), str(tmp_path / "raw.npy"), "--method", "ma-rs",
                     "--out-dir", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert "ma-rs on real video needs templates given" in err and err.count("\n") == 0 and not out.exists()
    from tbd_taichi.cli_batch import camera_input

    assert camera_input(tmp_path / "raw.npy") and not camera_input(tmp_path / "sim.npy")
    assert camera_input(tmp_path) and camera_input(tmp_path / "clip.mp4")


def test_scheduler_without_distributed_says_what_to_install(monkeypatch):
    monkeypatch.setitem(sys.modules, "distributed", None)  # import distributed -> ImportError
    with pytest.raises(TBDError, match=r"pip install 'tbd-taichi\[cluster\]'"):
        check_scheduler("local-dask")


def test_a_failing_item_does_not_stop_the_others():
    with Fanout(workers=1) as fanout:
        outcomes = {o.item: o for o in fanout.run(_inverse, [2, 0, 4])}
    assert outcomes[2].value == 0.5 and outcomes[4].value == 0.25
    assert outcomes[0].error.startswith("ZeroDivisionError") and not outcomes[0].fatal


def test_a_worker_without_its_backend_fails_its_items_fast():
    """A pool worker asked for a backend this machine lacks: every item comes back fatal, naming it."""
    from tbd_taichi import backend

    missing = next((a for a in backend.GPU_ARCHS if a not in backend.available_archs()), None)
    if missing is None:
        pytest.skip("every GPU backend is available here")
    with Fanout(workers=2, arch=missing) as fanout:
        outcomes = list(fanout.run(_inverse, [1, 2]))
    assert len(outcomes) == 2 and all(o.fatal and f"could not start the {missing} backend" in o.error for o in outcomes)


def _inverse(x):
    return 1 / x


def test_progress_shows_the_rate_per_minute():
    from tbd_taichi.progress import progress_bar

    bar = progress_bar("evaluation runs", True, rate_unit="runs")
    column = next(c for c in bar.columns if type(c).__name__ == "PerMinute")
    task_id = bar.add_task("runs", total=10)
    task = bar.tasks[task_id]
    assert str(column.render(task)) == ""  # nothing measured yet
    task.finished_speed = 0.5  # rich's measured rate, per second
    assert str(column.render(task)) == "30.0 runs/min"
