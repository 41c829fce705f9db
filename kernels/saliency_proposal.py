"""The proposal map from the candidate pixels (SGDS-PF Eqs. 24 and 29–33) as Taichi kernels: candidates
listed per row, then per image block the saliency, N_eff, the k-th largest threshold and the normalised
proposal, copied sparsely to host arrays.
"""
import taichi as ti

from .loops import light_ir
from .saliency_fields import D_BLOCKS, D_WIDTH
from .saliency_lanes import LANES, NEG_INF, ROW_BLOCK, image_dims
from .saliency_lef import correlate_d, lef_log_weight


@ti.func
def candidate_pixels(acc2: ti.template(), acc: ti.template(), acc_max: ti.template(), s: ti.i32, z: ti.template(),
                     valid: ti.template(), d: ti.template(), a: ti.f32, stats: ti.template(),
                     memory: ti.template(), ms: ti.i32, lef_scale: ti.f32, accumulated: ti.template(),
                     row_x: ti.template(), row_logw: ti.template(), row_lef: ti.template(), n_row: ti.template(),
                     serial: ti.template(), dims: ti.template()):
    """Eqs. 24 and 27–29: I_rt = [I_acc2 > T_acc2] ∧ [I_acc == I_acc_max], tested 8 lanes at a time;
    at I_rt pixels log Sal = log ω̌_lef (σ = 1), or, with ``accumulated``, lef_scale·L of the
    multi-frame LEF in memory[ms] (:func:`accumulate_lef`), listed per row (row_x, row_logw) in
    increasing x, with each pixel's log ω̌_lef (Eq. 28) in row_lef (for ICEF's MSW, Eq. 40).  ``dims``: (rows H,
    lane vectors V)."""
    threshold = stats[0]
    i_min = ti.cast(stats[1], ti.f32)
    i_max = ti.cast(stats[2], ti.f32)
    h, lanes = dims
    ti.loop_config(serialize=serial, block_dim=ROW_BLOCK)
    for y in range(h):
        n = 0
        for xb in range(lanes):
            keep = (ti.cast(acc2[0, y, xb], ti.f64) > threshold) & (acc[s, y, xb] == acc_max[s, y, xb]) & \
                (valid[xb] > 0)
            if keep.any():
                lef = lef_log_weight(correlate_d(z, s, d, y, xb, h), a, i_min, i_max)
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
                        written: ti.template(), n_written: ti.template(), row_lef: ti.template(), best: ti.template(),
                        dims: ti.template()):
    """Eqs. 29–33 for every block in one serial launch (blocks are few and I_rt pixels sparse).

    The I_rt pixels are first gathered from the row lists into per-block slabs.  Sal = exp(log Sal − block max); N_eff = (Σ Sal)²/Σ Sal² in f64 (Eq. 30); T_ep is the
    k-th largest log Sal, k = clamp(round(N_eff), 1, nnz) (Eq. 31); pixels with
    log Sal ≥ T_ep keep Sal / Σ kept Sal (Eqs. 32–33).  The previous frame's proposal
    pixels are cleared first; block_stats[b] = (N_eff, k, nnz, Σ kept Sal).  The block
    accumulators are reset for the next frame.  best[i] = (log ω̌_lef, pixel y·W + x) of the I_rt
    pixels with the K = best.shape[0] largest log ω̌_lef, descending (ties in row-major order; NEG_INF
    and −1 where there are fewer).  ``dims``: the frame's (rows H, width W px, blocks).
    """
    ti.loop_config(serialize=True)
    for _ in range(1):
        h, w, n_blocks = dims
        for i in range(n_written[None]):
            p = written[i]
            proposal[p // w, p % w] = 0.0
        n_written[None] = 0
        for i in range(best.shape[0]):
            best[i, 0] = NEG_INF
            best[i, 1] = -1.0
        for y in range(h):  # gather the I_rt pixels into block slabs, rows in order
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
        for b in range(n_blocks):
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
                        proposal[p // w, p % w] = ti.cast(
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
    """The frame's proposal pixels (the ``written`` list, pixels y·W + x of the frame's width W =
    ``proposal_out``'s; ``proposal_out`` arrives zeroed) and ``best`` into host arrays (one serial task: the
    pixels are few)."""
    ti.loop_config(serialize=True)
    for _ in range(1):
        w = proposal_out.shape[1]
        for i in range(n_written[None]):
            y, x = written[i] // w, written[i] % w
            proposal_out[y, x] = proposal[y, x]
        for i in range(best.shape[0]):
            best_out[i, 0] = best[i, 0]
            best_out[i, 1] = best[i, 1]


@light_ir
@ti.kernel
def proposal_from_candidates(f: ti.template(), zs: ti.i32, ms: ti.i32, accumulated: ti.template(),
                             proposal_out: ti.types.ndarray(dtype=ti.f32, ndim=2),
                             best_out: ti.types.ndarray(dtype=ti.f64, ndim=2), reuse: ti.i32):
    """The frame in slot ``zs``, second half: :func:`candidate_pixels`, :func:`proposals_per_block`, and the
    proposal and best list into host arrays (:func:`copy_out_proposal`; with ``reuse``, ``proposal_out``
    holds the last frame's proposal, cleared first by :func:`clear_previous_proposal`), in one launch
    (apart from the first half because one kernel for both compiles much longer for no gain)."""
    h, lanes = image_dims(f)
    candidate_pixels(f.acc2, f.acc, f.acc_max, zs, f.z, f.valid, f.d, f.params32[0], f.stats, f.memory, ms,
                     f.params32[2], accumulated, f.row_x, f.row_logw, f.row_lef, f.n_row, f.serial, (h, lanes))
    clear_previous_proposal(f.written, f.n_written, proposal_out, reuse)
    proposals_per_block(f.row_x, f.row_logw, f.n_row, f.row_base, f.col_block, f.block_offset, f.block_nnz,
                        f.block_max, f.entry_pixel, f.entry_logw, f.entry_sal, f.scratch, f.block_stats, f.proposal,
                        f.written, f.n_written, f.row_lef, f.best, (h, f.dims[D_WIDTH], f.dims[D_BLOCKS]))
    copy_out_proposal(f.proposal, f.written, f.n_written, f.best, proposal_out, best_out)
