"""Second saliency layer, segmentation statistics and the likelihood estimation filter (SGDS-PF
Eqs. 22–28, and the multi-frame LEF) as Taichi kernels.

The 5×5 correlation of Eq. 27 reads 0 outside the image.
"""
import taichi as ti

from .loops import light_ir
from .saliency_fields import R_FRAME, R_MEMORY, R_MEMORY_SRC, R_SUM_A, R_SUM_B, R_SUM_C
from .saliency_lanes import (LEF_NO_CAP, ROW_BLOCK, VEC, VEC64, add_lane_moments, chunk_runs, for_row_chunks,
                             frame_vector, image_dims, lane_shift, store_row_moments, sum_of_slots)
from .saliency_maxfilter import column_max, row_max


@ti.func
def second_layer_sum(src: ti.template(), a: ti.i32, b: ti.i32, c: ti.i32, scale: ti.f32, dst: ti.template(),
                     rows: ti.template(), serial: ti.template(), dims: ti.template()):
    """Second layer of Eq. 22: I_acc2 = (Σ of 3 I_acc_max slots)·scale, with per-row (Σ v, Σ v²) in f64
    (``dims``: rows H, lane vectors V).

    Padding lanes of I_acc_max are 0, so they add nothing to the sums.
    """
    h, lanes = dims
    ti.loop_config(serialize=serial, block_dim=ROW_BLOCK)
    for y in range(h):
        s1 = VEC64(0.0)
        s2 = VEC64(0.0)
        for xb in range(lanes):
            v = sum_of_slots(src, a, b, c, y, xb) * scale
            dst[0, y, xb] = v
            s1, s2 = add_lane_moments(v, s1, s2)
        store_row_moments(rows, 0, y, s1, s2)


@ti.func
def mean_std(rows: ti.template(), s: ti.i32, count: ti.f64, h: ti.i32) -> ti.types.vector(2, ti.f64):
    """(mean, N−1 std as MATLAB's std2) from per-row sums rows[s, y] of the frame's h rows, added top to bottom."""
    s1 = ti.cast(0.0, ti.f64)
    s2 = ti.cast(0.0, ti.f64)
    for y in range(h):
        s1 += rows[s, y, 0]
        s2 += rows[s, y, 1]
    mean = s1 / count
    var = ti.max(s2 - s1 * mean, 0.0) / ti.max(count - 1.0, 1.0)
    return ti.Vector([mean, ti.sqrt(var)], dt=ti.f64)


@ti.func
def threshold_and_intensity_range(acc2_rows: ti.template(), z_rows: ti.template(), zs: ti.i32, snr: ti.f64,
                                  count: ti.f64, stats: ti.template(), h: ti.i32):
    """Eq. 23 threshold and Eq. 26 intensity range (one serial task; the frame's h rows).

    stats = [T_acc2, I_min (clamped ≥ 0), I_max, mean(I_acc2), std2(I_acc2), mean(z), std2(z)].
    """
    ti.loop_config(serialize=True)
    for _ in range(1):
        acc2 = mean_std(acc2_rows, 0, count, h)
        z = mean_std(z_rows, zs, count, h)
        stats[0] = acc2[1] * (ti.f64(2.2) * snr - ti.f64(2.0)) + acc2[0]  # f64 literals: 2.2 is inexact in f32
        stats[1] = ti.max(z[0] + (snr - ti.f64(2.0)) * z[1], ti.f64(0.0))
        stats[2] = z[0] + (snr + ti.f64(3.0)) * z[1]
        stats[3] = acc2[0]
        stats[4] = acc2[1]
        stats[5] = z[0]
        stats[6] = z[1]


@ti.func
def correlate_d(z: ti.template(), zs: ti.i32, d: ti.template(), y: ti.i32, xb: ti.i32, h: ti.i32) -> VEC:
    """(z ⋆ D) at the 8 pixels of (y, xb) over the 5×5 window, zero outside the image of h rows (Eq. 27's B·σ²);
    terms added in (dy, dx) row-major order, like the NumPy twin."""
    acc = VEC(0.0)
    for dy in ti.static(range(5)):
        if 0 <= y + dy - 2 < h:
            prev = frame_vector(z, zs, y + dy - 2, xb - 1)
            cur = frame_vector(z, zs, y + dy - 2, xb)
            nxt = frame_vector(z, zs, y + dy - 2, xb + 1)
            for dx in ti.static(range(5)):
                acc += d[dy, dx] * lane_shift(prev, cur, nxt, dx - 2)
    return acc


@ti.func
def lef_log_weight(b, a, i_min, i_max):
    """Eqs. 27–28: max over I in [i_min, i_max] of −A·I² + B·I, at I_c = clamp(B/(2A)) (scalar or lanes)."""
    ic = ti.min(ti.max(b / (ti.f32(2.0) * a), i_min), i_max)
    return b * ic - a * (ic * ic)


