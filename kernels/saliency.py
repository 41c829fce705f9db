"""Multi-frame saliency extraction (SGDS-PF Eqs. 20–33) as Taichi kernels.

Image buffers are ring fields of shape (slots, H, W); kernels take the slot as an
argument, so each kernel compiles once.  Every kernel runs in IEEE f32 (the runtime
is started with fast_math off) and sums in a fixed order, so the NumPy twin
``tbd_taichi.numpy_kernels.saliency`` reproduces the same bits except after exp().

Border rule (both engines): out-of-image pixels are ignored by the max filters and
contribute 0 to the sums (the 3×3 energy sum and the 5×5 correlation).  All maxed
quantities are ≥ 0, so for them the two readings agree.
"""
import taichi as ti

NEG_INF = -3.0e38


@ti.kernel
def load_slot(src: ti.types.ndarray(dtype=ti.f32, ndim=2), dst: ti.template(), s: ti.i32):
    """dst[s] = src (a host frame into a ring slot)."""
    for y, x in ti.ndrange(src.shape[0], src.shape[1]):
        dst[s, y, x] = src[y, x]


@ti.func
def clipped(src: ti.template(), s: ti.i32, y: ti.i32, x: ti.i32) -> ti.f32:
    """max(src[s, y, x], 0), or 0 outside the image."""
    v = ti.f32(0.0)
    if 0 <= y < src.shape[1] and 0 <= x < src.shape[2]:
        v = ti.max(src[s, y, x], ti.f32(0.0))
    return v


@ti.kernel
def energy_collection(z: ti.template(), zs: ti.i32, out: ti.template(), os: ti.i32, r: ti.template()):
    """Eqs. 20–21 on p = max(z, 0): I_se = p·Σ_{(2r+1)²} p / max_{(2r+1)²} p, 0 where the max is 0.

    Normalised frames are zero-mean; the literal Eq. 21 would reward neg×neg products
    and divide by a negative maximum, so negative pixels count as no energy.
    """
    for y, x in ti.ndrange(z.shape[1], z.shape[2]):
        total = ti.f32(0.0)
        peak = ti.f32(0.0)
        for dy, dx in ti.static(ti.ndrange((-r, r + 1), (-r, r + 1))):
            v = clipped(z, zs, y + dy, x + dx)
            total += v
            peak = ti.max(peak, v)
        centre = ti.max(z[zs, y, x], ti.f32(0.0))
        out[os, y, x] = centre * total / peak if peak > 0 else ti.f32(0.0)


@ti.kernel
def max_filter(src: ti.template(), ss: ti.i32, dst: ti.template(), ds: ti.i32, r: ti.template()):
    """(2r+1)×(2r+1) maximum over the in-image neighbours (Eq. 20's operator).

    Indices are clamped to the image: a repeated edge pixel is an in-image neighbour,
    so the maximum equals the in-image-only maximum, without branches.
    """
    h, w = src.shape[1], src.shape[2]
    for y in range(h):
        for x in range(w):
            m = src[ss, y, x]
            for dy, dx in ti.static(ti.ndrange((-r, r + 1), (-r, r + 1))):
                m = ti.max(m, src[ss, ti.min(ti.max(y + dy, 0), h - 1), ti.min(ti.max(x + dx, 0), w - 1)])
            dst[ds, y, x] = m


@ti.kernel
def sum_slots(src: ti.template(), a: ti.i32, b: ti.i32, c: ti.i32, scale: ti.f32, dst: ti.template(), ds: ti.i32):
    """Eq. 22: dst = ((src[a] + src[b]) + src[c])·scale, skipping slots given as −1."""
    for y, x in ti.ndrange(src.shape[1], src.shape[2]):
        v = ti.f32(0.0)
        if a >= 0:
            v += src[a, y, x]
        if b >= 0:
            v += src[b, y, x]
        if c >= 0:
            v += src[c, y, x]
        dst[ds, y, x] = v * scale


@ti.kernel
def row_moments(src: ti.template(), s: ti.i32, out: ti.template()):
    """Per row y: out[y] = (Σ v, Σ v²) in f64, summed left to right (deterministic)."""
    for y in range(src.shape[1]):
        s1 = ti.cast(0.0, ti.f64)
        s2 = ti.cast(0.0, ti.f64)
        for x in range(src.shape[2]):
            v = ti.cast(src[s, y, x], ti.f64)
            s1 += v
            s2 += v * v
        out[y, 0] = s1
        out[y, 1] = s2


@ti.func
def correlate_d(z: ti.template(), zs: ti.i32, d: ti.template(), y: ti.i32, x: ti.i32) -> ti.f32:
    """(z ⋆ D)(y, x) over the 5×5 window, zero outside the image (Eq. 27's B·σ²)."""
    acc = ti.f32(0.0)
    for dy, dx in ti.static(ti.ndrange(5, 5)):
        yy, xx = y + dy - 2, x + dx - 2
        v = ti.f32(0.0)
        if 0 <= yy < z.shape[1] and 0 <= xx < z.shape[2]:
            v = z[zs, yy, xx]
        acc += d[dy, dx] * v
    return acc


@ti.func
def lef_log_weight(b: ti.f32, a: ti.f32, i_min: ti.f32, i_max: ti.f32) -> ti.f32:
    """Eqs. 27–28: max over I in [i_min, i_max] of −A·I² + B·I, at I_c = clamp(B/(2A))."""
    ic = ti.min(ti.max(b / (ti.f32(2.0) * a), i_min), i_max)
    return b * ic - a * (ic * ic)


