"""Multi-frame saliency extraction (SGDS-PF section 2.2.1, Eqs. 20–33): the scheduler.

From normalised frames z (zero-mean, unit-variance noise) to a normalised proposal
map per image block, streamed frame by frame with ring buffers so each frame's work
is done once:

1. I_se(f): 3×3 energy collection on max(z, 0) (Eqs. 20–21), then I_se_max(f).
2. I_acc(f) = I_se_max(f−1) + I_se_max(f) + I_se_max(f+1), then I_acc_max(f) (Eq. 22).
3. I_acc2(f) = I_acc_max(f−1) + I_acc_max(f) + I_acc_max(f+1) (Eq. 22, second layer).
4. T_acc2 = std2(I_acc2)·(2.2·snr − 2) + mean(I_acc2) over the whole image, std2 with
   the N−1 denominator as in MATLAB (Eq. 23); I_rt = [I_acc2 > T] ∧ [I_acc == I_acc_max] (Eq. 24).
5. log ω̌_lef at I_rt pixels: the likelihood estimation filter (Eqs. 25–28), with the
   intensity range of Eq. 26 from the frame's own mean and std, lower bound clamped ≥ 0.
6. Per block of side ≤ L_ib: Sal = exp(log ω̌ − block max) (Eq. 29, scale-free),
   N_eff (Eq. 30), keep Sal ≥ the k-th largest, k = clamp(round(N_eff), 1, nnz)
   (Eqs. 31–32), and normalise to sum 1 (Eq. 33).

Latency: the output for frame f needs frame f+2 (I_acc2(f) needs I_acc_max(f+1), which
needs I_se_max(f+2)), so :meth:`SaliencyExtractor.push` of frame t returns frame t−2.
Temporal borders: where f−1 or f+1 is outside the sequence, the 3-frame sums use the
frames that exist, scaled by 3/n so their level matches the interior (frames 0 and
T−1 of each layer); :meth:`SaliencyExtractor.flush` emits the last two frames.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from . import backend
from .engines import check_engine
from .errors import ParameterError
from .io import stream_frame
from .kernels.loops import block_class, frame_class, in_corner
from .kernels.saliency_fields import ring_slots
from .numpy_kernels import saliency as nps

BEST_K = 32  # candidates with the largest Eq. 28 LEF reported per frame (ICEF's MSW skips those at tracks)


@dataclass
class BlockGrid:
    """Image blocks: ceil(W/L)×ceil(H/L) near-equal tiles with edges at ⌊k·W/n⌋ (Eq. 30 context)."""

    block_id: np.ndarray  # (H, W) int32, row-major block index by·n_bx + bx
    n_by: int
    n_bx: int
    offsets: np.ndarray  # (B,) int32 start of each block's slab (cumulative areas)
    areas: np.ndarray  # (B,) int32 pixels per block
    row_base: np.ndarray  # (H,) int32 by·n_bx of each row: block_id[y, x] = row_base[y] + col_block[x]
    col_block: np.ndarray  # (W,) int32 bx of each column

    @property
    def n_blocks(self) -> int:
        return self.n_by * self.n_bx


def block_grid(shape, block_size: int) -> BlockGrid:
    """Split (H, W) into ceil(H/L)·ceil(W/L) blocks of side ≤ L."""
    h, w = shape
    if block_size < 1:
        raise ParameterError(f"block size L_ib must be ≥ 1, got {block_size}")
    n_by, n_bx = math.ceil(h / block_size), math.ceil(w / block_size)
    row_block = np.searchsorted(np.floor(np.arange(1, n_by) * h / n_by), np.arange(h), side="right")
    col_block = np.searchsorted(np.floor(np.arange(1, n_bx) * w / n_bx), np.arange(w), side="right")
    block_id = (row_block[:, None] * n_bx + col_block[None, :]).astype(np.int32)
    areas = np.bincount(block_id.ravel(), minlength=n_by * n_bx).astype(np.int32)
    offsets = (np.cumsum(areas) - areas).astype(np.int32)
    return BlockGrid(block_id, n_by, n_bx, offsets, areas, (row_block * n_bx).astype(np.int32),
                     col_block.astype(np.int32))


def psf_matrix(psf_sigma: float = 0.7) -> np.ndarray:
    """D of Eq. 25: exp(−(Δi² + Δj²)/(2Σ²))/(2πΣ²) on the 5×5 grid (float32)."""
    d = np.arange(-2, 3)
    r2 = d[:, None] ** 2 + d[None, :] ** 2
    return (np.exp(-r2 / (2 * psf_sigma ** 2)) / (2 * math.pi * psf_sigma ** 2)).astype(np.float32)


def moments_to_mean_std(rows: np.ndarray, count: int) -> tuple[float, float]:
    """Mean and N−1 standard deviation (MATLAB std2) from per-row (Σ v, Σ v²)."""
    s1, s2 = float(rows[:, 0].sum()), float(rows[:, 1].sum())
    mean = s1 / count
    var = max(s2 - s1 * mean, 0.0) / max(count - 1, 1)
    return mean, math.sqrt(var)


def segmentation_threshold(mean: float, std: float, snr: float) -> float:
    """Eq. 23: T_acc2 = std2(I_acc2)·(2.2·snr − 2) + mean(I_acc2)."""
    return std * (2.2 * snr - 2.0) + mean


def intensity_range(mean: float, std: float, snr: float) -> tuple[float, float]:
    """Eq. 26: [mean + (snr − 2)·std, mean + (snr + 3)·std], lower bound clamped to ≥ 0."""
    return max(mean + (snr - 2.0) * std, 0.0), mean + (snr + 3.0) * std


@dataclass
class SaliencyFrame:
    """Saliency output for one frame (0-based index ``frame`` into the input)."""

    frame: int
    proposal: np.ndarray | None  # (H, W) f32, OPsal_N of Eq. 33: sums to 1 over each non-empty block
    threshold: float | None = None  # T_acc2 of Eq. 23
    i_range: tuple[float, float] | None = None  # Eq. 26
    mask: np.ndarray | None = None  # (H, W) bool, I_rt of Eq. 24 (None unless details=True)
    n_eff: np.ndarray | None = None  # (B,) Eq. 30
    k: np.ndarray | None = None  # (B,) rank of T_ep (Eq. 31)
    nnz: np.ndarray | None = None  # (B,) candidate pixels per block
    best_lef: np.ndarray | None = None  # (BEST_K, 2): the largest log ω̌_lef (Eq. 28) over I_rt pixels and their
    # pixel indices y·W + x, descending; (−3e38, −1) rows where there are fewer candidates


class NumpySaliencyEngine:
    """Ring buffers as NumPy arrays; every step is a call of the NumPy twin."""

    def __init__(self, shape, grid: BlockGrid, d: np.ndarray, window: int, lef_memory: float = 0.0,
                 lef_scale: float = 1.0):
        self.grid, self.d, self.r = grid, d, window
        self.lef_memory, self.lef_scale = lef_memory, lef_scale
        self.ring = {name: np.zeros((3,) + tuple(shape), np.float32) for name in ("z", "se_max", "acc", "acc_max")}
        self.memory = np.zeros(shape, np.float32)  # the multi-frame LEF of the last frame emitted
        self.proposal = np.zeros(shape, np.float32)  # the latest frame's OPsal_N, as the Taichi engine keeps it

    def proposal_copy(self) -> np.ndarray:
        """The last emitted frame's proposal (Eq. 33) as an array of its own, which the caller may change."""
        return self.proposal.copy()

    def put_and_energy(self, slot: int, z: np.ndarray) -> None:
        """Store frame t and compute I_se_max(t) (Eqs. 20–21 and the first max filter)."""
        self.ring["z"][slot] = z
        self.ring["se_max"][slot] = nps.max_filter(nps.energy_collection(z, self.r), self.r)

    def put_energy_and_first_layer(self, slot: int, z: np.ndarray, slots, scale: float, dst: int) -> None:
        """Frame t into ``slot`` with its I_se_max, then the first layer of frame t − 1 into ``dst`` (none when
        every slot is −1)."""
        self.put_and_energy(slot, z)
        if max(slots) >= 0:
            self.first_layer(slots, scale, dst)

    def first_layer(self, slots, scale: float, dst: int) -> None:
        """I_acc (Eq. 22, first layer) into acc[dst] and its max filter into acc_max[dst]."""
        total = nps.sum_frames(*[self.ring["se_max"][s] if s >= 0 else None for s in slots], scale)
        self.ring["acc"][dst] = total
        self.ring["acc_max"][dst] = nps.max_filter(total, self.r)

    def second_layer_and_blocks(self, slots, scale: float, slot: int, snr: float, a: float, details: bool) -> dict:
        """I_acc2, Eqs. 23–24 and 26–33 for the frame in ``slot`` (and the multi-frame LEF)."""
        acc2 = nps.sum_frames(*[self.ring["acc_max"][s] if s >= 0 else None for s in slots], scale)
        count = acc2.size
        threshold = segmentation_threshold(*moments_to_mean_std(nps.row_moments(acc2), count), snr)
        z = self.ring["z"][slot]
        i_min, i_max = intensity_range(*moments_to_mean_std(nps.row_moments(z), count), snr)
        mask = nps.segment(acc2, threshold, self.ring["acc"][slot], self.ring["acc_max"][slot])
        lef = nps.lef_map(z, self.d, 1.0, a, i_min, i_max)
        logw = lef
        if self.lef_memory > 0:
            self.memory = nps.accumulate_lef(self.memory, z, self.d, a, self.lef_memory, self.r)
            logw = (np.float32(self.lef_scale) * self.memory).astype(np.float32)
        out = nps.block_proposal(mask, logw, self.grid.block_id, self.grid.n_blocks)
        self.proposal = out["proposal"]
        out.update(mask=mask, threshold=threshold, i_range=(i_min, i_max), best_lef=nps.best_lef(mask, lef, BEST_K))
        return out if details else {"best_lef": out["best_lef"]}


