"""Streamed (2r+1)² max filters and the first saliency layer (SGDS-PF Eqs. 20–22) as Taichi kernels.

The max filters are separable (a row pass then a column pass, r ≤ 8) and streamed: the image is split
into ``n_chunks`` runs of rows (the parallel loop; on the CPU each run starts a thread's share of the loop,
``loops.thread_span``), and each run walks down its rows once, keeping the row-pass results of the last
2r+1 rows in a small per-chunk ring, so intermediate images are never written to memory.  Out-of-image
pixels are ignored by the max filters and contribute 0 to the energy sum of Eq. 21.
"""
import taichi as ti

from .loops import light_ir
from .saliency_fields import R_DST, R_FRAME, R_SUM_A, R_SUM_B, R_SUM_C
from .saliency_lanes import (NEG_INF, ROW_BLOCK, VEC, VEC64, add_lane_moments, chunk_runs, for_row_chunks,
                             image_dims, lane_shift, positive_row_vector, row_vector, store_row_moments, sum_of_slots)


@ti.func
def row_max(src: ti.template(), s: ti.i32, y: ti.i32, dst: ti.template(), ds: ti.i32, dy: ti.i32, valid: ti.template(),
            r: ti.template(), lanes: ti.i32):
    """dst[ds, dy] = max over |d| ≤ r of src[s, y, x + d], in-image neighbours only (a sliding
    window of three vectors: one load per vector), over the row's ``lanes`` vectors."""
    prev = VEC(NEG_INF)
    cur = row_vector(src, s, y, 0, valid, NEG_INF)
    for xb in range(lanes):
        nxt = row_vector(src, s, y, xb + 1, valid, NEG_INF)
        m = cur
        for d in ti.static(range(-r, r + 1)):
            m = ti.max(m, lane_shift(prev, cur, nxt, d))
        dst[ds, dy, xb] = m
        prev = cur
        cur = nxt


@ti.func
def column_max(ring: ti.template(), c: ti.i32, y: ti.i32, dims: ti.template(), dst: ti.template(), ds: ti.i32,
               valid: ti.template(), r: ti.template()):
    """dst[ds, y] = max over in-image rows |d| ≤ r of row y + d, read from chunk c's ring of 2r+1 row
    maxima (row y' in slot y' mod (2r+1)); padding lanes set to 0.  ``dims``: (rows H, lane vectors V)."""
    h, lanes = dims
    for xb in range(lanes):
        m = ring[c, y % (2 * r + 1), xb]
        for d in ti.static(range(-r, r + 1)):
            if 0 <= y + d < h:
                m = ti.max(m, ring[c, (y + d) % (2 * r + 1), xb])
        dst[ds, y, xb] = ti.select(valid[xb] > 0, m, VEC(0.0))



@ti.func
def store_frame(src: ti.types.ndarray(dtype=VEC, ndim=2), z: ti.template(), zs: ti.i32, z_rows: ti.template(),
                serial: ti.template()):
    """Store a padded host frame (H, ⌈W/8⌉) of 8-vectors into ring slot ``zs`` and its per-row
    (Σ z, Σ z²) in f64 (for Eq. 26), summed per lane, then over the lanes.  In a ring wider than the frame
    (a size class) the vector after each row's last is set to 0: the filters read it as the row's outside."""
    ti.loop_config(serialize=serial, block_dim=ROW_BLOCK)
    for y in range(src.shape[0]):
        s1 = VEC64(0.0)
        s2 = VEC64(0.0)
        for xb in range(src.shape[1]):
            v = src[y, xb]
            z[zs, y, xb] = v
            s1, s2 = add_lane_moments(v, s1, s2)
        store_row_moments(z_rows, zs, y, s1, s2)
        if src.shape[1] < z.shape[2]:
            z[zs, y, src.shape[1]] = VEC(0.0)


