"""The bad-input battery, second part: outputs that would overwrite an input or cannot be written, values past
any sensible range, tables whose numbers are not frames or boxes, and flags a scenario would ignore.  Each is
refused before any work, in one line, with exit status 2 (as in test_bad_input.py), and the inputs are left as they
were."""
import hashlib
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest

import tbd_taichi as tbd
from tbd_taichi import metrics, validate
from tbd_taichi.errors import InputError, ParameterError
from test_bad_input import ERROR_SECONDS, cli_error

DATA = Path(__file__).parent / "data"
CLIP = DATA / "IR_DRONE_021.mp4"
BOXES = DATA / "IR_DRONE_021.csv"
PROC = Path("/proc")  # a folder that exists but takes no new file, whoever runs the tests (Linux)


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("outputs")
    rng = np.random.default_rng(1)
    frames = (1000 + 20 * rng.standard_normal((10, 24, 28))).astype(np.uint16)
    np.save(d / "good.npy", frames)
    np.savez(d / "good.npz", frames=frames)
    (d / "truncated.npz").write_bytes((d / "good.npz").read_bytes()[:300])
    (d / "noheader.npy").write_bytes(bytes(range(256)) * 8)
    huge = frames.astype(np.float64)
    huge[6, 2, 2] = 1e300
    np.save(d / "huge.npy", huge)
    shutil.copy(CLIP, d / "clip.mp4")
    (d / "truth.csv").write_text("frame,target_id,x,y\n0,0,5,6\n1,0,6,6\n")
    (d / "tracks.csv").write_text("frame,track_id,x,y,vx,vy,intensity,confidence\n0,1,5,6,0,0,1,1\n")
    for name, row in {"frame_fraction": "1.5,0,5,6", "frame_negative": "-3,0,5,6", "frame_huge": "1e20,0,5,6"}.items():
        (d / f"{name}.csv").write_text(f"frame,target_id,x,y\n0,0,5,6\n{row}\n")
    (d / "box_negative.csv").write_text("frame,x,y,w,h\n0,3,3,-5,4\n")
    (d / "far_frame.csv").write_text(f"frame,target_id,x,y\n0,0,5,6\n{10**7 - 1},0,5,6\n")
    for folder, sizes in {"mixed": [(24, 28)] * 6 + [(20, 28)] + [(24, 28)] * 3, "same": [(24, 28)] * 10}.items():
        (d / folder).mkdir()
        for k, (h, w) in enumerate(sizes):
            cv2.imwrite(str(d / folder / f"f{k:03d}.png"), frames[k, :h, :w])
    shutil.copytree(d / "same", d / "junk")
    (d / "junk" / "f007.png").write_bytes(b"not an image at all, only text" * 10)
    return d


def digest(path: Path) -> str:
    """A file's content, or a folder's files' contents, as one hash."""
    paths = sorted(path.iterdir()) if path.is_dir() else [path]
    return hashlib.sha256(b"".join(p.read_bytes() for p in paths)).hexdigest()


TRACK = ["track", "{d}/good.npy", "--out", "{d}/out.csv"]
EVAL = ["evaluate", "--tracks", "{d}/tracks.csv", "--truth", "{d}/truth.csv"]
CASES = [
    # (id, arguments, text the line names, input that must stay unchanged)
    ("video-over-input", ["track", "{d}/clip.mp4", "--out", "{d}/o.csv", "--video", "{d}/clip.mp4"], "--video",
     "clip.mp4"),
    ("out-over-truth", TRACK[:3] + ["{d}/truth.csv", "--truth", "{d}/truth.csv"], "--truth", "truth.csv"),
    ("diagnostics-over-truth", TRACK + ["--method", "tophat-pf", "--truth", "{d}/truth.csv", "--diagnostics",
                                        "{d}/truth.csv"], "--diagnostics", "truth.csv"),
    ("out-into-frame-folder", ["track", "{d}/same", "--out", "{d}/same/f000.png"], "folder", "same"),
    ("plot-is-video", TRACK + ["--plot", "{d}/o.png", "--video", "{d}/o.png"], "--video", None),
    ("npz-truncated", ["track", "{d}/truncated.npz", "--out", "{d}/o.csv"], "truncated.npz", None),
    ("npy-without-header", ["track", "{d}/noheader.npy", "--out", "{d}/o.csv"], "no NumPy header", None),
    ("float64-past-float32", ["track", "{d}/huge.npy", "--out", "{d}/o.csv"], "frame 6", None),
    ("folder-mixed-sizes", ["track", "{d}/mixed", "--out", "{d}/o.csv"], "f006.png", None),
    ("folder-not-an-image", ["track", "{d}/junk", "--out", "{d}/o.csv"], "f007.png", None),
    ("truth-of-another-clip", TRACK + ["--truth", str(BOXES)], "--truth", None),
    ("threads-absurd", TRACK + ["--threads", "100000"], "--threads", None),
    ("seed-past-32-bits", TRACK + ["--seed", str(2**32)], "--seed", None),
    ("fps-absurd", TRACK + ["--fps", "1e12"], "--fps", None),
    ("param-window-absurd", TRACK + ["--param", "icef_window=1000000000"], "icef_window", None),
    ("param-sigma-absurd", TRACK + ["--param", "psf_sigma=1e300"], "psf_sigma", None),
    ("param-speed-absurd", TRACK + ["--param", "V_limit=1e300"], "V_limit", None),
    ("param-tracks-absurd", TRACK + ["--param", "max_tracks=1000000000"], "GiB", None),
    ("param-track-particles-absurd", TRACK + ["--param", "N_tpf=1000000000"], "GiB", None),
    ("evaluate-frame-fraction", EVAL[:4] + ["{d}/frame_fraction.csv"], "line 3", None),
    ("evaluate-frame-negative", EVAL[:4] + ["{d}/frame_negative.csv"], "line 3", None),
    ("evaluate-frame-huge", EVAL[:4] + ["{d}/frame_huge.csv"], "line 3", None),
    ("evaluate-box-negative", EVAL[:4] + ["{d}/box_negative.csv"], "box w", None),
    ("evaluate-frames-too-few", EVAL + ["--frames", "1"], "--frames", None),
    ("evaluate-ospa-p-absurd", EVAL + ["--ospa-p", "1e308"], "--ospa-p", None),
    ("evaluate-ospa-c-tiny", EVAL + ["--ospa-c", "1e-300"], "--ospa-c", None),
    ("evaluate-tracks-folder", ["evaluate", "--tracks", "{d}", "--truth", "{d}/truth.csv"], "is a folder", None),
    ("simulate-targets-ignored", ["simulate", "--scenario", "long2012", "--targets", "5", "--out", "{d}/s.npz"],
     "--targets", None),
    ("suite-snrs-ignored", ["evaluate-suite", "--scenario", "long2012", "--methods", "mm-phd", "--snrs", "5",
                            "--out-dir", "{d}/suite"], "--snrs", None),
    ("batch-overlay-over-input", ["batch-track", "{d}/clip.mp4", "--out-dir", "{d}", "--video"], "clip.mp4",
     "clip.mp4"),
    ("batch-into-frame-folder", ["batch-track", "{d}/same", "--out-dir", "{d}/same"], "--out-dir", "same"),
    ("suite-seeds-past-32-bits", ["evaluate-suite", "--tests", "5", "--seed", str(2**32 - 2), "--out-dir",
                                  "{d}/suite"], "--seed", None),
]
UNWRITABLE = [  # a folder that exists and is "writable" by its mode for root, yet takes no file
    ("out", ["track", "{d}/good.npy", "--out", "/proc/tbd_out.csv"], "--out"),
    ("plot", TRACK + ["--plot", "/proc/tbd_plot.png"], "--plot"),
    ("video", TRACK + ["--video", "/proc/tbd_video.mp4"], "--video"),
    ("diagnostics", TRACK + ["--method", "tophat-pf", "--diagnostics", "/proc/tbd_d.csv"], "--diagnostics"),
    ("simulate", ["simulate", "--shape", "32", "32", "--frames", "4", "--snr", "2", "--out", "/proc/tbd_s.npz"],
     "--out"),
    ("suite", ["evaluate-suite", "--quick", "--out-dir", "/proc/tbd_suite"], "--out-dir"),
]


