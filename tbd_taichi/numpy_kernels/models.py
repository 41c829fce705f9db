"""NumPy twins of ``tbd_taichi.kernels.models``: the motion model and the likelihood ratio, vectorised over
particles, with the same f32 operations in the same order (so the same bits as the kernels).

* :func:`ncv_noise_factors`, :func:`ncv_step`: nearly constant velocity, Eqs. 9–10 with Q of Eq. 46 (T = 1);
* :func:`psf_constants`, :func:`psf_samples`, :func:`point_psf_log_ratio`: Eq. 15's log-likelihood ratio of
  a point target under the Gaussian PSF of Eq. 14.
"""
from __future__ import annotations

import math

import numpy as np

F32 = np.float32
TWO_PI = 2.0 * math.pi


def ncv_noise_factors(q1, q2) -> tuple:
    """Twin of ``NearlyConstantVelocity.noise_factors``: c11, c21, c22 of Eq. 46's Cholesky factor per axis and
    √q2 (f32; q1 in px²/frame³, q2 in intensity² per frame)."""
    q1, q2 = F32(q1), F32(q2)
    return np.sqrt(q1 / F32(3.0)), np.sqrt(q1) * F32(0.8660254037844386), np.sqrt(q1) * F32(0.5), np.sqrt(q2)


def ncv_step(x, vx, y, vy, inten, n, factors, i_floor) -> tuple:
    """Twin of ``NearlyConstantVelocity.step`` for arrays of particles: Eqs. 9–10 with the normals
    n = (n1, …, n5) and ``factors`` of :func:`ncv_noise_factors`; returns (x, vx, y, vy, inten)."""
    c11, c21, c22, sq2 = factors
    n1, n2, n3, n4, n5 = n
    return x + vx + c11 * n1, vx + (c21 * n1 + c22 * n2), y + vy + c11 * n3, vy + (c21 * n3 + c22 * n4), \
        np.maximum(inten + sq2 * n5, F32(i_floor))


def psf_samples(d0: np.ndarray, inv2s2, step, pixels: np.ndarray, size: int) -> np.ndarray:
    """Twin of ``PointPSFLikelihood.samples``: (n, 5) Gaussian samples (Eq. 14) by the same ratio recurrence,
    0 where ``pixels`` lie outside [0, size)."""
    g = np.empty((len(d0), 5), F32)
    gk = np.exp(-d0 * d0 * inv2s2)
    r = np.exp(-(F32(2.0) * d0 + F32(1.0)) * inv2s2)
    for k in range(5):
        g[:, k] = gk
        gk = gk * r
        r = r * step
    return np.where((pixels >= 0) & (pixels < size), g, F32(0))


def psf_constants(psf_sigma, noise_sigma) -> tuple:
    """Twin of ``PointPSFLikelihood.constants``: 1/(2Σ²), 1/(2πΣ²), 1/σ², exp(−2/(2Σ²)) in f32 (Σ in px)."""
    sig = F32(psf_sigma)
    inv2s2 = F32(1.0) / (F32(2.0) * sig * sig)
    norm = F32(1.0) / (F32(TWO_PI) * sig * sig)
    inv_var = F32(1.0) / (F32(noise_sigma) * F32(noise_sigma))
    return inv2s2, norm, inv_var, np.exp(F32(-2.0) * inv2s2)


def point_psf_log_ratio(x: np.ndarray, y: np.ndarray, inten: np.ndarray, z: np.ndarray, constants,
                        frame: np.ndarray | None = None) -> np.ndarray:
    """Twin of ``PointPSFLikelihood.log_ratio`` for E = 1 particles at (x, y) px with intensities ``inten`` on
    the normalised frame z (H, W, no border): Eq. 15 over the in-image pixels of each 5×5 window.  With a stack
    of frames z (K, H, W), ``frame`` gives each particle's frame (index into the stack)."""
    inv2s2, norm, inv_var, step = constants
    h, w = z.shape[-2:]
    cx = np.floor(x + F32(0.5)).astype(np.int64)
    cy = np.floor(y + F32(0.5)).astype(np.int64)
    k = np.arange(-2, 3)
    px, py = cx[:, None] + k, cy[:, None] + k
    gx = psf_samples((cx - 2).astype(F32) - x, inv2s2, step, px, w)
    gy = psf_samples((cy - 2).astype(F32) - y, inv2s2, step, py, h)
    rows, cols = np.clip(py, 0, h - 1)[:, :, None], np.clip(px, 0, w - 1)[:, None, :]
    zwin = z[rows, cols] if frame is None else z[np.asarray(frame)[:, None, None], rows, cols]
    use = (gy[:, :, None] > 0) & (gx[:, None, :] > 0)
    sz = np.zeros(len(x), F32)
    for j in range(5):
        row = np.zeros(len(x), F32)
        for kk in range(5):
            row = row + np.where(use[:, j, kk], gx[:, kk] * zwin[:, j, kk], F32(0))
        sz = sz + gy[:, j] * row
    a = inten * norm
    sgx = ((((gx[:, 0] * gx[:, 0] + gx[:, 1] * gx[:, 1]) + gx[:, 2] * gx[:, 2]) + gx[:, 3] * gx[:, 3])
           + gx[:, 4] * gx[:, 4])
    sgy = ((((gy[:, 0] * gy[:, 0] + gy[:, 1] * gy[:, 1]) + gy[:, 2] * gy[:, 2]) + gy[:, 3] * gy[:, 3])
           + gy[:, 4] * gy[:, 4])
    return (a * sz - F32(0.5) * a * a * sgx * sgy) * inv_var
