"""Where SGDS-PF's frame time goes, kernel by kernel, against the cost of the same work done alone.

The "work alone" of a kernel is the compute cost of its irreducible work on this machine's threads, each piece
measured alone in one tight parallel loop over an in-cache set (REPS passes over IN_CACHE particles in one
launch, min of 30 launches), times the work of a frame: for the particle step, per existing (E = 1) searching
particle the five counter-based normals of the propagation and Eq. 15's 5×5 likelihood (the project's own
``PointPSFLikelihood.log_ratio``), and per slot the exponential and f64 running sum of the normalisation and
the resampling's Exp(1) spacing, running sum and copy; for an image kernel, one streaming pass over the frame
(read one f32 and write one per pixel), which every such kernel makes at least once.  The E = 1 count is the
mean over the bench scene's timed frames (both buffers of the pool).  Launches and the per-group sums are left
out, but the loops' memory access differs from the kernels' (the pool keeps a block's particles together), so
it is an estimate of what the work costs here, not a strict bound: a kernel can run a little under it.  The measured side is ``bench --paired`` at the SNR 1.4
and 1.2 presets on 256 × 320 frames (a target confirmed and tracked in the timed frames), per stage and per
kernel (ms in the frames each ran).  Writes ``docs/results/kernel_floors.md`` and ``.json``.

    python benchmarks/kernel_floors.py [--frames 30] [--out docs/results]
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
import taichi as ti

from tbd_taichi import backend
from tbd_taichi.bench import machine_description, run_bench
from tbd_taichi.kernels.models.likelihood import PointPSFLikelihood
from tbd_taichi.kernels.particles.layout import PAD
from tbd_taichi.kernels.rng import (ExponentialTables, NormalTables, exponential_at, key_prefix, normals_at,
                                    uniform_at)

SHAPE = (256, 320)
PRESETS = (1.4, 1.2)
CHUNK = 1024  # particles per serial running sum (the pool's tiles)
IN_CACHE = 8192  # particles a work-alone loop goes over, REPS times in one launch
REPS = 16
COPY = 6  # floats a resampled particle carries (x, y, vx, vy, I, Tp)


@ti.data_oriented
class Floors:
    """Tight loops over ``n`` particles or one frame: the pieces of work each kernel cannot avoid."""

    def __init__(self, n: int):
        h, w = SHAPE
        self.n = n
        self.state = ti.field(ti.f32, (n, COPY))
        self.out = ti.field(ti.f32, (n, COPY))
        self.logw, self.cum = ti.field(ti.f32, n), ti.field(ti.f64, n)
        self.zp = ti.field(ti.f32, (h + 2 * PAD, w + 2 * PAD))
        self.img, self.img2 = ti.field(ti.f32, SHAPE), ti.field(ti.f32, SHAPE)
        self.model = PointPSFLikelihood()
        self.normal, self.expo = NormalTables.shared(), ExponentialTables.shared()
        rng = np.random.default_rng(0)
        st = np.zeros((n, COPY), np.float32)
        st[:, 0], st[:, 1] = rng.uniform(0, w - 1, n), rng.uniform(0, h - 1, n)
        st[:, 4] = rng.uniform(1, 5, n)
        self.state.from_numpy(st)
        self.zp.from_numpy(rng.normal(size=self.zp.shape).astype(np.float32))
        self.logw.from_numpy(rng.normal(size=n).astype(np.float32))

    @ti.kernel
    def propagate(self):
        """Five normals and the constant-velocity step per particle."""
        keys = [key_prefix(1, 2, s) for s in ti.static(range(5))]
        for q in range(REPS * self.n):
            i = q % self.n
            v = normals_at(self.normal.w, self.normal.k, self.normal.phi, keys, q)
            self.state[i, 2] += 0.001 * v[0]
            self.state[i, 3] += 0.001 * v[1]
            self.state[i, 0] += 0.001 * v[2]
            self.state[i, 1] += 0.001 * v[3]
            self.state[i, 4] += 0.001 * v[4]

    @ti.kernel
    def likelihood(self):
        """Eq. 15's log-likelihood ratio over the 5×5 window, per particle."""
        h, w = ti.static(SHAPE)
        c = self.model.constants(0.7, 1.0)
        for q in range(REPS * self.n):
            i = q % self.n
            self.logw[i] = self.model.log_ratio(self.state[i, 0], self.state[i, 1], self.state[i, 4], self.zp, c, h, w)

    @ti.kernel
    def normalise(self):
        """exp(log w − max) in f64 and its running sum, per chunk of CHUNK particles."""
        chunks = (self.n + CHUNK - 1) // CHUNK
        for q in range(REPS * chunks):
            t = q % chunks
            s = ti.cast(0.0, ti.f64)
            for i in range(t * CHUNK, ti.min((t + 1) * CHUNK, self.n)):
                s += ti.exp(ti.cast(self.logw[i], ti.f64) - 3.0)
                self.cum[i] = s

    @ti.kernel
    def resample(self):
        """An Exp(1) spacing per particle, its running sum, and a copy of a parent's COPY floats."""
        key, kp = key_prefix(1, 2, 9), key_prefix(1, 2, 10)
        chunks = (self.n + CHUNK - 1) // CHUNK
        for q in range(REPS * chunks):
            t = q % chunks
            s = ti.cast(0.0, ti.f64)
            for i in range(t * CHUNK, ti.min((t + 1) * CHUNK, self.n)):
                s += exponential_at(self.expo.w, self.expo.k, self.expo.f, key, q * CHUNK + i)
                self.cum[i] = s
                src = ti.min(t * CHUNK + ti.cast(uniform_at(kp, i) * CHUNK, ti.i32), self.n - 1)
                for d in ti.static(range(COPY)):
                    self.out[i, d] = self.state[src, d]

    @ti.kernel
    def image_pass(self):
        """REPS streaming passes over the frame: read a pixel, write one."""
        h, w = ti.static(SHAPE)
        for q, c in ti.ndrange(REPS * h, w):
            r = q % h
            self.img2[r, c] = self.img[r, c] * 0.5 + 1.0


