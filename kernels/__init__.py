"""Taichi kernels of tbd-taichi, installed as ``tbd_taichi.kernels``.

Each module here has a NumPy twin of the same name in ``tbd_taichi.numpy_kernels``
that honours the same contract; the tests compare the two.  Kernels compute one
data-parallel step over fields or ndarrays; the Python scheduler owns the bookkeeping.
Call :func:`tbd_taichi.init` (or let the public API do it) before launching a kernel.
"""
