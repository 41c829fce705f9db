"""``feature-fusion``: the adaptive feature-fusion particle filter of Huo, Zhang, Huang & Wang (Electronics 2022):
a box tracker started from the target's first-frame box (``--init-box``), following it by appearance.

Per frame: the grey, Sobel-edge and Gabor maps are binned (kernels.feature_fusion); N box centres move by Eq. 1's
random walk; each gets three kernel-weighted histograms over the box (Eqs. 11–18), fused with weights from their
correlation with the first frame's (Eqs. 19–21), and a likelihood from the Bhattacharyya distance (Eq. 22);
weights accumulate (Eq. 10), the estimate is their mean (Eq. 6); when N_eff < 2N/3 (Eq. 23) residual resampling
runs and the 0.2N lowest-weight particles are replaced by the points Δd = 2 px around the J best that lie closest
to the last estimate (Eqs. 24–25).  Resampling runs on the host (N is a few hundred).  Equations → code:
docs/methods/feature-fusion.md."""
from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass

import numpy as np

from .. import backend
from ..engines import frame_kernels
from ..errors import ParameterError
from ..io import stream_frame
from ..kernels.feature_fusion import FEATURES, FUSIONS, MAX_HALF, SERIAL_WORK, gabor_taps, histogram_work
from ..numpy_kernels.rng import normal, uniform
from ..tables import TRACK_COLUMNS, _dtype, make_table
from .registry import MethodSpec, OneSequence, param, validate_params

EXTRA_COLUMNS = ("w", "h")
S_INIT_X, S_INIT_Y, S_RESAMPLE = 10, 11, 12  # host streams (the kernels use 0, 1)
STAGES = ("features", "particles", "resampling")  # feature maps; random walk, weigh, estimate; resampling
RANGE_PERCENTILES = (0.5, 99.5)  # each feature's bins span these percentiles of frame 0
EIGHT_BIT = (0.0, 256.0)  # grey_range=8-bit: the grey bins' range, each of M bins 256/M grey levels wide
NEIGHBOURS = ((1, 0), (-1, 0), (0, 1), (0, -1), (1, 1), (1, -1), (-1, 1), (-1, -1))  # Eq. 25, in units of Δd


@dataclass(frozen=True)
class FeatureFusionParams:
    """Huo et al.'s parameters (§3) with the values the paper leaves open."""

    n_particles: int = param(200, doc="particles", symbol="N", unit="particles", source="not in the paper",
                             low=1, high=100_000)
    bins: int = param(16, doc="histogram bins per feature (the paper's [0, 255] would give 256, too sparse for a "
                      "small box)", symbol="M", source="Eq. 12", low=2, high=256)
    sigma_q: float = param(2.0, doc="random-walk standard deviation per axis", symbol="σ_q", unit="px",
                           source="Eq. 1 (value not in the paper)", low=0, high=100)
    sigma_0: float = param(2.0, doc="initial spread of the particles around the box centre", symbol="σ₀",
                           unit="px", source="not in the paper", low=0, high=100)
    sigma_l: float = param(0.15, doc="likelihood width: p(Y|X) ∝ exp(−d²/2σ_L²)", symbol="σ_L",
                           source="Eq. 22 (the mapping is not in the paper)", low=0, low_closed=False, high=10)
    gabor_sigma: float = param(1.5, doc="Gabor standard deviation σ_x = σ_y", symbol="σ_x, σ_y", unit="px",
                               source="Eq. 17 (value not in the paper)", low=0.3, high=10)
    gabor_omega: float = param(math.pi / 2, doc="Gabor frequency", symbol="ω", unit="rad/px",
                               source="Eq. 17 (value not in the paper)", low=0, high=math.pi)
    n_th: float = param(2 / 3, doc="resample when N_eff < n_th·N", symbol="N_th/N", source="§3.3", low=0, high=1)
    top_share: float = param(0.1, doc="J = ⌈top_share·N⌉ best particles seed the new ones", symbol="J/N",
                             source="not in the paper", low=0, low_closed=False, high=1)
    delta_d: float = param(2.0, doc="distance of the new candidate points", symbol="Δd", unit="px",
                           source="§3.3, Eq. 25", low=0, high=50)
    replace_share: float = param(0.2, doc="share of particles replaced by candidates", source="§3.3", low=0, high=1)
    grey_range: str = param("frame", doc="the grey bins' range: frame (frame 0's 0.5–99.5 percentiles, as the edge "
                            "and Gabor bins) or 8-bit ([0, 256): M equal bins of the paper's [0, 255] grey levels)",
                            source="Eq. 12", choices=("frame", "8-bit"))
    min_window: int = param(5, doc="the feature window is at least this many px on a side", unit="px",
                            source="not in the paper (its targets are 2×2)", low=1, high=2 * MAX_HALF + 1)
    fusion: str = param("adaptive", doc="adaptive (Eqs. 19–21, ρ = Σ v_i ρ_i), bin-sum (Eq. 21's bin-wise sum of "
                        "the v-weighted histograms, as printed) or grey (the grey histogram alone: the ablation)",
                        source="§3.2", choices=("adaptive", "bin-sum", "grey"))
    resampling: str = param("improved", doc="improved (residual + Eq. 24's new particles) or residual (plain)",
                            source="§3.3", choices=("improved", "residual"))
    motion: str = param("random-walk", doc="random-walk (Eq. 1) or constant-velocity (an extension)",
                        source="Eq. 1", choices=("random-walk", "constant-velocity"))