def best_ms(kernel, repeats: int = 30) -> float:
    """The fastest of ``repeats`` launches (after one warm-up), ms."""
    kernel()
    ti.sync()
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        kernel()
        ti.sync()
        best = min(best, time.perf_counter() - t0)
    return best * 1e3


def unit_costs() -> dict:
    """ms per particle (per slot for normalise and resample) of each piece, and per pass over the frame."""
    f = Floors(IN_CACHE)
    out = {name: best_ms(getattr(f, name)) / (REPS * IN_CACHE)
           for name in ("propagate", "likelihood", "normalise", "resample")}
    out["image_pass"] = best_ms(f.image_pass) / REPS
    return out


def existing_particles(snr: float, frames: int) -> tuple[int, float]:
    """The searching pool's stepped slots (N_sump per search block: the pool's spare groups stay empty) and its
    mean count of E = 1 particles over the bench scene at ``snr``."""
    from tbd_taichi import methods, simulate
    from tbd_taichi.bench import WARMUP

    spec = methods.get("sgds")
    scene = simulate(SHAPE, frames=frames + WARMUP, seed=0, **{"snr": snr, "motion": "transit", **spec.bench_scene})
    tracker = methods.make_tracker("sgds", SHAPE, **spec.bench_keywords(snr), history=False)
    live = []
    for k, frame in enumerate(scene.frames):
        tracker.update(frame)
        pool = tracker.tracker.search
        if k >= WARMUP:
            live.append(float((pool.k.e.to_numpy() == 1).sum()) / pool.k.e.shape[0])
    return int(tracker.tracker.grid.n_blocks * tracker.tracker.p.N_sump), float(np.mean(live))


def measured(snr: float, frames: int) -> dict:
    """``bench --paired --runs 2`` at the ``snr`` preset: stages and kernels (ms), both engines."""
    r = run_bench(SHAPE, snr=snr, n_frames=frames, runs=2, paired=True)
    t, n = r["engines"]["taichi"], r["engines"]["numpy"]
    return {"stages": t["stages"], "numpy_stages": n["stages"], "kernels": t["kernel_ms"],
            "update_ms": t["update_ms"], "numpy_update_ms": n["update_ms"], "fps": t["fps"],
            "host_ms": t["host_ms"]}


