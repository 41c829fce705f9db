"""MM-PHD's kernels (kernels/phd.py) against their NumPy twin and against references: erf against scipy, Eq. 4's
closed form against numeric integration, the windowed log-likelihood ratio against the full-image one (Eqs. 6–7,
13), the motion matrices against kinematics, and the random draws' statistics."""
import math

import numpy as np
import pytest
from scipy import integrate, special, stats

from tbd_taichi.kernels import phd as tk
from tbd_taichi.motion_models import MODELS, model_set, process_noise, transition, turn_block
from tbd_taichi.errors import ParameterError
from tbd_taichi.methods.mm_phd.pool import check_support, model_cdf, padded
from tbd_taichi.numpy_kernels import phd as nk

PI_EQ39 = np.array([[0.8, 0.1, 0.1], [0.3, 0.6, 0.1], [0.3, 0.1, 0.6]])
BETA = np.array([0.8, 0.1, 0.1])


def make_pools(shape, capacity=3000, groups=4, models="cv,c-ct,ac-ct", T=1.0):
    """The Taichi kernels and the twin, with the same model tables."""
    ms = model_set(models, T, math.pi / 10, 0.001, 0.01)
    n = len(ms["F"])
    switch = PI_EQ39 if n == 3 else np.full((n, n), 1.0 / n)
    beta = BETA if n == 3 else np.full(n, 1.0 / n)
    pools = (tk.PhdKernels(capacity, groups, shape), nk.PhdKernels(capacity, groups, shape))
    for k in pools:
        for name in ("F", "F_inv", "L"):
            k.put(name, padded(ms[name]))
        k.put("model_cdf", model_cdf(switch, beta))
    return pools


def random_pool(pools, rng, shape, lengths, masked=(1, 0, 0, 0)):
    """Both pools loaded with the same random particles (some outside the image) in groups of ``lengths``."""
    h, w = shape
    n = int(sum(lengths))
    state = np.zeros((n, 7), np.float32)
    state[:, 0] = rng.uniform(-2.5, w + 1.5, n)
    state[:, 2] = rng.uniform(-2.5, h + 1.5, n)
    state[:, [1, 3]] = rng.normal(0, 1.5, (n, 2))
    state[:, 4] = rng.uniform(3, 15, n)
    model = rng.integers(0, 3, n).astype(np.int32)
    gint = np.zeros((pools[0].max_groups, len(tk.GROUP_INT)), np.int32)
    gint[:len(lengths), tk.START] = np.concatenate([[0], np.cumsum(lengths)[:-1]])
    gint[:len(lengths), tk.LENGTH] = lengths
    gint[:len(lengths), tk.FRAME] = masked[:len(lengths)]
    gflt = np.zeros((pools[0].max_groups, len(tk.GROUP_FLOAT)), np.float32)
    gflt[:, tk.QSCALE] = rng.uniform(1, 50, pools[0].max_groups)
    gflt[:, tk.CX], gflt[:, tk.CY], gflt[:, tk.RADIUS] = tk.NO_CENTRE, tk.NO_CENTRE, 2.0
    z = rng.standard_normal(shape).astype(np.float32) * 1.5
    for k in pools:
        for g in range(len(lengths)):
            sl = slice(gint[g, tk.START], gint[g, tk.START] + lengths[g])
            k.load(int(sl.start), state[sl], model[sl], 1e-3 * (g + 1), g)
        for f in ("state", "model", "weight", "group"):  # load fills the next frame's buffer: both hold them
            k.put(f, k.get(f + "2"))
        k.put("gint", gint)
        k.put("gflt", gflt)
        k.put("raw", z)
    return state, z, gint, gflt


def birth_cells(z, th=0.5):
    """The cells with z ≥ th, and the ``cells`` field's contents: those first, then the other cell indices."""
    cells = np.flatnonzero(z.ravel() >= th).astype(np.int32)
    full = np.arange(z.size, dtype=np.int32)
    full[:cells.size] = cells
    return cells, full


