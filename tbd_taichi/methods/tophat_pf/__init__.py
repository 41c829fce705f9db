"""``tophat-pf``: Güler's (2016) top-hat candidates and one SIR particle filter per candidate (METU thesis, §3).

Frames 0–2: row-mean removal and an opening top-hat (Eqs. 3.4–3.10), their projection thresholded at μ + ασ
(Eqs. 3.12–3.13), one candidate per 8-connected component.  From frame 3: the cumulative-mean background (Algs.
8–9), one SIR filter per candidate in one pool (Eqs. 3.2, 3.14, 3.16; Algs. 2, 6), and at the end of each window
the trajectory cost, merge and elimination of Alg. 5 until ≤ 2 remain; the survivor with the strongest evidence
is confirmed and reported.  Equations → code: docs/methods/tophat-pf.md."""
from __future__ import annotations

import dataclasses

import numpy as np

from ..registry import MethodSpec
from .params import TophatPFParams, tophat_pf_params
from .tracker import TophatPFTracker


def _factory(shape, params, *, seed: int, engine: str, arch, init_box=None, **options):
    return TophatPFTracker(shape, seed=seed, engine=engine, arch=arch, **options, **dataclasses.asdict(params))


BENCH_NOISE, BENCH_DELTA, BENCH_SPOTS = 3.5, 30.0, 0.008  # counts, counts, clutter spots per pixel


def bench_frames(shape, n_frames: int, seed: int = 0) -> np.ndarray:
    """``tbd-taichi bench``'s frames: a 14-bit wall (mean 7195 counts, a row gradient of ±10, temporal noise σ 3.5)
    with still clutter spots (0.8 % of the pixels, 10–40 counts: dozens of candidates, 64 at 320 × 256) and one
    target pixel at mean + 30 counts crossing the middle row at 0.5 px/frame."""
    rng = np.random.default_rng(seed)
    h, w = shape
    wall = 7195.0 + np.linspace(-10.0, 10.0, h)[:, None] + np.zeros((h, w))
    spots = rng.integers(0, h * w, max(1, int(BENCH_SPOTS * h * w)))
    wall.flat[spots] += rng.uniform(10.0, 40.0, len(spots))
    frames = wall + rng.normal(0.0, BENCH_NOISE, (n_frames, h, w))
    for k in range(n_frames):
        frames[k, h // 2, min(k // 2, w - 1)] = frames[k].mean() + BENCH_DELTA
    return np.clip(np.rint(frames), 0, 16383).astype(np.uint16)


SPEC = MethodSpec(
    name="tophat-pf", title="top-hat + PF", paper="Güler 2016",
    kind="point-tbd",
    description="lists candidates by a top-hat over the first 3 frames, runs one SIR filter per candidate with a "
                "drift learnt from its own path, and drops the candidates whose motion is not smooth",
    params=TophatPFParams, factory=_factory, make_params=tophat_pf_params, scenario="guler2016", min_frames=4,
    options=("report", "paths", "diagnostics"), aliases={"particles": "n_particles"}, rank=6,
    particle_count=lambda shape, params: params.max_candidates * params.n_particles,
    bench_settings=lambda snr: {}, bench_frames=bench_frames,
    assumes="one point target present and above the top-hat threshold in frames 0–2, moving smoothly (≤ a few "
            "px a frame) over a still background",
)

__all__ = ["SPEC", "TophatPFParams", "TophatPFTracker"]
