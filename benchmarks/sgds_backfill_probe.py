"""SGDS-PF's backfill (issue 43) replayed on the suite's scenes: each run is tracked once, and its whole paths are
scored with the backfill off and with each (frames K, fitted points L) asked for, so the variants differ only in
the rows the backfill adds (docs/methods/sgds.md#where-the-misses-come-from).

    python benchmarks/sgds_backfill_probe.py SIDE SNR TESTS [K,K,...] [L,L,...] [FIRST]

Prints mean DSR, TSR and false tracks per sequence for each variant, as JSON.
"""
from __future__ import annotations

import json
import sys
import time

import numpy as np

from tbd_taichi import metrics
from tbd_taichi.methods import make_tracker
from tbd_taichi.methods.sgds.confirmation import backfilled
from tbd_taichi.simulate import simulate
from tbd_taichi.suite import SIZES
from tbd_taichi.tables import TRACK_DTYPE, make_table


def with_backfill(paths: np.ndarray, frames: int, fit: int, shape) -> np.ndarray:
    """``paths`` (whole paths without the backfill) with each track's backfilled rows added."""
    rows = [tuple(r) for r in paths.tolist()]
    for track in np.unique(paths["track_id"]):
        own = [(f, x, y, vx, vy, i, c) for f, t, x, y, vx, vy, i, c in rows if t == track]
        rows += [(f, track, *rest) for f, *rest in backfilled(sorted(own), frames, shape, fit)]
    return make_table(rows, TRACK_DTYPE)


def probe(side: int, snr: float, tests: int, ks, ls, first: int = 0) -> dict:
    n_frames = dict(SIZES)[side]
    scores = {(k, fit): [] for k in ks for fit in ls}
    t0 = time.time()
    for seed in range(first, first + tests):
        scene = simulate((side, side), frames=n_frames, snr=snr, seed=seed)
        inner = make_tracker("sgds", (side, side), snr=snr, seed=seed, profile="paper", backfill_frames=0).tracker
        for frame in scene.frames:
            inner.update(frame)
        paths = inner.finish()
        for k, fit in scores:
            s = metrics.evaluate(with_backfill(paths, k, fit, (side, side)), scene.truth, n_frames=n_frames)
            scores[(k, fit)].append((s["dsr"], s["false_tracks"]))
    out = {}
    for (k, fit), runs in scores.items():
        dsr = np.array([d for d, _ in runs])
        out[f"frames {k}, fit {fit}"] = dict(dsr=round(float(dsr.mean()), 3), tsr=round(metrics.tsr(dsr), 3),
                                             false_tracks=round(float(np.mean([f for _, f in runs])), 3))
    return dict(side=side, snr=snr, tests=tests, first=first, seconds=round(time.time() - t0), variants=out)


def main(argv: list[str]) -> None:
    if len(argv) < 3:
        sys.exit(__doc__.strip().splitlines()[-3].strip())
    ints = lambda text: [int(v) for v in text.split(",")]  # noqa: E731
    print(json.dumps(probe(int(argv[0]), float(argv[1]), int(argv[2]), ints(argv[3]) if len(argv) > 3 else [0, 8],
                           ints(argv[4]) if len(argv) > 4 else [20], int(argv[5]) if len(argv) > 5 else 0)))


if __name__ == "__main__":
    main(sys.argv[1:])
