"""Long et al. 2012's track-detection measures (§5.3, Tables 2–4) beside OSPA: the mean cardinality error, the
probability of track detection P_TD, false tracks, and the frames at which tracks are detected and halted.

Definitions (frames 0-based; :func:`paper_frame` gives the paper's 1-based numbers; distances in px):

* cardinality error: the mean over frames 0..n_frames−1 of |track rows in the frame − truth rows in it|;
* association: tracks to targets one to one (Hungarian, ``scipy.optimize.linear_sum_assignment``) on the mean
  distance over the frames both have; a pair with no common frame, or a mean distance above ``gate``, is gated
  out before the assignment (so it never displaces a pair within the gate) and is never associated;
* detected (per target): an associated track exists and its position at its detection frame lies within
  ``gate`` px (TRACK_GATE = 5 px, the paper's "initialised within the accuracy of 5 pixels") of the target then;
  P_TD counts run × target (the paper's values are multiples of 1/300: 100 runs × 3 targets);
* detection frame: the track's confirmation frame when given (``confirmed``: {track_id: frame}), else its first
  frame; start frame: its first frame (the start after the backward recursion); halt frame: its last frame +
  ``halt_drops`` (the frame of the second consecutive drop; it may lie past the sequence's last frame);
* false tracks: :func:`tbd_taichi.metrics.false_tracks` with the same gate — tracks whose points mostly lie
  farther than the gate from every target in view, i.e. tracks of no target.  A track left out of the one-to-one
  association only because another track of the same target was preferred (a re-acquired fragment, a
  duplicate) is not false; those are counted apart as ``unassociated_tracks``.
"""
from __future__ import annotations

import numpy as np

from .metrics import false_tracks

TRACK_GATE = 5.0  # px: §5.3's initialisation accuracy, and the OSPA cut-off c used with these measures


def paper_frame(frame):
    """The paper's 1-based frame number of a 0-based frame (or of an array or mean of them): ``frame + 1``."""
    return frame + 1


def _rows_per_frame(table: np.ndarray, n_frames: int) -> np.ndarray:
    """Number of rows of ``table`` in each frame 0..n_frames−1 (rows outside that range are left out)."""
    frames = table["frame"].astype(int)
    frames = frames[(frames >= 0) & (frames < n_frames)]
    return np.bincount(frames, minlength=n_frames)


def cardinality_error(tracks: np.ndarray, truth: np.ndarray, n_frames: int) -> float:
    """Mean over frames 0..n_frames−1 of |number of track rows − number of truth rows| in the frame (targets per
    frame; 0 for an empty sequence)."""
    if n_frames <= 0:
        return 0.0
    return float(np.mean(np.abs(_rows_per_frame(tracks, n_frames) - _rows_per_frame(truth, n_frames))))


