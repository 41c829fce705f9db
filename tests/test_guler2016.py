"""The guler2016 scenario: walls S1/S2 after Güler's 2016 thesis §3.1, a one-pixel target at the frame mean + Δ on
Motion 1 or 2, uint16 frames, and ``tbd-taichi simulate --scenario guler2016``."""
import json
import math

import numpy as np
import pytest

from tbd_taichi import cli, io, tables
from tbd_taichi.errors import ParameterError
from tbd_taichi.guler2016 import (DELTAS, FRAMES, MAX_VALUE, MEAN, NOISE_SHARE, NOISE_STREAM, RECORDING, SHAPE, SIGMA,
                                  START_PIXELS, check_guler2016, simulate_guler2016, start_levels, static_wall,
                                  truth_path, wall_background)

# Measured over wall seeds 0-39 (noise seed = wall seed) and over noise seeds 0-39 on the recording (module
# docstring): σ of every frame S1 9.08-9.33, S2 4.20-4.42; max - min of frame 0 S1 47-67, S2 32-43.
SIGMA_BAND = {"S1": (8.95, 9.45), "S2": (4.1, 4.55)}  # counts: the frame's std (the thesis: 9.15-9.26, 4.13-4.45)
RANGE_BAND = {"S1": (44, 72), "S2": (28, 48)}  # counts: max − min of frame 0 (the thesis: 59 and 40)
SIGMA_N = 3.5  # counts: the temporal noise on both walls (S1 9.2·√0.15 = 3.56, S2 4.3·√0.65 = 3.47)


def wall_of(p, frames=None):
    """The wall alone under a scene's params: the static part from default_rng(wall_seed), the drift and the
    noise from default_rng([seed, NOISE_STREAM])."""
    return wall_background(p["wall"], np.random.default_rng(p["wall_seed"]), p["frames"] if frames is None else frames,
                           p["noise_share"], np.random.default_rng([p["seed"], NOISE_STREAM]))


def fine_structure(image):
    """The std of the 1-px Laplacian of ``image`` with its row means removed (counts)."""
    bg = image - image.mean(axis=1, keepdims=True)
    return (4 * bg[1:-1, 1:-1] - bg[:-2, 1:-1] - bg[2:, 1:-1] - bg[1:-1, :-2] - bg[1:-1, 2:]).std()


def off_target(*scenes):
    """True where none of ``scenes`` has its target."""
    keep = np.ones_like(scenes[0].frames, bool)
    for sc in scenes:
        keep[sc.truth["frame"], sc.truth["y"].astype(int), sc.truth["x"].astype(int)] = False
    return keep


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
    assert p["wall_seed"] == RECORDING[p["wall"]] and p["noise_share"] == NOISE_SHARE[p["wall"]]


@pytest.mark.parametrize("wall", ["S1", "S2"])
@pytest.mark.parametrize("wall_seed, seed", [("rec", 0), ("rec", 1), ("rec", 7), (0, 0), (1, 1), (7, 7)])
def test_wall_statistics(wall, wall_seed, seed):
    """On the recording (several noise seeds) and on other walls: every frame's mean within ±5 counts of the
    thesis's (the drift is ≤ 4), σ of every frame and the range of frame 0 in their bands, the drift a slow
    change of a few counts, and S2's cold tail (mean − min > max − mean)."""
    wall_seed = RECORDING[wall] if wall_seed == "rec" else wall_seed
    bg = wall_background(wall, np.random.default_rng(wall_seed), FRAMES, None,
                         np.random.default_rng([seed, NOISE_STREAM])).astype(float)
    means = bg.mean(axis=(1, 2))
    assert np.abs(means - MEAN[wall]).max() <= 5.0
    assert abs(means[0] - MEAN[wall]) < 0.5
    lo, hi = SIGMA_BAND[wall]
    sds = bg.std(axis=(1, 2))
    assert np.all((sds >= lo) & (sds <= hi)), (sds.min(), sds.max())
    assert RANGE_BAND[wall][0] <= np.ptp(bg[0]) <= RANGE_BAND[wall][1]
    assert 1.0 <= np.ptp(means) <= 4.5 and np.abs(np.diff(means)).max() < 0.5
    if wall == "S2":
        assert means[0] - bg[0].min() > bg[0].max() - means[0] + 2


