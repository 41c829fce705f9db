"""Counter-based RNG: Taichi kernels against the NumPy twin, and statistical quality."""
import math

import numpy as np
import pytest
import taichi as ti

import tbd_taichi
from tbd_taichi.kernels import rng as trng
from tbd_taichi.numpy_kernels import rng as nrng
from conftest import TEST_ARCH

N = 200_000


DRAW_DTYPES = {"hash": np.uint32, "uniform": np.float32, "normal": np.float32, "exponential": np.float64}


def taichi_draws(kind, n, seed, frame, stream, offset=0, tables=()):
    """n draws of ``trng.fill_<kind>`` from key index ``offset`` on; ``tables``: a ziggurat's fields."""
    out = np.zeros(n, dtype=DRAW_DTYPES[kind])
    getattr(trng, f"fill_{kind}")(out, *tables, seed, frame, stream, offset)
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


def normal_fields():
    tables = trng.NormalTables()
    return tables.w, tables.k, tables.phi


@pytest.fixture(scope="module")
def normal_tables():
    return normal_fields()


def test_ziggurat_layers_have_equal_area_and_close():
    x, phi = trng.ziggurat_layers()
    assert np.all(np.diff(x) < 0) and x[-1] == 0 and x[1] == trng.ZIG_R
    areas = x[1:-1] * (phi[2:] - phi[1:-1])  # layer i ≥ 1: [0, x_i] × [φ_i, φ_{i+1}]
    np.testing.assert_allclose(areas, trng.ZIG_V, rtol=1e-8)  # the top layer closes to 1.2e-9 (R, V given to 12 digits)
    # layer 0: the box [0, R] × [0, φ(R)] plus the tail ∫_R^∞ φ = √(π/2)·erfc(R/√2)
    tail = np.sqrt(np.pi / 2) * math.erfc(trng.ZIG_R / np.sqrt(2))
    assert abs(trng.ZIG_R * phi[1] + tail - trng.ZIG_V) < 1e-12
    assert abs(x[0] * phi[1] - trng.ZIG_V) < 1e-15


