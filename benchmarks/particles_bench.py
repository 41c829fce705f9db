"""Particle-step benchmark: 36,000 particles in 6 groups and 1,000,000 in 1 group, Taichi against NumPy.

One step = existence, newborn draws, propagation, weighting, normalisation and
resampling for every group (``ParticlePool.step``) on a 320×256 frame.  Writes a
markdown table and the raw JSON to ``--out``.

    python benchmarks/particles_bench.py [--arch cpu] [--repeats 3] [--out docs/results]
"""
import argparse
import json
import statistics
from pathlib import Path

import tbd_taichi as tbd
from tbd_taichi.bench import machine_description, run_bench

CASES = [(36_000, 6, 20), (1_000_000, 1, 5)]  # particles, groups, timed frames


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--arch", default="cpu", help="Taichi backend (default cpu)")
    parser.add_argument("--repeats", type=int, default=3, help="runs per case (default 3)")
    parser.add_argument("--out", default="docs/results", help="output folder")
    args = parser.parse_args()
    rows, raw = [], []
    for particles, groups, frames in CASES:
        runs = [run_bench((256, 320), n_frames=frames, arch=args.arch, particles=particles, groups=groups, pipeline=False)
                for _ in range(args.repeats)]
        raw.extend(runs)
        ti_ms = statistics.median(r["engines"]["taichi"]["stages"]["particles"] for r in runs)
        np_ms = statistics.median(r["engines"]["numpy"]["stages"]["particles"] for r in runs)
        rows.append((particles, groups, ti_ms, np_ms))
        print(f"{particles} particles / {groups} groups: taichi {ti_ms:.2f} ms, numpy {np_ms:.2f} ms, "
              f"ratio {np_ms / ti_ms:.1f}x", flush=True)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    arch = raw[0]["arch"]
    lines = [f"# Particle step benchmark ({arch})", "",
             "Median ms per full step (existence, newborn draws, propagation, weighting, normalisation, "
             f"resampling) on a 320×256 frame, median of {args.repeats} runs after a 3-frame warm-up.", "",
             f"Command: `python benchmarks/particles_bench.py --arch {args.arch} --repeats {args.repeats}`; "
             f"machine: {machine_description()}, tbd-taichi {tbd.__version__}.", "",
             "| particles | groups | Taichi ms | NumPy ms | NumPy/Taichi |", "|---|---|---|---|---|"]
    lines += [f"| {p:,} | {g} | {t:.2f} | {n:.2f} | {n / t:.1f}× |" for p, g, t, n in rows]
    (out / f"bench_particles_{arch}.md").write_text("\n".join(lines) + "\n")
    (out / f"bench_particles_{arch}.json").write_text(json.dumps(raw, indent=1))
    print(f"wrote {out / f'bench_particles_{arch}.md'}")


if __name__ == "__main__":
    main()
