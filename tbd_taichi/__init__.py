"""tbd-taichi: track-before-detect particle filters for dim infrared point targets.

Quick start::

    import tbd_taichi as tbd
    tbd.init("cpu")                                   # or "cuda", "vulkan", "metal", "gpu", "auto"
    scene = tbd.simulate((200, 200), frames=150, snr=2.0, seed=1)
    frames = tbd.io.read_frames("clip.mp4")           # float32 (T, H, W)
    scores = tbd.metrics.evaluate(tracks, scene.truth)

Coordinates: x = column, y = row, 0-based, pixel centres at integers; frames are
0-based indices into the input.
"""
from . import io, metrics, normalize, tables
from .backend import available_archs, init, keep_freed_memory
from .errors import BackendError, InputError, ParameterError, TBDError
from .normalize import normalise_frame
from .params import PAPER_SALIENCY, SGDSParams
from .pf import OriginalPF
from .sgds import SGDSPF, track
from .simulate import Scenario, simulate

__version__ = "0.1.0"

__all__ = [
    "BackendError", "InputError", "OriginalPF", "PAPER_SALIENCY", "ParameterError", "SGDSPF", "SGDSParams", "Scenario", "TBDError",
    "available_archs", "init", "keep_freed_memory", "track",
    "io", "metrics", "normalise_frame", "normalize", "simulate", "tables", "__version__",
]
