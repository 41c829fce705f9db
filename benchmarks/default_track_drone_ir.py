"""`tbd-taichi track CLIP --truth CLIP.csv` with no other flag on every drone-ir clip: what a new user gets.

Runs the command line itself (in this process, one clip after the other), with the profile it picks for a
video (``auto`` → ``real-video``), its default output (each confirmed track's whole path) and its box scoring
(a hit is a track point inside the label box grown by 2 px).  Writes docs/results/drone_ir_default.md.

    python benchmarks/default_track_drone_ir.py [--data ../shared/data/drone-ir] [--method sgds] [--out FILE]
        [--seed S] [--param KEY=VALUE ...]

``--seed`` and ``--param`` are passed to ``track`` (other seeds; a method that needs a setting on real video, as
``--method ma-apf --param templates=vehicle``).
"""
from __future__ import annotations

import argparse
import contextlib
import io
import json
import tempfile
from pathlib import Path

import numpy as np

from tbd_taichi import cli

ROOT = Path(__file__).resolve().parent.parent


def track_clip(video: Path, labels: Path, method: str, work: Path, extra: list[str] = ()) -> dict:
    """The JSON summary ``track --json`` prints for one clip (scores included); ``extra``: more ``track`` flags."""
    out = io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(io.StringIO()):
        code = cli.main(["track", str(video), "--method", method, "--out", str(work / f"{video.stem}.csv"),
                         "--truth", str(labels), "--progress", "off", "--json", *extra])
    if code != 0:
        raise SystemExit(f"{video.name}: track exited with {code}")
    return json.loads(out.getvalue().strip().splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", default=str(ROOT.parent / "shared" / "data" / "drone-ir"))
    parser.add_argument("--method", default="sgds")
    parser.add_argument("--out", default=str(ROOT / "docs" / "results" / "drone_ir_default.md"))
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--param", action="append", default=[], metavar="KEY=VALUE")
    args = parser.parse_args()
    extra = ["--seed", str(args.seed)] + [item for p in args.param for item in ("--param", p)]
    flags = "".join(f" --param {p}" for p in args.param) + (f" --seed {args.seed}" if args.seed else "")
    clips = sorted(Path(args.data).glob("*.mp4"))
    rows = []
    with tempfile.TemporaryDirectory() as work:
        for video in clips:
            summary = track_clip(video, video.with_suffix(".csv"), args.method, Path(work), extra)
            rows.append((video.stem, summary))
            s = summary["scores"]
            print(f"{video.stem}: detection {s['detection_rate']:.3f}, false points/frame {s['false_points']:.3f}, "
                  f"tracks {summary['tracks']}, {summary['tracker_fps']:.0f} frames/s, profile {summary['profile']}",
                  flush=True)
    det = [s["scores"]["detection_rate"] for _, s in rows]
    false = [s["scores"]["false_points"] for _, s in rows]
    lines = [f"# `tbd-taichi track` with {'no flags' if not flags else 'no other flags'} on the drone-ir clips "
             f"({args.method}{flags})", "",
             f"`python benchmarks/default_track_drone_ir.py --method {args.method}{flags}`: for each clip "
             f"`tbd-taichi track CLIP.mp4 --method {args.method}{flags} --truth CLIP.csv --out tracks.csv` — the "
             "profile `auto` picks for a video (`real-video`), the default output (each confirmed track's whole "
             f"path), box scoring with the default 2 px margin. CPU, seed {args.seed}.", "",
             "| clip | frames | profile | detection rate | false points / frame | centre error (px) | tracks | "
             "tracker frames/s |", "|---|---:|---|---:|---:|---:|---:|---:|"]
    for clip, s in rows:
        sc = s["scores"]
        lines.append(f"| {clip} | {s['frames']} | {s['profile']} | {sc['detection_rate']:.3f} | "
                     f"{sc['false_points']:.3f} | {sc['centre_error']:.2f} | {s['tracks']} | {s['tracker_fps']:.0f} |")
    found = sum(d > 0 for d in det)
    lines += ["", f"Target found on {found} of {len(rows)} clips; mean detection rate {np.mean(det):.3f} (goal ≥ 0.8); "
              f"mean false points per frame {np.mean(false):.3f} (goal ≤ 0.05)."]
    Path(args.out).write_text("\n".join(lines) + "\n")
    print("\n".join(lines[-1:]))
    print(f"-> {args.out}")


if __name__ == "__main__":
    main()
