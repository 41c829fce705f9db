"""Loop layout and size classes shared by the kernel modules."""
import numpy as np
import taichi as ti
from taichi.lang import impl

THREAD_SPAN = 512  # Taichi's CPU range-for gives each thread a run of at least this many iterations
LIGHT_IR = "tbd_light_ir"  # the mark of :func:`light_ir` on Taichi's ``Kernel`` object


def thread_span(serial: bool) -> int:
    """Iterations per unit of work in a loop meant to split a few units over the CPU threads (compile time):
    THREAD_SPAN on a CPU runtime, so that each unit starts a thread's run (a loop over a few dozen units
    would otherwise run on one thread), and 1 for serial loops and GPUs (one thread per unit)."""
    return 1 if serial or impl.current_cfg().arch not in (ti.x64, ti.arm64) else THREAD_SPAN


def light_ir(kernel):
    """Mark a ``@ti.kernel`` (put this decorator above it) to be compiled without Taichi's advanced IR passes
    (``advanced_optimization=False`` for its compilation only; ``tbd_taichi.light_ir`` applies the mark).
    For the large kernels whose fields are sized by the frame, so that they compile again at each new frame size:
    there those passes took 70–85 % of the build, and the kernels ran as fast without them
    (docs/performance-history.md, "A new frame size").  LLVM's own optimisation still runs; fast_math stays off,
    so the bits are the same."""
    setattr(kernel._primal, LIGHT_IR, True)
    return kernel


def size_class(n: int) -> int:
    """The size class of an extent of n ≥ 0 entries (rows, lane vectors, blocks, pixels): the smallest power of
    two ≥ max(n, 2).  Fields allocated at the class, with the true extent read at run time, keep their shapes, and
    with them the compiled kernels (Taichi's offline cache is keyed on the fields' shapes), for every extent of
    the class."""
    return 1 << max(int(n) - 1, 1).bit_length()


COLUMN_CLASS = 64  # px: frame_class rounds the width up to a multiple of this (8 of the saliency kernels' lanes)
FRAME_CLASS_FLOOR = (256, 320)  # (rows, columns): the smallest class, a common thermal sensor's frame (and warmup's)
BLOCK_CLASS_FLOOR = 8  # search blocks: every frame of up to 8 (1024 × 512 at 256-px blocks) shares a block class


def block_class(n_blocks: int) -> int:
    """The size class of SGDS-PF's ``n_blocks`` search blocks: a power of two, at least BLOCK_CLASS_FLOOR.  The
    searching pool holds this many searching PFs (the groups past the blocks stay empty) and the saliency stage's
    block fields this many entries, so frames of other block counts of the class share their fields and compiled
    kernels.  Each spare group holds N_sump slots of memory; an empty group costs next to nothing per step
    (docs/performance.md, "A new frame size")."""
    return max(size_class(n_blocks), BLOCK_CLASS_FLOOR)


def frame_class(frame_shape) -> tuple[int, int]:
    """(rows, columns) of the size class of frames of ``frame_shape`` (H, W): H rounded up by :func:`size_class`
    and W up to a multiple of COLUMN_CLASS, each at least FRAME_CLASS_FLOOR's, so that every frame up to
    256 × 320 shares one class; SGDS-PF's saliency fields, top-hat + PF's images and (as a pixel count) MM-PHD's
    per-pixel fields take these extents.  Rows past H cost only memory (no loop reaches them), but the columns
    set the row stride: rounded up to a power of two (512 px for 320) they made the saliency kernels 10–15 %
    slower."""
    rows, columns = FRAME_CLASS_FLOOR
    return (max(size_class(int(frame_shape[0])), rows),
            max(COLUMN_CLASS * -(-int(frame_shape[1]) // COLUMN_CLASS), columns))


def in_corner(array: np.ndarray, shape) -> np.ndarray:
    """``array`` itself (contiguous) if it has ``shape``, else ``array`` in the leading corner of zeros of ``shape``:
    a frame, or a table that follows it, in a field of its size class."""
    array = np.asarray(array)
    if array.shape == tuple(shape):
        return np.ascontiguousarray(array)
    out = np.zeros(shape, array.dtype)
    out[tuple(slice(0, n) for n in array.shape)] = array
    return out


class FrameSize:
    """Mixin of the kernel classes whose frame-sized fields take the extents of the frame's size class: the frame's
    (H, W), px, in the field ``frame_hw``, which their kernels read at run time."""

    def frame_size_field(self, shape) -> tuple[int, int]:
        """Make ``frame_hw`` for frames of ``shape``; returns their size class (rows, columns)."""
        self.frame_hw = ti.field(ti.i32, 2)
        self.frame_extents = frame_class(shape)
        self._store_frame_size(shape)
        return self.frame_extents

    def set_frame_size(self, shape) -> None:
        """The frames are now of ``shape``, of the fields' size class (fields reused by another tracker; a class
        may extend this to clear what a larger frame of the class left)."""
        if frame_class(shape) != self.frame_extents:
            raise ValueError(f"frames of {tuple(shape)} are not of the fields' size class {self.frame_extents}")
        self._store_frame_size(shape)

    def _store_frame_size(self, shape) -> None:
        self.shape = (int(shape[0]), int(shape[1]))
        self.frame_hw.from_numpy(np.array(self.shape, np.int32))
