"""How much of SGDSPF.update is host work that both engines share, and what that leaves for a 10× ratio.

A Taichi and a NumPy tracker take the same simulated 320×256 sequence (one SNR preset) frame by
frame, in alternating order, so that the machine's slow spells (10–50 % on the project's VMs) slow
both engines alike; every Taichi kernel launch is timed (``tbd_taichi.launch.FastKernel``, the lean
path all per-frame kernels take on the CPU).  Per run (``--runs``), medians over the frames after
the warm-up:

* ``update``: wall time of one ``update`` call (ms);
* ``kernels``: time inside kernel launches (ms; Taichi only), and per kernel;
* ``host``: ``update`` − ``kernels`` (ms): the Python scheduler, OpenCV and NumPy work that the NumPy
  engine runs too (PP numbering, Eq. 37 quotas, labels, track starts and confidences, robust statistics);
* ``ceiling``: NumPy's ``update`` / Taichi's ``host``, the ratio if every Taichi kernel took no time;
* ``kernel_budget``: NumPy's ``update`` / 10 − Taichi's ``host`` (ms), what the kernels may take for 10×.

Writes host_share_<snr>.md and .json into --out.

    python benchmarks/host_share.py [--snr 1.4] [--frames 70] [--runs 2] [--out docs/results]
"""
from __future__ import annotations

import argparse
import collections
import json
import time
from pathlib import Path

import numpy as np

from tbd_taichi import backend, launch
from tbd_taichi.bench import machine_description
from tbd_taichi.sgds import SGDSPF
from tbd_taichi.simulate import simulate

SHAPE = (256, 320)
ENGINES = ("taichi", "numpy")
WARMUP = 10  # untimed frames: the first tracking PFs start (and step_pair first loads) at frame 3 or 4
OUT = Path(__file__).resolve().parent.parent / "docs" / "results"


class LaunchTimer:
    """Sums the wall time of every lean kernel launch, per kernel, while installed."""

    def __init__(self):
        self.seconds = collections.defaultdict(float)
        self._launch = launch.FastKernel.__call__

    def __enter__(self):
        timer, launch_kernel = self, self._launch

        def timed(kernel, *args, **kwargs):
            t0 = time.perf_counter()
            try:
                return launch_kernel(kernel, *args, **kwargs)
            finally:
                timer.seconds[kernel.kernel.func.__name__] += time.perf_counter() - t0

        launch.FastKernel.__call__ = timed
        return self

    def __exit__(self, *exc):
        launch.FastKernel.__call__ = self._launch


def paired_run(frames: np.ndarray, snr: float) -> dict:
    """One run: a Taichi and a NumPy tracker take the same frames in turn, frame by frame and in alternating
    order, so a slow spell of the machine slows both.  Per engine, medians (ms) of update, time in kernel
    launches (total and per kernel) and host."""
    trackers = {engine: SGDSPF(SHAPE, snr=snr, engine=engine, history=False) for engine in ENGINES}
    samples = {engine: collections.defaultdict(list) for engine in ENGINES}
    with LaunchTimer() as timer:
        for k, frame in enumerate(frames):
            for engine in (ENGINES if k % 2 == 0 else ENGINES[::-1]):
                timer.seconds.clear()
                t0 = time.perf_counter()
                trackers[engine].update(frame)
                update = time.perf_counter() - t0
                if k >= WARMUP:
                    kernels = sum(timer.seconds.values())
                    samples[engine]["update"].append(update)
                    samples[engine]["kernels"].append(kernels)
                    samples[engine]["host"].append(update - kernels)
                    for name, seconds in timer.seconds.items():
                        samples[engine]["kernel " + name].append(seconds)
    for tracker in trackers.values():
        tracker.finish()
    return {engine: engine_medians(s) for engine, s in samples.items()}


def engine_medians(samples: dict) -> dict:
    """Medians in ms: update, kernels, host, and per_kernel (over the frames each kernel ran in)."""
    ms = {name: float(np.median(v) * 1e3) for name, v in samples.items()}
    per_kernel = {name[7:]: v for name, v in sorted(ms.items(), key=lambda kv: -kv[1]) if name.startswith("kernel ")}
    return {"update": ms["update"], "kernels": ms["kernels"], "host": ms["host"], "per_kernel": per_kernel}


def share_table(runs: list[dict], snr: float, frames: int) -> str:
    """Markdown: each Taichi run against the NumPy run next to it."""
    lines = [f"# Host share of `SGDSPF.update`, 320×256, SNR {snr} preset", "",
             f"`python benchmarks/host_share.py --snr {snr} --frames {frames} --runs {len(runs)}`; "
             f"{machine_description()}; medians over {frames - WARMUP} frames per run.", "",
             "| run | Taichi update ms | kernels ms | host ms | NumPy update ms | ratio | ceiling (kernels free) "
             "| kernel budget for 10× (ms) |", "|---|---:|---:|---:|---:|---:|---:|---:|"]
    for k, run in enumerate(runs):
        t, n = run["taichi"], run["numpy"]
        lines.append(f"| {k + 1} | {t['update']:.2f} | {t['kernels']:.2f} | {t['host']:.2f} | {n['update']:.1f} "
                     f"| {run['ratio']:.1f}× | {run['ceiling']:.1f}× | {run['kernel_budget']:.2f} |")
    lines += ["", "Taichi kernels, ms per frame (run 1): " + ", ".join(
        f"`{name}` {v:.2f}" for name, v in runs[0]["taichi"]["per_kernel"].items() if v >= 0.01), ""]
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--snr", type=float, default=1.4, help="SNR preset and simulated SNR (default 1.4)")
    parser.add_argument("--frames", type=int, default=70, help="frames per run, warm-up included (default 70)")
    parser.add_argument("--runs", type=int, default=2, help="paired runs (default 2)")
    parser.add_argument("--out", default=str(OUT), help="output folder (default docs/results)")
    args = parser.parse_args()
    if args.frames <= WARMUP + 2:
        parser.error(f"--frames must exceed {WARMUP + 2}")
    backend.init("cpu")
    frames = simulate(SHAPE, frames=args.frames, snr=args.snr, seed=0, motion="transit").frames
    runs = []
    for k in range(args.runs):
        run = paired_run(frames, args.snr)
        t, n = run["taichi"], run["numpy"]["update"]
        run.update(ratio=n / t["update"], ceiling=n / t["host"], kernel_budget=n / 10 - t["host"])
        runs.append(run)
    table = share_table(runs, args.snr, args.frames)
    print(table)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / f"host_share_{args.snr:g}.md").write_text(table)
    (out / f"host_share_{args.snr:g}.json").write_text(json.dumps(
        {"snr": args.snr, "frames": args.frames, "machine": machine_description(), "runs": runs}, indent=1))


if __name__ == "__main__":
    main()
