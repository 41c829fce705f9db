"""Which host arrays a method hands its Taichi kernels each frame (docs/performance.md, issue 41 item 4).

On a GPU every NumPy array passed to a kernel is copied to the device before the launch and back after it, so the
bytes of NumPy arrays in kernel arguments per frame are the per-frame device↔host traffic (field transfers go
through `backend.to_host` / `from_host`, whose kernels take NumPy arrays too).  On the CPU these arrays are used
in place; the count is the same.  Runs a method on its bench scene and settings (`tbd-taichi bench`'s, 256 × 320 unless
``--shape``) and prints, per kernel, the launches and KiB of NumPy arguments per frame after a warm-up, and the
frame's own size for comparison.

    python benchmarks/host_device_traffic.py [--method sgds] [--snr 1.2] [--shape 256 320] [--frames 40]
"""
import argparse
from collections import defaultdict

import numpy as np
from taichi.lang import kernel_impl

from tbd_taichi import backend, launch
from tbd_taichi.bench import WARMUP, bench_sequence, pipeline_stepper


class Tally:
    """Per kernel name: launches and bytes of NumPy-array arguments, while ``on``."""

    def __init__(self):
        self.on, self.launches, self.bytes, self.inside = False, defaultdict(int), defaultdict(int), False
        self.arrays = {}  # kernel name → (position, shape, dtype) of its last call's NumPy arguments

    def add(self, name: str, args) -> None:
        if self.on and not self.inside:
            arrays = [(i, a) for i, a in enumerate(args) if isinstance(a, np.ndarray)]
            self.launches[name] += 1
            self.bytes[name] += sum(a.nbytes for _, a in arrays)
            self.arrays[name] = [(i, a.shape, a.dtype.name) for i, a in arrays]


def counted(tally: Tally) -> None:
    """Route the project's lean launches and Taichi's own kernel calls through ``tally`` (a lean launch that falls
    back to Taichi's call is counted once)."""
    lean_call, taichi_call = launch.FastKernel.__call__, kernel_impl.Kernel.__call__

    def lean(self, *args, **kwargs):
        tally.add(self.kernel.func.__name__, args)
        tally.inside = True
        try:
            return lean_call(self, *args, **kwargs)
        finally:
            tally.inside = False

    def direct(self, *args, **kwargs):
        tally.add(self.func.__name__, args)
        return taichi_call(self, *args, **kwargs)

    launch.FastKernel.__call__, kernel_impl.Kernel.__call__ = lean, direct


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--method", default="sgds", help="a registered method (default sgds)")
    parser.add_argument("--snr", type=float, default=1.2, help="the preset's SNR (default 1.2)")
    parser.add_argument("--shape", type=int, nargs=2, default=(256, 320), metavar=("H", "W"))
    parser.add_argument("--frames", type=int, default=40, help="counted frames (default 40)")
    args = parser.parse_args()
    backend.init("cpu")
    tally, shape = Tally(), tuple(args.shape)
    counted(tally)
    frames = bench_sequence(args.method, shape, args.frames + WARMUP + 10, args.snr)
    step, close = pipeline_stepper(shape, args.snr, "taichi", method=args.method)
    for frame in frames[:WARMUP + 10]:
        step(frame)
    tally.on = True
    for frame in frames[WARMUP + 10:]:
        step(frame)
    close()
    n, frame_kib = args.frames, shape[0] * shape[1] * 4 / 1024
    print(f"{args.method}, {shape[0]} × {shape[1]}, SNR preset {args.snr}: NumPy arrays handed to kernels per frame "
          f"(one f32 frame is {frame_kib:.0f} KiB)")
    for name in sorted(tally.bytes, key=lambda k: -tally.bytes[k]):
        print(f"  {name:<40} {tally.launches[name] / n:6.2f} launches {tally.bytes[name] / n / 1024:9.1f} KiB")
        if tally.bytes[name]:
            print("      last call's arrays (argument, shape, dtype): "
                  + "; ".join(f"{i} {shape} {dtype}" for i, shape, dtype in tally.arrays[name]))
    print(f"  {'all':<40} {sum(tally.launches.values()) / n:6.2f} launches "
          f"{sum(tally.bytes.values()) / n / 1024:9.1f} KiB")


if __name__ == "__main__":
    main()