@ti.kernel
def lef_map(z: ti.template(), zs: ti.i32, d: ti.template(), inv_var: ti.f32, a: ti.f32, i_min: ti.f32,
            i_max: ti.f32, out: ti.template()):
    """Likelihood estimation filter (Eqs. 25–28) at every pixel: log ω̌_lef."""
    for y, x in out:
        out[y, x] = lef_log_weight(correlate_d(z, zs, d, y, x) * inv_var, a, i_min, i_max)


@ti.kernel
def correlate_map(z: ti.template(), zs: ti.i32, d: ti.template(), out: ti.template()):
    """z ⋆ D at every pixel (zero padding)."""
    for y, x in out:
        out[y, x] = correlate_d(z, zs, d, y, x)


@ti.kernel
def reset_blocks(block_max: ti.template(), block_sum: ti.template(), block_sum2: ti.template(),
                 block_nnz: ti.template(), block_op: ti.template()):
    """Zero the per-block accumulators (one launch for all blocks)."""
    for b in block_max:
        block_max[b] = NEG_INF
        block_sum[b] = 0.0
        block_sum2[b] = 0.0
        block_nnz[b] = 0
        block_op[b] = 0.0


@ti.kernel
def segment_and_lef(acc2: ti.template(), threshold: ti.f64, acc: ti.template(), acc_max: ti.template(),
                    s: ti.i32, z: ti.template(), zs: ti.i32, d: ti.template(), inv_var: ti.f32, a: ti.f32,
                    i_min: ti.f32, i_max: ti.f32, block_id: ti.template(), block_offset: ti.template(),
                    mask: ti.template(), proposal: ti.template(), block_max: ti.template(),
                    block_nnz: ti.template(), entry_pixel: ti.template(), entry_logw: ti.template()):
    """Eqs. 23–24 and 27–29 per pixel, and the list of candidate pixels per block.

    I_rt = [I_acc2 > T_acc2] ∧ [I_acc == I_acc_max]; at I_rt pixels log Sal = log ω̌_lef
    is appended to its block's slab and the block maximum is updated (atomic max).
    """
    for y, x in mask:
        proposal[y, x] = 0.0
        keep = ti.cast(acc2[0, y, x], ti.f64) > threshold and acc[s, y, x] == acc_max[s, y, x]
        mask[y, x] = ti.cast(keep, ti.i32)
        if keep:
            lw = lef_log_weight(correlate_d(z, zs, d, y, x) * inv_var, a, i_min, i_max)
            b = block_id[y, x]
            ti.atomic_max(block_max[b], lw)
            slot = ti.atomic_add(block_nnz[b], 1)
            entry_pixel[block_offset[b] + slot] = y * mask.shape[1] + x
            entry_logw[block_offset[b] + slot] = lw


@ti.kernel
def block_saliency(block_offset: ti.template(), block_nnz: ti.template(), block_max: ti.template(),
                   entry_logw: ti.template(), entry_sal: ti.template(), block_sum: ti.template(),
                   block_sum2: ti.template(), max_area: ti.i32):
    """Sal = exp(log Sal − block max) and the block sums Σ Sal, Σ Sal² in f64 (for Eq. 30)."""
    for b, i in ti.ndrange(block_nnz.shape[0], max_area):
        if i < block_nnz[b]:
            e = block_offset[b] + i
            sal = ti.exp(entry_logw[e] - block_max[b])
            entry_sal[e] = sal
            s = ti.cast(sal, ti.f64)
            block_sum[b] += s
            block_sum2[b] += s * s


@ti.func
def rank_limit(s1: ti.f64, s2: ti.f64, nnz: ti.i32) -> ti.i32:
    """Eqs. 30–31: k = clamp(floor(N_eff + ½), 1, nnz) with N_eff = (Σ Sal)² / Σ Sal²."""
    neff = s1 * s1 / s2
    return ti.min(ti.max(ti.cast(ti.floor(neff + 0.5), ti.i32), 1), nnz)


@ti.kernel
def eliminate_low_weight(block_offset: ti.template(), block_nnz: ti.template(), block_sum: ti.template(),
                         block_sum2: ti.template(), entry_logw: ti.template(), entry_sal: ti.template(),
                         entry_keep: ti.template(), block_op: ti.template(), max_area: ti.i32):
    """Eqs. 31–32: keep a pixel iff fewer than k pixels of its block have a larger saliency.

    That is Sal ≥ T_ep with T_ep the k-th largest value.  Ranks compare log Sal, which is
    exactly reproducible, and stop counting at k.
    """
    for b, i in ti.ndrange(block_nnz.shape[0], max_area):
        n = block_nnz[b]
        if i < n:
            k = rank_limit(block_sum[b], block_sum2[b], n)
            off = block_offset[b]
            mine = entry_logw[off + i]
            greater = 0
            j = 0
            while j < n and greater < k:
                if entry_logw[off + j] > mine:
                    greater += 1
                j += 1
            keep = greater < k
            entry_keep[off + i] = ti.cast(keep, ti.i32)
            if keep:
                block_op[b] += ti.cast(entry_sal[off + i], ti.f64)


@ti.kernel
def write_proposal(block_offset: ti.template(), block_nnz: ti.template(), block_op: ti.template(),
                   entry_pixel: ti.template(), entry_sal: ti.template(), entry_keep: ti.template(),
                   proposal: ti.template(), max_area: ti.i32):
    """Eq. 33: OPsal_N = OPsal / Σ_block OPsal at the kept pixels (the rest stay 0)."""
    for b, i in ti.ndrange(block_nnz.shape[0], max_area):
        if i < block_nnz[b]:
            e = block_offset[b] + i
            if entry_keep[e]:
                p = entry_pixel[e]
                proposal[p // proposal.shape[1], p % proposal.shape[1]] = ti.cast(
                    ti.cast(entry_sal[e], ti.f64) / block_op[b], ti.f32)
