"""``tbd-taichi bench``: median ms/frame per stage, Taichi against NumPy in the same run.

A method's whole pipeline (``method``, any registered one; default SGDS-PF) runs through the public API, one
``update`` per frame with the preset of ``snr`` (or the method's ``bench_settings``), on a simulated sequence of
that SNR (or the method's ``bench_scene``: MM-PHD's has three targets at 13 dB and §5.3's settings).  Stages are the tracker's
``timings`` (each timed per frame after a warm-up, median over the timed frames); SGDS-PF's:

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
runs' frames, and each run's median update time and NumPy/Taichi ratio are listed too.  ``paired=True``
(``--paired``) has the engines take the frames in turn within each run, frame by frame, so that a slow spell
of the machine, however short, slows both: the ratio then holds from run to run.

On the CPU backend each engine also reports ``kernels_ms``, the median time in kernel launches
(:class:`~tbd_taichi.launch.LaunchClock`; 0 for the NumPy engine), and ``host_ms``, the median of ``update``
less that: the Python scheduler, NumPy and OpenCV work, which both engines run.

``total`` is the sum of the stage medians (CPU work, in either process); ``update_ms`` the median
wall time of one ``update`` call (or of the saliency step) and ``fps`` its inverse;
``peak_rss_mib`` the peak resident memory after the engine's run, of this process (everything
measured before in it included) plus its largest ended child (the front-end process).
"""
from __future__ import annotations

import contextlib
import functools
import os
import platform
import time

import numpy as np

from . import backend
from .errors import ParameterError
from .launch import LaunchClock
from .normalize import normalise_frame
from .particles import ParticlePool
from .methods.pf import birth_intensity_range
from .simulate import simulate

WARMUP = 3
KERNEL_PREFIX = "kernel "  # per-kernel sample names in engine_samples' results


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


def pipeline_stepper(shape, snr: float, engine: str, frontend_process: bool = False, method: str = "sgds",
                     settings=None):
    """One ``update`` of method ``method``'s tracker per call, which returns the seconds each of its stages
    (``timings``) took; and a function that releases the tracker (SGDS-PF's front-end process, if any).
    ``settings``: parameters over the method's bench keywords (``bench --param``)."""
    from . import methods

    spec = methods.get(method)
    options = {"history": False} if "history" in spec.options else {}
    if frontend_process:
        if "frontend_process" not in spec.options:
            raise ParameterError(f"--frontend-process applies to sgds only, not to {method}")
        options["frontend_process"] = True
    tracker = methods.make_tracker(method, shape, engine=engine, **{**spec.bench_keywords(snr), **(settings or {})},
                                   **options)

    def step(frame: np.ndarray) -> dict[str, float]:
        before = tracker.timings
        tracker.update(frame)
        after = tracker.timings
        return {name: after[name] - before[name] for name in before}
    return step, getattr(tracker, "close", lambda: None)


def saliency_stepper(shape, snr: float, engine: str, frontend_process: bool = False, method: str = "sgds",
                     settings=None):
    """Normalisation and the saliency stage only (no particle filters; ``frontend_process``, ``method``,
    ``settings`` unused)."""
    from .methods.sgds.params import SGDSParams
    from .saliency import SaliencyExtractor

    ext = SaliencyExtractor(shape, snr=snr, block_size=SGDSParams.for_snr(snr).L_ib, engine=engine, details=False)

    def step(frame: np.ndarray) -> dict[str, float]:
        t0 = time.perf_counter()
        z = normalise_frame(frame).z
        t1 = time.perf_counter()
        ext.push(z)
        return {"normalise": t1 - t0, "saliency": time.perf_counter() - t1}
    return step, lambda: None


