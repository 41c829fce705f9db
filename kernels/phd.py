"""Particle PHD track-before-detect kernels (Long et al. 2012, MM-PHD TBD): one particle pool for a detector and
its trackers, each filter a *group* of consecutive slots; every step is one launch for all groups given.

Slot layout (the scheduler's, ``tbd_taichi.methods.mm_phd``): group g owns slots [start_g, start_g + len_g); the
detector, group 0, comes first and its newborn slots are the last of its segment.  A particle is the 7-D state of ``tbd_taichi.motion_models``
(x, ẋ, y, ẏ, I, ẍ, ÿ; px, px/s, px/s²), a model index r and a PHD weight w.

Steps (Eq. numbers of the paper):

* :meth:`PhdKernels.propagate`: survivors switch model by Π (Eq. 31, Ξ = Π by Eq. 34) and move by
  X ← F^(r) X + √s_g·L^(r)·n (Eq. 1; F⁻¹ in the backward recursion, Eq. 26), w ← e·w (Eq. 33 with q = f);
  births are uniform over the thresholded cells, U[−V_max, V_max] velocity, U[I_min, I_max] intensity, r ~ β and
  w = γ/J (Eqs. 28–30, 32–34);
* :meth:`PhdKernels.likelihood`: the most influenced cell (Eq. 17) and the log-likelihood ratio over the
  window |i − i0| ≤ ⌊3Σ⌋ (Eqs. 13, 18) of the pixel-integrated PSF (Eq. 4, closed form with :func:`erf`);
* :meth:`PhdKernels.update`: Ψ per (group, cell) (Eqs. 15–16), w̃ = ℓw/(λ + Ψ) (Eq. 14), n̂ = Σ w̃ (Eq. 19)
  and the cumulative resampling weights, ∝ ℓ (Eq. 24) or ∝ w̃, and on request each group's class estimate in
  the same launch (:meth:`PhdKernels.estimate_group`: w̃-weighted mean, covariance and model probabilities,
  Eqs. 20, 35);
* :meth:`PhdKernels.resample`: systematic resampling of each group to its L_g particles of weight n̂_g/L_g
  (Eqs. 20, 24), written compacted to new segments of the second buffer, the next propagate's input;
* :meth:`PhdKernels.mask`: Eq. 36's detector frame, I_0 over the windows of the tracked targets.

Sums within a group run serially in one thread (groups in parallel), so results do not depend on the thread
count.  Random numbers are the counter-based ones of ``kernels.rng`` keyed on (seed, frame key, stream, slot).
The NumPy twin is ``tbd_taichi.numpy_kernels.phd``.
"""
import math

import numpy as np
import taichi as ti

from .loops import FrameSize, in_corner, light_ir, thread_span
from .particles.layout import first_above
from .rng import NormalTables, SharedTables, key_prefix, normals_at, table_field, uniform_at

DIM = 7
MAX_MODELS = 4
BETA_ROW = MAX_MODELS  # the row of model_cdf holding β
LOG_ZERO = -1.0e30  # log ℓ of a particle outside the image
# the update's scale: ℓ' = e^(log ℓ − s) with s = min(group's largest log ℓ, log λ + SHIFT_MAX), log ℓ − s
# capped at RATIO_CAP, so exact up to log ℓ = log λ + 150 (f32: λe^(−s) ≥ e^(−80) stays normal, so no denominator
# λe^(−s) + Ψ' is 0; a weak cell keeps its ℓ beside a very bright one; a sum of ℓ' over 2·10⁶ particles ≤ 5·10³⁶)
SHIFT_MAX, RATIO_CAP = 80.0, 70.0
S_SWITCH, S_NOISE = 0, 1  # streams: model switch; the 7 process-noise normals are streams 1…7
S_CELL, S_X, S_Y, S_VX, S_VY, S_I, S_MODEL = 8, 9, 10, 11, 12, 13, 14  # birth draws
S_RESAMPLE = 15
BIRTH_WIDTH = 6  # the birth field: survival e, V_max, I_min, I_max, newborn weight γ/J, intensity floor
RESAMPLE_CHUNK = 64  # outputs per thread's walk in resample
# (row, column) of the entries of F, F⁻¹ (F_SUPPORT) and L (L_SUPPORT) that can be non-zero in any of the models
# cv, c-ct, ac-ct, ca of tbd_taichi.motion_models (checked there by tests/test_mm_phd_kernels.py): the propagation
# multiplies only these, 17 and 13 of the 49
F_SUPPORT = ((0, 0), (0, 1), (0, 3), (0, 5), (1, 1), (1, 3), (1, 5), (2, 1), (2, 2), (2, 3), (2, 6), (3, 1), (3, 3),
             (3, 6), (4, 4), (5, 5), (6, 6))
