"""First-order noncausal Gauss–Markov random field clutter (Bruno et al. 2008, Eqs. 9, 13, 14; Moura & Balram):
V(r, j) = β_v[V(r−1, j) + V(r+1, j)] + β_h[V(r, j−1) + V(r, j+1)] + ε(r, j) with zero boundary, precision
Σ_v⁻¹ = A/σ_c², A = I ⊗ (I − β_h B_M) − β_v B_L ⊗ I (Eq. 14), diagonalised by the 2-D DST-I (notes A4).

Fields are in the frame's intensity units (σ_c² in units²); β_h, β_v are dimensionless. The maximum-likelihood
estimator (notes B1) needs ln det A and its β-derivatives every frame; each row's sum over the M columns is a
tridiagonal Toeplitz determinant (a Chebyshev U_M) in closed form, so one evaluation costs O(L), not O(L·M)."""
from __future__ import annotations

import functools
import itertools
import math
import numbers
from dataclasses import dataclass

import numpy as np

from .errors import ParameterError

MARGIN = 1e-6  # least λ_min (exact) or 1 − 2|β_h| − 2|β_v| (approximate) the estimator visits
SIGMA2_FLOOR = 1e-30  # units²: σ̂_c² of an all-zero frame (S0 = 0); still positive after a cast to float32
_TOL, _MAX_ITER = 1e-7, 50  # Newton stops when the step |Δβ| < _TOL or after _MAX_ITER steps
_X_SERIES, _N_SERIES = 4.0, 15  # rows with x = a/2|b| ≥ 4 use the moment series (truncation < 16^−15)
_DIRECT_COLS = 16  # up to this many columns the row sums are plain sums
_QUAD = 256  # midpoint nodes on [0, π] for the approximate (large-grid) log-determinant


def eigenvalues(shape, beta_h: float, beta_v: float) -> np.ndarray:
    """λ_kl = 1 − 2β_v·cos(kπ/(L+1)) − 2β_h·cos(lπ/(M+1)), k = 1..L, l = 1..M (notes A4): A's eigenvalues, (L, M)."""
    rows, cols = shape
    cv = np.cos(np.arange(1, rows + 1) * np.pi / (rows + 1))
    ch = np.cos(np.arange(1, cols + 1) * np.pi / (cols + 1))
    return 1.0 - 2.0 * beta_v * cv[:, None] - 2.0 * beta_h * ch[None, :]


def sample_gmrf(rng: np.random.Generator, shape, beta_h: float, beta_v: float, sigma_c: float, n: int = 1) -> np.ndarray:
    """``n`` exact draws (n, L, M) of the field: v = σ_c·S·diag(λ^−½)·S·w, w ~ N(0, I), S the orthonormal DST-I
    (notes A5), so Cov v = σ_c²A⁻¹ = Σ_v."""
    lam = eigenvalues(shape, beta_h, beta_v)
    w = rng.standard_normal((n,) + tuple(shape))
    from scipy import fft  # imported here: 0.1 s that a run of another method does not pay

    return sigma_c * fft.dstn(w / np.sqrt(lam), type=1, norm="ortho", axes=(1, 2))


def _lambda_min(shape, beta_h: float, beta_v: float) -> float:
    """min λ_kl = 1 − 2|β_v|cos(π/(L+1)) − 2|β_h|cos(π/(M+1)) (notes A4), dimensionless."""
    rows, cols = shape
    return 1.0 - 2.0 * abs(beta_v) * math.cos(math.pi / (rows + 1)) - 2.0 * abs(beta_h) * math.cos(math.pi / (cols + 1))


def positive_definite(shape, beta_h: float, beta_v: float) -> bool:
    """A (Eq. 14) is positive definite iff 2|β_v|cos(π/(L+1)) + 2|β_h|cos(π/(M+1)) < 1 (notes A4)."""
    return bool(_lambda_min(shape, beta_h, beta_v) > 0.0)


