"""Per-kernel cost of the normalisation stage (``tbd_taichi.background.Preprocessor``) on a real clip.

    python benchmarks/normalise_bench.py [CLIP] [--background spatiotemporal] [--engine taichi|numpy]

Reads the clip's frames, runs the first 20 to warm the kernels and the running backgrounds, then times every
later frame and every kernel launch in it; prints the median ms per frame and per kernel (docs/performance.md).
"""
from __future__ import annotations

import argparse
import time
from collections import defaultdict
from pathlib import Path

import numpy as np

import tbd_taichi
from tbd_taichi.background import BACKGROUNDS, Preprocessor
from tbd_taichi.io import read_frames

DEFAULT_CLIP = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "drone-ir" / "IR_DRONE_021.mp4"
WARM_FRAMES = 20


class TimedKernels:
    """The preprocessor's kernel module with every call timed (seconds per kernel name, one entry a call)."""

    def __init__(self, kernels):
        self.kernels, self.seconds = kernels, defaultdict(list)

    def __getattr__(self, name):
        kernel = getattr(self.kernels, name)

        def timed(*args):
            start = time.perf_counter()
            kernel(*args)
            self.seconds[name].append(time.perf_counter() - start)

        return timed


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("clip", nargs="?", default=str(DEFAULT_CLIP))
    parser.add_argument("--background", default="spatiotemporal", choices=BACKGROUNDS)
    parser.add_argument("--engine", default="taichi", choices=("taichi", "numpy"))
    args = parser.parse_args()
    tbd_taichi.init("cpu")
    frames = [np.asarray(f, np.float32) for f in read_frames(args.clip)]
    pre = Preprocessor(frames[0].shape, args.background, True, args.engine)
    for frame in frames[:WARM_FRAMES]:
        pre(frame)
    pre.k = timed = TimedKernels(pre.k)
    per_frame = []
    for frame in frames[WARM_FRAMES:]:
        start = time.perf_counter()
        pre(frame)
        per_frame.append(time.perf_counter() - start)
    print(f"{args.background} on {args.engine}, {len(per_frame)} frames {frames[0].shape}: "
          f"{1e3 * np.median(per_frame):.3f} ms per frame (median)")
    for name, seconds in sorted(timed.seconds.items(), key=lambda kv: -np.median(kv[1])):
        print(f"  {name:28s} {1e3 * np.median(seconds):.3f} ms x {len(seconds) / len(per_frame):.2f} a frame")


if __name__ == "__main__":
    main()
