"""Multi-frame saliency extraction (SGDS-PF Eqs. 20–33) as Taichi kernels.

Layout: an image (H, W) is stored as a field of 8-lane vectors (H, ⌈W/8⌉) along x,
so that LLVM turns each row operation into SIMD instructions (about 3× faster on
the CPU than scalar loops); ring buffers add a leading slot axis.  Lanes past W are
padding and always read as "outside the image".

Every kernel runs in IEEE f32 (the runtime starts with fast_math off) and adds in a
fixed order, so the NumPy twin ``tbd_taichi.numpy_kernels.saliency`` reproduces the
same bits except after exp().

Loops run row by row: the outer loop over rows is parallel, or serial when the
template argument ``serial`` is True (small images, where a parallel launch costs
more than the work).  (2r+1)² operators are separable, a row pass then a column
pass, with r ≤ 8.  The max filters are streamed: the image is split into
``n_chunks`` runs of rows (the parallel loop; on the CPU each run starts a thread's share of the
loop, ``loops.thread_span``, since Taichi's CPU range-for hands a thread at least 512 iterations
and a loop over 16 runs would run on one thread), and each run walks down its rows once,
keeping the row-pass results of the last 2r+1 rows in a small per-chunk ring, so
intermediate images are never written to memory (with the per-lane f64 row sums,
9.8 → 7.4 ms per frame for the whole stage at 1024×1024 on the 2-core CPU).

Border rule (both engines): out-of-image pixels are ignored by the max filters and
contribute 0 to the sums (the energy sum of Eq. 21 and the 5×5 correlation of Eq. 27).
"""
import taichi as ti

from .loops import thread_span

LANES = 8
NEG_INF = -3.0e38
LEF_NO_CAP = 3.0e38  # upper intensity bound of the multi-frame LEF's per-frame term (no cap)
ROW_BLOCK = 16  # rows per CPU task in parallel loops
VEC = ti.types.vector(LANES, ti.f32)


# ---------------------------------------------------------------- lane helpers (ti.func)

@ti.func
def lane_shift(prev: VEC, cur: VEC, nxt: VEC, d: ti.template()) -> VEC:
    """The vector of values at x + d for the 8 pixels of ``cur`` (|d| ≤ 8), lanes chosen at compile time."""
    out = VEC(0.0)
    for k in ti.static(range(LANES)):
        if ti.static(k + d < 0):
            out[k] = prev[k + d + LANES]
        elif ti.static(k + d >= LANES):
            out[k] = nxt[k + d - LANES]
        else:
            out[k] = cur[k + d]
    return out


@ti.func
def row_vector(src: ti.template(), s: ti.i32, y: ti.i32, xb: ti.i32, valid: ti.template(), fill: ti.f32) -> VEC:
    """src[s, y, xb] with padding lanes (and xb outside the row) set to ``fill``."""
    v = VEC(fill)
    if 0 <= xb < src.shape[2]:
        v = ti.select(valid[xb] > 0, src[s, y, xb], VEC(fill))
    return v


@ti.func
def frame_vector(z: ti.template(), s: ti.i32, y: ti.i32, xb: ti.i32) -> VEC:
    """z[s, y, xb] of a frame ring, 0 for xb outside the row (a frame's padding lanes hold 0)."""
    v = VEC(0.0)
    if 0 <= xb < z.shape[2]:
        v = z[s, y, xb]
    return v


@ti.func
def positive_row_vector(z: ti.template(), s: ti.i32, y: ti.i32, xb: ti.i32) -> VEC:
    """max(z, 0) at (s, y, xb) of a frame ring, 0 outside the image."""
    return ti.max(frame_vector(z, s, y, xb), 0.0)


@ti.func
def row_max(src: ti.template(), s: ti.i32, y: ti.i32, dst: ti.template(), ds: ti.i32, dy: ti.i32, valid: ti.template(),
            r: ti.template()):
    """dst[ds, dy] = max over |d| ≤ r of src[s, y, x + d], in-image neighbours only (a sliding
    window of three vectors: one load per vector)."""
    prev = VEC(NEG_INF)
    cur = row_vector(src, s, y, 0, valid, NEG_INF)
    for xb in range(src.shape[2]):
        nxt = row_vector(src, s, y, xb + 1, valid, NEG_INF)
        m = cur
        for d in ti.static(range(-r, r + 1)):
            m = ti.max(m, lane_shift(prev, cur, nxt, d))
        dst[ds, dy, xb] = m
        prev = cur
        cur = nxt