L_SUPPORT = ((0, 0), (1, 0), (1, 1), (2, 2), (3, 2), (3, 3), (4, 4), (5, 0), (5, 1), (5, 5), (6, 2), (6, 3), (6, 6))
SQRT_HALF = 0.7071067811865476
GROUP_INT = ("start", "length", "frame", "out_start", "out_len", "out_id")
GROUP_FLOAT = ("qscale", "out_weight", "cx", "cy", "radius")
START, LENGTH, FRAME, OUT_START, OUT_LEN, OUT_ID = range(len(GROUP_INT))
QSCALE, OUT_WEIGHT, CX, CY, RADIUS = range(len(GROUP_FLOAT))
NO_CENTRE = -1.0e6  # cx of a group whose class is centred on its peak cell
N_HAT, TOTAL, TOP = 0, 1, 2  # columns of gout: n̂, resampling total, the largest cell mass
EST_MEAN, EST_COV, EST_PROB = 0, DIM, DIM + DIM * DIM  # columns of est: mean (7), covariance (7×7), P_r (4)
EST_MASS = EST_PROB + MAX_MODELS  # the PHD mass Σw̃ of the class (Eq. 19 over the class)
EST_PEAK = EST_MASS + 1  # the PHD mass Ψ/(λ + Ψ) of the class's peak cell
EST_WIDTH = EST_PEAK + 1
_NP = {ti.f32: np.float32, ti.i32: np.int32}


ERF_STEPS = 1024  # erf's table points per unit of x
ERF_END = 4.0  # erf(x) = 1 in f32 for |x| ≥ this (1 − erf(4) = 1.5·10⁻⁸ < half an f32 ulp of 1)


def erf_table_values() -> np.ndarray:
    """erf(k/ERF_STEPS) for k = 0 … ERF_END·ERF_STEPS + 1 (math.erf, rounded to f32): :func:`erf`'s table."""
    return np.array([math.erf(k / ERF_STEPS) for k in range(int(ERF_END * ERF_STEPS) + 2)], np.float32)


@ti.data_oriented
class ErfTable(SharedTables):
    """:func:`erf`'s table as a field (``values``)."""

    def __init__(self):
        self.values = table_field(erf_table_values(), ti.f32)


@ti.func
def erf(x: ti.f32, table: ti.template()) -> ti.f32:
    """erf(x), odd in x, by linear interpolation in ``table`` (:class:`ErfTable`'s values) at steps h = 1/1024:
    |error| ≤ h²/8·max|erf''| = 1.2·10⁻⁷ plus f32 rounding, 1 for |x| ≥ ERF_END.  Taichi has no erf; a table
    read costs a third of Abramowitz & Stegun 7.1.26 (an exponential and a division)."""
    a = ti.min(ti.abs(x) * ti.f32(ERF_STEPS * 1.0), ti.f32(ERF_END * ERF_STEPS))
    i = ti.cast(a, ti.i32)
    lo = table[i]
    y = lo + (a - ti.cast(i, ti.f32)) * (table[i + 1] - lo)
    return ti.select(x < 0, -y, y)


PIXEL_FIELDS = ("raw", "masked", "cells")  # the per-pixel fields ``put`` fills from the start (cell y·W + x)