def test_one_temporal_noise_on_both_walls():
    """σ_n ≈ 3.5 counts on both walls (frame-to-frame differences less the drift); S1's σ is mostly its static
    structure (8.5 counts), S2's mostly noise (static 2.5)."""
    static_sd = {}
    for wall in ("S1", "S2"):
        bg = simulate_guler2016(wall, 1, 30, seed=2, frames=40).frames.astype(float)
        d = np.diff(bg, axis=0)[:, :, 40:]  # away from the target (columns 0-19 in these frames)
        d -= d.mean(axis=(1, 2), keepdims=True)  # the drift
        noise = d.std() / math.sqrt(2)  # includes the rounding's 1/12
        assert noise == pytest.approx(SIGMA_N, abs=0.2), wall
        assert noise == pytest.approx(SIGMA[wall] * math.sqrt(NOISE_SHARE[wall] + 1 / 12 / SIGMA[wall] ** 2), rel=0.03)
        static_sd[wall] = static_wall(wall, RECORDING[wall]).std()
        assert static_sd[wall] == pytest.approx(SIGMA[wall] * math.sqrt(1 - NOISE_SHARE[wall]), rel=1e-6)
    assert static_sd["S1"] > 2 * SIGMA_N > SIGMA_N > static_sd["S2"]


def test_start_pixels_are_the_first_lit_pixels():
    lit = [tuple(int(v) for v in truth_path(m, 3)[k]) for m in (1, 2) for k in range(3)]
    assert list(dict.fromkeys(lit)) == list(START_PIXELS) == [(0, 69), (1, 69), (0, 39), (1, 40)]


@pytest.mark.parametrize("wall", ["S1", "S2"])
def test_recording_is_the_first_wall_seed_with_cool_start_pixels(wall):
    """RECORDING[wall] is the first wall seed whose four start pixels lie within 1.5·σ_n of the frame mean."""
    sigma_n = SIGMA[wall] * math.sqrt(NOISE_SHARE[wall])
    meets = [bool(np.all(np.abs(start_levels(wall, s)) <= 1.5 * sigma_n)) for s in range(RECORDING[wall] + 1)]
    assert meets == [False] * RECORDING[wall] + [True]


@pytest.mark.parametrize("wall", ["S1", "S2"])
def test_start_levels_are_the_frames_levels(wall):
    """start_levels is what the frames show at the start pixels: without noise, each frame's pixel less its frame
    mean to the rounding; with the default noise, the mean over 134 frames to its noise (σ_n/√134 ≈ 0.3)."""
    levels = start_levels(wall, 4, noise_share=0.0)
    assert levels.shape == (4,) and np.ptp(levels) > 0.5
    sc = simulate_guler2016(wall, 1, 30, seed=1, wall_seed=4, noise_share=0.0, frames=FRAMES)
    f = sc.frames.astype(float)
    f[sc.truth["frame"], sc.truth["y"].astype(int), sc.truth["x"].astype(int)] = np.nan  # the target's pixels
    rel = f - np.nanmean(f, axis=(1, 2), keepdims=True)
    for (x, y), level in zip(START_PIXELS, levels):
        seen = rel[:, y, x][~np.isnan(rel[:, y, x])]
        assert len(seen) > 100 and np.abs(seen - level).max() <= 0.6
    rec = simulate_guler2016(wall, 2, 30, seed=1, frames=FRAMES)
    f = rec.frames.astype(float)
    f[rec.truth["frame"], rec.truth["y"].astype(int), rec.truth["x"].astype(int)] = np.nan
    mean = np.nanmean(f - np.nanmean(f, axis=(1, 2), keepdims=True), axis=0)
    assert np.abs([mean[y, x] for x, y in START_PIXELS[:2]] - start_levels(wall, RECORDING[wall])[:2]).max() < 1.5


def test_params_noise_figures(scene):
    p = scene.params
    bg = wall_of(p, 1)[0]
    assert p["sigma"] == pytest.approx(bg.std(dtype=np.float64))
    assert p["snr"] == pytest.approx(30 / p["sigma"]) and p["snr_thesis"] == pytest.approx(30 / (100 * p["sigma"]))


