"""Alg. 5 of Güler (2016) over all candidates at once: the trajectory cost J of each filter's path in a window,
the merge of filters that follow one thing, the elimination of the unsmooth ones, and the confirmation."""
from __future__ import annotations

import numpy as np


def trajectory_cost(path: np.ndarray, epsilon: float) -> np.ndarray:
    """Alg. 5's J per filter for a window's estimates ``path`` (L, G, 2) px, L = 2M − 1:
    Δv₁ = p_M − p₁, Δv₂ = p_{2M−1} − p_M, J = ‖Δv₂ − Δv₁‖ / ((‖Δv₂‖ + ‖Δv₁‖)/2 + ε); 0 on a straight steady path,
    → 2 on a reversal (J ≤ 2 by the triangle inequality)."""
    m = (path.shape[0] + 1) // 2
    dv1, dv2 = path[m - 1] - path[0], path[-1] - path[m - 1]
    num = np.hypot(*(dv2 - dv1).T)
    return num / ((np.hypot(*dv2.T) + np.hypot(*dv1.T)) / 2.0 + epsilon)


def kept_always(keep) -> set[int]:
    """The filters that always stay: ``keep`` an index (−1: none) or a sequence of them (the reported ones)."""
    return {int(k) for k in np.atleast_1d(keep) if k >= 0}


def merged(path: np.ndarray, alive: np.ndarray, rank: np.ndarray, distance: float, keep) -> np.ndarray:
    """``alive`` without the duplicates: of filters whose estimates stay within ``distance`` px of each other through
    the whole window ``path`` (L, G, 2), the one of lower ``rank`` stays (the tracker ranks by −evidence); the
    filters ``keep``, the confirmed and reported ones, always stay."""
    out = alive.copy()
    live = np.nonzero(alive)[0]
    if len(live) < 2:
        return out
    always = kept_always(keep)
    p = path[:, live]
    close = (np.hypot(*(p[:, :, None] - p[:, None, :]).transpose(3, 0, 1, 2)) <= distance).all(axis=0)
    order = sorted(range(len(live)), key=lambda i: (live[i] not in always, rank[live[i]], live[i]))
    kept: list[int] = []
    for i in order:
        if live[i] not in always and any(close[i, j] for j in kept):
            out[live[i]] = False
        else:
            kept.append(i)
    return out


def eliminated(alive: np.ndarray, cost: np.ndarray, evidence: np.ndarray, keep) -> np.ndarray:
    """Alg. 5's elimination: ``alive`` without the filters of J ≥ mean(J) over the live ones, always keeping the
    lowest J, the strongest ``evidence`` and the filters ``keep`` (see :func:`kept_always`)."""
    live = np.nonzero(alive)[0]
    out = alive.copy()
    if len(live) == 0:
        return out
    out[live[cost[live] >= cost[live].mean()]] = False
    out[live[np.argmin(cost[live])]] = True
    out[live[np.argmax(evidence[live])]] = True
    for k in kept_always(keep):
        out[k] = True
    return out


def strongest(alive: np.ndarray, evidence: np.ndarray, count: int) -> list[int]:
    """The ``count`` live filters of the strongest evidence (mean S_k/σ_k at the estimate), strongest first."""
    live = np.nonzero(alive)[0]
    return [int(g) for g in live[np.argsort(-evidence[live], kind="stable")][:count]]
