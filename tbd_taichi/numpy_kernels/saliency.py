"""NumPy twin of ``tbd_taichi.kernels.saliency``: same contracts, same f32 operation order.

Border rule: out-of-image pixels are ignored by max filters and count 0 in sums.
"""
from __future__ import annotations

import numpy as np

F32 = np.float32
NEG_INF = F32(-3.0e38)  # as the kernels' NEG_INF
LEF_NO_CAP = 3.0e38  # as the kernels' LEF_NO_CAP


def _window_sum_max(p: np.ndarray, r: int, axis: int):
    """Σ and max over |d| ≤ r along ``axis`` (zero outside), summed from −r to r."""
    pad = [(0, 0), (0, 0)]
    pad[axis] = (r, r)
    padded = np.pad(p, pad)
    n = p.shape[axis]
    total = np.zeros_like(p)
    peak = np.zeros_like(p)
    for d in range(2 * r + 1):
        v = padded[d:d + n] if axis == 0 else padded[:, d:d + n]
        total = total + v
        peak = np.maximum(peak, v)
    return total, peak


def energy_collection(z: np.ndarray, r: int = 1) -> np.ndarray:
    """Eqs. 20–21 on p = max(z, 0): p·Σ p / max p over the (2r+1)² window; 0 where max p = 0.

    The window sum is separable, rows first, as in the kernel.
    """
    p = np.maximum(z.astype(F32), F32(0))
    hs, hm = _window_sum_max(p, r, 1)
    total, _ = _window_sum_max(hs, r, 0)
    _, peak = _window_sum_max(hm, r, 0)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(peak > 0, p * total / peak, F32(0)).astype(F32)


def max_filter(src: np.ndarray, r: int = 1) -> np.ndarray:
    """(2r+1)² maximum over in-image neighbours (separable; max is exact in any order)."""
    padded = np.pad(src.astype(F32), r, constant_values=-np.inf)
    h, w = src.shape
    rows = padded[:, 0:w].copy()
    for dx in range(1, 2 * r + 1):
        rows = np.maximum(rows, padded[:, dx:dx + w])
    out = rows[0:h].copy()
    for dy in range(1, 2 * r + 1):
        out = np.maximum(out, rows[dy:dy + h])
    return out


def sum_frames(a, b, c, scale: float) -> np.ndarray:
    """Eq. 22: ((a + b) + c)·scale, with None for a missing frame."""
    present = [v for v in (a, b, c) if v is not None]
    total = np.zeros_like(present[0], dtype=F32)
    for v in present:
        total = total + v
    return total * F32(scale)


def row_moments(src: np.ndarray) -> np.ndarray:
    """(H, 2) f64: per-row Σ v and Σ v²."""
    v = src.astype(np.float64)
    return np.stack([v.sum(axis=1), (v * v).sum(axis=1)], axis=1)


def correlate_d(z: np.ndarray, d: np.ndarray) -> np.ndarray:
    """z ⋆ D (5×5, zero padding), summed in the kernel's row-major order."""
    padded = np.pad(z.astype(F32), 2)
    acc = np.zeros(z.shape, F32)
    for dy in range(5):
        for dx in range(5):
            acc = acc + F32(d[dy, dx]) * padded[dy:dy + z.shape[0], dx:dx + z.shape[1]]
    return acc


def lef_log_weight(b: np.ndarray, a: float, i_min: float, i_max: float) -> np.ndarray:
    """Eqs. 27–28: −A·I_c² + B·I_c with I_c = clamp(B/(2A), i_min, i_max)."""
    a, i_min, i_max = F32(a), F32(i_min), F32(i_max)
    ic = np.minimum(np.maximum(b / (F32(2.0) * a), i_min), i_max)
    return (b * ic - a * (ic * ic)).astype(F32)


