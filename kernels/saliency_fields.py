"""The saliency kernels' many fields as one template argument.

A kernel taking ``f: ti.template()`` reads ``f.z``, ``f.valid`` … at compile time, so grouping changes
neither the compiled code's work nor its results, only how many arguments a launch sets.
"""


class SaliencyFields:
    """Named Taichi fields plus the constants fixed with their shapes: ``r`` (max-filter radius, px),
    ``n_chunks`` (runs of rows of the streamed filters) and ``serial`` (one-thread loops).  Kernels compile
    once per object (keyed by identity), so these must not change after the first launch.  Scalars that a
    caller sets once live in fields: ``params64`` = [snr (Eqs. 23, 26), pixel count N],
    ``params32`` = [A (Eq. 27, σ = 1), γ (multi-frame LEF decay), lef_scale]."""

    def __init__(self, r: int, n_chunks: int, serial: bool, **fields):
        self.r, self.n_chunks, self.serial = int(r), int(n_chunks), bool(serial)
        self.__dict__.update(fields)
