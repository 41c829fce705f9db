"""Constant memory on an endless stream: SGDSPF(history=False) over N frames (default 100,000).

Frames are made on the fly (white noise with one still target of SNR 3 at the centre), so the
input takes no memory; the resident set size (RSS, from /proc) is sampled every ``--every``
frames after a warm-up.  Writes docs/results/memory_stream.md.

    python benchmarks/memory_stream.py [--frames 100000] [--shape 64 64]
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

import tbd_taichi
from tbd_taichi.methods.sgds import SGDSPF
from tbd_taichi.simulate import intensity_for_snr, render_psf

OUT = Path(__file__).resolve().parent.parent / "docs" / "results" / "memory_stream.md"


def rss_mib() -> float:
    """Resident set size of this process, MiB (Linux /proc)."""
    with open("/proc/self/statm") as handle:
        pages = int(handle.read().split()[1])
    return pages * 4096 / 2**20


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=100_000)
    parser.add_argument("--shape", type=int, nargs=2, default=[64, 64])
    parser.add_argument("--every", type=int, default=10_000)
    args = parser.parse_args()
    tbd_taichi.init("cpu")
    h, w = args.shape
    target = np.zeros((h, w), np.float32)
    render_psf(target, (w - 1) / 2, (h - 1) / 2, intensity_for_snr(3.0), 0.7)
    rng = np.random.default_rng(0)
    tracker = SGDSPF((h, w), snr=3.0, history=False)
    samples, rows, t0 = [], 0, time.perf_counter()
    for t in range(args.frames):
        rows += len(tracker.update(target + rng.standard_normal((h, w), dtype=np.float32)))
        if t % args.every == 0 and t >= 1000 or t == 1000:
            samples.append((t, rss_mib(), rows))
            print(f"frame {t:>7}: RSS {samples[-1][1]:.1f} MiB, {rows} confirmed rows", flush=True)
    tracker.finish()
    seconds = time.perf_counter() - t0
    base = samples[0][1]
    lines = [f"# Memory over a {args.frames:,}-frame stream", "",
             f"`python benchmarks/memory_stream.py --frames {args.frames} --shape {h} {w}`: "
             f"SGDSPF(history=False), {h}x{w}, one still SNR 3 target, CPU, {seconds / args.frames * 1e3:.2f} ms/frame.", "",
             "| frame | RSS (MiB) | change since frame 1000 (MiB) | confirmed rows so far |", "|---:|---:|---:|---:|"]
    lines += [f"| {t} | {m:.1f} | {m - base:+.1f} | {r} |" for t, m, r in samples]
    OUT.write_text("\n".join(lines) + "\n")
    print(f"-> {OUT}")


if __name__ == "__main__":
    main()
