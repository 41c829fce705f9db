"""``tbd-taichi bench``: median ms/frame per stage, Taichi against NumPy in the same run.

Stages (each timed per frame after a warm-up, median over the timed frames):

* ``normalise``: z = (frame − median)/(1.4826·MAD) on the host;
* ``saliency``: the whole multi-frame saliency stage (Eqs. 20–33), from z to the
  per-block proposal map, one :meth:`SaliencyExtractor.push` per frame;
* ``particles`` (with ``particles > 0``): one full particle-filter step of a pool of
  that many particles split into ``groups`` filters (existence, newborn draws,
  propagation, weighting, normalisation, resampling), :meth:`ParticlePool.step`.

``total`` is the sum of the stage medians.
"""
from __future__ import annotations

import time

import numpy as np

from . import backend
from .normalize import normalise_frame
from .params import SGDSParams
from .particles import ParticlePool
from .pf import birth_intensity_range
from .saliency import SaliencyExtractor
from .simulate import simulate

WARMUP = 3


def _median_ms(samples: list[float]) -> float:
    return float(np.median(samples) * 1e3)


def benchmark_pool(shape, particles: int, groups: int, engine: str, snr: float, seed: int = 0) -> ParticlePool:
    """A pool of ``particles`` split evenly into ``groups`` filters, half of them present at random positions."""
    caps = np.full(groups, particles // groups)
    caps[: particles % groups] += 1
    pool = ParticlePool(caps, shape, engine=engine, seed=seed)
    pool.configure_groups(np.arange(groups), "uniform", intensity=birth_intensity_range(snr))
    rng = np.random.default_rng(seed)
    h, w = shape
    pool.set_state({g: dict(x=rng.uniform(-0.5, w - 0.5, c), y=rng.uniform(-0.5, h - 0.5, c),
                            vx=rng.uniform(-1, 1, c), vy=rng.uniform(-1, 1, c), inten=rng.uniform(2, 9, c),
                            e=(rng.random(c) < 0.5).astype(np.int32), tp=np.ones(c, np.int32))
                    for g, c in enumerate(caps)})
    return pool


def bench_engine(frames: np.ndarray, snr: float, engine: str, particles: int = 0, groups: int = 1) -> dict:
    """Per-stage median ms/frame for one engine on raw ``frames`` (T, H, W)."""
    ext = SaliencyExtractor(frames.shape[1:], snr=snr, block_size=SGDSParams.for_snr(snr).L_ib, engine=engine,
                             details=False)
    pool = benchmark_pool(frames.shape[1:], particles, groups, engine, snr) if particles else None
    stages: dict[str, list[float]] = {"normalise": [], "saliency": []}
    if pool is not None:
        stages["particles"] = []
    for t, frame in enumerate(frames):
        t0 = time.perf_counter()
        z = normalise_frame(frame).z
        t1 = time.perf_counter()
        ext.push(z)
        t2 = time.perf_counter()
        if pool is not None:
            pool.step(t, z)
        t3 = time.perf_counter()
        if t >= WARMUP:
            stages["normalise"].append(t1 - t0)
            stages["saliency"].append(t2 - t1)
            if pool is not None:
                stages["particles"].append(t3 - t2)
    medians = {name: _median_ms(v) for name, v in stages.items()}
    return {"stages": medians, "total": float(sum(medians.values()))}


def run_bench(shape, snr: float = 1.4, n_frames: int = 20, engines=("taichi", "numpy"), arch: str = "cpu",
              seed: int = 0, particles: int = 0, groups: int = 1) -> dict:
    """Benchmark every engine on the same simulated sequence; returns the JSON-ready result."""
    cfg = backend.init(arch)
    frames = simulate(tuple(shape), frames=n_frames + WARMUP, snr=snr, seed=seed, motion="transit").frames
    result = {"shape": [int(shape[0]), int(shape[1])], "snr": snr, "frames": n_frames, "arch": cfg.arch,
              "particles": particles, "groups": groups, "engines": {}}
    for engine in engines:
        result["engines"][engine] = bench_engine(frames, snr, engine, particles, groups)
    return result


def format_table(result: dict) -> str:
    """A readable table with the Taichi/NumPy speed ratio per stage."""
    engines = result["engines"]
    stages = list(next(iter(engines.values()))["stages"]) + ["total"]
    names = list(engines)
    head = f"{'stage':<12}" + "".join(f"{n + ' ms':>14}" for n in names)
    ratio = "taichi" in engines and "numpy" in engines
    head += f"{'numpy/taichi':>14}" if ratio else ""
    pool = f", {result['particles']} particles in {result['groups']} group(s)" if result.get("particles") else ""
    lines = [f"shape {result['shape'][0]}x{result['shape'][1]} (HxW), SNR preset {result['snr']}, "
             f"{result['frames']} timed frames{pool}, arch {result['arch']}", head]
    for stage in stages:
        vals = {n: (engines[n]["total"] if stage == "total" else engines[n]["stages"][stage]) for n in names}
        row = f"{stage:<12}" + "".join(f"{vals[n]:>14.3f}" for n in names)
        if ratio:
            row += f"{vals['numpy'] / vals['taichi']:>13.1f}x"
        lines.append(row)
    return "\n".join(lines)
