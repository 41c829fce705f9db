"""MM-PHD's target-number and state extraction (Eqs. 19–20, 35: k-means over the detector's particles), the adaptive
process noise (Eq. 21) and the backward recursion's gate (Eq. 25): small host-side computations on a few targets."""
from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numpy as np

from ...kernels.phd import EST_COV, EST_MASS, EST_MEAN, EST_PEAK, EST_PROB
from ...motion_models import DIM, X, Y

DET_FLOOR = 1e-12  # floor of |P̂| in Eq. 21's ratio (the print's ‖·‖ is the determinant)


@dataclass
class Capture:
    """One target the detector found: its particles (state, model), their mean X̂ and covariance P̂, model
    probabilities (Eq. 35), PHD mass (its share of n̂) and the PHD mass Ψ/(λ + Ψ) of its peak cell."""

    state: np.ndarray
    model: np.ndarray
    mean: np.ndarray
    cov: np.ndarray
    probs: np.ndarray
    mass: float
    peak: float = 1.0


@dataclass
class ClassEstimate:
    """A filter's target class (one row of the kernels' ``est``): mean (7,), covariance (7, 7), model
    probabilities (Eq. 35), PHD mass Σw̃ and the PHD mass Ψ/(λ + Ψ) of its peak cell."""

    mean: np.ndarray
    cov: np.ndarray
    probs: np.ndarray
    mass: float
    peak: float


def unpack(est_row: np.ndarray, n_models: int) -> ClassEstimate:
    """The :class:`ClassEstimate` of one row of the kernels' ``est``."""
    return ClassEstimate(est_row[EST_MEAN:EST_MEAN + DIM].astype(float),
                         est_row[EST_COV:EST_COV + DIM * DIM].astype(float).reshape(DIM, DIM),
                         est_row[EST_PROB:EST_PROB + n_models].astype(float), float(est_row[EST_MASS]),
                         float(est_row[EST_PEAK]))


def live_dims(models) -> list[int]:
    """The state components the model set moves: x, ẋ, y, ẏ, I, and the accelerations only with CA."""
    return list(range(DIM)) if "ca" in models else list(range(5))


def log_det(cov: np.ndarray, dims) -> float:
    """log |P̂| over ``dims``, floored at log DET_FLOOR (Eq. 21)."""
    sign, value = np.linalg.slogdet(cov[np.ix_(dims, dims)])
    return max(value, math.log(DET_FLOOR)) if sign > 0 else math.log(DET_FLOOR)


def adapted_scale(scale: np.ndarray, log_det_now: np.ndarray, log_det_before: np.ndarray,
                  q_max_ratio: float) -> np.ndarray:
    """Eq. 21 for Q = s·Q_min (Q_max = q_max_ratio·Q_min): s ← 1 + (s − 1)·e^(1 − |P̂_k|/|P̂_{k−1}|) when the
    spread grew or held, s ← s_max + (s − s_max)·e^(1 − |P̂_{k−1}|/|P̂_k|) when it shrank; vectorised over
    trackers."""
    ratio = np.exp(np.clip(log_det_now - log_det_before, -50.0, 50.0))
    grew = ratio >= 1.0
    shrink = 1.0 + (scale - 1.0) * np.exp(1.0 - ratio)
    widen = q_max_ratio + (scale - q_max_ratio) * np.exp(1.0 - 1.0 / np.maximum(ratio, 1e-30))
    return np.where(grew, shrink, widen)


def captures(det: dict, n_hat: float, n_models: int, merge_distance: float, radius: float, draws: int,
             rng: np.random.Generator) -> list[Capture]:
    """The detector's targets (§3.1): ``draws`` particles drawn ∝ w̃ (the updated PHD, Eq. 14, so that the
    classes follow its mass rather than the likelihood-resampled cloud's noise cells), k-means with round(n̂)
    classes on their positions, classes closer than ``merge_distance`` (6Σ, Eq. 12) merged; each class keeps
    its draws within ``radius`` px (per axis) of its densest pixel, and gives their mean, covariance, model
    shares (Eq. 35), mass n̂·(their share of the draws) and largest cell mass; ``det``: the detector's slots
    (:meth:`PhdKernels.slots`)."""
    k = int(round(n_hat))
    w = det["wtilde"].astype(float)
    if k < 1 or len(w) == 0 or w.sum() <= 0:
        return []
    pick = rng.choice(len(w), size=draws, p=w / w.sum())
    state, model, cellmass = det["state"][pick], det["model"][pick], det["cellmass"][pick]
    pos = state[:, [X, Y]].astype(float)
    labels = np.zeros(draws, int) if k == 1 else k_means_labels(pos, k, rng)
    labels = merged_labels(pos, labels, merge_distance)
    out = []
    for lab in np.unique(labels):
        sel = (labels == lab) & near_densest_pixel(pos, labels == lab, radius)
        st = state[sel].astype(float)
        mean = st.mean(axis=0)
        d = st - mean
        probs = np.bincount(model[sel], minlength=n_models)[:n_models] / sel.sum()
        out.append(Capture(state[sel], model[sel], mean, d.T @ d / sel.sum(), probs, n_hat * sel.sum() / draws,
                           float(cellmass[sel].max())))
    return out


