"""Long et al. 2012's track-detection measures (§5.3, Tables 2–4) beside OSPA: the mean cardinality error, the
probability of track detection P_TD, false tracks, and the frames at which tracks are detected and halted.

Definitions (frames 0-based; :func:`paper_frame` gives the paper's 1-based numbers):

* cardinality error: the mean over frames 0..n_frames−1 of |track rows in the frame − truth rows in it|;
* association: tracks to targets one to one (Hungarian, ``scipy.optimize.linear_sum_assignment``) on the mean
  distance over the frames both have; a pair with no common frame, or a mean distance above ``gate``, is none;
* detected (per target): an associated track exists and its position at its detection frame lies within
  ``gate`` px (TRACK_GATE = 5 px, the paper's "initialised within the accuracy of 5 pixels") of the target then;
  P_TD counts run × target (the paper's values are multiples of 1/300: 100 runs × 3 targets);
* detection frame: the track's confirmation frame when given (``confirmed``: {track_id: frame}), else its first
  frame; start frame: its first frame (the start after the backward recursion); halt frame: its last frame +
  ``halt_drops`` (the frame of the second consecutive drop);
* false tracks: :func:`tbd_taichi.metrics.false_tracks` with the same gate (tracks whose points mostly lie
  farther than it from every target in view).
"""
from __future__ import annotations

import numpy as np

from .metrics import false_tracks

TRACK_GATE = 5.0  # px: §5.3's initialisation accuracy, and the OSPA cut-off c used with these measures


def paper_frame(frame):
    """The paper's 1-based frame number of a 0-based frame (or of an array or mean of them)."""
    return frame + 1


def cardinality_error(tracks: np.ndarray, truth: np.ndarray, n_frames: int) -> float:
    """Mean over frames 0..n_frames−1 of |number of track rows − number of truth rows| in the frame."""
    if n_frames <= 0:
        return 0.0
    est = np.bincount(tracks["frame"].astype(int), minlength=n_frames)[:n_frames] if len(tracks) else 0
    tru = np.bincount(truth["frame"].astype(int), minlength=n_frames)[:n_frames] if len(truth) else 0
    return float(np.mean(np.abs(np.asarray(est) - np.asarray(tru)) * np.ones(n_frames)))


def _mean_distances(tracks: np.ndarray, truth: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(track ids, target ids, mean distance matrix over the common frames; inf where none)."""
    track_ids, target_ids = np.unique(tracks["track_id"]), np.unique(truth["target_id"])
    dist = np.full((len(track_ids), len(target_ids)), np.inf)
    for i, tid in enumerate(track_ids):
        tr = tracks[tracks["track_id"] == tid]
        for j, gid in enumerate(target_ids):
            gt = truth[truth["target_id"] == gid]
            _, a, b = np.intersect1d(tr["frame"], gt["frame"], return_indices=True)
            if len(a):
                dist[i, j] = float(np.mean(np.hypot(tr["x"][a] - gt["x"][b], tr["y"][a] - gt["y"][b])))
    return track_ids, target_ids, dist


def associate_tracks(tracks: np.ndarray, truth: np.ndarray, gate: float = TRACK_GATE) -> dict[int, int]:
    """{target_id: track_id}: the one-to-one assignment of least total mean distance, pairs within ``gate``."""
    from scipy.optimize import linear_sum_assignment

    if not len(tracks) or not len(truth):
        return {}
    track_ids, target_ids, dist = _mean_distances(tracks, truth)
    cost = np.where(np.isfinite(dist), dist, 1e9)
    rows, cols = linear_sum_assignment(cost)
    return {int(target_ids[c]): int(track_ids[r]) for r, c in zip(rows, cols) if dist[r, c] <= gate}


def track_detection(tracks: np.ndarray, truth: np.ndarray, n_frames: int, gate: float = TRACK_GATE,
                    halt_drops: int = 2, confirmed: dict | None = None) -> dict:
    """Per target (``targets``: {target_id: {...}}) detected, detection/start/halt frames and the truth's first
    and last frames; overall the number of targets, detected, P_TD, false tracks, whether the declared number is
    right (every target associated and no false track) and the cardinality error."""
    pairs = associate_tracks(tracks, truth, gate)
    per = {}
    for gid in np.unique(truth["target_id"]):
        gt = truth[truth["target_id"] == gid]
        entry = dict(first=int(gt["frame"].min()), last=int(gt["frame"].max()), detected=False,
                     detection_frame=None, start_frame=None, halt_frame=None)
        tid = pairs.get(int(gid))
        if tid is not None:
            tr = tracks[tracks["track_id"] == tid]
            at = int((confirmed or {}).get(tid, tr["frame"].min()))
            row, ref = tr[tr["frame"] == at], gt[gt["frame"] == at]
            near = bool(len(row) and len(ref) and np.hypot(row["x"][0] - ref["x"][0], row["y"][0] - ref["y"][0]) <= gate)
            entry.update(detected=near, detection_frame=at, start_frame=int(tr["frame"].min()),
                         halt_frame=int(tr["frame"].max()) + halt_drops)
        per[int(gid)] = entry
    n_false = false_tracks(tracks, truth, gate) if len(tracks) else 0
    detected = sum(e["detected"] for e in per.values())
    return dict(targets=per, n_targets=len(per), detected=detected, p_td=detected / len(per) if per else float("nan"),
                false_tracks=n_false, correct_number=len(pairs) == len(per) and n_false == 0,
                cardinality_error=cardinality_error(tracks, truth, n_frames))


def pool_runs(results: list[dict]) -> dict:
    """Monte Carlo summary of :func:`track_detection` results, as Tables 2–4: P_TD (%) over run × target, the
    total false tracks, the mean detection, start and halt frames per target over the runs that detected it,
    and the mean cardinality error."""
    targets = sorted({t for r in results for t in r["targets"]})
    n = sum(r["n_targets"] for r in results)

    def mean_of(key, t):
        v = [r["targets"][t][key] for r in results if t in r["targets"] and r["targets"][t]["detected"]]
        return float(np.mean(v)) if v else float("nan")

    return dict(runs=len(results), p_td=100.0 * sum(r["detected"] for r in results) / n if n else float("nan"),
                false_tracks=int(sum(r["false_tracks"] for r in results)),
                detection_frame={t: mean_of("detection_frame", t) for t in targets},
                start_frame={t: mean_of("start_frame", t) for t in targets},
                halt_frame={t: mean_of("halt_frame", t) for t in targets},
                cardinality_error=float(np.mean([r["cardinality_error"] for r in results])) if results else 0.0)


