"""Candidate preprocessing of Güler (2016, §3.4.1.1–3.4.1.2) as one Taichi kernel: row-mean removal
(Eqs. 3.4–3.5) and the opening top-hat with a flat structuring element (Eqs. 3.6–3.8, 3.10).

* U = u − ū_row: each pixel minus its row's mean (intensity units, the input's; the mean summed in f64);
* the opening U ∘ B = (U ⊖ B) ⊕ B with a flat SE (b ≡ 0) that is OpenCV's square or ellipse mask
  (:func:`structuring_element`); out-of-image pixels are ignored (OpenCV's default morphology border:
  +∞ for erosion, −∞ for dilation), so a peak on the border is kept whole;
* out = U − U ∘ B (Eq. 3.10), in the same units.

Both SE shapes are symmetric and every row of their mask is a centred contiguous run of half-width h_dy
(checked by :func:`row_half_widths`), so a flat dilation is separable: a row pass keeps, for every
half-width 0..R (R = size // 2), the running max over |dx| ≤ h (one level per half-width, built
incrementally), and a column pass takes the max over the in-image row offsets dy of level h_dy.  Erosion
is −dilate(−·) (negation is exact).  The loops over the SE are dynamic: any odd size works.

The NumPy twin is ``tbd_taichi.numpy_kernels.tophat``."""
import numpy as np
import taichi as ti

from ..errors import ParameterError
from .loops import FrameSize

SHAPES = ("square", "disk")


def structuring_element(size: int, shape: str) -> np.ndarray:
    """The flat SE's (size, size) uint8 mask: all ones for "square" (``cv2.MORPH_RECT``), OpenCV's
    ``MORPH_ELLIPSE`` for "disk": with r = c = size // 2, row i keeps |j − c| ≤ round(c·√(1 − (i − r)²/r²))
    (round half to even, as OpenCV's cvRound), the same mask as ``cv2.getStructuringElement``."""
    if shape not in SHAPES:
        raise ParameterError(f"se_shape must be one of {', '.join(SHAPES)}, got {shape!r}")
    size = int(size)
    if size < 1 or size % 2 == 0:
        raise ParameterError(f"se_size must be an odd integer >= 1, got {size}")
    if shape == "square":
        return np.ones((size, size), np.uint8)
    r = c = size // 2
    dy = np.arange(size) - r
    half = np.rint(c * np.sqrt((r * r - dy * dy) / float(max(r * r, 1))))
    return (np.abs(np.arange(size)[None, :] - c) <= half[:, None]).astype(np.uint8)


def row_half_widths(mask: np.ndarray) -> np.ndarray:
    """int32 half-width of each row of a square odd ``mask`` (−1 for an empty row), after checking that each
    row is a run centred on the middle column (what the separable passes need); ParameterError if not."""
    size = mask.shape[0]
    c = size // 2
    half = np.asarray(mask, bool).sum(axis=1) // 2 - (~np.asarray(mask, bool).any(axis=1))
    for i, h in enumerate(half):
        expected = np.abs(np.arange(size) - c) <= h
        if not np.array_equal(np.asarray(mask[i], bool), expected):
            raise ParameterError(f"structuring element row {i} is not a centred contiguous run")
    return half.astype(np.int32)


def se_geometry(se_size: int, se_shape: str) -> tuple[np.ndarray, int, np.ndarray]:
    """The flat SE's mask, its radius R = size // 2 and each row's half-width (what the separable passes of the
    kernel and of its NumPy twin run on)."""
    mask = structuring_element(int(se_size), str(se_shape))
    return mask, int(se_size) // 2, row_half_widths(mask)


@ti.data_oriented
class TophatKernels(FrameSize):
    """Fields for frames of ``shape`` (H, W) and a flat SE of odd ``se_size`` and ``se_shape`` ("square"/"disk").
    The images take the extents of the frame's size class (``loops.frame_class``) and the kernels read (H, W) from
    ``frame_hw``, so frames of one class share the compiled kernels."""

    def __init__(self, shape, se_size: int, se_shape: str):
        self.se_size, self.se_shape = int(se_size), str(se_shape)
        self.mask, self.radius, half = se_geometry(se_size, se_shape)
        h, w = self.frame_size_field(shape)
        self.u = ti.field(ti.f32, (h, w))  # U, Eq. 3.5
        self.eroded = ti.field(ti.f32, (h, w))  # −(U ⊖ B)
        self.opened = ti.field(ti.f32, (h, w))  # U ∘ B, Eq. 3.8
        self.levels = ti.field(ti.f32, (self.radius + 1, h, w))  # row maxima over |dx| ≤ level
        self.half = ti.field(ti.i32, self.se_size)  # the SE's half-width at row offset dy + R
        self.half.from_numpy(half)

    @ti.kernel
    def tophat(self, frame: ti.types.ndarray(dtype=ti.f32, ndim=2), out: ti.types.ndarray(dtype=ti.f32, ndim=2)):
        """out = U − (U ⊖ B) ⊕ B (Eq. 3.10) with U = frame minus its row means (Eqs. 3.4–3.5); same units as
        ``frame``, both (H, W) f32."""
        self.remove_row_means(frame)
        self.row_levels(self.u, -1.0)
        self.column_max(self.eroded)  # −erosion (Eq. 3.7): the dilation of −U
        self.row_levels(self.eroded, -1.0)
        self.column_max(self.opened)  # dilation of the erosion (Eqs. 3.6, 3.8)
        h, w = self.frame_hw[0], self.frame_hw[1]
        for r, c in ti.ndrange(h, w):
            out[r, c] = self.u[r, c] - self.opened[r, c]

    @ti.func
    def remove_row_means(self, frame: ti.template()):
        """u[r, c] = frame[r, c] − ū_r (Eqs. 3.4–3.5), ū_r summed in f64 and rounded to f32; one thread per row."""
        h, w = self.frame_hw[0], self.frame_hw[1]
        for r in range(h):
            acc = ti.f64(0.0)
            for c in range(w):
                acc += ti.cast(frame[r, c], ti.f64)
            mean = ti.cast(acc / w, ti.f32)
            for c in range(w):
                self.u[r, c] = frame[r, c] - mean

    @ti.func
    def row_levels(self, src: ti.template(), sign: ti.f32):
        """levels[k, r, c] = max over in-image |dx| ≤ k of sign·src[r, c + dx], for k = 0..R (cumulative)."""
        h, w = self.frame_hw[0], self.frame_hw[1]
        for r, c in ti.ndrange(h, w):
            m = sign * src[r, c]
            self.levels[0, r, c] = m
            for k in range(1, self.radius + 1):
                if c - k >= 0:
                    m = ti.max(m, sign * src[r, c - k])
                if c + k < w:
                    m = ti.max(m, sign * src[r, c + k])
                self.levels[k, r, c] = m

    @ti.func
    def column_max(self, dst: ti.template()):
        """dst[r, c] = max over in-image row offsets dy (non-empty SE rows) of levels[half[dy], r + dy, c]: the
        flat dilation by B of the image whose row levels were built (the row dy = 0 is never empty)."""
        h, w = self.frame_hw[0], self.frame_hw[1]
        for r, c in ti.ndrange(h, w):
            m = self.levels[self.half[self.radius], r, c]
            for i in range(self.se_size):
                rr, k = r + i - self.radius, self.half[i]
                if 0 <= rr < h and k >= 0:
                    m = ti.max(m, self.levels[k, rr, c])
            dst[r, c] = m
