"""SGDS-PF's particle populations (Eqs. 36–37, Algorithm 2): numbering the (block, Seq) populations of the
searching PFs and Eq. 37's elimination quotas on the host (the device numbers them at the end of the step,
``kernels/population_numbers.py``; these are its NumPy twin, ``numpy_kernels.populations``), and the resizing of a
handed-over population to a tracking PF."""
from __future__ import annotations

import numpy as np

from ...numpy_kernels.populations import eliminated_per_population, slab_populations  # noqa: F401 (this module's API)


def resize_population(n: int, size: int, u: np.ndarray) -> np.ndarray:
    """Indices that bring a PP of n particles to ``size`` (Algorithm 2's "random eliminating or
    copying"): a random subset without replacement if n ≥ size, else all plus random copies.
    ``u`` holds at least max(n, size) uniforms."""
    if n >= size:  # the size smallest u (distinct: 53-bit uniforms), in index order
        return np.sort(np.argpartition(u[:n], size - 1)[:size]) if size else np.zeros(0, np.int64)
    return np.concatenate([np.arange(n), np.floor(u[:size - n] * n).astype(np.int64)])


def populations(group: np.ndarray, seq: np.ndarray, table_limit: int = 1 << 22):
    """Particle populations as (block, Seq) pairs, ordered by block then Seq.

    ``group``: each particle's block, non-decreasing (state order); ``seq``: its Seq.
    Returns (block of each PP, PP index of each particle, particles per PP); see :func:`slab_populations`."""
    group = np.asarray(group, np.int64)
    return slab_populations(np.bincount(group) if len(group) else np.zeros(0, np.int64), seq, table_limit)