def test_normal_matches_twin(normal_tables):
    n = 300_000  # about 3,600 rejection paths and 140 tail draws
    for offset in (0, 0xFFFF0000 // trng.ZIG_TRIES):
        t = taichi_draws("normal", n, 9, 8, 7, offset, tables=normal_tables)
        ref = nrng.normal(9, 8, 7, np.arange(n) + offset)
        # integer hashes and comparisons, exact f32 products; the wedge and tail tests are f64,
        # where LLVM's and NumPy's exp/log may differ in the last ulp
        np.testing.assert_allclose(t, ref, rtol=1e-6, atol=0)
        assert (t == ref).mean() > 0.9999



@ti.kernel
def fill_normals3(out: ti.types.ndarray(dtype=ti.f32, ndim=2), w: ti.template(), k: ti.template(),
                  phi: ti.template(), seed: ti.u32, frame: ti.u32, stream: ti.u32):
    """out[i, d] = normals_at(tables, [key of stream + d for d in 0, 1, 2], i)[d]."""
    keys = [trng.key_prefix(seed, frame, stream + d) for d in ti.static(range(3))]
    for i in range(out.shape[0]):
        v = trng.normals_at(w, k, phi, keys, i)
        for d in ti.static(range(3)):
            out[i, d] = v[d]


def test_normals_at_equals_normal_at_per_stream(normal_tables):
    """The several-stream draw gives each stream's normal_at variate, also where one, two or all three take
    the slow path (≈ 1,200 rejections per stream in 100 000 draws)."""
    n = 100_000
    out = np.zeros((n, 3), np.float32)
    fill_normals3(out, *normal_tables, 5, 6, 7)
    for d in range(3):
        np.testing.assert_array_equal(out[:, d], taichi_draws("normal", n, 5, 6, 7 + d, tables=normal_tables))

def test_normal_moments_tails_and_shape(normal_tables):
    n = 1_000_000
    z = taichi_draws("normal", n, 5, 2, 1, tables=normal_tables).astype(np.float64)
    assert abs(z.mean()) < 4 / np.sqrt(n)
    assert abs(z.var() - 1) < 4 * np.sqrt(2 / n)
    assert abs((z ** 3).mean()) < 4 * np.sqrt(15 / n)
    assert abs((z ** 4).mean() - 3) < 4 * np.sqrt(96 / n)
    # the tail beyond R = 3.44 (Marsaglia's tail method) and the wedges carry the right mass
    for t in (1.0, 2.0, 3.0, trng.ZIG_R, 4.0):
        p = math.erfc(t / np.sqrt(2))
        assert abs((np.abs(z) > t).mean() - p) < 4 * np.sqrt(p * (1 - p) / n)
    # chi-square over 128 equiprobable bins of |z| ≤ 3.6 (every layer's edge falls inside a bin)
    edges = np.sort(np.concatenate([[0.0], [float(v) for v in _half_normal_quantiles(128)]]))
    counts = np.histogram(np.abs(z), bins=np.append(edges, np.inf))[0]
    expected = n / (len(edges))
    chi2 = ((counts - expected) ** 2 / expected).sum()
    assert chi2 < 200  # 128 dof: P(χ² > 200) ≈ 1e-4


def _half_normal_quantiles(k):
    """The k − 1 inner edges of k equiprobable bins of |z| (bisection on erf)."""
    out = []
    for j in range(1, k):
        lo, hi = 0.0, 10.0
        for _ in range(60):
            mid = (lo + hi) / 2
            lo, hi = (mid, hi) if math.erf(mid / math.sqrt(2)) < j / k else (lo, mid)
        out.append(lo)
    return out


@pytest.fixture(scope="module")
def exponential_tables():
    tables = trng.ExponentialTables()
    return tables.w, tables.k, tables.f


def test_exponential_layers_have_equal_area_and_close():
    x, f = trng.exponential_layers()
    assert np.all(np.diff(x) < 0) and x[-1] == 0 and x[1] == trng.EXP_R
    np.testing.assert_allclose(x[1:-1] * (f[2:] - f[1:-1]), trng.EXP_V, rtol=1e-8)  # layers i ≥ 1
    assert abs(x[-2] * (1 - f[-2]) - trng.EXP_V) < 1e-12  # the top layer closes at f(0) = 1
    # layer 0: the box [0, R] × [0, e^−R] plus the tail ∫_R^∞ e^−x = e^−R
    assert abs((trng.EXP_R + 1) * f[1] - trng.EXP_V) < 1e-12 and abs(x[0] * f[1] - trng.EXP_V) < 1e-15


def test_exponential_matches_twin(exponential_tables):
    n = 300_000  # about 3,300 rejection paths and 20 tail draws
    for offset in (0, 0xFFFF0000 // trng.ZIG_TRIES):
        t = taichi_draws("exponential", n, 9, 8, 7, offset, tables=exponential_tables)
        ref = nrng.exponential(9, 8, 7, np.arange(n) + offset)
        np.testing.assert_allclose(t, ref, rtol=1e-14, atol=0)  # f64 exp/log may differ in the last ulp
        assert (t == ref).mean() > 0.9999


def test_exponential_moments_tails_and_shape(exponential_tables):
    n = 1_000_000
    x = taichi_draws("exponential", n, 5, 2, 1, tables=exponential_tables)
    assert x.min() > 0
    assert abs(x.mean() - 1) < 4 / np.sqrt(n)  # Exp(1): mean 1, variance 1
    assert abs(x.var() - 1) < 4 * np.sqrt(8 / n)  # var of (x − 1)² is 8
    # the wedges and the tail beyond R = 7.70 carry the right mass: P(x > t) = e^−t
    for t in (0.5, 1.0, 2.0, 4.0, trng.EXP_R, 9.0):
        p = math.exp(-t)
        assert abs((x > t).mean() - p) < 4 * np.sqrt(p * (1 - p) / n)
    # chi-square over 256 equiprobable bins
    counts = np.histogram(1 - np.exp(-x), bins=256, range=(0, 1))[0]
    chi2 = ((counts - n / 256) ** 2 / (n / 256)).sum()
    assert chi2 < 350  # 255 dof: P(χ² > 350) ≈ 1e-4


def test_normal_independent_across_streams_and_signs(normal_tables):
    n = N
    a = taichi_draws("normal", n, 5, 2, 1, tables=normal_tables).astype(np.float64)
    b = taichi_draws("normal", n, 5, 2, 2, tables=normal_tables).astype(np.float64)
    assert abs(np.mean(a * b)) < 4 / np.sqrt(n)  # streams uncorrelated
    assert abs(np.mean(a * a * b * b) - 1) < 4 * np.sqrt(8 / n)  # and independent (E[a²b²] = 1, var 8)
    assert abs(np.mean(a[:-1] * a[1:])) < 4 / np.sqrt(n)  # neighbouring indices too
    assert abs((a > 0).mean() - 0.5) < 4 * 0.5 / np.sqrt(n)


def test_uniform_moments_and_uniformity():
    u = taichi_draws("uniform", N, 3, 1, 0).astype(np.float64)
    assert u.min() > 0 and u.max() < 1
    se = np.sqrt(1 / 12 / N)  # standard error of the mean
    assert abs(u.mean() - 0.5) < 4 * se
    assert abs(u.var() - 1 / 12) < 4 * np.sqrt(1 / 180 / N)  # var of (u-½)² is 1/180
    counts = np.histogram(u, bins=100, range=(0, 1))[0]
    chi2 = ((counts - N / 100) ** 2 / (N / 100)).sum()
    assert chi2 < 150  # chi-square, 99 dof: P(>150) ≈ 6e-4


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
        tables = normal_fields()
        one = (taichi_draws("normal", N, 1, 2, 3, tables=tables), taichi_draws("hash", N, 1, 2, 3))
        tbd_taichi.init("cpu", threads=2)
        tables = normal_fields()
        two = (taichi_draws("normal", N, 1, 2, 3, tables=tables), taichi_draws("hash", N, 1, 2, 3))
    finally:
        tbd_taichi.init(TEST_ARCH)
    assert all(np.array_equal(a, b) for a, b in zip(one, two))


def test_kernel_classes_share_one_set_of_tables_per_runtime():
    """Each table field filled from NumPy compiles a kernel: every kernel class takes the runtime's one instance,
    and a restarted runtime gets new tables (the old fields are gone with it)."""
    import tbd_taichi
    from tbd_taichi import backend
    from tbd_taichi.kernels.tophat_pf import TophatPFKernels

    tbd_taichi.init("cpu")
    first = trng.NormalTables.shared()
    assert trng.NormalTables.shared() is first and trng.ExponentialTables.shared() is trng.ExponentialTables.shared()
    assert TophatPFKernels(2, 4, (8, 9), 3).tables is first
    w, k, phi = trng.ziggurat_tables()
    assert np.array_equal(first.w.to_numpy(), w) and np.array_equal(first.phi.to_numpy(), phi)
    tbd_taichi.init("cpu", threads=1)  # another runtime
    try:
        assert trng.NormalTables.shared() is not first
    finally:
        tbd_taichi.init("cpu")
    assert backend.current().threads is None
