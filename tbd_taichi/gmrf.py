"""First-order noncausal Gauss–Markov random field clutter (Bruno et al. 2008, Eqs. 9, 13, 14; Moura & Balram):
V(r, j) = β_v[V(r−1, j) + V(r+1, j)] + β_h[V(r, j−1) + V(r, j+1)] + ε(r, j) with zero boundary, precision
Σ_v⁻¹ = A/σ_c², A = I ⊗ (I − β_h B_M) − β_v B_L ⊗ I (Eq. 14), diagonalised by the 2-D DST-I (notes A4)."""
from __future__ import annotations

import numpy as np
from scipy import fft


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
    return sigma_c * fft.dstn(w / np.sqrt(lam), type=1, norm="ortho", axes=(1, 2))
