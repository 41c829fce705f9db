"""Particle pool kernels (SGDS-PF Eqs. 7–19): Taichi against the NumPy twin, brute force and statistics."""
import math

import numpy as np
import pytest

import tbd_taichi
from tbd_taichi.errors import ParameterError
from tbd_taichi.particles import ParticlePool
from conftest import TEST_ARCH

SHAPE = (23, 31)  # odd, not a multiple of anything
CAPS = [700, 1500, 300]


def random_states(rng, caps, shape, p_exist=0.6):
    """Random particle states per group, positions covering the borders and just outside."""
    h, w = shape
    out = {}
    for g, cap in enumerate(caps):
        n = cap - 17 * g  # some groups not full
        out[g] = dict(x=rng.uniform(-0.4, w - 0.6, n).astype(np.float32), y=rng.uniform(-0.4, h - 0.6, n).astype(np.float32),
                      vx=rng.uniform(-1, 1, n).astype(np.float32), vy=rng.uniform(-1, 1, n).astype(np.float32),
                      inten=rng.uniform(0.5, 12, n).astype(np.float32), e=(rng.random(n) < p_exist).astype(np.int32),
                      tp=rng.integers(0, 9, n).astype(np.int32), seq=rng.integers(0, 5, n).astype(np.int32))
    return out


def make_pools(rng, caps=CAPS, shape=SHAPE, **kw):
    states = random_states(rng, caps, shape)
    z = rng.standard_normal(shape).astype(np.float32)
    z[5, 7] = 40.0  # an extreme pixel
    pools = []
    for engine in ("taichi", "numpy"):
        p = ParticlePool(caps, shape, engine=engine, seed=11, map_capacity=64, **kw)
        p.configure_groups([0, 2], "uniform", pb=0.3, pd=0.2, intensity=(2.0, 9.0))
        p.configure_groups([1], "map", pb=0.3, pd=0.2, intensity=(2.0, 9.0), vmax=0.5)
        p.set_proposal_map({1: (np.array([3 * shape[1] + 4, 10 * shape[1] + 20, 22 * shape[1] + 30]),
                                np.array([0.2, 0.5, 0.3]))})
        p.set_state(states)
        p.load_frame(z)
        pools.append(p)
    return pools, z


def assert_states_match(a, b, rtol=1e-5, atol=1e-5):
    sa, sb = a.state(), b.state()
    for key in ("e", "tp", "seq", "group", "slot"):
        np.testing.assert_array_equal(sa[key], sb[key], err_msg=key)
    for key in ("x", "vx", "y", "vy", "inten", "logw"):
        np.testing.assert_allclose(sa[key], sb[key], rtol=rtol, atol=atol, err_msg=key)


