"""The searching and tracking PFs' step: two ``step`` launches and ``estimates`` against one ``step_with``.

Two pools shaped like SGDS-PF's at the SNR 1.4 preset on 320×256: six searching PFs of 8,000
particles (map births) and 32 tracking PFs of 500 (copy births, ``--tracks`` of them live), stepped on
the same simulated frames.  Each way gets its own pair of pools with the same seeds; the two are timed
frame by frame in alternation, so a slow spell of the machine hits both.

    python benchmarks/paired_step_bench.py [--frames 60] [--tracks 32]
"""
import argparse
import statistics
import time

import numpy as np

import tbd_taichi as tbd
from tbd_taichi.particles import ParticlePool

SHAPE = (256, 320)
SEARCH_GROUPS, N_SUMP, TRACK_GROUPS, N_TPF = 6, 8000, 32, 500


def pools(tracks: int):
    """A searching pool with proposal maps and a tracking pool with ``tracks`` live tracks (fixed seeds)."""
    rng = np.random.default_rng(0)
    h, w = SHAPE
    search = ParticlePool([N_SUMP] * SEARCH_GROUPS, SHAPE, seed=1, map_capacity=h * w)
    search.configure_groups(np.arange(SEARCH_GROUPS), "map", pb=0.05, pd=0.05, intensity=(0.1, 4.4), mu=0.5)
    search.set_proposal_map({g: (np.sort(rng.choice(h * w, 3000, replace=False)), rng.random(3000))
                             for g in range(SEARCH_GROUPS)})
    track = ParticlePool([N_TPF] * TRACK_GROUPS, SHAPE, seed=7)
    track.configure_groups(np.arange(TRACK_GROUPS), "copy", pb=0.05, pd=0.02, intensity=(0.1, 4.4))
    track.set_state({g: dict(x=rng.uniform(0, w - 1, N_TPF), y=rng.uniform(0, h - 1, N_TPF),
                             vx=rng.normal(0, 0.3, N_TPF), vy=rng.normal(0, 0.3, N_TPF), inten=rng.uniform(1, 4, N_TPF),
                             e=(rng.random(N_TPF) < 0.7).astype(int), tp=np.ones(N_TPF, int)) for g in range(tracks)})
    return search, track


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=60, help="timed frames (after 10 of warm-up)")
    parser.add_argument("--tracks", type=int, default=TRACK_GROUPS, help=f"live tracking PFs (≤ {TRACK_GROUPS})")
    args = parser.parse_args()
    tbd.init("cpu")
    frames = tbd.simulate(SHAPE, args.frames + 10, snr=1.4, seed=0, motion="transit").frames
    (s1, t1), (s2, t2) = pools(args.tracks), pools(args.tracks)
    top_up = np.full(SEARCH_GROUPS, N_SUMP)
    seq1, seq2 = np.empty(s1.capacity, np.int32), np.empty(s2.capacity, np.int32)
    separate, paired = [], []
    for f, frame in enumerate(frames):
        z = ((frame - frame.mean()) / frame.std()).astype(np.float32)
        t0 = time.perf_counter()
        s1.step(f, z, top_up=top_up, seq_out=seq1)
        t1.step(f, z)
        t1.estimates()
        t_mid = time.perf_counter()
        s2.step_with(t2, f, z, top_up=top_up, seq_out=seq2)
        t_end = time.perf_counter()
        if f >= 10:
            separate.append(t_mid - t0)
            paired.append(t_end - t_mid)
    print(f"paired in one launch: {s2._pairs_with(t2)} (split over {s2.split} thread(s))")
    print(f"two steps + estimates {statistics.median(separate) * 1e3:.3f} ms, step_with "
          f"{statistics.median(paired) * 1e3:.3f} ms (median of {args.frames} frames, {args.tracks} live tracks)")


if __name__ == "__main__":
    main()