@ti.data_oriented
class PhdKernels(FrameSize):
    """The pool's fields (``capacity`` slots, ``max_groups`` groups) and its steps, for frames of ``shape``'s size
    class.  The per-pixel fields (the frames, the birth cells, Ψ) are one-dimensional, ``pixels`` entries (the
    class's) holding a frame row after row at its own width (cell y·W + x), and the kernels read the frame's (H, W)
    from ``frame_hw`` (``FrameSize``), so one compiled set serves every frame size of the class."""

    def __init__(self, capacity: int, max_groups: int, shape, serial: bool = False):
        rows, columns = self.frame_size_field(shape)
        self.capacity, self.max_groups, self.pixels = int(capacity), int(max_groups), rows * columns
        c, g = self.capacity, self.max_groups
        self.state = ti.field(ti.f32, (c, DIM))
        self.state2 = ti.field(ti.f32, (c, DIM))
        self.model, self.model2 = ti.field(ti.i32, c), ti.field(ti.i32, c)
        self.group, self.group2 = ti.field(ti.i32, c), ti.field(ti.i32, c)
        self.weight, self.weight2 = ti.field(ti.f32, c), ti.field(ti.f32, c)
        self.loglik, self.wtilde, self.cdf = ti.field(ti.f32, c), ti.field(ti.f32, c), ti.field(ti.f32, c)
        self.cellmass = ti.field(ti.f32, c)
        self.cell = ti.field(ti.i32, c)
        # group tables (columns GROUP_INT, GROUP_FLOAT): input segment, frame (0 raw, 1 masked), output segment
        # and new id; Q scale s_g, output weight, gate centre and radius; results n̂_g, total_g; estimates (EST_*)
        self.gint, self.gflt = ti.field(ti.i32, (g, len(GROUP_INT))), ti.field(ti.f32, (g, len(GROUP_FLOAT)))
        self.gout = ti.field(ti.f32, (g, 3))
        self.est = ti.field(ti.f32, (g, EST_WIDTH))
        self.psi = ti.field(ti.f32, (g, self.pixels))
        self.raw, self.masked = ti.field(ti.f32, self.pixels), ti.field(ti.f32, self.pixels)  # cell y·W + x
        self.cells = ti.field(ti.i32, self.pixels)
        self.F, self.F_inv, self.L = (ti.field(ti.f32, (MAX_MODELS, DIM, DIM)) for _ in range(3))
        # rows 0…MAX_MODELS−1: cumulative Π rows (Eq. 39); row BETA_ROW: cumulative β (Eq. 28)
        self.model_cdf = ti.field(ti.f32, (MAX_MODELS + 1, MAX_MODELS))
        self.birth = ti.field(ti.f32, BIRTH_WIDTH)  # (e, V_max, I_min, I_max, γ/J, I_floor): propagate's
        self.tables, self.erf_table = NormalTables.shared(), ErfTable.shared()
        self.span = thread_span(serial)

    # ------------------------------------------------------------------ propagate (Eqs. 1, 26, 28–34)

    @light_ir
    @ti.kernel
    def propagate(self, seed: ti.u32, frame_key: ti.u32, total: ti.i32, backward: ti.i32, n_cells: ti.i32,
                  first_birth: ti.i32, n_births: ti.i32):
        """Slots [0, total): survivors, read from the second buffer (the resampled pool, :meth:`resample` and
        :meth:`load`), switch model and move (``backward`` ≠ 0: by F⁻¹, Eq. 26), w ← e·w, into the first; the
        newborn slots [first_birth, first_birth + n_births) join group 0 (the detector) and draw Eqs. 28–30's
        births over ``cells[0:n_cells]``.  The ``birth`` field holds (e, V_max, I_min, I_max,
        γ/J, I_floor); V_max in px/s; a survivor's intensity is kept ≥ I_floor."""
        survive, vmax, i_min, i_max = self.birth[0], self.birth[1], self.birth[2], self.birth[3]
        w_birth, i_floor = self.birth[4], self.birth[5]
        k_switch = key_prefix(seed, frame_key, S_SWITCH)
        keys = [key_prefix(seed, frame_key, S_NOISE + d) for d in ti.static(range(DIM))]
        kb = [key_prefix(seed, frame_key, s) for s in ti.static(range(S_CELL, S_MODEL + 1))]
        for p in range(total):
            if first_birth <= p < first_birth + n_births:
                self.group[p] = 0
                c = self.cells[ti.min(ti.cast(uniform_at(kb[0], p) * n_cells, ti.i32), n_cells - 1)]
                self.state[p, 0] = ti.cast(c % self.frame_hw[1], ti.f32) - 0.5 + uniform_at(kb[1], p)
                self.state[p, 2] = ti.cast(c // self.frame_hw[1], ti.f32) - 0.5 + uniform_at(kb[2], p)
                self.state[p, 1] = vmax * (2.0 * uniform_at(kb[3], p) - 1.0)
                self.state[p, 3] = vmax * (2.0 * uniform_at(kb[4], p) - 1.0)
                self.state[p, 4] = i_min + (i_max - i_min) * uniform_at(kb[5], p)
                self.state[p, 5] = 0.0
                self.state[p, 6] = 0.0
                self.model[p] = self.draw(BETA_ROW, uniform_at(kb[6], p))
                self.weight[p] = w_birth
            else:
                g = self.group2[p]
                self.group[p] = g
                r = self.draw(self.model2[p], uniform_at(k_switch, p))
                self.model[p] = r
                n = normals_at(self.tables.w, self.tables.k, self.tables.phi, keys, p)
                x = ti.Vector([self.state2[p, d] for d in ti.static(range(DIM))], dt=ti.f32)
                fx = ti.Vector([0.0] * DIM, dt=ti.f32)
                if backward != 0:  # a statement, not a conditional expression: only one product is computed
                    fx = self.transition(self.F_inv, r, x)
                else:
                    fx = self.transition(self.F, r, x)
                ln = self.transition(self.L, r, n, L_SUPPORT)
                s = ti.sqrt(self.gflt[g, QSCALE])
                for i in ti.static(range(DIM)):
                    acc = fx[i] + s * ln[i]
                    self.state[p, i] = ti.max(acc, i_floor) if i == 4 else acc
                self.weight[p] = self.weight2[p] * survive

    @ti.func
    def transition(self, matrices: ti.template(), r: ti.i32, v, support: ti.template() = F_SUPPORT):
        """M^(r)·v for the 7×7 matrices M^(r) of ``matrices``, over the entries of ``support`` only (the
        structural non-zeros of every model's F, F⁻¹ or L)."""
        out = ti.Vector([0.0] * DIM, dt=ti.f32)
        for e in ti.static(support):
            out[e[0]] += matrices[r, e[0], e[1]] * v[e[1]]
        return out

    @ti.func
    def draw(self, row: ti.i32, u: ti.f32) -> ti.i32:
        """The first model j with model_cdf[row, j] > u: a switch by Π's row ``row`` or a birth's by β."""
        out = -1
        for j in ti.static(range(MAX_MODELS)):
            if out < 0 and u < self.model_cdf[row, j]:
                out = j
        return ti.max(out, 0)

    # ------------------------------------------------------------------ likelihood (Eqs. 4, 13, 17, 18)

    @light_ir
    @ti.kernel
    def likelihood(self, first: ti.i32, count: ti.i32, half: ti.template(), psf_sigma: ti.f32,
                   masked: ti.template()):
        """Slots [first, first + count), weighed on the masked frame (``masked`` = 1) or the raw one (0): the most
        influenced cell (row·W + col of the pixel holding (x, y), Eq. 17; −1 outside the image) and log ℓ =
        Σ_window h(z − h/2) (Eq. 13 with σ_n = 1 on the normalised frame) over |col − col0|, |row − row0| ≤
        ``half`` = ⌊3Σ⌋ (Eq. 18), pixels outside the image left out; h is Eq. 4's pixel integral, h = I·fx·fy
        (:meth:`fractions`)."""
        scale = ti.f32(SQRT_HALF) / psf_sigma
        for p in range(first, first + count):
            if ti.static(masked == 1):
                self.weigh_particle(p, self.masked, half, scale)
            else:
                self.weigh_particle(p, self.raw, half, scale)

    @ti.func
    def weigh_particle(self, p: ti.i32, frame: ti.template(), half: ti.template(), scale: ti.f32):
        """:meth:`likelihood` of slot p on ``frame``; windows clear of the border skip the per-pixel checks."""
        h, w = self.frame_hw[0], self.frame_hw[1]
        x, y, inten = self.state[p, 0], self.state[p, 2], self.state[p, 4]
        col = ti.cast(ti.floor(x + 0.5), ti.i32)
        row = ti.cast(ti.floor(y + 0.5), ti.i32)
        if 0 <= col < w and 0 <= row < h:
            fx = self.fractions(col, x, scale, half)
            fy = self.fractions(row, y, scale, half)
            acc = ti.f32(0.0)
            if half <= col < w - half and half <= row < h - half:
                for a, b in ti.static(ti.ndrange(2 * half + 1, 2 * half + 1)):
                    hv = inten * fx[b] * fy[a]
                    acc += hv * (frame[(row + a - half) * w + col + b - half] - 0.5 * hv)
            else:
                for a in ti.static(range(2 * half + 1)):
                    r = row + a - half
                    if 0 <= r < h:
                        for b in ti.static(range(2 * half + 1)):
                            c = col + b - half
                            if 0 <= c < w:
                                hv = inten * fx[b] * fy[a]
                                acc += hv * (frame[r * w + c] - 0.5 * hv)
            self.cell[p] = row * w + col
            self.loglik[p] = acc
        else:
            self.cell[p] = -1
            self.loglik[p] = LOG_ZERO

    @ti.func
    def fractions(self, centre: ti.i32, pos: ti.f32, scale: ti.f32, half: ti.template()):
        """Eq. 4 along one axis for the 2·half + 1 pixels around ``centre``: ½[erf(edge_{k+1}) − erf(edge_k)] from
        the 2·half + 2 pixel edges' erf (each edge shared by two pixels; the twin's ``pixel_fraction`` takes the
        two per pixel)."""
        e = ti.Vector([erf((ti.cast(centre + k, ti.f32) - 0.5 - pos) * scale, self.erf_table.values)
                       for k in ti.static(range(-half, half + 2))], dt=ti.f32)
        return ti.Vector([0.5 * (e[k + 1] - e[k]) for k in ti.static(range(2 * half + 1))], dt=ti.f32)

    # ------------------------------------------------------------------ update (Eqs. 14–16, 19, 24)

    @light_ir
    @ti.kernel
    def update(self, first_group: ti.i32, n_groups: ti.i32, lam: ti.f32, on_likelihood: ti.i32, th: ti.f32,
               miss: ti.f32, radius: ti.f32):
        """Groups [first_group, first_group + n_groups), each in one thread.  The measurements are the cells of
        the group's frame with z ≥ ``th`` (§5.1's pre-segmentation; λ = 1 − Φ(Th) is their false-alarm rate).
        With s = min(the group's largest log ℓ, log λ + SHIFT_MAX) and ℓ' = e^(min(log ℓ − s, RATIO_CAP)):
        Ψ'[cell] = Σ w·ℓ' over the group's particles of that measurement cell (Eqs. 15–16), w̃ = wℓ'/(λe^(−s) + Ψ') = ℓw/(λ + Ψ)
        (Eq. 14; exact below the cap, log ℓ ≤ s + RATIO_CAP, at least log λ + 150), and w̃ = ``miss``·w
        (1 − p_d, a missed detection) for a particle whose cell is no measurement; n̂ = Σ w̃ (Eq. 19), cdf =
        cumulative ℓ' (Eq. 24, ×``miss`` off the measurements; ``on_likelihood`` = 0: cumulative w̃) and total =
        its last value; cellmass = the PHD mass Ψ/(λ + Ψ) of the particle's cell and top its largest value.  Ψ is
        cleared afterwards.  ``radius`` > 0: then each group's class estimate (:meth:`estimate_group`), in the
        same thread."""
        span = ti.static(self.span)
        for it in range(n_groups * span):
            if it % span == 0:
                g = first_group + it // span
                self.update_group(g, lam, on_likelihood, th, miss)
                if radius > 0.0:
                    self.estimate_group(g, radius)

    @ti.func
    def update_group(self, g: ti.i32, lam: ti.f32, on_likelihood: ti.i32, th: ti.f32, miss: ti.f32):
        """:meth:`update` for group g, in this thread."""
        a, b = self.segment(g)
        m = ti.f32(LOG_ZERO)
        for p in range(a, b):
            m = ti.max(m, self.loglik[p])
        m = ti.min(m, ti.log(lam) + SHIFT_MAX)
        src = self.gint[g, FRAME]
        for p in range(a, b):  # ℓ' kept in cdf until the next pass overwrites it
            if self.measured(self.cell[p], src, th):
                lk = self.scaled_ratio(p, m)
                self.cdf[p] = lk
                self.psi[g, self.cell[p]] += self.weight[p] * lk
            elif self.cell[p] >= 0 and on_likelihood != 0:
                self.cdf[p] = self.scaled_ratio(p, m)
        lam_m = lam * ti.exp(ti.min(-m, 80.0))
        n_hat, cum, top = ti.f32(0.0), ti.f32(0.0), ti.f32(0.0)
        for p in range(a, b):
            wt, rho, mass = ti.f32(0.0), ti.f32(0.0), ti.f32(0.0)
            if self.measured(self.cell[p], src, th):
                lk = self.cdf[p]
                psi = self.psi[g, self.cell[p]]
                mass = psi / (lam_m + psi)
                wt = self.weight[p] * lk / (lam_m + psi)
                rho = lk if on_likelihood != 0 else wt
            elif self.cell[p] >= 0:
                wt = miss * self.weight[p]
                rho = miss * self.cdf[p] if on_likelihood != 0 else wt
            self.wtilde[p] = wt
            self.cellmass[p] = mass
            top = ti.max(top, mass)
            n_hat += wt
            cum += rho
            self.cdf[p] = cum
        for p in range(a, b):
            if self.cell[p] >= 0:
                self.psi[g, self.cell[p]] = 0.0
        self.gout[g, N_HAT] = n_hat
        self.gout[g, TOTAL] = cum
        self.gout[g, TOP] = top

    @ti.func
    def scaled_ratio(self, p: ti.i32, shift: ti.f32) -> ti.f32:
        """ℓ' = e^(min(log ℓ − shift, RATIO_CAP)) of particle p (:meth:`update`'s scale)."""
        return ti.exp(ti.min(self.loglik[p] - shift, RATIO_CAP))

    @ti.func
    def segment(self, g: ti.i32):
        """Group g's slots [a, b)."""
        return self.gint[g, START], self.gint[g, START] + self.gint[g, LENGTH]

    @ti.func
    def measured(self, cell: ti.i32, src: ti.i32, th: ti.f32) -> ti.i32:
        """Whether ``cell`` (row·W + col; −1 outside) is a measurement: z ≥ th on frame ``src`` (0 raw, 1 masked)."""
        out = 0
        if cell >= 0:
            zv = self.masked[cell] if src == 1 else self.raw[cell]
            out = ti.cast(zv >= th, ti.i32)
        return out

    # ------------------------------------------------------------------ estimate (Eqs. 20, 35)

    @ti.func
    def estimate_group(self, g: ti.i32, radius: ti.f32):
        """Group g's class estimate, in this thread (:meth:`update` with ``radius`` > 0): the target's class (§3.1)
        is the particles within ``radius`` px (per axis) of the centre of the cell of largest PHD mass Ψ/(λ + Ψ)
        among the group's particles inside its gate (within gflt's RADIUS of (CX, CY); every particle when CX is
        NO_CENTRE).  Writes the class's mass Σw̃, its w̃-weighted mean and covariance and each model's w̃ share
        (Eq. 35's L_{k,r}/L_k in expectation over the resampling); a class with Σw̃ = 0 uses equal weights, an
        empty one gives mass 0 and a zero mean."""
        w = self.frame_hw[1]
        a, b = self.segment(g)
        gx, gy, gate = self.gflt[g, CX], self.gflt[g, CY], self.gflt[g, RADIUS]
        best, peak = ti.f32(-1.0), -1
        for p in range(a, b):
            inside = gx <= NO_CENTRE or (ti.abs(self.state[p, 0] - gx) <= gate
                                         and ti.abs(self.state[p, 2] - gy) <= gate)
            if self.cell[p] >= 0 and inside and self.cellmass[p] > best:
                best, peak = self.cellmass[p], self.cell[p]
        cx, cy = ti.cast(peak % w, ti.f32), ti.cast(peak // w, ti.f32)
        sw, n_in = ti.f32(0.0), 0
        for p in range(a, b):
            if peak >= 0 and self.near(p, cx, cy, radius):
                sw += self.wtilde[p]
                n_in += 1
        flat = sw <= 0.0
        norm = ti.f32(1.0) / ti.select(flat, ti.cast(ti.max(n_in, 1), ti.f32), sw)
        mean = ti.Vector([0.0] * DIM, dt=ti.f32)
        probs = ti.Vector([0.0] * MAX_MODELS, dt=ti.f32)
        for p in range(a, b):
            if peak >= 0 and self.near(p, cx, cy, radius):
                wp = ti.select(flat, 1.0, self.wtilde[p]) * norm
                for d in ti.static(range(DIM)):
                    mean[d] += wp * self.state[p, d]
                for r in ti.static(range(MAX_MODELS)):
                    if self.model[p] == r:
                        probs[r] += wp
        cov = ti.Matrix.zero(ti.f32, DIM, DIM)
        for p in range(a, b):
            if peak >= 0 and self.near(p, cx, cy, radius):
                wp = ti.select(flat, 1.0, self.wtilde[p]) * norm
                dv = ti.Vector([self.state[p, d] - mean[d] for d in ti.static(range(DIM))], dt=ti.f32)
                cov += wp * dv.outer_product(dv)
        for i in ti.static(range(DIM)):
            self.est[g, EST_MEAN + i] = mean[i]
            for j in ti.static(range(DIM)):
                self.est[g, EST_COV + DIM * i + j] = cov[i, j]
        for r in ti.static(range(MAX_MODELS)):
            self.est[g, EST_PROB + r] = probs[r]
        self.est[g, EST_MASS] = sw
        self.est[g, EST_PEAK] = ti.max(best, 0.0)

    @ti.func
    def near(self, p: ti.i32, cx: ti.f32, cy: ti.f32, radius: ti.f32):
        """Whether slot p lies within ``radius`` px per axis of (cx, cy)."""
        return ti.abs(self.state[p, 0] - cx) <= radius and ti.abs(self.state[p, 2] - cy) <= radius

    # ------------------------------------------------------------------ resample (Eqs. 20, 24)

    @ti.kernel
    def resample(self, seed: ti.u32, frame_key: ti.u32, n_groups: ti.i32, max_out: ti.i32):
        """Systematic resampling: output j of group g is the first slot of g's segment whose cdf exceeds
        (j + u_g)/L_g·total_g (u_g ~ U(0, 1) keyed on g; total_g = 0: the segment taken evenly), copied to slot
        out_start_g + j of the second buffer with weight out_weight_g and group out_id_g.  The outputs run in
        chunks of RESAMPLE_CHUNK, in parallel: a chunk's first output is found by binary search, the next ones
        by walking on from it (the points rise with j), a step or two each instead of a search.  ``max_out`` must
        be at least every group's L_g."""
        key = key_prefix(seed, frame_key, S_RESAMPLE)
        for g, c in ti.ndrange(n_groups, (max_out + RESAMPLE_CHUNK - 1) // RESAMPLE_CHUNK):
            n_out = self.gint[g, OUT_LEN]
            a, n = self.gint[g, START], self.gint[g, LENGTH]
            total, u = self.gout[g, TOTAL], uniform_at(key, g)
            src = -1
            for j in range(c * RESAMPLE_CHUNK, ti.min((c + 1) * RESAMPLE_CHUNK, n_out)):
                if total > 0.0:
                    target = (ti.cast(j, ti.f32) + u) / ti.cast(n_out, ti.f32) * total
                    if src < 0:
                        src = first_above(self.cdf, a, a + n - 1, target)
                    while src < a + n - 1 and self.cdf[src] <= target:
                        src += 1
                else:
                    src = a + (j * n) // n_out
                o = self.gint[g, OUT_START] + j
                for d in ti.static(range(DIM)):
                    self.state2[o, d] = self.state[src, d]
                self.model2[o] = self.model[src]
                self.weight2[o] = self.gflt[g, OUT_WEIGHT]
                self.group2[o] = self.gint[g, OUT_ID]

    # ------------------------------------------------------------------ mask (Eq. 36)

    @ti.kernel
    def mask(self, first_group: ti.i32, n_groups: ti.i32, half: ti.i32, value: ti.f32):
        """masked = raw with ``value`` (I_0) over the (2·half + 1)² window around the pixel of the estimated
        position (est's x, y) of each group in [first_group, first_group + n_groups) (Eq. 36)."""
        h, w = self.frame_hw[0], self.frame_hw[1]
        for i in range(h * w):
            self.masked[i] = self.raw[i]
        for t, a, b in ti.ndrange(n_groups, 2 * half + 1, 2 * half + 1):
            g = first_group + t
            r = ti.cast(ti.floor(self.est[g, EST_MEAN + 2] + 0.5), ti.i32) + a - half
            c = ti.cast(ti.floor(self.est[g, EST_MEAN] + 0.5), ti.i32) + b - half
            if 0 <= r < h and 0 <= c < w:
                self.masked[r * w + c] = value

    # ------------------------------------------------------------------ host transfers

    def slots(self, start: int, count: int) -> dict:
        """Copies of slots [start, start + count): state, model, w̃ and cell mass."""
        out = {"state": np.zeros((count, DIM), np.float32), "model": np.zeros(count, np.int32),
               "wtilde": np.zeros(count, np.float32), "cellmass": np.zeros(count, np.float32)}
        if count > 0:
            self.copy_slots(start, out["state"], out["model"], out["wtilde"], out["cellmass"])
        return out

    @ti.kernel
    def copy_slots(self, start: ti.i32, state: ti.types.ndarray(dtype=ti.f32, ndim=2),
                   model: ti.types.ndarray(dtype=ti.i32, ndim=1), wtilde: ti.types.ndarray(dtype=ti.f32, ndim=1),
                   cellmass: ti.types.ndarray(dtype=ti.f32, ndim=1)):
        """state, model, w̃, cell mass ← slots [start, start + len(model))."""
        for p in range(model.shape[0]):
            for d in ti.static(range(DIM)):
                state[p, d] = self.state[start + p, d]
            model[p] = self.model[start + p]
            wtilde[p] = self.wtilde[start + p]
            cellmass[p] = self.cellmass[start + p]

    def put(self, name: str, values) -> None:
        """Field ``name`` ← ``values`` of its shape; a per-pixel field (PIXEL_FIELDS) takes a frame (H, W) or
        table, row after row, into its leading entries (zeros past them)."""
        field = getattr(self, name)
        values = np.asarray(values, dtype=_NP[field.dtype])
        field.from_numpy(in_corner(values.ravel(), tuple(field.shape)) if name in PIXEL_FIELDS else values)

    def get(self, name: str) -> np.ndarray:
        """A copy of field ``name``."""
        return getattr(self, name).to_numpy()

    @ti.kernel
    def load(self, offset: ti.i32, state: ti.types.ndarray(dtype=ti.f32, ndim=2),
             model: ti.types.ndarray(dtype=ti.i32, ndim=1), weight: ti.f32, group: ti.i32):
        """Slots [offset, offset + n) of the second buffer (the next :meth:`propagate`'s input) ← the n rows of
        ``state`` and ``model``, weight ``weight``, group ``group``."""
        for p in range(state.shape[0]):
            for d in ti.static(range(DIM)):
                self.state2[offset + p, d] = state[p, d]
            self.model2[offset + p] = model[p]
            self.weight2[offset + p] = weight
            self.group2[offset + p] = group
