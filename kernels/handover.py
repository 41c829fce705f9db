"""The multi-frame hand-over's draw (``tbd_taichi.methods.sgds.handover``): Eq. 15's log ratio of each handed-over
particle, taken back along its own velocity and summed over the frames before the hand-over, then each
population's N_tpf particles drawn ∝ exp(sum) by systematic resampling, all populations of a frame in one launch.

The NumPy twin is ``tbd_taichi.numpy_kernels.handover`` (the same f32 ratios, summed in f64 in the same order, the
same draws from the same cumulative weights).
"""
import taichi as ti

from .models.likelihood import PAD, PointPSFLikelihood

F32_2, F64_1, F64_2 = (ti.types.ndarray(dtype=ti.f32, ndim=2), ti.types.ndarray(dtype=ti.f64, ndim=1),
                       ti.types.ndarray(dtype=ti.f64, ndim=2))
I32_1, I32_2 = ti.types.ndarray(dtype=ti.i32, ndim=1), ti.types.ndarray(dtype=ti.i32, ndim=2)
LIKELIHOOD = PointPSFLikelihood()
# rows of ``state``: x, y, vx, vy, intensity (px, px/frame, σ units) and E (0 or 1)
X, Y, VX, VY, INTEN, E = range(6)
# rows of ``pps``: first member, size, and (written) whether the population has an E = 1 member
START, SIZE, ANY_E = range(3)
# entries of ``values``: Eq. 15's four constants (f32 values), the frames' rows h, the draws per population, then
# each population's systematic offset u
H_ROWS, DRAWS, OFFSETS = 4, 5, 6
NOT_DRAWN = -1.0e300  # the score of an E = 0 member of a population that has E = 1 members


@ti.kernel
def multi_frame_draws(state: F32_2, pps: I32_2, frames: F32_2, window: F32_2, values: F64_1, picks: I32_1,
                      scores: F64_2):
    """For each population r (columns of ``pps``): s_i = Σ_k log ω̃(z_k | x_i − back_k·vx_i, y_i − back_k·vy_i, I_i)
    (Eq. 15, f32 ratios summed over k in order in f64) into ``scores[0]`` for the members that may be drawn (the
    E = 1 ones where the population has any, else all; NOT_DRAWN for the others), then ``picks[r·size + j]``
    (member indices) by systematic resampling ∝ exp(s_i − max s) with offset u_r (:func:`systematic_draw`).

    ``frames``: the frames of h rows, each with its zero border of PAD pixels, stacked one above the other;
    ``window``: rows back_k (frames back) and slot_k (z_k's place in ``frames``); ``values``: see H_ROWS, DRAWS,
    OFFSETS."""
    h, size = ti.cast(values[H_ROWS], ti.i32), ti.cast(values[DRAWS], ti.i32)
    w = frames.shape[1] - 2 * PAD
    c = (ti.cast(values[0], ti.f32), ti.cast(values[1], ti.f32), ti.cast(values[2], ti.f32),
         ti.cast(values[3], ti.f32))
    for r in range(pps.shape[1]):
        has_e = 0
        for i in range(pps[START, r], pps[START, r] + pps[SIZE, r]):
            has_e = ti.max(has_e, ti.cast(state[E, i] == 1.0, ti.i32))
        pps[ANY_E, r] = has_e
    for r, j in ti.ndrange(pps.shape[1], state.shape[1]):
        if j < pps[SIZE, r]:
            i = pps[START, r] + j
            s = ti.f64(NOT_DRAWN)
            if state[E, i] == 1.0 or pps[ANY_E, r] == 0:
                s = 0.0
                x, y, vx, vy, inten = state[X, i], state[Y, i], state[VX, i], state[VY, i], state[INTEN, i]
                for k in range(window.shape[1]):
                    back = window[0, k]
                    s += ti.f64(LIKELIHOOD.log_ratio(x - back * vx, y - back * vy, inten, frames, c, h, w,
                                                     ti.cast(window[1, k], ti.i32) * (h + 2 * PAD)))
            scores[0, i] = s
    for r in range(pps.shape[1]):
        systematic_draw(r, pps, size, values[OFFSETS + r], picks, scores)


@ti.func
def systematic_draw(r: ti.i32, pps: ti.template(), size: ti.i32, u: ti.f64, picks: ti.template(),
                    scores: ti.template()):
    """Population r's ``size`` systematic draws with offset u ∈ [0, 1): the cumulative weights c_i of
    exp(s_i − max s) (0 for NOT_DRAWN) in f64 into ``scores[1]``, then member i takes the draws j with
    (u + j)/size·c_total in [c_(i−1), c_i), j ∈ [below(i − 1), below(i)) (:func:`draws_below`)."""
    a, n = pps[START, r], pps[SIZE, r]
    top = ti.f64(NOT_DRAWN)
    for i in range(a, a + n):
        top = ti.max(top, scores[0, i])
    total = ti.f64(0.0)
    for i in range(a, a + n):
        if scores[0, i] > NOT_DRAWN:
            total += ti.exp(scores[0, i] - top)
        scores[1, i] = total
    below = 0
    for i in range(a, a + n):
        upto = draws_below(scores[1, i], total, size, u)
        for j in range(below, upto):
            picks[r * size + j] = i
        below = upto


@ti.func
def draws_below(cumulative: ti.f64, total: ti.f64, size: ti.i32, u: ti.f64) -> ti.i32:
    """The number of systematic draws j ∈ [0, size) with (u + j)/size·total < ``cumulative``:
    min(max(⌈cumulative/total·size − u⌉, 0), size) (f64, as the twin computes it)."""
    return ti.min(ti.max(ti.cast(ti.ceil(cumulative / total * ti.cast(size, ti.f64) - u), ti.i32), 0), size)
