"""The multiaspect target model of Bruno, Araújo & Pavlov (EURASIP JASP 2008) shared by its filters
(``tbd_taichi.methods.multiaspect``) and its simulator (``tbd_taichi.bruno2008``): the aspect chain G (Eq. 1), the
white-noise-acceleration motion (Eq. 4) in pixel units, the quantised centroid and the extended grid (Eq. 3, §2),
P_in (Eq. 6, closed form) and the border-aware energy tables of ρ (Eq. 12).

Coordinates are the project's: x = column, y = row, 0-based, pixel centres at integers, velocities in px/frame.
The paper's x is the **row** counted from 1 (Eqs. 8, 15): :func:`paper_to_project` converts once.

Templates are a (K, h, w) float stack, h and w odd, the centroid at the centre pixel; a value is what the target
adds to the (mean-removed) frame there, 0 off the shape (Eq. 8, a_kl = b_kl·φ_kl)."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from .errors import InputError, ParameterError

PAPER_G = np.array([[0.6, 0.4, 0.0, 0.0],
                    [0.4, 0.2, 0.4, 0.0],
                    [0.0, 0.4, 0.2, 0.4],
                    [0.0, 0.0, 0.4, 0.6]])  # §4: G(i, j) = Pr(aspect i | aspect j), 40% to each adjacent aspect
NEIGHBOUR_SHARE = 0.4
MAX_TEMPLATE_SIDE = 63  # px: a template larger than this is no "small" target (and the kernels loop over it)
MOTION_FORMS = ("continuous", "discrete")
# §4's initial law in project coordinates (the paper's x ~ U[50, 70] is the row): column U[10, 20] px,
# row U[50, 70] px, each velocity N(2, 0.1²) px/frame (10 m/s at ζ = 0.2 m/px, T = 0.04 s), aspect uniform
PAPER_PRIOR = {"x": (10.0, 20.0), "y": (50.0, 70.0), "v_mean": 2.0, "v_sd": 0.1}
PAPER_Q, PAPER_T, PAPER_ZETA = 6.0, 0.04, 0.2  # §4: q (m²/s³), frame interval (s), resolution (m/px)


def aspect_transition(k: int) -> np.ndarray:
    """G for K aspects: §4's matrix for K = 4, else 0.4 to each adjacent aspect and the rest kept (Eq. 1)."""
    if k == 4:
        return PAPER_G.copy()
    g = np.zeros((k, k))
    for j in range(k):
        for i in (j - 1, j + 1):
            if 0 <= i < k:
                g[i, j] = NEIGHBOUR_SHARE
        g[j, j] = 1.0 - g[:, j].sum()
    return g


def check_transition(g, k: int, name: str = "G") -> np.ndarray:
    """``g`` as a K×K column-stochastic float array (Eq. 1), else a ParameterError naming the problem."""
    g = np.asarray(g, dtype=float)
    if g.shape != (k, k):
        raise ParameterError(f"{name} must be {k}x{k} (one row and column per template), got shape {g.shape}")
    if not np.all(np.isfinite(g)) or np.any(g < 0):
        raise ParameterError(f"{name} must hold finite probabilities ≥ 0")
    sums = g.sum(axis=0)
    if np.any(np.abs(sums - 1.0) > 1e-6):
        bad = int(np.argmax(np.abs(sums - 1.0)))
        raise ParameterError(f"{name} must be column-stochastic (Eq. 1: each column sums to 1); column {bad} sums "
                             f"to {sums[bad]:.6g}")
    return g


def check_templates(t, name: str = "templates") -> np.ndarray:
    """``t`` as a (K, h, w) float64 stack: K ≥ 1, h, w odd and ≤ MAX_TEMPLATE_SIDE, finite, no template all zero;
    returned cropped to its support (:func:`crop_to_support`)."""
    t = np.asarray(t)
    if t.ndim != 3:
        raise ParameterError(f"{name} must be a 3-D stack (K, h, w), got {t.ndim}-D shape {t.shape}")
    k, h, w = t.shape
    if k == 0:
        raise ParameterError(f"{name} holds no template (K = 0)")
    if h % 2 == 0 or w % 2 == 0:
        raise ParameterError(f"{name}' h, w must be odd (the centroid is the centre pixel), got {h}x{w}")
    if max(h, w) > MAX_TEMPLATE_SIDE:
        raise ParameterError(f"{name} of {h}x{w} px is too large: h, w ≤ {MAX_TEMPLATE_SIDE}")
    if not np.issubdtype(t.dtype, np.number) or np.issubdtype(t.dtype, np.complexfloating):
        raise ParameterError(f"{name} must be real numbers, got dtype {t.dtype}")
    t = t.astype(float)
    if not np.all(np.isfinite(t)):
        raise ParameterError(f"{name} hold NaN or inf")
    empty = [i for i in range(k) if not np.any(t[i])]
    if empty:
        raise ParameterError(f"{name}: template {empty[0]} is all zero (a target must add something)")
    return crop_to_support(t)


