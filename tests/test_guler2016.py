"""The guler2016 scenario: walls S1/S2 after Güler's 2016 thesis §3.1, a one-pixel target at the frame mean + Δ on
Motion 1 or 2, uint16 frames, and ``tbd-taichi simulate --scenario guler2016``."""
import json
import math

import numpy as np
import pytest

from tbd_taichi import cli, io, tables
from tbd_taichi.errors import ParameterError
from tbd_taichi.guler2016 import (DELTAS, FRAMES, MAX_VALUE, MEAN, SHAPE, check_guler2016, simulate_guler2016,
                                  truth_path, wall_background)

SIGMA_BAND = {"S1": (8.0, 10.0), "S2": (3.8, 4.8)}  # counts: the frame's std (the thesis: ≈ 9.2 and 4.1-4.5)
RANGE_BAND = {"S1": (50, 72), "S2": (30, 52)}  # counts: max − min of a frame (the thesis: 59 and 40)


@pytest.fixture(scope="module", params=[("S1", 1), ("S2", 2)], ids=["S1-motion1", "S2-motion2"])
def scene(request):
    wall, motion = request.param
    return simulate_guler2016(wall, motion, 30, seed=3)


def test_shape_dtype_and_14_bit_range(scene):
    assert scene.frames.shape == (FRAMES,) + SHAPE and scene.frames.dtype == np.uint16
    assert int(scene.frames.max()) <= MAX_VALUE
    p = scene.params
    assert p["scenario"] == "guler2016" and p["frames"] == FRAMES and p["shape"] == list(SHAPE) and p["seed"] == 3
    assert p["delta"] == 30 and json.dumps(p)


@pytest.mark.parametrize("wall", ["S1", "S2"])
@pytest.mark.parametrize("seed", [0, 1, 7])
def test_wall_statistics(wall, seed):
    """Every frame's mean within ±5 counts of the thesis's (the drift is ≤ 4), σ and the range of frame 0 in their
    bands, and the drift a slow change of a few counts."""
    bg = wall_background(wall, np.random.default_rng(seed), FRAMES).astype(float)
    means = bg.mean(axis=(1, 2))
    assert np.abs(means - MEAN[wall]).max() <= 5.0
    assert abs(means[0] - MEAN[wall]) < 0.5
    lo, hi = SIGMA_BAND[wall]
    assert lo <= bg[0].std() <= hi and np.all((bg.std(axis=(1, 2)) >= lo) & (bg.std(axis=(1, 2)) <= hi))
    assert RANGE_BAND[wall][0] <= np.ptp(bg[0]) <= RANGE_BAND[wall][1]
    assert 1.0 <= np.ptp(means) <= 4.5 and np.abs(np.diff(means)).max() < 0.5


def test_params_noise_figures(scene):
    p = scene.params
    bg = wall_background(p["wall"], np.random.default_rng(p["seed"]), 1)[0]
    assert p["sigma"] == pytest.approx(bg.std(dtype=np.float64))
    assert p["snr"] == pytest.approx(30 / p["sigma"]) and p["snr_thesis"] == pytest.approx(30 / (100 * p["sigma"]))


def test_s1_is_structured_and_s2_smooth():
    """The row-mean-removed temporal mean: S1 has edges and blobs at the target's scale (a 1-px Laplacian well
    above the noise's), S2 hardly any."""
    def fine_structure(wall):
        bg = wall_background(wall, np.random.default_rng(0), FRAMES).astype(float).mean(axis=0)
        bg -= bg.mean(axis=1, keepdims=True)
        lap = 4 * bg[1:-1, 1:-1] - bg[:-2, 1:-1] - bg[2:, 1:-1] - bg[1:-1, :-2] - bg[1:-1, 2:]
        return lap.std()
    assert fine_structure("S1") > 3 * fine_structure("S2")


def test_target_pixel_is_the_frame_mean_plus_delta(scene):
    """The frames equal the wall alone except at the truth pixel, which holds round(wall's frame mean + Δ)."""
    p = scene.params
    bg = wall_background(p["wall"], np.random.default_rng(p["seed"]), p["frames"])
    truth = scene.truth
    assert len(truth) == FRAMES and np.array_equal(truth["frame"], np.arange(FRAMES))
    assert np.all(truth["target_id"] == 0) and np.all(truth["intensity"] == 30)
    k, x, y = truth["frame"], truth["x"].astype(int), truth["y"].astype(int)
    assert np.array_equal(np.stack([x, y], 1), truth_path(p["motion"], FRAMES))
    diff = scene.frames != bg
    diff[k, y, x] = False
    assert not diff.any()
    expected = np.floor(bg.mean(axis=(1, 2), dtype=np.float64) + 30 + 0.5)
    assert np.array_equal(scene.frames[k, y, x], expected.astype(np.uint16))