@ti.func
def column_max(ring: ti.template(), c: ti.i32, y: ti.i32, h: ti.i32, dst: ti.template(), ds: ti.i32,
               valid: ti.template(), r: ti.template()):
    """dst[ds, y] = max over in-image rows |d| ≤ r of row y + d, read from chunk c's ring of 2r+1 row
    maxima (row y' in slot y' mod (2r+1)); padding lanes set to 0."""
    for xb in range(ring.shape[2]):
        m = ring[c, y % (2 * r + 1), xb]
        for d in ti.static(range(-r, r + 1)):
            if 0 <= y + d < h:
                m = ti.max(m, ring[c, (y + d) % (2 * r + 1), xb])
        dst[ds, y, xb] = ti.select(valid[xb] > 0, m, VEC(0.0))


@ti.func
def chunk_rows(c: ti.i32, n_chunks: ti.i32, h: ti.i32):
    """Rows [y0, y1) of chunk c when h rows are split into n_chunks near-equal runs."""
    return (c * h) // n_chunks, ((c + 1) * h) // n_chunks


@ti.func
def sum_of_slots(src: ti.template(), a: ti.i32, b: ti.i32, c: ti.i32, y: ti.i32, xb: ti.i32) -> VEC:
    """((src[a] + src[b]) + src[c]) at (y, xb), slots given as −1 skipped."""
    v = VEC(0.0)
    if a >= 0:
        v += src[a, y, xb]
    if b >= 0:
        v += src[b, y, xb]
    if c >= 0:
        v += src[c, y, xb]
    return v


VEC64 = ti.types.vector(LANES, ti.f64)


@ti.func
def lane_sum(v: VEC64) -> ti.f64:
    """Σ of the 8 lanes, left to right."""
    total = ti.cast(0.0, ti.f64)
    for k in ti.static(range(LANES)):
        total += v[k]
    return total


@ti.func
def add_lane_moments(v: VEC, s1: VEC64, s2: VEC64):
    """(s1 + v, s2 + v²) in f64, one accumulator per lane (8 independent chains of additions)."""
    w = ti.cast(v, ti.f64)
    return s1 + w, s2 + w * w


@ti.func
def store_row_moments(rows: ti.template(), s: ti.i32, y: ti.i32, s1: VEC64, s2: VEC64):
    """rows[s, y] = (Σ v, Σ v²) of a row from its per-lane sums, lanes added left to right."""
    rows[s, y, 0] = lane_sum(s1)
    rows[s, y, 1] = lane_sum(s2)


# ---------------------------------------------------------------- pipeline kernels

@ti.func
def store_frame(src: ti.types.ndarray(dtype=VEC, ndim=2), z: ti.template(), zs: ti.i32, z_rows: ti.template(),
                serial: ti.template()):
    """Store a padded host frame (H, ⌈W/8⌉) of 8-vectors into ring slot ``zs`` and its per-row
    (Σ z, Σ z²) in f64 (for Eq. 26), summed per lane, then over the lanes."""
    ti.loop_config(serialize=serial, block_dim=ROW_BLOCK)
    for y in range(src.shape[0]):
        s1 = VEC64(0.0)
        s2 = VEC64(0.0)
        for xb in range(src.shape[1]):
            v = src[y, xb]
            z[zs, y, xb] = v
            s1, s2 = add_lane_moments(v, s1, s2)
        store_row_moments(z_rows, zs, y, s1, s2)


