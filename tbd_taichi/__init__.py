"""tbd-taichi: track-before-detect particle filters for dim infrared point targets.

Quick start::

    import tbd_taichi as tbd
    tbd.init("cpu")                                   # or "cuda", "vulkan", "metal", "gpu", "auto"
    scene = tbd.simulate((200, 200), frames=150, snr=2.0, seed=1)
    tracker = tbd.make_tracker("sgds", (200, 200), seed=0)  # tbd.methods.names() lists the methods
    frames = tbd.io.read_frames("clip.mp4")           # float32 (T, H, W)
    scores = tbd.metrics.evaluate(tracks, scene.truth)

Coordinates: x = column, y = row, 0-based, pixel centres at integers; frames are
0-based indices into the input.
"""
from ._source_tree import mount_kernels

mount_kernels()  # a source checkout's kernels/ as tbd_taichi.kernels (installed packages have their own)

from . import io, methods, metrics, normalize, tables  # noqa: E402
from .backend import available_archs, init, keep_freed_memory  # noqa: E402
from .errors import BackendError, InputError, ParameterError, TBDError  # noqa: E402
from .methods import make_tracker, track  # noqa: E402
from .methods.pf import OriginalPF  # noqa: E402
from .methods.sgds import PAPER_SALIENCY, SGDSPF, SGDSParams  # noqa: E402
from .normalize import normalise_frame  # noqa: E402
from .simulate import Scenario, simulate  # noqa: E402

__version__ = "0.1.0"

__all__ = [
    "BackendError", "InputError", "OriginalPF", "PAPER_SALIENCY", "ParameterError", "SGDSPF", "SGDSParams", "Scenario", "TBDError",
    "available_archs", "init", "keep_freed_memory", "make_tracker", "track",
    "io", "methods", "metrics", "normalise_frame", "normalize", "simulate", "tables", "__version__",
]