def test_every_stage_matches_the_numpy_twin(rng):
    (t, n), _ = make_pools(rng)
    for frame in range(3):
        for pool in (t, n):
            pool.predict(frame)
        assert_states_match(t, n)
        np.testing.assert_array_equal(t._get("born"), n._get("born"))
        for pool in (t, n):
            pool.weigh()
        assert_states_match(t, n, rtol=2e-5, atol=2e-5)  # f32 exp differs by ulps
        np.testing.assert_allclose(t.normalised_weights(), n.normalised_weights(), rtol=1e-4, atol=1e-12)
        n._put("logw", t._get("logw"))  # the contract: the same weights give the same parents
        n.normalise()
        for pool in (t, n):
            pool.resample(frame, n_out=[600, 1500, 100], systematic=frame == 1)  # frame 1: systematic
        np.testing.assert_array_equal(t._get("parent")[:2300], n._get("parent")[:2300])
        assert_states_match(t, n)
    et, en = t.estimates(), n.estimates()
    np.testing.assert_array_equal(et.p_exist, en.p_exist)  # integer counts
    np.testing.assert_array_equal(et.tp_mean, en.tp_mean)
    for field in ("x", "y", "vx", "vy", "intensity"):  # means of states that agree to f32 ulps
        np.testing.assert_allclose(getattr(et, field), getattr(en, field), rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(et.cov, en.cov, rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(et.cov_e, en.cov_e, rtol=1e-5, atol=1e-6)


def test_existence_prediction_statistics():
    n = 200_000
    pool = ParticlePool([n], (10, 10), engine="taichi", seed=3, q1=0.0)  # q1 = 0: nothing leaves the image
    pool.configure_groups([0], pb=0.1, pd=0.25)
    e0 = (np.arange(n) % 2).astype(np.int32)
    pool.set_state({0: dict(x=np.full(n, 5.0), y=np.full(n, 5.0), vx=0 * e0, vy=0 * e0, inten=np.ones(n), e=e0, tp=e0)})
    pool.predict(0)
    e1 = pool.state()["e"]
    born = pool._get("born")[:n]
    sd = lambda p: 4 * math.sqrt(p * (1 - p) / (n / 2))  # noqa: E731  4 standard errors
    assert abs(e1[e0 == 0].mean() - 0.1) < sd(0.1)  # Eq. 7
    assert abs(1 - e1[e0 == 1].mean() - 0.25) < sd(0.25)  # Eq. 8
    np.testing.assert_array_equal(born, (e0 == 0) & (e1 == 1))


def test_newborn_uniform_and_from_map():
    n, shape = 120_000, (40, 50)
    pool = ParticlePool([n, n], shape, engine="taichi", seed=4, map_capacity=8)
    pool.configure_groups([0], "uniform", pb=1.0, region=(2.0, 12.0, 5.0, 25.0), vmax=0.8, intensity=(3.0, 5.0))
    pool.configure_groups([1], "map", pb=1.0, vmax=0.8, intensity=(3.0, 5.0))
    pix = np.array([0, 7 * 50 + 9, 39 * 50 + 49])
    pool.set_proposal_map({1: (pix, np.array([1.0, 2.0, 5.0]))})
    zero = np.zeros(n)
    pool.set_state({g: dict(x=zero, y=zero, vx=zero, vy=zero, inten=zero + 1, e=zero.astype(np.int32), tp=zero)
                    for g in (0, 1)})
    pool.predict(0)
    s = pool.state()
    g0, g1 = s["group"] == 0, s["group"] == 1
    assert np.all(s["tp"] == 1) and np.all(s["e"][g0 | g1] == 1 - 0 * s["e"][g0 | g1])
    x, y = s["x"][g0], s["y"][g0]
    assert x.min() >= 2 and x.max() < 12 and y.min() >= 5 and y.max() < 25
    assert abs(x.mean() - 7) < 4 * 10 / math.sqrt(12 * n) and abs(np.var(x) - 100 / 12) < 0.1
    speed = np.hypot(s["vx"], s["vy"])
    assert speed.max() <= 0.8 + 1e-6 and abs(speed.mean() - 0.4) < 0.01
    assert s["inten"].min() >= 3 and s["inten"].max() < 5
    # from the map: pixel counts ∝ weights 1:2:5 (chi-square, 2 dof, P(> 13.8) = 0.001)
    px = np.floor(s["x"][g1] + 0.5).astype(int) + 50 * np.floor(s["y"][g1] + 0.5).astype(int)
    counts = np.array([(px == p).sum() for p in pix])
    assert counts.sum() == n
    expected = n * np.array([1, 2, 5]) / 8
    assert ((counts - expected) ** 2 / expected).sum() < 13.8
    assert np.all(np.abs(s["x"][g1] - np.floor(s["x"][g1] + 0.5)) <= 0.5)
    assert np.all(s["seq"][g1] == 0)  # no labels given: Seq 0


@pytest.mark.parametrize("engine", ["taichi", "numpy"])
def test_map_newborns_take_their_pixels_pp_label(engine):
    """Eq. 36: a particle drawn from a proposal pixel gets the label image's PP id at that pixel as its Seq;
    a label image of another shape is refused."""
    n, shape = 3000, (9, 13)
    pool = ParticlePool([n], shape, engine=engine, seed=2, map_capacity=4)
    pool.configure_groups([0], "map", pb=1.0, vmax=0.5, intensity=(2.0, 3.0))
    pix = np.array([0, 4 * 13 + 7, 8 * 13 + 12])
    labels = np.zeros(shape, np.int32)
    labels.flat[pix] = [11, 12, 13]
    pool.set_proposal_map({0: (pix, np.array([1.0, 1.0, 1.0]))}, labels)
    zero = np.zeros(n)
    pool.set_state({0: dict(x=zero, y=zero, vx=zero, vy=zero, inten=zero + 1, e=zero.astype(np.int32), tp=zero)})
    pool.predict(0)
    s = pool.state()
    px = np.floor(s["x"] + 0.5).astype(int) + 13 * np.floor(s["y"] + 0.5).astype(int)
    np.testing.assert_array_equal(s["seq"], labels.flat[px])
    assert set(np.unique(s["seq"])) == {11, 12, 13}
    with pytest.raises(ParameterError, match=r"labels must have the frame's shape \(9, 13\)"):
        pool.set_proposal_map({0: (pix, np.ones(3))}, np.zeros((13, 9), np.int32))


def test_propagation_reproduces_ncv_moments():
    n, q1, q2 = 200_000, 0.004, 0.02
    pool = ParticlePool([n], (400, 400), engine="taichi", seed=6, q1=q1, q2=q2)
    pool.configure_groups([0], pb=0.0, pd=0.0)
    x0, v0 = np.full(n, 200.0), np.full(n, 0.7)
    one = np.ones(n, np.int32)
    pool.set_state({0: dict(x=x0, y=x0, vx=v0, vy=-v0, inten=np.full(n, 5.0), e=one, tp=one)})
    pool.predict(0)
    s = pool.state()
    dx, dvx = s["x"] - 200.7, s["vx"] - 0.7
    dy, dvy = s["y"] - 199.3, s["vy"] + 0.7
    tol = 4 * math.sqrt(2 / n)  # relative s.e. of a variance
    assert np.var(dx) == pytest.approx(q1 / 3, rel=tol) and np.var(dy) == pytest.approx(q1 / 3, rel=tol)
    assert np.var(dvx) == pytest.approx(q1, rel=tol) and np.var(dvy) == pytest.approx(q1, rel=tol)
    assert np.mean(dx * dvx) == pytest.approx(q1 / 2, rel=2 * tol)
    assert np.var(s["inten"] - 5.0) == pytest.approx(q2, rel=tol)
    assert abs(np.corrcoef(dx, dy)[0, 1]) < 4 / math.sqrt(n)
    assert np.all(s["tp"] == 2)


def test_particles_leaving_the_image_lose_existence():
    pool = ParticlePool([2], (10, 10), engine="numpy", seed=1, q1=0.0, q2=0.0)
    pool.configure_groups([0], pb=0.0, pd=0.0)
    one = np.ones(2, np.int32)
    pool.set_state({0: dict(x=np.array([9.3, 5.0]), y=np.array([5.0, 5.0]), vx=np.array([0.5, 0.5]),
                            vy=np.zeros(2), inten=np.ones(2), e=one, tp=one)})
    pool.predict(0)
    np.testing.assert_array_equal(pool.state()["e"], [0, 1])


def brute_force_log_weight(z, x, y, inten, psf_sigma=0.7, sigma=1.0):
    """Eqs. 11–15 term by term in float64 over the 5×5 window (in-image pixels only)."""
    h, w = z.shape
    cx, cy = math.floor(x + 0.5), math.floor(y + 0.5)
    total = 0.0
    for j in range(cy - 2, cy + 3):
        for i in range(cx - 2, cx + 3):
            if 0 <= i < w and 0 <= j < h:
                hij = inten / (2 * math.pi * psf_sigma ** 2) * math.exp(-((i - x) ** 2 + (j - y) ** 2) / (2 * psf_sigma ** 2))
                total += -hij * (hij - 2 * z[j, i]) / (2 * sigma ** 2)
    return total


@pytest.mark.parametrize("engine", ["taichi", "numpy"])
def test_log_weights_equal_brute_force(rng, engine):
    (t, n), z = make_pools(rng, psf_sigma=0.9, noise_sigma=1.3)
    pool = t if engine == "taichi" else n
    st = {k: v[pool.state()["group"] == 0] for k, v in pool.state().items()}
    h, w = SHAPE  # windows half outside and wholly outside the image (E = 1 set by hand)
    st["x"][:8] = [-3.0, -1.2, -0.6, w - 0.4, w + 0.7, w + 5.0, 5.0, 10.0]
    st["y"][:8] = [4.0, 0.3, -1.4, h + 0.9, h - 0.5, 6.0, h + 1.6, -2.4]
    st["e"][:8] = 1
    pool.set_state({0: st})
    pool.weigh()
    s = pool.state()
    assert s["logw"][1] != 0 and s["logw"][5] == 0  # partial window counts, a window off the image does not
    ref = np.array([brute_force_log_weight(z, x, y, i, 0.9, 1.3) if e else 0.0
                    for x, y, i, e in zip(s["x"], s["y"], s["inten"], s["e"])])
    np.testing.assert_allclose(s["logw"], ref, rtol=2e-5, atol=2e-4)  # f32: 25 terms of size ≤ |I·z|


def test_segmented_normalisation_is_a_softmax_per_group(rng):
    (t, _), _ = make_pools(rng)
    t.weigh()
    s, w = t.state(), t.normalised_weights()
    for g in range(len(CAPS)):
        lw = s["logw"][s["group"] == g].astype(np.float64)
        ref = np.exp(lw - lw.max()) / np.exp(lw - lw.max()).sum()
        np.testing.assert_allclose(w[s["group"] == g], ref, rtol=1e-6)
        assert w[s["group"] == g].sum() == pytest.approx(1.0, abs=1e-12)


@pytest.mark.parametrize("systematic", [False, True])
def test_resampling_is_unbiased(systematic):
    """Offspring counts over R resamplings (Eq. 18): mean N_out·w per parent; variance N_out·w(1−w)
    for multinomial (the paper's independent uniforms), clearly less for systematic.  Input and
    output span several tiles, so the sorted walk crosses tile borders."""
    n_in, n_out, reps = 1500, 2500, 300
    rng = np.random.default_rng(2)
    logw = rng.normal(0, 1.5, n_in).astype(np.float32)
    pool = ParticlePool([n_out], (8, 8), engine="taichi", seed=9)
    pool.configure_groups([0], pb=0.0, pd=0.0)
    w = np.exp(logw.astype(np.float64) - logw.max())
    w /= w.sum()
    counts = np.zeros((reps, n_in))
    for r in range(reps):
        pool.set_counts([n_in])
        lw = pool._get("logw")
        lw[:n_in] = logw
        pool._put("logw", lw)
        pool.normalise()
        pool.resample(r, n_out=[n_out], systematic=systematic)
        counts[r] = np.bincount(pool._get("parent")[:n_out], minlength=n_in)
    mean = counts.mean(axis=0)
    expected = n_out * w
    var = n_out * w * (1 - w)
    se = np.sqrt(var / reps)  # multinomial; systematic has smaller variance, so the same bound holds
    assert np.all(np.abs(mean - expected) < 5 * se + 1e-9)
    z = (mean - expected) / np.maximum(se, 1e-12)
    assert abs(z.mean()) < 0.3  # no systematic bias across parents
    # sample variance over 300 reps: relative s.e. √(2/299) ≈ 0.08 per parent, ≈ 0.01 averaged over the
    # 500 heaviest parents
    heavy = np.argsort(w)[-500:]
    ratio = np.mean(counts[:, heavy].var(axis=0, ddof=1) / var[heavy])
    if systematic:
        assert ratio < 0.5
    else:
        assert 0.93 < ratio < 1.07
    assert pool.counts[0] == n_out  # output count differs from input count


@pytest.mark.parametrize("systematic", [False, True])
def test_parents_are_the_first_slots_above_the_positions(systematic):
    """Eq. 18 by a direct search: every output's parent is the first slot whose cumulative weight exceeds
    its position, for output counts that leave some of a tile's interleaved walks empty (1–3), end
    mid-tile or just past a tile, and for a group whose weight sits on a single particle."""
    n_in = [1500, 40, 900, 5]
    n_out = [[1, 2, 3, 7], [1025, 3, 1024, 2], [2049, 33, 4, 1]]
    rng = np.random.default_rng(4)
    pool = ParticlePool([2100, 100, 1100, 10], (8, 8), engine="taichi", seed=3)
    pool.configure_groups(range(4), pb=0.0, pd=0.0)
    for r, counts in enumerate(n_out):
        pool.set_counts(n_in)
        lw = pool._get("logw")
        for g, n in enumerate(n_in):
            lw[pool.off[g]:pool.off[g] + n] = rng.normal(0, 2.0, n) if g != 3 else [0, 0, 60, 0, 0]
        pool._put("logw", lw)
        pool.normalise()
        pool.resample(r, n_out=counts, systematic=systematic)
        parent, cum, pos = pool._get("parent"), pool._get("cum"), pool._get("spc")
        for g, (n, m) in enumerate(zip(n_in, counts)):
            o = int(pool.off[g])
            ref = o + np.minimum(np.searchsorted(cum[o:o + n], pos[o:o + m], side="right"), n - 1)
            np.testing.assert_array_equal(parent[o:o + m], ref, err_msg=f"rep {r} group {g}")
            if g == 3:
                assert (parent[o:o + m] == o + 2).all()


def test_capacity_overflow_is_a_clear_error_and_changes_nothing(rng):
    (t, _), _ = make_pools(rng)
    before = t.state()
    with pytest.raises(ParameterError, match=r"group 1: resampled count 1501 exceeds its capacity 1500"):
        t.resample(0, n_out=[600, 1501, 100])
    with pytest.raises(ParameterError, match="group 0: live count 701"):
        t.set_counts([701, 0, 0])
    after = t.state()
    for key in before:
        np.testing.assert_array_equal(before[key], after[key])
    with pytest.raises(ParameterError, match="capacity"):
        ParticlePool([10, 0], (5, 5))


@pytest.mark.parametrize("engine", ["taichi", "numpy"])
def test_load_states_round_trip(rng, engine):
    """Flat per-group states in, the same states out; groups left out keep their particles."""
    pool = ParticlePool([5, 7, 4], SHAPE, engine=engine)
    pool.set_state({2: dict(x=np.arange(3.0), y=np.ones(3), e=1), 0: dict(x=np.full(2, 9.0), inten=np.arange(2.0))})
    st = pool.state()
    np.testing.assert_array_equal(st["group"], [0, 0, 2, 2, 2])
    np.testing.assert_array_equal(st["slot"], [0, 1, 12, 13, 14])
    np.testing.assert_array_equal(st["x"], [9, 9, 0, 1, 2])
    np.testing.assert_array_equal(st["inten"], [0, 1, 0, 0, 0])
    np.testing.assert_array_equal(st["e"], [0, 0, 1, 1, 1])
    pool.load_states(np.array([1, 1]), dict(x=np.array([4.0, 5.0])), groups=[1])
    assert pool.counts.tolist() == [2, 2, 3]
    pool.load_states(np.array([1]), dict(x=np.array([6.0])))  # all groups: 0 and 2 become empty
    assert pool.counts.tolist() == [0, 1, 0] and pool.state()["x"].tolist() == [6.0]
    with pytest.raises(ParameterError, match="ordered by group"):
        pool.load_states(np.array([2, 0]), dict(x=np.zeros(2)))
    with pytest.raises(ParameterError, match="group 2: particle count 5 exceeds its capacity 4"):
        pool.load_states(np.full(5, 2), dict(x=np.zeros(5)))


def test_estimates_eq19_and_covariance(rng):
    (t, _), _ = make_pools(rng)
    est, s = t.estimates(), t.state()
    for g in range(len(CAPS)):
        sel = s["group"] == g
        e = s["e"][sel] == 1
        assert est.p_exist[g] == pytest.approx(e.mean())
        assert est.x[g] == pytest.approx(s["x"][sel][e].mean(), rel=1e-6)  # Eq. 19
        assert est.intensity[g] == pytest.approx(s["inten"][sel][e].mean(), rel=1e-6)
        assert est.tp_mean[g] == pytest.approx(s["tp"][sel].mean())
        cov = np.cov(np.stack([s["x"][sel], s["y"][sel]]).astype(np.float64), bias=True)
        np.testing.assert_allclose(est.cov[g], cov, rtol=1e-6, atol=1e-9)
        cov_e = np.cov(np.stack([s["x"][sel][e], s["y"][sel][e]]).astype(np.float64), bias=True)  # SCEF's
        np.testing.assert_allclose(est.cov_e[g], cov_e, rtol=1e-6, atol=1e-9)
        assert not np.allclose(est.cov_e[g], est.cov[g])  # a different cloud
    empty = ParticlePool([10, 10], SHAPE, engine="taichi")
    empty.set_state({0: dict(x=np.arange(10.0), y=np.zeros(10), vx=0, vy=0, inten=1.0, e=0, tp=1)})
    assert np.all(np.isnan(empty.estimates().cov_e))  # no E = 1 particle, or no particle at all


@pytest.mark.parametrize("engine", ["taichi", "numpy"])
def test_one_launch_step_equals_the_three_stages(rng, engine):
    """``step`` (predict, weigh and resample in one launch) gives the bits of the three calls, on
    both engines, with and without new output counts and with systematic resampling."""
    states = random_states(rng, CAPS, SHAPE)
    z = rng.standard_normal(SHAPE).astype(np.float32)
    pools = []
    for _ in range(2):
        p = ParticlePool(CAPS, SHAPE, engine=engine, seed=5, map_capacity=8)
        p.configure_groups([0, 1], "uniform", pb=0.3, pd=0.2, intensity=(2.0, 9.0))
        p.configure_groups([2], "copy", pb=0.3, pd=0.2)
        p.set_state(states)
        pools.append(p)
    one, three = pools
    seq_out = np.full(sum(CAPS) + 3, -7, np.int32)
    for f, (n_out, systematic) in enumerate([(None, False), ([650, 1400, 0], False), ([500, 900, 300], True)]):
        seq_out[:] = -7
        seq = one.step(f, z, n_out=n_out, systematic=systematic, seq_out=seq_out if f else None)
        three.load_frame(z)
        three.predict(f)
        three.weigh()
        three.resample(f, n_out=n_out, systematic=systematic)
        a, b = one.state(), three.state()
        assert all(np.array_equal(a[k], b[k]) for k in a), f
        np.testing.assert_array_equal(one.max_log_weights(), three.max_log_weights())
        if f:  # the Seq read in the same launch: the resampled particles' own, in state order, in seq_out's front
            assert seq.base is seq_out and len(seq) == int(one.counts.sum())
            np.testing.assert_array_equal(seq, b["seq"])
            assert (seq_out[len(seq):] == -7).all()
        else:
            assert seq is None
    with pytest.raises(ParameterError, match="int32"):
        one.step(3, z, seq_out=np.zeros(sum(CAPS), np.int64))


def test_weights_use_the_frame_as_it_was_loaded(rng):
    """load_frame keeps its own copy: a caller that reuses its array before weigh changes nothing."""
    (t, _), z = make_pools(rng)
    ref = ParticlePool(CAPS, SHAPE, engine="taichi", seed=11, map_capacity=64)
    ref.set_state({g: {k: v[t.state()["group"] == g] for k, v in t.state().items() if k not in ("group", "slot")}
                   for g in range(len(CAPS))})
    ref.load_frame(z.copy())
    t.load_frame(z)
    z[...] = 100.0
    t.weigh()
    ref.weigh()
    np.testing.assert_array_equal(t.state()["logw"], ref.state()["logw"])
    assert np.abs(t.state()["logw"]).max() > 0


def test_frame_of_another_shape_is_refused_and_the_border_stays_zero(rng):
    """A frame whose shape is not the pool's gets an error naming both shapes, for load_frame and step
    alike; a frame of ones leaves the weights' zero border as it was (the kernels read through it)."""
    from tbd_taichi.kernels.particles import PAD

    (t, n), z = make_pools(rng)
    for pool in (t, n):
        with pytest.raises(ParameterError, match=r"shape \(23, 30\).*built for \(23, 31\)"):
            pool.load_frame(z[:, :-1])
        with pytest.raises(ParameterError, match=r"shape \(31, 23\)"):
            pool.step(0, z.T)
        pool.load_frame(np.ones(SHAPE))
        bordered = pool._z
        assert bordered.shape == (SHAPE[0] + 2 * PAD, SHAPE[1] + 2 * PAD)
        assert bordered[PAD:-PAD, PAD:-PAD].min() == 1.0 and bordered.sum() == SHAPE[0] * SHAPE[1]


def test_same_results_with_one_and_two_threads(rng, monkeypatch):
    """The parallel loops (forced: pools this small, or CPUs with two threads, run serially) give the
    same particles with one worker thread and with two."""
    import tbd_taichi.particles as particles

    monkeypatch.setattr(particles, "SERIAL_PARTICLES", 0)
    monkeypatch.setattr(particles, "SERIAL_THREADS", 0)
    states = random_states(rng, CAPS, SHAPE)
    z = rng.standard_normal(SHAPE).astype(np.float32)

    def run():
        p = ParticlePool(CAPS, SHAPE, engine="taichi", seed=5)
        p.configure_groups([0, 1, 2], pb=0.2, pd=0.1, intensity=(2.0, 9.0))
        p.set_state(states)
        for f in range(4):
            p.step(f, z)
        return p.state()

    try:
        tbd_taichi.init("cpu", threads=1)
        one = run()
        tbd_taichi.init("cpu", threads=2)
        two = run()
    finally:
        tbd_taichi.init(TEST_ARCH)
    for key in one:
        np.testing.assert_array_equal(one[key], two[key])


@pytest.mark.skipif(TEST_ARCH != "cpu", reason="the serial/parallel choice is the CPU's")
def test_particle_loops_are_serial_for_small_pools_or_two_threads():
    """Serial loops up to SERIAL_PARTICLES slots, and at any size with at most SERIAL_THREADS CPU
    threads (measured faster there); parallel for large pools on more threads."""
    import tbd_taichi.particles as particles

    big = particles.SERIAL_PARTICLES + 1
    try:
        tbd_taichi.init("cpu", threads=2)
        assert ParticlePool([big], SHAPE).k.serial
        tbd_taichi.init("cpu", threads=4)
        assert not ParticlePool([big], SHAPE).k.serial
        assert ParticlePool([1000], SHAPE).k.serial
    finally:
        tbd_taichi.init(TEST_ARCH)


def test_gpu_layout_gives_the_same_bits_on_the_cpu(rng, monkeypatch):
    """The one-thread-per-slot layout that GPUs use, run on the CPU, against the tiled CPU layout:
    every stage, multinomial and systematic resampling, a top-up, copies, an empty group and the
    one-launch step."""
    import tbd_taichi.particles as particles

    states = random_states(rng, CAPS, SHAPE)
    z = rng.standard_normal(SHAPE).astype(np.float32)

    def run():
        p = ParticlePool(CAPS, SHAPE, engine="taichi", seed=3, map_capacity=8)
        p.configure_groups([0], "uniform", pb=0.3, pd=0.2, intensity=(2.0, 9.0))
        p.configure_groups([1], "map", pb=0.3, pd=0.2, intensity=(2.0, 9.0))
        p.configure_groups([2], "copy", pb=0.3, pd=0.2)
        p.set_proposal_map({1: (np.array([5, 40, 300]), np.array([0.2, 0.5, 0.3]))})
        p.set_state(states)
        out = []
        for f in range(4):
            p.load_frame(z)
            p.predict(f, top_up=[700, 1500, 300] if f == 1 else None)
            p.weigh()
            p.resample(f, n_out=[650, 0 if f == 2 else 1400, 300], systematic=f == 3)
            out.append((p.state(), p.estimates().x, p.max_log_weights(), p._get("gmax")))
        for f in range(4, 6):  # the one-launch step
            p.step(f, z, n_out=[600, 1300, 250] if f == 4 else None, systematic=f == 5)
            out.append((p.state(), p.estimates().x, p.max_log_weights(), p._get("gmax")))
        return out

    tiled = run()
    monkeypatch.setattr(particles, "one_thread_per_slot", lambda arch: True)
    flat = run()
    for (st, *rest_t), (sf, *rest_f) in zip(tiled, flat):
        for key in st:
            np.testing.assert_array_equal(st[key], sf[key], err_msg=key)
        for a, b in zip(rest_t, rest_f):  # Eq. 19 estimates, best E = 1 weights, Eq. 16's maxima
            np.testing.assert_array_equal(a, b)


@pytest.mark.skipif(TEST_ARCH != "cpu", reason="the split tile loops are the CPU's")
@pytest.mark.parametrize("threads", [1, 2])
@pytest.mark.parametrize("caps", [[2100, 1500, 1300, 1100], [3100, 1500, 300]])
def test_split_tile_loops_and_fused_step_give_the_same_bits(rng, monkeypatch, threads, caps):
    """Tile loops split over two threads (forced: ``tile_threads`` splits only pools of SPLIT_PARTICLES
    slots or more, and only with pinned workers) against the serial layout, on one and two threads:
    the fused one-launch step of a pool without copies (a top-up, an empty group, multinomial and
    systematic resampling, the Seq read-out), and of a pool with copies.  Four groups (3 + 2 + 1 + 2
    tiles; the copying group 2 has two) are dealt out group by group, and then the pool with copies is
    fused too; three (4 + 2 + 1) tile by tile, and the pool with copies runs split, unfused loops.
    Both threads get partial tiles."""
    import tbd_taichi.particles as particles

    states = random_states(rng, caps, SHAPE)
    z = rng.standard_normal(SHAPE).astype(np.float32)
    z[0, 0] = 60.0

    def run(copies):
        p = ParticlePool(caps, SHAPE, engine="taichi", seed=9, map_capacity=8)
        p.configure_groups([0] + list(range(3, len(caps))), "uniform", pb=0.3, pd=0.2, intensity=(2.0, 9.0))
        p.configure_groups([1], "map", pb=0.3, pd=0.2, intensity=(2.0, 9.0))
        p.configure_groups([2], "copy" if copies else "uniform", pb=0.3, pd=0.2)
        p.set_proposal_map({1: (np.array([5, 40, 300]), np.array([0.2, 0.5, 0.3]))})
        p.set_state(states)
        out = []
        for f in range(5):
            seq = np.empty(p.capacity, np.int32)
            top_up = caps if f == 1 else None
            n_out = ([caps[0] - 100, 0, 280] + [1000] * (len(caps) - 3)) if f == 2 else None
            got = p.step(f, z, n_out=n_out, systematic=f == 4, top_up=top_up, seq_out=seq)
            out.append((p.state(), got.copy(), p.estimates().x, p.max_log_weights(), p._get("gmax")))
        return out, (p.split, p.k.tiles_by_group, p._fused_step())

    try:
        tbd_taichi.init("cpu", threads=threads)
        for copies in (False, True):
            serial, one = run(copies)
            monkeypatch.setattr(particles, "tile_threads", lambda capacity, n_tiles, flat: 2)
            split, two = run(copies)
            monkeypatch.undo()
            assert (one[0], two) == (1, (2, len(caps) >= 4, len(caps) >= 4 or not copies))
            for (st, *rest_t), (sp, *rest_s) in zip(serial, split):
                for key in st:
                    np.testing.assert_array_equal(st[key], sp[key], err_msg=key)
                for a, b in zip(rest_t, rest_s):
                    np.testing.assert_array_equal(a, b)
    finally:
        tbd_taichi.init(TEST_ARCH)


@pytest.mark.skipif(TEST_ARCH != "cpu", reason="the paired step is the CPU's split layout")
@pytest.mark.parametrize("split", [2, 1])
def test_paired_step_gives_each_pool_its_own_bits(rng, monkeypatch, split):
    """``step_with``: a split pool (four groups, whole groups per thread: the searching PFs; ``split`` 1: serial
    and unsplit, as SGDS-PF's pool on real video) and a serial pool of copying groups (the tracking PFs: one
    group of two tiles, an empty group, one emptied on the way) in one launch, against each pool's own ``step``
    and ``estimates``, over a top-up, a partial resampling count and the Seq read-out.  It fails if a group of
    either pool is dropped or stepped twice."""
    import tbd_taichi.particles as particles

    caps, track_caps = [2100, 1500, 1300, 1100], [500, 1200, 500, 500]
    states = random_states(rng, caps, SHAPE)
    track_states = random_states(rng, track_caps, SHAPE)
    del track_states[2]
    z = rng.standard_normal(SHAPE).astype(np.float32)
    z[0, 0] = 60.0

    def run(paired):
        p = ParticlePool(caps, SHAPE, engine="taichi", seed=9, map_capacity=8)
        p.configure_groups([0, 2, 3], "uniform", pb=0.3, pd=0.2, intensity=(2.0, 9.0))
        p.configure_groups([1], "map", pb=0.3, pd=0.2, intensity=(2.0, 9.0))
        p.set_proposal_map({1: (np.array([5, 40, 300]), np.array([0.2, 0.5, 0.3]))})
        p.set_state(states)
        t = ParticlePool(track_caps, SHAPE, engine="taichi", seed=17)
        t.configure_groups(np.arange(4), "copy", pb=0.3, pd=0.1)
        t.set_state(track_states)
        assert p.pairs_with(t)
        out = []
        for f in range(4):
            if f == 2:
                t.set_counts([500, 1200, 0, 0])
            seq = np.empty(p.capacity, np.int32)
            top_up = caps if f == 1 else None
            if paired:
                got, est = p.step_with(t, f, z, top_up=top_up, seq_out=seq)
            else:
                got = p.step(f, z, top_up=top_up, seq_out=seq)
                t.step(f, z)
                est = t.estimates()
            out.append((p.state(), t.state(), got.copy(), est.x, est.cov_e, est.max_logw, p.max_log_weights()))
        return out

    monkeypatch.setattr(particles, "tile_threads", lambda capacity, n_tiles, flat: split if capacity > 3000 else 1)
    try:
        tbd_taichi.init("cpu", threads=2)
        paired, separate = run(True), run(False)  # run(False) steps the same pools through step and estimates
    finally:
        tbd_taichi.init(TEST_ARCH)
    for (sp, tp, *rest_p), (ss, ts, *rest_s) in zip(paired, separate):
        for a, b in ((sp, ss), (tp, ts)):
            for key in a:
                np.testing.assert_array_equal(a[key], b[key], err_msg=key)
        for a, b in zip(rest_p, rest_s):
            np.testing.assert_array_equal(a, b)
    assert len(paired[-1][1]["x"]) == 1700  # the tracking pool's live groups were stepped


def test_pools_pair_only_with_the_same_frame_and_constants(monkeypatch):
    """``pairs_with``: not across engines, frame shapes or motion constants, nor for a pool that is not
    split by group (then ``step_with`` runs the three calls it stands for)."""
    import tbd_taichi.particles as particles

    monkeypatch.setattr(particles, "tile_threads", lambda capacity, n_tiles, flat: 2)
    a = ParticlePool([1100] * 4, SHAPE)
    if not a._fused_step():  # a GPU: no split layout
        assert not a.pairs_with(ParticlePool([500], SHAPE))
        return
    assert a.pairs_with(ParticlePool([500], SHAPE))
    assert not a.pairs_with(ParticlePool([500], SHAPE, engine="numpy"))
    assert not a.pairs_with(ParticlePool([500], (SHAPE[0] + 1, SHAPE[1])))
    assert not a.pairs_with(ParticlePool([500], SHAPE, q1=0.002))
    assert not ParticlePool([1100] * 2, SHAPE).pairs_with(ParticlePool([500], SHAPE))  # tiles dealt one by one


def test_serial_pools_pair_on_one_thread(monkeypatch):
    """Two serial, unsplit pools pair (one thread steps both pools' groups, as their own steps would); a pool
    whose loops run in parallel does not (its step would lose the threads)."""
    import tbd_taichi.particles as particles

    monkeypatch.setattr(particles, "tile_threads", lambda capacity, n_tiles, flat: 1)
    a = ParticlePool([1100] * 4, SHAPE)
    if a.k.flat:  # a GPU: no CPU layout
        assert not a.pairs_with(ParticlePool([500], SHAPE))
        return
    assert a.k.serial and a.pairs_with(ParticlePool([500], SHAPE))
    monkeypatch.setattr(particles, "SERIAL_THREADS", 0)
    big = ParticlePool([particles.SERIAL_PARTICLES + 1], SHAPE)  # neither small nor on ≤ 2 threads: parallel loops
    assert not big.k.serial and not big.pairs_with(ParticlePool([500], SHAPE))


def test_tile_loops_split_only_for_large_pools_with_pinned_workers(monkeypatch):
    """``tile_threads``: 1 (serial) without pinned workers, for small pools and on GPUs; else the workers,
    at most one per tile."""
    import tbd_taichi.particles as particles
    from tbd_taichi import backend

    big = particles.SPLIT_PARTICLES
    monkeypatch.setattr(backend, "pinned_workers", lambda: [])
    assert particles.tile_threads(big, 40, False) == 1
    monkeypatch.setattr(backend, "pinned_workers", lambda: [11, 12, 13])
    assert particles.tile_threads(big, 40, False) == 3
    assert particles.tile_threads(big, 2, False) == 2
    assert particles.tile_threads(big - 1, 40, False) == 1
    assert particles.tile_threads(big, 40, True) == 1


@pytest.mark.parametrize("engine", ["taichi", "numpy"])
def test_keep_removes_particles_in_place_and_in_order(rng, engine):
    """ParticlePool.keep against the host reference load_states(state[keep]); groups of all sizes, empty ones included."""
    (t, n), _ = make_pools(rng)
    pool = t if engine == "taichi" else n
    pool.set_counts([700, 0, 37])
    pool.predict(0)
    before = pool.state()
    keep = rng.random(len(before["x"])) < 0.6
    keep[:5] = False  # the first slots go: the rest move down
    pool.keep(keep)
    after = pool.state()
    np.testing.assert_array_equal(pool.counts, np.bincount(before["group"][keep], minlength=3))
    for key in ("x", "vx", "y", "vy", "inten", "e", "tp", "seq", "group"):
        np.testing.assert_array_equal(after[key], before[key][keep], err_msg=key)
    with pytest.raises(ParameterError, match="keep flag"):
        pool.keep(np.ones(3, bool))


def test_numpy_models_are_the_pools_motion_and_likelihood():
    """numpy_kernels.models: NCV without noise is constant velocity with the intensity floored, and the point-PSF
    log-ratio of a particle on an empty frame is −½a²Σgx²Σgy²/σ² < 0, larger on a bright pixel under it."""
    from tbd_taichi.numpy_kernels import models

    f32 = np.float32
    zero = (np.zeros(2, f32),) * 5
    x, vx, y, vy, inten = models.ncv_step(np.array([1, 2], f32), np.array([0.5, -1], f32), np.array([3, 4], f32),
                                          np.array([0.25, 0], f32), np.array([0.05, 2], f32), zero,
                                          models.ncv_noise_factors(0.001, 0.01), 0.1)
    np.testing.assert_array_equal(x, [1.5, 1]), np.testing.assert_array_equal(y, [3.25, 4])
    np.testing.assert_array_equal(vx, [0.5, -1]), np.testing.assert_array_equal(inten, f32([0.1, 2]))
    z = np.zeros((9, 9), f32)
    consts = models.psf_constants(0.7, 1.0)
    dark = models.point_psf_log_ratio(np.array([4.0], f32), np.array([4.0], f32), np.array([5.0], f32), z, consts)
    z[4, 4] = 3.0
    bright = models.point_psf_log_ratio(np.array([4.0], f32), np.array([4.0], f32), np.array([5.0], f32), z, consts)
    assert dark[0] < 0 < bright[0]


def test_generic_pool_has_no_population_kernels():
    """The generic pool and its kernels carry no SGDS-PF population logic (SearchingPool adds it)."""
    from tbd_taichi.methods.sgds.searching_pool import SearchingPool

    pool = ParticlePool([10], SHAPE, engine="numpy")
    assert not hasattr(pool, "eliminate") and not hasattr(pool.k, "eliminate")
    searching = SearchingPool([10], SHAPE, engine="numpy")
    assert hasattr(searching, "eliminate_and_hand_over") and hasattr(searching.k, "eliminate_and_hand_over")


@pytest.mark.parametrize("engine", ["taichi", "numpy"])
def test_the_kernels_hold_the_hosts_live_counts_after_every_operation(rng, engine):
    """The paired step reads the second pool's live counts from its kernels (``n``), so every operation that
    changes the host's counts must leave the same counts there: states loaded, counts set, a top-up, partial
    resampling, a step with a top-up, particles removed, and an SGDS-PF hand-over."""
    from tbd_taichi.methods.sgds.searching_pool import SearchingPool

    (t, n), z = make_pools(rng)
    pool = t if engine == "taichi" else n
    checks = []

    def check(what):
        np.testing.assert_array_equal(pool._get("n"), pool.counts, err_msg=what)
        checks.append(what)

    check("set_state")
    pool.set_counts([650, 0, 283])
    check("set_counts")
    pool.predict(0, top_up=[700, 100, 283])
    check("predict with a top-up")
    pool.weigh()
    pool.resample(0, n_out=[300, 50, 283])
    check("resample to other counts")
    pool.step(1, z, top_up=[500, 50, 290])
    check("step with a top-up")
    keep = rng.random(int(pool.counts.sum())) < 0.5
    pool.keep(keep)
    check("keep")
    pool.load_states(np.array([0, 0, 2]), {name: np.zeros(3) for name in ("x", "vx", "y", "vy", "inten", "e", "tp")})
    check("load_states")
    s = SearchingPool([40, 40], SHAPE, engine=engine, seed=3)
    s.configure_groups([0, 1], "uniform", pb=0.3, pd=0.2)
    s.predict(0, top_up=[40, 25])
    pp = np.repeat([0, 1], [40, 25])
    index = np.zeros(SHAPE, np.int32)
    s.eliminate_and_hand_over(pp, [40, 25], [10, 5], [0.5, 0.5], index, 0.0, 0.0, [], 1.0, 1)
    np.testing.assert_array_equal(s._get("n"), s.counts, err_msg="eliminate_and_hand_over")
    assert s.counts.sum() < 65 and len(checks) == 7


def test_a_pool_at_another_frame_size_reuses_a_finished_pools_fields_and_weighs_at_its_own_size(rng):
    """A tracking-style pool's fields do not follow the frame (its kernels read frame_hw), so a pool at another
    size takes the fields of a finished one; it must predict and weigh at its own size, as the NumPy twin does (the
    first pool's frame is 40 px wide, the second's 51: particles at x > 40 live and are weighed)."""
    import gc

    from tbd_taichi import backend

    tbd_taichi.init(TEST_ARCH)
    caps, shape = [700, 700], (23, 51)
    first = ParticlePool(caps, (30, 40), seed=11)
    fields = first.k._target
    del first
    gc.collect()
    states = random_states(rng, caps, shape)
    z = rng.standard_normal(shape).astype(np.float32)
    z[5:8, 45:48] += 3.0  # a bright spot where only the new frame has pixels
    pools = []
    for engine in ("taichi", "numpy"):
        pool = ParticlePool(caps, shape, engine=engine, seed=11)
        pool.configure_groups([0, 1], "uniform", pb=0.3, pd=0.05, vmax=1.5, intensity=(1.0, 4.0))
        pool.set_state(states)
        pool.load_frame(z)
        pools.append(pool)
    reused, twin = pools
    assert reused.k._target is fields and backend.holds_old_values(fields)
    for frame in range(3):
        for pool in pools:
            pool.predict(frame)
        assert_states_match(reused, twin)
        for pool in pools:
            pool.weigh()
        assert_states_match(reused, twin, rtol=2e-5, atol=2e-5)  # f32 exp differs by ulps
    s = reused.state()
    assert ((s["x"] > 40) & (s["e"] == 1) & (s["logw"] != 0)).any()
