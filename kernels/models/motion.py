"""Motion models of the particle kernels (the seam ``ParticleKernels.motion``).

A motion model has

* ``noise_factors(q1, q2)``: the constants of its process noise, computed once per launch;
* ``step(x, vx, y, vy, inten, n, factors, i_floor)``: one particle's state after one frame (T = 1), given five
  standard normal draws ``n`` (the pool's streams ``NOISE_STREAMS``: n1 … n5) and those constants; returns
  (x, vx, y, vy, inten).  Positions in px, velocities in px/frame, intensity in the units of Eq. 14.

The pool keeps what is not the model's: which particles move (E = 1 and not newborn, or copied newborns),
Tp ← Tp + 1, and E ← 0 for a particle that leaves the image.

Seams to come: a coordinated-turn model (MM-PHD), white-noise acceleration (Bruno), a random-walk drift
(Güler): each another class with the same two methods (a model needing more than five normals also needs
more noise streams in ``kernels.particles.layout``).
"""
import taichi as ti


@ti.data_oriented
class NearlyConstantVelocity:
    """Nearly constant velocity, Eqs. 9–10 with the process noise Q of Eq. 46 (T = 1), and a random walk of the
    intensity floored at ``i_floor``."""

    @ti.func
    def noise_factors(self, q1: ti.f32, q2: ti.f32):
        """Cholesky factor of Eq. 46's NCV noise (T = 1: [[q1/3, q1/2], [q1/2, q1]]) per axis, c11, c21, c22,
        and √q2 of the intensity walk (q1 in px²/frame³, q2 in intensity² per frame)."""
        return ti.sqrt(q1 / ti.f32(3.0)), ti.sqrt(q1) * ti.f32(0.8660254037844386), ti.sqrt(q1) * ti.f32(0.5), \
            ti.sqrt(q2)

    @ti.func
    def step(self, x: ti.f32, vx: ti.f32, y: ti.f32, vy: ti.f32, inten: ti.f32, n: ti.template(),
             factors: ti.template(), i_floor: ti.f32):
        """Eqs. 9–10: x ← x + vx + c11·n1, vx ← vx + c21·n1 + c22·n2 (y, vy likewise with n3, n4),
        I ← max(I + √q2·n5, i_floor); ``factors`` = (c11, c21, c22, √q2) of :meth:`noise_factors`."""
        c11, c21, c22, sq2 = factors
        n1, n2, n3, n4, n5 = n
        return x + vx + c11 * n1, vx + (c21 * n1 + c22 * n2), y + vy + c11 * n3, vy + (c21 * n3 + c22 * n4), \
            ti.max(inten + sq2 * n5, i_floor)
