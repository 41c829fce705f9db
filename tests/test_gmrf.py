"""The GMRF clutter model of Bruno et al. 2008 (Eqs. 9, 13, 14; notes §2.6, A3–A5, B1), checked against dense
linear algebra: the eigenvalues, ln det A, the exact sampler, vᵀAv = S0 − 2β_h S_h − 2β_v S_v, and the
maximum-likelihood estimator (it recovers the parameters of exact draws and is the maximiser of ℓ)."""
import math

import numpy as np
import pytest
from scipy import optimize

from tbd_taichi import gmrf
from tbd_taichi.errors import ParameterError

# Spread of the estimates on one 120×120 draw, measured over 400 (β = (0.22, 0.24), σ_c = 3) and 300
# (β = (−0.2, 0.25), σ_c = 1) exact draws: sd(β̂_h) ≈ sd(β̂_v) ≈ 0.0057, sd(σ̂_c)/σ_c ≈ 0.0062, for both the exact and
# the approximate ML (whose bias is ≈ 0.001). The tolerances below are about 4 sd.
BETA_TOL, SIGMA_REL_TOL = 0.025, 0.025


def dense_a(shape, beta_h, beta_v):
    """Eq. 14 built densely: A = I_L ⊗ (I_M − β_h B_M) + B_L ⊗ (−β_v I_M), B_J ones on the first off-diagonals."""
    rows, cols = shape

    def b(j):
        return np.eye(j, k=1) + np.eye(j, k=-1)
    return np.kron(np.eye(rows), np.eye(cols) - beta_h * b(cols)) + np.kron(b(rows), -beta_v * np.eye(cols))


def profile_loglik(v, beta_h, beta_v, log_det_a=None):
    """ℓ(β) = −(LM/2) ln σ̂_c²(β) + ½ ln det A(β), σ̂_c² = vᵀAv/(LM), with ln det A = Σ ln λ_kl summed directly."""
    v = np.asarray(v, np.float64)
    n = v.size
    quad = (v * v).sum() - 2 * beta_h * (v[:, :-1] * v[:, 1:]).sum() - 2 * beta_v * (v[:-1] * v[1:]).sum()
    if log_det_a is None:
        log_det_a = np.log(gmrf.eigenvalues(v.shape, beta_h, beta_v)).sum()
    return -0.5 * n * math.log(quad / n) + 0.5 * log_det_a


@pytest.mark.parametrize("shape", [(5, 7), (6, 4), (1, 5), (4, 1), (3, 20)])
@pytest.mark.parametrize("beta", [(0.22, 0.24), (-0.3, 0.1), (0.0, -0.45), (0.49, 0.0)])
def test_eigenvalues_match_dense_matrix(shape, beta):
    lam = np.sort(gmrf.eigenvalues(shape, *beta).ravel())
    np.testing.assert_allclose(lam, np.linalg.eigvalsh(dense_a(shape, *beta)), rtol=0, atol=1e-12)


def near_boundary(shape, share, lam_min, sign=1.0):
    """(β_h, β_v) with λ_min = lam_min, a fraction ``share`` of 1 − λ_min carried by β_h."""
    c_v, c_h = (math.cos(math.pi / (n + 1)) for n in shape)
    return sign * share * (1 - lam_min) / (2 * c_h), (1 - share) * (1 - lam_min) / (2 * c_v)


@pytest.mark.parametrize("shape", [(5, 7), (6, 4), (3, 20), (20, 18), (9, 40)])
def test_log_det_matches_slogdet(shape):
    # M > 16 (20×18, 9×40) takes the closed-form route; the rest sum the eigenvalues directly.
    betas = [(0.0, 0.0), (0.22, 0.24), (-0.2, 0.25), (0.1, -0.05), (0.3, 0.01),
             near_boundary(shape, 0.5, 1e-3), near_boundary(shape, 0.9, 1e-4, -1.0)]
    for beta in betas:
        sign, ref = np.linalg.slogdet(dense_a(shape, *beta))
        assert sign == 1.0
        assert gmrf.log_det(shape, *beta) == pytest.approx(ref, rel=1e-10, abs=1e-10), beta


