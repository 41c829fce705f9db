"""Score SGDS-PF on the real drone-ir clips; writes docs/results/drone_ir.md and an overlay GIF.

One configuration for every clip (no per-clip tuning): ``SGDSPF(shape, **settings)`` with the real-video
profile's settings (``tbd-taichi track --real-video``: ``background="spatiotemporal", snr=5, min_peak_z=16,
keep_peak_z=12, keep_after=50``), otherwise defaults (bad-pixel suppression on, seed 0).  Scores use
the online output (rows as they are confirmed, what a live user sees):

* detection rate: labelled frames with a confirmed point inside the label box grown by 2 px;
* false points: confirmed points outside every grown box, per frame;
* frames to first confirmation: from the first labelled frame to the first hit.

    python benchmarks/drone_ir_eval.py [--data ../shared/data/drone-ir] [--frames N] [--gif CLIP]
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

import tbd_taichi as tbd
from tbd_taichi import io, methods, metrics, tables
from tbd_taichi.plots import write_overlay_gif
from tbd_taichi.profiles import profile_settings

REAL_VIDEO_SETTINGS = profile_settings(methods.get("sgds"), "real-video")  # the one configuration for every clip

ROOT = Path(__file__).resolve().parent.parent
LOCAL_SNR = {"IR_DRONE_152": 1.5, "IR_HELICOPTER_015": 1.9, "IR_AIRPLANE_027": 3.1, "IR_HELICOPTER_049": 3.8,
             "IR_DRONE_142": 4.2, "IR_HELICOPTER_032": 5.4, "IR_DRONE_021": 6.7, "IR_AIRPLANE_031": 8.9,
             "IR_AIRPLANE_030": 9.7, "IR_BIRD_016": 13.8, "IR_BIRD_073": 17.7, "IR_DRONE_089": 26.5}  # data README


def score_clip(video: Path, labels: Path, n_frames: int | None = None, **tracker_kw) -> tuple[dict, np.ndarray]:
    """Run SGDS-PF over one clip; returns (scores with ms/frame, online tracks table)."""
    frames = io.read_frames(video)[:n_frames]
    boxes = tables.read_boxes(labels)
    boxes = boxes[boxes["frame"] < len(frames)]
    tracker = tbd.SGDSPF(frames.shape[1:], **{**REAL_VIDEO_SETTINGS, **tracker_kw})
    t0 = time.perf_counter()
    for frame in frames:
        tracker.update(frame)
    tracker.finish()
    ms = (time.perf_counter() - t0) / len(frames) * 1e3
    tracks = tracker.online()
    scores = metrics.box_scores(tracks, boxes, len(frames))
    scores.update(frames=len(frames), ms_per_frame=ms, tracks=len(np.unique(tracks["track_id"])))
    return scores, tracks


def write_gif(video: Path, tracks: np.ndarray, labels: Path, out: Path, frames: int = 120, step: int = 2) -> None:
    """A small GIF: every ``step``-th frame of the first ``frames``, label box green, tracks in their colours."""
    write_overlay_gif(io.iter_frames(io.open_frames(video)), tracks, out, truth=tables.read_boxes(labels),
                      limit=frames, step=step, scale=2)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", default=str(ROOT.parent / "shared" / "data" / "drone-ir"))
    parser.add_argument("--frames", type=int, default=None, help="first N frames of each clip (default all)")
    parser.add_argument("--gif", default="IR_DRONE_021", help="clip shown in docs/results/drone_ir.gif")
    args = parser.parse_args()
    tbd.keep_freed_memory()  # large per-frame temporaries reuse the heap (see backend.keep_freed_memory)
    tbd.init("cpu")
    data, out_dir = Path(args.data), ROOT / "docs" / "results"
    rows = []
    first = min(LOCAL_SNR, key=LOCAL_SNR.get)
    score_clip(data / f"{first}.mp4", data / f"{first}.csv", 8)  # compiles the kernels: ms/frame without it
    for clip in sorted(LOCAL_SNR, key=LOCAL_SNR.get):
        scores, tracks = score_clip(data / f"{clip}.mp4", data / f"{clip}.csv", args.frames)
        rows.append((clip, scores))
        print(clip, {k: round(v, 3) for k, v in scores.items()}, flush=True)
        if clip == args.gif:
            write_gif(data / f"{clip}.mp4", tracks, data / f"{clip}.csv", out_dir / "drone_ir.gif")
    bright = [s for c, s in rows if LOCAL_SNR[c] >= 3]
    dim = [s for c, s in rows if LOCAL_SNR[c] < 3]
    lines = ["# SGDS-PF on the real drone-ir clips", "",
             f"`python benchmarks/drone_ir_eval.py{' --frames ' + str(args.frames) if args.frames else ''}` — one "
             f"configuration for every clip: `SGDSPF(shape, **settings)` with the real-video profile's settings `{REAL_VIDEO_SETTINGS}` "
             "(`tbd-taichi track --real-video`), otherwise defaults (bad-pixel suppression, seed 0), online output, CPU.", "",
             "| clip | local SNR | frames | detection rate | false points / frame | frames to first confirmation "
             "| tracks | ms/frame |", "|---|---:|---:|---:|---:|---:|---:|---:|"]
    for clip, s in rows:
        lines.append(f"| {clip} | {LOCAL_SNR[clip]} | {s['frames']} | {s['detection_rate']:.2f} | {s['false_points']:.2f} "
                     f"| {s['first_confirmation']:.0f} | {s['tracks']} | {s['ms_per_frame']:.0f} |")
    mean = lambda sel, key: float(np.nanmean([s[key] for s in sel]))  # noqa: E731
    lines += ["", f"Mean detection rate: {mean(bright, 'detection_rate'):.2f} on the {len(bright)} clips with local SNR ≥ 3 "
              f"(goal 0.8), {mean(dim, 'detection_rate'):.2f} on the dimmest two (goal 0.5). Mean false points per frame: "
              f"{mean([s for _, s in rows], 'false_points'):.3f} (goal 0.05).", "",
              "How the configuration came about (the same 12 clips; there is no held-out set, so these figures are "
              "optimistic for unseen video):", "",
              "| configuration | detection, local SNR ≥ 3 | detection, dimmest two | false points / frame |",
              "|---|---:|---:|---:|",
              "| `background='spatial'`, snr 1.4 | 0.86 | 0.55 | 11.65 |",
              "| `background='spatiotemporal'`, snr 5 | 0.88 | 0.91 | 1.23 |",
              "| … snr 8 | 0.76 | 0.89 | 0.20 |",
              "| … snr 12 | 0.63 | 0.44 | 0.07 |",
              "| … snr 5, min_peak_z 10, running mean from the first frame | 0.87 | 0.91 | 0.32 |",
              "| … snr 5, min_peak_z 12, running mean from the first frame | 0.86 | 0.90 | 0.20 |",
              "| … snr 5, min_peak_z 15, running mean from the first frame | 0.84 | 0.81 | 0.08 |",
              "| … snr 5, min_peak_z 15, running mean from 0 (chosen) | 0.83 | 0.81 | 0.051 |",
              "| … and the 10-frame ICEF window (`icef_window`, the tracker's default since) | 0.84 | 0.81 | 0.051 |",
              "| … with the window's threshold scaled to the frame area (0.036 at 320×256; default since) | 0.84 | 0.81 "
              "| 0.051 |",
              "| … the multi-frame LEF and ICEF's MSW from the candidates, tracked ones left in (a first version) | 0.83 "
              "| 0.81 | 0.017 |",
              "| … the multi-frame LEF and ICEF's MSW from the untracked candidates (`lef_memory` 0.9, `msw_reference` "
              "candidates; default since) | 0.83 | 0.81 | 0.050 |",
              "| … the median and MAD from 2¹⁴ sampled pixels, and SCEF over the tracking PF's E = 1 particles "
              "(both default since) | 0.83 | 0.81 | 0.049 |",
              "| … the tracking PFs stepped in the searching PFs' launch, a handed-over track's first step at f + 1 "
              "(default since; seeds 1 and 2: 0.048 and 0.051 false points, the build before 0.049 and 0.048) "
              "| 0.84 | 0.80 | 0.051 |",
              "| … min_peak_z 16 (issue 36: `track` with no flag must stay ≤ 0.05 false points per frame with whole "
              "paths; 17 and 18 gave 0.79 and 0.76 detection online, no false point) | 0.83 | 0.75 | 0.022 |",
              "| … a track reported in 50 frames stays reported down to a running peak z of 12 (`keep_peak_z`, "
              "`keep_after`; issue 43) | 0.87 | 0.89 | 0.022 |", "",
              "With `spatial` alone, still point-like clutter (tree tops, dark sensor rows, compression texture) was "
              "confirmed. With the spatiotemporal background the confirmed clutter is fainter than the targets: "
              "over the snr-5 run's tracks, the largest z within 1 px of the estimate (median over a track's rows) is "
              "10–52 on the 17 tracks on a target (16 or more on every clip's main track) and 0.5–14.3 on the 37 "
              "others. Raising the snr preset instead costs "
              "acquisition (it also raises the saliency threshold and the birth intensities), so the gate "
              "(`min_peak_z`, output only) was chosen; starting its running mean at 0 means a track must stay bright for "
              "about ten frames, which removed the short tracks on ground transients early in the clips. The false "
              "points left are mostly real unlabelled objects: a vehicle moving along the road in IR_DRONE_142 and "
              "moving ground objects in IR_BIRD_016. The multi-frame LEF moved detection on two clips, IR_BIRD_016 "
              "0.92 → 0.84 and IR_AIRPLANE_031 0.95 → 0.92 (first confirmation at frame 25 instead of 16). With "
              "tracked candidates left in ICEF's MSW the vehicle was not confirmed, but only because a bright tracked "
              "object then set MSW for every other track, which also held dim targets down (IR_DRONE_021 with "
              "`background='spatial'`: detection 0.08 against 0.25).", "",
              f"![{args.gif}](drone_ir.gif)", ""]
    out = out_dir / "drone_ir.md"
    kept = out.read_text().split("](drone_ir.gif)\n", 1)[1:] if out.exists() else []  # hand-written sections below
    out.write_text("\n".join(lines) + (kept[0] if kept else ""))
    print(f"-> {out_dir / 'drone_ir.md'}")


if __name__ == "__main__":
    main()
