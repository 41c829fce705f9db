"""``tophat-pf``: Güler's (2016) top-hat candidates and one SIR particle filter per candidate (METU thesis, §3).

Frames 0–2: row-mean removal and an opening top-hat (Eqs. 3.4–3.10), their projection thresholded at μ + ασ
(Eqs. 3.12–3.13), one candidate per 8-connected component.  From frame 3: the cumulative-mean background (Algs.
8–9), one SIR filter per candidate in one pool (Eqs. 3.2, 3.14, 3.16; Algs. 2, 6), and at the end of each window
the trajectory cost, merge and elimination of Alg. 5 until ≤ 2 remain; the survivor with the strongest evidence
is confirmed and reported.  Equations → code: docs/methods/tophat-pf.md."""
from __future__ import annotations

import dataclasses

from ..registry import MethodSpec
from .params import TophatPFParams, tophat_pf_params
from .tracker import TophatPFTracker


def _factory(shape, params, *, seed: int, engine: str, arch, init_box=None, **options):
    return TophatPFTracker(shape, seed=seed, engine=engine, arch=arch, **options, **dataclasses.asdict(params))


SPEC = MethodSpec(
    name="tophat-pf", title="top-hat + PF", paper="Güler 2016",
    kind="point-tbd",
    description="lists candidates by a top-hat over the first 3 frames, runs one SIR filter per candidate with a "
                "drift learnt from its own path, and drops the candidates whose motion is not smooth",
    params=TophatPFParams, factory=_factory, make_params=tophat_pf_params, scenario="guler2016", min_frames=4,
    options=("report", "paths", "diagnostics"), aliases={"particles": "n_particles"}, rank=6,
    particle_count=lambda shape, params: params.max_candidates * params.n_particles,
    assumes="one point target present and above the top-hat threshold in frames 0–2, moving smoothly (≤ a few "
            "px a frame) over a still background",
)

__all__ = ["SPEC", "TophatPFParams", "TophatPFTracker"]
