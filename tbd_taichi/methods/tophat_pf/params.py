"""Güler's (2016) parameters for ``tophat-pf``, declared once, with the values the thesis leaves open, and the
window schedule of Alg. 5 (Table 4.5)."""
from __future__ import annotations

from dataclasses import dataclass

from ...errors import ParameterError
from ..registry import param, validate_params

FIRST_FRAMES = 3  # frames 0–2 give the candidates (Eq. 3.12, m = 3); the filters start at frame 3


@dataclass(frozen=True)
class TophatPFParams:
    """The candidate stage (Eqs. 3.4–3.13), the SIR filters (Eqs. 3.2, 3.14, 3.16, Algs. 2, 6) and Alg. 5's
    windows."""

    se_size: int = param(5, doc="top-hat structuring element side (odd)", unit="px",
                         source="Eqs. 3.6–3.10 (not in the thesis)", low=3, high=255, integer=True)
    se_shape: str = param("square", doc="flat structuring element: square or disk (OpenCV's ellipse)",
                          source="Eqs. 3.6–3.10 (not in the thesis)", choices=("square", "disk"))
    alpha: float = param(3.0, doc="candidate threshold T = μ + α·σ of the projection", symbol="α",
                         source="Eq. 3.13, Table 4.4", low=0, low_closed=False, high=100)
    max_candidates: int = param(64, doc="candidates kept (the strongest), one per 8-connected component",
                                source="not in the thesis", low=1, high=1024, integer=True)
    n_particles: int = param(5000, doc="particles per candidate", symbol="N", unit="particles", source="§4",
                             low=1, high=1_000_000, integer=True)
    c: float = param(0.5, doc="process noise coefficient: x_k = x_{k−1} + B + C·n, n ~ N(0, I₂)", symbol="C",
                     unit="px", source="Eq. 3.2, §4", low=0, low_closed=False, high=100)
    sigma_v: float = param(0.5, doc="motion likelihood width (Eq. 3.16)", symbol="σ_v", unit="px",
                           source="Eq. 3.16 (not in the thesis)", low=0, low_closed=False, high=100)
    s_drift: int = param(80, doc="the drift B is the mean of the estimate's last S displacements",
                         symbol="S", unit="frames", source="Alg. 6, Table 4.10", low=1, high=1000, integer=True)
    sigma_0: float = param(1.0, doc="initial spread of the particles around the candidate", symbol="σ₀",
                           unit="px", source="not in the thesis", low=0, high=100)
    windows: str = param("7,9,9", doc="Alg. 5's window lengths from frame 3 (odd, ≥ 3); the last repeats while "
                         "more than 2 candidates remain", unit="frames", source="Table 4.5")
    merge_distance: float = param(1.5, doc="filters closer than this through a whole window merge (the lower "
                                  "cost stays)", unit="px", source="not in the thesis", low=0, high=100)
    epsilon: float = param(0.01, doc="added to Alg. 5's denominator (a still candidate's 0/0)", symbol="ε",
                           unit="px", source="Alg. 5 (not in the thesis)", low=0, low_closed=False, high=100)
    drift: bool = param(True, doc="learn the drift B from the path (Alg. 6), from the end of window 1",
                        symbol="B", source="Alg. 6")
    weighting: str = param("combined", doc="combined (Eq. 3.14 × Eq. 3.16, once B is learnt) or standard "
                           "(Eq. 3.14 alone)", source="§3.4.2, Alg. 7", choices=("combined", "standard"))


def window_lengths(text: str) -> tuple[int, ...]:
    """``windows`` ("7,9,9") as lengths, or a ParameterError naming the rule."""
    try:
        lengths = tuple(int(v) for v in str(text).split(","))
    except ValueError:
        lengths = ()
    if not lengths or any(n < 3 or n % 2 == 0 for n in lengths):
        raise ParameterError(f"tophat-pf parameter windows = {text!r} must be comma-separated odd window lengths "
                             "≥ 3 (frames), e.g. 7,9,9")
    return lengths


def window_of(lengths: tuple[int, ...], index: int, first: int) -> tuple[int, int]:
    """(first, last) frame of window ``index`` (0-based) starting at frame ``first``: its length is the given one,
    or the last given one past the list."""
    return first, first + lengths[min(index, len(lengths) - 1)] - 1


def tophat_pf_params(shape, **overrides) -> TophatPFParams:
    """The parameters with ``overrides``, validated (the structuring element against the frame ``shape``)."""
    from ...tophat import check_structuring_element

    p = validate_params(TophatPFParams(**overrides), "tophat-pf")
    window_lengths(p.windows)
    check_structuring_element(p.se_size, p.se_shape, shape)
    return p