def check_gmrf(shape, beta_h: float, beta_v: float, sigma_c: float) -> None:
    """ParameterError unless β_h, β_v, σ_c are finite, σ_c > 0 (units) and A(β) is positive definite (notes A4)."""
    if not all(isinstance(x, numbers.Real) and math.isfinite(x) for x in (beta_h, beta_v, sigma_c)):
        raise ParameterError(f"GMRF parameters must be finite, got beta_h={beta_h}, beta_v={beta_v}, "
                             f"sigma_c={sigma_c}")
    if not sigma_c > 0:
        raise ParameterError(f"sigma_c must be > 0, got {sigma_c}")
    if not positive_definite(shape, beta_h, beta_v):
        raise ParameterError(f"beta_h={beta_h}, beta_v={beta_v} do not give a positive definite A on a {shape[0]}×"
                             f"{shape[1]} grid: need 2|beta_v|cos(π/(L+1)) + 2|beta_h|cos(π/(M+1)) < 1")


def lag_sums(v) -> tuple[float, float, float]:
    """(S0, S_h, S_v) = (Σ v(r,j)², Σ v(r,j)v(r,j+1), Σ v(r,j)v(r+1,j)) in float64 (notes B1), units²; then
    vᵀAv = S0 − 2β_h·S_h − 2β_v·S_v."""
    v = np.ascontiguousarray(v, dtype=np.float64)
    if v.ndim != 2:
        raise ParameterError(f"v must be a 2-D frame, got shape {v.shape}")
    f, m = v.ravel(), v.shape[1]
    s_h = float(f[:-1] @ f[1:] - v[:-1, -1] @ v[1:, 0])  # the row-major neighbours minus the row wrap-arounds
    return float(f @ f), s_h, float(f[:-m] @ f[m:])


@functools.lru_cache(maxsize=64)
def _cosines(n: int) -> np.ndarray:
    """cos(kπ/(n+1)), k = 1..n (the DST-I frequencies of notes A4), read-only."""
    c = np.cos(np.arange(1, n + 1) * np.pi / (n + 1))
    c.flags.writeable = False
    return c


@functools.lru_cache(maxsize=64)
def _series_coefficients(n: int) -> np.ndarray:
    """(J, 3): m_2j/2j, m_2j, (2j − 1)·m_2j for j = 1..J, m_p = Σ_l cos^p(lπ/(n+1)) (odd moments vanish)."""
    m = np.cumprod(np.broadcast_to(_cosines(n) ** 2, (_N_SERIES, n)), axis=0).sum(axis=1)
    j = np.arange(1, _N_SERIES + 1)
    coef = np.stack([m / (2 * j), m, (2 * j - 1) * m], axis=1)
    coef.flags.writeable = False
    return coef


def _row_direct(a: np.ndarray, b: float, n_cols: int) -> tuple:
    """F = Σ_l ln λ_l, λ_l = a − 2b·c_l, and F_a, F_b, F_aa, F_ab, F_bb (∂/∂a, ∂/∂b) by direct sums over l."""
    c = _cosines(n_cols)
    lam = a[:, None] - 2.0 * b * c[None, :]
    r = 1.0 / lam
    r2 = r * r
    return (np.log(lam).sum(1), r.sum(1), -2.0 * (r @ c), -r2.sum(1), 2.0 * (r2 @ c), -4.0 * (r2 @ (c * c)))


def _row_series(a: np.ndarray, b: float, n_cols: int) -> tuple:
    """The same six for ρ = 2b/a ≤ ½: F = M ln a − Σ_j m_2j ρ^2j/(2j) (the Taylor series of Σ_l ln(1 − ρc_l))."""
    rho = 2.0 * b / a
    u = rho * rho
    powers = u[:, None] ** np.arange(_N_SERIES)[None, :]
    g0, g1, g2 = (powers @ _series_coefficients(n_cols)).T  # Σ_j coefficient·u^(j−1)
    a2 = a * a
    return (n_cols * np.log(a) - u * g0, (n_cols + u * g1) / a, -2.0 * rho * g1 / a,
            (-n_cols - 2.0 * u * g1 - u * g2) / a2, 2.0 * rho * (g1 + g2) / a2, -4.0 * g2 / a2)


def _cheb_real(d: np.ndarray, x: np.ndarray, n: int) -> np.ndarray:
    """x = 1 + d = cosh t ≥ 1: (ln U_M, sinh t, K = n·coth nt − coth t, K' = n²csch²nt − csch²t), n = M + 1."""
    t = np.log1p(d + np.sqrt(d * (d + 2.0)))
    sh, q = np.sinh(t), np.exp(-2.0 * n * t)
    en = -np.expm1(-2.0 * n * t)
    return np.stack([(n - 1) * t + np.log(en) - np.log(-np.expm1(-2.0 * t)), sh, n * (1.0 + q) / en - x / sh,
                     4.0 * n * n * q / en ** 2 - 1.0 / sh ** 2])