def k_means_labels(pos: np.ndarray, k: int, rng: np.random.Generator) -> np.ndarray:
    """k-means (k-means++ start) class labels of the points ``pos`` with at most ``k`` classes, and no more than
    the distinct points (more would leave k-means++ nothing to draw from); a class emptied on the way is dropped."""
    from scipy.cluster.vq import kmeans2  # imported here: 0.1 s that a run of another method does not pay

    k = min(k, len(np.unique(pos, axis=0)))
    if k < 2:
        return np.zeros(len(pos), int)
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", "One of the clusters is empty", UserWarning)
        return kmeans2(pos, k, minit="++", seed=rng)[1]


def near_densest_pixel(pos: np.ndarray, members: np.ndarray, radius: float) -> np.ndarray:
    """The points within ``radius`` px per axis of the centre of the pixel holding most of the ``members``."""
    pix = np.floor(pos[members] + 0.5).astype(np.int64)
    lo = pix.min(axis=0)
    span = pix.max(axis=0) - lo + 1
    flat = (pix[:, 1] - lo[1]) * span[0] + (pix[:, 0] - lo[0])
    best = int(np.argmax(np.bincount(flat)))
    cx, cy = best % span[0] + lo[0], best // span[0] + lo[1]
    return (np.abs(pos[:, 0] - cx) <= radius) & (np.abs(pos[:, 1] - cy) <= radius)


def merged_labels(pos: np.ndarray, labels: np.ndarray, distance: float) -> np.ndarray:
    """``labels`` with the classes whose centres (member means, px) lie closer than ``distance`` joined
    (repeatedly, nearest pair first, the pair's later class into the earlier); the joined class's centre is the
    mean of all its members.  The centres and their gaps are updated per merge (O(k²): the argmin over the gaps),
    not recomputed from the points."""
    ids, inverse, counts = np.unique(labels, return_inverse=True, return_counts=True)
    k = len(ids)
    if k < 2:
        return labels.copy()
    counts = counts.astype(float)
    centres = np.stack([np.bincount(inverse, weights=pos[:, a], minlength=k) for a in range(2)], axis=1)
    centres /= counts[:, None]
    gaps = np.linalg.norm(centres[:, None] - centres[None], axis=2)
    np.fill_diagonal(gaps, np.inf)
    into = np.arange(k)
    while True:
        a, b = np.unravel_index(np.argmin(gaps), gaps.shape)
        if not gaps[a, b] < distance:
            break
        a, b = min(a, b), max(a, b)
        centres[a] = (counts[a] * centres[a] + counts[b] * centres[b]) / (counts[a] + counts[b])
        counts[a] += counts[b]
        into[into == b] = a
        gaps[b, :] = gaps[:, b] = np.inf
        live = np.isfinite(gaps[a]) | (np.arange(k) == a)
        row = np.where(live, np.linalg.norm(centres - centres[a], axis=1), np.inf)
        row[a] = np.inf
        gaps[a, :] = gaps[:, a] = row
    return ids[into][inverse]


def gated(capture: Capture, dims, probability: float) -> np.ndarray:
    """Eq. 25: the capture's particles with (X − X̂)ᵀ P̂⁻¹ (X − X̂) ≤ ξ on ``dims``, ξ the χ²_d quantile of
    ``probability``; a boolean mask (all True if P̂ is singular)."""
    d = capture.state[:, dims].astype(float) - capture.mean[dims]
    cov = capture.cov[np.ix_(dims, dims)] + np.eye(len(dims)) * 1e-9
    try:
        m = np.einsum("pi,ij,pj->p", d, np.linalg.inv(cov), d)
    except np.linalg.LinAlgError:
        return np.ones(len(d), bool)
    from scipy.special import chdtri  # χ² quantiles (scipy.stats.chi2.ppf calls the same)

    keep = m <= chdtri(len(dims), 1.0 - probability)
    return keep if keep.any() else np.ones(len(d), bool)