@ti.func
def energy_row_pass(z: ti.template(), zs: ti.i32, y: ti.i32, hs: ti.template(), hm: ti.template(), c: ti.i32,
                    r: ti.template()):
    """Row pass of Eq. 21 for image row y: Σ and max of p = max(z, 0) over |dx| ≤ r, into slot
    y mod (2r+1) of chunk c's rings hs and hm."""
    slot = y % (2 * r + 1)
    prev = VEC(0.0)
    cur = positive_row_vector(z, zs, y, 0)
    for xb in range(z.shape[2]):
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
                  xb: ti.i32, r: ti.template()) -> VEC:
    """Column pass of Eqs. 20–21: I_se = p · Σ_{(2r+1)²} p / max_{(2r+1)²} p (p = max(z, 0)), 0 where max p = 0."""
    total = VEC(0.0)
    peak = VEC(0.0)
    for d in ti.static(range(-r, r + 1)):
        if 0 <= y + d < z.shape[1]:
            total += hs[c, (y + d) % (2 * r + 1), xb]
            peak = ti.max(peak, hm[c, (y + d) % (2 * r + 1), xb])
    centre = ti.max(z[zs, y, xb], 0.0)
    return ti.select(peak > 0, centre * total / ti.select(peak > 0, peak, 1.0), VEC(0.0))


@ti.func
def energy_and_max(z: ti.template(), zs: ti.i32, valid: ti.template(), hs: ti.template(), hm: ti.template(),
                   line: ti.template(), ring: ti.template(), se_max: ti.template(), ds: ti.i32,
                   n_chunks: ti.i32, r: ti.template(), i_se: ti.template(), keep_i_se: ti.template(),
                   serial: ti.template()):
    """I_se (Eqs. 20–21 on max(z, 0)) and its (2r+1)² max filter I_se_max into se_max[ds], streamed.

    Each chunk of rows walks down the image once: row y's row pass (rings hs, hm), row y − r's
    I_se and its row maximum (ring), row y − 2r's column maximum (output), so every
    intermediate row stays in cache.  Chunks recompute 2r halo rows on each side.
    With ``keep_i_se``, I_se is also written to i_se[0] (tests, figures).
    """
    h = z.shape[1]
    span = ti.static(thread_span(serial))
    ti.loop_config(serialize=serial)
    for u in range(n_chunks * span):  # chunk u // span (see loops.thread_span)
        if u % span == 0:
            c = u // span
            y0, y1 = chunk_rows(c, n_chunks, h)
            for y in range(y0 - 2 * r, y1 + 2 * r):
                if 0 <= y < h:
                    energy_row_pass(z, zs, y, hs, hm, c, r)
                yb = y - r
                if 0 <= yb < h and y0 - r <= yb < y1 + r:
                    for xb in range(z.shape[2]):
                        line[c, 0, xb] = energy_column(z, zs, hs, hm, c, yb, xb, r)
                        if ti.static(keep_i_se):
                            if y0 <= yb < y1:
                                i_se[0, yb, xb] = line[c, 0, xb]
                    row_max(line, c, 0, ring, c, yb % (2 * r + 1), valid, r)
                if y0 <= y - 2 * r < y1:
                    column_max(ring, c, y - 2 * r, h, se_max, ds, valid, r)


@ti.func
def first_layer_sum(src: ti.template(), a: ti.i32, b: ti.i32, c3: ti.i32, scale: ti.f32, valid: ti.template(),
                    acc: ti.template(), ds: ti.i32, line: ti.template(), ring: ti.template(), acc_max: ti.template(),
                    n_chunks: ti.i32, r: ti.template(), serial: ti.template()):
    """First layer of Eq. 22: I_acc = (Σ of src slots a, b, c3; −1 skipped)·scale into acc[ds] and its
    (2r+1)² max filter into acc_max[ds], streamed like :func:`energy_and_max` (r halo rows).
    With one slot and scale 1 it is the max filter of that slot."""
    h = src.shape[1]
    span = ti.static(thread_span(serial))
    ti.loop_config(serialize=serial)
    for u in range(n_chunks * span):  # chunk u // span (see loops.thread_span)
        if u % span == 0:
            c = u // span
            y0, y1 = chunk_rows(c, n_chunks, h)
            for y in range(y0 - r, y1 + r):
                if 0 <= y < h:
                    for xb in range(src.shape[2]):
                        v = sum_of_slots(src, a, b, c3, y, xb) * scale
                        line[c, 0, xb] = v
                        if y0 <= y < y1:
                            acc[ds, y, xb] = v
                    row_max(line, c, 0, ring, c, y % (2 * r + 1), valid, r)
                if y0 <= y - r < y1:
                    column_max(ring, c, y - r, h, acc_max, ds, valid, r)