def _cheb_trig(d: np.ndarray, n: int) -> np.ndarray:
    """x = 1 + d = cos θ < 1: the same with t = iθ, (ln U_M, sin θ, cot θ − n·cot nθ, n²csc²nθ − csc²θ)."""
    th = 2.0 * np.arcsin(np.sqrt(-d / 2.0))
    sn, snn = np.sin(th), np.sin(n * th)
    return np.stack([np.log(snn) - np.log(sn), sn, 1.0 / np.tan(th) - n / np.tan(n * th),
                     (n / snn) ** 2 - 1.0 / sn ** 2])


def _row_closed(a: np.ndarray, b: float, n_cols: int) -> tuple:
    """The same six from U_M(x) = Π_l 2(x − c_l), x = a/2b = cosh t (or cos θ): ln U = ln sinh((M+1)t) −
    ln sinh t, S1 = Σ 1/(x − c_l) = U'/U = K/sinh t, S2 = Σ 1/(x − c_l)² = −S1' (b > 0, (M+1)|t| ≥ 1, x < 4)."""
    n, x = n_cols + 1, a / (2.0 * b)
    d = (a - 2.0 * b) / (2.0 * b)
    real = d >= 0
    u = np.empty((4, len(a)))
    if real.any():
        u[:, real] = _cheb_real(d[real], x[real], n)
    if not real.all():
        u[:, ~real] = _cheb_trig(d[~real], n)
    ln_u, sh, k, dk = u
    s1 = k / sh
    s2 = dk / sh ** 2 + np.where(real, k, -k) * x / sh ** 3
    b2 = 4.0 * b * b
    return (n_cols * math.log(b) + ln_u, s1 / (2.0 * b), -(x * s1 - n_cols) / b, -s2 / b2,
            2.0 * (x * s2 - s1) / b2, -4.0 * (x * x * s2 - 2.0 * x * s1 + n_cols) / b2)


def _row_sums(a: np.ndarray, beta_h: float, n_cols: int) -> tuple:
    """F(a_k) = Σ_l ln(a_k − 2β_h c_l) and its derivatives for every row k, each row by an exact route: the moment
    series where x = a/2|β_h| ≥ 4, plain sums where (M+1)|t| < 1 (the closed form cancels) or M ≤ 16, else U_M."""
    if n_cols <= _DIRECT_COLS:
        return _row_direct(a, beta_h, n_cols)
    b = abs(beta_h)
    x = a / (2.0 * b) if b > 0 else np.full(len(a), np.inf)
    route = np.where(x >= _X_SERIES, 0, np.where(np.abs(x - 1.0) * 2.0 * (n_cols + 1) ** 2 < 1.0, 2, 1))
    out = np.empty((6, len(a)))
    for k, fn in enumerate((_row_series, _row_closed, _row_direct)):
        if (sel := route == k).any():
            out[:, sel] = fn(a[sel], b, n_cols)
    if beta_h < 0:  # {c_l} is symmetric, so F is even in β_h
        out[[2, 4]] *= -1.0
    return tuple(out)


def _row_integral(a: np.ndarray, beta_h: float, n_cols: int) -> tuple:
    """F = M·(1/2π)∫ ln(a − 2β_h cos ω)dω = M·ln((a + r)/2), r = √(a² − 4β_h²), and its derivatives."""
    r = np.sqrt(a * a - 4.0 * beta_h * beta_h)
    ar = a + r
    fb = -4.0 * beta_h / (r * ar)
    fbb = -4.0 / (r * ar) - 16.0 * beta_h ** 2 * (a + 2.0 * r) / (r ** 3 * ar ** 2)
    return tuple(n_cols * q for q in (np.log(ar / 2.0), 1.0 / r, fb, -a / r ** 3, 4.0 * beta_h / r ** 3, fbb))