@pytest.mark.parametrize("shape", [(21, 17), (8, 9)])
def test_kernels_match_twin(shape, rng):
    """One whole step on both engines (odd sizes, particles across the borders): the same cells, log ℓ, w̃, n̂,
    estimates and resampled particles, to f32 rounding."""
    pools = make_pools(shape)
    lengths = [900, 500, 401, 7]
    state, z, gint, gflt = random_pool(pools, rng, shape, lengths)
    cells, full = birth_cells(z)
    out = []
    centres = np.zeros((4, tk.EST_WIDTH), np.float32)
    centres[:2, tk.EST_MEAN], centres[:2, tk.EST_MEAN + 2] = [3.2, 16.0], [4.7, 20.4]  # the second at the corner
    for k in pools:
        k.put("cells", full)
        k.put("est", centres)
        k.mask(0, 2, 2, -3.0)
        k.put("birth", np.array([0.99, 4, 5, 15, 1e-4, 4.0], np.float32))
        k.propagate(7, 3, sum(lengths), 0, cells.size, 700, 200)
        k.likelihood(0, lengths[0], 2, 0.7, 1)
        k.likelihood(lengths[0], sum(lengths[1:]), 2, 0.7, 0)
        k.update(0, 1, 0.2, 1, 0.84, 0.01, 0.0)
        k.update(1, 3, 0.2, 0, -1e30, 0.01, 0.0)
        np.testing.assert_array_equal(k.get("est"), centres)  # radius 0: no class estimates
        k.update(0, 1, 0.2, 1, 0.84, 0.01, 2.1)  # the same updates, with the class estimates in their launch
        k.update(1, 3, 0.2, 0, -1e30, 0.01, 2.1)
        g2 = gint.copy()
        g2[:4, tk.OUT_LEN] = [600, 300, 0, 5]
        g2[:4, tk.OUT_START] = [0, 650, 950, 950]
        g2[:4, tk.OUT_ID] = [0, 1, 2, 2]
        k.put("gint", g2)
        k.resample(7, 3, 4, 600)
        snap = {f: k.get(f) for f in ("cell", "loglik", "wtilde", "cellmass", "gout", "est", "masked", "model")}
        snap.update({f + "_after": k.get(f + "2")[:955] for f in ("state", "model", "weight", "group")})
        out.append(snap)
    a, b = out
    n = sum(lengths)
    np.testing.assert_array_equal(a["cell"][:n], b["cell"][:n])
    np.testing.assert_array_equal(a["model"][:n], b["model"][:n])
    np.testing.assert_array_equal(a["masked"], b["masked"])
    np.testing.assert_allclose(a["loglik"][:n], b["loglik"][:n], rtol=1e-4, atol=2e-4)
    np.testing.assert_allclose(a["wtilde"][:n], b["wtilde"][:n], rtol=2e-3, atol=1e-9)
    np.testing.assert_allclose(a["cellmass"][:n], b["cellmass"][:n], rtol=2e-3, atol=1e-7)
    np.testing.assert_allclose(a["gout"], b["gout"], rtol=2e-3)
    np.testing.assert_allclose(a["est"], b["est"], rtol=5e-3, atol=5e-4)
    for f in ("model_after", "group_after"):
        np.testing.assert_array_equal(a[f][:950], b[f][:950])
    np.testing.assert_allclose(a["state_after"][:950], b["state_after"][:950], rtol=1e-4, atol=1e-4)
    np.testing.assert_allclose(a["weight_after"][:950], b["weight_after"][:950], rtol=1e-6)
    # group 2 ended: nothing of it is left; its successor got the new id 2
    assert set(a["group_after"][950:955]) == {2}