def engine_samples(frames: np.ndarray, snr: float, engines: tuple, particles: int = 0, groups: int = 1,
                   pipeline: bool = True, frontend_process: bool = False,
                   kernel_time: bool = False, method: str = "sgds", settings=None) -> dict[str, dict[str, list[float]]]:
    """The runs of ``engines`` over raw ``frames`` (T, H, W), frame by frame in turn (in ``engines``' order on
    even frames, reversed on odd ones), so that a slow spell of the machine slows each alike; with one engine, its
    run alone.  Per engine, seconds per timed frame (after WARMUP) of each stage and of the whole step
    ("update"); with ``kernel_time`` (CPU backends) also the time in kernel launches ("kernels",
    :class:`~tbd_taichi.launch.LaunchClock`)."""
    stepper = pipeline_stepper if pipeline else saliency_stepper
    steps, closers, pools = {}, [], {}
    for engine in engines:
        steps[engine], close = stepper(frames.shape[1:], snr, engine, frontend_process, method, settings)
        closers.append(close)
        pools[engine] = benchmark_pool(frames.shape[1:], particles, groups, engine, snr) if particles else None
    samples: dict[str, dict[str, list[float]]] = {engine: {} for engine in engines}
    for t, frame in enumerate(frames):
        for engine in (engines if t % 2 == 0 else engines[::-1]):
            with LaunchClock() if kernel_time else contextlib.nullcontext() as clock:
                t0 = time.perf_counter()
                seconds = steps[engine](frame)
                t1 = time.perf_counter()
            if kernel_time:
                seconds["kernels"] = clock.seconds
                seconds.update({KERNEL_PREFIX + name: v for name, v in clock.by_kernel.items()})
            if pools[engine] is not None:
                z = normalise_frame(frame).z  # untimed: the pipeline has normalised this frame already
                t2 = time.perf_counter()
                pools[engine].step(t, z)
                seconds["particles"] = time.perf_counter() - t2
            if t >= WARMUP:
                for name, value in {**seconds, "update": t1 - t0}.items():
                    samples[engine].setdefault(name, []).append(value)
    for close in closers:
        close()  # a front-end process ends here, so its peak memory counts below
    return samples


def engine_summary(runs: list[dict[str, list[float]]]) -> dict:
    """Per-stage median ms/frame over the timed frames of all ``runs`` (``engine_samples`` results of one
    engine), their sum, the median update time, fps, each run's median update time and the process's peak memory
    now; with kernel times, the median ms in kernel launches ("kernels_ms") and outside them ("host_ms": the
    Python, NumPy and OpenCV work of ``update``), and per kernel ("kernel_ms", largest first: the median over
    the frames in which the kernel ran)."""
    names = dict.fromkeys(name for run in runs for name in run)  # a kernel may run in some runs only
    pooled = {name: [v for run in runs for v in run.get(name, [])] for name in names}
    medians = {name: _median_ms(v) for name, v in pooled.items()
               if name not in ("update", "kernels") and not name.startswith(KERNEL_PREFIX)}
    update_ms = _median_ms(pooled["update"])
    summary = {"stages": medians, "total": float(sum(medians.values())), "update_ms": update_ms,
               "fps": 1e3 / update_ms, "run_update_ms": [_median_ms(run["update"]) for run in runs],
               "peak_rss_mib": peak_rss_mib()}
    if "kernels" in pooled:
        kernels = np.array(pooled["kernels"])
        summary["kernels_ms"] = _median_ms(kernels)
        summary["host_ms"] = _median_ms(np.array(pooled["update"]) - kernels)
        per_kernel = {name[len(KERNEL_PREFIX):]: _median_ms(v) for name, v in pooled.items()
                      if name.startswith(KERNEL_PREFIX)}
        summary["kernel_ms"] = dict(sorted(per_kernel.items(), key=lambda kv: -kv[1]))
    return summary


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


def bench_sequence(method: str, shape, n_frames: int, snr: float, seed: int = 0) -> np.ndarray:
    """The ``n_frames`` frames the bench times ``method`` on: its ``bench_frames`` if it has them, else a simulated
    transit at ``snr`` with its ``bench_scene``."""
    from . import methods

    spec = methods.get(method)
    if spec.bench_frames:
        return spec.bench_frames(tuple(shape), n_frames, seed)
    return simulate(tuple(shape), frames=n_frames, seed=seed,
                    **{"snr": snr, "motion": "transit", **spec.bench_scene}).frames