def _log_det_derivs(shape, beta_h: float, beta_v: float, approximate: bool):
    """(ln det A, ∇, ∇²) in (β_h, β_v): Σ_k w_k F(a_k, β_h) with a_k = 1 − 2β_v·c_k; exact: c_k = cos(kπ/(L+1)),
    w_k = 1; approximate: midpoint nodes c_k = cos ω_k on [0, π], w_k = L/K (L·M times the large-grid integral)."""
    rows, cols = shape
    if approximate:
        c, w = np.cos((np.arange(_QUAD) + 0.5) * np.pi / _QUAD), rows / _QUAD
        f, fa, fb, faa, fab, fbb = _row_integral(1.0 - 2.0 * beta_v * c, beta_h, cols)
    else:
        c, w = _cosines(rows), 1.0
        f, fa, fb, faa, fab, fbb = _row_sums(1.0 - 2.0 * beta_v * c, beta_h, cols)
    grad = w * np.array([fb.sum(), -2.0 * (fa @ c)])
    hvh = -2.0 * (fab @ c)
    hess = w * np.array([[fbb.sum(), hvh], [hvh, 4.0 * (faa @ (c * c))]])
    return w * float(f.sum()), grad, hess


def log_det(shape, beta_h: float, beta_v: float, approximate: bool = False) -> float:
    """ln det A = Σ_kl ln λ_kl (Eq. 14, notes A4), or with ``approximate`` L·M·(1/4π²)∬ ln(1 − 2β_h cos ω₁ −
    2β_v cos ω₂)dω₁dω₂ (the large-grid limit, ref. [12]'s approximate ML; needs |β_h| + |β_v| < ½). Dimensionless."""
    if not positive_definite(shape, beta_h, beta_v):
        raise ParameterError(f"log_det: beta_h={beta_h}, beta_v={beta_v} do not give a positive definite A on a "
                             f"{shape[0]}×{shape[1]} grid (need 2|beta_v|cos(π/(L+1)) + 2|beta_h|cos(π/(M+1)) < 1)")
    if approximate and not abs(beta_h) + abs(beta_v) < 0.5:
        raise ParameterError(f"log_det(approximate=True) needs |beta_h| + |beta_v| < 0.5, got {beta_h}, {beta_v}")
    return _log_det_derivs(tuple(shape), float(beta_h), float(beta_v), approximate)[0]


@dataclass(frozen=True)
class GmrfParams:
    """GMRF clutter parameters: β_h, β_v (dimensionless) and the prediction-error variance σ_c² (units²)."""
    beta_h: float
    beta_v: float
    sigma_c2: float

    @property
    def sigma_c(self) -> float:
        """σ_c = √σ_c² (units)."""
        return math.sqrt(self.sigma_c2)


def _slack(shape, beta, approximate: bool) -> tuple[float, np.ndarray]:
    """How far β is inside the search region, λ_min − MARGIN (approximate: 1 − 2|β_h| − 2|β_v| − MARGIN), and the
    weights w of |β| in it (slack = 1 − MARGIN − w·|β|): the region is a convex diamond."""
    w = np.full(2, 2.0) if approximate else 2.0 * np.cos(np.pi / (np.array(shape[::-1]) + 1.0))
    return 1.0 - MARGIN - float(w @ np.abs(beta)), w


def _profile(shape, sums, beta, approximate: bool):
    """ℓ(β) = −(LM/2)·ln σ̂_c²(β) + ½ ln det A(β) (Eq. 13 profiled over σ_c²), its gradient and Hessian, and
    σ̂_c²(β) = (S0 − 2β_h S_h − 2β_v S_v)/(LM) (notes B1)."""
    n = shape[0] * shape[1]
    s0, s = sums[0], np.array(sums[1:])
    q = s0 - 2.0 * (beta @ s)
    ld, g, h = _log_det_derivs(shape, beta[0], beta[1], approximate)
    hess = 2.0 * n * np.outer(s, s) / q ** 2 + 0.5 * h
    return -0.5 * n * math.log(q / n) + 0.5 * ld, n * s / q + 0.5 * g, hess, float(q / n)