def _mean_distances(tracks: np.ndarray, truth: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(track ids, target ids, matrix of the mean track–target distance over their common frames, px; inf where
    they have none)."""
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
    """{target_id: track_id}: among the one-to-one assignments with the most pairs of mean distance ≤ ``gate``
    px, the one of least total mean distance; only those pairs are returned."""
    from scipy.optimize import linear_sum_assignment  # imported here: 0.4 s the CLI's early errors don't pay

    if not len(tracks) or not len(truth):
        return {}
    track_ids, target_ids, dist = _mean_distances(tracks, truth)
    allowed = np.isfinite(dist) & (dist <= gate)
    # a gated-out pair costs more than any full set of allowed pairs, so the assignment first maximises the
    # number of allowed pairs and only then minimises their total distance
    big = 1.0 + min(dist.shape) * float(dist[allowed].max(initial=0.0))
    rows, cols = linear_sum_assignment(np.where(allowed, dist, big))
    return {int(target_ids[c]): int(track_ids[r]) for r, c in zip(rows, cols) if allowed[r, c]}


def _target_entry(gt: np.ndarray, tr: np.ndarray | None, gate: float, halt_drops: int,
                  confirmed: dict[int, int]) -> dict:
    """One target's row of :func:`track_detection`: its truth rows ``gt`` and its associated track's rows ``tr``
    (None: no track)."""
    entry = dict(first=int(gt["frame"].min()), last=int(gt["frame"].max()), detected=False,
                 detection_frame=None, start_frame=None, halt_frame=None)
    if tr is None:
        return entry
    start = int(tr["frame"].min())
    at = confirmed.get(int(tr["track_id"][0]), start)
    row, ref = tr[tr["frame"] == at], gt[gt["frame"] == at]
    near = bool(len(row) and len(ref) and np.hypot(row["x"][0] - ref["x"][0], row["y"][0] - ref["y"][0]) <= gate)
    entry.update(detected=near, detection_frame=at, start_frame=start, halt_frame=int(tr["frame"].max()) + halt_drops)
    return entry


def track_detection(tracks: np.ndarray, truth: np.ndarray, n_frames: int, gate: float = TRACK_GATE,
                    halt_drops: int = 2, confirmed: dict | None = None) -> dict:
    """One run's measures against point truth (gate in px, frames 0-based).

    ``targets``: {target_id: {first, last (the truth's first and last frames), detected, detection_frame,
    start_frame, halt_frame (None without an associated track)}}; overall ``n_targets``, ``detected``, ``p_td``
    (detected / n_targets, a fraction), ``false_tracks`` (see the module), ``unassociated_tracks`` (tracks in no
    pair of the association), ``correct_number`` (every target associated and no false track) and
    ``cardinality_error`` (:func:`cardinality_error`)."""
    pairs = associate_tracks(tracks, truth, gate)
    confirmed = {int(k): int(v) for k, v in (confirmed or {}).items()}
    per = {}
    for gid in np.unique(truth["target_id"]):
        tid = pairs.get(int(gid))
        tr = None if tid is None else tracks[tracks["track_id"] == tid]
        per[int(gid)] = _target_entry(truth[truth["target_id"] == gid], tr, gate, halt_drops, confirmed)
    n_false = false_tracks(tracks, truth, gate) if len(tracks) else 0
    detected = int(sum(e["detected"] for e in per.values()))
    return dict(targets=per, n_targets=len(per), detected=detected, p_td=detected / len(per) if per else float("nan"),
                false_tracks=n_false, unassociated_tracks=len(np.unique(tracks["track_id"])) - len(pairs),
                correct_number=len(pairs) == len(per) and n_false == 0,
                cardinality_error=cardinality_error(tracks, truth, n_frames))


def pool_runs(results: list[dict]) -> dict:
    """Monte Carlo summary of :func:`track_detection` results, as Tables 2–4: ``runs``; ``n_targets`` and
    ``detected`` summed over run × target; ``p_td`` = 100 · Σ detected / Σ n_targets (%); ``false_tracks`` summed
    over runs; the mean ``detection_frame``, ``start_frame`` and ``halt_frame`` per target id over the runs that
    detected it (0-based; NaN: none did); the mean ``cardinality_error`` over runs."""
    targets = sorted({t for r in results for t in r["targets"]})
    n = sum(r["n_targets"] for r in results)
    detected = sum(r["detected"] for r in results)

    def mean_of(key, t):
        v = [r["targets"][t][key] for r in results if t in r["targets"] and r["targets"][t]["detected"]]
        return float(np.mean(v)) if v else float("nan")

    return dict(runs=len(results), n_targets=n, detected=detected,
                p_td=100.0 * detected / n if n else float("nan"),
                false_tracks=int(sum(r["false_tracks"] for r in results)),
                detection_frame={t: mean_of("detection_frame", t) for t in targets},
                start_frame={t: mean_of("start_frame", t) for t in targets},
                halt_frame={t: mean_of("halt_frame", t) for t in targets},
                cardinality_error=float(np.mean([r["cardinality_error"] for r in results])) if results else 0.0)
