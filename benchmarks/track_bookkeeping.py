"""What SGDS-PF's per-track bookkeeping costs the host per frame (docs/performance.md, issue 41 item 2).

Runs the tracker on the bench scene (256 × 320, the SNR 1.2 preset, `tbd-taichi bench`'s targets) and times,
per frame after a warm-up, the host functions whose work grows with the number of tracks: the confirmation
(`_confirm_tracks`: Eqs. 39–43 for every tracking PF, the ends, the reports and the duplicate merge), the
proposal's masking around the tracks (`_suppress_tracked`) and ICEF's MSW (`_log_msw`).  ``--max-tracks``
raises the number of tracking PFs (the preset has 32, all in use at SNR 1.2).

    python benchmarks/track_bookkeeping.py [--frames 150] [--max-tracks 32] [--engine taichi]
"""
import argparse
import functools
import time

from tbd_taichi import backend, methods
from tbd_taichi.bench import WARMUP, bench_sequence, machine_description
from tbd_taichi.methods.sgds.tracker import SGDSPF

TIMED = ("_confirm_tracks", "_suppress_tracked", "_log_msw")


def timed_methods(seconds: dict) -> None:
    """Wrap SGDSPF's TIMED methods so that each adds its wall time to ``seconds``."""
    for name in TIMED:
        method = getattr(SGDSPF, name)

        @functools.wraps(method)
        def clocked(*args, _method=method, _name=name, **kwargs):
            t0 = time.perf_counter()
            try:
                return _method(*args, **kwargs)
            finally:
                seconds[_name] = seconds.get(_name, 0.0) + time.perf_counter() - t0

        setattr(SGDSPF, name, clocked)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=150, help="timed frames (default 150)")
    parser.add_argument("--max-tracks", type=int, default=32, help="tracking PFs (default 32, the preset's)")
    parser.add_argument("--engine", choices=("taichi", "numpy"), default="taichi")
    args = parser.parse_args()
    if args.engine == "taichi":
        backend.init("cpu")
    spec, seconds = methods.get("sgds"), {}
    frames = bench_sequence("sgds", (256, 320), args.frames + WARMUP + 10, 1.2)
    tracker = methods.make_tracker("sgds", (256, 320), engine=args.engine, history=False,
                                   **{**spec.bench_keywords(1.2), "max_tracks": args.max_tracks})
    for frame in frames[:WARMUP + 10]:
        tracker.update(frame)
    timed_methods(seconds)
    for frame in frames[WARMUP + 10:]:
        tracker.update(frame)
    per_frame = {name: seconds.get(name, 0.0) / args.frames * 1e3 for name in TIMED}
    print(f"{machine_description()}; engine {args.engine}; {args.max_tracks} tracking PFs, "
          f"{len(tracker.active)} active at the end; ms per frame over {args.frames} frames:")
    print("  " + ", ".join(f"{name} {ms:.3f}" for name, ms in per_frame.items())
          + f"; together {sum(per_frame.values()):.3f}")


if __name__ == "__main__":
    main()
