"""Background suppression, local noise and bad-pixel kernels (issue 7), on ndarrays.

Every kernel takes (H, W) float32 ndarrays (NumPy arrays on the CPU), so it compiles once
per process whatever the image size, and a template flag ``serial`` (one compiled variant
each): row loops on one thread, for images where a parallel launch costs more than the work.
The separable box sums run as a row pass and a column pass, and each column pass finishes its
pixel in the same launch (the hollow residual; the local noise and z), so a frame of the
``spatiotemporal`` background takes seven launches.
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
def window_term(src: ti.template(), at, clip: ti.f32, clipped: ti.template()):
    """src[at] as f64, or min(|src[at]|, clip) where ``clipped``."""
    v = src[at]
    if ti.static(clipped):
        v = ti.min(ti.abs(v), clip)
    return ti.f64(v)


@ti.func
def window_start(src: ti.template(), r: ti.i32, line: ti.i32, along_rows: ti.template(), clip: ti.f32,
                 clipped: ti.template()):
    """Σ_{|d| ≤ r} src at clamp(d) along one row or column: the running sum before its first element."""
    n = src.shape[1] if ti.static(along_rows) else src.shape[0]
    acc = ti.f64(0.0)
    for d in range(-r, r + 1):
        acc += window_term(src, pixel(line, ti.max(ti.min(d, n - 1), 0), along_rows), clip, clipped)
    return acc


@ti.func
def window_step(src: ti.template(), r: ti.i32, line: ti.i32, k: ti.i32, along_rows: ti.template(), clip: ti.f32,
                clipped: ti.template()):
    """What the running sum gains moving from element k to k + 1: src at clamp(k + r + 1) − src at clamp(k − r)."""
    n = src.shape[1] if ti.static(along_rows) else src.shape[0]
    return window_term(src, pixel(line, ti.min(k + r + 1, n - 1), along_rows), clip, clipped) - \
        window_term(src, pixel(line, ti.max(k - r, 0), along_rows), clip, clipped)


@ti.func
def running_box_sum(src: ti.template(), dst: ti.template(), r: ti.i32, line: ti.i32, along_rows: ti.template(),
                    clip: ti.f32, clipped: ti.template()):
    """dst = Σ_{|d| ≤ r} src (or min(|src|, clip)) at clamp(k + d) along one row or column, as a running f64 sum."""
    n = src.shape[1] if ti.static(along_rows) else src.shape[0]
    acc = window_start(src, r, line, along_rows, clip, clipped)
    for k in range(n):
        dst[pixel(line, k, along_rows)] = ti.cast(acc, ti.f32)
        acc += window_step(src, r, line, k, along_rows, clip, clipped)


@ti.func
def column_sweep(image: ti.template(), rows_a: ti.template(), rows_b: ti.template(), state: ti.template(),
                 out: ti.template(), acc: ti.template(), p: ti.template(), start: ti.template(),
                 at_pixel: ti.template(), serial: ti.template()):
    """The column pass of separable window sums: ``start(…, j)`` sets column j's running sums in ``acc`` (f64,
    (2, W)), ``at_pixel(…, k, j)`` uses and advances them at row k.  Parallel: one column per thread.  Serial:
    all columns advanced a row at a time, so memory is read row by row (the same additions in the same order:
    the same bits)."""
    h, w = image.shape[0], image.shape[1]
    if ti.static(serial):
        ti.loop_config(serialize=True)
        for _ in range(1):
            for j in range(w):
                start(image, rows_a, rows_b, state, out, acc, p, j)
            for k in range(h):
                for j in range(w):
                    at_pixel(image, rows_a, rows_b, state, out, acc, p, k, j)
    else:
        for j in range(w):
            start(image, rows_a, rows_b, state, out, acc, p, j)
            for k in range(h):
                at_pixel(image, rows_a, rows_b, state, out, acc, p, k, j)


@ti.kernel
def ring_row_sums(x: F2, rows_outer: F2, rows_inner: F2, r_outer: ti.i32, r_inner: ti.i32, serial: ti.template()):
    """The row pass of the hollow window's two box sums: rows_outer[i, j] = Σ_{|d| ≤ r_outer} x[i, clamp(j + d)],
    rows_inner likewise with r_inner."""
    ti.loop_config(serialize=serial)
    for i in range(x.shape[0]):
        running_box_sum(x, rows_outer, r_outer, i, True, 0.0, False)
        running_box_sum(x, rows_inner, r_inner, i, True, 0.0, False)


@ti.func
def ring_start(x: ti.template(), rows_outer: ti.template(), rows_inner: ti.template(), unused: ti.template(),
               out: ti.template(), acc: ti.template(), radii: ti.template(), j: ti.i32):
    acc[0, j] = window_start(rows_outer, radii[0], j, False, 0.0, False)
    acc[1, j] = window_start(rows_inner, radii[1], j, False, 0.0, False)


@ti.func
def ring_pixel(x: ti.template(), rows_outer: ti.template(), rows_inner: ti.template(), unused: ti.template(),
               out: ti.template(), acc: ti.template(), radii: ti.template(), k: ti.i32, j: ti.i32):
    ring = ti.static(float((2 * radii[0] + 1) ** 2 - (2 * radii[1] + 1) ** 2))
    out[k, j] = x[k, j] - (ti.cast(acc[0, j], ti.f32) - ti.cast(acc[1, j], ti.f32)) / ring
    acc[0, j] += window_step(rows_outer, radii[0], j, k, False, 0.0, False)
    acc[1, j] += window_step(rows_inner, radii[1], j, k, False, 0.0, False)


@ti.kernel
def hollow_residual(x: F2, rows_outer: F2, rows_inner: F2, radii: ti.template(),
                    acc: ti.types.ndarray(dtype=ti.f64, ndim=2), out: F2, serial: ti.template()):
    """out = x minus the mean of the ring between the (2·radii[0]+1)² and (2·radii[1]+1)² boxes around each pixel
    (raw units): the column pass over ``ring_row_sums``' rows, each box sum rounded to f32 before the difference.
    ``radii`` = (outer, inner), a tuple of ints fixed at compile time (the ring's pixel count folds into a constant)."""
    column_sweep(x, rows_outer, rows_inner, x, out, acc, radii, ring_start, ring_pixel, serial)


@ti.kernel
def clipped_abs_row_sums(r: F2, clip: ti.f32, rows: F2, radius: ti.i32, serial: ti.template()):
    """rows[i, j] = Σ_{|d| ≤ radius} min(|r[i, clamp(j + d)]|, clip): the row pass of the local noise window."""
    ti.loop_config(serialize=serial)
    for i in range(r.shape[0]):
        running_box_sum(r, rows, radius, i, True, clip, True)


@ti.func
def noise_start(r: ti.template(), rows: ti.template(), unused: ti.template(), noise: ti.template(),
                out: ti.template(), acc: ti.template(), p: ti.template(), j: ti.i32):
    acc[0, j] = window_start(rows, ti.cast(p[0], ti.i32), j, False, 0.0, False)


@ti.func
def noise_pixel(r: ti.template(), rows: ti.template(), unused: ti.template(), noise: ti.template(),
                out: ti.template(), acc: ti.template(), p: ti.template(), k: ti.i32, j: ti.i32):
    radius = ti.cast(p[0], ti.i32)
    alpha, to_sigma, floor = ti.cast(p[1], ti.f32), ti.cast(p[3], ti.f32), ti.cast(p[4], ti.f32)
    abs_sum = ti.cast(acc[0, j], ti.f32)
    if p[2] != 0.0:  # first frame: the running mean starts at this frame's value
        noise[k, j] = abs_sum
    noise[k, j] = noise[k, j] + alpha * (abs_sum - noise[k, j])
    out[k, j] = r[k, j] / ti.max(to_sigma * noise[k, j] / ti.f32((2 * radius + 1) ** 2), floor)
    acc[0, j] += window_step(rows, radius, j, k, False, 0.0, False)


@ti.kernel
def standardise(r: F2, rows: F2, noise: F2, p: ti.types.ndarray(dtype=ti.f64, ndim=1),
                acc: ti.types.ndarray(dtype=ti.f64, ndim=2), out: F2, serial: ti.template()):
    """z = r / max(to_sigma · N / n, floor), N the running mean (N ← N + α(S − N); N = S where ``first``) of the
    window's clipped |r| sum S: the column pass over ``clipped_abs_row_sums``' rows.  p = (radius, α, first,
    to_sigma, floor); n = (2·radius + 1)².  With first = 1, N = S exactly (a frame's own local σ)."""
    column_sweep(r, rows, rows, noise, out, acc, p, noise_start, noise_pixel, serial)


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