def crop_to_support(t: np.ndarray) -> np.ndarray:
    """The (K, h, w) stack cut to the smallest centred box that holds every aspect's non-zero pixels.  §2 defines
    r_i, r_s (l_i, l_s) as the largest distances of a *target pixel* from the centroid, so the extended grid (the
    centroids with a target pixel in the image) must not count a template's zero margin; a centred box takes
    max(r_i, r_s) each side, the paper's grid when the support is symmetric."""
    rows, cols = np.nonzero(np.any(t != 0, axis=0))
    (_, h, w) = t.shape
    hh = int(np.abs(rows - (h - 1) // 2).max())
    hw = int(np.abs(cols - (w - 1) // 2).max())
    return t[:, (h - 1) // 2 - hh:(h + 1) // 2 + hh, (w - 1) // 2 - hw:(w + 1) // 2 + hw]


def load_array(name: str, path) -> np.ndarray:
    """The array in the ``.npy`` file ``path`` (--param NAME=PATH), or an InputError naming it."""
    p = Path(path)
    if p.suffix.lower() != ".npy":
        raise InputError(f"--param {name}={path}: give a .npy file")
    if not p.is_file():
        raise InputError(f"--param {name}={path}: no such file")
    try:
        return np.load(p, allow_pickle=False)
    except (OSError, ValueError) as exc:
        raise InputError(f"--param {name}={path}: not a readable .npy array ({exc})") from None


def motion_noise(q: float, T: float, zeta: float, form: str = "continuous") -> np.ndarray:
    """Q of Eq. 4's white-noise acceleration for one axis, (position px, velocity px/frame), 2×2.

    ``continuous`` (Bar-Shalom & Li's CWNA, the paper's ref. [3]): q·[[T³/3, T²/2], [T²/2, T]] m², m²/s, m²/s²;
    ``discrete`` (DWNA): q·[[T⁴/4, T³/2], [T³/2, T²]].  Metres → px divide by ζ, m/s → px/frame multiply by T/ζ:
    q = 6 m²/s³, T = 0.04 s, ζ = 0.2 m/px give position sd 0.057 px and velocity sd 0.098 px/frame (CWNA)."""
    if form not in MOTION_FORMS:
        raise ParameterError(f"motion must be one of {', '.join(MOTION_FORMS)}, got {form!r}")
    if form == "continuous":
        shape = np.array([[1.0 / 3.0, 0.5], [0.5, 1.0]]) * T ** 3
    else:
        shape = np.array([[0.25, 0.5], [0.5, 1.0]]) * T ** 4
    return q * shape / zeta ** 2


def noise_factor(cov: np.ndarray) -> tuple[float, float, float]:
    """(a, b, c) of the lower Cholesky factor [[a, 0], [b, c]] of a 2×2 covariance: w = (a·n₁, b·n₁ + c·n₂)."""
    a = math.sqrt(max(cov[0, 0], 0.0))
    b = cov[1, 0] / a if a > 0 else 0.0
    return a, b, math.sqrt(max(cov[1, 1] - b * b, 0.0))


def quantise(v) -> np.ndarray:
    """Eq. 3's rounding to the nearest pixel centre, halves up (floor(v + ½), not NumPy's half-to-even)."""
    return np.floor(np.asarray(v, dtype=float) + 0.5).astype(np.int64)


def paper_to_project(x_paper, y_paper) -> tuple[np.ndarray, np.ndarray]:
    """The paper's (x = row, y = column, 1-based; Eqs. 3, 8, 15) as the project's (x = column, y = row, 0-based)."""
    return np.asarray(y_paper, dtype=float) - 1.0, np.asarray(x_paper, dtype=float) - 1.0


def project_to_paper(x, y) -> tuple[np.ndarray, np.ndarray]:
    """The inverse of :func:`paper_to_project`."""
    return np.asarray(y, dtype=float) + 1.0, np.asarray(x, dtype=float) + 1.0


def half_sizes(templates: np.ndarray) -> tuple[int, int]:
    """(rows, columns) each side of the centroid: r_i = r_s and l_i = l_s of §2 for centred templates."""
    return (templates.shape[1] - 1) // 2, (templates.shape[2] - 1) // 2


def extended_grid(shape, halves) -> tuple[float, float, float, float]:
    """The centroid positions whose template still touches the image (§2's extended grid), as the continuous
    box [x_lo, x_hi) × [y_lo, y_hi) whose quantised points (Eq. 3) are the grid: columns −h_w … W − 1 + h_w,
    rows −h_h … H − 1 + h_h."""
    (h, w), (hh, hw) = shape, halves
    return -hw - 0.5, w - 0.5 + hw, -hh - 0.5, h - 0.5 + hh


def p_inside(mean_x, mean_y, sd: float, shape, halves) -> np.ndarray:
    """P_in of Eq. 6 in closed form (notes A1): the probability that the next quantised centroid, Gaussian
    around (mean_x, mean_y) with position sd ``sd`` per axis, lies on the extended grid."""
    x0, x1, y0, y1 = extended_grid(shape, halves)
    mean_x, mean_y = np.asarray(mean_x, float), np.asarray(mean_y, float)
    if sd <= 0:
        return ((mean_x >= x0) & (mean_x < x1) & (mean_y >= y0) & (mean_y < y1)).astype(float)
    from scipy.special import ndtr  # imported here: listing the methods does not pay for scipy.special

    px = ndtr((x1 - mean_x) / sd) - ndtr((x0 - mean_x) / sd)
    py = ndtr((y1 - mean_y) / sd) - ndtr((y0 - mean_y) / sd)
    return px * py


def energy_tables(templates: np.ndarray, shape) -> np.ndarray:
    """(3, K, H + h − 1, W + w − 1) float64: E₀, C_h, C_v of ρ = E₀ − 2β_h·C_h − 2β_v·C_v (Eq. 12; notes A6) for
    every aspect and extended-grid centroid (index = centroid + half size): Σ a² over the template pixels inside
    the image, Σ a·a(right neighbour) and Σ a·a(below) over the pairs with both pixels inside.  Built once; ρ is
    then exact for the truncated h of Remark 1 (Eq. 14 is the finite field's precision)."""
    t = np.asarray(templates, float)
    k, th, tw = t.shape
    h, w = shape
    inside = np.zeros((h + 2 * (th - 1), w + 2 * (tw - 1)))
    inside[th - 1:th - 1 + h, tw - 1:tw - 1 + w] = 1.0
    right = inside * np.roll(inside, -1, axis=1)  # the pixel and its right neighbour both inside
    below = inside * np.roll(inside, -1, axis=0)
    out = np.zeros((3, k, h + th - 1, w + tw - 1))
    pair_h = np.zeros_like(t)
    pair_h[:, :, :-1] = t[:, :, :-1] * t[:, :, 1:]
    pair_v = np.zeros_like(t)
    pair_v[:, :-1, :] = t[:, :-1, :] * t[:, 1:, :]
    from scipy import ndimage  # imported here, as in LocalPlane: 0.15 s that a run of another method does not pay

    for z in range(k):
        for slot, (mask, kernel) in enumerate(((inside, t[z] ** 2), (right, pair_h[z]), (below, pair_v[z]))):
            full = ndimage.correlate(mask, kernel, mode="constant", origin=(-(th // 2), -(tw // 2)))
            out[slot, z] = full[:h + th - 1, :w + tw - 1]
    return out


class LocalPlane:
    """The local mean of frames of ``shape`` as a least-squares plane a + b·(x − x̄) + c·(y − ȳ) over the
    ``window``² pixels around each pixel that lie in the image, evaluated at the pixel (box sums by
    ``scipy.ndimage.uniform_filter``; the window's geometry is summed once).  Inside, it equals the box mean (the
    window is centred); at the borders, where a box mean is biased by the slope of the background (up to σ_c and
    more on smooth terrain: false "targets" along the edges), the plane follows it."""

    def __init__(self, shape, window: int):
        from scipy import ndimage

        self.window, self.uniform_filter = int(window), ndimage.uniform_filter
        yy, xx = np.mgrid[0:shape[0], 0:shape[1]].astype(np.float64)
        self.one = self._box(np.ones(tuple(shape)))
        self.mx, self.my = self._box(xx) / self.one, self._box(yy) / self.one
        sxx = self._box(xx * xx) / self.one - self.mx ** 2
        syy = self._box(yy * yy) / self.one - self.my ** 2
        sxy = self._box(xx * yy) / self.one - self.mx * self.my
        det = np.maximum(sxx * syy - sxy * sxy, 1e-12)
        self.sxx, self.syy, self.sxy, self.det = sxx / det, syy / det, sxy / det, det
        self.dx, self.dy = xx - self.mx, yy - self.my
        self.xx, self.yy = xx, yy

    def _box(self, a: np.ndarray) -> np.ndarray:
        return self.uniform_filter(a, self.window, mode="constant")

    def __call__(self, frame: np.ndarray) -> np.ndarray:
        """The plane's value at each pixel of ``frame`` (float64)."""
        f = np.asarray(frame, dtype=np.float64)
        mf = self._box(f) / self.one
        sxf = self._box(self.xx * f) / self.one - self.mx * mf
        syf = self._box(self.yy * f) / self.one - self.my * mf
        return mf + (self.syy * sxf - self.sxy * syf) * self.dx + (self.sxx * syf - self.sxy * sxf) * self.dy