@ti.kernel
def accumulate_max(src: ti.template(), a: ti.i32, b: ti.i32, c3: ti.i32, scale: ti.f32, valid: ti.template(),
                   acc: ti.template(), ds: ti.i32, line: ti.template(), ring: ti.template(), acc_max: ti.template(),
                   n_chunks: ti.i32, r: ti.template(), serial: ti.template()):
    """One launch of :func:`first_layer_sum`."""
    first_layer_sum(src, a, b, c3, scale, valid, acc, ds, line, ring, acc_max, n_chunks, r, serial)


@ti.kernel
def frame_to_first_layer(src: ti.types.ndarray(dtype=VEC, ndim=2), z: ti.template(), zs: ti.i32,
                         z_rows: ti.template(), valid: ti.template(), hs: ti.template(), hm: ti.template(),
                         line: ti.template(), ring: ti.template(), se_max: ti.template(), n_chunks: ti.i32,
                         r: ti.template(), i_se: ti.template(), keep_i_se: ti.template(), a: ti.i32, b: ti.i32,
                         c3: ti.i32, scale: ti.f32, acc: ti.template(), ds: ti.i32, acc_max: ti.template(),
                         serial: ti.template()):
    """A new frame into slot ``zs`` (:func:`store_frame`, :func:`energy_and_max`) and the first layer of the
    frame before it into slot ``ds`` (:func:`first_layer_sum` of se_max slots a, b, c3), in one launch."""
    store_frame(src, z, zs, z_rows, serial)
    energy_and_max(z, zs, valid, hs, hm, line, ring, se_max, zs, n_chunks, r, i_se, keep_i_se, serial)
    first_layer_sum(se_max, a, b, c3, scale, valid, acc, ds, line, ring, acc_max, n_chunks, r, serial)


@ti.func
def second_layer_sum(src: ti.template(), a: ti.i32, b: ti.i32, c: ti.i32, scale: ti.f32, dst: ti.template(),
                     rows: ti.template(), serial: ti.template()):
    """Second layer of Eq. 22: I_acc2 = (Σ of 3 I_acc_max slots)·scale, with per-row (Σ v, Σ v²) in f64.

    Padding lanes of I_acc_max are 0, so they add nothing to the sums.
    """
    ti.loop_config(serialize=serial, block_dim=ROW_BLOCK)
    for y in range(src.shape[1]):
        s1 = VEC64(0.0)
        s2 = VEC64(0.0)
        for xb in range(src.shape[2]):
            v = sum_of_slots(src, a, b, c, y, xb) * scale
            dst[0, y, xb] = v
            s1, s2 = add_lane_moments(v, s1, s2)
        store_row_moments(rows, 0, y, s1, s2)


@ti.func
def mean_std(rows: ti.template(), s: ti.i32, count: ti.f64) -> ti.types.vector(2, ti.f64):
    """(mean, N−1 std as MATLAB's std2) from per-row sums rows[s, y], rows added top to bottom."""
    s1 = ti.cast(0.0, ti.f64)
    s2 = ti.cast(0.0, ti.f64)
    for y in range(rows.shape[1]):
        s1 += rows[s, y, 0]
        s2 += rows[s, y, 1]
    mean = s1 / count
    var = ti.max(s2 - s1 * mean, 0.0) / ti.max(count - 1.0, 1.0)
    return ti.Vector([mean, ti.sqrt(var)], dt=ti.f64)


@ti.func
def threshold_and_intensity_range(acc2_rows: ti.template(), z_rows: ti.template(), zs: ti.i32, snr: ti.f64,
                                  count: ti.f64, stats: ti.template()):
    """Eq. 23 threshold and Eq. 26 intensity range (one serial task).

    stats = [T_acc2, I_min (clamped ≥ 0), I_max, mean(I_acc2), std2(I_acc2), mean(z), std2(z)].
    """
    ti.loop_config(serialize=True)
    for _ in range(1):
        acc2 = mean_std(acc2_rows, 0, count)
        z = mean_std(z_rows, zs, count)
        stats[0] = acc2[1] * (ti.f64(2.2) * snr - ti.f64(2.0)) + acc2[0]  # f64 literals: 2.2 is inexact in f32
        stats[1] = ti.max(z[0] + (snr - ti.f64(2.0)) * z[1], ti.f64(0.0))
        stats[2] = z[0] + (snr + ti.f64(3.0)) * z[1]
        stats[3] = acc2[0]
        stats[4] = acc2[1]
        stats[5] = z[0]
        stats[6] = z[1]


