"""Background suppression, local noise and bad-pixel kernels (issue 7), on ndarrays.

Every kernel takes (H, W) float32 ndarrays (NumPy arrays on the CPU), so it compiles once
per process whatever the image size, and a template flag ``serial`` (one compiled variant
each): row loops on one thread, for images where a parallel launch costs more than the work.
The NumPy twin is ``tbd_taichi.numpy_kernels.background``.  Borders are replicated (the nearest pixel
inside the image), as in ``cv2.BORDER_REPLICATE`` and ``scipy.ndimage`` mode "nearest".
Running sums are f64, rounded to f32 once.
"""
import taichi as ti

F2 = ti.types.ndarray(dtype=ti.f32, ndim=2)


@ti.func
def pixel(line: ti.i32, k: ti.i32, along_rows: ti.template()):
    """(row, column) of element k of row ``line`` (along_rows) or of column ``line``."""
    return (line, k) if ti.static(along_rows) else (k, line)


@ti.func
def running_box_sum(src: ti.template(), dst: ti.template(), r: ti.i32, line: ti.i32, along_rows: ti.template()):
    """dst = Σ_{|d| ≤ r} src at clamp(k + d) along one row or column, as a running f64 sum."""
    n = src.shape[1] if ti.static(along_rows) else src.shape[0]
    acc = ti.f64(0.0)
    for d in range(-r, r + 1):
        acc += ti.f64(src[pixel(line, ti.max(ti.min(d, n - 1), 0), along_rows)])
    for k in range(n):
        dst[pixel(line, k, along_rows)] = ti.cast(acc, ti.f32)
        acc += ti.f64(src[pixel(line, ti.min(k + r + 1, n - 1), along_rows)]) - \
            ti.f64(src[pixel(line, ti.max(k - r, 0), along_rows)])


@ti.kernel
def box_sum_rows(src: F2, dst: F2, r: ti.i32, serial: ti.template()):
    """dst[i, j] = Σ_{|d| ≤ r} src[i, clamp(j + d)]: a (2r+1)-wide running sum along each row."""
    ti.loop_config(serialize=serial)
    for i in range(src.shape[0]):
        running_box_sum(src, dst, r, i, True)


@ti.kernel
def box_sum_cols(src: F2, dst: F2, r: ti.i32, acc: ti.types.ndarray(dtype=ti.f64, ndim=1), serial: ti.template()):
    """dst[i, j] = Σ_{|d| ≤ r} src[clamp(i + d), j]: the column pass of the separable box sum.

    Parallel: one running sum per column.  Serial: the same running sums, one per column in
    ``acc`` (f64, W), advanced a row at a time, so memory is read row by row (the same additions
    in the same order: the same bits)."""
    h, w = src.shape[0], src.shape[1]
    if ti.static(serial):
        ti.loop_config(serialize=True)
        for _ in range(1):
            for j in range(w):
                acc[j] = ti.f64(0.0)
            for d in range(-r, r + 1):
                for j in range(w):
                    acc[j] += ti.f64(src[ti.max(ti.min(d, h - 1), 0), j])
            for k in range(h):
                lo, hi = ti.max(k - r, 0), ti.min(k + r + 1, h - 1)
                for j in range(w):
                    dst[k, j] = ti.cast(acc[j], ti.f32)
                    acc[j] += ti.f64(src[hi, j]) - ti.f64(src[lo, j])
    else:
        for j in range(w):
            running_box_sum(src, dst, r, j, False)


@ti.kernel
def hollow_residual(x: F2, outer: F2, inner: F2, n_outer: ti.f32, n_inner: ti.f32, out: F2, serial: ti.template()):
    """x minus the mean of the ring between two box sums (outer minus inner window), raw units."""
    ti.loop_config(serialize=serial)
    for i in range(x.shape[0]):
        for j in range(x.shape[1]):
            out[i, j] = x[i, j] - (outer[i, j] - inner[i, j]) / (n_outer - n_inner)


