"""``tbd-taichi bench``: median ms/frame per stage, Taichi against NumPy in the same run.

The whole SGDS-PF pipeline runs through the public API, one :meth:`SGDSPF.update` per frame
with the Table 2 preset of ``snr``, on a simulated sequence of that SNR.  Stages (each timed
per frame after a warm-up, median over the timed frames):

* ``normalise``: z = (frame − median)/(1.4826·MAD) on the host;
* ``saliency``: the whole multi-frame saliency stage (Eqs. 20–33), from z to the
  per-block proposal map;
* ``searching``: Algorithm 1 (all blocks' searching PFs, PP bookkeeping, hand-over);
* ``tracking``: Algorithm 2 (all tracking PFs, confirmation, paths);
* ``particles`` (with ``particles > 0``): one full particle-filter step of a separate pool
  of that many particles split into ``groups`` filters, :meth:`ParticlePool.step`.

``pipeline=False`` (``--no-pipeline``) times only ``normalise`` and ``saliency`` (with a
:class:`SaliencyExtractor`), plus ``particles`` if asked.

``frontend_process=True`` (``--frontend-process``): the tracker runs normalisation and saliency
in a second process, one frame ahead (:mod:`tbd_taichi.frontend`).  Their times are then the
child's own, spent alongside the particle filters, and the stage ``waiting`` is this process's
wait for the child (hand-over of the frame, copies of z and the proposal map).

``machine`` names the CPU and its logical CPU count, ``versions`` Python, Taichi and NumPy: figures
from different machines differ by 2× and more (docs/results/bench_machines.md), so every result says
where it was measured.

``runs`` > 1 repeats each engine's run, the engines in turn and in alternating order; the medians pool all
runs' frames, and each run's median update time and NumPy/Taichi ratio are listed too.

``total`` is the sum of the stage medians (CPU work, in either process); ``update_ms`` the median
wall time of one ``update`` call (or of the saliency step) and ``fps`` its inverse;
``peak_rss_mib`` the peak resident memory after the engine's run, of this process (everything
measured before in it included) plus its largest ended child (the front-end process).
"""
from __future__ import annotations

import functools
import os
import platform
import time

import numpy as np

from . import backend
from .errors import ParameterError
from .normalize import normalise_frame
from .particles import ParticlePool
from .pf import birth_intensity_range
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


def pipeline_stepper(shape, snr: float, engine: str, frontend_process: bool = False):
    """One SGDSPF.update per call, which returns the seconds each pipeline stage took; and a function
    that stops the tracker's front-end process (if any)."""
    from .sgds import SGDSPF

    tracker = SGDSPF(shape, snr=snr, engine=engine, history=False, frontend_process=frontend_process)

    def step(frame: np.ndarray) -> dict[str, float]:
        before = dict(tracker.stage_seconds)
        tracker.update(frame)
        return {name: tracker.stage_seconds[name] - before[name] for name in before}
    return step, tracker.front.close


def saliency_stepper(shape, snr: float, engine: str, frontend_process: bool = False):
    """Normalisation and the saliency stage only (no particle filters; ``frontend_process`` unused)."""
    from .params import SGDSParams
    from .saliency import SaliencyExtractor

    ext = SaliencyExtractor(shape, snr=snr, block_size=SGDSParams.for_snr(snr).L_ib, engine=engine, details=False)

    def step(frame: np.ndarray) -> dict[str, float]:
        t0 = time.perf_counter()
        z = normalise_frame(frame).z
        t1 = time.perf_counter()
        ext.push(z)
        return {"normalise": t1 - t0, "saliency": time.perf_counter() - t1}
    return step, lambda: None


def engine_samples(frames: np.ndarray, snr: float, engine: str, particles: int = 0, groups: int = 1,
                   pipeline: bool = True, frontend_process: bool = False) -> dict[str, list[float]]:
    """One engine's run over raw ``frames`` (T, H, W): seconds per timed frame (after WARMUP) of each stage,
    and of the whole step under "update"."""
    step, close = (pipeline_stepper if pipeline else saliency_stepper)(frames.shape[1:], snr, engine,
                                                                      frontend_process)
    pool = benchmark_pool(frames.shape[1:], particles, groups, engine, snr) if particles else None
    samples: dict[str, list[float]] = {}
    for t, frame in enumerate(frames):
        t0 = time.perf_counter()
        seconds = step(frame)
        t1 = time.perf_counter()
        if pool is not None:
            z = normalise_frame(frame).z  # untimed: the pipeline has normalised this frame already
            t2 = time.perf_counter()
            pool.step(t, z)
            seconds["particles"] = time.perf_counter() - t2
        if t >= WARMUP:
            for name, value in {**seconds, "update": t1 - t0}.items():
                samples.setdefault(name, []).append(value)
    close()  # a front-end process ends here, so its peak memory counts below
    return samples


