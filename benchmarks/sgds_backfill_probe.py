"""SGDS-PF's backfill (issue 43) replayed on the suite's scenes: each run is tracked once, and its whole paths are
scored with each backfill length asked for (``SGDSPF.whole_paths`` under ``backfill_frames`` = K), so the variants
differ only in the rows the backfill adds (docs/methods/sgds.md#where-the-misses-come-from).

    python benchmarks/sgds_backfill_probe.py SIDE SNR TESTS [K,K,...] [FIRST] ['{"name": value, ...}']

Prints mean DSR, TSR and false tracks per sequence for each K, as JSON; the JSON overrides go to the tracker.
"""
from __future__ import annotations

import json
import sys
import time
from dataclasses import replace

import numpy as np

from tbd_taichi import metrics
from tbd_taichi.methods import make_tracker
from tbd_taichi.simulate import simulate
from tbd_taichi.suite import SIZES


def probe(side: int, snr: float, tests: int, lengths, first: int = 0, overrides: dict | None = None) -> dict:
    n_frames = dict(SIZES)[side]
    scores = {k: [] for k in lengths}
    t0 = time.time()
    for seed in range(first, first + tests):
        scene = simulate((side, side), frames=n_frames, snr=snr, seed=seed)
        inner = make_tracker("sgds", (side, side), snr=snr, seed=seed, profile="paper", **(overrides or {})).tracker
        for frame in scene.frames:
            inner.update(frame)
        inner.finish()
        for k in lengths:
            inner.p = replace(inner.p, backfill_frames=k)
            s = metrics.evaluate(inner.whole_paths(), scene.truth, n_frames=n_frames)
            scores[k].append((s["dsr"], s["false_tracks"]))
    out = {}
    for k, runs in scores.items():
        dsr = np.array([d for d, _ in runs])
        out[f"backfill {k}"] = dict(dsr=round(float(dsr.mean()), 3), tsr=round(metrics.tsr(dsr), 3),
                                    false_tracks=round(float(np.mean([f for _, f in runs])), 3))
    return dict(side=side, snr=snr, tests=tests, first=first, overrides=overrides or {},
                seconds=round(time.time() - t0), variants=out)


def main(argv: list[str]) -> None:
    if len(argv) < 3:
        sys.exit(__doc__.strip().splitlines()[-3].strip())
    lengths = [int(v) for v in argv[3].split(",")] if len(argv) > 3 else [0, 8]
    print(json.dumps(probe(int(argv[0]), float(argv[1]), int(argv[2]), lengths, int(argv[4]) if len(argv) > 4 else 0,
                           json.loads(argv[5]) if len(argv) > 5 else None)))


if __name__ == "__main__":
    main(sys.argv[1:])
