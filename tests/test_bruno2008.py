"""The bruno2008 simulator (Bruno, Araújo & Pavlov 2008, §2 and §4): the vehicle templates, the PTCR, Eq. 8's
placement (x = column, y = row, cut at the borders), the GMRF clutter's covariance (Eq. 14), the motion (Eq. 4)
and aspect chain (Eq. 1), exit and re-entry, reproducibility, its CLI and its errors."""
import math

import numpy as np
import pytest
from scipy import sparse, stats
from scipy.sparse.linalg import splu

from tbd_taichi import cli, tables
from tbd_taichi.bruno2008 import (BETA_H, BETA_V, EMPTY_FRAMES, FRAMES, SHAPE, SIGMA_C, local_mean, ptcr_peak,
                                  simulate_bruno2008, streams, target_path, vehicle_templates)
from tbd_taichi.errors import ParameterError
from tbd_taichi.gmrf import sample_gmrf
from tbd_taichi.multiaspect import PAPER_G, PAPER_PRIOR, check_templates, motion_noise

HUGE = (10 ** 6, 10 ** 6)  # a frame no path leaves: long paths for the motion and aspect statistics
HALVES = (5, 5)


def _target_images(scene):
    """frames − local mean − clutter, recomputed from the seed's streams (the clutter as one draw of all frames)."""
    mean_rng, _, clutter_rng = streams(scene.params["seed"])
    clutter = sample_gmrf(clutter_rng, SHAPE, BETA_H, BETA_V, SIGMA_C, len(scene.frames))
    return scene.frames.astype(float) - local_mean(mean_rng) - clutter


def _expected_images(scene, templates):
    """Eq. 8 written out pixel by pixel: a[k, l] of the row's aspect at row round(y) + k − 5, column
    round(x) + l − 5 (halves up), the pixels outside the image dropped (Remark 1)."""
    out = np.zeros(scene.frames.shape)
    for row in scene.truth:
        qx, qy = math.floor(row["x"] + 0.5), math.floor(row["y"] + 0.5)
        t = templates[row["aspect"] - 1]
        for k in range(11):
            for l in range(11):
                r, c = qy + k - 5, qx + l - 5
                if 0 <= r < SHAPE[0] and 0 <= c < SHAPE[1]:
                    out[row["frame"], r, c] += t[k, l]
    return out


def test_vehicle_templates():
    """Four valid 11×11 templates, the centroid pixel on the vehicle, a zero border ring (the whole vehicle
    fits), max = peak; rotation and shear keep the area (sum within 2 % of the reference: 4×4 supersampling),
    the 0.85 scale makes it 0.85² = 0.7225 (within 2 %); adjacent aspects correlate more than aspects 1 and 4."""
    t = vehicle_templates(peak=2.5)
    assert check_templates(t).shape == (4, 9, 9)
    assert np.all(t[:, 5, 5] > 0) and t.max() == pytest.approx(2.5, abs=1e-12) and t.min() == 0.0
    ring = np.concatenate([t[:, 0, :], t[:, -1, :], t[:, :, 0], t[:, :, -1]], axis=1)
    assert not ring.any()
    sums = t.sum(axis=(1, 2)) / t[0].sum()
    assert sums[[1, 3]] == pytest.approx([1.0, 1.0], rel=0.02) and sums[2] == pytest.approx(0.85 ** 2, rel=0.02)
    corr = np.corrcoef(t.reshape(4, -1))
    assert min(corr[0, 1], corr[1, 2], corr[2, 3]) > corr[0, 3] + 0.1
    assert np.array_equal(vehicle_templates(1.0) * 2.5, t)


def test_ptcr_and_placement_on_the_frames():
    """With the seed's mean and clutter removed, what is left is exactly Eq. 8 (float32 frames near 100: 1e-4)
    with the peak σ_c·10^(PTCR/20): x is the column and y the row; intensity and aspect columns agree."""
    scene = simulate_bruno2008(seed=3, ptcr_db=8.1)
    peak = 10 ** (8.1 / 20) * SIGMA_C
    assert ptcr_peak(8.1) == pytest.approx(peak) and ptcr_peak(6.5) == pytest.approx(2.1135, abs=1e-4)
    target = _target_images(scene)
    assert target.max() == pytest.approx(peak, abs=1e-4)
    assert np.abs(target - _expected_images(scene, vehicle_templates(peak))).max() < 1e-4
    tr = scene.truth
    assert np.array_equal(tr["frame"], np.arange(FRAMES)) and np.all(tr["target_id"] == 0)
    assert np.allclose(tr["intensity"], peak) and set(tr["aspect"].tolist()) <= {1, 2, 3, 4}
    assert np.all(np.abs(np.diff(tr["aspect"])) <= 1)  # G moves only to adjacent aspects
    swapped = scene.truth.copy()
    swapped["x"], swapped["y"] = tr["y"], tr["x"]
    assert np.abs(target - _expected_images(type(scene)(scene.frames, swapped), vehicle_templates(peak))).max() > 1