@pytest.mark.parametrize("lam", [1e-14, 1e-30])
def test_update_matches_twin_beside_very_bright_pixels(lam, rng):
    """Pixels of 40σ and 80σ and a small λ (Th 7.7 and the floor): the scale's shift is capped at log λ + 80 and
    log ℓ − s at 70 for the brightest particles; both engines give the same finite w̃, cell masses and n̂."""
    shape = (15, 19)
    pools = make_pools(shape)
    lengths = [700, 300]
    _, z, _, _ = random_pool(pools, rng, shape, lengths, masked=(0, 0))
    z[5, 5] += 80.0
    z[9, 12] += 40.0
    cells, full = birth_cells(z)
    out = []
    for k in pools:
        k.put("raw", z)
        k.put("cells", full)
        k.likelihood(0, sum(lengths), 2, 0.7, 0)
        k.update(0, 2, lam, 1, 0.5, 0.01, 0.0)
        out.append({f: k.get(f)[:sum(lengths)] for f in ("loglik", "wtilde", "cellmass", "cdf")} | {"gout": k.get("gout")})
    a, b = out
    assert a["loglik"].max() > np.log(lam) + 80 + 70  # the cap is reached
    for f in ("wtilde", "cellmass", "cdf", "gout"):
        assert np.all(np.isfinite(a[f])) and np.all(np.isfinite(b[f])), f
    np.testing.assert_allclose(a["wtilde"], b["wtilde"], rtol=2e-3, atol=1e-9)
    np.testing.assert_allclose(a["cellmass"], b["cellmass"], rtol=2e-3, atol=1e-7)
    np.testing.assert_allclose(a["gout"], b["gout"], rtol=2e-3)


def test_erf_against_scipy():
    """The interpolated table on both engines within 1.2·10⁻⁷ (+ f32 rounding) of scipy over [−6, 6], and the two
    engines bit-equal."""
    x = np.linspace(-6, 6, 4001).astype(np.float32)
    ref = special.erf(x.astype(np.float64))
    assert np.max(np.abs(nk.erf(x) - ref)) < 3e-7
    import taichi as ti

    out = ti.ndarray(ti.f32, x.size)

    @ti.kernel
    def fill(src: ti.types.ndarray(dtype=ti.f32, ndim=1), dst: ti.types.ndarray(dtype=ti.f32, ndim=1)):
        for i in range(src.shape[0]):
            dst[i] = tk.erf(src[i], table.values)

    table = tk.ErfTable.shared()
    fill(x, out)
    assert np.max(np.abs(out.to_numpy() - ref)) < 3e-7
    np.testing.assert_array_equal(out.to_numpy(), nk.erf(x))
    odd = np.array([np.inf, -np.inf, np.nan, 1e30, -1e30], np.float32)  # ±1 at the table's end; NaN reads it too
    out = ti.ndarray(ti.f32, odd.size)
    fill(odd, out)
    np.testing.assert_array_equal(out.to_numpy(), nk.erf(odd))
    np.testing.assert_array_equal(nk.erf(odd)[[0, 1, 3, 4]], [1, -1, 1, -1])


@pytest.mark.parametrize("pos,sigma", [(3.3, 0.7), (0.05, 0.6), (-0.4, 1.2)])
def test_pixel_integral_against_quadrature(pos, sigma):
    """Eq. 4's closed form (per axis ½[erf − erf]) equals the numeric integral of the Gaussian over the pixel."""
    for centre in (0.0, 3.0, 4.0, -1.0):
        ref, _ = integrate.quad(lambda u: stats.norm.pdf(u, pos, sigma), centre - 0.5, centre + 0.5)
        got = float(nk.pixel_fraction(np.float32(centre), np.float32(pos), np.float32(1 / (math.sqrt(2) * sigma))))
        assert got == pytest.approx(ref, abs=1e-6)
    # the 2-D integral of Eq. 4 is the product of the two axes
    x, y, centre = pos, 1.7, (3.0, 2.0)
    ref2, _ = integrate.dblquad(lambda v, u: stats.norm.pdf(u, x, sigma) * stats.norm.pdf(v, y, sigma),
                                centre[0] - 0.5, centre[0] + 0.5, centre[1] - 0.5, centre[1] + 0.5)
    s = np.float32(1 / (math.sqrt(2) * sigma))
    prod = float(nk.pixel_fraction(np.float32(centre[0]), np.float32(x), s) *
                 nk.pixel_fraction(np.float32(centre[1]), np.float32(y), s))
    assert prod == pytest.approx(ref2, abs=1e-6)