@ti.func
def correlate_d(z: ti.template(), zs: ti.i32, d: ti.template(), y: ti.i32, xb: ti.i32) -> VEC:
    """(z ⋆ D) at the 8 pixels of (y, xb) over the 5×5 window, zero outside the image (Eq. 27's B·σ²);
    terms added in (dy, dx) row-major order, like the NumPy twin."""
    acc = VEC(0.0)
    for dy in ti.static(range(5)):
        if 0 <= y + dy - 2 < z.shape[1]:
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
def candidate_pixels(acc2: ti.template(), acc: ti.template(), acc_max: ti.template(), s: ti.i32, z: ti.template(),
                     valid: ti.template(), d: ti.template(), a: ti.f32, stats: ti.template(),
                     memory: ti.template(), ms: ti.i32, lef_scale: ti.f32, accumulated: ti.template(),
                     row_x: ti.template(), row_logw: ti.template(), row_lef: ti.template(), n_row: ti.template(),
                     serial: ti.template()):
    """Eqs. 24 and 27–29: I_rt = [I_acc2 > T_acc2] ∧ [I_acc == I_acc_max], tested 8 lanes at a time;
    at I_rt pixels log Sal = log ω̌_lef (σ = 1), or, with ``accumulated``, lef_scale·L of the
    multi-frame LEF in memory[ms] (:func:`accumulate_lef`), listed per row (row_x, row_logw) in
    increasing x, with each pixel's log ω̌_lef (Eq. 28) in row_lef (for ICEF's MSW, Eq. 40)."""
    threshold = stats[0]
    i_min = ti.cast(stats[1], ti.f32)
    i_max = ti.cast(stats[2], ti.f32)
    ti.loop_config(serialize=serial, block_dim=ROW_BLOCK)
    for y in range(acc2.shape[1]):
        n = 0
        for xb in range(acc2.shape[2]):
            keep = (ti.cast(acc2[0, y, xb], ti.f64) > threshold) & (acc[s, y, xb] == acc_max[s, y, xb]) & \
                (valid[xb] > 0)
            if keep.any():
                lef = lef_log_weight(correlate_d(z, s, d, y, xb), a, i_min, i_max)
                lw = lef
                if ti.static(accumulated):
                    lw = lef_scale * memory[ms, y, xb]
                for k in ti.static(range(LANES)):
                    if keep[k]:
                        row_x[y, n] = xb * LANES + k
                        row_logw[y, n] = lw[k]
                        row_lef[y, n] = lef[k]
                        n += 1
        n_row[y] = n


@ti.func
def multi_frame_lef(z: ti.template(), zs: ti.i32, d: ti.template(), a: ti.f32, memory_decay: ti.f32,
                    valid: ti.template(), memory: ti.template(), src: ti.i32, dst: ti.i32, ring: ti.template(),
                    n_chunks: ti.i32, r: ti.template(), serial: ti.template()):
    """Multi-frame LEF (not in the paper; a dynamic-programming accumulation of Eq. 27):
    memory[dst] = log ω̌⁺(z[zs]) + γ·max_{(2r+1)²} memory[src], γ = ``memory_decay``, where
    log ω̌⁺ = max over I ≥ 0 of −A·I² + B·I (Eqs. 27–28 without the Eq. 26 bounds: (z⋆D)²/(4A)
    where z⋆D > 0, else 0).  The max filter lets the best path move ≤ r px per frame, so a
    target's evidence adds up along its track over about 1/(1 − γ) frames, while noise peaks
    do not line up.  The max filter is streamed like :func:`accumulate_max`; padding lanes 0."""
    h = memory.shape[1]
    span = ti.static(thread_span(serial))
    ti.loop_config(serialize=serial)
    for u in range(n_chunks * span):  # chunk u // span (see loops.thread_span)
        if u % span == 0:
            c = u // span
            y0, y1 = chunk_rows(c, n_chunks, h)
            for y in range(y0 - r, y1 + r):
                if 0 <= y < h:
                    row_max(memory, src, y, ring, c, y % (2 * r + 1), valid, r)
                yc = y - r
                if y0 <= yc < y1:
                    column_max(ring, c, yc, h, memory, dst, valid, r)
                    for xb in range(memory.shape[2]):
                        lef = lef_log_weight(correlate_d(z, zs, d, yc, xb), a, ti.f32(0.0), ti.f32(LEF_NO_CAP))
                        memory[dst, yc, xb] = ti.select(valid[xb] > 0, lef + memory_decay * memory[dst, yc, xb], VEC(0.0))


