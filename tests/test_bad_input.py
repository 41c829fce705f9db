"""The bad-input battery: every sub-command and the Python API refuse bad arguments, paths and files early, with
the project's own error, one line naming the offender, no traceback, exit status 2 (CLI) — and good input is
still accepted (the controls at the end), so that a validator that refuses everything fails here.

CLI cases run in-process (``cli.main``): an exception that is not the project's would escape and fail the test,
and the time to the error is measured without the interpreter's start-up.  A few run as real processes to check
the whole path, traceback-free stderr included."""
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import tbd_taichi as tbd
from tbd_taichi import cli, metrics, tables
from tbd_taichi.errors import InputError, ParameterError, TBDError

DATA = Path(__file__).parent / "data"
CLIP = DATA / "IR_DRONE_021.mp4"
BOXES = DATA / "IR_DRONE_021.csv"
ERROR_SECONDS = 2.0  # the bound on the time to an error, whatever the input size


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """Good and bad inputs, made once."""
    d = tmp_path_factory.mktemp("battery")
    rng = np.random.default_rng(0)
    good = (1000 + 20 * rng.standard_normal((12, 24, 28))).astype(np.uint16)
    np.save(d / "good.npy", good)
    np.save(d / "float.npy", rng.standard_normal((12, 24, 28)).astype(np.float32))
    nan = rng.standard_normal((12, 24, 28)).astype(np.float32)
    nan[7, 3, 4] = np.nan
    np.save(d / "nan.npy", nan)
    inf = nan.copy()
    inf[7, 3, 4] = np.inf
    np.save(d / "inf.npy", inf)
    np.save(d / "bool.npy", good > 1000)
    np.save(d / "complex.npy", good.astype(np.complex64))
    np.save(d / "2d.npy", good[0])
    np.save(d / "tiny.npy", good[:, :4, :4])
    np.save(d / "small.npy", good[:, :8, :8])
    np.save(d / "two.npy", good[:2])
    np.save(d / "empty.npy", np.zeros((0, 24, 28), np.float32))
    (d / "garbage.npy").write_bytes(b"\x93NUMPY garbage" + bytes(range(256)))
    (d / "corrupt.mp4").write_bytes(rng.integers(0, 256, 4096, dtype=np.uint8).tobytes())
    (d / "empty.mp4").write_bytes(b"")
    (d / "truncated.mp4").write_bytes(CLIP.read_bytes()[:2000])
    (d / "folder_empty").mkdir()
    (d / "binary.csv").write_bytes(bytes(range(256)) * 4)
    (d / "empty.csv").write_text("")
    (d / "latin1.csv").write_bytes("frame,target_id,x,y\n0,0,1,2\n1,0,\xe9,2\n".encode("latin-1"))
    (d / "garbled.csv").write_text("frame,target_id,x,y\n0,0,1,2\n1,0,abc,2\n")
    (d / "nan_truth.csv").write_text("frame,target_id,x,y\n0,0,1,2\n1,0,nan,2\n")
    (d / "short_row.csv").write_text("frame,target_id,x,y\n0,0,1,2\n1,0\n")
    (d / "no_xy.csv").write_text("frame,id,a,b\n0,0,1,2\n")
    (d / "points.csv").write_text("frame,target_id,x,y\n0,0,5,6\n1,0,6,6\n")
    (d / "tracks.csv").write_text("frame,track_id,x,y,vx,vy,intensity,confidence\n0,1,5,6,0,0,1,1\n1,1,6,6,0,0,1,1\n")
    (d / "bad_tracks.csv").write_text("frame,track_id,x,y,vx,vy,intensity,confidence\n0,1,5,6,0,0,1,1\n1,1,x,6,0,0,1,1\n")
    (d / "file").write_text("not a folder")
    return d


def cli_error(args, capsys):
    """Run the CLI in-process on ``args``: (exit code, stderr, seconds).  An exception other than SystemExit
    escapes (a traceback is a failing case)."""
    capsys.readouterr()
    started = time.perf_counter()
    try:
        code = cli.main([str(a) for a in args])
    except SystemExit as exc:  # argparse's usage errors
        code = exc.code
    seconds = time.perf_counter() - started
    return code, capsys.readouterr().err, seconds


