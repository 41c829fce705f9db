"""The whole SGDS-PF pipeline (SGDSPF.update) per stage, Taichi against NumPy in the same run.

320×256 (the paper's camera format) with the SNR 1.2, 1.4 and 2.0 presets, and 1024×1024 with
the 1.4 preset; on a GPU backend also 4096×4096.  Writes bench_pipeline_<arch>.md and .json
into --out (default docs/results); with --frontend-process (normalisation and saliency in a
second process) bench_pipeline_<arch>_frontend_process.md and .json; with --paired (the engines take the frames
in turn, frame by frame, within each run) the name ends in _paired.

    python benchmarks/pipeline_bench.py [--arch cpu] [--frames 20] [--frontend-process] [--runs 1] [--paired]
                                        [--out docs/results]
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

from tbd_taichi.bench import format_table, run_bench

CASES = [((256, 320), 1.2), ((256, 320), 1.4), ((256, 320), 2.0), ((1024, 1024), 1.4)]
GPU_CASES = [((4096, 4096), 1.4)]
OUT = Path(__file__).resolve().parent.parent / "docs" / "results"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--arch", default="cpu")
    parser.add_argument("--frames", type=int, default=20)
    parser.add_argument("--out", default=str(OUT), help="output folder (default docs/results)")
    parser.add_argument("--runs", type=int, default=1, help="runs per engine, in turn (tbd-taichi bench --runs)")
    parser.add_argument("--frontend-process", action="store_true",
                        help="normalisation and saliency in a second process (SGDSPF(frontend_process=True))")
    parser.add_argument("--paired", action="store_true",
                        help="the engines take the frames in turn, frame by frame, within each run (bench --paired)")
    args = parser.parse_args()
    cases = CASES + (GPU_CASES if args.arch != "cpu" else [])
    flag = ((" --frontend-process" if args.frontend_process else "") + (f" --runs {args.runs}" if args.runs > 1 else "")
            + (" --paired" if args.paired else ""))
    results, lines = [], [f"# SGDS-PF pipeline benchmark ({args.arch}{flag})", "",
                          f"`python benchmarks/pipeline_bench.py --arch {args.arch} --frames {args.frames}{flag}` "
                          f"(same as `tbd-taichi bench --shape H W --snr S{flag}`); median ms/frame after a 3-frame "
                          "warm-up.", ""]
    for shape, snr in cases:
        frames = args.frames if shape[0] < 1024 else max(5, args.frames // (4 if shape[0] < 4096 else 8))
        result = run_bench(shape, snr=snr, n_frames=frames, arch=args.arch, frontend_process=args.frontend_process,
                           runs=args.runs, paired=args.paired)
        results.append(result)
        table = format_table(result)
        print(table, flush=True)
        lines += ["```", table, "```", ""]
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    name = (f"bench_pipeline_{args.arch}" + ("_frontend_process" if args.frontend_process else "")
            + ("_paired" if args.paired else ""))
    (out / f"{name}.md").write_text("\n".join(lines))
    (out / f"{name}.json").write_text(json.dumps(results, indent=1))


if __name__ == "__main__":
    main()