@ti.kernel
def accumulate_lef(z: ti.template(), zs: ti.i32, d: ti.template(), a: ti.f32, memory_decay: ti.f32,
                   valid: ti.template(), memory: ti.template(), src: ti.i32, dst: ti.i32, ring: ti.template(),
                   n_chunks: ti.i32, r: ti.template(), serial: ti.template()):
    """One launch of :func:`multi_frame_lef`."""
    multi_frame_lef(z, zs, d, a, memory_decay, valid, memory, src, dst, ring, n_chunks, r, serial)


@ti.func
def kth_largest(values: ti.template(), scratch: ti.template(), off: ti.i32, n: ti.i32, k: ti.i32) -> ti.f32:
    """The k-th largest of values[off:off+n] (1 ≤ k ≤ n) by quickselect on a scratch copy (average O(n))."""
    for i in range(n):
        scratch[off + i] = values[off + i]
    lo, hi = off, off + n - 1
    target = off + k - 1  # position in descending order
    while lo < hi:
        pivot = scratch[(lo + hi) // 2]
        i, j = lo, hi
        while i <= j:
            while scratch[i] > pivot:
                i += 1
            while scratch[j] < pivot:
                j -= 1
            if i <= j:
                held = scratch[i]
                scratch[i] = scratch[j]
                scratch[j] = held
                i += 1
                j -= 1
        if target <= j:
            hi = j
        elif target >= i:
            lo = i
        else:
            lo = hi  # target lies among values equal to the pivot
            scratch[target] = pivot
    return scratch[target]


@ti.func
def insert_best(best: ti.template(), value: ti.f32, pixel: ti.i32):
    """Insert (value, pixel) into the descending list best[:, 0] if it beats the last entry (a later
    equal value goes after the earlier one)."""
    k = best.shape[0]
    v = ti.cast(value, ti.f64)
    if v > best[k - 1, 0]:
        i = k - 1
        while i > 0 and best[i - 1, 0] < v:
            best[i, 0] = best[i - 1, 0]
            best[i, 1] = best[i - 1, 1]
            i -= 1
        best[i, 0] = v
        best[i, 1] = ti.cast(pixel, ti.f64)


@ti.func
def proposals_per_block(row_x: ti.template(), row_logw: ti.template(), n_row: ti.template(), row_base: ti.template(),
                        col_block: ti.template(),
                        block_offset: ti.template(), block_nnz: ti.template(), block_max: ti.template(),
                        entry_pixel: ti.template(), entry_logw: ti.template(), entry_sal: ti.template(),
                        scratch: ti.template(), block_stats: ti.template(), proposal: ti.template(),
                        written: ti.template(), n_written: ti.template(), row_lef: ti.template(), best: ti.template()):
    """Eqs. 29–33 for every block in one serial launch (blocks are few and I_rt pixels sparse).

    The I_rt pixels are first gathered from the row lists into per-block slabs.  Sal = exp(log Sal − block max); N_eff = (Σ Sal)²/Σ Sal² in f64 (Eq. 30); T_ep is the
    k-th largest log Sal, k = clamp(round(N_eff), 1, nnz) (Eq. 31); pixels with
    log Sal ≥ T_ep keep Sal / Σ kept Sal (Eqs. 32–33).  The previous frame's proposal
    pixels are cleared first; block_stats[b] = (N_eff, k, nnz, Σ kept Sal).  The block
    accumulators are reset for the next frame.  best[i] = (log ω̌_lef, pixel y·W + x) of the I_rt
    pixels with the K = best.shape[0] largest log ω̌_lef, descending (ties in row-major order; NEG_INF
    and −1 where there are fewer).
    """
    ti.loop_config(serialize=True)
    for _ in range(1):
        for i in range(n_written[None]):
            p = written[i]
            proposal[p // proposal.shape[1], p % proposal.shape[1]] = 0.0
        n_written[None] = 0
        w = proposal.shape[1]
        for i in range(best.shape[0]):
            best[i, 0] = NEG_INF
            best[i, 1] = -1.0
        for y in range(n_row.shape[0]):  # gather the I_rt pixels into block slabs, rows in order
            for i in range(n_row[y]):
                x = row_x[y, i]
                lw = row_logw[y, i]
                b = row_base[y] + col_block[x]  # two small tables, not an (H, W) image: no cache misses
                block_max[b] = ti.max(block_max[b], lw)
                e = block_offset[b] + block_nnz[b]
                entry_pixel[e] = y * w + x
                entry_logw[e] = lw
                block_nnz[b] += 1
                insert_best(best, row_lef[y, i], y * w + x)
        for b in range(block_nnz.shape[0]):
            n = block_nnz[b]
            off = block_offset[b]
            s1 = ti.cast(0.0, ti.f64)
            s2 = ti.cast(0.0, ti.f64)
            for i in range(n):
                sal = ti.exp(entry_logw[off + i] - block_max[b])
                entry_sal[off + i] = sal
                v = ti.cast(sal, ti.f64)
                s1 += v
                s2 += v * v
            k = 0
            neff = ti.cast(0.0, ti.f64)
            kept = ti.cast(0.0, ti.f64)
            if n > 0:
                neff = s1 * s1 / s2
                k = ti.min(ti.max(ti.cast(ti.floor(neff + 0.5), ti.i32), 1), n)
                t_ep = kth_largest(entry_logw, scratch, off, n, k)
                for i in range(n):
                    if entry_logw[off + i] >= t_ep:
                        kept += ti.cast(entry_sal[off + i], ti.f64)
                for i in range(n):
                    if entry_logw[off + i] >= t_ep:
                        p = entry_pixel[off + i]
                        proposal[p // proposal.shape[1], p % proposal.shape[1]] = ti.cast(
                            ti.cast(entry_sal[off + i], ti.f64) / kept, ti.f32)
                        written[n_written[None]] = p
                        n_written[None] += 1
            block_stats[b, 0] = neff
            block_stats[b, 1] = ti.cast(k, ti.f64)
            block_stats[b, 2] = ti.cast(n, ti.f64)
            block_stats[b, 3] = kept
            block_nnz[b] = 0
            block_max[b] = NEG_INF


@ti.func
def clear_previous_proposal(written: ti.template(), n_written: ti.template(), proposal_out: ti.template(),
                            reuse: ti.i32):
    """With ``reuse``, zero the last frame's proposal pixels (the ``written`` list) in ``proposal_out``, the
    host array that frame was copied into (one serial task)."""
    ti.loop_config(serialize=True)
    for _ in range(1):
        if reuse != 0:
            w = proposal_out.shape[1]
            for i in range(n_written[None]):
                proposal_out[written[i] // w, written[i] % w] = 0.0


@ti.func
def copy_out_proposal(proposal: ti.template(), written: ti.template(), n_written: ti.template(), best: ti.template(),
                      proposal_out: ti.template(), best_out: ti.template()):
    """The frame's proposal pixels (the ``written`` list; ``proposal_out`` arrives zeroed) and ``best`` into
    host arrays (one serial task: the pixels are few)."""
    ti.loop_config(serialize=True)
    for _ in range(1):
        w = proposal.shape[1]
        for i in range(n_written[None]):
            y, x = written[i] // w, written[i] % w
            proposal_out[y, x] = proposal[y, x]
        for i in range(best.shape[0]):
            best_out[i, 0] = best[i, 0]
            best_out[i, 1] = best[i, 1]


@ti.kernel
def second_layer_and_lef(acc_max: ti.template(), a: ti.i32, b: ti.i32, c: ti.i32, scale: ti.f32,
                         acc2: ti.template(), acc2_rows: ti.template(), z_rows: ti.template(), zs: ti.i32,
                         snr: ti.f64, count: ti.f64, stats: ti.template(), z: ti.template(), d: ti.template(),
                         lef_a: ti.f32, memory_decay: ti.f32, valid: ti.template(), memory: ti.template(),
                         ms_src: ti.i32, ms: ti.i32, ring: ti.template(), n_chunks: ti.i32, r: ti.template(),
                         accumulated: ti.template(), serial: ti.template()):
    """The frame in slot ``zs``, first half: :func:`second_layer_sum`, :func:`threshold_and_intensity_range`
    and, with ``accumulated``, :func:`multi_frame_lef` (memory slot ``ms_src`` → ``ms``), in one launch."""
    second_layer_sum(acc_max, a, b, c, scale, acc2, acc2_rows, serial)
    threshold_and_intensity_range(acc2_rows, z_rows, zs, snr, count, stats)
    if ti.static(accumulated):
        multi_frame_lef(z, zs, d, lef_a, memory_decay, valid, memory, ms_src, ms, ring, n_chunks, r, serial)


@ti.kernel
def proposal_from_candidates(acc2: ti.template(), acc: ti.template(), acc_max: ti.template(), zs: ti.i32,
                             z: ti.template(), valid: ti.template(), d: ti.template(), lef_a: ti.f32,
                             stats: ti.template(), memory: ti.template(), ms: ti.i32, lef_scale: ti.f32,
                             accumulated: ti.template(), row_x: ti.template(), row_logw: ti.template(),
                             row_lef: ti.template(), n_row: ti.template(), row_base: ti.template(),
                             col_block: ti.template(), block_offset: ti.template(), block_nnz: ti.template(),
                             block_max: ti.template(), entry_pixel: ti.template(), entry_logw: ti.template(),
                             entry_sal: ti.template(), scratch: ti.template(), block_stats: ti.template(),
                             proposal: ti.template(), written: ti.template(), n_written: ti.template(),
                             best: ti.template(), serial: ti.template(),
                             proposal_out: ti.types.ndarray(dtype=ti.f32, ndim=2),
                             best_out: ti.types.ndarray(dtype=ti.f64, ndim=2), reuse: ti.i32):
    """The frame in slot ``zs``, second half: :func:`candidate_pixels`, :func:`proposals_per_block`, and the
    proposal and best list into host arrays (:func:`copy_out_proposal`; with ``reuse``, ``proposal_out``
    holds the last frame's proposal, cleared first by :func:`clear_previous_proposal`), in one launch.
    (Both halves in one kernel took twice as long to compile as the two, for no measurable gain.)"""
    candidate_pixels(acc2, acc, acc_max, zs, z, valid, d, lef_a, stats, memory, ms, lef_scale, accumulated, row_x,
                     row_logw, row_lef, n_row, serial)
    clear_previous_proposal(written, n_written, proposal_out, reuse)
    proposals_per_block(row_x, row_logw, n_row, row_base, col_block, block_offset, block_nnz, block_max,
                        entry_pixel, entry_logw, entry_sal, scratch, block_stats, proposal, written, n_written,
                        row_lef, best)
    copy_out_proposal(proposal, written, n_written, best, proposal_out, best_out)


# ---------------------------------------------------------------- single operators (tests, figures)

@ti.kernel
def lef_map(z: ti.template(), zs: ti.i32, d: ti.template(), a: ti.f32, i_min: ti.f32,
            i_max: ti.f32, out: ti.template()):
    """Likelihood estimation filter (Eqs. 25–28) at every pixel of a lane ring: log ω̌_lef (σ = 1)."""
    for y, xb in ti.ndrange(z.shape[1], z.shape[2]):
        out[0, y, xb] = lef_log_weight(correlate_d(z, zs, d, y, xb), a, i_min, i_max)


@ti.kernel
def correlate_map(z: ti.template(), zs: ti.i32, d: ti.template(), out: ti.template()):
    """z ⋆ D at every pixel of a lane ring (zero padding)."""
    for y, xb in ti.ndrange(z.shape[1], z.shape[2]):
        out[0, y, xb] = correlate_d(z, zs, d, y, xb)