def test_clutter_covariance_matches_eq14():
    """(frame − local mean) away from the target (> 7 px from its centroid) and the border (10 px) over 100
    frames: its variance and lag-1 correlations match σ_c²·A⁻¹ of Eq. 14 (A built as a sparse matrix, β_h on
    columns, β_v on rows; solved at the centre pixel: 1.515, 0.361 horizontal, 0.377 vertical).  Over 8 seeds
    the estimates' sd is 0.15 % (variance) and 0.0008 (correlations): 1.5 % and 0.005 allow 6+ sd, while
    swapping β_h and β_v moves the correlations by 0.017."""
    scene = simulate_bruno2008(seed=5, frames=100)
    v = scene.frames.astype(float) - local_mean(streams(5)[0])
    keep = np.ones(v.shape, bool)
    for row in scene.truth:
        qx, qy = math.floor(row["x"] + 0.5), math.floor(row["y"] + 0.5)
        keep[row["frame"], max(qy - 7, 0):qy + 8, max(qx - 7, 0):qx + 8] = False
    v, keep = v[:, 10:110, 10:110], keep[:, 10:110, 10:110]
    var = (v ** 2)[keep].mean()
    both_h, both_v = keep[:, :, :-1] & keep[:, :, 1:], keep[:, :-1, :] & keep[:, 1:, :]
    rho_h = (v[:, :, :-1] * v[:, :, 1:])[both_h].mean() / var
    rho_v = (v[:, :-1, :] * v[:, 1:, :])[both_v].mean() / var
    (h, w) = SHAPE
    band = lambda n: sparse.diags([np.ones(n - 1), np.ones(n - 1)], [-1, 1])
    a = (sparse.kron(sparse.identity(h), sparse.identity(w) - BETA_H * band(w))
         - BETA_V * sparse.kron(band(h), sparse.identity(w)))
    e = np.zeros(h * w)
    e[60 * w + 60] = 1.0
    cov = SIGMA_C ** 2 * splu(a.tocsc()).solve(e).reshape(h, w)
    assert var == pytest.approx(cov[60, 60], rel=0.015)
    assert rho_h == pytest.approx(cov[60, 61] / cov[60, 60], abs=0.005)
    assert rho_v == pytest.approx(cov[61, 60] / cov[60, 60], abs=0.005)
    assert abs(v[keep].mean()) < 0.05  # the local mean is removed exactly (clutter mean's sd ≈ 0.005)


def test_prior_and_motion_noise():
    """§4's prior over 400 paths (column in [10, 20], row in [50, 70], v mean 2 ± 0.02 (SE 0.005), sd 0.1
    ± 15 % (SE 3.5 %), aspect uniform: χ²₃ < 16.3 = p 0.001); then Eq. 4's CWNA over a 4000-frame path: the
    velocity increments' sd 0.098 px/frame and the position innovations' 0.057 px within 5 % (SE 1.1 %), their
    correlation √3/2 within 0.02 (SE 0.004); and the simulator's truth over 30 seeds (1140 increments, SE 2.1 %)
    within 10 %."""
    rng = np.random.default_rng(11)
    starts = np.concatenate([target_path(rng, 1, HUGE, HALVES, PAPER_G) for _ in range(400)])
    assert starts["x"].min() >= 10 and starts["x"].max() <= 20 and starts["y"].min() >= 50 and starts["y"].max() <= 70
    v0 = np.concatenate([starts["vx"], starts["vy"]])
    assert v0.mean() == pytest.approx(PAPER_PRIOR["v_mean"], abs=0.02) and v0.std() == pytest.approx(0.1, rel=0.15)
    assert stats.chisquare(np.bincount(starts["aspect"], minlength=5)[1:]).statistic < 16.3
    q = motion_noise(6.0, 0.04, 0.2)
    path = target_path(rng, 4000, HUGE, HALVES, PAPER_G)
    assert len(path) == 4000 and np.array_equal(path["frame"], np.arange(4000))
    for p, v in (("x", "vx"), ("y", "vy")):
        dv, dp = np.diff(path[v]), np.diff(path[p]) - path[v][:-1]
        assert math.sqrt(q[1, 1]) == pytest.approx(0.098, abs=1e-3)
        assert dv.std() == pytest.approx(math.sqrt(q[1, 1]), rel=0.05)
        assert dp.std() == pytest.approx(math.sqrt(q[0, 0]), rel=0.05)
        assert np.corrcoef(dp, dv)[0, 1] == pytest.approx(math.sqrt(3) / 2, abs=0.02)
    dv = np.concatenate([np.diff(simulate_bruno2008(seed=s).truth[v]) for s in range(30) for v in ("vx", "vy")])
    assert len(dv) == 1140 and dv.std() == pytest.approx(0.098, rel=0.10)


