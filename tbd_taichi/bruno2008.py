"""The simulator scenario ``bruno2008``: one small extended multiaspect target in GMRF clutter (Bruno, Araújo &
Pavlov 2008, §2 and §4).

* target: an artificial military vehicle (:func:`vehicle_templates`) whose aspect z ∈ 1..K follows the Markov
  chain G (Eq. 1, ``multiaspect.aspect_transition``), moving by white-noise acceleration (Eq. 4, the CWNA of
  ``multiaspect.motion_noise`` in px: q = 6 m²/s³, T = 0.04 s, ζ = 0.2 m/px) from §4's prior (column U[10, 20],
  row U[50, 70] px, each velocity N(2, 0.1²) px/frame, aspect uniform).  It is present while its quantised
  centroid (Eq. 3) lies on the extended grid (§2) and ends at the first frame it leaves;
* frames (Eqs. 7–8): Y = local mean + H(s*, z) + V, the template of the current aspect added at the quantised
  centroid and cut at the image borders (Remark 1), V one exact first-order GMRF draw per frame (Eqs. 9, 14;
  ``gmrf.sample_gmrf``) with β_h = 0.22, β_v = 0.24, σ_c = 1;
* the local mean (the paper's IRAR local means are not available): a smooth static field
  MEAN_LEVEL + MEAN_RELIEF·(white noise Gaussian-filtered with σ = MEAN_SMOOTH px, normalised to unit sd),
  drawn from the seed; :func:`local_mean` with :func:`streams` recomputes it (oracle mean removal);
* PTCR (not defined in the paper): 20·log10(max|a| / σ_c), see :func:`ptcr_peak`;
* ``exit_reentry`` (Figs. 1–5): the first target runs until it leaves (frame e), frames e..e+5 are empty and a
  second target from the same prior appears at frame e + 6; the sequence runs max(51, e + 21) frames.

Coordinates: x = column, y = row, 0-based, pixel centres at integers; velocities px/frame; frames 0-based.
The truth adds an ``aspect`` column (1..K) to ``tables.TRUTH_COLUMNS``; ``intensity`` is the peak value of that
aspect's template.
"""
from __future__ import annotations

import math

import numpy as np
from scipy import ndimage

from .errors import ParameterError
from .gmrf import sample_gmrf
from .multiaspect import (PAPER_PRIOR, PAPER_Q, PAPER_T, PAPER_ZETA, aspect_transition, check_templates, extended_grid,
                          half_sizes, motion_noise, noise_factor, quantise)
from .simulate import Scenario
from .tables import TRUTH_COLUMNS, _dtype, make_table

SHAPE = (120, 120)  # px: the figures' axes span [0, 24] m at 0.2 m/px
BETA_H, BETA_V, SIGMA_C = 0.22, 0.24, 1.0  # smooth terrain (β_h + β_v < ½); clutter in units of σ_c
MEAN_LEVEL, MEAN_RELIEF, MEAN_SMOOTH = 100.0, 10.0, 40.0  # local mean: level, sd and smoothing σ (px): smooth
# terrain (the paper's real IRAR means are smooth); its residual after the filters' 33 px local mean has sd ≈ 0.4σ_c
FRAMES = 20  # §4's Monte Carlo runs
PTCRS = (6.5, 8.1)  # dB, §4's Monte Carlo
EMPTY_FRAMES = 6  # Figs. 4–5: the target leaves at frame 31 and a new one appears at 37 (1-based)
MIN_REENTRY_FRAMES, AFTER_ENTRY = 51, 15  # exit_reentry runs max(51, entry + 15) frames (Fig. 5: frame 51)
MAX_FRAMES, MAX_FIRST_PATH = 10000, 10000
PTCR_RANGE = (-20.0, 60.0)  # dB, (low, high]
TEMPLATE_SIDE, SUPERSAMPLE = 11, 4
HULL_PHI, TURRET_PHI = 0.7, 1.0
# aspects 1–4 (Eq. 8's a = b·φ): (rotation °, scale, shear of the body's long axis along its short axis)
ASPECTS = ((0.0, 1.0, 0.0), (30.0, 1.0, 0.0), (60.0, 0.85, 0.0), (90.0, 1.0, 0.3))
BRUNO2008_TRUTH_COLUMNS = TRUTH_COLUMNS + ("aspect",)
PATH_DTYPE = np.dtype([("frame", np.int64), ("x", float), ("vx", float), ("y", float), ("vy", float),
                       ("aspect", np.int64)])