def lef_map(z: np.ndarray, d: np.ndarray, inv_var: float, a: float, i_min: float, i_max: float) -> np.ndarray:
    """log ω̌_lef at every pixel (Eqs. 25–28)."""
    return lef_log_weight(correlate_d(z, d) * F32(inv_var), a, i_min, i_max)


def accumulate_lef(memory: np.ndarray, z: np.ndarray, d: np.ndarray, a: float, memory_decay: float,
                   r: int = 1) -> np.ndarray:
    """Multi-frame LEF (not in the paper): log ω̌⁺(z) + γ·max_{(2r+1)²} memory, where log ω̌⁺ is
    Eqs. 27–28 with the intensity bounds [0, ∞) (``memory`` is the previous frame's result, zeros
    before the first frame)."""
    lef = lef_log_weight(correlate_d(z, d), a, 0.0, LEF_NO_CAP)
    return (lef + F32(memory_decay) * max_filter(memory, r)).astype(F32)


def best_lef(mask: np.ndarray, lef: np.ndarray, k: int) -> np.ndarray:
    """(k, 2) f64: (log ω̌_lef, pixel y·W + x) of the I_rt pixels with the k largest log ω̌_lef,
    descending, ties in row-major order; (NEG_INF, −1) rows where there are fewer (NEG_INF as f32)."""
    idx = np.flatnonzero(mask)
    values = lef.ravel()[idx]
    order = np.argsort(-values.astype(np.float64), kind="stable")[:k]
    out = np.tile(np.array([NEG_INF, -1.0]), (k, 1))  # the kernel's fill: f32 −3e38
    out[:len(order), 0] = values[order]
    out[:len(order), 1] = idx[order]
    return out


def segment(acc2: np.ndarray, threshold: float, acc: np.ndarray, acc_max: np.ndarray) -> np.ndarray:
    """Eq. 24: I_rt = [I_acc2 > T_acc2] ∧ [I_acc == I_acc_max] (bool)."""
    return (acc2.astype(np.float64) > threshold) & (acc == acc_max)


def block_proposal(mask: np.ndarray, logw: np.ndarray, block_id: np.ndarray, n_blocks: int) -> dict:
    """Eqs. 29–33 for all blocks at once.

    Returns the proposal map (H, W) f32 (each non-empty block sums to 1), the kept mask,
    and per block: N_eff, the rank k, the candidate count nnz.
    """
    idx = np.flatnonzero(mask)
    b = block_id.ravel()[idx]
    lw = logw.ravel()[idx].astype(F32)
    bmax = np.full(n_blocks, -np.inf, F32)
    np.maximum.at(bmax, b, lw)
    sal = np.exp(lw - bmax[b]).astype(F32)
    s1 = np.bincount(b, sal.astype(np.float64), minlength=n_blocks)
    s2 = np.bincount(b, sal.astype(np.float64) ** 2, minlength=n_blocks)
    nnz = np.bincount(b, minlength=n_blocks)
    with np.errstate(invalid="ignore", divide="ignore"):
        neff = np.where(nnz > 0, s1 * s1 / s2, 0.0)
    k = np.minimum(np.maximum(np.floor(neff + 0.5).astype(np.int64), 1), nnz)
    order = np.lexsort((-lw, b))  # by block, then descending log Sal
    start = np.cumsum(nnz) - nnz
    kth = np.full(n_blocks, np.inf, F32)
    has = nnz > 0
    kth[has] = lw[order][start[has] + k[has] - 1]
    keep = lw >= kth[b]
    op = np.bincount(b[keep], sal[keep].astype(np.float64), minlength=n_blocks)
    proposal = np.zeros(mask.shape, F32)
    proposal.ravel()[idx[keep]] = (sal[keep].astype(np.float64) / op[b[keep]]).astype(F32)
    kept = np.zeros(mask.shape, bool)
    kept.ravel()[idx[keep]] = True
    return {"proposal": proposal, "kept": kept, "n_eff": neff, "k": k, "nnz": nnz}
