"""Likelihood ratios of the particle kernels (the seam ``ParticleKernels.likelihood``).

A likelihood model has

* ``constants(psf_sigma, noise_sigma)``: its constants, computed once per launch;
* ``log_ratio(x, y, inten, zp, constants, h, w)``: the log-likelihood ratio (target present against noise
  alone) of one E = 1 particle at (x, y) px with intensity ``inten`` on the normalised frame ``zp``, which has a
  zero border of ``PAD`` pixels ((h + 2·PAD, w + 2·PAD); h, w the frame's size, run-time values: the pool's
  ``frame_hw`` field in the particle kernels, arguments in ``kernels/handover.py``).

The pool keeps what is not the model's: log-weight 0 for E = 0 particles, the maxima and the normalisation.

Seams to come: a pixel-integrated PSF, a clutter-whitened template correlation, a histogram similarity:
each another class with the same two methods.
"""
import math

import taichi as ti

PAD = 4  # zero border of the frame the weights read: a 5×5 window (Eq. 15) that touches the image stays inside it

TWO_PI = 2.0 * math.pi


@ti.data_oriented
class PointPSFLikelihood:
    """Eq. 15's log-likelihood ratio of a point target imaged by the Gaussian PSF of Eq. 14 in white Gaussian
    noise of standard deviation σ, over the 5×5 window around the particle."""

    @ti.func
    def samples(self, d0: ti.f32, inv2s2: ti.f32, step: ti.f32, p0: ti.i32, size: ti.i32):
        """Eq. 14 along one axis: g_k = exp(−(d0 + k)²/(2Σ²)) for k = 0…4 (0 where pixel p0 + k is outside
        [0, size)), from g_0 and the ratio r_k = g_{k+1}/g_k = exp(−(2(d0 + k) + 1)/(2Σ²)) = r_0·step^k,
        step = exp(−2/(2Σ²)): two exponentials instead of five, a few f32 ulps apart."""
        g = ti.Vector([0.0] * 5, dt=ti.f32)
        gk = ti.exp(-d0 * d0 * inv2s2)
        r = ti.exp(-(ti.f32(2.0) * d0 + ti.f32(1.0)) * inv2s2)
        for k in ti.static(range(5)):
            g[k] = gk if 0 <= p0 + k < size else ti.f32(0.0)
            gk *= r
            r *= step
        return g

    @ti.func
    def constants(self, psf_sigma: ti.f32, noise_sigma: ti.f32):
        """Eqs. 14–15's constants from Σ (px) and σ: 1/(2Σ²), 1/(2πΣ²), 1/σ² and :meth:`samples`' ratio step
        exp(−2/(2Σ²))."""
        inv2s2 = ti.f32(1.0) / (ti.f32(2.0) * psf_sigma * psf_sigma)
        norm = ti.f32(1.0) / (ti.f32(TWO_PI) * psf_sigma * psf_sigma)
        return inv2s2, norm, ti.f32(1.0) / (noise_sigma * noise_sigma), ti.exp(ti.f32(-2.0) * inv2s2)

    @ti.func
    def log_ratio(self, x: ti.f32, y: ti.f32, inten: ti.f32, zp: ti.template(), constants: ti.template(),
                  h: ti.template(), w: ti.template(), row0: ti.i32 = 0) -> ti.f32:
        """Eq. 15 in the log domain: log ω̃ = Σ_{5×5} h(2z − h)/(2σ²) with
        h = I/(2πΣ²)·exp(−((i−x)² + (j−y)²)/(2Σ²)) (Eq. 14), over the in-image pixels of the 5×5 window around
        (⌊x+½⌋, ⌊y+½⌋).  The Gaussian is separable, h = a·gx·gy, so Σh² = a²·Σgx²·Σgy²; each axis's five
        samples come from two exponentials (:meth:`samples`).  ``constants``: those of :meth:`constants`; ``row0``:
        the bordered frame's first row in ``zp`` (frames stacked one above the other)."""
        inv2s2, norm, inv_var, step = constants
        cx = ti.cast(ti.floor(x + 0.5), ti.i32)
        cy = ti.cast(ti.floor(y + 0.5), ti.i32)
        gx = self.samples(ti.cast(cx - 2, ti.f32) - x, inv2s2, step, cx - 2, w)
        gy = self.samples(ti.cast(cy - 2, ti.f32) - y, inv2s2, step, cy - 2, h)
        # first window row/column in the padded frame; outside pixels read the zero
        # border (and their g is 0), so the sum needs no branches.  A window that
        # misses the image (g all 0) is clamped to one that does not overflow.
        r0 = ti.min(ti.max(cy, -2), h + 1) + PAD - 2 + row0
        c0 = ti.min(ti.max(cx, -2), w + 1) + PAD - 2
        sz = ti.f32(0.0)
        for j in ti.static(range(5)):
            row = ti.f32(0.0)
            for k in ti.static(range(5)):
                row += gx[k] * zp[r0 + j, c0 + k]
            sz += gy[j] * row
        a = inten * norm
        return (a * sz - ti.f32(0.5) * a * a * gx.dot(gx) * gy.dot(gy)) * inv_var