@ti.func
def energy_row_pass(z: ti.template(), zs: ti.i32, y: ti.i32, hs: ti.template(), hm: ti.template(), c: ti.i32,
                    r: ti.template(), lanes: ti.i32):
    """Row pass of Eq. 21 for image row y: Σ and max of p = max(z, 0) over |dx| ≤ r, into slot
    y mod (2r+1) of chunk c's rings hs and hm (the row's ``lanes`` vectors)."""
    slot = y % (2 * r + 1)
    prev = VEC(0.0)
    cur = positive_row_vector(z, zs, y, 0)
    for xb in range(lanes):
        nxt = positive_row_vector(z, zs, y, xb + 1)
        total = VEC(0.0)
        peak = VEC(0.0)
        for d in ti.static(range(-r, r + 1)):
            v = lane_shift(prev, cur, nxt, d)
            total += v
            peak = ti.max(peak, v)
        hs[c, slot, xb] = total
        hm[c, slot, xb] = peak
        prev = cur
        cur = nxt


@ti.func
def energy_column(z: ti.template(), zs: ti.i32, hs: ti.template(), hm: ti.template(), c: ti.i32, y: ti.i32,
                  xb: ti.i32, r: ti.template(), h: ti.i32) -> VEC:
    """Column pass of Eqs. 20–21: I_se = p · Σ_{(2r+1)²} p / max_{(2r+1)²} p (p = max(z, 0)), 0 where max p = 0
    (rows of a frame of h rows)."""
    total = VEC(0.0)
    peak = VEC(0.0)
    for d in ti.static(range(-r, r + 1)):
        if 0 <= y + d < h:
            total += hs[c, (y + d) % (2 * r + 1), xb]
            peak = ti.max(peak, hm[c, (y + d) % (2 * r + 1), xb])
    centre = ti.max(z[zs, y, xb], 0.0)
    return ti.select(peak > 0, centre * total / ti.select(peak > 0, peak, 1.0), VEC(0.0))


@ti.func
def energy_and_max(z: ti.template(), zs: ti.i32, valid: ti.template(), hs: ti.template(), hm: ti.template(),
                   line: ti.template(), ring: ti.template(), se_max: ti.template(), ds: ti.i32,
                   n_chunks: ti.i32, r: ti.template(), i_se: ti.template(), keep_i_se: ti.template(),
                   serial: ti.template(), dims: ti.template()):
    """I_se (Eqs. 20–21 on max(z, 0)) and its (2r+1)² max filter I_se_max into se_max[ds], streamed.

    Each chunk of rows walks down the image once: row y's row pass (rings hs, hm), row y − r's
    I_se and its row maximum (ring), row y − 2r's column maximum (output), so every
    intermediate row stays in cache.  Chunks recompute 2r halo rows on each side.
    With ``keep_i_se``, I_se is also written to i_se[0] (tests, figures).  ``dims``: (rows H, lane vectors V).
    """
    for_row_chunks(dims[0], 2 * r, n_chunks, serial, energy_and_max_rows,
                   {'z': z, 'zs': zs, 'valid': valid, 'hs': hs, 'hm': hm, 'line': line, 'ring': ring,
                    'se_max': se_max, 'ds': ds, 'r': r, 'i_se': i_se, 'keep_i_se': keep_i_se, 'dims': dims})


@ti.func
def energy_and_max_rows(c: ti.i32, y: ti.i32, y0: ti.i32, y1: ti.i32, args: ti.template()):
    """``energy_and_max`` at row y of chunk c (rows [y0, y1)): row y's row pass, row y − r's I_se and its row
    maximum, row y − 2r's column maximum."""
    z, hs, hm, line, ring = ti.static(args['z'], args['hs'], args['hm'], args['line'], args['ring'])
    r = ti.static(args['r'])
    h, lanes = args['dims']
    zs = args['zs']
    if 0 <= y < h:
        energy_row_pass(z, zs, y, hs, hm, c, r, lanes)
    yb = y - r
    if 0 <= yb < h and y0 - r <= yb < y1 + r:
        for xb in range(lanes):
            line[c, 0, xb] = energy_column(z, zs, hs, hm, c, yb, xb, r, h)
            if ti.static(args['keep_i_se']):
                if y0 <= yb < y1:
                    args['i_se'][0, yb, xb] = line[c, 0, xb]
        row_max(line, c, 0, ring, c, yb % (2 * r + 1), args['valid'], r, lanes)
    if y0 <= y - 2 * r < y1:
        column_max(ring, c, y - 2 * r, args['dims'], args['se_max'], args['ds'], args['valid'], r)