def test_window_ratio_against_full_image(rng):
    """Eq. 13 over Eq. 18's window equals the full-image log ratio of Eqs. 6–7 up to the PSF mass outside the
    window (for Σ = 0.7 and a ±2 px window, |difference| < 1 % of ½Σh²)."""
    shape = (19, 23)
    pools = make_pools(shape, capacity=64, groups=1)
    z = rng.standard_normal(shape).astype(np.float32)
    state = np.zeros((20, 7), np.float32)
    state[:, 0] = rng.uniform(3, 19, 20)
    state[:, 2] = rng.uniform(3, 15, 20)
    state[:, 4] = 10.0
    cols, rows = np.arange(shape[1]), np.arange(shape[0])
    for k in pools:
        k.put("raw", z)
        k.put("state", np.concatenate([state, np.zeros((44, 7), np.float32)]))
        k.put("gint", np.zeros((1, len(tk.GROUP_INT)), np.int32))
        k.likelihood(0, 20, 2, 0.7, 0)
        got = k.get("loglik")[:20]
        for p in range(20):
            x, y, inten = state[p, 0], state[p, 2], state[p, 4]
            fx = stats.norm.cdf(cols + 0.5, x, 0.7) - stats.norm.cdf(cols - 0.5, x, 0.7)
            fy = stats.norm.cdf(rows + 0.5, y, 0.7) - stats.norm.cdf(rows - 0.5, y, 0.7)
            h = inten * np.outer(fy, fx)
            full = float(np.sum(h * (z - h / 2)))  # log of Π p_s+n/p_n over every pixel, σ_n = 1
            assert got[p] == pytest.approx(full, abs=0.01 * float(np.sum(h * h) / 2) + 0.05)


def test_motion_matrices_follow_kinematics():
    """CV moves by v·T; CT turns the velocity by ωT (AC-CT toward +y) along the arc of radius |v|/ω; CA adds
    a·T²/2; F⁻¹ undoes F; Q's blocks are Li & Jilkov's."""
    T, w = 2.0, math.pi / 10
    x = np.array([5.0, 1.0, 6.0, 0.5, 9.0, 0.1, -0.2])
    cv = transition("cv", T, w) @ x
    assert cv[[0, 2]] == pytest.approx([7.0, 7.0]) and cv[[1, 3]] == pytest.approx([1.0, 0.5])
    ac = transition("ac-ct", T, w) @ x
    ang = math.atan2(ac[3], ac[1]) - math.atan2(0.5, 1.0)
    assert ang == pytest.approx(w * T) and math.hypot(ac[1], ac[3]) == pytest.approx(math.hypot(1.0, 0.5))
    # position from integrating the rotating velocity
    ts = np.linspace(0, T, 2001)
    vx = 1.0 * np.cos(w * ts) - 0.5 * np.sin(w * ts)
    vy = 1.0 * np.sin(w * ts) + 0.5 * np.cos(w * ts)
    assert ac[0] == pytest.approx(5.0 + integrate.trapezoid(vx, ts), abs=1e-5)
    assert ac[2] == pytest.approx(6.0 + integrate.trapezoid(vy, ts), abs=1e-5)
    c = transition("c-ct", T, w) @ x
    assert math.atan2(c[3], c[1]) - math.atan2(0.5, 1.0) == pytest.approx(-w * T)
    ca = transition("ca", T, w) @ x
    assert ca[0] == pytest.approx(5 + 1 * T + 0.1 * T * T / 2) and ca[3] == pytest.approx(0.5 - 0.2 * T)
    for m in MODELS:
        F = transition(m, T, w)
        assert np.allclose(np.linalg.inv(F) @ F, np.eye(7))
    q = process_noise("cv", T, 0.001, 0.01)
    assert q[0, 0] == pytest.approx(0.001 * T ** 3 / 3) and q[0, 1] == pytest.approx(0.001 * T ** 2 / 2)
    assert q[4, 4] == pytest.approx(0.01 * T)
    q = process_noise("ca", T, 0.001, 0.01)
    assert q[0, 0] == pytest.approx(0.001 * T ** 5 / 20) and q[5, 5] == pytest.approx(0.001 * T)
    assert turn_block(w, T).shape == (4, 4)



