"""Batched particle filter kernels (SGDS-PF section 2.1, Eqs. 7–19) over one particle pool, one concept a module.

* :mod:`.layout`: the pool's fields and tiles, the loop helpers, the shared constants;
* :mod:`.slots`: live counts, host transfers, state order, proposal maps;
* :mod:`.propagate`: existence (Eqs. 7–8), newborn draws (Eq. 34), propagation (Eqs. 9–10);
* :mod:`.weight`: log-weights (Eqs. 14–15), maxima and normalisation (Eqs. 16–17);
* :mod:`.resample`: spacings, parents (Eq. 18), gather;
* :mod:`.estimate`: the moment sums behind Eq. 19;
* :mod:`.step`: the stages composed into one launch (``step``, ``fused_step``, ``step_pair``).

:class:`ParticleKernels` combines them; the NumPy twin is ``tbd_taichi.numpy_kernels.particles``.  The motion
model and the likelihood ratio are seams (``kernels.models``): ``ParticleKernels(…, motion=…, likelihood=…)``.
SGDS-PF's particle populations (Eqs. 36–38) are not here: ``kernels.populations.SearchingKernels`` adds them.
"""
import taichi as ti

from .estimate import EstimateMixin
from .layout import (BIRTH_STREAMS, COPY_TRIES, FLOAT_STATE, INT_STATE, M_E, M_EI, M_EVX, M_EVY, M_EX, M_EXX,
                     M_EXY, M_EY, M_EYY, M_N, M_TP, M_X, M_XX, M_XY, M_Y, M_YY, N_MOMENTS, NEG_INF, NOISE_STREAMS,
                     PAD, S_BIRTH_ANGLE, S_BIRTH_I, S_BIRTH_MU, S_BIRTH_PIXEL, S_BIRTH_SPEED, S_BIRTH_X,
                     S_BIRTH_Y, S_COPY, S_EXIST, S_NOISE_I, S_NOISE_VX, S_NOISE_VY, S_NOISE_X, S_NOISE_Y,
                     S_RESAMPLE, S_RESAMPLE_END, S_SYSTEMATIC, STATE, TILE, TWO_PI, WALKS, LayoutMixin)
from .propagate import PropagateMixin
from .resample import ResampleMixin
from .slots import SlotsMixin
from .step import StepMixin
from .weight import WeightMixin
from ..models import NearlyConstantVelocity, PointPSFLikelihood


@ti.data_oriented
class ParticleKernels(LayoutMixin, SlotsMixin, PropagateMixin, WeightMixin, ResampleMixin, EstimateMixin, StepMixin):
    """Fields and kernels of one particle pool; the scheduler is ``tbd_taichi.particles.ParticlePool``.

    ``motion``: the motion model the propagation calls (default :class:`~..models.NearlyConstantVelocity`,
    Eqs. 9–10); ``likelihood``: the likelihood ratio the weights call (default
    :class:`~..models.PointPSFLikelihood`, Eq. 15).  Kernels compile for the models they were built with."""

    @staticmethod
    def frame_key(frame_shape) -> tuple:
        """What of the frame's size the fields' shapes hold: nothing here (the kernels read frame_hw), so a set of
        fields, and the kernels compiled for it, serves a pool at any frame size (``tbd_taichi.particles``' reuse
        key); a subclass with per-pixel fields names their size class."""
        return ()

    def __init__(self, capacity: int, n_groups: int, n_tiles: int, frame_shape, map_capacity: int, serial: bool,
                 flat: bool, split: int = 1, motion=None, likelihood=None):
        self.motion = NearlyConstantVelocity() if motion is None else motion
        self.likelihood = PointPSFLikelihood() if likelihood is None else likelihood
        super().__init__(capacity, n_groups, n_tiles, frame_shape, map_capacity, serial, flat, split)


__all__ = ['ParticleKernels', 'LayoutMixin', 'SlotsMixin', 'PropagateMixin', 'WeightMixin', 'ResampleMixin',
           'EstimateMixin', 'StepMixin', 'BIRTH_STREAMS', 'COPY_TRIES', 'FLOAT_STATE', 'INT_STATE', 'M_E', 'M_EI',
           'M_EVX', 'M_EVY', 'M_EX', 'M_EXX', 'M_EXY', 'M_EY', 'M_EYY', 'M_N', 'M_TP', 'M_X', 'M_XX', 'M_XY', 'M_Y',
           'M_YY', 'N_MOMENTS', 'NEG_INF', 'NOISE_STREAMS', 'PAD', 'S_BIRTH_ANGLE', 'S_BIRTH_I', 'S_BIRTH_MU',
           'S_BIRTH_PIXEL', 'S_BIRTH_SPEED', 'S_BIRTH_X', 'S_BIRTH_Y', 'S_COPY', 'S_EXIST', 'S_NOISE_I', 'S_NOISE_VX',
           'S_NOISE_VY', 'S_NOISE_X', 'S_NOISE_Y', 'S_RESAMPLE', 'S_RESAMPLE_END', 'S_SYSTEMATIC', 'STATE', 'TILE',
           'TWO_PI', 'WALKS']
