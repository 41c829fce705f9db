"""NumPy twin of ``tbd_taichi.kernels.tophat``: the same constructor and ``tophat(frame, out)`` contract
(row-mean removal, Eqs. 3.4–3.5, then the opening top-hat with a flat SE, Eqs. 3.6–3.8, 3.10; out-of-image
pixels ignored), vectorised over pixels with the same separable row levels and column max."""
from __future__ import annotations

import numpy as np

from ..kernels.tophat import SHAPES, se_geometry, structuring_element

__all__ = ["SHAPES", "TophatKernels", "structuring_element"]

F32 = np.float32


class TophatKernels:
    """The kernel's state as arrays, for frames of ``shape`` (H, W) and an odd ``se_size``, ``se_shape`` SE."""

    def __init__(self, shape, se_size: int, se_shape: str):
        self.shape = (int(shape[0]), int(shape[1]))
        self.se_size, self.se_shape = int(se_size), str(se_shape)
        self.mask, self.radius, self.half = se_geometry(se_size, se_shape)

    def tophat(self, frame: np.ndarray, out: np.ndarray) -> None:
        """out = U − (U ⊖ B) ⊕ B (Eq. 3.10), U = frame minus its row means (Eqs. 3.4–3.5), f32 (H, W)."""
        frame = np.asarray(frame, F32)
        u = frame - frame.mean(axis=1, dtype=np.float64).astype(F32)[:, None]
        eroded = -self._dilate(-u)  # Eq. 3.7
        out[...] = u - self._dilate(eroded)  # Eqs. 3.6, 3.8, 3.10

    def _dilate(self, image: np.ndarray) -> np.ndarray:
        """Flat dilation by the SE with out-of-image pixels ignored: row levels, then the column max."""
        return self._column_max(self._row_levels(image))

    def _row_levels(self, image: np.ndarray) -> np.ndarray:
        """(R + 1, H, W): level k is the max over in-image |dx| ≤ k of each row (built cumulatively)."""
        h, w = image.shape
        r = self.radius
        padded = np.full((h, w + 2 * r), -np.inf, F32)
        padded[:, r:r + w] = image
        levels = np.empty((r + 1, h, w), F32)
        levels[0] = image
        for k in range(1, r + 1):
            levels[k] = np.maximum(levels[k - 1], np.maximum(padded[:, r - k:r - k + w], padded[:, r + k:r + k + w]))
        return levels

    def _column_max(self, levels: np.ndarray) -> np.ndarray:
        """(H, W): the max over row offsets dy of level half[dy] shifted by dy (out-of-image rows ignored)."""
        _, h, w = levels.shape
        r = self.radius
        padded = np.full((levels.shape[0], h + 2 * r, w), -np.inf, F32)
        padded[:, r:r + h] = levels
        out = levels[self.half[r]].copy()
        for i, k in enumerate(self.half):
            if k >= 0:
                np.maximum(out, padded[k, i:i + h], out=out)
        return out
