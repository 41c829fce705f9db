"""The long2012 simulator (Long et al. 2012 §5): Eq. 4 against quadrature, Eq. 37, the paper's states and
frames, the scenes' geometry, the noise, reproducibility, its CLI and its errors."""
import math

import numpy as np
import pytest
from scipy import integrate, stats

from tbd_taichi import cli, tables
from tbd_taichi.errors import ParameterError
from tbd_taichi.long2012 import CASES, JITTER_SD, intensity_for_db, pixel_integrated, simulate_long2012


@pytest.mark.parametrize("x,y,sigma", [(5.3, 4.8, 0.7), (0.2, 0.4, 0.6), (9.6, 3.0, 0.7)])
def test_eq4_against_quadrature(x, y, sigma):
    """Each rendered pixel equals the 2-D integral of I·N(x, Σ²)·N(y, Σ²) over it (also at the border, where the
    window is clipped), and a target well inside sums to I."""
    shape, inten = (10, 10), 9.0
    rows, cols, values = pixel_integrated(shape, x, y, inten, sigma)
    for r in (rows.start, min(int(round(y)), rows.stop - 1), rows.stop - 1):
        for c in (cols.start, min(int(round(x)), cols.stop - 1), cols.stop - 1):
            ref, _ = integrate.dblquad(lambda v, u: stats.norm.pdf(u, x, sigma) * stats.norm.pdf(v, y, sigma),
                                       c - 0.5, c + 0.5, r - 0.5, r + 0.5)
            assert values[r - rows.start, c - cols.start] == pytest.approx(inten * ref, abs=1e-7)
    _, _, inside = pixel_integrated((40, 40), 20.2, 19.7, inten, sigma)
    assert inside.sum() == pytest.approx(inten, rel=1e-6)


def test_eq37_and_the_paper_intensity():
    """§5.2's I = 9.74 at 10 dB with Σ = 0.7 and σ_n = 1."""
    assert intensity_for_db(10.0, 0.7) == pytest.approx(9.74, abs=0.01)


def test_section_5_2_states_and_turns():
    """The paper's first states (x − ½, y − ½, frame − 1), present frames 4–33 and 9–28, target 1 turned by +π
    (AC-CT, toward +y) and target 2 by −π over their turn legs, the model column, velocities in px/frame."""
    sc = simulate_long2012("5.2", seed=0)
    tr = sc.truth
    t = [tr[tr["target_id"] == k] for k in range(3)]
    assert (t[0]["frame"].min(), t[0]["frame"].max(), t[2]["frame"].min(), t[2]["frame"].max()) == (4, 33, 9, 28)
    assert (t[0]["x"][0], t[0]["y"][0], t[0]["vx"][0]) == pytest.approx((14.5, 9.5, 1.5))
    assert (t[1]["x"][0], t[1]["y"][0], t[1]["vx"][0]) == pytest.approx((24.5, 17.5, -1.3))
    assert (t[2]["x"][0], t[2]["y"][0], t[2]["vy"][0]) == pytest.approx((19.5, 34.5, -1.5))
    for k, sign, model in ((0, 1, 2), (1, -1, 1)):
        turn = t[k][t[k]["model"] == model]
        assert len(turn) == 10
        before = math.atan2(turn["vy"][0], turn["vx"][0])
        after = t[k][t[k]["frame"] == turn["frame"][-1] + 1]
        angle = math.atan2(after["vy"][0], after["vx"][0]) - before
        assert math.remainder(angle - sign * math.pi, 2 * math.pi) == pytest.approx(0, abs=1e-9)


PRESENT = {"5.1": {0: (4, 23)}, "5.2": {0: (4, 33), 1: (4, 33), 2: (9, 28)},
           "5.3": {0: (7, 28), 1: (7, 28), 2: (14, 33)}}  # 0-based first and last frames (the brief, §5)


@pytest.mark.parametrize("case", list(CASES))
def test_scenes_present_in_view_and_apart(case):
    """Each target's present frames; every position ≥ 3 px inside the image (x ≥ 2.5 and ≤ W − 3.5: the image
    spans −½…W − ½) and, while present together, targets ≥ 6Σ apart (Eq. 12)."""
    sc = simulate_long2012(case, seed=1)
    h, w = sc.frames.shape[1:]
    tr, sigma = sc.truth, CASES[case].psf_sigma
    spans = {k: (tr["frame"][tr["target_id"] == k].min(), tr["frame"][tr["target_id"] == k].max())
             for k in np.unique(tr["target_id"]).tolist()}
    assert spans == PRESENT[case]
    assert tr["x"].min() >= 2.5 and tr["x"].max() <= w - 3.5 and tr["y"].min() >= 2.5 and tr["y"].max() <= h - 3.5
    for f in np.unique(tr["frame"]):
        p = tr[tr["frame"] == f]
        for i in range(len(p)):
            for j in range(i + 1, len(p)):
                assert math.hypot(p["x"][i] - p["x"][j], p["y"][i] - p["y"][j]) >= 6 * sigma