@pytest.mark.parametrize("T, omega", [(1.0, math.pi / 10), (2.0, -0.3), (0.37, 2.9)])
def test_propagation_support_holds_every_model(T, omega):
    """The propagate kernel multiplies only F_SUPPORT's entries of F and F⁻¹ and L_SUPPORT's of L: every other
    entry of every model's matrices is exactly zero, whatever T, ω and the noise densities (check_support passes),
    no entry is kept in vain, and a matrix with an entry outside is refused."""
    ms = model_set(",".join(MODELS), T, omega, 0.37, 0.05)
    check_support(ms)
    for name, support in (("F", tk.F_SUPPORT), ("F_inv", tk.F_SUPPORT), ("L", tk.L_SUPPORT)):
        kept = np.abs(ms[name]).max(axis=0)[tuple(np.array(support).T)]
        assert np.all(kept > 0), name
        bad = {k: v.copy() for k, v in ms.items()}
        bad[name][0, 4, 0] = 0.5  # intensity from x: outside every support
        with pytest.raises(ParameterError, match=name):
            check_support(bad)

def moved(engine_pool, n, model, qscale=1.0, frame_key=5):
    """n particles at a fixed state, all of ``model``, propagated once with Π = identity."""
    k = engine_pool
    start = np.tile(np.array([10.0, 1.0, 12.0, -0.5, 9.0, 0.0, 0.0], np.float32), (n, 1))
    k.put("model_cdf", model_cdf(np.eye(3), BETA))
    k.load(0, start, np.full(n, model, np.int32), 1.0, 0)
    gint = np.zeros((k.max_groups, len(tk.GROUP_INT)), np.int32)
    gint[0, tk.LENGTH] = n
    gflt = np.zeros((k.max_groups, len(tk.GROUP_FLOAT)), np.float32)
    gflt[0, tk.QSCALE] = qscale
    k.put("gint", gint)
    k.put("gflt", gflt)
    k.put("birth", np.array([0.99, 4, 5, 15, 0.0, 0.0], np.float32))
    k.propagate(3, frame_key, n, 0, 1, 0, 0)
    return k.get("state")[:n].astype(float), k.get("weight")[:n]


@pytest.mark.parametrize("engine", [0, 1])
def test_propagation_moments(engine):
    """20 000 particles of one state: mean F·x and covariance s·Q within sampling error (4 standard errors of
    the mean, 5 of the covariance); weights times e."""
    n = 20_000
    k = make_pools((30, 30), capacity=n, groups=2, T=2.0)[engine]
    ms = model_set("cv,c-ct,ac-ct", 2.0, math.pi / 10, 0.001, 0.01)
    x0 = np.array([10.0, 1.0, 12.0, -0.5, 9.0, 0.0, 0.0])
    for r in range(3):
        st, w = moved(k, n, r, qscale=7.0)
        Q = 7.0 * ms["L"][r] @ ms["L"][r].T
        mean = ms["F"][r] @ x0
        sd = np.sqrt(np.maximum(np.diag(Q), 1e-30))
        assert np.all(np.abs(st.mean(axis=0) - mean) <= 4 * sd / math.sqrt(n) + 1e-5)
        live = np.diag(Q) > 0
        scale = np.sqrt(np.outer(np.diag(Q), np.diag(Q)))[np.ix_(live, live)]
        # a sample covariance's standard error is ≤ √(2·Q_ii·Q_jj/n): allow 5 of them
        assert np.all(np.abs(np.cov(st.T)[np.ix_(live, live)] - Q[np.ix_(live, live)]) <= 5 * scale * math.sqrt(2 / n))
        assert np.allclose(w, 0.99)