def test_target_replaces_the_pixel_and_is_clipped():
    """A huge Δ saturates at 16383; a tiny Δ still replaces the pixel (the value is the mean + Δ, not pixel + Δ)."""
    big = simulate_guler2016("S2", 1, 1e6, seed=0, frames=4)
    assert np.all(big.frames[big.truth["frame"], big.truth["y"].astype(int), big.truth["x"].astype(int)] == MAX_VALUE)
    small = simulate_guler2016("S1", 1, 0.01, seed=0, frames=4)
    f = small.frames.astype(float)
    lit = f[np.arange(4), 69, small.truth["x"].astype(int)]
    assert np.all(np.abs(lit - f.mean(axis=(1, 2))) <= 0.52)


def test_motion_paths_by_hand():
    one = truth_path(1, FRAMES)
    assert [tuple(one[k]) for k in (0, 1, 2, 3, 133)] == [(0, 69), (0, 69), (1, 69), (1, 69), (66, 69)]
    two = truth_path(2, FRAMES)
    # 0.5/√2 = 0.35355 px per axis per frame: 0, 0.354, 0.707, 1.061, ... 47.02 -> rounded 0, 0, 1, 1, 47
    assert [tuple(two[k]) for k in (0, 1, 2, 3, 133)] == [(0, 39), (0, 39), (1, 40), (1, 40), (47, 86)]
    assert np.all(two[:, 1] - two[:, 0] == 39)  # 45°, down-right
    assert np.all((two >= 0) & (two < 100)) and np.all((one >= 0) & (one < 100))
    assert np.all(np.diff(two, axis=0) >= 0) and np.abs(np.diff(two, axis=0)).max() == 1
    cont = np.arange(FRAMES) * 0.5 / math.sqrt(2)
    assert np.abs(two[:, 0] - cont).max() <= 0.5


def test_long_sequence_target_leaves_and_truth_stops():
    sc = simulate_guler2016("S1", 2, 50, seed=1, frames=200)
    assert sc.frames.shape[0] == 200 and len(sc.truth) == 172 and sc.truth["frame"].max() == 171
    assert sc.truth[-1]["y"] == 99 and sc.params["frames_in_view"] == 172


def test_same_seed_same_frames_different_seed_different():
    a = simulate_guler2016("S1", 1, 20, seed=5, frames=10)
    b = simulate_guler2016("S1", 1, 20, seed=5, frames=10)
    c = simulate_guler2016("S1", 1, 20, seed=6, frames=10)
    assert np.array_equal(a.frames, b.frames) and np.array_equal(a.truth, b.truth)
    assert not np.array_equal(a.frames, c.frames)
    longer = simulate_guler2016("S1", 1, 20, seed=5, frames=20)
    assert np.array_equal(a.frames, longer.frames[:10])  # the first frames do not depend on the length
    other = simulate_guler2016("S1", 2, 60, seed=5, frames=10)  # the same wall under another motion and Δ
    same = np.ones_like(a.frames, bool)
    for sc in (a, other):
        same[sc.truth["frame"], sc.truth["y"].astype(int), sc.truth["x"].astype(int)] = False
    assert np.array_equal(a.frames[same], other.frames[same])


def test_every_thesis_delta_is_accepted():
    for delta in DELTAS:
        check_guler2016("S1", 1, delta, FRAMES)


@pytest.mark.parametrize("args, offender", [
    (("S3", 1, 30, 134), "wall"), ((1, 1, 30, 134), "wall"), (("S1", 3, 30, 134), "motion"),
    (("S1", "1", 30, 134), "motion"), (("S1", True, 30, 134), "motion"), (("S1", 1, 0, 134), "delta"),
    (("S1", 1, -5, 134), "delta"), (("S1", 1, float("nan"), 134), "delta"), (("S1", 1, float("inf"), 134), "delta"),
    (("S1", 1, 30, 3), "frames"), (("S1", 1, 30, 5001), "frames"), (("S1", 1, 30, 10.5), "frames")])
def test_api_bad_arguments_are_one_line_errors(args, offender):
    with pytest.raises(ParameterError) as caught:
        simulate_guler2016(*args[:3], frames=args[3])
    message = str(caught.value)
    assert offender in message and "\n" not in message


@pytest.mark.parametrize("call, offender", [
    (lambda: simulate_guler2016("S1", 1, 30, noise_share=1.5), "noise_share"),
    (lambda: simulate_guler2016("S1", 1, 30, seed=-1), "seed"),
    (lambda: wall_background("S9", np.random.default_rng(0), 4), "wall")])
def test_other_bad_arguments(call, offender):
    with pytest.raises(ParameterError, match=offender):
        call()