def expand(args, d: Path) -> list[str]:
    return [str(a).replace("{d}", str(d)) for a in args]


@pytest.mark.parametrize("args, offender, kept", [c[1:] for c in CASES], ids=[c[0] for c in CASES])
def test_refused_early_in_one_line_and_inputs_kept(files, capsys, args, offender, kept):
    before = digest(files / kept) if kept else None
    code, err, seconds = cli_error(expand(args, files), capsys)
    lines = [line for line in err.splitlines() if line.strip()]
    assert code == 2, err
    assert len(lines) == 1 and "error:" in lines[0] and "Traceback" not in err, err
    assert offender in lines[0], lines[0]
    assert seconds < ERROR_SECONDS, f"the error took {seconds:.1f} s"
    if kept:
        assert digest(files / kept) == before, f"{kept} was changed"


@pytest.mark.skipif(not PROC.is_dir(), reason="needs Linux's /proc")
@pytest.mark.parametrize("args, offender", [c[1:] for c in UNWRITABLE], ids=[c[0] for c in UNWRITABLE])
def test_an_output_the_system_refuses_is_found_before_the_run(files, capsys, args, offender):
    code, err, seconds = cli_error(expand(args, files), capsys)
    assert code == 2 and offender in err and "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    assert seconds < ERROR_SECONDS


def test_the_output_probe_leaves_no_file_and_keeps_an_existing_one(tmp_path):
    new, old = tmp_path / "new.csv", tmp_path / "old.csv"
    old.write_text("kept\n")
    assert validate.output_path("--out", new) == new and not new.exists()
    assert validate.output_path("--out", old) == old and old.read_text() == "kept\n"


def test_a_far_frame_is_scored_without_a_pass_over_every_frame(files, capsys):
    """A truth row at frame MAX_FRAME: the OSPA mean divides by every frame but visits only those with rows."""
    code, err, _ = cli_error(expand(EVAL[:4] + ["{d}/far_frame.csv", "--json"], files), capsys)
    assert code == 0, err
    tracks = tbd.tables.read_tracks(files / "tracks.csv")
    truth = tbd.tables.read_truth(files / "truth.csv")
    ten = [metrics.ospa(tracks[tracks["frame"] == f][["x", "y"]].tolist(), truth[truth["frame"] == f][["x", "y"]].tolist())
           for f in range(10)]
    assert metrics.mean_ospa(tracks, truth, n_frames=10) == pytest.approx(np.mean(ten), rel=1e-12)


def test_the_api_refuses_a_seed_past_32_bits():
    with pytest.raises(ParameterError, match="seed"):
        tbd.make_tracker("pf", (32, 32), seed=2**32)


def test_a_folder_of_same_size_images_still_runs(files, capsys):
    code, err, _ = cli_error(expand(["track", "{d}/same", "--out", "{d}/same_tracks.csv", "--method", "pf"], files),
                           capsys)
    assert code == 0, err
    with pytest.raises(InputError, match="f006.png"):
        tbd.io.open_frames(files / "mixed")