def expand(args, d: Path) -> list[str]:
    return [str(a).replace("{d}", str(d)).replace("{clip}", str(CLIP)).replace("{boxes}", str(BOXES)) for a in args]


TRACK = ["track", "{d}/good.npy", "--out", "{d}/out.csv"]
EVAL = ["evaluate", "--tracks", "{d}/tracks.csv", "--truth", "{d}/points.csv"]
SIM = ["simulate", "--shape", "32", "32", "--frames", "4", "--snr", "2", "--out", "{d}/sim.npz"]
BENCH = ["bench", "--shape", "32", "32", "--frames", "2"]
SUITE = ["evaluate-suite", "--quick", "--out-dir", "{d}/suite"]
MMPHD = TRACK + ["--method", "mm-phd"]

# (case id, argument list, text the one-line message must contain)
CLI_CASES = [
    # track: numbers
    ("track-seed-negative", TRACK + ["--seed", "-1"], "--seed"),
    ("track-seed-fraction", TRACK + ["--seed", "1.5"], "--seed"),
    ("track-seed-text", TRACK + ["--seed", "abc"], "--seed"),
    ("track-snr-inf", TRACK + ["--snr", "inf"], "--snr"),
    ("track-snr-nan", TRACK + ["--snr", "nan"], "--snr"),
    ("track-snr-zero", TRACK + ["--snr", "0"], "--snr"),
    ("track-snr-negative", TRACK + ["--snr", "-2"], "--snr"),
    ("track-particles-zero", TRACK + ["--method", "pf", "--particles", "0"], "--particles"),
    ("track-particles-negative", TRACK + ["--method", "pf", "--particles", "-5"], "--particles"),
    ("track-particles-absurd", TRACK + ["--method", "pf", "--particles", "2000000000"], "GiB"),
    ("track-particles-for-sgds", TRACK + ["--particles", "500"], "--particles"),
    ("track-threshold-above-one", TRACK + ["--method", "pf", "--threshold", "1.5"], "threshold"),
    ("track-threshold-zero", TRACK + ["--method", "pf", "--threshold", "0"], "--threshold"),
    ("track-min-peak-z-negative", TRACK + ["--min-peak-z", "-1"], "--min-peak-z"),
    ("track-fps-zero", TRACK + ["--fps", "0"], "--fps"),
    ("track-box-margin-negative", TRACK + ["--box-margin", "-1"], "--box-margin"),
    ("track-threads-zero", TRACK + ["--threads", "0"], "--threads"),
    ("track-param-unknown", TRACK + ["--param", "nonsense=3"], "nonsense"),
    ("track-param-malformed", TRACK + ["--param", "N_sump"], "--param"),
    ("track-param-out-of-range", TRACK + ["--param", "N_sump=0"], "N_sump"),
    ("track-param-wrong-type", TRACK + ["--param", "N_sump=many"], "N_sump"),
    ("track-init-box-garbled", TRACK + ["--init-box", "1,2,3"], "--init-box"),
    ("track-init-box-for-point-method", TRACK + ["--init-box", "1,2,3,4"], "box"),
    # track: choices
    ("track-arch-nonsense", TRACK + ["--arch", "nonsense"], "--arch"),
    ("track-method-unknown", TRACK + ["--method", "nonsense"], "--method"),
    ("track-engine-unknown", TRACK + ["--engine", "cupy"], "--engine"),
    ("track-profile-unknown", TRACK + ["--profile", "fast"], "--profile"),
    ("track-profile-contradiction", TRACK + ["--profile", "paper", "--real-video"], "--real-video"),
    ("track-background-unknown", TRACK + ["--background", "median"], "--background"),
    ("track-paper-saliency-pf", TRACK + ["--method", "pf", "--paper-saliency"], "--paper-saliency"),
    ("track-no-input", ["track", "--out", "{d}/out.csv"], "INPUT"),
    ("track-no-out", ["track", "{d}/good.npy"], "--out"),
    # track: outputs
    ("track-out-missing-folder", ["track", "{d}/good.npy", "--out", "{d}/missing/out.csv"], "does not exist"),
    ("track-out-is-folder", ["track", "{d}/good.npy", "--out", "{d}"], "is a folder"),
    ("track-out-under-a-file", ["track", "{d}/good.npy", "--out", "{d}/file/out.csv"], "does not exist"),
    ("track-out-is-input", ["track", "{d}/good.npy", "--out", "{d}/good.npy"], "input"),
    ("track-plot-extension", TRACK + ["--plot", "{d}/p.xyz"], "--plot"),
    ("track-plot-missing-folder", TRACK + ["--plot", "{d}/missing/p.png"], "--plot"),
    ("track-video-extension", TRACK + ["--video", "{d}/v.gif"], "--video"),
    ("track-video-missing-folder", TRACK + ["--video", "{d}/missing/v.mp4"], "--video"),
    ("track-video-is-out", TRACK + ["--video", "{d}/out.csv"], "--video"),
    # track: inputs
    ("track-input-missing", ["track", "{d}/none.npy", "--out", "{d}/out.csv"], "none.npy"),
    ("track-input-nan", ["track", "{d}/nan.npy", "--out", "{d}/out.csv"], "frame 7"),
    ("track-input-inf", ["track", "{d}/inf.npy", "--out", "{d}/out.csv"], "frame 7"),
    ("track-input-bool", ["track", "{d}/bool.npy", "--out", "{d}/out.csv"], "bool"),
    ("track-input-complex", ["track", "{d}/complex.npy", "--out", "{d}/out.csv"], "complex"),
    ("track-input-2d", ["track", "{d}/2d.npy", "--out", "{d}/out.csv"], "dimensions"),
    ("track-input-tiny-frames", ["track", "{d}/tiny.npy", "--out", "{d}/out.csv"], "tiny.npy"),
    ("track-input-no-frames", ["track", "{d}/empty.npy", "--out", "{d}/out.csv"], "empty.npy"),
    ("track-input-garbage-npy", ["track", "{d}/garbage.npy", "--out", "{d}/out.csv"], "garbage.npy"),
    ("track-input-corrupt-video", ["track", "{d}/corrupt.mp4", "--out", "{d}/out.csv"], "corrupt.mp4"),
    ("track-input-empty-video", ["track", "{d}/empty.mp4", "--out", "{d}/out.csv"], "empty.mp4"),
    ("track-input-truncated-video", ["track", "{d}/truncated.mp4", "--out", "{d}/out.csv"], "truncated.mp4"),
    ("track-input-empty-folder", ["track", "{d}/folder_empty", "--out", "{d}/out.csv"], "folder_empty"),
    ("track-input-unknown-suffix", ["track", "{d}/points.csv", "--out", "{d}/out.csv"], "points.csv"),
    # track: truth files (parsed before the run)
    ("track-truth-missing", TRACK + ["--truth", "{d}/none.csv"], "none.csv"),
    ("track-truth-binary", TRACK + ["--truth", "{d}/binary.csv"], "binary.csv"),
    ("track-truth-empty", TRACK + ["--truth", "{d}/empty.csv"], "empty.csv"),
    ("track-truth-latin1", TRACK + ["--truth", "{d}/latin1.csv"], "latin1.csv"),
    ("track-truth-garbled", TRACK + ["--truth", "{d}/garbled.csv"], "line 3"),
    ("track-truth-nan", TRACK + ["--truth", "{d}/nan_truth.csv"], "line 3"),
    ("track-truth-short-row", TRACK + ["--truth", "{d}/short_row.csv"], "line 3"),
    ("track-truth-no-columns", TRACK + ["--truth", "{d}/no_xy.csv"], "no_xy.csv"),
    ("track-truth-is-folder", TRACK + ["--truth", "{d}"], "is a folder"),
    # track --method mm-phd: its parameters and inputs (issue 37)
    ("mmphd-input-nan", ["track", "{d}/nan.npy", "--method", "mm-phd", "--out", "{d}/out.csv"], "frame 7"),
    ("mmphd-input-inf", ["track", "{d}/inf.npy", "--method", "mm-phd", "--out", "{d}/out.csv"], "frame 7"),
    ("mmphd-two-frames", ["track", "{d}/two.npy", "--method", "mm-phd", "--out", "{d}/out.csv"], "3"),
    ("mmphd-frame-below-window", ["track", "{d}/small.npy", "--method", "mm-phd", "--out", "{d}/out.csv",
                                  "--param", "psf_sigma=1.5"], "window"),
    ("mmphd-switch-rows", MMPHD + ["--param", "switch=0.5,0.1,0.1;0.3,0.6,0.1;0.3,0.1,0.6"], "switch"),
    ("mmphd-switch-shape", MMPHD + ["--param", "switch=0.5,0.5"], "switch"),
    ("mmphd-birth-models", MMPHD + ["--param", "birth_models=0.5,0.1,0.1"], "birth_models"),
    ("mmphd-imin-above-imax", MMPHD + ["--param", "i_min=20", "--param", "i_max=10"], "i_min"),
    ("mmphd-sigma-zero", MMPHD + ["--param", "psf_sigma=0"], "psf_sigma"),
    ("mmphd-interval-zero", MMPHD + ["--param", "frame_interval=0"], "frame_interval"),
    ("mmphd-births-zero", MMPHD + ["--param", "births=0"], "births"),
    ("mmphd-lmax-negative", MMPHD + ["--param", "max_particles=-4"], "max_particles"),
    ("mmphd-omega-zero", MMPHD + ["--param", "omega=0"], "omega"),
    ("mmphd-model-unknown", MMPHD + ["--param", "models=cv,zigzag"], "models"),
    ("mmphd-pool-overflow", MMPHD + ["--param", "max_tracks=1024", "--param", "max_particles=1000000"], "GiB"),
    # simulate
    ("simulate-shape-huge", ["simulate", "--shape", "20000", "20000", "--frames", "100", "--snr", "2",
                             "--out", "{d}/s.npz"], "GiB"),
    ("simulate-shape-small", ["simulate", "--shape", "4", "40", "--frames", "5", "--snr", "2", "--out", "{d}/s.npz"],
     "--shape"),
    ("simulate-shape-fraction", ["simulate", "--shape", "40.5", "40", "--frames", "5", "--snr", "2",
                                 "--out", "{d}/s.npz"], "--shape"),
    ("simulate-frames-zero", SIM[:4] + ["--frames", "0", "--snr", "2", "--out", "{d}/s.npz"], "--frames"),
    ("simulate-snr-inf", SIM[:6] + ["--snr", "inf", "--out", "{d}/s.npz"], "--snr"),
    ("simulate-targets-zero", SIM + ["--targets", "0"], "--targets"),
    ("simulate-seed-negative", SIM + ["--seed", "-3"], "--seed"),
    ("simulate-motion-unknown", SIM + ["--motion", "fly"], "--motion"),
    ("simulate-out-extension", SIM[:8] + ["--out", "{d}/sim.npy"], ".npz"),
    ("simulate-out-missing-folder", SIM[:8] + ["--out", "{d}/missing/sim.npz"], "does not exist"),
    # evaluate
    ("evaluate-ospa-p-zero", EVAL + ["--ospa-p", "0"], "--ospa-p"),
    ("evaluate-ospa-p-half", EVAL + ["--ospa-p", "0.5"], "--ospa-p"),
    ("evaluate-ospa-c-zero", EVAL + ["--ospa-c", "0"], "--ospa-c"),
    ("evaluate-t0-negative", EVAL + ["--t0", "-1"], "--t0"),
    ("evaluate-frames-zero", EVAL + ["--frames", "0"], "--frames"),
    ("evaluate-box-margin-nan", EVAL + ["--box-margin", "nan"], "--box-margin"),
    ("evaluate-tracks-missing", ["evaluate", "--tracks", "{d}/none.csv", "--truth", "{d}/points.csv"], "none.csv"),
    ("evaluate-tracks-binary", ["evaluate", "--tracks", "{d}/binary.csv", "--truth", "{d}/points.csv"], "binary.csv"),
    ("evaluate-tracks-garbled", ["evaluate", "--tracks", "{d}/bad_tracks.csv", "--truth", "{d}/points.csv"], "line 3"),
    ("evaluate-tracks-are-truth", ["evaluate", "--tracks", "{d}/points.csv", "--truth", "{d}/points.csv"],
     "track_id"),
    ("evaluate-truth-binary", ["evaluate", "--tracks", "{d}/tracks.csv", "--truth", "{d}/binary.csv"], "binary.csv"),
    ("evaluate-truth-empty", ["evaluate", "--tracks", "{d}/tracks.csv", "--truth", "{d}/empty.csv"], "empty.csv"),
    ("evaluate-truth-garbled", ["evaluate", "--tracks", "{d}/tracks.csv", "--truth", "{d}/garbled.csv"], "line 3"),
    # evaluate-suite
    ("suite-tests-zero", SUITE + ["--tests", "0"], "--tests"),
    ("suite-workers-zero", SUITE + ["--workers", "0"], "--workers"),
    ("suite-snrs-text", SUITE + ["--snrs", "1,abc"], "--snrs"),
    ("suite-snrs-inf", SUITE + ["--snrs", "1,inf"], "--snrs"),
    ("suite-methods-unknown", SUITE + ["--methods", "sgds,nonsense"], "--methods"),
    ("suite-tracker-snr-zero", SUITE + ["--tracker-snr", "0"], "--tracker-snr"),
    ("suite-seed-negative", SUITE + ["--seed", "-1"], "--seed"),
    ("suite-out-dir-is-file", ["evaluate-suite", "--quick", "--out-dir", "{d}/file"], "--out-dir"),
    ("suite-out-dir-parent-missing", ["evaluate-suite", "--quick", "--out-dir", "{d}/missing/deeper"], "--out-dir"),
    # bench
    ("bench-shape-huge", ["bench", "--shape", "20000", "20000"], "GiB"),
    ("bench-shape-small", ["bench", "--shape", "2", "2"], "--shape"),
    ("bench-frames-zero", BENCH[:4] + ["--frames", "0"], "--frames"),
    ("bench-runs-zero", BENCH + ["--runs", "0"], "--runs"),
    ("bench-engines-unknown", BENCH + ["--engines", "taichi,cupy"], "--engines"),
    ("bench-particles-negative", BENCH + ["--particles", "-1"], "--particles"),
    ("bench-particles-below-groups", BENCH + ["--particles", "3", "--groups", "5"], "--groups"),
    ("bench-snr-nan", BENCH + ["--snr", "nan"], "--snr"),
    # no command at all
    ("no-command", [], "COMMAND"),
    ("unknown-command", ["frobnicate"], "frobnicate"),
]