def test_s1_is_structured_and_s2_smooth():
    """The static walls' 1-px Laplacian (row means removed): S1 has edges and blobs at the target's scale, S2
    hardly any; and S1's is kept well below the noise's (σ_n·√20 ≈ 16), so that a top-hat candidate stage at
    α = 3 can find Δ = 20 (S1 measured 2.2–3.2 counts over wall seeds 0–9; blob and grain weights 0.9, 0.4
    gave 5.6–6.9)."""
    for wall_seed in [RECORDING["S1"], 0, 1, 2, 3]:
        s1 = fine_structure(static_wall("S1", wall_seed))
        s2 = fine_structure(static_wall("S2", wall_seed))
        assert 1.5 < s1 < 4.0 and s1 > 10 * s2, (wall_seed, s1, s2)


def test_target_pixel_is_the_frame_mean_plus_delta(scene):
    """The frames equal the wall alone except at the truth pixel, which holds round(wall's frame mean + Δ)."""
    p = scene.params
    bg = wall_of(p)
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


def test_same_seeds_same_frames():
    a = simulate_guler2016("S1", 1, 20, seed=5, frames=10)
    b = simulate_guler2016("S1", 1, 20, seed=5, frames=10)
    assert np.array_equal(a.frames, b.frames) and np.array_equal(a.truth, b.truth) and a.params == b.params
    given = simulate_guler2016("S1", 1, 20, seed=5, frames=10, wall_seed=RECORDING["S1"])
    assert np.array_equal(a.frames, given.frames)  # wall_seed None is the recording
    longer = simulate_guler2016("S1", 1, 20, seed=5, frames=20)
    assert np.array_equal(a.frames, longer.frames[:10])  # the first frames do not depend on the length
    other = simulate_guler2016("S1", 2, 60, seed=5, frames=10)  # the same wall under another motion and Δ
    same = off_target(a, other)
    assert np.array_equal(a.frames[same], other.frames[same])


@pytest.mark.parametrize("wall", ["S1", "S2"])
def test_other_seed_same_wall_other_noise(wall):
    """Another ``seed`` on the same wall_seed: the same static wall (without noise each frame less its mean equal
    to the rounding; with it the means of 134 frames equal to their noise), but other noise."""
    quiet = [simulate_guler2016(wall, 1, 20, seed=s, noise_share=0.0) for s in (5, 6)]
    keep = off_target(*quiet)
    rel = [sc.frames.astype(float) - sc.frames.mean(axis=(1, 2), keepdims=True) for sc in quiet]
    assert np.abs(rel[0] - rel[1])[keep].max() <= 1.2
    assert not np.array_equal(quiet[0].frames, quiet[1].frames)  # the drift differs
    a, c = (simulate_guler2016(wall, 1, 20, seed=s) for s in (5, 6))
    keep = off_target(a, c)
    fa, fc = a.frames.astype(float), c.frames.astype(float)
    fa[~keep], fc[~keep] = np.nan, np.nan
    ma, mc = (np.nanmean(f - np.nanmean(f, axis=(1, 2), keepdims=True), axis=0) for f in (fa, fc))
    assert np.abs(ma - mc).max() < 2.5  # √2·σ_n/√134 ≈ 0.43 counts apart
    static = static_wall(wall, RECORDING[wall])
    assert np.abs(ma - (static - static.mean())).max() < 2.0
    na, nc = (f - m - np.nanmean(f - m, axis=(1, 2), keepdims=True) for f, m in ((fa, ma), (fc, mc)))
    ok = ~np.isnan(na) & ~np.isnan(nc)
    assert np.nanstd(na - nc) > 1.2 * SIGMA_N  # independent noise: √2·σ_n apart
    assert abs(np.corrcoef(na[ok], nc[ok])[0, 1]) < 0.05