@pytest.mark.parametrize("engine", [0, 1])
def test_model_switches_follow_pi(engine):
    """From each model, the next model's frequencies over 30 000 particles match Π's row (χ² test, p > 0.001)."""
    n = 30_000
    k = make_pools((10, 10), capacity=n, groups=2)[engine]
    for r in range(3):
        k.put("model_cdf", model_cdf(PI_EQ39, BETA))
        k.load(0, np.zeros((n, 7), np.float32), np.full(n, r, np.int32), 1.0, 0)
        gint = np.zeros((k.max_groups, len(tk.GROUP_INT)), np.int32)
        gint[0, tk.LENGTH] = n
        k.put("gint", gint)
        k.put("birth", np.array([1, 4, 5, 15, 0, 0], np.float32))
        k.propagate(11, 2 + r, n, 0, 1, 0, 0)
        counts = np.bincount(k.get("model")[:n], minlength=3)[:3]
        assert stats.chisquare(counts, PI_EQ39[r] * n).pvalue > 1e-3


@pytest.mark.parametrize("engine", [0, 1])
def test_births_uniform_over_thresholded_cells(engine, rng):
    """Births land only in the listed cells, uniformly over them (χ² over the cells), with velocity in
    [−V_max, V_max], intensity in [I_min, I_max], model by β and weight γ/J."""
    shape, n = (12, 15), 40_000
    k = make_pools(shape, capacity=n, groups=2)[engine]
    cells = np.sort(rng.choice(shape[0] * shape[1], 37, replace=False)).astype(np.int32)
    full = np.arange(shape[0] * shape[1], dtype=np.int32)
    full[:cells.size] = cells
    k.put("cells", full)
    gint = np.zeros((k.max_groups, len(tk.GROUP_INT)), np.int32)
    gint[0, tk.LENGTH] = n
    k.put("gint", gint)
    k.put("birth", np.array([0.99, 3.0, 6.0, 12.0, 0.05 / n, 0.0], np.float32))
    k.propagate(5, 9, n, 0, cells.size, 0, n)
    st = k.get("state")[:n]
    pix = np.floor(st[:, 2] + 0.5).astype(int) * shape[1] + np.floor(st[:, 0] + 0.5).astype(int)
    assert set(np.unique(pix)) <= set(cells.tolist())
    counts = np.array([(pix == c).sum() for c in cells])
    assert stats.chisquare(counts).pvalue > 1e-3
    assert np.all(np.abs(st[:, [1, 3]]) <= 3.0) and np.all((st[:, 4] >= 6) & (st[:, 4] <= 12))
    assert stats.chisquare(np.bincount(k.get("model")[:n], minlength=3)[:3], BETA * n).pvalue > 1e-3
    assert np.allclose(k.get("weight")[:n], 0.05 / n)
    assert np.all(k.get("group")[:n] == 0)


def test_put_fills_the_per_pixel_fields_from_the_start_and_checks_the_others():
    """A frame goes row after row into the start of ``raw`` (zeros past it) on both engines; any other field takes
    only an array of its own shape."""
    shape = (5, 7)
    z = np.arange(35, dtype=np.float32).reshape(shape) + 1
    for k in make_pools(shape, capacity=16, groups=2):
        k.put("raw", z)
        raw = np.asarray(k.get("raw"))
        np.testing.assert_array_equal(raw[:35], z.ravel())
        assert not raw[35:].any()
        with pytest.raises(ValueError):
            k.put("gint", np.zeros((1, 1), np.int32))