def test_frames_render_eq4_at_the_jittered_positions():
    """At 60 dB (I ≈ 3079) each frame is Eq. 4 at truth + that frame's jitter, one (ux, uy) for every target
    (Eqs. 3–4), plus N(0, 1): the residual stays within 6σ_n over 64 000 pixels (P(any > 6) ≈ 1e-4); rendered at
    the truth without the jitter (0.5 px sd) it misses by hundreds."""
    sc = simulate_long2012("5.2", seed=2, snr_db=60.0)
    jitter = np.asarray(sc.params["jitter"])
    assert jitter.shape == (40, 2)
    with_jitter, without = np.zeros(sc.frames.shape), np.zeros(sc.frames.shape)
    for row in sc.truth:
        f = row["frame"]
        for image, (ux, uy) in ((with_jitter, jitter[f]), (without, (0.0, 0.0))):
            rs, cs, values = pixel_integrated((40, 40), row["x"] + ux, row["y"] + uy, row["intensity"], 0.7)
            image[f, rs, cs] += values
    assert np.abs(sc.frames - with_jitter).max() < 6.0
    assert np.abs(sc.frames - without).max() > 100.0


def test_noise_jitter_and_seeds():
    """Away from the targets the pixels are N(0, 1) (std within 3 % over 30 000 pixels: its standard error is
    0.4 %); the jitter has sd 0.5 px (within 30 % over 80 draws); the same seed gives the same frames."""
    sc = simulate_long2012("5.3", seed=4)
    quiet = sc.frames[:, :40, :]  # the launches stay below row 50
    assert quiet.std() == pytest.approx(1.0, rel=0.03) and abs(quiet.mean()) < 0.02
    assert np.std(sc.params["jitter"]) == pytest.approx(JITTER_SD, rel=0.3)
    again, other = simulate_long2012("5.3", seed=4), simulate_long2012("5.3", seed=5)
    assert np.array_equal(sc.frames, again.frames) and not np.array_equal(sc.frames, other.frames)
    assert simulate_long2012("5.1", seed=0, snr_db=8.0).truth["intensity"][0] == pytest.approx(intensity_for_db(8, 0.7))


def test_simulate_cli_writes_the_scene(tmp_path, capsys):
    out = tmp_path / "s.npz"
    assert cli.main(["simulate", "--scenario", "long2012", "--case", "5.2", "--seed", "3", "--out", str(out)]) == 0
    data = np.load(out)
    assert data["frames"].shape == (40, 40, 40)
    header = tables.read_header(tmp_path / "s_truth.csv")
    assert header == ["frame", "target_id", "x", "y", "vx", "vy", "intensity", "model"]
    models = [line.rsplit(",", 1)[1] for line in (tmp_path / "s_truth.csv").read_text().splitlines()[1:]]
    assert set(models) == {"0", "1", "2"}  # written as integers: cv, c-ct, ac-ct
    truth = tables.read_truth(tmp_path / "s_truth.csv")
    assert len(truth) == 80 and truth.dtype["model"] == np.int64
    assert np.array_equal(truth["model"], data["truth"]["model"])
    assert "model" not in tables.read_truth(_plain_truth_csv(tmp_path)).dtype.names


@pytest.mark.parametrize("argv, message", [
    (["--out", "s.npz"], "--scenario jia2022 needs --shape, --frames, --snr"),
    (["--scenario", "long2012", "--frames", "5", "--out", "s.npz"], "--frames applies to --scenario jia2022"),
    (["--scenario", "long2012", "--snr-db", "0", "--out", "s.npz"], "--snr-db")])
def test_simulate_cli_scenario_arguments(tmp_path, capsys, argv, message):
    """jia2022 still needs its own arguments; long2012 refuses them and a non-positive --snr-db (one line, exit 2:
    returned by ``main`` for a check, argparse's exit for a bad value)."""
    argv = [str(tmp_path / a) if a.endswith(".npz") else a for a in argv]
    try:
        code = cli.main(["simulate"] + argv)
    except SystemExit as exc:
        code = exc.code
    err = capsys.readouterr().err
    assert code == 2 and message in err and err.count("\n") == 1
    assert not (tmp_path / "s.npz").exists()


def _plain_truth_csv(tmp_path):
    """A jia2022-style truth CSV (no model column)."""
    path = tmp_path / "plain_truth.csv"
    tables.write_csv(tables.make_table([(0, 0, 1.0, 2.0, 0.5, 0.0, 5.0)], tables.TRUTH_DTYPE), path)
    return path


@pytest.mark.parametrize("kwargs, offender", [({"case": "5.4"}, "case"), ({"snr_db": 0}, "snr_db"),
                                              ({"snr_db": float("nan")}, "snr_db"), ({"seed": -1}, "seed")])
def test_bad_arguments(kwargs, offender):
    with pytest.raises(ParameterError) as caught:
        simulate_long2012(**kwargs)
    assert offender in str(caught.value) and "\n" not in str(caught.value)
