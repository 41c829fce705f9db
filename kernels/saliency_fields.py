"""The saliency kernels' many fields as one template argument.

A kernel taking ``f: ti.template()`` reads ``f.z``, ``f.valid`` … at compile time, so grouping changes
neither the compiled code's work nor its results, only how many arguments a launch sets.
"""
import numpy as np


class SaliencyFields:
    """Named Taichi fields plus the constants fixed with their shapes: ``r`` (max-filter radius, px) and
    ``serial`` (one-thread loops).  Kernels compile once per object (keyed by identity), so these must not
    change after the first launch.  Scalars that a
    caller sets once live in fields: ``params64`` = [snr (Eqs. 23, 26), pixel count N],
    ``params32`` = [A (Eq. 27, σ = 1), γ (multi-frame LEF decay), lef_scale]; ``dims`` (``D_*``) = the frame's
    rows H, 8-lane vectors per row V, width W (px), blocks and runs of rows of the streamed filters, which the
    kernels read at run time: the fields are allocated at the extents of the frame's size class
    (``loops.frame_class``), so one compiled set serves a class."""

    def __init__(self, r: int, serial: bool, **fields):
        self.r, self.serial = int(r), bool(serial)
        self.__dict__.update(fields)


D_ROWS, D_LANES, D_WIDTH, D_BLOCKS, D_CHUNKS = range(5)  # the columns of ``dims``

# the ring slots a launch works on, one i32 array (``ring_slots``): the frame's slot, the three slots whose images
# are summed (−1: none), the destination slot of a sum, the multi-frame LEF's source and destination memory slots
R_FRAME, R_SUM_A, R_SUM_B, R_SUM_C, R_DST, R_MEMORY_SRC, R_MEMORY = range(7)


def ring_slots(frame: int = 0, sums=(-1, -1, -1), dst: int = 0, memory=(0, 0)):
    """The ``R_*`` slots of a launch as the kernels read them (int32 array)."""
    return np.array([frame, *sums, dst, *memory], np.int32)
