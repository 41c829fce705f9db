"""Eq. 19's per-group sums: P(E), the E = 1 means of the state, mean Tp and the spreads (covariances of all
particles and of the E = 1 particles), added deterministically (tiles serially, groups in tile order, f64).
"""
import taichi as ti

from .layout import M_BEST, N_MOMENTS


@ti.data_oriented
class EstimateMixin:
    """Eq. 19 and the spreads over the pool (``estimates``)."""

    @ti.func
    def tile_sums(self, b: ti.i32):
        """Per tile (serially, in slot order): the sums behind Eq. 19, P(E), mean Tp and the covariances of
        all particles and of the E = 1 particles."""
        self.for_tiles(self.tile_moment_sums, b)

    @ti.func
    def tile_moment_sums(self, t: ti.i32, b: ti.template()):
        """``tile_sums`` for tile t."""
        self.moment_sums(t, b, self.tile_end(t))

    @ti.func
    def moment_sums(self, t: ti.i32, b: ti.i32, end: ti.i32):
        """``tile_sums`` for the slots of tile t before ``end``, in buffer b."""
        acc = ti.Vector([0.0] * N_MOMENTS, dt=ti.f64)
        for i in range(self.tile_start[t], end):
            e = ti.cast(self.e[b, i], ti.f64)
            x = ti.cast(self.x[b, i], ti.f64)
            y = ti.cast(self.y[b, i], ti.f64)
            acc += ti.Vector([1.0, e, e * x, e * ti.cast(self.vx[b, i], ti.f64), e * y,
                              e * ti.cast(self.vy[b, i], ti.f64), e * ti.cast(self.inten[b, i], ti.f64),
                              ti.cast(self.tp[b, i], ti.f64), x, y, x * x, y * y, x * y,
                              e * x * x, e * y * y, e * x * y], dt=ti.f64)
        for k in ti.static(range(N_MOMENTS)):
            self.tile_moments[t, k] = acc[k]

    @ti.kernel
    def estimates(self, b: ti.i32, moments: ti.types.ndarray(dtype=ti.f64, ndim=2)):
        """Per group, the tile sums added in tile order into ``moments`` (G, N_ESTIMATES), and the last weigh's
        largest E = 1 log-weight (column M_BEST)."""
        self.tile_sums(b)
        self.group_moments(moments)

    @ti.func
    def group_moments(self, moments: ti.template()):
        """``estimates``' second part: each group's tile sums, added in tile order."""
        ti.loop_config(serialize=self.serial)
        for g in range(self.off.shape[0]):
            self.group_moment(g, moments)

    @ti.func
    def group_moment(self, g: ti.i32, moments: ti.template()):
        """``group_moments`` for group g."""
        for k in ti.static(range(N_MOMENTS)):
            s = ti.cast(0.0, ti.f64)
            for t in range(self.gt0[g], self.gt1[g]):
                s += self.tile_moments[t, k]
            moments[g, k] = s
        moments[g, M_BEST] = ti.cast(self.best_e[g], ti.f64)
