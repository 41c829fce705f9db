"""What SGDS-PF's multi-frame hand-over costs per call (docs/performance.md, issue 41 item 2).

Runs the tracker on a simulated 200 × 200 sequence at the SNR 1.2 preset, keeps the inputs of its last
``--calls`` hand-overs (the PPs' particles, the ring of recent frames), then replays them ``--repeats`` times
through ``multi_frame_draws`` for each engine: ms per call (the generators' set-up included, as the tracker makes
them), fastest and median over the repeats (each the mean of the kept calls), with and without the velocity jitter
and without the recent frames (the launch, the jitter and the draws alone).

    python benchmarks/handover_draws.py [--calls 8] [--repeats 60]
"""
import argparse
import copy
import time

import numpy as np

from tbd_taichi import backend, methods
from tbd_taichi.bench import machine_description
from tbd_taichi.methods.sgds import handover, tracker
from tbd_taichi.simulate import simulate


def kept_calls(n_calls: int) -> list:
    """The arguments of the last ``n_calls`` hand-overs of a 40-frame SNR 1.2 run (seed 3)."""
    calls, draw = [], tracker.multi_frame_draws

    def keep(kernels, members, pps, size, recent, frame, sigmas, rngs, jitter=0.0):
        calls.append((copy.deepcopy(members), list(pps), size, copy.deepcopy(recent), frame, sigmas, jitter))
        return draw(kernels, members, pps, size, recent, frame, sigmas, rngs, jitter)

    tracker.multi_frame_draws = keep
    try:
        run = methods.make_tracker("sgds", (200, 200), engine="taichi", snr=1.2)
        for frame in simulate((200, 200), frames=40, seed=3, snr=1.2, motion="transit").frames:
            run.update(frame)
    finally:
        tracker.multi_frame_draws = draw
    return calls[-n_calls:]


def ms_per_call(kernels, calls: list, repeats: int) -> tuple[float, float]:
    """(fastest, median) over ``repeats`` of the mean ms per call of ``calls``."""
    means = []
    for _ in range(repeats + 1):
        t0 = time.perf_counter()
        for members, pps, size, recent, frame, sigmas, jitter in calls:
            rngs = [np.random.default_rng([3, frame, handover.HANDOVER_STREAM, k + 1]) for k in range(len(pps))]
            handover.multi_frame_draws(kernels, {k: v.copy() for k, v in members.items()}, pps, size, recent, frame,
                                       sigmas, rngs, jitter)
        means.append((time.perf_counter() - t0) / len(calls) * 1e3)
    return min(means[1:]), float(np.median(means[1:]))  # the first pass compiles


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--calls", type=int, default=8)
    ap.add_argument("--repeats", type=int, default=60)
    args = ap.parse_args()
    backend.init("cpu")
    calls = kept_calls(args.calls)
    print(f"{machine_description()}: {len(calls)} hand-overs, {np.mean([len(c[1]) for c in calls]):.1f} PPs and "
          f"{np.mean([sum(n for _, n in c[1]) for c in calls]):.0f} particles a call, {calls[0][2]} draws per PP")
    cases = {"as run": calls, "no jitter": [c[:6] + (0.0,) for c in calls],
             "no recent frames": [c[:3] + (handover.RecentFrames(0, c[3].shape),) + c[4:] for c in calls]}
    for engine in ("taichi", "numpy"):
        kernels = handover.engine_kernels(engine)
        for label, case in cases.items():
            fastest, median = ms_per_call(kernels, case, args.repeats)
            print(f"{engine:7s} {label:17s} {fastest:7.3f} ms fastest, {median:7.3f} ms median")


if __name__ == "__main__":
    main()