@pytest.mark.parametrize("args, offender", [c[1:] for c in CLI_CASES], ids=[c[0] for c in CLI_CASES])
def test_the_cli_refuses_bad_input_early_in_one_line(files, capsys, args, offender):
    code, err, seconds = cli_error(expand(args, files), capsys)
    lines = [line for line in err.splitlines() if line.strip()]
    assert code == 2, err
    assert len(lines) == 1 and "error:" in lines[0], err
    assert offender.replace("{d}", str(files)) in lines[0], lines[0]
    assert "Traceback" not in err
    assert seconds < ERROR_SECONDS, f"the error took {seconds:.1f} s"


def test_an_unwritable_output_folder_is_refused(files, capsys, monkeypatch):
    """Root may write anywhere, so the refusal is checked with os.access answering "no" for one folder."""
    locked = files / "locked"
    locked.mkdir(exist_ok=True)
    real_access = os.access
    monkeypatch.setattr(os, "access", lambda p, mode: False if Path(p) == locked else real_access(p, mode))
    code, err, _ = cli_error(expand(TRACK[:3] + [f"{locked}/out.csv"], files), capsys)
    assert code == 2 and "not writable" in err and "locked" in err
    code, err, _ = cli_error(expand(TRACK + ["--plot", f"{locked}/p.png"], files), capsys)
    assert code == 2 and "--plot" in err and "not writable" in err


