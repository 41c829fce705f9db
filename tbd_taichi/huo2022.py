"""The ``huo2022`` scenario: box-truth sequences after Huo et al. 2022's Table 1 (their data, ref. [23], is not
shipped): 256 × 256 frames in 8-bit grey levels, one target with a box per frame.

Sequences (``SEQUENCES``; Table 1's characteristics):

* ``weak``: a 2 × 2 target of peak contrast 3σ (``dim_contrast``) over a smooth background, slow wandering (data5, data20);
* ``complex``: a 2 × 2 target among bright clutter blobs of the same contrast on a textured background (data8,
  data19);
* ``fast``: a 5 × 5 textured target moving fast with sudden jumps and growing from far to near (data16, data18);
* ``rotating``: an elongated 5 × 3 target that rotates as it moves, while the background changes from sky to
  terrain (data20's rotation and its Fig. 6 change "from sky to mountain"): from 40 % of the frames on, a brighter
  textured ground rises from the bottom edge to row 60 (``horizon``).

Truth: ``frame,x,y,w,h,target_id`` with x, y the box's top-left corner (as drone-ir's labels), w, h its size; the
box centre (x + w/2, y + h/2) is the target's centre."""
from __future__ import annotations

import math

import numpy as np
from scipy import ndimage

from .errors import ParameterError
from .simulate import Scenario
from .tables import BOX_COLUMNS, _dtype, make_table

SHAPE = (256, 256)
SEQUENCES = ("weak", "complex", "fast", "rotating")
FRAMES = 200
NOISE = 4.0  # grey levels: the sensor noise σ
DIM_CONTRAST = 3.0  # the weak and complex 2 × 2 targets' peak contrast, in units of NOISE
TRUTH_COLUMNS = BOX_COLUMNS + ("target_id",)


def check_huo2022(sequence: str, frames, dim_contrast=DIM_CONTRAST) -> None:
    """A ParameterError for an unknown sequence, a frame count outside [2, 5000] or a ``dim_contrast`` that is not
    a finite number > 0."""
    from .validate import positive, whole

    if sequence not in SEQUENCES:
        raise ParameterError(f"sequence (--sequence) must be one of {', '.join(SEQUENCES)}, got {sequence!r}")
    if frames is not None:
        whole("frames (--frames)", frames, 2, 5000)
    positive("dim_contrast", dim_contrast)


def background(rng: np.random.Generator, textured: bool) -> np.ndarray:
    """A static background in grey levels: smooth relief (σ 30 px) around 90, plus fine texture when ``textured``."""
    relief = ndimage.gaussian_filter(rng.standard_normal(SHAPE), 30, mode="reflect")
    out = 90 + 25 * relief / relief.std()
    if textured:
        fine = ndimage.gaussian_filter(rng.standard_normal(SHAPE), 2.5, mode="reflect")
        out += 12 * fine / fine.std()
    return out


def target_patch(size: tuple[int, int], angle: float, rng_texture: np.ndarray) -> np.ndarray:
    """A (size) target rotated by ``angle`` (rad): a rectangle of the textured values ``rng_texture`` (values in
    [0, 1], 2 px of supersampling), returned as coverage × texture on a square canvas."""
    h, w = size
    side = int(math.ceil(math.hypot(h, w))) | 1
    yy, xx = (np.mgrid[0:side * 4, 0:side * 4] + 0.5) / 4.0 - side / 2.0
    c, s = math.cos(angle), math.sin(angle)
    u, v = c * xx + s * yy, -s * xx + c * yy
    inside = (np.abs(u) < w / 2) & (np.abs(v) < h / 2)
    tex = rng_texture[np.clip((v + h / 2).astype(int), 0, h - 1), np.clip((u + w / 2).astype(int), 0, w - 1)]
    return (inside * tex).reshape(side, 4, side, 4).mean(axis=(1, 3))


def terrain(rng: np.random.Generator) -> np.ndarray:
    """The ground that rises into the ``rotating`` sequence: brighter than the sky (about 125 grey levels) with
    fine texture of sd 15."""
    fine = ndimage.gaussian_filter(rng.standard_normal(SHAPE), 1.5, mode="reflect")
    relief = ndimage.gaussian_filter(rng.standard_normal(SHAPE), 12, mode="reflect")
    return 125 + 15 * fine / fine.std() + 10 * relief / relief.std()


