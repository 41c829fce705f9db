"""Real infrared video end to end: SGDS-PF on a drone clip, scored against its labels, with an overlay video.

Runs SGDS-PF with the real-video settings ``tbd_taichi.background.REAL_VIDEO`` (spatiotemporal
background suppression, snr 5 preset, tracks reported from a running peak z of 16; otherwise
defaults) over a clip of the drone-ir set (CC0; IR_DRONE_021 ships in tests/data),
prints the detection rate, false points per frame and frames to first confirmation, and
writes the tracks CSV and an overlay video with each confirmed track.

    python demos/drone_ir.py [--clip tests/data/IR_DRONE_021.mp4] [--out out/drone_ir] [--frames N]
"""
import argparse
from pathlib import Path

import tbd_taichi as tbd
from tbd_taichi import io, metrics, tables
from tbd_taichi.background import REAL_VIDEO
from tbd_taichi.plots import write_overlay_video

ROOT = Path(__file__).resolve().parent.parent


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--clip", default=str(ROOT / "tests" / "data" / "IR_DRONE_021.mp4"),
                        help="a video; its labels CSV (frame,x,y,w,h) is looked for beside it")
    parser.add_argument("--out", default="out/drone_ir")
    parser.add_argument("--frames", type=int, default=None, help="only the first N frames")
    args = parser.parse_args()
    clip, out = Path(args.clip), Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    tbd.keep_freed_memory()  # glibc: reuse freed frame-sized buffers instead of page-faulting new ones
    frames = io.read_frames(clip)[:args.frames]
    tracker = tbd.SGDSPF(frames.shape[1:], **REAL_VIDEO)  # real video needs background suppression
    for frame in frames:
        tracker.update(frame)
    tracker.finish()
    tracks = tracker.online()  # the rows as confirmed, what a live user sees
    tables.write_csv(tracks, out / "tracks.csv")
    labels = clip.with_suffix(".csv")
    if labels.is_file():
        boxes = tables.read_boxes(labels)
        scores = metrics.box_scores(tracks, boxes[boxes["frame"] < len(frames)], len(frames))
        print(f"{clip.stem}: detection rate {scores['detection_rate']:.2f}, false points/frame "
              f"{scores['false_points']:.2f}, frames to first confirmation {scores['first_confirmation']:.0f}")
    n = write_overlay_video(frames, tracks, out / "overlay.avi")
    print(f"{len(tracks)} confirmed rows -> {out / 'tracks.csv'}; overlay video ({n} frames) -> {out / 'overlay.avi'}")


if __name__ == "__main__":
    main()
