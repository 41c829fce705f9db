"""Close targets (issue 43, item 4): two and three dim targets crossing or in parallel 3–8 px apart
(:mod:`tbd_taichi.formation`), tracked by a registered method with the scenario SNR's preset; writes
docs/results/formation.md.

Per condition (geometry, targets, SNR, separation): the mean per-target DSR (Eq. 48), the mean of each run's
lowest target DSR, the share of runs without an identity swap (:func:`~tbd_taichi.formation.identity_swaps`),
mean OSPA (c = 5 px, p = 2), false tracks per run and ms/frame.

    python benchmarks/formation_eval.py [--runs 50] [--methods sgds] [--snrs 1.6,2.0] [--separations 3,5,8]
                                        [--targets 2,3] [--geometries crossing,parallel] [--out FILE]
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from tbd_taichi.formation import GEOMETRIES, formation_scores, simulate_formation
from tbd_taichi.methods import make_tracker, names

ROOT = Path(__file__).resolve().parent.parent
HEADER = ("| method | geometry | targets | SNR | separation (px) | closest (px) | runs | mean target DSR | "
          "targets with DSR ≥ 0.8 | mean lowest DSR | runs without a swap | OSPA (px) | false tracks / run | ms/frame |")


def run_condition(method: str, geometry: str, targets: int, snr: float, separation: float, runs: int) -> dict:
    """``runs`` seeds of one condition; the summary row's figures."""
    scores, ms, closest = [], [], None
    for seed in range(runs):
        scene = simulate_formation(geometry, targets, separation, snr, seed)
        closest = scene.params["closest_px"]
        tracker = make_tracker(method, scene.frames.shape[1:], snr=snr, seed=seed, profile="paper")
        t0 = time.perf_counter()
        for frame in scene.frames:
            tracker.update(frame)
        tracks = tracker.finish()
        ms.append((time.perf_counter() - t0) / len(scene.frames) * 1e3)
        scores.append(formation_scores(tracks, scene.truth, len(scene.frames)))
    dsr = np.array([d for s in scores for d in s["dsr"].values()])
    return dict(method=method, geometry=geometry, targets=targets, snr=snr, separation=separation, closest=closest,
                runs=runs, dsr=dsr.mean(), share_08=(dsr >= 0.8).mean(),
                lowest=np.mean([s["min_dsr"] for s in scores]),
                no_swap=np.mean([s["total_swaps"] == 0 for s in scores]),
                ospa=np.mean([s["ospa"] for s in scores]), false=np.mean([s["false_tracks"] for s in scores]),
                ms=np.median(ms))


def row(r: dict) -> str:
    return (f"| {r['method']} | {r['geometry']} | {r['targets']} | {r['snr']:g} | {r['separation']:g} | "
            f"{r['closest']:.1f} | {r['runs']} | {r['dsr']:.2f} | {r['share_08']:.2f} | {r['lowest']:.2f} | "
            f"{r['no_swap']:.2f} | {r['ospa']:.2f} | {r['false']:.2f} | {r['ms']:.1f} |")


def numbers(text: str, kind=float) -> list:
    return [kind(v) for v in text.split(",") if v]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--runs", type=int, default=50)
    ap.add_argument("--methods", default="sgds", help=f"comma-separated, of: {', '.join(names())}")
    ap.add_argument("--snrs", default="1.6,2.0")
    ap.add_argument("--separations", default="3,5,8")
    ap.add_argument("--targets", default="2,3")
    ap.add_argument("--geometries", default=",".join(GEOMETRIES))
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "results" / "formation.md")
    args = ap.parse_args()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    lines = [HEADER, "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    print(lines[0])
    for method in args.methods.split(","):
        for geometry in args.geometries.split(","):
            for targets in numbers(args.targets, int):
                for snr in numbers(args.snrs):
                    for separation in numbers(args.separations):
                        lines.append(row(run_condition(method, geometry, targets, snr, separation, args.runs)))
                        print(lines[-1], flush=True)
    command = "python benchmarks/formation_eval.py " + " ".join(
        f"--{k} {v}" for k, v in vars(args).items() if k != "out")
    args.out.write_text("# Close targets: crossing and parallel (issue 43, item 4)\n\n"
                        f"`{command}`; 100×100 px, 80 frames, speed 0.8 px/frame, crossing angle 60°, CPU.\n"
                        "What the columns mean and what the table shows: "
                        "[docs/methods/sgds.md](../methods/sgds.md#close-targets).\n\n" + "\n".join(lines) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