@pytest.mark.parametrize("wall", ["S1", "S2"])
def test_other_wall_seed_other_wall(wall):
    """Another wall_seed with the same ``seed``: another static wall (the noise aside, hardly correlated)."""
    s = [static_wall(wall, w) for w in (RECORDING[wall], RECORDING[wall] + 1)]
    assert np.corrcoef(s[0].ravel(), s[1].ravel())[0, 1] < 0.8
    a, b = (simulate_guler2016(wall, 1, 20, seed=5, wall_seed=w, noise_share=0.0, frames=4)
            for w in (RECORDING[wall], RECORDING[wall] + 1))
    keep = off_target(a, b)
    rel = [sc.frames.astype(float) - sc.frames.mean(axis=(1, 2), keepdims=True) for sc in (a, b)]
    assert np.abs(rel[0] - rel[1])[keep].max() > 5
    assert (a.params["wall_seed"], b.params["wall_seed"]) == (RECORDING[wall], RECORDING[wall] + 1)


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
    (lambda: wall_background("S9", np.random.default_rng(0), 4), "wall"),
    (lambda: simulate_guler2016("S1", 1, 30, wall_seed=-1), "wall_seed"),
    (lambda: simulate_guler2016("S1", 1, 30, wall_seed=2.0), "wall_seed"),
    (lambda: simulate_guler2016("S1", 1, 30, wall_seed=True), "wall_seed"),
    (lambda: start_levels("S1", -3), "wall_seed"), (lambda: start_levels("S3", 0), "wall"),
    (lambda: static_wall("S2", 0, noise_share=-0.1), "noise_share")])
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
    assert params["wall_seed"] == RECORDING["S2"] and params["seed"] == 4
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
    assert (params["wall_seed"], params["seed"]) == (RECORDING["S1"], 0)


def test_simulate_cli_wall_seed(tmp_path, capsys):
    """--wall-seed draws the wall, --seed the noise: the frames are the API's with both."""
    out = tmp_path / "w.npz"
    assert cli.main(["simulate", "--scenario", "guler2016", "--wall-seed", "4", "--seed", "2", "--frames", "6",
                     "--out", str(out)]) == 0
    assert "wall seed 4" in capsys.readouterr().out
    with np.load(out) as npz:
        frames, params = npz["frames"], json.loads(str(npz["params"]))
    assert params["wall_seed"] == 4 and params["seed"] == 2
    assert np.array_equal(frames, simulate_guler2016("S1", 1, 30, seed=2, frames=6, wall_seed=4).frames)
    assert not np.array_equal(frames, simulate_guler2016("S1", 1, 30, seed=2, frames=6).frames)


@pytest.mark.parametrize("argv, message", [
    (["--wall", "S3"], "--wall"), (["--motion", "3"], "--motion"), (["--motion", "stay"], "--motion 1 or 2"),
    (["--delta", "0"], "--delta"), (["--delta", "-2"], "--delta"), (["--delta", "nan"], "--delta"),
    (["--delta", "inf"], "--delta"), (["--frames", "3"], "--frames"), (["--frames", "5001"], "--frames"),
    (["--snr", "2"], "--snr applies to --scenario jia2022"), (["--ptcr", "3"], "--ptcr applies"),
    (["--sequence", "weak"], "--sequence applies"), (["--wall-seed", "-1"], "--wall-seed"),
    (["--wall-seed", "1.5"], "--wall-seed"), (["--wall-seed", "x"], "--wall-seed")])
def test_simulate_cli_errors(simulate_error, argv, message):
    """A bad or foreign argument is one line naming it, exit 2, and nothing is written."""
    code, err, written = simulate_error("guler2016", argv)
    assert code == 2 and message in err and err.count("\n") == 1, err
    assert not written


@pytest.mark.parametrize("argv, message", [
    (["--shape", "20", "20", "--frames", "5", "--snr", "2", "--motion", "1"], "--scenario jia2022 takes --motion stay"),
    (["--shape", "20", "20", "--frames", "5", "--snr", "2", "--wall", "S1"], "--wall applies to --scenario guler2016"),
    (["--shape", "20", "20", "--frames", "5", "--snr", "2", "--delta", "5"], "--delta applies to --scenario guler2016"),
    (["--scenario", "huo2022", "--motion", "2"], "--motion applies to --scenario jia2022 or guler2016"),
    (["--scenario", "huo2022", "--wall-seed", "0"], "--wall-seed applies to --scenario guler2016"),
    (["--shape", "20", "20", "--frames", "5", "--snr", "2", "--wall-seed", "3"],
     "--wall-seed applies to --scenario guler2016")])
def test_guler2016_arguments_refused_elsewhere(tmp_path, capsys, argv, message):
    code = cli.main(["simulate", *argv, "--out", str(tmp_path / "s.npz")])
    err = capsys.readouterr().err
    assert code == 2 and message in err and err.count("\n") == 1, err