@ti.kernel
def running_residual(x: F2, bg: F2, alpha: ti.f32, first: ti.i32, out: F2, serial: ti.template()):
    """Temporal background: out = x − B, then B ← B + α(x − B); B = x on the first frame."""
    ti.loop_config(serialize=serial)
    for i in range(x.shape[0]):
        for j in range(x.shape[1]):
            if first:
                bg[i, j] = x[i, j]
            out[i, j] = x[i, j] - bg[i, j]
            bg[i, j] = bg[i, j] + alpha * (x[i, j] - bg[i, j])


@ti.kernel
def rebase_background(s: F2, prev_r: F2, bg: F2, serial: ti.template()):
    """bg = s − prev_r: after a global change (codec keyframe, gain step) the change is taken as
    background, so the residual s − bg carries the previous frame's foreground over."""
    ti.loop_config(serialize=serial)
    for i in range(s.shape[0]):
        for j in range(s.shape[1]):
            bg[i, j] = s[i, j] - prev_r[i, j]


@ti.kernel
def row_abs_difference_sums(a: F2, b: F2, out: ti.types.ndarray(dtype=ti.f64, ndim=1), serial: ti.template()):
    """out[i] = Σ_j |a[i, j] − b[i, j]| in f64, one row per thread (the caller sums the rows in a
    fixed order, so the total does not depend on the thread count)."""
    ti.loop_config(serialize=serial)
    for i in range(a.shape[0]):
        acc = ti.f64(0.0)
        for j in range(a.shape[1]):
            acc += ti.abs(ti.f64(a[i, j]) - ti.f64(b[i, j]))
        out[i] = acc


@ti.kernel
def clipped_abs(r: F2, clip: ti.f32, out: F2, serial: ti.template()):
    """min(|r|, clip): the robust input of the local noise estimate."""
    ti.loop_config(serialize=serial)
    for i in range(r.shape[0]):
        for j in range(r.shape[1]):
            out[i, j] = ti.min(ti.abs(r[i, j]), clip)


@ti.kernel
def standardise(r: F2, abs_sum: F2, n: ti.f32, to_sigma: ti.f32, floor: ti.f32, out: F2, serial: ti.template()):
    """z = r / max(to_sigma · abs_sum / n, floor): residual over the local noise σ."""
    ti.loop_config(serialize=serial)
    for i in range(r.shape[0]):
        for j in range(r.shape[1]):
            out[i, j] = r[i, j] / ti.max(to_sigma * abs_sum[i, j] / n, floor)


@ti.kernel
def isolated_spikes(z: F2, rate: F2, rho: ti.f32, z_hi: ti.f32, ratio: ti.f32, rate_max: ti.f32, out: F2,
                    serial: ti.template()):
    """Bad pixels: a pixel is a spike when |z| > z_hi and every 8-neighbour has |z| < ratio·|z|
    (a point target's PSF lights its neighbours); rate ← (1−ρ)·rate + ρ·spike; out = 0 where
    rate > rate_max (a persistent outlier: hot, dead or blinking), else z."""
    h, w = z.shape[0], z.shape[1]
    ti.loop_config(serialize=serial)
    for i in range(z.shape[0]):
        for j in range(z.shape[1]):
            a = ti.abs(z[i, j])
            spike = 0.0
            if a > z_hi:  # rare: only then look at the neighbours
                neighbours = 0.0
                for di, dj in ti.static(ti.ndrange((-1, 2), (-1, 2))):
                    if ti.static(di != 0 or dj != 0):
                        ii, jj = i + di, j + dj
                        if 0 <= ii < h and 0 <= jj < w:
                            neighbours = ti.max(neighbours, ti.abs(z[ii, jj]))
                if neighbours < ratio * a:
                    spike = 1.0
            rate[i, j] = (1.0 - rho) * rate[i, j] + rho * spike
            out[i, j] = z[i, j]
            if rate[i, j] > rate_max:
                out[i, j] = 0.0
