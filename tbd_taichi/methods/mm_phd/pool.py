"""The host side of MM-PHD's particle pool: it lays the detector and the trackers out as groups of one pool
(``kernels.phd``, or its NumPy twin) and sequences one frame's launches; it keeps no per-particle state itself."""
from __future__ import annotations

import numpy as np

from ... import backend
from ...engines import frame_kernels
from ...errors import ParameterError
from ...kernels.phd import (CX, CY, F_SUPPORT, FRAME, GROUP_FLOAT, GROUP_INT, L_SUPPORT, LENGTH, NO_CENTRE,
                             OUT_ID, OUT_LEN, N_HAT, OUT_START, OUT_WEIGHT, QSCALE, RADIUS, START, TOP)
from ...motion_models import DIM, model_set
from .params import P_DETECT, Derived, MMPHDParams

MAX_MODELS = 4
EVERY_CELL = 1.0e30  # −threshold that makes every cell a measurement


def model_cdf(switch: np.ndarray, birth: np.ndarray) -> np.ndarray:
    """(MAX_MODELS + 1, MAX_MODELS) cumulative rows: Π's rows (Eq. 39) then β (Eq. 28), padded with 1."""
    out = np.ones((MAX_MODELS + 1, MAX_MODELS), np.float32)
    n = len(birth)
    out[:n, :n] = np.cumsum(switch, axis=1)
    out[MAX_MODELS, :n] = np.cumsum(birth)
    out[:, n - 1:] = 1.0  # the last model takes what rounding leaves
    return out


def check_support(ms: dict) -> None:
    """The propagation kernel multiplies only ``kernels.phd``'s F_SUPPORT entries of F and F⁻¹ and L_SUPPORT's of
    L: a model set with another non-zero entry is an error (a new motion model must widen the supports)."""
    for name, support, label in (("F", F_SUPPORT, "F_SUPPORT"), ("F_inv", F_SUPPORT, "F_SUPPORT"),
                                 ("L", L_SUPPORT, "L_SUPPORT")):
        outside = np.ones(ms[name].shape[1:], bool)
        outside[tuple(np.array(support).T)] = False
        if np.any(ms[name][:, outside] != 0):
            raise ParameterError(f"motion models: {name} has non-zero entries outside kernels.phd's {label}; "
                                 "widen the support for the new model")


def padded(matrices: np.ndarray) -> np.ndarray:
    """(n, 7, 7) model matrices as the (MAX_MODELS, 7, 7) table of the kernels."""
    out = np.zeros((MAX_MODELS, DIM, DIM), np.float32)
    out[:len(matrices)] = matrices
    return out


