"""Lane layout and row helpers of the saliency kernels (``kernels.saliency``).

An image (H, W) is stored as a field of 8-lane vectors (H, ⌈W/8⌉) along x, so that LLVM turns each row
operation into SIMD instructions; ring buffers add a leading slot axis.  Lanes past W are padding and
always read as "outside the image".
"""
import taichi as ti

from .loops import thread_span
from .saliency_fields import D_CHUNKS, D_LANES, D_ROWS

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
    """z[s, y, xb] of a frame ring, 0 for xb outside the row (a frame's padding lanes hold 0, and so does the
    vector after a row's last, ``store_frame``'s, in a ring wider than the frame)."""
    v = VEC(0.0)
    if 0 <= xb < z.shape[2]:
        v = z[s, y, xb]
    return v


@ti.func
def positive_row_vector(z: ti.template(), s: ti.i32, y: ti.i32, xb: ti.i32) -> VEC:
    """max(z, 0) at (s, y, xb) of a frame ring, 0 outside the image."""
    return ti.max(frame_vector(z, s, y, xb), 0.0)



@ti.func
def image_dims(f: ti.template()):
    """(rows H, 8-lane vectors per row V) of the frame, read at run time from the fields ``f``
    (:class:`~.saliency_fields.SaliencyFields`; its fields have those extents' size classes)."""
    return f.dims[D_ROWS], f.dims[D_LANES]


@ti.func
def chunk_runs(f: ti.template()) -> ti.i32:
    """The runs of rows the streamed filters split the frame into (``f.dims``; at most the chunk rings' first
    extent)."""
    return f.dims[D_CHUNKS]


@ti.func
def chunk_rows(c: ti.i32, n_chunks: ti.i32, h: ti.i32):
    """Rows [y0, y1) of chunk c when h rows are split into n_chunks near-equal runs."""
    return (c * h) // n_chunks, ((c + 1) * h) // n_chunks


@ti.func
def for_row_chunks(h: ti.i32, halo: ti.template(), n_chunks: ti.i32, serial: ti.template(), body: ti.template(),
                   args: ti.template()):
    """body(c, y, y0, y1, args) for every chunk c of the h rows, [y0, y1) (``chunk_rows``), and each y in
    [y0 − halo, y1 + halo) in order: the streamed filters' walk down the image, one thread a chunk (the first
    iteration of each thread_span-long run of the parallel loop, see ``loops.thread_span``)."""
    span = ti.static(thread_span(serial))
    ti.loop_config(serialize=serial)
    for u in range(n_chunks * span):
        if u % span == 0:
            c = u // span
            y0, y1 = chunk_rows(c, n_chunks, h)
            for y in range(y0 - halo, y1 + halo):
                body(c, y, y0, y1, args)


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