def horizon(t: int, n: int) -> float:
    """The row where the ground starts in frame t of n (below the image until 40 % of the frames, then rising
    linearly to row 60 at the last frame)."""
    start, top = SHAPE[0] + 4.0, 60.0
    share = min(max((t - 0.4 * n) / max(0.6 * n - 1, 1), 0.0), 1.0)
    return start - share * (start - top)


def path(rng: np.random.Generator, n: int, sequence: str) -> np.ndarray:
    """(n, 2) target centres (x, y): a smooth wander, fast with jumps for ``fast``."""
    speed = 3.0 if sequence == "fast" else 0.8
    heading = rng.uniform(0, 2 * math.pi)
    pos = np.array([rng.uniform(70, 186), rng.uniform(70, 186)])
    out = np.zeros((n, 2))
    for t in range(n):
        heading += rng.normal(0, 0.15)
        pos = pos + speed * np.array([math.cos(heading), math.sin(heading)])
        if sequence == "fast" and t % 60 == 59:
            pos = pos + rng.uniform(-12, 12, 2)  # a sudden jump (camera micro-vibration)
        for k in range(2):  # bounce off a 24 px margin
            if not 24 <= pos[k] <= SHAPE[1 - k] - 24:
                heading = math.pi - heading if k == 0 else -heading
                pos[k] = np.clip(pos[k], 24, SHAPE[1 - k] - 24)
        out[t] = pos
    return out


def simulate_huo2022(sequence: str = "fast", seed: int = 0, frames: int | None = None,
                     dim_contrast: float = DIM_CONTRAST) -> Scenario:
    """Frames (T, 256, 256) float32 in grey levels and box truth of ``sequence`` (module docstring);
    ``dim_contrast``: the weak and complex targets' peak contrast in noise σ (the complex clutter blobs keep 3σ)."""
    from .validate import whole

    check_huo2022(sequence, frames, dim_contrast)
    whole("seed", seed, 0)
    n = FRAMES if frames is None else int(frames)
    rng = np.random.default_rng([seed, SEQUENCES.index(sequence)])
    base = background(rng, textured=sequence in ("complex", "fast"))
    if sequence == "complex":  # 40 target-like blobs
        for _ in range(40):
            r, c = rng.integers(4, SHAPE[0] - 4, 2)
            base[r:r + 2, c:c + 2] += 3 * NOISE
    centres = path(rng, n, sequence)
    texture = rng.uniform(0.6, 1.0, (7, 7))
    ground = terrain(rng) if sequence == "rotating" else None
    rows_of = np.arange(SHAPE[0], dtype=float)[:, None]
    contrast = float(dim_contrast) * NOISE if sequence in ("weak", "complex") else 60.0
    images = np.empty((n,) + SHAPE, np.float32)
    rows = []
    for t in range(n):
        if sequence == "fast":
            side = int(round(3 + 4 * t / max(n - 1, 1))) | 1  # from far (3 px) to near (7 px)
            size, angle = (side, side), 0.0
        elif sequence == "rotating":
            size, angle = (3, 5), 2 * math.pi * t / 120
        else:
            size, angle = (2, 2), 0.0
        patch = contrast * target_patch(size, angle, texture)
        frame = base + rng.normal(0, NOISE, SHAPE)
        if ground is not None:  # sky above the horizon, ground below (a 3 px soft edge)
            share = np.clip((rows_of - horizon(t, n)) / 3.0 + 0.5, 0.0, 1.0)
            frame = frame + share * (ground - base)
        x, y = centres[t]
        half = patch.shape[0] / 2
        r0, c0 = int(round(y - half)), int(round(x - half))
        frame[r0:r0 + patch.shape[0], c0:c0 + patch.shape[1]] += patch
        images[t] = np.clip(frame, 0, 255)
        extent_y, extent_x = np.nonzero(patch > 0.25 * contrast)
        by0, by1 = r0 + extent_y.min(), r0 + extent_y.max() + 1
        bx0, bx1 = c0 + extent_x.min(), c0 + extent_x.max() + 1
        rows.append((t, bx0 - 0.5, by0 - 0.5, bx1 - bx0, by1 - by0, 0))
    params = dict(scenario="huo2022", sequence=sequence, seed=seed, frames=n, shape=list(SHAPE), noise=NOISE,
                  contrast=contrast)
    return Scenario(images, make_table(rows, _dtype(TRUTH_COLUMNS)), params)
