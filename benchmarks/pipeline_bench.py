"""The whole SGDS-PF pipeline (SGDSPF.update) per stage, Taichi against NumPy in the same run.

320×256 (the paper's camera format) with the SNR 1.2, 1.4 and 2.0 presets, and 1024×1024 with
the 1.4 preset.  Writes docs/results/bench_pipeline_<arch>.md and .json.

    python benchmarks/pipeline_bench.py [--arch cpu] [--frames 20]
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

from tbd_taichi.bench import format_table, run_bench

CASES = [((256, 320), 1.2), ((256, 320), 1.4), ((256, 320), 2.0), ((1024, 1024), 1.4)]
OUT = Path(__file__).resolve().parent.parent / "docs" / "results"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--arch", default="cpu")
    parser.add_argument("--frames", type=int, default=20)
    args = parser.parse_args()
    results, lines = [], [f"# SGDS-PF pipeline benchmark ({args.arch})", "",
                          f"`python benchmarks/pipeline_bench.py --arch {args.arch} --frames {args.frames}` "
                          "(same as `tbd-taichi bench --shape H W --snr S`); median ms/frame after a 3-frame warm-up.", ""]
    for shape, snr in CASES:
        frames = args.frames if shape[0] < 1024 else max(5, args.frames // 4)
        result = run_bench(shape, snr=snr, n_frames=frames, arch=args.arch)
        results.append(result)
        table = format_table(result)
        print(table, flush=True)
        lines += ["```", table, "```", ""]
    (OUT / f"bench_pipeline_{args.arch}.md").write_text("\n".join(lines))
    (OUT / f"bench_pipeline_{args.arch}.json").write_text(json.dumps(results, indent=1))


if __name__ == "__main__":
    main()
