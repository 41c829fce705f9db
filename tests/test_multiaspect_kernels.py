"""The multiaspect kernels (kernels/multiaspect.py) against their NumPy twin and against references: d against the
dense Eq. 14 matrix, λ and ρ against yᵀAh and hᵀAh at interior, edge and corner centroids, the (z, s) transition
against Eq. 2 (P_in, G, p_a, f₀), the resample-move step keeping a toy posterior, and the APF's Eqs. 23–24 by hand."""
import numpy as np
import pytest
from scipy import ndimage, stats

from tbd_taichi.kernels import multiaspect as tk
from tbd_taichi.multiaspect import aspect_transition, energy_tables, motion_noise, noise_factor, p_inside
from tbd_taichi.numpy_kernels import multiaspect as nk

BH, BV, S2 = 0.21, 0.23, 1.7


def dense_a(h, w, bh=BH, bv=BV):
    """Eq. 14's σ_c²Σ_v⁻¹ = I ⊗ (I − β_h B_M) − β_v B_L ⊗ I (row-lexicographic)."""
    b = lambda n: np.eye(n, k=1) + np.eye(n, k=-1)
    return np.kron(np.eye(h), np.eye(w) - bh * b(w)) - bv * np.kron(b(h), np.eye(w))


def make_pools(shape, templates, groups=2, n=500, G=None):
    """The Taichi kernels and the twin with the same templates, energy tables and G."""
    G = aspect_transition(len(templates)) if G is None else G
    cdf = np.cumsum(G, axis=0).T.copy()
    cdf[:, -1] = 1.0
    pools = (tk.MultiaspectKernels(groups, n, shape, templates.shape),
             nk.MultiaspectKernels(groups, n, shape, templates.shape))
    for k in pools:
        k.set_templates(templates, energy_tables(templates, shape))
        k.put("gcdf", cdf)
        k.put("gpar", np.tile(np.array([[BH, BV, S2]], np.float32), (groups, 1)))
    return pools