def engine_summary(runs: list[dict[str, list[float]]]) -> dict:
    """Per-stage median ms/frame over the timed frames of all ``runs`` (``engine_samples`` results), their sum,
    the median update time, fps, each run's median update time and the process's peak memory now."""
    pooled = {name: [v for run in runs for v in run[name]] for name in runs[0]}
    medians = {name: _median_ms(v) for name, v in pooled.items() if name != "update"}
    update_ms = _median_ms(pooled["update"])
    return {"stages": medians, "total": float(sum(medians.values())), "update_ms": update_ms,
            "fps": 1e3 / update_ms, "run_update_ms": [_median_ms(run["update"]) for run in runs],
            "peak_rss_mib": peak_rss_mib()}


@functools.lru_cache(maxsize=1)
def machine_description() -> str:
    """The CPU model and logical CPU count, e.g. "Intel(R) Xeon(R) Processor, 16 CPUs"."""
    model = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as info:
            model = next((line.split(":", 1)[1].strip() for line in info if line.startswith("model name")), model)
    except OSError:
        pass
    return f"{model}, {os.cpu_count()} CPUs"


def software_versions() -> dict:
    """Versions of Python, Taichi and NumPy, which the figures depend on."""
    import taichi

    return {"python": platform.python_version(), "taichi": ".".join(map(str, taichi.__version__)),
            "numpy": np.__version__}


def peak_rss_mib() -> float:
    """Peak resident set size of this process plus that of its largest ended child process (the
    tracker's front-end process), MiB."""
    import resource
    import sys

    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss + resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    return peak / 2**20 if sys.platform == "darwin" else peak / 1024  # bytes on macOS, KiB on Linux


def run_bench(shape, snr: float = 1.4, n_frames: int = 20, engines=("taichi", "numpy"), arch: str = "cpu",
              seed: int = 0, particles: int = 0, groups: int = 1, pipeline: bool = True,
              frontend_process: bool = False, runs: int = 1) -> dict:
    """Benchmark every engine on the same simulated sequence; returns the JSON-ready result.
    ``frontend_process``: the trackers run normalisation and saliency in a second process.  ``runs`` > 1
    repeats the engines' runs, in turn and in alternating order (taichi, numpy, numpy, taichi, …), so that a
    VM's slow spells (10–50 % for minutes) fall on both; the medians pool every run's frames, and
    ``run_update_ms`` lists each run's median update time (``run_ratios``: NumPy over Taichi, run by run)."""
    if runs < 1:
        raise ParameterError(f"runs must be ≥ 1, got {runs}")
    backend.keep_freed_memory()
    cfg = backend.init(arch)
    frames = simulate(tuple(shape), frames=n_frames + WARMUP, snr=snr, seed=seed, motion="transit").frames
    result = {"shape": [int(shape[0]), int(shape[1])], "snr": snr, "frames": n_frames, "arch": cfg.arch,
              "particles": particles, "groups": groups, "pipeline": pipeline,
              "frontend_process": bool(frontend_process and pipeline), "runs": runs, "machine": machine_description(),
              "versions": software_versions(), "engines": {}}
    samples: dict[str, list] = {engine: [] for engine in engines}
    for r in range(runs):
        for engine in (engines if r % 2 == 0 else engines[::-1]):
            samples[engine].append(engine_samples(frames, snr, engine, particles, groups, pipeline, frontend_process))
    for engine in engines:
        result["engines"][engine] = engine_summary(samples[engine])
    if "taichi" in samples and "numpy" in samples:
        result["run_ratios"] = [n / t for n, t in zip(result["engines"]["numpy"]["run_update_ms"],
                                                     result["engines"]["taichi"]["run_update_ms"])]
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
    front = ", front end in a second process" if result.get("frontend_process") else ""
    front += f", {result['runs']} runs each" if result.get("runs", 1) > 1 else ""
    lines = [f"shape {result['shape'][0]}x{result['shape'][1]} (HxW), SNR preset {result['snr']}, "
             f"{result['frames']} timed frames{pool}, arch {result['arch']}{front}",
             f"on {result.get('machine', 'an unrecorded machine')}", head]
    for stage in stages + ["update", "fps", "peak MiB"]:
        vals = {n: _row_value(engines[n], stage) for n in names}
        row = f"{stage:<12}" + "".join(f"{vals[n]:>14.3f}" for n in names)
        if ratio and stage not in ("fps", "peak MiB"):
            row += f"{vals['numpy'] / vals['taichi']:>13.1f}x"
        lines.append(row)
    if result.get("runs", 1) > 1:
        for n in names:
            lines.append(f"{n} update per run: " + ", ".join(f"{v:.2f}" for v in engines[n]["run_update_ms"]) + " ms")
        if "run_ratios" in result:
            lines.append("numpy/taichi per run: " + ", ".join(f"{v:.1f}x" for v in result["run_ratios"]))
    return "\n".join(lines)


def _row_value(engine: dict, stage: str) -> float:
    extra = {"total": "total", "update": "update_ms", "fps": "fps", "peak MiB": "peak_rss_mib"}
    return engine[extra[stage]] if stage in extra else engine["stages"][stage]