def _transition_chi2(counts, g):
    """Pearson's χ² of the counts (new aspect, old aspect) against Eq. 1's columns G[:, old], and its degrees of
    freedom (cells with G > 0 less one a column); a count in a cell where G = 0 is infinite."""
    expected = counts.sum(axis=0) * g
    if np.any(counts[g == 0]):
        return math.inf, 0
    cells = g > 0
    return float((((counts - expected) ** 2)[cells] / expected[cells]).sum()), int(cells.sum() - g.shape[1])


def test_aspect_transitions_follow_g():
    """10 000 transitions under an asymmetric column-stochastic G: Pearson's χ² below its 0.999 quantile, while
    the transpose (rows read as columns) is rejected; §4's G through the same path: no jump of two aspects."""
    g = np.array([[0.7, 0.2, 0.0, 0.0], [0.3, 0.5, 0.3, 0.0], [0.0, 0.3, 0.1, 0.2], [0.0, 0.0, 0.6, 0.8]])
    rng = np.random.default_rng(7)
    counts = np.zeros((4, 4))
    for _ in range(2):
        z = target_path(rng, 5001, HUGE, HALVES, g)["aspect"] - 1
        np.add.at(counts, (z[1:], z[:-1]), 1)
    chi2, dof = _transition_chi2(counts, g)
    assert chi2 < stats.chi2.ppf(0.999, dof)
    assert _transition_chi2(counts, g.T)[0] > stats.chi2.ppf(0.999, dof)
    z = target_path(rng, 2000, HUGE, HALVES, PAPER_G)["aspect"]
    paper_counts = np.zeros((4, 4))
    np.add.at(paper_counts, (z[1:] - 1, z[:-1] - 1), 1)
    chi2, dof = _transition_chi2(paper_counts, PAPER_G)
    assert chi2 < stats.chi2.ppf(0.999, dof)


def test_exit_and_reentry():
    """Figs. 1–5: target 0 on frames 0..e − 1 and leaving (its next predicted centroid off the extended grid of
    the 9×9 support, rows and columns ≤ 123), frames e..e + 5 without truth and without template pixels, target 1
    from e + 6 at a §4 prior position, max(51, e + 21) frames; the frames are Eq. 8 cut at the border.  §4's prior leaves
    around frame 30 (row U[50, 70] at 2 px/frame to 123.5): e in [25, 40] for seeds 0–3."""
    for seed in range(4):
        scene = simulate_bruno2008(seed=seed, exit_reentry=True)
        e, entry, tr = scene.params["exit_frame"], scene.params["entry_frame"], scene.truth
        assert 25 <= e <= 40 and entry == e + EMPTY_FRAMES == e + 6 and len(scene.frames) == max(51, e + 21)
        first, second = tr[tr["target_id"] == 0], tr[tr["target_id"] == 1]
        assert np.array_equal(first["frame"], np.arange(e)) and len(first) + len(second) == len(tr)
        assert np.array_equal(second["frame"], np.arange(entry, len(scene.frames)))
        last = first[-1]
        assert max(last["y"] + last["vy"], last["x"] + last["vx"]) > 123.0  # 10σ of the 0.057 px position noise
        assert 10 <= second["x"][0] <= 20 and 50 <= second["y"][0] <= 70
        target = _target_images(scene)
        assert np.abs(target[e:entry]).max() < 1e-4 and np.abs(target[entry]).max() > 1.0
        if seed == 0:
            peak = ptcr_peak(6.5)
            assert np.abs(target - _expected_images(scene, vehicle_templates(peak))).max() < 1e-4
            assert scene.params["exit_reentry"] is True and scene.params["scenario"] == "bruno2008"