STEP_KERNELS = ("step", "step_pair")  # the searching PFs' step alone, or with the tracking PFs' (when tracks live)
IMAGE_KERNELS = ("isolated_spikes", "frame_to_first_layer", "second_layer_and_lef", "proposal_from_candidates")


def step_floor(cost: dict, slots: int, existing: float) -> float:
    """The particle step's work alone, ms: E = 1 particles propagate and weigh, every slot normalises and resamples."""
    return existing * (cost["propagate"] + cost["likelihood"]) + slots * (cost["normalise"] + cost["resample"])


def table(result: dict) -> list[str]:
    """The markdown rows: stage, kernel, ms at each preset, the work alone, their ratio."""
    lines = ["| stage | kernel (work per frame) | " + " | ".join(f"SNR {s} preset ms" for s in PRESETS)
             + " | work alone ms (" + ", ".join(str(s) for s in PRESETS) + ") | measured / work alone |",
             "|---|---|" + "---|" * (len(PRESETS) + 2)]
    m, cost, n = result["measured"], result["unit_ms"], result["particles"]
    for k in STEP_KERNELS:
        floor = [step_floor(cost, *n[str(s)]) for s in PRESETS]
        ms = [m[str(s)]["kernels"].get(k, float("nan")) for s in PRESETS]
        if all(np.isnan(ms)):  # ``step`` runs only where the pools cannot pair (a GPU; --threads with no split)
            continue
        lines.append(f"| searching{' + tracking' if k == 'step_pair' else ''} | `{k}` ("
                     + ", ".join(f"{n[str(s)][0]:,} slots, {n[str(s)][1]:,.0f} with E = 1" for s in PRESETS)
                     + "; then numbers the PPs, Eq. 37) | " + " | ".join(f"{v:.2f}" for v in ms) + " | "
                     + ", ".join(f"{v:.2f}" for v in floor)
                     + " | " + ", ".join(f"{a / b:.1f}×" for a, b in zip(ms, floor)) + " |")
    rest = sorted({k for s in PRESETS for k in m[str(s)]["kernels"]} - set(STEP_KERNELS),
                  key=lambda k: -m[str(PRESETS[-1])]["kernels"].get(k, 0.0))
    for k in rest:
        ms = [m[str(s)]["kernels"].get(k, float("nan")) for s in PRESETS]
        if k in IMAGE_KERNELS:
            floor = cost["image_pass"]
            lines.append(f"| front end | `{k}` (256 × 320 px; work alone: one pass) | " + " | ".join(f"{v:.2f}" for v in ms)
                         + f" | {floor:.3f} | " + ", ".join(f"{a / floor:.0f} passes" for a in ms) + " |")
        else:
            lines.append(f"| bookkeeping, transfers | `{k}` | " + " | ".join(f"{v:.2f}" for v in ms) + " | – | – |")
    for s in PRESETS:
        d = m[str(s)]
        lines.append(f"| **frame, SNR {s}** | update {d['update_ms']:.2f} ms ({d['fps']:.0f} fps), of which host "
                     f"{d['host_ms']:.2f}; NumPy engine {d['numpy_update_ms']:.1f} ms "
                     f"({d['numpy_update_ms'] / d['update_ms']:.1f}×) | | | | |")
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=30, help="timed frames per preset (default 30)")
    parser.add_argument("--out", default="docs/results", help="output folder (default docs/results)")
    args = parser.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    result = {"machine": machine_description(), "measured": {}, "particles": {}}
    for s in PRESETS:
        result["measured"][str(s)] = measured(s, args.frames)
        result["particles"][str(s)] = existing_particles(s, args.frames)
    backend.init("cpu")
    result["unit_ms"] = unit_costs()
    (out / "kernel_floors.json").write_text(json.dumps(result, indent=1))
    lines = ["# SGDS-PF: where the frame time goes, against the work alone", "",
             f"`python benchmarks/kernel_floors.py --frames {args.frames}` on {result['machine']}. Measured: "
             "`bench --paired --runs 2` per kernel (ms in the frames each ran; on the CPU `step_pair` steps the "
             "searching and tracking PFs in every frame, also with no live track). Work alone: the kernel's "
             "irreducible work, each "
             "piece alone in a tight parallel loop over an in-cache set (see the script's docstring).", ""]
    lines += table(result)
    (out / "kernel_floors.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