def run_bench(shape, snr: float = 1.4, n_frames: int = 20, engines=("taichi", "numpy"), arch: str = "cpu",
              seed: int = 0, particles: int = 0, groups: int = 1, pipeline: bool = True,
              frontend_process: bool = False, runs: int = 1, paired: bool = False, method: str = "sgds",
              settings=None, threads: int | None = None) -> dict:
    """Benchmark every engine on the same simulated sequence; returns the JSON-ready result.
    ``method``: the registered method whose tracker is timed (``pipeline``).
    ``frontend_process``: the trackers run normalisation and saliency in a second process.  ``runs`` > 1
    repeats the engines' runs, in turn and in alternating order (taichi, numpy, numpy, taichi, …), so that a
    VM's slow spells (10–50 % for minutes) fall on both; the medians pool every run's frames, and
    ``run_update_ms`` lists each run's median update time (``run_ratios``: NumPy over Taichi, run by run).
    ``paired``: in each run the engines take the frames in turn, frame by frame (their trackers side by side in
    memory), so that even a short slow spell falls on both.  On the CPU backend each engine also reports the
    median time in kernel launches and outside them (``kernels_ms``, ``host_ms``).  ``settings``: the method's
    parameters over its bench keywords (``--param``); the frames are the method's ``bench_frames`` if it has them.
    ``threads``: the CPU backend's worker threads (None: every core)."""
    if runs < 1:
        raise ParameterError(f"runs must be ≥ 1, got {runs}")
    from . import methods

    methods.get(method)  # an unknown method fails here
    backend.keep_freed_memory()
    cfg = backend.init(arch, threads=threads)
    frames = bench_sequence(method, shape, n_frames + WARMUP, snr, seed)
    result = {"method": method, "shape": [int(shape[0]), int(shape[1])], "snr": snr, "frames": n_frames, "arch": cfg.arch,
              "threads": backend.cpu_threads() if cfg.arch == "cpu" else None,
              "particles": particles, "groups": groups, "pipeline": pipeline,
              "frontend_process": bool(frontend_process and pipeline), "runs": runs, "paired": bool(paired),
              "settings": dict(settings or {}),
              "machine": machine_description(), "versions": software_versions(), "engines": {}}
    engines = tuple(engines)
    samples: dict[str, list] = {engine: [] for engine in engines}
    for r in range(runs):
        order = engines if r % 2 == 0 else engines[::-1]
        for together in ([order] if paired else [(engine,) for engine in order]):
            for engine, run in engine_samples(frames, snr, together, particles, groups, pipeline, frontend_process,
                                              kernel_time=cfg.arch == "cpu", method=method,
                                              settings=settings).items():
                samples[engine].append(run)
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
    front += ", engines frame by frame in turn" if result.get("paired") and len(names) > 1 else ""
    lines = [f"{result.get('method', 'sgds')}: shape {result['shape'][0]}x{result['shape'][1]} (HxW), SNR preset {result['snr']}, "
             f"{result['frames']} timed frames{pool}, arch {result['arch']}"
             + (f", {result['threads']} thread(s)" if result.get("threads") else "") + front,
             f"on {result.get('machine', 'an unrecorded machine')}", head]
    split = ["kernels", "host"] if all("kernels_ms" in engines[n] for n in names) else []
    for stage in stages + ["update"] + split + ["fps", "peak MiB"]:
        vals = {n: _row_value(engines[n], stage) for n in names}
        row = f"{stage:<12}" + "".join(f"{vals[n]:>14.3f}" for n in names)
        if ratio and stage not in ("fps", "peak MiB", "kernels", "host"):
            row += f"{vals['numpy'] / vals['taichi']:>13.1f}x" if vals["taichi"] > 0 else f"{'-':>14}"
        lines.append(row)
    if result.get("runs", 1) > 1:
        for n in names:
            lines.append(f"{n} update per run: " + ", ".join(f"{v:.2f}" for v in engines[n]["run_update_ms"]) + " ms")
        if "run_ratios" in result:
            lines.append("numpy/taichi per run: " + ", ".join(f"{v:.1f}x" for v in result["run_ratios"]))
    kernel_ms = engines.get("taichi", {}).get("kernel_ms")
    if kernel_ms:
        lines.append("taichi kernels, ms in the frames each ran: "
                     + ", ".join(f"{name} {v:.2f}" for name, v in kernel_ms.items() if v >= 0.01))
    return "\n".join(lines)


def _row_value(engine: dict, stage: str) -> float:
    extra = {"total": "total", "update": "update_ms", "fps": "fps", "peak MiB": "peak_rss_mib", "kernels": "kernels_ms",
             "host": "host_ms"}
    return engine[extra[stage]] if stage in extra else engine["stages"][stage]
