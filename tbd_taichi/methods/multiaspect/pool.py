"""The host side of the multiaspect filters: one pool of G groups (filters) of N particles (``kernels.multiaspect``
or its NumPy twin) and the launch order of one frame for the resample-move (§3.2) and auxiliary (§3.3) filters.
It keeps no per-particle state itself."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...engines import frame_kernels
from ...kernels.multiaspect import STATE, SUM_ABSENT, SUM_ASPECT, SUM_X
from ...multiaspect import energy_tables

FILTERS = ("rs", "apf")


@dataclass(frozen=True)
class Presence:
    """One group's §3.4 output: P̂(z = 0), the mean (x, ẋ, y, ẏ) of the present particles (NaN if none) and the
    count of each aspect among them."""

    p_absent: float
    mean: np.ndarray
    aspect_counts: np.ndarray

    @property
    def present(self) -> bool:
        """Eq. 26: decide H₁ (present) iff P̂(z = 0 | y) < ½."""
        return self.p_absent < 0.5

    @property
    def aspect(self) -> int:
        """The most frequent aspect (1..K) among the present particles (the lowest on a tie)."""
        return int(np.argmax(self.aspect_counts)) + 1


class MultiaspectPool:
    """``groups`` filters of ``n`` particles for frames of ``shape``, templates of ``template_shape`` (K, h, w) and
    G, on ``engine``; :meth:`set_templates` before the first step."""

    def __init__(self, shape, template_shape, G: np.ndarray, groups: int, n: int, seed: int, engine: str,
                 arch: str | None = None):
        dims = (int(groups), int(n), tuple(int(v) for v in shape), tuple(int(v) for v in template_shape))
        self.k = frame_kernels(self, engine, "multiaspect", "MultiaspectKernels", dims, shape, arch)
        self.groups, self.n, self.shape, self.seed = int(groups), int(n), tuple(shape), int(seed)
        self.sums = np.zeros((self.groups, SUM_ASPECT + int(template_shape[0])))
        cdf = np.cumsum(G, axis=0).T.copy()  # row j: column j of G, cumulated
        cdf[:, -1] = 1.0
        self.k.put("gcdf", cdf)

    def set_templates(self, templates: np.ndarray) -> None:
        """The (K, h, w) templates a_kl(z) (Eq. 8) and their energy tables (Eq. 12; notes A6)."""
        self.templates = np.asarray(templates, float)
        self.energy = energy_tables(templates, self.shape)
        self.k.set_templates(self.templates, self.energy)

    def start(self, p_absent: float, law: np.ndarray, motion) -> None:
        """Every particle drawn from ``law`` (z = 0 with probability ``p_absent``), which is also f₀ for the steps;
        the motion noise factor (a, b, c)."""
        law = np.asarray(law, np.float32)
        self.k.configure(np.asarray(motion, np.float32), law)
        self.k.init_prior(self.seed, float(p_absent), law)
        self.side = 0  # the side of the kernels' prev holding the particles at n − 1

    def set_frames(self, y: np.ndarray, gmrf: np.ndarray) -> None:
        """The mean-removed frames (G, H, W) and their (β_h, β_v, σ_c²) rows (G, 3); computes d (Eq. 16)."""
        self.k.load(np.ascontiguousarray(y, np.float32), np.ascontiguousarray(gmrf, np.float32))

    def set_births(self, share: float, support: np.ndarray | None = None) -> None:
        """The data-driven birth proposal of each group (:mod:`.births`) from its d and GMRF row, over f₀'s
        ``support`` cells of the extended grid (None: all)."""
        from .births import likelihood_map, proposal

        gpar = self.k.get("gpar").astype(float)
        tables = [proposal(likelihood_map(self.k.d_image(g), self.templates, self.energy, *gpar[g]), share, support)
                  for g in range(self.groups)]
        self.k.put("birth_cdf", np.stack([t[0] for t in tables]))
        self.k.put("birth_lq", np.stack([t[1] for t in tables]))

    def step(self, kind: str, frame: int, p_a: float, coupled: bool, moves: int = 1,
             data_births: bool = False) -> None:
        """One frame of filter ``kind``: rs (§3.2: prior draw, Eq. 18's weights, multinomial resampling, ``moves``
        MH moves from the ancestor's n − 1 state, Eqs. 19–21) or apf (§3.3: a prior draw per particle, Eq. 23's
        first-stage weights, auxiliary indices, a fresh draw, Eq. 24's weights, post-sampling selection).
        ``data_births``: entering targets are drawn from :meth:`set_births`' proposal, weighted by f₀/q."""
        k, seed, c, b, p_a = self.k, self.seed, int(coupled), int(data_births), float(p_a)
        side = self.side
        k.propagate(seed, frame, 0, 0, c, b, p_a, side, 0)  # with each particle's ℓ
        k.resample(seed, frame, 0, 0, 0, side)
        if kind == "rs":
            for sweep in range(moves):  # the MH move in the propagation; the last writes the other side
                k.propagate(seed, frame, 1 + sweep, 1, c, b, p_a, side, 2 if sweep == moves - 1 else 1)
        else:
            k.propagate(seed, frame, 1, 1, c, b, p_a, side, 0)
            k.resample(seed, frame, 1, 1, 1, side)
        self.side = 1 - side

    def presence(self) -> list[Presence]:
        """Each group's §3.4 output for the particles just committed."""
        self.k.summarize(self.sums, self.side)
        out = []
        for row in self.sums:
            present = self.n - row[SUM_ABSENT]
            mean = row[SUM_X:SUM_X + STATE] / present if present > 0 else np.full(STATE, np.nan)
            out.append(Presence(float(row[SUM_ABSENT] / self.n), mean, row[SUM_ASPECT:].copy()))
        return out

    def particles(self) -> dict:
        """Copies of the committed particles: state (C, 4) and aspect (C,)."""
        state, aspect = self.k.particles(self.side)
        return {"state": state, "aspect": aspect}