def feature_fusion_params(shape, **overrides) -> FeatureFusionParams:
    """The parameters with ``overrides``, validated."""
    return validate_params(FeatureFusionParams(**overrides), "feature-fusion")


def residual_resample(weights: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Residual resampling (§3.3): ⌊N·w_i⌋ copies of particle i, then N − N′ multinomial draws (``u``, uniforms)
    from the residual weights (N·w_i − ⌊N·w_i⌋)/(N − N′); returns the N parent indices sorted by parent weight,
    highest first."""
    n = len(weights)
    copies = np.floor(n * weights).astype(np.int64)
    parents = np.repeat(np.arange(n), copies)
    rest = n - len(parents)
    if rest > 0:
        residual = n * weights - copies
        cdf = np.cumsum(residual / residual.sum())
        drawn = np.minimum(np.searchsorted(cdf, u[:rest] * cdf[-1], side="right"), n - 1)
        parents = np.concatenate([parents, drawn])
    return parents[np.argsort(-weights[parents], kind="stable")]


def new_particles(best: np.ndarray, last: np.ndarray, delta: float, count: int) -> np.ndarray:
    """Eqs. 24–25: the points Δd away in 8 directions around ``best`` (J, 2), duplicates removed, the ``count``
    closest to the last estimate ``last`` (fewer if there are fewer)."""
    pts = (best[:, None, :] + delta * np.asarray(NEIGHBOURS, float)[None]).reshape(-1, 2)
    pts = np.unique(pts, axis=0)
    order = np.argsort(np.hypot(pts[:, 0] - last[0], pts[:, 1] - last[1]), kind="stable")
    return pts[order[:count]]


class FeatureFusionTracker(OneSequence):
    """``update(frame)`` returns one row a frame: (frame, 1, x, y, vx, vy, intensity, confidence = ρ at the
    estimate, w, h), the box centre and the init box's size."""

    def __init__(self, shape, init_box, seed: int = 0, engine: str = "taichi", arch: str | None = None, **params):
        self.shape = (int(shape[0]), int(shape[1]))
        self.p = feature_fusion_params(self.shape, **params)
        self.box = clipped_box(init_box, self.shape)
        self.seed, self.n = int(seed), self.p.n_particles
        x, y, w, h = self.box
        self.half = (max(w, self.p.min_window) / 2.0, max(h, self.p.min_window) / 2.0)
        if max(self.half) > MAX_HALF:
            raise ParameterError(f"init_box {init_box!r}: a side over {2 * MAX_HALF} px is larger than the "
                                 "feature-fusion tracker takes")
        row, col = gabor_taps(self.p.gabor_sigma, self.p.gabor_sigma, self.p.gabor_omega)
        dims = (self.n + 1, self.shape, self.p.bins, ((len(row) - 1) // 2, (len(col) - 1) // 2))
        self.k = frame_kernels(self, engine, "feature_fusion", "FeatureFusionKernels", dims, self.shape, arch)
        self.k.put("row_taps", row)
        self.k.put("col_taps", col)
        self.serial = backend.serial_loops(histogram_work(self.n, *self.half), SERIAL_WORK)
        self.k.configure(self.p.sigma_q, int(self.p.motion == "constant-velocity"), *self.half, self.p.sigma_l,
                         FUSIONS.index(self.p.fusion))
        self.raw = np.zeros((FEATURES,) + self.shape, np.float32)
        self.centre = np.array([x + w / 2.0, y + h / 2.0])  # the box centre, as drone-ir's cx, cy
        self.summary = np.zeros(4)  # x̂, ŷ, N_eff, ρ at the estimate
        self.rows: list[tuple] = []
        self.frame = 0
        self.resampled: list[int] = []
        self.seconds = {s: 0.0 for s in STAGES}

    def _weigh(self, first: int, count: int) -> None:
        self.k.weigh(first, count, *self.half, self.p.sigma_l, FUSIONS.index(self.p.fusion))

    def _start(self, frame: np.ndarray) -> None:
        """Frame 0: the bins' ranges, the template histograms at the box centre (Eq. 12) and the particles."""
        self.k.feature_maps(frame, self.raw, 1)
        lo, hi = np.percentile(self.raw.reshape(FEATURES, -1), RANGE_PERCENTILES, axis=1)
        if self.p.grey_range == "8-bit":
            lo[0], hi[0] = EIGHT_BIT
        self.k.put("ranges", np.stack([lo, np.maximum(hi, lo + 1e-6)], axis=1))
        self.k.rebin(self.raw)
        state = np.zeros((self.n + 1, 4), np.float32)
        state[self.n, :2] = self.centre
        self.k.put("state", state)
        self.k.put("logw", np.zeros(self.n + 1))  # fields may come from a finished tracker (backend.reusable)
        self._weigh(self.n, 1)
        self.k.put("template", self.k.get("hist")[self.n])
        i = np.arange(self.n)
        state[:self.n, 0] = self.centre[0] + self.p.sigma_0 * normal(self.seed, 0, S_INIT_X, i)
        state[:self.n, 1] = self.centre[1] + self.p.sigma_0 * normal(self.seed, 0, S_INIT_Y, i)
        state[:, 0] = np.clip(state[:, 0], 0, self.shape[1] - 1)
        state[:, 1] = np.clip(state[:, 1], 0, self.shape[0] - 1)
        self.k.put("state", state)

    def update(self, frame: np.ndarray) -> list[tuple]:
        """Step on one raw frame; one row for it."""
        self._check_open("update")
        t0 = time.perf_counter()
        z = stream_frame(frame, self.shape, self.frame, "tracker")
        if self.frame == 0:
            self._start(z)
            self.rows.append(self._row(self.centre, np.zeros(2), 1.0, z))
            self.frame += 1
            self.seconds["features"] += time.perf_counter() - t0
            return self.rows[-1:]
        self.k.feature_maps(z, self.raw, 0)
        t1 = time.perf_counter()
        self.k.step(self.seed, self.frame, self.summary, self.serial)  # Eqs. 1, 11–22, 10, 6, 23: x̂ to slot N
        estimate, neff, rho = self.summary[:2].copy(), self.summary[2], float(self.summary[3])
        t2 = time.perf_counter()
        if neff < self.p.n_th * self.n:  # Eq. 23
            self._resample()
        last = self.centre
        self.centre = estimate
        self.seconds["features"] += t1 - t0
        self.seconds["particles"] += t2 - t1
        self.seconds["resampling"] += time.perf_counter() - t2
        self.rows.append(self._row(estimate, estimate - last, rho, z))
        self.frame += 1
        return self.rows[-1:]

    def _resample(self) -> None:
        """§3.3: residual resampling, then (improved) the new particles of Eqs. 24–25; weights 1/N."""
        state, logw = backend.to_host(self.k.state), backend.to_host(self.k.logw)[:self.n]  # fast typed copies
        w = np.exp(logw - logw.max())
        w /= w.sum()
        u = uniform(self.seed, self.frame, S_RESAMPLE, np.arange(self.n)).astype(np.float64)
        parents = residual_resample(w, u)
        new = state[parents].copy()
        if self.p.resampling == "improved":
            j = max(1, math.ceil(self.p.top_share * self.n))
            count = int(self.p.replace_share * self.n)
            pts = new_particles(new[:j, :2].astype(float), self.centre, self.p.delta_d, count)
            if len(pts):
                new[self.n - len(pts):, :2] = pts  # the lowest-weight particles: the sorted set's tail
                new[self.n - len(pts):, 2:] = 0.0
        state[:self.n] = new[:self.n]
        state[:self.n, 0] = np.clip(state[:self.n, 0], 0, self.shape[1] - 1)
        state[:self.n, 1] = np.clip(state[:self.n, 1], 0, self.shape[0] - 1)
        backend.from_host(self.k.state, state)
        backend.from_host(self.k.logw, np.zeros(self.n + 1))
        self.resampled.append(self.frame)

    def _row(self, centre, velocity, rho: float, frame: np.ndarray) -> tuple:
        c = int(np.clip(round(centre[0]), 0, self.shape[1] - 1))
        r = int(np.clip(round(centre[1]), 0, self.shape[0] - 1))
        return (self.frame, 1, float(centre[0]), float(centre[1]), float(velocity[0]), float(velocity[1]),
                float(frame[r, c]), rho, float(self.box[2]), float(self.box[3]))

    def finish(self) -> np.ndarray:
        """Every row as a tracks table (with w, h)."""
        self._close_sequence()
        return make_table(self.rows, _dtype(TRACK_COLUMNS + EXTRA_COLUMNS))


def clipped_box(box, shape) -> tuple[float, float, float, float]:
    """The init box (x, y, w, h: left column and top row, 0-based, centre (x + w/2, y + h/2)) clipped to the frame
    [−½, W − ½] × [−½, H − ½], with a warning naming the clip when it was partly outside."""
    x, y, w, h = (float(v) for v in box)
    height, width = shape
    x0, y0 = max(x, -0.5), max(y, -0.5)
    x1, y1 = min(x + w, width - 0.5), min(y + h, height - 0.5)
    if (x0, y0, x1, y1) != (x, y, x + w, y + h):
        warnings.warn(f"init_box {box!r} is partly outside the {height}x{width} frame: clipped to "
                      f"{x0:g},{y0:g},{x1 - x0:g},{y1 - y0:g}", stacklevel=3)
    return x0, y0, x1 - x0, y1 - y0


BENCH_BOX = (15.5, 15.5, 9.0, 9.0)  # the bench scene's first-frame box (x, y, w, h)


def bench_frames(shape, n_frames: int, seed: int = 0) -> np.ndarray:
    """``tbd-taichi bench``'s frames: an 8-bit-like textured 9×9 target starting in BENCH_BOX and moving
    (1.5, 1) px a frame over smooth background and noise."""
    rng = np.random.default_rng(seed)
    h, w = shape
    yy, xx = np.mgrid[0:h, 0:w]
    frames = 60 + 20 * np.sin(xx / 37.0) * np.cos(yy / 23.0) + rng.normal(0, 4, (n_frames, h, w))
    patch = 120 + 40 * rng.random((9, 9))
    for t in range(n_frames):
        x0 = int(round(BENCH_BOX[0] + 0.5 + 1.5 * t)) % max(w - 9, 1)
        y0 = int(round(BENCH_BOX[1] + 0.5 + 1.0 * t)) % max(h - 9, 1)
        frames[t, y0:y0 + 9, x0:x0 + 9] = patch
    return frames.astype(np.float32)


def _factory(shape, params, *, seed: int, engine: str, arch, init_box=None, **options):
    import dataclasses

    return FeatureFusionTracker(shape, init_box, seed=seed, engine=engine, arch=arch, **dataclasses.asdict(params))


SPEC = MethodSpec(
    name="feature-fusion", title="adaptive feature-fusion PF", paper="Huo, Zhang, Huang & Wang 2022",
    kind="box-tracker",
    description="follows one target from its first-frame box (--init-box) by grey, Sobel-edge and Gabor "
                "histograms fused by their correlation with the first frame's; residual resampling plus new "
                "particles around the best ones",
    params=FeatureFusionParams, factory=_factory, make_params=feature_fusion_params, needs_init_box=True,
    scenario="huo2022", min_frames=2, aliases={"particles": "n_particles"}, rank=5,
    particle_count=lambda shape, params: params.n_particles, extra_columns=lambda params: EXTRA_COLUMNS,
    bench_settings=lambda snr: {"init_box": BENCH_BOX}, bench_frames=bench_frames,
    assumes="one target whose first-frame box is given; it keeps its size and roughly its appearance, moving "
            "≤ ~3σ_q = 6 px a frame",
)