CLUTTER_CHUNK = 256  # frames of clutter drawn at a time (bounds the float64 work memory)


def _vehicle(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """φ at body coordinates (u along the hull, v across it, px, origin at the centroid): a hull |u| ≤ 4,
    |v| ≤ 2 (8×4 px, φ = 0.7), a turret |u|, |v| ≤ 1.5 (3×3 px) and a barrel 1.5 ≤ u ≤ 4.5, |v| ≤ 0.5 (φ = 1)."""
    hull = (np.abs(u) <= 4.0) & (np.abs(v) <= 2.0)
    turret = (np.abs(u) <= 1.5) & (np.abs(v) <= 1.5)
    barrel = (u >= 1.5) & (u <= 4.5) & (np.abs(v) <= 0.5)
    return np.where(turret | barrel, TURRET_PHI, np.where(hull, HULL_PHI, 0.0))


def _affine(degrees: float, scale: float, shear: float) -> np.ndarray:
    """The body → image map (u, v) ↦ (x, y) = R(θ)·scale·[[1, shear], [0, 1]]·(u, v), θ from +x toward +y."""
    t = math.radians(degrees)
    rot = np.array([[math.cos(t), -math.sin(t)], [math.sin(t), math.cos(t)]])
    return rot @ (scale * np.array([[1.0, shear], [0.0, 1.0]]))


def vehicle_templates(peak: float = 1.0) -> np.ndarray:
    """(4, 11, 11) float64: the vehicle at the four aspects of ``ASPECTS`` (reference, 30°, 60° × 0.85, 90°
    sheared: a gradual sequence, as G moves only to adjacent aspects).  Each pixel is the mean of φ over its
    4×4 sub-pixel centres mapped back to the body (coverage × intensity); the stack is scaled so its maximum is
    ``peak``.  The centroid is the centre pixel (row and column 5)."""
    half = TEMPLATE_SIDE // 2
    sub = (np.arange(TEMPLATE_SIDE * SUPERSAMPLE) + 0.5) / SUPERSAMPLE - 0.5 - half  # sub-pixel centres, px
    xx, yy = np.meshgrid(sub, sub)
    out = np.empty((len(ASPECTS), TEMPLATE_SIDE, TEMPLATE_SIDE))
    for k, aspect in enumerate(ASPECTS):
        u, v = np.linalg.solve(_affine(*aspect), np.stack([xx.ravel(), yy.ravel()]))
        phi = _vehicle(u, v).reshape(TEMPLATE_SIDE, SUPERSAMPLE, TEMPLATE_SIDE, SUPERSAMPLE)
        out[k] = phi.mean(axis=(1, 3))
    return out * (peak / out.max())


def ptcr_peak(ptcr_db: float, sigma_c: float = SIGMA_C) -> float:
    """The template peak a for a PTCR of ``ptcr_db``: PTCR = 20·log10(max|a| / σ_c), so a = σ_c·10^(PTCR/20).
    σ_c is the GMRF's prediction-error sd; against the marginal clutter sd σ_v = σ_c·√mean(1/λ) (σ_v/σ_c = 1.23
    at β = 0.22, 0.24 on 120×120) the same target is 1.8 dB weaker: this definition is 1–2 dB easier."""
    return sigma_c * 10.0 ** (ptcr_db / 20.0)


def streams(seed: int) -> tuple[np.random.Generator, ...]:
    """The three independent generators of a scene: (local mean, target paths, clutter)."""
    return tuple(np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(3))


def local_mean(rng: np.random.Generator, shape=SHAPE) -> np.ndarray:
    """(H, W) float64 smooth static mean: MEAN_LEVEL + MEAN_RELIEF·z, z white noise Gaussian-filtered
    (σ = MEAN_SMOOTH px, reflecting borders) and normalised to zero mean and unit sd."""
    z = ndimage.gaussian_filter(rng.standard_normal(shape), MEAN_SMOOTH, mode="reflect")
    return MEAN_LEVEL + MEAN_RELIEF * (z - z.mean()) / z.std()


def _on_grid(x: float, y: float, shape, halves) -> bool:
    """Whether the quantised centroid (Eq. 3) lies on the extended grid (``multiaspect.extended_grid``'s box)."""
    x0, x1, y0, y1 = extended_grid(shape, halves)
    return bool(x0 <= x < x1 and y0 <= y < y1)


def target_path(rng: np.random.Generator, n_frames: int, shape, halves, G, prior=PAPER_PRIOR,
                start_frame: int = 0) -> np.ndarray:
    """One target's path (PATH_DTYPE rows: frame, x, vx, y, vy, aspect) over at most ``n_frames`` frames from
    ``start_frame``.  s₀ = (x, vx, y, vy): x ~ U[prior x], y ~ U[prior y] px, each v ~ N(v_mean, v_sd²)
    px/frame; z₀ uniform on 1..K.  Then s ← F·s + w per axis, F = [[1, 1], [0, 1]] (T = 1 frame), w ~ N(0, Q)
    with Q = motion_noise(q, T, ζ) (Eq. 4), and z ~ G[:, z − 1] (Eq. 1; aspects 1-based, G's columns 0-based).
    The path ends before the first frame whose quantised centroid is off the extended grid."""
    G = np.asarray(G, float)
    k = G.shape[0]
    a, b, c = noise_factor(motion_noise(PAPER_Q, PAPER_T, PAPER_ZETA))
    x, y = rng.uniform(*prior["x"]), rng.uniform(*prior["y"])
    vx, vy = rng.normal(prior["v_mean"], prior["v_sd"], 2)
    z = int(rng.integers(1, k + 1))
    rows = []
    for i in range(n_frames):
        if i > 0:
            nx, ny = rng.standard_normal(2), rng.standard_normal(2)
            x, vx = x + vx + a * nx[0], vx + b * nx[0] + c * nx[1]
            y, vy = y + vy + a * ny[0], vy + b * ny[0] + c * ny[1]
            z = int(rng.choice(k, p=G[:, z - 1])) + 1
        if not _on_grid(x, y, shape, halves):
            break
        rows.append((start_frame + i, x, vx, y, vy, z))
    return np.array(rows, dtype=PATH_DTYPE)


def add_template(image: np.ndarray, template: np.ndarray, x: float, y: float) -> None:
    """Eq. 8 in place: ``template`` added with its centre pixel at the quantised (row, column) = (round y,
    round x) (Eq. 3), the pixels outside the image dropped (Remark 1)."""
    (h, w), (th, tw) = image.shape, template.shape
    r0, c0 = int(quantise(y)) - th // 2, int(quantise(x)) - tw // 2
    rs, cs = slice(max(r0, 0), min(r0 + th, h)), slice(max(c0, 0), min(c0 + tw, w))
    if rs.start < rs.stop and cs.start < cs.stop:
        image[rs, cs] += template[rs.start - r0:rs.stop - r0, cs.start - c0:cs.stop - c0]


def check_bruno2008(ptcr_db, frames, exit_reentry: bool) -> None:
    """A ParameterError for a PTCR that is not a finite number in (−20, 60] dB, ``frames`` not a whole number in
    [3, 10000], or ``frames`` given with ``exit_reentry`` (whose length follows the target)."""
    from .validate import whole

    lo, hi = PTCR_RANGE
    if isinstance(ptcr_db, bool) or not isinstance(ptcr_db, (int, float, np.integer, np.floating)) \
            or not math.isfinite(ptcr_db) or not lo < ptcr_db <= hi:
        raise ParameterError(f"ptcr_db (--ptcr) must be a finite number in ({lo:g}, {hi:g}] dB, got {ptcr_db!r}")
    if frames is not None:
        if exit_reentry:
            raise ParameterError("frames (--frames) cannot be given with exit_reentry (--exit-reentry): the "
                                 f"sequence runs max({MIN_REENTRY_FRAMES}, exit frame + {EMPTY_FRAMES + AFTER_ENTRY})"
                                 " frames")
        whole("frames (--frames)", frames, 3, MAX_FRAMES)


def _clutter(rng: np.random.Generator, frames: np.ndarray) -> None:
    """Add one exact GMRF draw (β_h, β_v, σ_c) to each frame, CLUTTER_CHUNK frames at a time (the same numbers
    as one draw of all: the generator fills them in order)."""
    for f0 in range(0, len(frames), CLUTTER_CHUNK):
        n = min(CLUTTER_CHUNK, len(frames) - f0)
        frames[f0:f0 + n] += sample_gmrf(rng, frames.shape[1:], BETA_H, BETA_V, SIGMA_C, n)


def simulate_bruno2008(seed: int = 0, ptcr_db: float = 6.5, exit_reentry: bool = False, frames: int | None = None,
                       templates=None, shape=SHAPE) -> Scenario:
    """The frames (T, H, W) float32 = local mean + template + GMRF clutter, the truth (with ``aspect``)
    and the parameters of a §4 scene (``shape`` 120×120: the paper's figures; others for benchmarks).
    ``templates`` (K, h, w) replace the vehicle (scaled so that their maximum |a| gives ``ptcr_db``; G then is
    ``aspect_transition(K)``).  The same seed gives the same frames."""
    from .validate import frame_shape, whole

    check_bruno2008(ptcr_db, frames, exit_reentry)
    whole("seed", seed, 0)
    shape = frame_shape("shape", shape)
    peak = ptcr_peak(float(ptcr_db))
    if templates is None:
        templates = check_templates(vehicle_templates(peak))
    else:
        templates = check_templates(templates)
        templates = templates * (peak / np.abs(templates).max())
    G, halves = aspect_transition(len(templates)), half_sizes(templates)
    mean_rng, path_rng, clutter_rng = streams(seed)
    mean = local_mean(mean_rng, shape)
    exit_frame = entry_frame = None
    if exit_reentry:
        first = target_path(path_rng, MAX_FIRST_PATH, shape, halves, G)
        exit_frame, entry_frame = len(first), len(first) + EMPTY_FRAMES
        n_frames = max(MIN_REENTRY_FRAMES, entry_frame + AFTER_ENTRY)
        paths = [first, target_path(path_rng, n_frames - entry_frame, shape, halves, G, start_frame=entry_frame)]
    else:
        n_frames = FRAMES if frames is None else int(frames)
        paths = [target_path(path_rng, n_frames, shape, halves, G)]
    images = np.empty((n_frames,) + shape, dtype=np.float32)
    images[:] = mean
    peaks = np.abs(templates).max(axis=(1, 2))
    rows = []
    for tid, path in enumerate(paths):
        for p in path:
            add_template(images[p["frame"]], templates[p["aspect"] - 1], p["x"], p["y"])
            rows.append((p["frame"], tid, p["x"], p["y"], p["vx"], p["vy"], peaks[p["aspect"] - 1], p["aspect"]))
    _clutter(clutter_rng, images)
    params = dict(scenario="bruno2008", seed=seed, ptcr_db=float(ptcr_db), beta_h=BETA_H, beta_v=BETA_V,
                  sigma_c=SIGMA_C, exit_reentry=bool(exit_reentry), exit_frame=exit_frame, entry_frame=entry_frame,
                  q=PAPER_Q, T=PAPER_T, zeta=PAPER_ZETA, shape=list(shape), frames=n_frames)
    return Scenario(images, make_table(rows, _dtype(BRUNO2008_TRUTH_COLUMNS)), params)


def bench_frames(shape, n_frames: int, seed: int = 0) -> np.ndarray:
    """``tbd-taichi bench``'s frames for the multiaspect filters: a §4 scene of ``shape`` at PTCR 6.5 dB."""
    return simulate_bruno2008(seed, PTCRS[0], frames=max(3, n_frames), shape=shape).frames[:n_frames]