@ti.func
def first_layer_sum(src: ti.template(), a: ti.i32, b: ti.i32, c3: ti.i32, scale: ti.f32, valid: ti.template(),
                    acc: ti.template(), ds: ti.i32, line: ti.template(), ring: ti.template(), acc_max: ti.template(),
                    n_chunks: ti.i32, r: ti.template(), serial: ti.template(), dims: ti.template()):
    """First layer of Eq. 22: I_acc = (Σ of src slots a, b, c3; −1 skipped)·scale into acc[ds] and its
    (2r+1)² max filter into acc_max[ds], streamed like :func:`energy_and_max` (r halo rows).
    With one slot and scale 1 it is the max filter of that slot.  ``dims``: (rows H, lane vectors V)."""
    for_row_chunks(dims[0], r, n_chunks, serial, first_layer_rows,
                   {'src': src, 'slots': (a, b, c3), 'scale': scale, 'valid': valid, 'acc': acc, 'ds': ds, 'line': line,
                    'ring': ring, 'acc_max': acc_max, 'r': r, 'dims': dims})


@ti.func
def first_layer_rows(c: ti.i32, y: ti.i32, y0: ti.i32, y1: ti.i32, args: ti.template()):
    """``first_layer_sum`` at row y of chunk c (rows [y0, y1)): row y's sum and row maximum, row y − r's column
    maximum."""
    src, line, ring = ti.static(args['src'], args['line'], args['ring'])
    r = ti.static(args['r'])
    h, lanes = args['dims']
    ds = args['ds']
    if 0 <= y < h:
        a, b, c3 = args['slots']
        for xb in range(lanes):
            v = sum_of_slots(src, a, b, c3, y, xb) * args['scale']
            line[c, 0, xb] = v
            if y0 <= y < y1:
                args['acc'][ds, y, xb] = v
        row_max(line, c, 0, ring, c, y % (2 * r + 1), args['valid'], r, lanes)
    if y0 <= y - r < y1:
        column_max(ring, c, y - r, args['dims'], args['acc_max'], ds, args['valid'], r)


@light_ir
@ti.kernel
def accumulate_max(f: ti.template(), ring: ti.types.ndarray(dtype=ti.i32, ndim=1), scale: ti.f32):
    """One launch of :func:`first_layer_sum`: I_acc of se_max slots ring[R_SUM_*] into f.acc[ring[R_DST]], its max
    filter into f.acc_max[ring[R_DST]] (``f``: :class:`~.saliency_fields.SaliencyFields`; ``ring``:
    :func:`~.saliency_fields.ring_slots`)."""
    first_layer_sum(f.se_max, ring[R_SUM_A], ring[R_SUM_B], ring[R_SUM_C], scale, f.valid, f.acc, ring[R_DST],
                    f.line, f.ring_max, f.acc_max, chunk_runs(f), f.r, f.serial, image_dims(f))


@light_ir
@ti.kernel
def frame_to_first_layer(src: ti.types.ndarray(dtype=VEC, ndim=2), f: ti.template(),
                         ring: ti.types.ndarray(dtype=ti.i32, ndim=1), scale: ti.f32, keep_i_se: ti.template()):
    """A new frame into slot ring[R_FRAME] (:func:`store_frame`, :func:`energy_and_max`) and the first layer of
    the frame before it into slot ring[R_DST] (:func:`first_layer_sum` of se_max slots ring[R_SUM_*]), in one
    launch (``f``: :class:`~.saliency_fields.SaliencyFields`; ``ring``: :func:`~.saliency_fields.ring_slots`)."""
    zs, dims = ring[R_FRAME], image_dims(f)
    store_frame(src, f.z, zs, f.z_rows, f.serial)
    energy_and_max(f.z, zs, f.valid, f.hs, f.hm, f.line, f.ring_max, f.se_max, zs, chunk_runs(f), f.r, f.i_se, keep_i_se,
                   f.serial, dims)
    first_layer_sum(f.se_max, ring[R_SUM_A], ring[R_SUM_B], ring[R_SUM_C], scale, f.valid, f.acc, ring[R_DST],
                    f.line, f.ring_max, f.acc_max, chunk_runs(f), f.r, f.serial, dims)
