"""feature-fusion (Huo 2022) on the drone-ir clips, the paper's protocol: each clip from its first labelled box,
CLE, DP@20 (and @5), mean IoU, AUC and fps, the mean over clips; beside the grey-only and plain-residual
ablations and a box left at the start; then the huo2022 scenario's sequences.  Writes
docs/results/feature-fusion.md and its precision/success plot.

    python benchmarks/feature_fusion_drone_ir.py [--data ../shared/data/drone-ir] [--out docs/results]
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

import tbd_taichi as tbd
from tbd_taichi import io, tables
from tbd_taichi.otb import otb_scores
from tbd_taichi.plots import plot_otb_curves

CONFIGS = {  # label → make_tracker keywords (None: the box left at the start)
    "feature-fusion": {},
    "grey only": {"fusion": "grey"},
    "plain residual": {"resampling": "residual"},
    "box left at the start": None,
}
PAPER = ("| Huo 2022 (Table 2, its six sequences) | 37.4 | 77.2% | – | 27.0% | – | 106 |\n"
         "| PF (Table 2) | 42.9 | 66.2% | – | 15.9% | – | 121 |")


def run_clip(video: Path, labels: Path, settings) -> tuple[dict, float]:
    """The OTB scores of one configuration on one clip and its tracker's frames/s (start-up excluded)."""
    boxes = tables.read_boxes(labels)
    frames = io.read_frames(video)
    b = boxes[0]
    first = int(b["frame"])
    seq = frames[first:]
    if settings is None:  # the init box, every frame
        rows = [(first + t, 1, b["x"] + b["w"] / 2, b["y"] + b["h"] / 2, b["w"], b["h"]) for t in range(len(seq))]
        tracks = np.array(rows, dtype=[("frame", int), ("track_id", int), ("x", float), ("y", float),
                                       ("w", float), ("h", float)])
        return otb_scores(tracks, boxes), float("nan")
    tracker = tbd.make_tracker("feature-fusion", seq.shape[1:], init_box=(b["x"], b["y"], b["w"], b["h"]), seed=0,
                               **settings)
    tracker.update(seq[0])
    start = time.perf_counter()
    for frame in seq[1:]:
        tracker.update(frame)
    fps = (len(seq) - 1) / (time.perf_counter() - start)
    tracks = tracker.finish()
    tracks["frame"] += first
    return otb_scores(tracks, boxes), fps


def huo2022_table() -> list[str]:
    """feature-fusion and its grey-only ablation on the four huo2022 sequences (200 frames, seed 0)."""
    from tbd_taichi.huo2022 import SEQUENCES, simulate_huo2022

    lines = ["", "The huo2022 scenario (`tbd-taichi simulate --scenario huo2022 --sequence S`, 200 frames, seed 0; "
             "after Huo's Table 1): CLE px, DP@20, mean IoU; fused (grey only).", "",
             "| sequence | CLE px | DP@20 | mean IoU |", "|---|---|---|---|"]
    for seq in SEQUENCES:
        sc = simulate_huo2022(seq, seed=0)
        b = sc.truth[0]
        got = []
        for settings in ({}, {"fusion": "grey"}):
            tracks = tbd.track(sc.frames, method="feature-fusion", init_box=(b["x"], b["y"], b["w"], b["h"]),
                               seed=0, **settings)
            got.append(otb_scores(tracks, sc.truth))
        f, g = got
        lines.append(f"| {seq} | {f['cle']:.1f} ({g['cle']:.1f}) | {100 * f['dp20']:.0f}% ({100 * g['dp20']:.0f}%) | "
                     f"{100 * f['mean_iou']:.0f}% ({100 * g['mean_iou']:.0f}%) |")
    return lines


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=str(Path(__file__).resolve().parents[2] / "shared" / "data" / "drone-ir"))
    ap.add_argument("--out", default=str(Path(__file__).resolve().parents[1] / "docs" / "results"))
    args = ap.parse_args()
    clips = sorted(Path(args.data).glob("*.mp4"))
    results = {label: {} for label in CONFIGS}
    for clip in clips:
        for label, settings in CONFIGS.items():
            results[label][clip.stem] = run_clip(clip, clip.with_suffix(".csv"), settings)
        s, fps = results["feature-fusion"][clip.stem]
        print(f"{clip.stem}: CLE {s['cle']:.1f} DP@20 {s['dp20']:.2f} IoU {s['mean_iou']:.2f} {fps:.0f} fps",
              flush=True)
    out = Path(args.out)
    lines = ["# feature-fusion on the drone-ir clips (Huo 2022's protocol)", "",
             "Command: `python benchmarks/feature_fusion_drone_ir.py` (the 12 CC0 clips of shared/data/drone-ir, "
             "each from its first labelled box, one configuration for all; frames after the first scored; a "
             "frame without a track row would count as a miss at CLE 100 px). fps: the tracker's update loop on "
             "the 2-core VM, decoding and start-up excluded.", "",
             "| configuration | CLE px | DP@20 | DP@5 | mean IoU (overlap) | AUC | fps |", "|---|---|---|---|---|---|---|"]
    for label, per_clip in results.items():
        scores = [s for s, _ in per_clip.values()]
        fps = [f for _, f in per_clip.values() if np.isfinite(f)]
        mean = {k: float(np.mean([s[k] for s in scores])) for k in ("cle", "dp20", "dp5", "mean_iou", "auc")}
        lines.append(f"| {label} | {mean['cle']:.1f} | {100 * mean['dp20']:.1f}% | {100 * mean['dp5']:.1f}% | "
                     f"{100 * mean['mean_iou']:.1f}% | {mean['auc']:.3f} | "
                     f"{np.mean(fps):.0f} |" if fps else
                     f"| {label} | {mean['cle']:.1f} | {100 * mean['dp20']:.1f}% | {100 * mean['dp5']:.1f}% | "
                     f"{100 * mean['mean_iou']:.1f}% | {mean['auc']:.3f} | – |")
    lines += [PAPER, "", "Per clip (feature-fusion; box left at the start in brackets):", "",
              "| clip | frames | CLE px | DP@20 | DP@5 | mean IoU | fps |", "|---|---|---|---|---|---|---|"]
    for clip in clips:
        s, fps = results["feature-fusion"][clip.stem]
        b, _ = results["box left at the start"][clip.stem]
        lines.append(f"| {clip.stem} | {s['scored_frames'] + 1} | {s['cle']:.1f} ({b['cle']:.1f}) | "
                     f"{100 * s['dp20']:.0f}% ({100 * b['dp20']:.0f}%) | {100 * s['dp5']:.0f}% ({100 * b['dp5']:.0f}%) | "
                     f"{100 * s['mean_iou']:.0f}% ({100 * b['mean_iou']:.0f}%) | {fps:.0f} |")
    mean_curves = {label: {"dp_curve": np.mean([s["dp_curve"] for s, _ in per.values()], axis=0).tolist(),
                           "success_curve": np.mean([s["success_curve"] for s, _ in per.values()], axis=0).tolist(),
                           "dp20": float(np.mean([s["dp20"] for s, _ in per.values()])),
                           "auc": float(np.mean([s["auc"] for s, _ in per.values()]))}
                   for label, per in results.items()}
    lines += huo2022_table()
    plot = out / "feature_fusion_drone_ir.png"
    plot_otb_curves(mean_curves, plot, title="drone-ir, mean over 12 clips")
    lines += ["", f"![precision and success plots]({plot.name})", ""]
    (out / "feature-fusion.md").write_text("\n".join(lines))
    print(f"-> {out / 'feature-fusion.md'}")


if __name__ == "__main__":
    main()