@ti.func
def multi_frame_lef(z: ti.template(), zs: ti.i32, d: ti.template(), a: ti.f32, memory_decay: ti.f32,
                    valid: ti.template(), memory: ti.template(), src: ti.i32, dst: ti.i32, ring: ti.template(),
                    n_chunks: ti.i32, r: ti.template(), serial: ti.template(), dims: ti.template()):
    """Multi-frame LEF (not in the paper; a dynamic-programming accumulation of Eq. 27):
    memory[dst] = log ω̌⁺(z[zs]) + γ·max_{(2r+1)²} memory[src], γ = ``memory_decay``, where
    log ω̌⁺ = max over I ≥ 0 of −A·I² + B·I (Eqs. 27–28 without the Eq. 26 bounds: (z⋆D)²/(4A)
    where z⋆D > 0, else 0).  The max filter lets the best path move ≤ r px per frame, so a
    target's evidence adds up along its track over about 1/(1 − γ) frames, while noise peaks
    do not line up.  The max filter is streamed like :func:`accumulate_max`; padding lanes 0.  ``dims``: (rows H,
    lane vectors V)."""
    for_row_chunks(dims[0], r, n_chunks, serial, multi_frame_lef_rows,
                   {'z': z, 'zs': zs, 'd': d, 'a': a, 'decay': memory_decay, 'valid': valid, 'memory': memory,
                    'src': src, 'dst': dst, 'ring': ring, 'r': r, 'dims': dims})


@ti.func
def multi_frame_lef_rows(c: ti.i32, y: ti.i32, y0: ti.i32, y1: ti.i32, args: ti.template()):
    """``multi_frame_lef`` at row y of chunk c (rows [y0, y1)): row y's row maximum of memory[src], row y − r's
    column maximum and its new memory."""
    memory, ring, valid = ti.static(args['memory'], args['ring'], args['valid'])
    r = ti.static(args['r'])
    h, lanes = args['dims']
    dst = args['dst']
    if 0 <= y < h:
        row_max(memory, args['src'], y, ring, c, y % (2 * r + 1), valid, r, lanes)
    yc = y - r
    if y0 <= yc < y1:
        column_max(ring, c, yc, args['dims'], memory, dst, valid, r)
        for xb in range(lanes):
            lef = lef_log_weight(correlate_d(args['z'], args['zs'], args['d'], yc, xb, h), args['a'], ti.f32(0.0),
                                 ti.f32(LEF_NO_CAP))
            memory[dst, yc, xb] = ti.select(valid[xb] > 0, lef + args['decay'] * memory[dst, yc, xb], VEC(0.0))


@ti.kernel
def accumulate_lef(f: ti.template(), zs: ti.i32, src: ti.i32, dst: ti.i32):
    """One launch of :func:`multi_frame_lef` of frame f.z[zs], memory slot ``src`` → ``dst``, with A and γ
    from f.params32 (``f``: :class:`~.saliency_fields.SaliencyFields`)."""
    multi_frame_lef(f.z, zs, f.d, f.params32[0], f.params32[1], f.valid, f.memory, src, dst, f.ring_max, chunk_runs(f),
                    f.r, f.serial, image_dims(f))


@light_ir
@ti.kernel
def second_layer_and_lef(f: ti.template(), ring: ti.types.ndarray(dtype=ti.i32, ndim=1), scale: ti.f32,
                         accumulated: ti.template()):
    """The frame in slot ring[R_FRAME], first half: :func:`second_layer_sum` of acc_max slots ring[R_SUM_*],
    :func:`threshold_and_intensity_range` and, with ``accumulated``, :func:`multi_frame_lef` (memory slot
    ring[R_MEMORY_SRC] → ring[R_MEMORY]), in one launch; snr and N from f.params64, A and γ from f.params32
    (``f``: :class:`~.saliency_fields.SaliencyFields`; ``ring``: :func:`~.saliency_fields.ring_slots`)."""
    zs, a, b, c = ring[R_FRAME], ring[R_SUM_A], ring[R_SUM_B], ring[R_SUM_C]
    dims = image_dims(f)
    second_layer_sum(f.acc_max, a, b, c, scale, f.acc2, f.acc2_rows, f.serial, dims)
    threshold_and_intensity_range(f.acc2_rows, f.z_rows, zs, f.params64[0], f.params64[1], f.stats, dims[0])
    if ti.static(accumulated):
        multi_frame_lef(f.z, zs, f.d, f.params32[0], f.params32[1], f.valid, f.memory, ring[R_MEMORY_SRC],
                        ring[R_MEMORY], f.ring_max, chunk_runs(f), f.r, f.serial, dims)


# ---------------------------------------------------------------- single operators (tests, figures)

@ti.kernel
def lef_map(z: ti.template(), zs: ti.i32, d: ti.template(), a: ti.f32, i_min: ti.f32,
            i_max: ti.f32, out: ti.template()):
    """Likelihood estimation filter (Eqs. 25–28) at every pixel of a lane ring of the frame's own extents (not an
    engine's size-class fields): log ω̌_lef (σ = 1)."""
    for y, xb in ti.ndrange(z.shape[1], z.shape[2]):
        out[0, y, xb] = lef_log_weight(correlate_d(z, zs, d, y, xb, z.shape[1]), a, i_min, i_max)


@ti.kernel
def correlate_map(z: ti.template(), zs: ti.i32, d: ti.template(), out: ti.template()):
    """z ⋆ D at every pixel of a lane ring of the frame's own extents (zero padding)."""
    for y, xb in ti.ndrange(z.shape[1], z.shape[2]):
        out[0, y, xb] = correlate_d(z, zs, d, y, xb, z.shape[1])
