"""Linear motion models of the multiple-model filters (Long et al. 2012, Eq. 1; forms of Li & Jilkov 2003 and
Davey & Rutten 2007, the paper's refs. [19] and [7]) as matrices on one common 7-D state.

State order (``STATE``): x, ẋ, y, ẏ, I, ẍ, ÿ; positions in px (x = column, y = row), velocities in px/s,
accelerations in px/s², I the total (integrated) intensity.  Eq. 2's 5-D state is the first five entries; the
accelerations are used by CA only and are frozen (kept, no noise) under CV and the coordinated turns.

* ``cv``: constant velocity, per axis [[1, T], [0, 1]], Q = q_s·[[T³/3, T²/2], [T²/2, T]];
* ``ac-ct`` / ``c-ct``: coordinated turn at +ω / −ω rad/s (anticlockwise / clockwise on the screen with y = row
  pointing down, the velocity turning from +x toward +y for +ω), Q as CV;
* ``ca``: constant acceleration, per axis [[1, T, T²/2], [0, 1, T], [0, 0, 1]],
  Q = q_s·[[T⁵/20, T⁴/8, T³/6], [T⁴/8, T³/3, T²/2], [T³/6, T²/2, T]];
* every model: I ← I + N(0, q_i·T) (intensity random walk).

The kernels receive F, F⁻¹ (the backward recursion's dynamics) and the Cholesky factor of Q for each model of a
filter's model set; nothing else about a model is hard-wired in them.
"""
from __future__ import annotations

import math

import numpy as np

from .errors import ParameterError

STATE = ("x", "vx", "y", "vy", "intensity", "ax", "ay")
DIM = len(STATE)
MODELS = ("cv", "c-ct", "ac-ct", "ca")
X, VX, Y, VY, I, AX, AY = range(DIM)


def check_models(names) -> tuple[str, ...]:
    """``names`` (a comma list or a sequence) as a tuple of known model names, or a ParameterError."""
    items = [n.strip().lower() for n in (names.split(",") if isinstance(names, str) else names)]
    if not items or any(n not in MODELS for n in items) or len(set(items)) != len(items):
        raise ParameterError(f"models = {names!r} must be distinct names of {', '.join(MODELS)}, comma separated")
    return tuple(items)


def turn_block(omega: float, T: float) -> np.ndarray:
    """The coordinated-turn transition of [x, ẋ, y, ẏ] at rate ω rad/s over T s (Li & Jilkov 2003, Eq. 4.4);
    the velocity rotates by ωT, the position follows the arc."""
    if omega == 0:
        raise ParameterError("omega must be non-zero for a coordinated-turn model (omega = 0 is CV)")
    s, c = math.sin(omega * T), math.cos(omega * T)
    return np.array([[1.0, s / omega, 0.0, -(1.0 - c) / omega],
                     [0.0, c, 0.0, -s],
                     [0.0, (1.0 - c) / omega, 1.0, s / omega],
                     [0.0, s, 0.0, c]])


def transition(model: str, T: float, omega: float) -> np.ndarray:
    """F^(r) of Eq. 1 on the 7-D state for ``model`` over T s (turn rate ω rad/s for the CT models)."""
    F = np.eye(DIM)
    pv = [X, VX, Y, VY]
    if model in ("cv", "ca"):
        F[X, VX] = F[Y, VY] = T
        if model == "ca":
            F[X, AX] = F[Y, AY] = 0.5 * T * T
            F[VX, AX] = F[VY, AY] = T
    elif model in ("ac-ct", "c-ct"):
        F[np.ix_(pv, pv)] = turn_block(omega if model == "ac-ct" else -omega, T)
    else:
        check_models([model])
    return F


def process_noise(model: str, T: float, q_s: float, q_i: float) -> np.ndarray:
    """Q^r of Eq. 1 on the 7-D state: the white-noise-acceleration (CV, CT) or white-noise-jerk (CA) blocks per
    axis with power spectral density q_s, and q_i·T on the intensity."""
    Q = np.zeros((DIM, DIM))
    if model == "ca":
        block = q_s * np.array([[T ** 5 / 20, T ** 4 / 8, T ** 3 / 6], [T ** 4 / 8, T ** 3 / 3, T ** 2 / 2],
                                [T ** 3 / 6, T ** 2 / 2, T]])
        axes = ([X, VX, AX], [Y, VY, AY])
    else:
        block = q_s * np.array([[T ** 3 / 3, T ** 2 / 2], [T ** 2 / 2, T]])
        axes = ([X, VX], [Y, VY])
    for idx in axes:
        Q[np.ix_(idx, idx)] = block
    Q[I, I] = q_i * T
    return Q


def noise_factor(Q: np.ndarray) -> np.ndarray:
    """A lower-triangular L with L·Lᵀ = Q for a positive semi-definite Q whose zero rows are whole (frozen
    components): the Cholesky factor of the non-zero part, zeros elsewhere."""
    live = np.flatnonzero(np.abs(Q).sum(axis=1) > 0)
    L = np.zeros_like(Q)
    if live.size:
        L[np.ix_(live, live)] = np.linalg.cholesky(Q[np.ix_(live, live)])
    return L


def model_set(names, T: float, omega: float, q_s: float, q_i: float) -> dict[str, np.ndarray]:
    """The matrices of a filter's model set, stacked in ``names`` order: F, F⁻¹ (backward dynamics, F(−T)) and
    the noise factor L of Q, each (n_models, 7, 7) float64."""
    names = check_models(names)
    F = np.stack([transition(m, T, omega) for m in names])
    L = np.stack([noise_factor(process_noise(m, T, q_s, q_i)) for m in names])
    return {"F": F, "F_inv": np.linalg.inv(F), "L": L}