def test_noise_share_splits_the_variance():
    quiet = wall_background("S1", np.random.default_rng(2), 6, noise_share=0.0).astype(float)
    assert np.abs(np.diff(quiet, axis=0) - np.diff(quiet.mean(axis=(1, 2)))[:, None, None]).max() <= 1.0
    noisy = wall_background("S1", np.random.default_rng(2), 6, noise_share=1.0).astype(float)
    temporal = (noisy - noisy.mean(axis=0)).std() * math.sqrt(6 / 5)
    assert temporal == pytest.approx(9.2, rel=0.05)


# ---------------------------------------------------------------- the command line


def test_simulate_cli_writes_uint16_frames_and_point_truth(tmp_path, capsys):
    out = tmp_path / "g.npz"
    assert cli.main(["simulate", "--scenario", "guler2016", "--wall", "S2", "--motion", "2", "--delta", "20",
                     "--frames", "12", "--seed", "4", "--out", str(out)]) == 0
    assert "S2" in capsys.readouterr().out
    with np.load(out) as npz:
        frames, params = npz["frames"], json.loads(str(npz["params"]))
    ref = simulate_guler2016("S2", 2, 20, seed=4, frames=12)
    assert frames.dtype == np.uint16 and np.array_equal(frames, ref.frames)
    assert params["wall"] == "S2" and params["motion"] == 2 and params["delta"] == 20
    truth_csv = tmp_path / "g_truth.csv"
    assert truth_csv.read_text().splitlines()[0] == "frame,target_id,x,y,vx,vy,intensity"
    kind, truth = tables.read_any_truth(truth_csv)
    assert kind == "points" and len(truth) == 12
    assert np.array_equal(np.stack([truth["x"], truth["y"]], 1), truth_path(2, 12))
    loaded = io.read_frames(out)
    assert loaded.dtype == np.float32 and np.array_equal(loaded, frames.astype(np.float32))
    rows = [(r["frame"], 0, r["x"], r["y"], 0, 0, 1, 1) for r in truth]  # the truth as tracks scores perfectly
    tables.write_csv(tables.make_table(rows, tables.TRACK_DTYPE), tmp_path / "k.csv")
    assert cli.main(["evaluate", "--tracks", str(tmp_path / "k.csv"), "--truth", str(truth_csv), "--json"]) == 0
    scores = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert scores["dsr"] == 1.0 and scores["edt_mean"] == 0


def test_simulate_cli_defaults(tmp_path, capsys):
    out = tmp_path / "d.npz"
    assert cli.main(["simulate", "--scenario", "guler2016", "--out", str(out)]) == 0
    with np.load(out) as npz:
        params = json.loads(str(npz["params"]))
        assert npz["frames"].shape == (FRAMES,) + SHAPE
    assert (params["wall"], params["motion"], params["delta"], params["frames"]) == ("S1", 1, 30, FRAMES)


@pytest.mark.parametrize("argv, message", [
    (["--wall", "S3"], "--wall"), (["--motion", "3"], "--motion"), (["--motion", "stay"], "--motion 1 or 2"),
    (["--delta", "0"], "--delta"), (["--delta", "-2"], "--delta"), (["--delta", "nan"], "--delta"),
    (["--delta", "inf"], "--delta"), (["--frames", "3"], "--frames"), (["--frames", "5001"], "--frames"),
    (["--snr", "2"], "--snr applies to --scenario jia2022"), (["--ptcr", "3"], "--ptcr applies"),
    (["--sequence", "weak"], "--sequence applies")])
def test_simulate_cli_errors(tmp_path, capsys, argv, message):
    """A bad or foreign argument is one line naming it, exit 2, and nothing is written."""
    try:
        code = cli.main(["simulate", "--scenario", "guler2016", *argv, "--out", str(tmp_path / "g.npz")])
    except SystemExit as exc:
        code = exc.code
    err = capsys.readouterr().err
    assert code == 2 and message in err and err.count("\n") == 1, err
    assert not (tmp_path / "g.npz").exists()


@pytest.mark.parametrize("argv, message", [
    (["--shape", "20", "20", "--frames", "5", "--snr", "2", "--motion", "1"], "--scenario jia2022 takes --motion stay"),
    (["--shape", "20", "20", "--frames", "5", "--snr", "2", "--wall", "S1"], "--wall applies to --scenario guler2016"),
    (["--shape", "20", "20", "--frames", "5", "--snr", "2", "--delta", "5"], "--delta applies to --scenario guler2016"),
    (["--scenario", "huo2022", "--motion", "2"], "--motion applies to --scenario jia2022 or guler2016")])
def test_guler2016_arguments_refused_elsewhere(tmp_path, capsys, argv, message):
    code = cli.main(["simulate", *argv, "--out", str(tmp_path / "s.npz")])
    err = capsys.readouterr().err
    assert code == 2 and message in err and err.count("\n") == 1, err
