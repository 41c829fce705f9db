"""The searching and tracking PFs' step: two ``step`` launches and ``estimates`` against one ``step_with``.

The pools are those of ``SGDSPF((256, 320), snr=1.4)``: its searching PFs (one per block, map births,
N_sump particles each) with random proposal maps, and its tracking PFs (N_tpf particles each, copy
births), ``--tracks`` of them live, stepped on the same simulated frames.  Each way gets its own
tracker with the same seed; the two are timed frame by frame in alternation, so a slow spell of the
machine hits both.

    python benchmarks/paired_step_bench.py [--frames 60] [--tracks 32]
"""
import argparse
import statistics
import time

import numpy as np

import tbd_taichi as tbd

SHAPE = (256, 320)
MAX_TRACKS = 32  # SGDSPF's default max_tracks
MAP_PIXELS = 3000  # proposal pixels per block


def pools(tracks: int):
    """The searching pool (with proposal maps) and the tracking pool (``tracks`` live tracks) of an SGDS-PF
    at the SNR 1.4 preset (fixed seeds)."""
    rng = np.random.default_rng(0)
    h, w = SHAPE
    tracker = tbd.SGDSPF(SHAPE, snr=1.4, seed=1, max_tracks=MAX_TRACKS)
    search, track, n_tpf = tracker.search, tracker.tracks_pool, tracker.p.N_tpf
    search.set_proposal_map({g: (np.sort(rng.choice(h * w, MAP_PIXELS, replace=False)), rng.random(MAP_PIXELS))
                             for g in range(search.n_groups)})
    track.set_state({g: dict(x=rng.uniform(0, w - 1, n_tpf), y=rng.uniform(0, h - 1, n_tpf),
                             vx=rng.normal(0, 0.3, n_tpf), vy=rng.normal(0, 0.3, n_tpf), inten=rng.uniform(1, 4, n_tpf),
                             e=(rng.random(n_tpf) < 0.7).astype(int), tp=np.ones(n_tpf, int)) for g in range(tracks)})
    return search, track, tracker.p.N_sump


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=60, help="timed frames (after 10 of warm-up)")
    parser.add_argument("--tracks", type=int, default=MAX_TRACKS, help=f"live tracking PFs (≤ {MAX_TRACKS})")
    args = parser.parse_args()
    tbd.init("cpu")
    frames = tbd.simulate(SHAPE, args.frames + 10, snr=1.4, seed=0, motion="transit").frames
    (s1, t1, n_sump), (s2, t2, _) = pools(args.tracks), pools(args.tracks)
    top_up = np.full(s1.n_groups, n_sump)
    seq1, seq2 = np.empty(s1.capacity, np.int32), np.empty(s2.capacity, np.int32)
    separate, paired = [], []
    for f, frame in enumerate(frames):
        z = tbd.normalise_frame(frame).z
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
    print(f"paired in one launch: {s2.pairs_with(t2)} (split over {s2.split} thread(s))")
    print(f"two steps + estimates {statistics.median(separate) * 1e3:.3f} ms, step_with "
          f"{statistics.median(paired) * 1e3:.3f} ms (median of {args.frames} frames, {args.tracks} live tracks)")


if __name__ == "__main__":
    main()
