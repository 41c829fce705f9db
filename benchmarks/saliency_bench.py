"""Saliency stage benchmark at the issue's four sizes, Taichi against NumPy in the same run.

Runs ``tbd-taichi bench`` for 200×200, 320×256, 1024×1024 and 2048×2048 (H×W given as
H W), repeats each ``--repeats`` times (this CPU's timings vary by ±30 % between runs),
keeps the median of the per-run medians, and writes a markdown table and the raw JSON.

    python benchmarks/saliency_bench.py [--arch cpu] [--repeats 3] [--out docs/results]
"""
import argparse
import json
import statistics
from pathlib import Path

import tbd_taichi as tbd
from tbd_taichi.bench import machine_description, run_bench

SIZES = [(200, 200), (256, 320), (1024, 1024), (2048, 2048)]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--arch", default="cpu", help="Taichi backend (default cpu)")
    parser.add_argument("--repeats", type=int, default=3, help="runs per size (default 3)")
    parser.add_argument("--frames", type=int, default=20, help="timed frames per run (default 20)")
    parser.add_argument("--snr", type=float, default=1.4, help="SNR preset (default 1.4)")
    parser.add_argument("--out", default="docs/results", help="output folder")
    args = parser.parse_args()
    rows, raw = [], []
    for shape in SIZES:
        runs = [run_bench(shape, snr=args.snr, n_frames=args.frames, arch=args.arch, pipeline=False) for _ in range(args.repeats)]
        raw.extend(runs)
        ti_ms = statistics.median(r["engines"]["taichi"]["stages"]["saliency"] for r in runs)
        np_ms = statistics.median(r["engines"]["numpy"]["stages"]["saliency"] for r in runs)
        rows.append((shape, ti_ms, np_ms))
        print(f"{shape[0]}x{shape[1]}: taichi {ti_ms:.2f} ms, numpy {np_ms:.2f} ms, ratio {np_ms / ti_ms:.1f}x", flush=True)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    arch = raw[0]["arch"]
    lines = [f"# Saliency stage benchmark ({arch})", "",
             f"Median ms/frame of the saliency stage (Eqs. 20–33, normalised frame to proposal map), SNR preset "
             f"{args.snr}, median of {args.repeats} runs × {args.frames} timed frames after a 3-frame warm-up.", "",
             f"Command: `python benchmarks/saliency_bench.py --arch {args.arch} --repeats {args.repeats}`; "
             f"machine: {machine_description()}, tbd-taichi {tbd.__version__}.", "",
             "| H×W | Taichi ms | NumPy ms | NumPy/Taichi |", "|---|---|---|---|"]
    lines += [f"| {h}×{w} | {t:.2f} | {n:.2f} | {n / t:.1f}× |" for (h, w), t, n in rows]
    (out / f"bench_saliency_{arch}.md").write_text("\n".join(lines) + "\n")
    (out / f"bench_saliency_{arch}.json").write_text(json.dumps(raw, indent=1))
    print(f"wrote {out / f'bench_saliency_{arch}.md'}")


if __name__ == "__main__":
    main()