def estimate_gmrf(v, approximate: bool = False, start: GmrfParams | None = None) -> GmrfParams:
    """Maximum-likelihood (β_h, β_v, σ_c²) of Eq. 13 for a mean-removed L×M frame v (notes B1): damped Newton on
    ℓ(β) with the analytic gradient and Hessian from ``start`` (else, or if it lies outside the search region,
    (0, 0)); steps are halved to stay in λ_min ≥ MARGIN (approximate: 1 − 2|β_h| − 2|β_v| ≥ MARGIN) and to raise ℓ;
    stops when |Δβ| < 1e-7 or after 50 steps. An all-zero frame (S0 = 0) gives β = (0, 0), σ_c² = SIGMA2_FLOOR.
    ``approximate`` uses the large-grid log-determinant (ref. [12]'s AML). σ_c² in units², β dimensionless."""
    v, scale = np.ascontiguousarray(v, dtype=np.float64), 1.0
    if v.ndim != 2 or min(v.shape) < 3:
        raise ParameterError(f"v must be a 2-D frame with both sides ≥ 3, got shape {v.shape}")
    with np.errstate(over="ignore", under="ignore", invalid="ignore"):
        sums = lag_sums(v)
    if not 1e-250 < sums[0] < 1e250:  # NaN/inf, all zero, or Σv² near under/overflow: β is scale-free
        if not np.isfinite(v).all():
            raise ParameterError("v must be finite: it holds NaN or inf")
        scale = float(np.abs(v).max())
        if scale == 0.0:
            return GmrfParams(0.0, 0.0, SIGMA2_FLOOR)
        sums = lag_sums(v / scale)
    beta = np.zeros(2) if start is None else np.array([start.beta_h, start.beta_v], dtype=np.float64)
    if not (np.isfinite(beta).all() and _slack(v.shape, beta, approximate)[0] >= 0):
        beta = np.zeros(2)
    beta, s2 = _newton(v.shape, sums, beta, approximate)
    return GmrfParams(float(beta[0]), float(beta[1]), max(s2 * scale * scale, SIGMA2_FLOOR))


def _newton(shape, sums, beta: np.ndarray, approximate: bool):
    """Damped Newton ascent of ℓ (see :func:`_profile`) from a feasible β: (β̂, σ̂_c²(β̂)). Where the Hessian H is
    not negative definite the step uses ½∇² ln det A instead (negative definite, so still an ascent direction). A
    step that would leave the search region stops on its edge; on the edge a step pointing out slides along it."""
    val, g, h, s2 = _profile(shape, sums, beta, approximate)
    for _ in range(_MAX_ITER):
        if not (h[0, 0] < 0 and np.linalg.det(h) > 0):
            h = 0.5 * _log_det_derivs(shape, beta[0], beta[1], approximate)[2]
        d = -np.linalg.solve(h, g)
        slack, w = _slack(shape, beta, approximate)
        normal = w * np.where(beta != 0, np.sign(beta), np.sign(d))  # outward normal of the edge nearest β
        out, edge = float(normal @ d), []  # out: the slack a full step uses up
        if out > 0 and slack < 1e-12:  # on the edge, pointing out: Newton along the edge instead
            p = np.array([normal[1], -normal[0]])
            d = -(g @ p) / (p @ h @ p) * p
        elif out > slack:  # the full step leaves the region: first try stopping on its edge
            edge = [slack / out]
        size = float(np.abs(d).max())
        for step in itertools.chain(edge, (0.5 ** k for k in itertools.count())):  # Armijo backtracking
            if step * size < 1e-3 * _TOL:  # pinned at the margin: no feasible ascent left
                return beta, s2
            nb = beta + step * d
            if _slack(shape, nb, approximate)[0] >= 0:
                new = _profile(shape, sums, nb, approximate)
                rising = not edge or step != edge[0] or new[1] @ d > 0  # keep an edge stop only if ℓ still rises
                if (new[0] >= val + 1e-4 * step * (g @ d) and rising) or step * size < _TOL:
                    break
        beta, (val, g, h, s2) = nb, new
        if step * size < _TOL:
            break
    return beta, s2


def local_mean(frame, window: int) -> np.ndarray:
    """The local mean (frame units) over a window×window box reflected at the border (the paper's local-mean
    removal before the GMRF, §2.2): ndimage.uniform_filter(frame as float64, size=window, mode="reflect")."""
    if isinstance(window, bool) or not isinstance(window, (int, np.integer)) or window < 3 or window % 2 == 0:
        raise ParameterError(f"window must be an odd integer ≥ 3, got {window!r}")
    frame = np.asarray(frame, dtype=np.float64)
    if frame.ndim != 2:
        raise ParameterError(f"frame must be 2-D, got shape {frame.shape}")
    from scipy import ndimage

    return ndimage.uniform_filter(frame, size=int(window), mode="reflect")
