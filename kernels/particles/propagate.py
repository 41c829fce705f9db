"""Steps 1–2 of the particle filter: existence (Eqs. 7–8), newborn and initial draws (Eq. 34, with the top-up
of Eq. 35) and propagation of existing particles (Eqs. 9–10).
"""
import taichi as ti

from ..rng import key_prefix, normals_at, uniform_at, uniform_f64_at
from .layout import BIRTH_STREAMS, COPY_TRIES, NOISE_STREAMS, S_EXIST, TWO_PI, first_above


@ti.data_oriented
class PropagateMixin:
    """Steps 1–2 over the pool (Eqs. 7–10, 34)."""

    @ti.func
    def existence_rates(self, g: ti.i32, args: ti.template()):
        return self.pb[g], self.pd[g]

    @ti.func
    def existence_step(self, i: ti.i32, g: ti.i32, rates: ti.template(), args: ti.template()):
        """Eqs. 7–8 for slot i: E ← [u ≥ P_d] if E = 1, [u < P_b] if E = 0; ``born`` marks 0 → 1."""
        key, b = args
        pb, pd = rates
        u = uniform_at(key, i)
        e0 = self.e[b, i]
        e1 = 0
        if e0 == 1:
            e1 = ti.cast(u >= pd, ti.i32)
        else:
            e1 = ti.cast(u < pb, ti.i32)
        self.born[i] = ti.cast(e0 == 0 and e1 == 1, ti.i32)
        self.e[b, i] = e1

    @ti.func
    def predict_existence(self, seed: ti.u32, frame: ti.i32, b: ti.i32):
        """Step 1, Eqs. 7–8, for every live particle."""
        self.for_slots(False, self.existence_rates, self.existence_step, (key_prefix(seed, frame, S_EXIST), b))

    @ti.func
    def map_entry_draw(self, g: ti.i32, v: ti.f64) -> ti.i32:
        """First entry of group g's proposal list whose cumulative weight exceeds v (binary search)."""
        return first_above(self.map_cdf, self.map_off[g], self.map_off[g] + self.map_n[g] - 1, v)

    @ti.func
    def first_added_slot(self, g: ti.i32, args: ti.template()) -> ti.i32:
        return self.off[g] + self.n_before[g]

    @ti.func
    def mark_if_added(self, i: ti.i32, g: ti.i32, first: ti.i32, args: ti.template()):
        if i >= first:
            self.born[i] = 2

    @ti.func
    def mark_initial(self):
        """Slots added since n_before (the top-up of Eq. 35) become initial particles (born = 2).  On the
        CPU a loop per group over its added slots alone (usually none)."""
        if ti.static(self.flat):
            self.for_slots(False, self.first_added_slot, self.mark_if_added, ())
        else:
            ti.loop_config(serialize=self.serial)
            for g in range(self.n.shape[0]):
                for i in range(self.first_added_slot(g, ()), self.off[g] + self.n[g]):
                    self.born[i] = 2

    @ti.func
    def draw_newborn(self, seed: ti.u32, frame: ti.i32, b: ti.i32, width: ti.i32):
        """Step 2 for newborn (born = 1, E 0 → 1) and initial (born = 2) particles (Eq. 34).

        kind 0: position uniform over [bx0, bx1) × [by0, by1); kind 1: a pixel drawn from the
        group's proposal map plus U(−½, ½) in x and y, and Seq the PP label of that pixel (Eq. 36); with
        an empty map the particle cannot be placed and gets E = 0.  Speed U[0, vmax] in a uniform
        direction, intensity U[imin, imax], Tp = 1; initial particles draw E = [U < μ].
        kind 2 (tracking PFs): a copy of a random E = 1 particle of the same group (E = 0 if
        none is found), propagated afterwards like an existing particle.
        """
        keys = [key_prefix(seed, frame, st) for st in ti.static(BIRTH_STREAMS)]
        self.for_slots(False, self.no_group_values, self.newborn_draw, (keys, b, width))

    @ti.func
    def newborn_draw(self, i: ti.i32, g: ti.i32, _: ti.template(), args: ti.template()):
        """``draw_newborn`` for slot i (newborns are few, so their group's values are loaded here)."""
        keys, b, width = args
        kx, ky, ks, ka, ki, kp, km, kc = keys
        if self.born[i] >= 1:
            k = self.kind[g]
            if k == 2:
                found = -1
                for t in range(COPY_TRIES):
                    u = uniform_at(kc, i * COPY_TRIES + t)
                    j = self.off[g] + ti.min(ti.cast(u * ti.cast(self.n[g], ti.f32), ti.i32), self.n[g] - 1)
                    if found < 0 and self.e[b, j] == 1 and self.born[j] == 0:
                        found = j
                if found >= 0:
                    self.copy_state(b, found, b, i)
                    self.e[b, i] = 1
                else:
                    self.e[b, i] = 0
            elif k == 1 and self.map_n[g] == 0:
                self.e[b, i] = 0
            else:
                ux = uniform_at(kx, i)
                uy = uniform_at(ky, i)
                if k == 0:
                    self.x[b, i] = self.bx0[g] + (self.bx1[g] - self.bx0[g]) * ux
                    self.y[b, i] = self.by0[g] + (self.by1[g] - self.by0[g]) * uy
                else:
                    m = self.map_entry_draw(g, uniform_f64_at(kp, i) * self.map_total[g])
                    p = self.map_pixel[m]
                    self.x[b, i] = ti.cast(p % width, ti.f32) + (ux - ti.f32(0.5))
                    self.y[b, i] = ti.cast(p // width, ti.f32) + (uy - ti.f32(0.5))
                    self.seq[b, i] = self.map_seq[m]
                speed = self.vmax[g] * uniform_at(ks, i)
                angle = ti.f32(TWO_PI) * uniform_at(ka, i)
                self.vx[b, i] = speed * ti.cos(angle)
                self.vy[b, i] = speed * ti.sin(angle)
                self.inten[b, i] = self.imin[g] + (self.imax[g] - self.imin[g]) * uniform_at(ki, i)
                self.tp[b, i] = 1
                if self.born[i] == 2:
                    self.e[b, i] = ti.cast(uniform_at(km, i) < self.mu[g], ti.i32)

    @ti.func
    def propagate(self, seed: ti.u32, frame: ti.i32, b: ti.i32, q1: ti.f32, q2: ti.f32, i_floor: ti.f32,
                  width: ti.i32, height: ti.i32):
        """Step 2 for existing particles (E 1 → 1, and copied newborns of kind 2), Eqs. 9–10: NCV plus
        Cholesky-factored noise of Q (Eq. 46, T = 1), I ← max(I + √q2·n, i_floor) (the motion model
        ``self.motion``), Tp ← Tp + 1.  A particle whose position leaves the image (x ∉ [−½, W−½))
        gets E = 0."""
        c11, c21, c22, sq2 = self.motion.noise_factors(q1, q2)
        keys = [key_prefix(seed, frame, st) for st in ti.static(NOISE_STREAMS)]
        self.for_slots(False, self.copies_newborns, self.propagate_slot,
                       (keys, (c11, c21, c22, sq2, i_floor), b, width, height))

    @ti.func
    def copies_newborns(self, g: ti.i32, args: ti.template()) -> ti.i32:
        """Whether group g's newborns are copies (kind 2), which are propagated like existing particles."""
        return self.kind[g] == 2

    @ti.func
    def propagate_slot(self, i: ti.i32, g: ti.i32, copies: ti.i32, args: ti.template()):
        """``propagate`` for slot i: the motion model's step on five normals (streams NOISE_STREAMS)."""
        keys, noise, b, width, height = args
        c11, c21, c22, sq2, i_floor = noise
        w, k, phi = ti.static(self.normal.w, self.normal.k, self.normal.phi)
        if self.e[b, i] == 1 and (self.born[i] == 0 or copies):
            n1, n2, n3, n4, n5 = normals_at(w, k, phi, keys, i)
            x, vx, y, vy, inten = self.motion.step(self.x[b, i], self.vx[b, i], self.y[b, i], self.vy[b, i],
                                                   self.inten[b, i], (n1, n2, n3, n4, n5), (c11, c21, c22, sq2),
                                                   i_floor)
            # plain stores: ``field[i] += v`` is Taichi's atomic add, a locked compare-and-swap loop in a
            # parallel CPU task (the split step), though no other thread writes slot i
            self.x[b, i] = x
            self.y[b, i] = y
            self.vx[b, i] = vx
            self.vy[b, i] = vy
            self.inten[b, i] = inten
            self.tp[b, i] = self.tp[b, i] + 1
            if x < -0.5 or x >= width - 0.5 or y < -0.5 or y >= height - 0.5:
                self.e[b, i] = 0

    @ti.kernel
    def predict(self, frame: ti.i32, b: ti.i32, counts: ti.types.ndarray(dtype=ti.i32, ndim=1)):
        """Steps 1–2 in one launch (see ``predict_particles``), with the pool's constants (``step_values``)."""
        self.predict_particles(self.step_values(frame, b), counts)

    @ti.func
    def predict_particles(self, values: ti.template(), counts: ti.template()):
        """Steps 1–2: existence (Eqs. 7–8), live counts ← ``counts`` with the added slots as initial
        particles (Eq. 35), newborn and initial draws, propagation (Eqs. 9–10); ``values``: ``step_values``."""
        seed, frame, b, q1, q2, i_floor, width, height, _, _ = values
        self.predict_existence(seed, frame, b)
        self.store_counts(counts)
        self.mark_initial()
        self.draw_newborn(seed, frame, b, width)
        self.propagate(seed, frame, b, q1, q2, i_floor, width, height)