def random_templates(rng, k=3, h=5, w=7):
    t = rng.uniform(0.2, 2.0, (k, h, w)) * (rng.random((k, h, w)) < 0.7)
    t[:, h // 2, w // 2] = 1.5
    return t


def load(pools, rng, shape, frames=None, z_low=0):
    """Both pools with the same random particles (some off the grid), frames and GMRF rows."""
    k0 = pools[0]
    h, w = shape
    c = k0.capacity
    state = np.zeros((c, 4), np.float32)
    state[:, 0] = rng.uniform(-8, w + 7, c)
    state[:, 2] = rng.uniform(-8, h + 7, c)
    state[:, [1, 3]] = rng.normal(0, 1.5, (c, 2))
    z = rng.integers(z_low, k0.k + 1, c).astype(np.int32)
    frames = rng.normal(0, 2, (k0.groups,) + shape).astype(np.float32) if frames is None else frames
    gpar = np.tile(np.array([[BH, BV, S2]], np.float32), (k0.groups, 1))
    gpar[:, 0] += 0.01 * np.arange(k0.groups)
    for k in pools:
        k.set_particles(state, z)
        k.put("anc", rng.integers(0, c, c).astype(np.int32))
        k.load(frames, gpar)
    return state, z, frames, gpar


MOTION = np.asarray(noise_factor(motion_noise(6.0, 0.04, 0.2)), np.float32)
LAW = np.array([-3, 20, -2, 15, 0.5, 0.3, 1.0], np.float32)


@pytest.mark.parametrize("shape", [(13, 17), (8, 9)])
def test_dmap_matches_dense_eq14_and_scipy(rng, shape):
    pools = make_pools(shape, random_templates(rng))
    _, _, frames, gpar = load(pools, rng, shape)
    for k in pools:
        d = [k.d_image(g) for g in range(k.groups)]
        for g in range(k.groups):
            a = dense_a(*shape, gpar[g, 0], gpar[g, 1])
            np.testing.assert_allclose(d[g].ravel(), a @ frames[g].ravel().astype(float), rtol=0, atol=2e-5)
            kernel = np.array([[0, -gpar[g, 1], 0], [-gpar[g, 0], 1, -gpar[g, 0]], [0, -gpar[g, 1], 0]])
            ref = ndimage.correlate(frames[g].astype(float), kernel, mode="constant")
            np.testing.assert_allclose(d[g], ref, atol=2e-5)


@pytest.mark.parametrize("engine", [0, 1])
def test_likelihood_is_the_exact_gaussian_ratio_at_interior_edge_and_corner(rng, engine):
    shape = (11, 14)
    t = random_templates(rng, k=2, h=5, w=3)
    pools = make_pools(shape, t, groups=1, n=8)
    k = pools[engine]
    frames = rng.normal(0, 2, (1,) + shape).astype(np.float32)
    k.load(frames, np.array([[BH, BV, S2]], np.float32))
    # centroids (col, row): interior, left edge, bottom edge, corner, just on the extended grid, off it
    spots = [(6, 5), (0, 4), (7, 10), (-1, 12), (15, -2), (16, 5)]
    state = np.zeros((8, 4), np.float32)
    z = np.array([1, 2, 1, 2, 1, 1, 0, 2], np.int32)
    for i, (c, r) in enumerate(spots):
        state[i, 0], state[i, 2] = c + 0.3, r - 0.4
    state[6:, 0], state[6:, 2] = 5, 5
    state[7, 0] = -40  # off the grid
    k.put("prop", state)
    k.put("prop_z", z)
    k.likelihood()
    ll = k.get("prop_ll")
    a = dense_a(*shape)
    for i in range(8):
        img = np.zeros(shape)
        c, r = int(np.floor(state[i, 0] + 0.5)), int(np.floor(state[i, 2] + 0.5))
        if z[i]:
            for da in range(5):
                for db in range(3):
                    rr, cc = r + da - 2, c + db - 1
                    if 0 <= rr < shape[0] and 0 <= cc < shape[1]:
                        img[rr, cc] = t[z[i] - 1, da, db]
        h = img.ravel()
        lam, rho = frames[0].ravel() @ a @ h, h @ a @ h  # Eqs. 11, 12
        assert ll[i] == pytest.approx((2 * lam - rho) / (2 * S2), abs=2e-4), i
    assert ll[5] == 0.0 and ll[6] == 0.0 and ll[7] == 0.0


def test_cached_template_sums_are_bit_identical_in_any_slot_order(rng):
    """The kernels reuse ℓ (Eqs. 10, 15) within a run of slots (kernels.multiaspect.log_ratio): particles crowded on
    a few (centroid, aspect) pairs, as after resampling, give the same bits whatever the order (hits, misses and
    cache collisions differ), and agree with the twin, which sums every particle."""
    shape, groups, n = (21, 26), 2, 1500
    pools = make_pools(shape, random_templates(rng, k=4), groups=groups, n=n)
    load(pools, rng, shape)
    c = groups * n
    cells = np.stack([rng.integers(-3, shape[1] + 3, 60), rng.integers(-3, shape[0] + 3, 60)], axis=1)
    pick = rng.integers(0, len(cells), c)
    state = np.zeros((c, 4), np.float32)
    state[:, 0] = cells[pick, 0] + rng.uniform(-0.49, 0.49, c)
    state[:, 2] = cells[pick, 1] + rng.uniform(-0.49, 0.49, c)
    z = rng.integers(0, 5, c).astype(np.int32)  # some absent
    state[::97, 0] = -50.0  # some off the extended grid
    perm = np.concatenate([g * n + rng.permutation(n) for g in range(groups)])  # within each group
    lls = []
    for k, order in ((pools[0], np.arange(c)), (pools[0], perm), (pools[1], np.arange(c))):
        k.put("prop", state[order])
        k.put("prop_z", z[order])
        k.likelihood()
        lls.append(k.get("prop_ll")[np.argsort(order)])
    np.testing.assert_array_equal(lls[0], lls[1])
    np.testing.assert_allclose(lls[0], lls[2], rtol=1e-5, atol=1e-4)
    assert np.count_nonzero(lls[0]) > c // 2


def test_every_step_agrees_with_the_twin(rng):
    shape = (15, 19)
    pools = make_pools(shape, random_templates(rng), groups=3, n=700)
    load(pools, rng, shape)
    for kind in ("rs", "apf"):
        outs = []
        for k in pools:
            o = {}
            k.configure(MOTION, LAW)
            k.propagate(7, 3, 0, 0, 0, 0, 0.3, 0, 0)
            o["prop"], o["prop_z"] = k.get("prop"), k.get("prop_z")
            k.likelihood()
            o["ll"] = k.get("prop_ll")
            k.resample(7, 3, 0, 0, 0, 0)
            o["cdf"], o["total"], o["pick"] = k.get("cdf"), k.get("total"), k.get("pick")
            o["cur1"], o["anc"] = k.get("cur"), k.get("anc")
            if kind == "rs":
                k.propagate(7, 3, 1, 1, 1, 0, 0.3, 0, 1)  # computes prop_ll too, and one MH move into cur
                o["cur"], o["cur_z"] = k.get("cur"), k.get("cur_z")
                k.propagate(7, 3, 2, 1, 1, 0, 0.3, 0, 2)  # the last sweep: into prev's side 1
            else:
                k.propagate(7, 3, 1, 1, 1, 0, 0.3, 0, 0)
                k.resample(7, 3, 1, 1, 1, 0)
                o["cdf2"], o["pick2"] = k.get("cdf"), k.get("pick")
            o["gsum"] = np.zeros((k.groups, tk.SUM_ASPECT + k.k))
            o["prop2"], o["z2"], o["ll2"] = k.get("prop"), k.get("prop_z"), k.get("prop_ll")
            k.summarize(o["gsum"], 1)
            o["prev"], o["prev_z"] = k.particles(1)
            outs.append(o)
        a, b = outs
        for key in a:
            if a[key].dtype.kind in "iu":
                np.testing.assert_array_equal(a[key], b[key], err_msg=f"{kind} {key}")
            else:
                np.testing.assert_allclose(a[key], b[key], rtol=1e-4, atol=1e-4, err_msg=f"{kind} {key}")
        z = a["prev_z"].reshape(3, 700)
        np.testing.assert_array_equal(a["gsum"][:, tk.SUM_ABSENT], (z == 0).sum(axis=1))
        np.testing.assert_array_equal(a["gsum"][:, tk.SUM_ASPECT:], [np.bincount(r, minlength=4)[1:] for r in z])


def test_prior_draw_agrees_and_follows_its_law(rng):
    shape = (20, 30)
    pools = make_pools(shape, random_templates(rng), groups=2, n=20000)
    law = np.array([2, 12, 5, 9, 2.0, 0.1, 0.0], np.float32)
    for k in pools:
        k.init_prior(11, 0.25, law)
    s0, z0 = pools[0].particles(0)
    np.testing.assert_allclose(s0, pools[1].particles(0)[0], atol=1e-5)
    np.testing.assert_array_equal(z0, pools[1].particles(0)[1])
    n = len(z0)
    # P(z = 0) = 0.25 within 4 binomial sd; aspects uniform on 1..K (chi-square at the 0.1% level)
    assert abs((z0 == 0).mean() - 0.25) < 4 * np.sqrt(0.25 * 0.75 / n)
    counts = np.bincount(z0[z0 > 0], minlength=4)[1:]
    assert stats.chisquare(counts).pvalue > 1e-3
    assert s0[:, 0].min() >= 2 and s0[:, 0].max() <= 12 and s0[:, 2].min() >= 5 and s0[:, 2].max() <= 9
    assert abs(s0[:, 1].mean() - 2.0) < 0.005 and abs(s0[:, 3].std() - 0.1) < 0.005


def test_transition_follows_eq2(rng):
    """Exits with 1 − P_in (Eq. 6, closed form), aspects by G's column (Eq. 1), entries with p_a, a uniform aspect
    and s ~ f₀ (Eq. 5), the motion by Eq. 4's Q; in both engines."""
    shape = (12, 16)
    t = random_templates(rng, k=4, h=5, w=5)
    n = 40000
    pools = make_pools(shape, t, groups=1, n=n)
    state = np.zeros((n, 4), np.float32)
    z = np.zeros(n, np.int32)
    # half the particles present at aspect 2 straddling the right edge of the extended grid (x + ẋ = 17.5 ± …)
    half = n // 2
    state[:half, 0], state[:half, 1], state[:half, 2], state[:half, 3] = 17.45, 0.0, 5.0, 0.0
    z[:half] = 2
    motion = np.asarray(noise_factor(motion_noise(6.0, 0.04, 0.2)), np.float32)
    G = aspect_transition(4)
    for k in pools:
        k.set_particles(state, z)
        k.configure(motion, LAW)
        k.propagate(3, 1, 0, 0, 0, 0, 0.2, 0, 0)
    pz, ps = pools[0].get("prop_z"), pools[0].get("prop")
    np.testing.assert_array_equal(pz, pools[1].get("prop_z"))
    p_in = float(p_inside(17.45, 5.0, motion[0], shape, (2, 2)))
    assert 0.2 < p_in < 0.9
    stay = pz[:half] != 0
    assert abs(stay.mean() - p_in) < 4 * np.sqrt(p_in * (1 - p_in) / half)
    counts = np.bincount(pz[:half][stay], minlength=5)[1:]
    expected = G[:, 1] * stay.sum()
    used = expected > 0
    assert counts[~used].sum() == 0
    assert stats.chisquare(counts[used], expected[used]).pvalue > 1e-3
    moved = ps[:half]
    assert abs(moved[:, 0].std() - motion[0]) < 0.03 * motion[0]
    cov = motion_noise(6.0, 0.04, 0.2)
    assert abs(np.var(moved[:, 1]) - cov[1, 1]) < 0.05 * cov[1, 1]
    assert abs(np.cov(moved[:, 0], moved[:, 1])[0, 1] - cov[0, 1]) < 0.1 * cov[0, 1]
    entered = pz[half:] != 0
    assert abs(entered.mean() - 0.2) < 4 * np.sqrt(0.16 / half)
    born = ps[half:][entered]
    assert born[:, 0].min() >= LAW[0] and born[:, 0].max() <= LAW[1]
    assert abs(born[:, 0].mean() - (LAW[0] + LAW[1]) / 2) < 4 * (LAW[1] - LAW[0]) / np.sqrt(12 * len(born))
    assert stats.chisquare(np.bincount(pz[half:][entered], minlength=5)[1:]).pvalue > 1e-3


def test_coupled_exit_is_the_drawn_centroid_leaving(rng):
    shape = (12, 16)
    pools = make_pools(shape, random_templates(rng, k=2, h=5, w=5), groups=1, n=5000)
    state = np.zeros((5000, 4), np.float32)
    state[:, 0], state[:, 2] = 17.45, 5.0
    for k in pools:
        k.set_particles(state, np.ones(5000, np.int32))
        k.configure(MOTION, LAW)
        k.propagate(3, 1, 0, 0, 1, 0, 0.0, 0, 0)
        off = np.floor(k.get("prop")[:, 0] + 0.5) > 17
        np.testing.assert_array_equal(k.get("prop_z") == 0, off)


@pytest.mark.parametrize("engine", [0, 1])
def test_resample_move_keeps_the_posterior_of_a_toy_model(rng, engine):
    """One ancestor, d = 0 and an interior target: ℓ depends on the aspect only (ℓ_i = −ρ_i/2σ_c²), so the
    posterior of z is ∝ G(i, j)·e^(ℓ_i); the resampled and MH-moved aspects must follow it."""
    shape = (30, 30)
    t = np.ones((3, 3, 3)) * np.array([0.3, 0.8, 1.2])[:, None, None]
    n = 30000
    pools = make_pools(shape, t, groups=1, n=n)
    k = pools[engine]
    k.load(np.zeros((1,) + shape, np.float32), np.array([[0.0, 0.0, 4.0]], np.float32))
    state = np.tile(np.array([[15.0, 0.0, 15.0, 0.0]], np.float32), (n, 1))
    k.set_particles(state, np.full(n, 2, np.int32))
    k.configure(MOTION, LAW)
    k.propagate(5, 2, 0, 0, 0, 0, 0.0, 0, 0)
    k.likelihood()
    k.resample(5, 2, 0, 0, 0, 0)
    k.propagate(5, 2, 1, 1, 0, 0, 0.0, 0, 2)  # the MH move, into prev's side 1
    z = k.particles(1)[1]
    ell = -(t.reshape(3, -1) ** 2).sum(axis=1) / (2 * 4.0)
    post = aspect_transition(3)[:, 1] * np.exp(ell)
    post /= post.sum()
    counts = np.bincount(z, minlength=4)[1:]
    # multinomial resampling plus an MH move: counts near n·post (chi-square; the MH step adds correlation, so a
    # lenient level)
    assert stats.chisquare(counts, post * n).pvalue > 1e-4
    assert abs(counts[2] / n - post[2]) < 0.02


@pytest.mark.parametrize("engine", [0, 1])
def test_apf_stage_weights_by_hand(rng, engine):
    """Eq. 23: μ ∝ e^ℓ̂; Eq. 24: w̃_j ∝ e^(ℓ̃_j − ℓ̂_{i(j)}) for a 6-particle pool."""
    shape = (9, 9)
    t = random_templates(rng, k=2, h=3, w=3)
    k = make_pools(shape, t, groups=1, n=6)[engine]
    load((k,), rng, shape, z_low=1)
    state, z = k.particles(0)
    state[:, 0], state[:, 2] = rng.uniform(0, 8, 6), rng.uniform(0, 8, 6)
    k.set_particles(state, z)
    k.configure(MOTION, LAW)
    k.propagate(1, 4, 0, 0, 0, 0, 0.0, 0, 0)
    k.likelihood()
    ll_hat = k.get("prop_ll").astype(float)
    k.resample(1, 4, 0, 0, 0, 0)
    np.testing.assert_allclose(k.get("cdf"), np.cumsum(np.exp(ll_hat - ll_hat.max())), rtol=1e-5)
    aux = k.get("pick")
    np.testing.assert_array_equal(k.get("anc"), aux)
    np.testing.assert_allclose(k.get("cur_ll"), ll_hat[aux], rtol=1e-6)
    # the fresh draw starts from the auxiliary index's n − 1 state: with no motion noise, prop = F·prev[aux]
    prev = k.particles(0)[0]
    k.configure(np.zeros(3, np.float32), LAW)
    k.propagate(1, 4, 2, 1, 0, 0, 0.0, 0, 0)
    np.testing.assert_allclose(k.get("prop")[:, 0], prev[aux, 0] + prev[aux, 1], atol=1e-5)
    k.configure(MOTION, LAW)
    k.propagate(1, 4, 1, 1, 0, 0, 0.0, 0, 0)
    ll_new = k.get("prop_ll").astype(float)
    k.resample(1, 4, 1, 1, 1, 0)
    v = ll_new - ll_hat[aux]
    np.testing.assert_allclose(k.get("cdf"), np.cumsum(np.exp(v - v.max())), rtol=1e-4)
    np.testing.assert_allclose(k.particles(1)[0], k.get("prop")[k.get("pick")])  # the selection: the other side


def test_multinomial_draws_follow_the_weights(rng):
    shape = (8, 8)
    pools = make_pools(shape, random_templates(rng, k=1, h=3, w=3), groups=2, n=8)
    for k in pools:
        k.put("prop_ll", np.log(np.array([1, 0, 3, 0, 0, 4, 0, 2, 0, 0, 0, 0, 0, 0, 0, 1e-3], np.float32) + 1e-30))
    picks = []
    for k in pools:
        hist = np.zeros(16)
        for f in range(2000):
            k.resample(9, f, 0, 0, 0, 0)
            pick = k.get("pick")
            assert np.all(np.diff(pick[:8]) >= 0) and np.all(np.diff(pick[8:]) >= 0)  # merged: in slot order
            hist += np.bincount(pick, minlength=16)
        picks.append(hist)
    np.testing.assert_array_equal(picks[0], picks[1])
    first = picks[0][:8] / picks[0][:8].sum()
    np.testing.assert_allclose(first[[0, 2, 5, 7]], np.array([1, 3, 4, 2]) / 10, atol=0.01)  # 4 sd of 16000 draws
    assert picks[0][8:].sum() == 16000 and picks[0][15] == 16000  # the second group's one live weight


def test_likelihood_map_matches_the_kernels_likelihood(rng):
    """Remark 3's map (host FFT correlation, births.py) equals the kernel's ℓ at every aspect and cell sampled."""
    from tbd_taichi.methods.multiaspect.births import likelihood_map

    shape = (14, 11)
    t = random_templates(rng, k=2, h=5, w=3)
    pools = make_pools(shape, t, groups=1, n=400)
    k = pools[0]
    frames = rng.normal(0, 2, (1,) + shape).astype(np.float32)
    k.load(frames, np.array([[BH, BV, S2]], np.float32))
    lmap = likelihood_map(k.d_image(0).astype(float), t, energy_tables(t, shape), BH, BV, S2)
    assert lmap.shape == (2, 14 + 4, 11 + 2)
    col, row = rng.integers(-1, 12, 400), rng.integers(-2, 16, 400)
    z = rng.integers(1, 3, 400).astype(np.int32)
    state = np.zeros((400, 4), np.float32)
    state[:, 0], state[:, 2] = col + rng.uniform(-0.45, 0.45, 400), row + rng.uniform(-0.45, 0.45, 400)
    k.put("prop", state)
    k.put("prop_z", z)
    k.put("blw", np.zeros(400, np.float32))
    k.likelihood()
    np.testing.assert_allclose(k.get("prop_ll"), lmap[z - 1, row + 2, col + 1], rtol=1e-4, atol=1e-3)


def test_data_births_follow_the_proposal_and_carry_f0_over_q(rng):
    from tbd_taichi.methods.multiaspect.births import proposal

    shape = (10, 12)
    t = random_templates(rng, k=2, h=3, w=5)
    n = 60000
    pools = make_pools(shape, t, groups=1, n=n)
    cells = (10 + 2) * (12 + 4)
    lmap = np.full((2, 12, 16), -50.0)
    lmap[0, 3, 4], lmap[1, 7, 9] = 2.0, 1.0  # two hot cells
    cdf, lq = proposal(lmap, 0.6)
    q = np.diff(np.concatenate([[0.0], cdf]))
    law = np.array([-2.5, 13.5, -1.5, 10.5, 0.0, 0.0, 2.0], np.float32)  # the image prior's f₀ over this grid
    outs = []
    for k in pools:
        k.set_particles(np.zeros((n, 4), np.float32), np.zeros(n, np.int32))
        k.put("birth_cdf", cdf[None])
        k.put("birth_lq", lq[None].astype(np.float32))
        k.configure(MOTION, law)
        k.propagate(2, 5, 0, 0, 0, 1, 1.0, 0, 0)
        outs.append((k.get("prop"), k.get("prop_z"), k.get("blw")))
    (s, z, blw), (s2, z2, blw2) = outs
    np.testing.assert_array_equal(z, z2)
    np.testing.assert_allclose(s, s2, atol=1e-4)
    np.testing.assert_allclose(blw, blw2, atol=1e-5)
    assert (z > 0).all()
    cell = (np.floor(s[:, 2] + 0.5).astype(int) + 1) * 16 + np.floor(s[:, 0] + 0.5).astype(int) + 2
    counts = np.bincount(cell, minlength=cells)
    hot = [3 * 16 + 4, 7 * 16 + 9]
    np.testing.assert_allclose(counts[hot] / n, q[hot], atol=4 * np.sqrt(0.25 / n))
    assert stats.chisquare(counts, q * n).pvalue > 1e-3
    np.testing.assert_allclose(blw, np.log(1.0 / (cells * q[cell])), rtol=1e-5, atol=1e-5)
