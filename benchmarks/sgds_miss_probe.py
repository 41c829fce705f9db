"""How SGDS-PF's tracking PFs on the target end, with parameter overrides (issue 43, item 2;
docs/results/sgds_explain.md#item-2-what-was-tried-at-snr-12-and-why-the-defaults-stay).

Runs the suite's scenes (test k: seed k, the condition's Table 2 preset) and prints mean DSR, TSR and false
tracks per sequence, and how each tracking PF whose path came within T0 = 2 px of the target ended: confidence
below T_ft (``low C``), no E = 1 particle for 3 frames (``lost``), merged into an older track that is on the target
(``merged``) or not, or after drifting off the target.  ``-v`` prints each missed run's tracks on the target.

    python benchmarks/sgds_miss_probe.py SIDE SNR TESTS ['{"name": value, ...}'] [FIRST] [-v]
"""
from __future__ import annotations

import collections
import json
import sys
import time

import numpy as np

from tbd_taichi import metrics
from tbd_taichi.methods import make_tracker
from tbd_taichi.simulate import simulate
from tbd_taichi.suite import SIZES


def end_reason(tracker, track, truth: dict) -> str | None:
    """How ``track`` ended, if its path touched the target (None otherwise)."""
    def near(f, x, y):
        return f in truth and np.hypot(truth[f][0] - x, truth[f][1] - y) < metrics.T0

    f, (x, y) = track.path[-1][0], track.last_xy()
    if not any(near(g, px, py) for g, px, py, *_ in track.path):
        return None
    if not near(f, x, y):
        return "drifted off"
    if track.confidence < tracker.p.T_ft:
        return "low C"
    if track.frames_without_e >= 3:
        return "lost"
    h, w = tracker.shape
    if not (-0.5 <= x < w - 0.5 and -0.5 <= y < h - 0.5):
        return "out of view"
    on = any(near(f, *other.last_xy()) for other in tracker.active if other is not track)
    return "merged, older on target" if on else "merged, older off target"


def probe(side: int, snr: float, tests: int, overrides: dict, first: int = 0, verbose: bool = False) -> dict:
    frames = dict(SIZES)[side]  # the suite's frames for this side
    ends, dsrs, false = collections.Counter(), [], []
    t0 = time.time()
    for k in range(first, first + tests):
        scene = simulate((side, side), frames=frames, snr=snr, seed=k)
        inner = make_tracker("sgds", (side, side), snr=snr, seed=k, profile="paper", **overrides).tracker
        truth = {int(r["frame"]): (r["x"], r["y"]) for r in scene.truth}
        life, end = [], inner._end_track

        def watch(track, end=end, inner=inner, life=life):
            reason = end_reason(inner, track, truth)
            if reason:
                ends[("confirmed" if track.confirmed else "unconfirmed", reason)] += 1
                life.append((track.path[0][0], track.path[-1][0], reason, round(track.confidence, 2)))
            end(track)

        inner._end_track = watch
        for frame in scene.frames:
            inner.update(frame)
        s = metrics.evaluate(inner.finish(), scene.truth, n_frames=frames)
        dsrs.append(s["dsr"])
        false.append(s["false_tracks"])
        if verbose and s["dsr"] <= metrics.T1:
            print(k, round(s["dsr"], 2), "tracks on the target (start, end, how, C):", life)
    d = np.array(dsrs)
    return dict(side=side, snr=snr, tests=tests, overrides=overrides, dsr=round(float(d.mean()), 3),
                tsr=round(metrics.tsr(d), 3), false_tracks=round(float(np.mean(false)), 3), seconds=round(time.time() - t0),
                ends={f"{a}, {b}": n for (a, b), n in sorted(ends.items())})


def main(argv: list[str]) -> None:
    verbose = "-v" in argv
    args = [a for a in argv if a != "-v"]
    if len(args) < 3:
        sys.exit(__doc__.strip().splitlines()[-1].strip())
    overrides = json.loads(args[3]) if len(args) > 3 else {}
    print(json.dumps(probe(int(args[0]), float(args[1]), int(args[2]), overrides,
                           int(args[4]) if len(args) > 4 else 0, verbose)))


if __name__ == "__main__":
    main(sys.argv[1:])
