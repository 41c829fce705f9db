"""Models the particle kernels call through a seam: the motion model (``ParticleKernels.motion``, Eqs. 9–10)
and the likelihood ratio (``ParticleKernels.likelihood``, Eqs. 14–15).

A model is a small ``ti.data_oriented`` object whose ``ti.func`` methods work on one particle's values, so a
method can hand the pool another one without touching the pool's loops, tiles or random streams.  The NumPy
twins are in ``tbd_taichi.numpy_kernels.models``.
"""
from .likelihood import PointPSFLikelihood
from .motion import NearlyConstantVelocity

__all__ = ["NearlyConstantVelocity", "PointPSFLikelihood"]