def test_seeds_and_defaults():
    """The same seed gives the same frames and truth, another seed others; 20 float32 frames of 120×120."""
    a, b, c = simulate_bruno2008(seed=9), simulate_bruno2008(seed=9), simulate_bruno2008(seed=10)
    assert a.frames.shape == (FRAMES, 120, 120) and a.frames.dtype == np.float32
    assert np.array_equal(a.frames, b.frames) and np.array_equal(a.truth, b.truth)
    assert not np.array_equal(a.frames, c.frames)
    assert a.truth.dtype.names == tables.TRUTH_COLUMNS + ("aspect",) and a.truth.dtype["aspect"] == np.int64
    p = a.params
    assert (p["beta_h"], p["beta_v"], p["sigma_c"], p["frames"], p["shape"]) == (0.22, 0.24, 1.0, 20, [120, 120])
    assert p["exit_frame"] is None and p["entry_frame"] is None


@pytest.mark.parametrize("kwargs, offender", [
    ({"ptcr_db": float("nan")}, "ptcr_db"), ({"ptcr_db": -20.0}, "ptcr_db"), ({"ptcr_db": 60.5}, "ptcr_db"),
    ({"ptcr_db": "6"}, "ptcr_db"), ({"ptcr_db": True}, "ptcr_db"), ({"frames": 2}, "frames"),
    ({"frames": 10001}, "frames"), ({"frames": 30, "exit_reentry": True}, "frames"), ({"seed": -1}, "seed"),
    ({"templates": np.ones((11, 11))}, "templates")])
def test_bad_arguments(kwargs, offender):
    with pytest.raises(ParameterError) as caught:
        simulate_bruno2008(**kwargs)
    assert offender in str(caught.value) and "\n" not in str(caught.value)


def test_simulate_cli_writes_the_scene(tmp_path, capsys):
    """The npz holds frames, truth, params and the local mean; the truth CSV has an integer aspect column."""
    out = tmp_path / "b.npz"
    assert cli.main(["simulate", "--scenario", "bruno2008", "--ptcr", "8.1", "--frames", "12", "--seed", "4",
                     "--out", str(out)]) == 0
    with np.load(out) as data:
        assert data["frames"].shape == (12, 120, 120) and len(data["truth"]) == 12
        assert np.allclose(data["local_mean"], local_mean(streams(4)[0]), atol=1e-4)
        assert np.array_equal(data["frames"], simulate_bruno2008(seed=4, ptcr_db=8.1, frames=12).frames)
    lines = (tmp_path / "b_truth.csv").read_text().splitlines()
    assert lines[0] == "frame,target_id,x,y,vx,vy,intensity,aspect"
    assert {line.rsplit(",", 1)[1] for line in lines[1:]} <= {"1", "2", "3", "4"}
    assert "PTCR 8.1 dB" in capsys.readouterr().out


@pytest.mark.parametrize("argv, message", [
    (["--ptcr", "70"], "--ptcr"), (["--ptcr", "nan"], "--ptcr"), (["--exit-reentry", "--frames", "30"], "--frames"),
    (["--frames", "2"], "--frames"), (["--case", "5.1"], "--case applies to --scenario long2012"),
    (["--snr-db", "10"], "--snr-db applies to --scenario long2012"), (["--snr", "2"], "--snr applies"),
    (["--shape", "40", "40"], "--shape applies")])
def test_simulate_cli_errors(simulate_error, argv, message):
    """A bad or foreign argument of bruno2008 is one line naming it, exit 2, and nothing is written."""
    code, err, written = simulate_error("bruno2008", argv)
    assert code == 2 and message in err and err.count("\n") == 1
    assert not written


@pytest.mark.parametrize("argv, message", [
    (["--shape", "40", "40", "--frames", "5", "--snr", "2", "--ptcr", "6"], "--ptcr applies to --scenario bruno2008"),
    (["--scenario", "long2012", "--exit-reentry"], "--exit-reentry applies to --scenario bruno2008")])
def test_bruno2008_arguments_refused_elsewhere(tmp_path, capsys, argv, message):
    code = cli.main(["simulate", *argv, "--out", str(tmp_path / "s.npz")])
    err = capsys.readouterr().err
    assert code == 2 and message in err and err.count("\n") == 1