@pytest.mark.skipif(os.geteuid() == 0, reason="root reads files whatever their mode")
def test_an_unreadable_truth_file_is_refused(files, capsys):
    locked = files / "locked.csv"
    shutil.copy(files / "points.csv", locked)
    locked.chmod(0)
    code, err, _ = cli_error(expand(TRACK + ["--truth", str(locked)], files), capsys)
    assert code == 2 and "locked.csv" in err and "not readable" in err


@pytest.mark.parametrize("args", [TRACK + ["--seed", "-1"], ["simulate", "--shape", "20000", "20000", "--frames",
                                                              "100", "--snr", "2", "--out", "{d}/s.npz"],
                                  TRACK + ["--truth", "{d}/binary.csv"]], ids=["seed", "memory", "binary-truth"])
def test_a_real_process_prints_one_line_and_no_traceback(files, args):
    res = subprocess.run([sys.executable, "-m", "tbd_taichi", *expand(args, files)], capture_output=True, text=True)
    assert res.returncode == 2 and res.stdout == ""
    assert len(res.stderr.strip().splitlines()) == 1 and "Traceback" not in res.stderr, res.stderr


# ---------------------------------------------------------------- the Python API

FRAME = np.zeros((24, 28), np.float32)


def api_tracker(**kw):
    return tbd.make_tracker("pf", (24, 28), n_particles=64, **kw)


