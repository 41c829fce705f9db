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
    # 81920 px: se(mean) = 0.0035; se(MAD-sigma) ≈ 1.65/sqrt(n) ≈ 0.006
    assert abs(z.mean()) < 0.02 and abs(z.std() - 1) < 0.03
    assert z.dtype == np.float32


def test_14_bit_camera_sequence_with_target(rng):
    scene = simulate((128, 160), frames=3, snr=3.0, seed=4)
    raw = to_camera(scene.frames, offset=2000, gain=30, bits=14)
    assert raw.dtype == np.uint16
    z = normalize.normalise_sequence(raw)
    # integer rounding adds 1/12 LSB² of noise: σ_z² = 1 + 1/(12·30²)
    assert abs(z.std() - 1) < 0.02 and abs(np.median(z)) < 0.02
    slope, intercept = np.polyfit(scene.frames.ravel(), z.ravel(), 1)
    assert abs(slope - 1) < 0.02 and abs(intercept) < 0.02  # MAD σ has ≈0.4% s.e. per frame
    residual = z - (slope * scene.frames + intercept)
    assert residual.std() < 0.015  # rounding: 1/(30·√12) = 0.0096


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
