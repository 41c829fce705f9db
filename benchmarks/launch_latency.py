"""What a kernel launch costs on this machine, alone and after host work (docs/results/bench_machines.md).

The tracker alternates host bookkeeping with kernel launches about seven times a frame.  On some VMs the first
launch after a stretch of host work costs 10–20× a launch made back to back, which hits the Taichi engine (many
short stretches) much more than the NumPy engine.  This measures, median µs over ``--repeats`` (after a NumPy
sum of 4 MiB between repeats, so every case starts from the same state):

* ``serial``: a one-task kernel that copies 32 integers, through the tracker's lean launch path, back to back;
* ``serial after N ms``: the same after N ms of Python work, and ``second`` a different kernel right after it;
* ``numpy copy after N ms``: a NumPy copy of 32 integers after the same work, for scale;
* ``parallel``: an empty parallel loop over 2 iterations (a start of Taichi's CPU thread pool).

    python benchmarks/launch_latency.py [--repeats 300]
"""

import argparse
import time
import types

import numpy as np

from tbd_taichi import backend
from tbd_taichi.bench import machine_description

WORK_MS = (0.0, 0.5, 2.0, 5.0)


def busy(ms: float) -> None:
    """Python work for ``ms`` milliseconds (a loop on the clock)."""
    end = time.perf_counter() + ms * 1e-3
    while time.perf_counter() < end:
        pass


def median_us(samples) -> float:
    return float(np.median(samples) * 1e6)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=300)
    args = parser.parse_args()
    backend.init("cpu")
    import taichi as ti

    from tbd_taichi.launch import Launcher

    a, b = ti.field(ti.i32, 64), ti.field(ti.i32, 64)

    @ti.kernel
    def copy_a(c: ti.types.ndarray(dtype=ti.i32, ndim=1)):
        ti.loop_config(serialize=True)
        for k in range(c.shape[0]):
            a[k] = c[k]

    @ti.kernel
    def copy_b(c: ti.types.ndarray(dtype=ti.i32, ndim=1)):
        ti.loop_config(serialize=True)
        for k in range(c.shape[0]):
            b[k] = c[k]

    @ti.kernel
    def empty_parallel(n: ti.i32):
        for k in range(n):
            a[k] += 1

    kernels = Launcher(types.SimpleNamespace(copy_a=copy_a, copy_b=copy_b, empty_parallel=empty_parallel))
    c = np.arange(32, dtype=np.int32)
    flush = np.random.default_rng(0).random(1 << 19)
    kernels.copy_a(c), kernels.copy_b(c), kernels.empty_parallel(2)  # compile
    print(f"on {machine_description()}, median of {args.repeats} (µs)")
    for ms in WORK_MS:
        first, second, copy = [], [], []
        for _ in range(args.repeats):
            flush.sum()
            busy(ms)
            t0 = time.perf_counter()
            kernels.copy_a(c)
            t1 = time.perf_counter()
            kernels.copy_b(c)
            t2 = time.perf_counter()
            first.append(t1 - t0), second.append(t2 - t1)
            busy(ms)
            t3 = time.perf_counter()
            c.copy()
            copy.append(time.perf_counter() - t3)
        print(f"after {ms:3.1f} ms of Python: serial launch {median_us(first):7.1f}, second {median_us(second):7.1f}, "
              f"numpy copy {median_us(copy):6.1f}")
    par = []
    for _ in range(args.repeats):
        t0 = time.perf_counter()
        kernels.empty_parallel(2)
        par.append(time.perf_counter() - t0)
    print(f"empty parallel loop, back to back: {median_us(par):7.1f}")


if __name__ == "__main__":
    main()