def update_after_finish():
    tracker = api_tracker()
    tracker.update(FRAME)
    tracker.finish()
    tracker.update(FRAME)


def finish_twice():
    tracker = api_tracker()
    tracker.update(FRAME)
    tracker.finish()
    tracker.finish()


def frame_with_nan():
    tracker = api_tracker()
    tracker.update(FRAME)
    bad = FRAME.copy()
    bad[3, 3] = np.nan
    tracker.update(bad)


def mm_phd_two_frames():
    tracker = tbd.make_tracker("mm-phd", (24, 28), births=50, max_particles=100)
    tracker.update(FRAME)
    tracker.update(FRAME)
    tracker.finish()


API_CASES = [
    ("seed-negative", lambda: api_tracker(seed=-1), ParameterError, "seed"),
    ("seed-fraction", lambda: api_tracker(seed=1.5), ParameterError, "seed"),
    ("seed-bool", lambda: api_tracker(seed=True), ParameterError, "seed"),
    ("shape-one-side", lambda: tbd.make_tracker("pf", (24,)), ParameterError, "shape"),
    ("shape-zero", lambda: tbd.make_tracker("pf", (0, 28)), ParameterError, "shape"),
    ("method-unknown", lambda: tbd.make_tracker("kalman", (24, 28)), ParameterError, "kalman"),
    ("engine-unknown", lambda: api_tracker(engine="cupy"), ParameterError, "cupy"),
    ("profile-unknown", lambda: api_tracker(profile="fast"), ParameterError, "fast"),
    ("param-unknown", lambda: api_tracker(nonsense=1), ParameterError, "nonsense"),
    ("param-out-of-range", lambda: tbd.make_tracker("pf", (24, 28), n_particles=0), ParameterError, "n_particles"),
    ("particles-absurd", lambda: tbd.make_tracker("pf", (24, 28), n_particles=2_000_000_000), ParameterError, "GiB"),
    ("frame-wrong-shape", lambda: api_tracker().update(np.zeros((20, 28))), InputError, "frame 0"),
    ("frame-3d", lambda: api_tracker().update(np.zeros((2, 24, 28))), InputError, "frame 0"),
    ("frame-nan", frame_with_nan, InputError, "frame 1"),
    ("frame-bool", lambda: api_tracker().update(FRAME > 0), InputError, "bool"),
    ("frame-complex", lambda: api_tracker().update(FRAME.astype(np.complex64)), InputError, "complex"),
    ("frame-text", lambda: api_tracker().update("frame.png"), InputError, "frame 0"),
    ("update-after-finish", update_after_finish, ParameterError, "after finish"),
    ("finish-twice", finish_twice, ParameterError, "after finish"),
    ("evaluate-text", lambda: metrics.evaluate("tracks.csv", []), ParameterError, "tracks"),
    ("evaluate-missing-columns", lambda: metrics.evaluate({"frame": [0], "x": [1]}, []), ParameterError, "track_id"),
    ("evaluate-ragged-rows", lambda: metrics.evaluate([(0, 1, 2)], []), ParameterError, "tracks"),
    ("evaluate-nan-rows", lambda: metrics.evaluate([(0, 1, np.nan, 2)], []), ParameterError, "NaN"),
    ("evaluate-t0-negative", lambda: metrics.evaluate([], [], t0=-1), ParameterError, "t0"),
    ("evaluate-ospa-c-zero", lambda: metrics.evaluate([], [], ospa_c=0), ParameterError, "ospa_c"),
    ("evaluate-ospa-p-half", lambda: metrics.evaluate([], [], ospa_p=0.5), ParameterError, "ospa_p"),
    ("box-scores-no-size", lambda: metrics.box_scores([], [(0, 1, 2)], 5), ParameterError, "boxes"),
    ("mmphd-switch-rows", lambda: tbd.make_tracker("mm-phd", (24, 28), switch="0.5,0.5,0; 0,1,0; 0,0,0.9"),
     ParameterError, "switch"),
    ("mmphd-omega-zero", lambda: tbd.make_tracker("mm-phd", (24, 28), omega=0.0), ParameterError, "omega"),
    ("mmphd-model-unknown", lambda: tbd.make_tracker("mm-phd", (24, 28), models="cv,jump"), ParameterError,
     "models"),
    ("mmphd-below-window", lambda: tbd.make_tracker("mm-phd", (8, 8), psf_sigma=1.5), ParameterError, "window"),
    ("mmphd-two-frames", mm_phd_two_frames, InputError, "3 frames"),
    ("simulate-shape-huge", lambda: tbd.simulate((20000, 20000), 100), ParameterError, "GiB"),
    ("simulate-frames-zero", lambda: tbd.simulate((32, 32), 0), ParameterError, "frames"),
    ("simulate-snr-inf", lambda: tbd.simulate((32, 32), 5, snr=np.inf), ParameterError, "snr"),
    ("simulate-motion", lambda: tbd.simulate((32, 32), 5, motion="fly"), ParameterError, "motion"),
    ("open-frames-missing", lambda: tbd.io.open_frames("/nonexistent/clip.mp4"), InputError, "clip.mp4"),
    ("open-frames-bool", lambda: tbd.io.open_frames(np.zeros((3, 8, 8), bool)), InputError, "bool"),
    ("open-frames-nan", lambda: tbd.io.open_frames(np.full((3, 8, 8), np.nan)), InputError, "frame 0"),
    ("read-tracks-binary", lambda: tables.read_tracks(Path(__file__).parent / "data" / "IR_DRONE_021.mp4"),
     InputError, "binary"),
]


