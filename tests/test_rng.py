"""Counter-based RNG: Taichi kernels against the NumPy twin, and statistical quality."""
import numpy as np
import pytest

import tbd_taichi
from tbd_taichi.kernels import rng as trng
from tbd_taichi.numpy_kernels import rng as nrng
from conftest import TEST_ARCH

N = 200_000


def taichi_draws(kind, n, seed, frame, stream, offset=0):
    out = np.zeros(n, dtype=np.uint32 if kind == "hash" else np.float32)
    getattr(trng, f"fill_{kind}")(out, seed, frame, stream, offset)
    return out


@pytest.mark.parametrize("seed,frame,stream,offset", [
    (0, 0, 0, 0), (1, 2, 3, 4), (0xFFFFFFFF, 123456, 7, 0xFFFF0000), (42, 0xFFFFFFFE, 0xFFFFFFFF, 17)])
def test_hash_and_uniform_bit_identical(seed, frame, stream, offset):
    n = 5000
    index = (np.arange(n, dtype=np.int64) + offset) & 0xFFFFFFFF
    assert np.array_equal(taichi_draws("hash", n, seed, frame, stream, offset), nrng.hash_key(seed, frame, stream, index))
    assert np.array_equal(taichi_draws("uniform", n, seed, frame, stream, offset), nrng.uniform(seed, frame, stream, index))


def test_uniform_f64_matches_twin_and_is_uniform():
    n = 100_000
    t = np.zeros(n, np.float64)
    trng.fill_uniform_f64(t, 4, 5, 6, 0)
    np.testing.assert_array_equal(t, nrng.uniform_f64(4, 5, 6, np.arange(n)))
    assert t.min() > 0 and t.max() < 1 and len(np.unique(t)) == n
    assert abs(t.mean() - 0.5) < 4 * np.sqrt(1 / 12 / n)


def taichi_normal_pairs(n, seed, frame, stream):
    a, b = np.zeros(n, np.float32), np.zeros(n, np.float32)
    trng.fill_normal_pair(a, b, seed, frame, stream, 0)
    return a, b


def test_normal_pair_matches_twin():
    n = 50_000
    t = taichi_normal_pairs(n, 9, 8, 7)
    ref = nrng.normal_pair(9, 8, 7, np.arange(n))
    for a, b in zip(t, ref):
        # polar method: the same attempts are kept (integer hashes, exact f32 products and the
        # comparison s < 1); f32 log may differ by a few ulp between LLVM and NumPy
        np.testing.assert_allclose(a, b, rtol=1e-5, atol=1e-6)


def test_uniform_moments_and_uniformity():
    u = taichi_draws("uniform", N, 3, 1, 0).astype(np.float64)
    assert u.min() > 0 and u.max() < 1
    se = np.sqrt(1 / 12 / N)  # standard error of the mean
    assert abs(u.mean() - 0.5) < 4 * se
    assert abs(u.var() - 1 / 12) < 4 * np.sqrt(1 / 180 / N)  # var of (u-½)² is 1/180
    counts = np.histogram(u, bins=100, range=(0, 1))[0]
    chi2 = ((counts - N / 100) ** 2 / (N / 100)).sum()
    assert chi2 < 150  # chi-square, 99 dof: P(>150) ≈ 6e-4


def test_normal_pair_moments_and_independence():
    pair = taichi_normal_pairs(N, 5, 2, 1)
    for z in (c.astype(np.float64) for c in pair):
        assert abs(z.mean()) < 4 / np.sqrt(N)
        assert abs(z.var() - 1) < 4 * np.sqrt(2 / N)
        assert abs((z ** 3).mean()) < 4 * np.sqrt(15 / N)
        assert abs((z ** 4).mean() - 3) < 4 * np.sqrt(96 / N)
        # the tails exist: P(|z| > 3) = 0.0027
        assert abs((np.abs(z) > 3).mean() - 0.0027) < 4 * np.sqrt(0.0027 / N)
    a, b = pair[0].astype(np.float64), pair[1].astype(np.float64)
    assert abs(np.mean(a * b)) < 4 / np.sqrt(N)  # the two halves are uncorrelated
    assert abs(np.mean(a * a * b * b) - 1) < 4 * np.sqrt(8 / N)  # and independent (E[a²b²] = 1, var 8)


@pytest.mark.parametrize("axis", ["index", "frame", "stream", "seed"])
def test_no_correlation_between_neighbouring_keys(axis):
    n = 100_000
    keys = dict(seed=np.full(n, 11), frame=np.full(n, 5), stream=np.full(n, 2), index=np.arange(n))
    keys[axis] = np.arange(n)
    other = dict(keys)
    other[axis] = keys[axis] + 1
    if axis != "index":
        keys["index"] = other["index"] = np.full(n, 77)
    a = nrng.uniform(**keys).astype(np.float64)
    b = nrng.uniform(**other).astype(np.float64)
    assert abs(np.corrcoef(a, b)[0, 1]) < 4 / np.sqrt(n)
    # low bits of the hash are as random as the high bits
    bits = nrng.hash_key(**keys) & 1
    assert abs(bits.mean() - 0.5) < 4 * 0.5 / np.sqrt(n)


def test_same_numbers_with_one_and_two_threads():
    try:
        tbd_taichi.init("cpu", threads=1)
        one = taichi_normal_pairs(N, 1, 2, 3) + (taichi_draws("hash", N, 1, 2, 3),)
        tbd_taichi.init("cpu", threads=2)
        two = taichi_normal_pairs(N, 1, 2, 3) + (taichi_draws("hash", N, 1, 2, 3),)
    finally:
        tbd_taichi.init(TEST_ARCH)
    assert all(np.array_equal(a, b) for a, b in zip(one, two))