class PhdPool:
    """One pool of ``capacity`` slots and ``max_groups`` groups on ``engine``; group 0 is the detector when a
    frame's layout has one.  :meth:`layout` fixes the groups of a frame, the step methods launch."""

    def __init__(self, shape, p: MMPHDParams, d: Derived, capacity: int, max_groups: int, seed: int,
                 engine: str, arch: str | None):
        self.p, self.d, self.seed, self.shape = p, d, int(seed), tuple(int(v) for v in shape)
        # the per-pixel fields hold the pixels of the frames' size class and the kernels read the frame's (H, W)
        # from frame_hw, so frames of a class share the compiled kernels; Taichi compiles a data-oriented object's
        # kernels once per object: a new pool takes the fields of a finished one of the class (frame_kernels)
        self.k = frame_kernels(self, engine, "phd", "PhdKernels", (int(capacity), int(max_groups), self.shape),
                               self.shape, arch)
        self.max_groups = max_groups
        ms = model_set(d.models, p.frame_interval, p.omega, p.q_s, p.q_i)
        check_support(ms)
        for name in ("F", "F_inv", "L"):
            self.k.put(name, padded(ms[name]))
        self.k.put("model_cdf", model_cdf(d.switch, d.birth_models))
        self.gint = np.zeros((max_groups, len(GROUP_INT)), np.int32)
        self.gflt = np.zeros((max_groups, len(GROUP_FLOAT)), np.float32)
        self.n_groups = 0
        self.birth = np.array([p.survival, p.vmax, *d.i_range, p.birth_mass / p.births, d.i_floor], np.float32)
        self.k.put("birth", self.birth)  # propagate's; set_frame changes the newborn weight γ/J

    def set_frame(self, z: np.ndarray, births: bool = True) -> int:
        """The frame the filters weigh and, with ``births``, the birth cells {z ≥ Th} (Eq. 29; none: every cell,
        with newborn weight 0 this frame); returns their number."""
        backend.from_host_leading(self.k.raw, z.ravel())
        if not births:
            return 0
        cells = np.flatnonzero(z.ravel() >= self.d.threshold).astype(np.int32)
        weight = np.float32(self.p.birth_mass / self.p.births if cells.size else 0.0)
        if weight != self.birth[4]:
            self.birth[4] = weight
            backend.from_host(self.k.birth, self.birth)
        full = np.arange(z.size, dtype=np.int32)
        full[:cells.size] = cells
        backend.from_host_leading(self.k.cells, full)
        return int(cells.size) or z.size

    def layout(self, lengths, masked, qscale, centres=None, radii=None) -> int:
        """Groups of consecutive slots of ``lengths`` (the detector's newborn slots included), weighing the
        masked frame where ``masked``, with Q scales ``qscale``, gate centres ``centres`` (x, y rows, the
        predicted target positions; None: no gate) and gate radii ``radii`` (px per axis; None: 3Σ); returns
        the slots in use."""
        n = len(lengths)
        g = self.gint
        g[:] = 0
        g[:n, LENGTH] = lengths
        g[:n, START] = np.concatenate([[0], np.cumsum(lengths)[:-1]])
        g[:n, FRAME] = masked
        self.gflt[:] = 0
        self.gflt[:n, QSCALE] = qscale
        self.gflt[:n, CX:CY + 1] = NO_CENTRE if centres is None else centres
        self.gflt[:n, RADIUS] = self.d.class_radius if radii is None else radii
        self.n_groups = n
        backend.from_host(self.k.gint, g)
        backend.from_host(self.k.gflt, self.gflt)
        return int(np.sum(lengths))

    def propagate(self, frame_key: int, total: int, n_cells: int, births: int = 0, backward: bool = False) -> None:
        """Eqs. 1, 26, 28–34 over slots [0, total); the detector's last ``births`` slots are newborn."""
        first = int(self.gint[0, START] + self.gint[0, LENGTH]) - births
        self.k.propagate(self.seed, frame_key, total, int(backward), max(n_cells, 1), first, births)

    def weigh(self, first_group: int, n_groups: int, on_likelihood: bool | None = None,
              segmented: bool = False, estimate: bool = False) -> None:
        """Eqs. 4, 13–19 for groups [first_group, first_group + n_groups) (their slots are consecutive, their
        frame the same), with the resampling weights ∝ ℓ (Eq. 24) or ∝ w̃ (``on_likelihood``; None: the
        likelihood_resampling parameter); ``segmented``: only cells with z ≥ Th are measurements (§5.1's
        pre-segmentation, a particle elsewhere keeps (1 − p_d)·w), else every cell is; ``estimate``: then the
        groups' class estimates (Eqs. 20, 35; :meth:`estimates` reads them)."""
        if n_groups <= 0:
            return
        a = int(self.gint[first_group, START])
        last = first_group + n_groups - 1
        count = int(self.gint[last, START] + self.gint[last, LENGTH]) - a
        frames = self.gint[first_group:last + 1, FRAME]
        if np.any(frames != frames[0]):
            raise ValueError("PhdPool.weigh: the groups weighed together must share one frame")
        if count > 0:
            self.k.likelihood(a, count, self.d.half, self.p.psf_sigma, int(frames[0]))
        lik = self.p.likelihood_resampling if on_likelihood is None else on_likelihood
        th = self.d.threshold if segmented else -EVERY_CELL
        self.k.update(first_group, n_groups, self.d.lam, int(lik), th, 1.0 - P_DETECT,
                      self.d.class_radius if estimate else 0.0)

    def estimates(self) -> np.ndarray:
        """The kernels' ``est`` table (all groups): the class estimates of the last :meth:`weigh` with
        ``estimate``."""
        return backend.to_host(self.k.est)

    def mask(self, first_group: int, n_groups: int) -> None:
        """Eq. 36: the detector's frame with I_0 over the windows around the estimated positions of groups
        [first_group, first_group + n_groups), ⌊3Σ⌋ + mask_margin px each side."""
        self.k.mask(first_group, n_groups, self.d.half + self.p.mask_margin, self.p.mask_value)

    def n_hat(self) -> tuple[np.ndarray, np.ndarray]:
        """n̂ of each group of the layout (Eq. 19) and the largest PHD mass Ψ/(λ + Ψ) of one of its cells."""
        out = backend.to_host(self.k.gout)[:self.n_groups].astype(float)
        return out[:, N_HAT], out[:, TOP]

    def resample(self, frame_key: int, out_lengths, out_weights, keep, room: int = 0) -> int:
        """Each group g to ``out_lengths[g]`` particles of weight ``out_weights[g]`` (0 length: the group ends),
        compacted in group order with ``room`` free slots after group 0 (the next frame's newborns); the kept
        groups are renumbered 0, 1, …; returns the slots in use (room included)."""
        n = self.n_groups
        lens = np.where(keep, out_lengths, 0).astype(np.int32)
        g = self.gint
        g[:n, OUT_LEN] = lens
        g[:n, OUT_START] = np.concatenate([[0], np.cumsum(lens)[:-1]]) + np.where(np.arange(n) > 0, room, 0)
        g[:n, OUT_ID] = np.cumsum(keep) - 1
        self.gflt[:n, OUT_WEIGHT] = out_weights
        backend.from_host(self.k.gint, g)
        backend.from_host(self.k.gflt, self.gflt)
        self.k.resample(self.seed, frame_key, n, int(max(lens.max(initial=0), 1)))
        return int(lens.sum()) + (room if n > 0 else 0)

    def particles(self, start: int, count: int) -> dict:
        """Slots [start, start + count) on the host: state (count, 7), model, w̃ and cell mass."""
        return self.k.slots(start, count)

    def load(self, offset: int, state: np.ndarray, model: np.ndarray, weight: float, group: int) -> None:
        """Slots [offset, offset + n) of the next frame's pool ← the particles ``state``, ``model`` of weight
        ``weight`` in ``group``."""
        self.k.load(offset, np.ascontiguousarray(state, np.float32), np.ascontiguousarray(model, np.int32),
                    float(weight), int(group))