@pytest.mark.parametrize("call, error, offender", [c[1:] for c in API_CASES], ids=[c[0] for c in API_CASES])
def test_the_api_refuses_bad_input_with_its_own_error(call, error, offender):
    started = time.perf_counter()
    with pytest.raises(error) as caught:
        call()
    assert isinstance(caught.value, TBDError)
    message = str(caught.value)
    assert "\n" not in message and offender in message, message
    assert time.perf_counter() - started < ERROR_SECONDS + 20  # + a first kernel compile for the frame cases


# ---------------------------------------------------------------- good-input controls


@pytest.mark.parametrize("args", [EVAL, EVAL + ["--ospa-p", "1", "--ospa-c", "0.5", "--t0", "0", "--json"],
                                  ["evaluate", "--tracks", "{d}/tracks.csv", "--truth", "{boxes}", "--box-margin", "0"],
                                  SIM, SIM + ["--targets", "3", "--seed", "7", "--motion", "transit"]],
                         ids=["evaluate", "evaluate-edges", "evaluate-boxes", "simulate", "simulate-options"])
def test_good_input_is_accepted(files, capsys, args):
    code, err, _ = cli_error(expand(args, files), capsys)
    assert code == 0, err


def test_a_good_track_run_with_every_output_passes_the_checks(files, capsys):
    """The checks pass a run with every output and option given (an integer clip: the real-video profile)."""
    args = expand(TRACK + ["--method", "pf", "--particles", "200", "--threshold", "0.9", "--seed", "2",
                           "--truth", "{d}/points.csv", "--plot", "{d}/p.svg", "--video", "{d}/v.avi", "--fps", "7",
                           "--box-margin", "0", "--progress", "off", "--json"], files)
    code, err, _ = cli_error(args, capsys)
    assert code == 0, err
    assert (files / "p.svg").stat().st_size > 0 and (files / "v.avi").stat().st_size > 0


def test_good_api_input_is_accepted():
    tracker = tbd.make_tracker("pf", (24, 28), n_particles=64, seed=np.int64(3), profile="paper")
    for k in range(3):
        tracker.update(np.full((24, 28), k, np.int16))
    assert tracker.finish().dtype == tables.TRACK_DTYPE
    scores = metrics.evaluate([(0, 1, 5.0, 6.0)], [(0, 0, 5.0, 6.0)], t0=0.5, ospa_p=1)
    assert scores["dsr"] == 1.0
    assert tbd.simulate((8, 8), 1, snr=0.0).frames.shape == (1, 8, 8)