CHUNK_ROWS = {"cpu": 64, "gpu": 4}  # rows per streamed chunk of the max filters in parallel mode


def chunk_count(height: int, serial: bool, arch: str) -> int:
    """Runs of rows the streamed max filters split the image into: one when serial, else
    ⌈H / rows⌉ (long runs on the CPU, where halo rows cost; short ones on a GPU, for threads)."""
    if serial:
        return 1
    return -(-height // CHUNK_ROWS["cpu" if arch == "cpu" else "gpu"])


def lane_layout(width: int) -> tuple[int, np.ndarray]:
    """Number of 8-lane vectors per row and the (V, 8) lane-validity mask (1 inside, 0 padding)."""
    from .kernels.saliency import LANES

    blocks = -(-width // LANES)
    valid = (np.arange(blocks * LANES).reshape(blocks, LANES) < width).astype(np.float32)
    return blocks, valid


def to_lanes(image: np.ndarray, blocks: int, out: np.ndarray | None = None) -> np.ndarray:
    """(H, W) float32 → (H, V, 8) with zero padding lanes: a view when W = 8V, else written into ``out``."""
    h, w = image.shape
    if w == blocks * 8:
        return np.ascontiguousarray(image, dtype=np.float32).reshape(h, blocks, 8)
    if out is None:
        out = np.zeros((h, blocks * 8), np.float32)
    out[:, :w] = image
    return out.reshape(h, blocks, 8)


def from_lanes(lanes: np.ndarray, width: int) -> np.ndarray:
    """(…, H, V, 8) → (…, H, W)."""
    return lanes.reshape(lanes.shape[:-2] + (-1,))[..., :width]


class TaichiSaliencyEngine:
    """Ring buffers as Taichi fields of 8-lane vectors; each step is one kernel launch for the
    whole image or for all blocks."""

    def __init__(self, shape, grid: BlockGrid, d: np.ndarray, window: int, lef_memory: float = 0.0,
                 lef_scale: float = 1.0):
        from .kernels import saliency
        from .launch import Launcher

        ks = Launcher(saliency)
        self.ks, self.grid, self.r = ks, grid, window
        self.lef_memory, self.lef_scale = lef_memory, lef_scale
        self.memory_slot = 0  # slot of memory holding the last emitted frame's multi-frame LEF
        self.shape = (int(shape[0]), int(shape[1]))
        self.n_lanes, valid = lane_layout(self.shape[1])
        # the fields' extents: each size class of the frame's (rows, lane vectors, blocks) shares one set of
        # compiled kernels, which read the true extents from f.dims
        rows, columns = frame_class(self.shape)
        self.classes = (rows, columns // ks.LANES, block_class(grid.n_blocks))
        self.serial = backend.serial_loops(self.shape[0] * self.shape[1])
        arch = backend.current().arch
        self.n_chunks = chunk_count(self.shape[0], self.serial, arch)  # runs of the frame's rows
        self.chunk_room = chunk_count(rows, self.serial, arch)  # the most runs of a frame of the class
        self.keep_i_se = False  # also store I_se (tests, figures)
        self.f = backend.reusable(self, ("saliency", self.classes, self.r, self.chunk_room, self.serial), self._fields)
        f = self.f
        f.params32[1] = lef_memory  # γ; snr, N and A in second_layer_and_blocks
        f.params32[2] = lef_scale
        self.params = None  # (snr, A) last written to f
        rows, lanes, blocks = self.classes
        backend.from_host_many(f, {"valid": in_corner(valid, (lanes, ks.LANES)), "d": d,
                                   "row_base": in_corner(grid.row_base, (rows,)),
                                   "col_block": in_corner(grid.col_block, (lanes * ks.LANES,)),
                                   "block_offset": in_corner(grid.offsets, (blocks,)),
                                   "dims": np.array([self.shape[0], self.n_lanes, self.shape[1], grid.n_blocks,
                                                     self.n_chunks])})
        f.block_max.fill(ks.NEG_INF)
        if backend.holds_old_values(f):  # new fields are zeros
            backend.zero_many(f, ("proposal", "n_written", "memory"))
        self.host_lanes = np.zeros((self.shape[0], self.n_lanes * ks.LANES), np.float32)  # padding lanes stay 0
        self.host_proposal = None  # the last emitted frame's proposal, until proposal_copy hands it over

    def _fields(self):
        """The engine's Taichi fields: ring buffers of 8-lane rows, per-row and per-block scratch."""
        import taichi as ti

        from .kernels.saliency_fields import SaliencyFields

        ks, (h, lanes, nb) = self.ks, self.classes
        w = lanes * ks.LANES
        image = lambda slots=1: ti.Vector.field(ks.LANES, ti.f32, shape=(slots, h, lanes))  # noqa: E731
        f = SaliencyFields(self.r, self.serial,
                           valid=ti.Vector.field(ks.LANES, ti.f32, shape=lanes), ring={name: image(3) for name in ("z", "se_max", "acc", "acc_max")})
        f.z, f.se_max, f.acc, f.acc_max = (f.ring[name] for name in ("z", "se_max", "acc", "acc_max"))
        f.params64, f.params32 = ti.field(ti.f64, shape=2), ti.field(ti.f32, shape=3)
        f.dims = ti.field(ti.i32, shape=5)  # saliency_fields.D_*: H, V, W, blocks, runs of rows of the frame
        rows = lambda depth: ti.Vector.field(ks.LANES, ti.f32, shape=(self.chunk_room, depth, lanes))  # noqa: E731
        f.hs, f.hm, f.ring_max, f.line = rows(2 * self.r + 1), rows(2 * self.r + 1), rows(2 * self.r + 1), rows(1)
        f.i_se, f.acc2 = image(), image()
        f.z_rows = ti.field(ti.f64, shape=(3, h, 2))
        f.acc2_rows = ti.field(ti.f64, shape=(1, h, 2))
        f.row_x = ti.field(ti.i32, shape=(h, w))
        f.row_logw = ti.field(ti.f32, shape=(h, w))
        f.row_lef = ti.field(ti.f32, shape=(h, w))
        f.best = ti.field(ti.f64, shape=(BEST_K, 2))
        f.memory = image(2)  # multi-frame LEF, two slots used in turn
        f.n_row = ti.field(ti.i32, shape=h)
        f.stats = ti.field(ti.f64, shape=8)
        f.d = ti.field(ti.f32, shape=(5, 5))
        f.row_base, f.col_block = ti.field(ti.i32, shape=h), ti.field(ti.i32, shape=w)
        f.block_offset, f.block_max = ti.field(ti.i32, shape=nb), ti.field(ti.f32, shape=nb)
        f.block_nnz, f.block_stats = ti.field(ti.i32, shape=nb), ti.field(ti.f64, shape=(nb, 4))
        f.proposal = ti.field(ti.f32, shape=(h, w))
        f.written, f.n_written = ti.field(ti.i32, shape=h * w), ti.field(ti.i32, shape=())
        f.entry_pixel, f.entry_logw = ti.field(ti.i32, shape=h * w), ti.field(ti.f32, shape=h * w)
        f.entry_sal, f.scratch = ti.field(ti.f32, shape=h * w), ti.field(ti.f32, shape=h * w)
        return f

    def host_lanes_of(self, field, slot: int) -> np.ndarray:
        """Slot ``slot`` of a lane-layout ring field (slots, rows, vectors) as the frame's (H, V, 8) lanes, cut from
        the field's size-class extents (tests, figures)."""
        return backend.to_host(field)[slot][:self.shape[0], :self.n_lanes]

    def put_lanes(self, field, images: np.ndarray) -> None:
        """Fill a lane-layout ring field with ``images`` (slots, H, V, 8), zero beyond the frame (tests)."""
        field.from_numpy(in_corner(images, tuple(field.shape) + (images.shape[-1],)))

    def proposal_copy(self) -> np.ndarray:
        """The last emitted frame's proposal (Eq. 33) as a host array of its own, which the caller may change."""
        out, self.host_proposal = self.host_proposal, None
        return out if out is not None else backend.to_host(self.f.proposal)[:self.shape[0], :self.shape[1]].copy()

    def put_energy_and_first_layer(self, slot: int, z: np.ndarray, slots, scale: float, dst: int) -> None:
        """Frame t into ``slot`` with its I_se_max, and the first layer of frame t − 1 into ``dst`` (as
        :meth:`first_layer`), in one launch; with every slot −1, a first layer of zeros into ``dst``."""
        f = self.f
        self.ks.frame_to_first_layer(to_lanes(z, self.n_lanes, self.host_lanes), f,
                                     ring_slots(frame=slot, sums=slots, dst=dst), scale, self.keep_i_se)

    def first_layer(self, slots, scale: float, dst: int) -> None:
        self.ks.accumulate_max(self.f, ring_slots(sums=slots, dst=dst), scale)

    def second_layer_and_blocks(self, slots, scale: float, slot: int, snr: float, a: float, details: bool) -> dict:
        """I_acc2 to the proposal of the frame in ``slot`` in two launches; the proposal comes back as a host
        array (:meth:`proposal_copy`), written sparsely into zeros: a new array after the last one was handed
        over, else the last one with its pixels cleared (no allocation per frame when nobody takes them)."""
        ks, f = self.ks, self.f
        accumulated = self.lef_memory > 0
        src = self.memory_slot
        if accumulated:
            self.memory_slot = 1 - src
        reuse = self.host_proposal is not None
        if not reuse:
            self.host_proposal = np.zeros(self.shape, np.float32)
        best = np.empty(f.best.shape)
        if self.params != (snr, a):  # set once per extractor: fields, not launch arguments
            self.params = (snr, a)
            f.params64[0], f.params64[1], f.params32[0] = snr, float(self.shape[0] * self.shape[1]), a
        ks.second_layer_and_lef(f, ring_slots(frame=slot, sums=slots, memory=(src, self.memory_slot)), scale,
                                accumulated)
        ks.proposal_from_candidates(f, slot, self.memory_slot, accumulated, self.host_proposal, best, int(reuse))
        if not details:
            return {"best_lef": best}
        stats, blocks = backend.to_host(f.stats), backend.to_host(f.block_stats)[:self.grid.n_blocks]
        nnz = blocks[:, 2].astype(np.int64)
        entries = backend.to_host(self.f.entry_pixel)
        mask = np.zeros(self.shape, bool)
        for off, n in zip(self.grid.offsets, nnz):
            mask.ravel()[entries[off:off + n]] = True
        return {"proposal": self.host_proposal.copy(), "mask": mask, "best_lef": best,
                "threshold": float(stats[0]), "i_range": (float(stats[1]), float(stats[2])),
                "n_eff": blocks[:, 0], "k": blocks[:, 1].astype(np.int64), "nnz": nnz}


class SaliencyExtractor:
    """Streaming saliency stage: ``push`` normalised frames, get proposal maps 2 frames later.

    ``snr`` is the lowest SNR to detect (Eqs. 23 and 26); ``block_size`` is L_ib (px);
    ``psf_sigma`` is Σ (px) of D (Eq. 25); ``window`` the radius of the 3×3 operators.
    ``details=False`` copies nothing but ``best_lef`` back to the host: the proposal stays in the
    engine (the tracker's path), and the returned frames carry only their index and ``best_lef``.

    ``lef_memory`` γ > 0 replaces Eq. 29's weight log ω̌_lef by ``lef_scale``·L, the multi-frame
    LEF L(f) = log ω̌⁺(f) + γ·max3×3 L(f − 1) (not in the paper; ``accumulate_lef`` in the
    kernels): a target moving ≤ 1 px/frame adds its evidence up over about 1/(1 − γ) frames.
    γ = 0 (the default here) is Eq. 29 as printed.
    """

    def __init__(self, shape, snr: float = 1.4, block_size: int = 150, psf_sigma: float = 0.7,
                 engine: str = "taichi", window: int = 1, arch: str | None = None, details: bool = True,
                 lef_memory: float = 0.0, lef_scale: float = 1.0):
        check_engine(engine)
        if len(shape) != 2 or min(shape) < 1:
            raise ParameterError(f"shape must be (H, W) with H, W ≥ 1, got {shape}")
        if snr <= 0 or psf_sigma <= 0 or window < 1:
            raise ParameterError("snr and psf_sigma must be > 0 and window ≥ 1")
        if not 0 <= lef_memory < 1 or not lef_scale > 0:
            raise ParameterError(f"lef_memory must be in [0, 1) and lef_scale > 0, got {lef_memory!r}, {lef_scale!r}")
        self.shape, self.snr = (int(shape[0]), int(shape[1])), float(snr)
        self.grid = block_grid(self.shape, block_size)
        d = psf_matrix(psf_sigma)
        self.a = float((d.astype(np.float64) ** 2).sum() / 2.0)  # A = ΣD²/(2σ²), σ = 1 (Eq. 27)
        if engine == "taichi":
            backend.ensure_init(arch)
            self.engine = TaichiSaliencyEngine(self.shape, self.grid, d, window, lef_memory, lef_scale)
        else:
            self.engine = NumpySaliencyEngine(self.shape, self.grid, d, window, lef_memory, lef_scale)
        self.details = details
        self.n_pushed = 0
        self.n_emitted = 0

    def _slots(self, centre: int, last: int) -> tuple[list[int], float]:
        """Ring slots of frames centre−1..centre+1 that exist in [0, last], and the 3/n scale."""
        slots = [f % 3 if 0 <= f <= last else -1 for f in (centre - 1, centre, centre + 1)]
        return slots, 3.0 / sum(s >= 0 for s in slots)

    def _layer1(self, f: int, last: int) -> None:
        slots, scale = self._slots(f, last)
        self.engine.first_layer(slots, scale, f % 3)

    def _emit(self, f: int, last: int) -> SaliencyFrame:
        slots, scale = self._slots(f, last)
        out = self.engine.second_layer_and_blocks(slots, scale, f % 3, self.snr, self.a, self.details)
        self.n_emitted = f + 1
        return SaliencyFrame(f, out.get("proposal"), out.get("threshold"), out.get("i_range"), out.get("mask"),
                             out.get("n_eff"), out.get("k"), out.get("nnz"), out["best_lef"])

    def push(self, z) -> list[SaliencyFrame]:
        """Add normalised frame t; returns the output for frame t−2 (empty for t < 2)."""
        return self.push_checked(stream_frame(z, self.shape, self.n_pushed, "extractor"))

    def push_checked(self, z: np.ndarray) -> list[SaliencyFrame]:
        """:meth:`push` for a frame known to be a finite float32 (H, W) array (the tracker's own z)."""
        t = self.n_pushed
        # frame t in, and the first layer of frame t − 1, in one launch; for frame 0 a first layer of no frames
        # into slot 2, which frame 2's own first layer overwrites before any read (one kernel to compile, not two)
        slots, scale = self._slots(t - 1, t) if t >= 1 else ([-1, -1, -1], 1.0)
        self.engine.put_energy_and_first_layer(t % 3, z, slots, scale, (t - 1) % 3)
        self.n_pushed = t + 1
        return [self._emit(t - 2, t)] if t >= 2 else []

    def flush(self) -> list[SaliencyFrame]:
        """Finish the sequence: outputs for the last (up to) two frames, with truncated sums."""
        return list(self.emit_remaining())

    def emit_remaining(self):
        """:meth:`flush` one frame at a time: each frame's output is emitted when the generator
        reaches it, so the engine's proposal (kept there with ``details=False``) is that frame's
        until the next one is drawn."""
        last = self.n_pushed - 1
        if last < 0:
            return
        self._layer1(last, last)
        for f in range(self.n_emitted, last + 1):
            yield self._emit(f, last)


def saliency_sequence(frames, **kwargs) -> list[SaliencyFrame]:
    """Run the extractor over a whole (T, H, W) sequence of normalised frames."""
    frames = np.asarray(frames)
    ext = SaliencyExtractor(frames.shape[1:], **kwargs)
    out = []
    for z in frames:
        out.extend(ext.push(z))
    return out + ext.flush()


def saliency_stages(frames, f: int, snr: float = 1.4, block_size: int = 150, psf_sigma: float = 0.7) -> dict:
    """Every intermediate map of frame ``f`` (2 ≤ f ≤ T−3) by the NumPy twin, for figures and debugging.

    Keys: z, I_se, I_acc2, I_rt (mask), lef (log ω̌_lef), saliency (Sal/ΣSal per block), proposal
    (OPsal_N, Eq. 33), block_id.
    """
    frames = np.asarray(frames, np.float32)
    if not 2 <= f <= len(frames) - 3:
        raise ParameterError(f"frame {f} needs frames f-2..f+2 inside the sequence of {len(frames)}")
    se_max = {k: nps.max_filter(nps.energy_collection(frames[k])) for k in range(f - 2, f + 3)}
    acc = {k: nps.sum_frames(se_max[k - 1], se_max[k], se_max[k + 1], 1.0) for k in range(f - 1, f + 2)}
    acc_max = {k: nps.max_filter(v) for k, v in acc.items()}
    acc2 = nps.sum_frames(acc_max[f - 1], acc_max[f], acc_max[f + 1], 1.0)
    count = acc2.size
    threshold = segmentation_threshold(*moments_to_mean_std(nps.row_moments(acc2), count), snr)
    i_min, i_max = intensity_range(*moments_to_mean_std(nps.row_moments(frames[f]), count), snr)
    d = psf_matrix(psf_sigma)
    a = float((d.astype(np.float64) ** 2).sum() / 2.0)
    mask = nps.segment(acc2, threshold, acc[f], acc_max[f])
    lef = nps.lef_map(frames[f], d, 1.0, a, i_min, i_max)
    grid = block_grid(frames.shape[1:], block_size)
    out = nps.block_proposal(mask, lef, grid.block_id, grid.n_blocks)
    saliency = np.zeros(mask.shape, np.float64)
    for b in range(grid.n_blocks):
        inside = mask & (grid.block_id == b)
        if inside.any():
            w = np.exp(lef[inside] - lef[inside].max())
            saliency[inside] = w / w.sum()
    return {"z": frames[f], "I_se": nps.energy_collection(frames[f]), "I_acc2": acc2, "I_rt": mask, "lef": lef,
            "saliency": saliency, "proposal": out["proposal"], "block_id": grid.block_id}
