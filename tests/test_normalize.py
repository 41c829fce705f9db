"""Normalisation to zero-mean, unit-variance noise from raw camera data."""
import numpy as np
import pytest

from tbd_taichi import normalize
from tbd_taichi.errors import ParameterError
from tbd_taichi.simulate import simulate, to_camera


@pytest.mark.parametrize("background", ["median", "mean"])
def test_gaussian_noise_with_offset_and_gain(rng, background):
    frame = 3000.0 + 25.0 * rng.standard_normal((256, 320))
    z = normalize.normalise_frame(frame, background).z
    # the statistics see 11,703 px (stat_sample's stride 7): se(median) = 1.2533/√n = 0.012,
    # se(MAD σ) ≈ 1.166/√n = 0.011; the mean background sees all 81,920 (se 0.0035)
    assert abs(z.mean()) < 0.04 and abs(z.std() - 1) < 0.035
    assert z.dtype == np.float32


def test_14_bit_camera_sequence_with_target(rng):
    scene = simulate((128, 160), frames=3, snr=3.0, seed=4)
    raw = to_camera(scene.frames, offset=2000, gain=30, bits=14)
    assert raw.dtype == np.uint16
    z = normalize.normalise_sequence(raw)
    # integer rounding adds 1/12 LSB² of noise: σ_z² = 1 + 1/(12·30²)
    assert abs(z.std() - 1) < 0.02 and abs(np.median(z)) < 0.02
    slope, intercept = np.polyfit(scene.frames.ravel(), z.ravel(), 1)
    # per frame the statistics see 6,827 px (stride 3): se(median) = 1.2533/√n = 0.015, se(MAD σ) = 1.4 %
    assert abs(slope - 1) < 0.02 and abs(intercept) < 0.02
    residual = z - (slope * scene.frames + intercept)
    assert residual.std() < 0.025  # rounding 1/(30·√12) = 0.0096 and the per-frame median's 0.015: 0.018


def test_strided_sample_visits_every_column():
    """A stride that divides the width (2 at 320×256 with 2¹⁶ samples) sees only some columns; the
    sample's stride is coprime with W, so every column is in it."""
    for h, w in ((256, 320), (200, 200), (1024, 1024), (37, 1001)):
        columns = normalize.stat_sample(np.tile(np.arange(w, dtype=np.float32), (h, 1)))
        assert len(columns) <= normalize.MAX_SAMPLES
        assert np.array_equal(np.unique(columns), np.arange(w)), (h, w)


def test_sampled_statistics_estimate_those_of_the_whole_frame(rng):
    """Raw 1024×1024 frame, offset 1000, σ 7, 0.5 % hot pixels, odd columns 3σ brighter (column
    pattern noise): the sample's median and 1.4826·MAD agree with the whole frame's within 4 standard
    errors (n ≈ 16,100: se(median) = 1.2533·σ_mix/√n ≈ 0.11, se(MAD σ) ≈ 1.2 %)."""
    frame = 1000.0 + 7.0 * rng.standard_normal((1024, 1024))
    frame[:, 1::2] += 21.0
    frame[rng.random(frame.shape) < 0.005] = 16000.0
    sample = normalize.stat_sample(frame)
    whole_median = float(np.median(frame))
    whole_sigma = normalize.MAD_TO_SIGMA * float(np.median(np.abs(frame - whole_median)))
    assert abs(float(np.median(sample)) - whole_median) < 0.45
    assert normalize.robust_sigma(frame) == pytest.approx(whole_sigma, rel=0.05)


def test_bright_target_does_not_inflate_sigma(rng):
    frame = rng.standard_normal((64, 64))
    frame[30:34, 30:34] += 200.0
    n = normalize.normalise_frame(frame)
    assert abs(n.sigma - 1) < 0.05 and abs(n.background) < 0.05


def test_quantised_frame_with_zero_mad_falls_back_to_std():
    frame = np.zeros((50, 50))
    frame[::10, ::10] = 10.0  # MAD is 0: more than half the pixels equal the median
    sigma = normalize.robust_sigma(frame)
    assert sigma == pytest.approx(frame.std(), rel=1e-6)


def test_constant_frame_gives_zeros():
    n = normalize.normalise_frame(np.full((8, 9), 77.0))
    assert n.sigma == 1.0 and np.all(n.z == 0)


def test_unknown_background():
    with pytest.raises(ParameterError, match="unknown background 'fancy'"):
        normalize.normalise_frame(np.zeros((4, 4)), "fancy")


@pytest.mark.parametrize("n", [1, 2, 3, 8, 11, 1000, 11703, 16384])
def test_sample_median_is_numpys_median_bit_for_bit(rng, n):
    """Odd and even sizes, ties (quantised values) and extremes: the same float32 value as np.median."""
    for values in (rng.normal(size=n), np.round(rng.normal(size=n) * 3), rng.uniform(-1e30, 1e30, n)):
        values = values.astype(np.float32)
        assert normalize.sample_median(values) == float(np.median(values))
        assert normalize.sample_median(values[::-1]) == float(np.median(values))
    assert np.isnan(normalize.sample_median(np.zeros(0, np.float32)))
