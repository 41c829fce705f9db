"""SGDS-PF's particle populations (Algorithm 2): the resizing of a handed-over population to a tracking PF.  The
populations are numbered, with Eq. 37's quotas, at the end of the searching PFs' step
(``kernels/population_numbers.py``; NumPy twin and host reference ``numpy_kernels.populations``)."""
from __future__ import annotations

import numpy as np


def resize_population(n: int, size: int, u: np.ndarray) -> np.ndarray:
    """Indices that bring a PP of n particles to ``size`` (Algorithm 2's "random eliminating or
    copying"): a random subset without replacement if n ≥ size, else all plus random copies.
    ``u`` holds at least max(n, size) uniforms."""
    if n >= size:  # the size smallest u (distinct: 53-bit uniforms), in index order
        return np.sort(np.argpartition(u[:n], size - 1)[:size]) if size else np.zeros(0, np.int64)
    return np.concatenate([np.arange(n), np.floor(u[:size - n] * n).astype(np.int64)])