def eigen_derivatives(shape, beta_h, beta_v):
    """ln det A, its gradient and Hessian in (β_h, β_v) by direct sums over the L·M eigenvalues."""
    c_v, c_h = (np.cos(np.arange(1, n + 1) * np.pi / (n + 1)) for n in shape)
    lam = gmrf.eigenvalues(shape, beta_h, beta_v)
    r, r2 = 1 / lam, 1 / lam ** 2
    hv = -4 * c_v @ r2 @ c_h
    return (np.log(lam).sum(), np.array([-2 * (r @ c_h).sum(), -2 * (c_v @ r).sum()]),
            np.array([[-4 * (r2 @ c_h ** 2).sum(), hv], [hv, -4 * (c_v ** 2 @ r2).sum()]]))


@pytest.mark.parametrize("shape", [(120, 120), (1024, 1000), (7, 300), (300, 7), (40, 17)])
def test_closed_form_log_det_and_derivatives_match_eigenvalue_sums(shape):
    """The O(L) closed form (moment series, Chebyshev U_M for cosh and cos branches, direct rows near x = 1) against
    the O(L·M) sums. Rounding in λ is ~1e-16, so 1/λ² carries ~1e-16/λ_min relative error: λ_min ≥ 1e-4 here."""
    rng = np.random.default_rng(3)
    c_v = np.cos(np.arange(1, shape[0] + 1) * np.pi / (shape[0] + 1))
    betas = [(0.0, 0.0), (1e-9, 0.2), (0.22, 0.24), (-0.2, 0.25), (0.25, -1e-6)]
    betas += [near_boundary(shape, s, lm, sg) for s in (0.05, 0.5, 0.95) for lm in (1e-2, 1e-4) for sg in (1, -1)]
    for k in (0, shape[0] // 3, shape[0] - 1):  # a row with x = a_k/2β_h at, just above and just below 1
        betas += [(0.2, 0.6 / (2 * c_v[k]) * (1 + e)) for e in (0.0, 1e-9, -1e-9, 1e-6, -1e-6, 1e-3)]
    betas += [tuple(b) for b in rng.uniform(-0.5, 0.5, (30, 2))]
    checked = 0
    for beta in betas:
        if gmrf._lambda_min(shape, *beta) < 1e-4:
            continue
        checked += 1
        ld, grad, hess = gmrf._log_det_derivs(shape, *beta, False)
        ref = eigen_derivatives(shape, *beta)
        assert ld == pytest.approx(ref[0], rel=1e-12, abs=1e-9), beta
        scale = np.abs(ref[1]).max() + 1.0
        np.testing.assert_allclose(grad, ref[1], rtol=0, atol=1e-9 * scale, err_msg=str(beta))
        np.testing.assert_allclose(hess, ref[2], rtol=0, atol=1e-9 * np.abs(ref[2]).max(), err_msg=str(beta))
        assert gmrf.log_det(shape, *beta) == ld
    assert checked >= 30


def test_log_det_rejects_parameters_outside_its_domain():
    with pytest.raises(ParameterError, match="positive definite"):
        gmrf.log_det((5, 5), 0.3, 0.3)
    assert gmrf.positive_definite((5, 5), 0.26, 0.245)  # PD on a small grid although |β_h| + |β_v| > ½ ...
    assert gmrf.log_det((5, 5), 0.26, 0.245) < 0
    with pytest.raises(ParameterError, match="0.5"):  # ... where the large-grid integral is not defined
        gmrf.log_det((5, 5), 0.26, 0.245, approximate=True)


@pytest.mark.parametrize("beta", [(0.22, 0.24), (-0.1, 0.3), (0.0, 0.0), (0.3, -0.15), (0.249, 0.249)])
def test_approximate_log_det_is_the_large_grid_integral(beta):
    """Reference: a 1024² midpoint rule on [0, π]² for the periodic analytic integrand (exponentially accurate);
    the derivatives the estimator uses against central differences (step 1e-6: error ~1e-12/1e-6 relative)."""
    w = (np.arange(1024) + 0.5) * np.pi / 1024
    integral = np.log(1 - 2 * beta[0] * np.cos(w)[None, :] - 2 * beta[1] * np.cos(w)[:, None]).mean()
    shape = (100, 80)
    assert gmrf.log_det(shape, *beta, approximate=True) == pytest.approx(8000 * integral, rel=1e-9, abs=1e-9)
    _, grad, hess = gmrf._log_det_derivs(shape, *beta, True)
    e = 1e-6
    for i in range(2):
        step = np.eye(2)[i] * e
        up, down = (gmrf._log_det_derivs(shape, *(np.array(beta) + s * step), True) for s in (1, -1))
        assert grad[i] == pytest.approx((up[0] - down[0]) / (2 * e), rel=1e-5, abs=1e-4)
        np.testing.assert_allclose(hess[i], (up[1] - down[1]) / (2 * e), rtol=1e-5, atol=1e-3)


def test_approximate_log_det_differs_from_exact_by_a_boundary_term():
    """ln det A − L·M·∫∫ is O(L + M) (the zero boundary of Eq. 14): its relative size shrinks like (L+M)/LM and
    the per-side constant settles (256² vs 512²: −0.1148 vs −0.1149 at β = (0.22, 0.24))."""
    beta = (0.22, 0.24)
    per_side = []
    for n in (256, 512):
        exact, approx = gmrf.log_det((n, n), *beta), gmrf.log_det((n, n), *beta, approximate=True)
        assert exact == pytest.approx(np.log(gmrf.eigenvalues((n, n), *beta)).sum(), rel=1e-12)
        assert abs(approx - exact) / abs(exact) < 2.0 / n  # 0.6 % at 256², 0.3 % at 512²
        per_side.append((approx - exact) / (2 * n))
    assert per_side[1] == pytest.approx(per_side[0], rel=0.01)


def test_sample_covariance_is_sigma_c2_inverse_a():
    """20000 draws on 3×4: each sample covariance entry has sd √((Σ_ij² + Σ_ii Σ_jj)/n); allow 5 sd (78 entries)."""
    shape, beta, sigma_c, n = (3, 4), (0.2, 0.25), 1.5, 20000
    draws = gmrf.sample_gmrf(np.random.default_rng(11), shape, *beta, sigma_c, n).reshape(n, -1)
    cov = sigma_c ** 2 * np.linalg.inv(dense_a(shape, *beta))
    emp = draws.T @ draws / n  # the mean is known to be 0
    sd = np.sqrt((cov ** 2 + np.outer(np.diag(cov), np.diag(cov))) / n)
    assert np.all(np.abs(emp - cov) < 5 * sd), np.abs(emp - cov) / sd
    assert np.abs(draws.mean(axis=0)).max() < 5 * np.sqrt(np.diag(cov).max() / n)


def test_quadratic_form_equals_lag_sums():
    rng = np.random.default_rng(5)
    for shape in [(5, 7), (4, 3), (1, 6)]:
        v = rng.standard_normal(shape)
        s0, s_h, s_v = gmrf.lag_sums(v)
        assert s0 == pytest.approx((v * v).sum(), rel=1e-13)
        assert s_h == pytest.approx((v[:, :-1] * v[:, 1:]).sum(), rel=1e-12, abs=1e-13)
        assert s_v == pytest.approx((v[:-1] * v[1:]).sum(), rel=1e-12, abs=1e-13)
        for beta_h, beta_v in rng.uniform(-0.3, 0.3, (5, 2)):
            x = v.ravel()
            quad = x @ dense_a(shape, beta_h, beta_v) @ x
            assert quad == pytest.approx(s0 - 2 * beta_h * s_h - 2 * beta_v * s_v, rel=1e-12)
    with pytest.raises(ParameterError, match="2-D"):
        gmrf.lag_sums(np.zeros(5))


@pytest.mark.parametrize("truth", [(0.22, 0.24, 3.0), (-0.2, 0.25, 1.0)])
@pytest.mark.parametrize("approximate", [False, True])
def test_estimate_recovers_parameters_of_exact_draws(truth, approximate):
    v = gmrf.sample_gmrf(np.random.default_rng(2024), (120, 120), *truth, 1)[0]
    est = gmrf.estimate_gmrf(v, approximate=approximate)
    assert isinstance(est, gmrf.GmrfParams)
    assert abs(est.beta_h - truth[0]) < BETA_TOL and abs(est.beta_v - truth[1]) < BETA_TOL
    assert est.sigma_c == pytest.approx(truth[2], rel=SIGMA_REL_TOL)
    assert isinstance(est.sigma_c2, float) and est.sigma_c == math.sqrt(est.sigma_c2)


@pytest.mark.parametrize("approximate", [False, True])
def test_estimate_is_the_maximiser_of_the_likelihood(approximate):
    """ℓ at the estimate ≥ ℓ at the truth and at points 1e-5 away (the curvature ~LM/sd² makes those ~1e-6 lower,
    far above rounding in ℓ ~ 1e-11); σ̂_c² is the closed-form vᵀAv/(LM) at β̂."""
    truth = (0.22, 0.24, 3.0)
    v = gmrf.sample_gmrf(np.random.default_rng(99), (120, 120), *truth, 1)[0]
    est = gmrf.estimate_gmrf(v, approximate=approximate)

    def loglik(bh, bv):
        ld = gmrf.log_det(v.shape, bh, bv, approximate=True) if approximate else None
        return profile_loglik(v, bh, bv, ld)

    best = loglik(est.beta_h, est.beta_v)
    assert best > loglik(*truth[:2])
    for d in (1e-5, 1e-3):
        for step in ((d, 0), (-d, 0), (0, d), (0, -d), (d, -d)):
            assert best > loglik(est.beta_h + step[0], est.beta_v + step[1]), step
    s0, s_h, s_v = gmrf.lag_sums(v)
    assert est.sigma_c2 == pytest.approx((s0 - 2 * est.beta_h * s_h - 2 * est.beta_v * s_v) / v.size, rel=1e-12)


def test_estimate_matches_dense_maximum_likelihood_on_a_small_grid():
    """Eq. 13 maximised by Nelder–Mead with det A from numpy.linalg.slogdet of the dense matrix (9×11 frame)."""
    v = gmrf.sample_gmrf(np.random.default_rng(8), (9, 11), 0.2, 0.2, 1.0, 1)[0]
    x = v.ravel()

    def neg(beta):
        a = dense_a(v.shape, *beta)
        sign, ld = np.linalg.slogdet(a)
        if sign <= 0 or np.linalg.eigvalsh(a)[0] < 1e-9:
            return np.inf
        return 0.5 * x.size * math.log(x @ a @ x / x.size) - 0.5 * ld

    ref = optimize.minimize(neg, [0.0, 0.0], method="Nelder-Mead", options={"xatol": 1e-9, "fatol": 1e-12})
    est = gmrf.estimate_gmrf(v)
    np.testing.assert_allclose([est.beta_h, est.beta_v], ref.x, atol=1e-5)


@pytest.mark.parametrize("approximate", [False, True])
@pytest.mark.parametrize("name", ["sinusoid", "ramp", "checkerboard", "constant"])
def test_estimate_handles_maximisers_at_the_edge(name, approximate):
    """Smooth or alternating frames put the approximate ML on |β_h| + |β_v| = ½ (the integral stays finite there):
    the estimate must slide along that edge to the constrained maximum, found here by Nelder–Mead from three starts
    on ℓ built from the public log_det and lag_sums (−∞ outside the region the estimator searches)."""
    r, c = np.arange(24.0)[:, None], np.arange(30.0)[None, :]
    v = {"sinusoid": np.sin(r / 3 + c / 5), "ramp": r + c, "checkerboard": (-1.0) ** (r + c),
         "constant": np.full((24, 30), 3.0)}[name]
    s0, s_h, s_v = gmrf.lag_sums(v)

    def neg(beta):
        inside = (1 - 2 * abs(beta[0]) - 2 * abs(beta[1]) if approximate
                  else gmrf._lambda_min(v.shape, *beta)) >= gmrf.MARGIN
        if not inside:
            return np.inf
        ld = gmrf.log_det(v.shape, *beta, approximate=approximate)
        return 0.5 * v.size * math.log((s0 - 2 * beta[0] * s_h - 2 * beta[1] * s_v) / v.size) - 0.5 * ld

    ref = min((optimize.minimize(neg, x0, method="Nelder-Mead", options={"xatol": 1e-11, "fatol": 1e-13,
                                                                           "maxiter": 4000})
               for x0 in ([0, 0], [0.2, 0.2], [-0.2, -0.2])), key=lambda res: res.fun)
    est = gmrf.estimate_gmrf(v, approximate=approximate)
    assert neg([est.beta_h, est.beta_v]) <= ref.fun + 1e-9 * abs(ref.fun)
    np.testing.assert_allclose([est.beta_h, est.beta_v], ref.x, atol=1e-5)


def test_warm_start_gives_the_same_estimate():
    v = gmrf.sample_gmrf(np.random.default_rng(4), (120, 120), 0.22, 0.24, 3.0, 1)[0]
    for approximate in (False, True):
        cold = gmrf.estimate_gmrf(v, approximate=approximate)
        for start in (gmrf.GmrfParams(0.22, 0.24, 9.0), cold, gmrf.GmrfParams(-0.2, 0.1, 1.0),
                      gmrf.GmrfParams(0.5, 0.5, 1.0), gmrf.GmrfParams(float("nan"), 0.0, 1.0)):  # last two: invalid
            warm = gmrf.estimate_gmrf(v, approximate=approximate, start=start)
            assert warm.beta_h == pytest.approx(cold.beta_h, abs=1e-7)
            assert warm.beta_v == pytest.approx(cold.beta_v, abs=1e-7)
            assert warm.sigma_c2 == pytest.approx(cold.sigma_c2, rel=1e-9)


def test_estimate_needs_few_log_det_evaluations(monkeypatch):
    """It runs every frame: one evaluation of ln det A and its derivatives costs O(L), and a 120×120 estimate needs
    ≤ 10 of them from (0, 0) (8 today: Newton converges quadratically; a step stopped on the edge of the region where
    ℓ falls is retried inside) and 1 from its own answer."""
    v = gmrf.sample_gmrf(np.random.default_rng(0), (120, 120), 0.22, 0.24, 3.0, 1)[0]
    calls = []
    real = gmrf._log_det_derivs
    monkeypatch.setattr(gmrf, "_log_det_derivs", lambda *a: calls.append(a) or real(*a))
    for approximate in (False, True):
        calls.clear()
        cold = gmrf.estimate_gmrf(v, approximate=approximate)
        assert len(calls) <= 10
        calls.clear()
        gmrf.estimate_gmrf(v, approximate=approximate, start=cold)
        assert len(calls) <= 2


def test_estimate_of_an_all_zero_frame_is_the_floor():
    for approximate in (False, True):
        est = gmrf.estimate_gmrf(np.zeros((8, 9)), approximate=approximate)
        assert (est.beta_h, est.beta_v, est.sigma_c2) == (0.0, 0.0, gmrf.SIGMA2_FLOOR)
    assert np.float32(gmrf.SIGMA2_FLOOR) > 0


def test_estimate_is_scale_free():
    """β̂ does not depend on the units and σ̂_c² scales with their square, even where Σv² under/overflows."""
    v = gmrf.sample_gmrf(np.random.default_rng(6), (40, 50), 0.2, 0.25, 1.0, 1)[0]
    ref = gmrf.estimate_gmrf(v)
    for c in (1e-150, 1e-3, 1e140):
        est = gmrf.estimate_gmrf(v * c)
        assert est.beta_h == pytest.approx(ref.beta_h, abs=1e-9) and est.beta_v == pytest.approx(ref.beta_v, abs=1e-9)
        assert est.sigma_c2 == pytest.approx(ref.sigma_c2 * c * c, rel=1e-9)
    est32 = gmrf.estimate_gmrf(v.astype(np.float32))
    assert est32.beta_h == pytest.approx(ref.beta_h, abs=1e-5)


@pytest.mark.parametrize("bad", [np.full((5, 5), np.nan), np.pad([[np.inf]], 3), np.zeros(25), np.zeros((2, 9)),
                                 np.zeros((9, 2)), np.zeros((3, 4, 5))])
def test_estimate_rejects_bad_input(bad):
    with pytest.raises(ParameterError, match="v must"):
        gmrf.estimate_gmrf(bad)


def test_positive_definite_boundary():
    shape = (5, 7)
    crit_h, crit_v = (1 / (2 * math.cos(math.pi / (n + 1))) for n in (7, 5))
    for sign in (1, -1):
        assert gmrf.positive_definite(shape, sign * crit_h * (1 - 1e-9), 0.0)
        assert not gmrf.positive_definite(shape, sign * crit_h * (1 + 1e-9), 0.0)
        assert gmrf.positive_definite(shape, 0.0, sign * crit_v * (1 - 1e-9))
        assert not gmrf.positive_definite(shape, 0.0, sign * crit_v * (1 + 1e-9))
    assert gmrf.positive_definite(shape, *near_boundary(shape, 0.3, 1e-9))
    assert not gmrf.positive_definite(shape, *near_boundary(shape, 0.3, -1e-9))
    rng = np.random.default_rng(0)
    for beta in rng.uniform(-0.7, 0.7, (200, 2)):
        lam_min = np.linalg.eigvalsh(dense_a(shape, *beta))[0]
        if abs(lam_min) > 1e-9:
            assert gmrf.positive_definite(shape, *beta) == (lam_min > 0)


@pytest.mark.parametrize("args, match", [
    ((float("nan"), 0.1, 1.0), "finite"), ((0.1, float("inf"), 1.0), "finite"), ((0.1, 0.1, float("nan")), "finite"),
    ((0.1, 0.1, 0.0), "sigma_c must be > 0"), ((0.1, 0.1, -2.0), "sigma_c must be > 0"),
    ((0.3, 0.3, 1.0), "positive definite"), ((-0.6, 0.0, 1.0), "positive definite"), (("0.1", 0.1, 1.0), "finite")])
def test_check_gmrf_errors(args, match):
    with pytest.raises(ParameterError, match=match):
        gmrf.check_gmrf((120, 120), *args)


def test_check_gmrf_accepts_valid_parameters():
    assert gmrf.check_gmrf((120, 120), 0.22, 0.24, 3.0) is None
    assert gmrf.check_gmrf((5, 5), 0.26, 0.245, 1.0) is None  # positive definite on 5×5 (A4)


@pytest.mark.parametrize("window", [3, 5, np.int64(7)])
def test_local_mean_reflects_at_the_border(window):
    """Direct box mean over a symmetric pad (…c b a | a b c…, scipy's "reflect"), every pixel incl. the borders."""
    frame = np.random.default_rng(1).integers(0, 255, (6, 9)).astype(np.uint8)
    h = int(window) // 2
    padded = np.pad(frame.astype(np.float64), h, mode="symmetric")
    ref = np.array([[padded[i:i + window, j:j + window].mean() for j in range(9)] for i in range(6)])
    out = gmrf.local_mean(frame, window)
    assert out.dtype == np.float64
    np.testing.assert_allclose(out, ref, rtol=0, atol=1e-12)
    assert out[0, 0] != pytest.approx(np.pad(frame.astype(float), h)[:window, :window].mean())  # not zero padding


@pytest.mark.parametrize("window", [4, 1, 0, -3, 3.0, True, "5"])
def test_local_mean_rejects_bad_windows(window):
    with pytest.raises(ParameterError, match="window"):
        gmrf.local_mean(np.zeros((8, 8)), window)


def test_gmrf_params_is_frozen():
    p = gmrf.GmrfParams(0.1, 0.2, 4.0)
    assert p.sigma_c == 2.0
    with pytest.raises(AttributeError):
        p.beta_h = 0.3
