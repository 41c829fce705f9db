"""The multi-frame hand-over's likelihood sum (``tbd_taichi.methods.sgds.handover``): Eq. 15's log ratio of each
handed-over particle, taken back along its own velocity, summed over the frames before the hand-over.

The NumPy twin is ``tbd_taichi.numpy_kernels.handover`` (the same f32 ratios, summed in f64 in the same order).
"""
import taichi as ti

from .models.likelihood import PAD, PointPSFLikelihood

F32_1, F32_2 = ti.types.ndarray(dtype=ti.f32, ndim=1), ti.types.ndarray(dtype=ti.f32, ndim=2)
LIKELIHOOD = PointPSFLikelihood()


@ti.kernel
def retrodicted_log_ratio(state: F32_2, frames: F32_2, back: F32_1, slots: ti.types.ndarray(dtype=ti.i32, ndim=1),
                          constants: F32_1, h: ti.i32, out: ti.types.ndarray(dtype=ti.f64, ndim=1)):
    """out[i] = Σ_k log ω̃(z_k | x_i − back[k]·vx_i, y_i − back[k]·vy_i, I_i) (Eq. 15), summed over k in order in
    f64.  ``state``: rows x, y, vx, vy, inten (px, px/frame, σ units) of the particles; ``frames``: frames of h rows
    (and frames.shape[1] − 2·PAD columns), each with its zero border of PAD pixels, stacked one above the other;
    z_k is the one in slot ``slots[k]`` (rows from slots[k]·(h + 2·PAD)); ``constants``: Eq. 15's, as
    ``numpy_kernels.models.psf_constants`` gives them (host-computed, so both engines use the same bits).  The
    frame size is a run-time value: one compiled kernel serves every size."""
    w = frames.shape[1] - 2 * PAD
    c = (constants[0], constants[1], constants[2], constants[3])
    for i in range(state.shape[1]):
        x, y, vx, vy, inten = state[0, i], state[1, i], state[2, i], state[3, i], state[4, i]
        s = ti.f64(0.0)
        for k in range(back.shape[0]):
            s += ti.f64(LIKELIHOOD.log_ratio(x - back[k] * vx, y - back[k] * vy, inten, frames, c, h, w,
                                             slots[k] * (h + 2 * PAD)))
        out[i] = s
