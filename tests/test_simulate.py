"""Simulator against its model: Eq. 1 SNR, Eq. 14 PSF, Eqs. 44–46 motion, N(0, 1) noise."""
import math

import numpy as np
import pytest

from tbd_taichi.errors import ParameterError
from tbd_taichi.simulate import intensity_for_snr, ncv_trajectory, render_psf, simulate

SIGMA_PSF = 0.7


def signal_only(scene, shape):
    """The noiseless frames implied by the truth (Eq. 14)."""
    out = np.zeros((scene.params["frames"],) + shape, np.float64)
    for row in scene.truth:
        render_psf(out[row["frame"]], row["x"], row["y"], row["intensity"], SIGMA_PSF)
    return out


def test_intensity_from_snr():
    assert intensity_for_snr(2.0) == pytest.approx(6.1575, abs=1e-4)  # 2·2π·0.7²


def test_psf_peak_equals_snr_at_pixel_centre():
    img = np.zeros((9, 9))
    render_psf(img, 4.0, 4.0, intensity_for_snr(1.4), SIGMA_PSF)
    assert img[4, 4] == pytest.approx(1.4, rel=1e-6)
    assert img[4, 5] == pytest.approx(1.4 * math.exp(-1 / (2 * SIGMA_PSF ** 2)), rel=1e-6)
    assert img.sum() == pytest.approx(intensity_for_snr(1.4), rel=2e-3)  # point sampling ≈ unit volume


def test_measured_snr_and_noise():
    shape = (60, 60)
    scene = simulate(shape, frames=400, snr=2.0, seed=3, q1=0.0, q2=0.0, speed=(0.05, 0.1))
    residual = scene.frames - signal_only(scene, shape)
    n = residual.size
    assert abs(residual.mean()) < 4 / math.sqrt(n) and abs(residual.std() - 1) < 4 * math.sqrt(0.5 / n)
    # Eq. 1 at the nearest pixel: (value − mean)/std, against the PSF-predicted peak
    f, x, y = scene.truth["frame"], scene.truth["x"], scene.truth["y"]
    cx, cy = np.floor(x + 0.5).astype(int), np.floor(y + 0.5).astype(int)
    frames = scene.frames[f]
    measured = (frames[np.arange(len(f)), cy, cx] - frames.mean(axis=(1, 2))) / frames.std(axis=(1, 2))
    predicted = 2.0 * np.exp(-((cx - x) ** 2 + (cy - y) ** 2) / (2 * SIGMA_PSF ** 2))
    assert abs(measured.mean() - predicted.mean()) < 4 / math.sqrt(len(f))
    assert predicted.mean() > 1.3  # the target is mostly near a pixel centre, not lost


def test_motion_statistics_match_q():
    rng = np.random.default_rng(0)
    q1, q2 = 0.001, 0.01
    states = np.stack([ncv_trajectory(rng, np.array([0, 0.7, 0, -0.3, 5.0]), 200, q1, q2) for _ in range(100)])
    prev, nxt = states[:, :-1], states[:, 1:]
    d = np.concatenate([nxt[..., 0] - prev[..., 0] - prev[..., 1], nxt[..., 2] - prev[..., 2] - prev[..., 3]]).ravel()
    dv = np.concatenate([nxt[..., 1] - prev[..., 1], nxt[..., 3] - prev[..., 3]]).ravel()
    di = (nxt[..., 4] - prev[..., 4]).ravel()
    n = d.size
    tol = 4 * math.sqrt(2 / n)  # relative s.e. of a variance estimate
    assert np.var(d) == pytest.approx(q1 / 3, rel=tol)
    assert np.var(dv) == pytest.approx(q1, rel=tol)
    assert np.mean(d * dv) == pytest.approx(q1 / 2, rel=2 * tol)
    assert np.var(di) == pytest.approx(q2, rel=2 * tol)
    assert abs(np.mean(dv)) < 4 * math.sqrt(q1 / n)


@pytest.mark.parametrize("shape,frames", [((50, 50), 70), ((200, 200), 150)])
def test_targets_stay_in_view_by_default(shape, frames):
    for seed in range(5):
        scene = simulate(shape, frames, snr=1.4, targets=2, seed=seed)
        t = scene.truth
        assert len(t) == 2 * frames
        assert t["x"].min() >= 1.5 and t["x"].max() < shape[1] - 2.5
        first = t[t["frame"] == 0]
        assert np.all((np.hypot(first["vx"], first["vy"]) >= 0.5 - 1e-9) & (np.hypot(first["vx"], first["vy"]) <= 1.0))


def test_transit_targets_enter_and_leave():
    scene = simulate((40, 40), 120, snr=2.0, targets=4, seed=2, motion="transit")
    t = scene.truth
    assert np.all((t["x"] >= -0.5) & (t["x"] < 39.5) & (t["y"] >= -0.5) & (t["y"] < 39.5))
    per_target = np.bincount(t["target_id"], minlength=4)
    assert per_target.min() >= 5 and per_target.max() < 120


@pytest.mark.parametrize("frames", [1, 2, 4, 9])
def test_short_transit_sequences(frames):
    """A few frames (e.g. ``tbd-taichi bench --frames 1`` plus 3 warm-up frames) still simulate:
    a target entering from outside may need up to 4 frames to come into view, so only
    sequences longer than 4 frames must show it (5 frames from 9 on)."""
    scene = simulate((512, 512), frames, snr=2.0, seed=3, motion="transit")
    assert scene.frames.shape == (frames, 512, 512)
    assert len(scene.truth) >= min(5, max(frames - 4, 0))
    assert np.all((scene.truth["x"] >= -0.5) & (scene.truth["x"] < 511.5))


def test_same_seed_same_scenario():
    a, b = simulate((30, 40), 10, 2.0, seed=7), simulate((30, 40), 10, 2.0, seed=7)
    np.testing.assert_array_equal(a.frames, b.frames)
    np.testing.assert_array_equal(a.truth, b.truth)
    assert a.frames.shape == (10, 30, 40) and a.frames.dtype == np.float32
    assert not np.array_equal(a.frames, simulate((30, 40), 10, 2.0, seed=8).frames)


def test_bad_parameters():
    with pytest.raises(ParameterError, match="psf_sigma"):
        simulate((10, 10), 5, 2.0, psf_sigma=0)
    with pytest.raises(ParameterError, match="could not keep a target"):
        simulate((6, 6), 100, 2.0, speed=(1.0, 1.0))
