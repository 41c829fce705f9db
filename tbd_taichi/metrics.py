"""Tracking metrics (SGDS-PF Eqs. 47–49) and OSPA.

Inputs are the tables of :mod:`tbd_taichi.tables` (tracks and truth), in pixels.

* EDT (Eq. 47): Euclidean distance between estimate and truth, px.  Where several
  confirmed tracks exist in a frame, a target is scored against the nearest one.
* DSR (Eq. 48): the fraction of a target's in-view frames with EDT < T0
  (T0 = 2 px); a frame without any estimate is a miss.
* TSR (Eq. 49): the fraction of runs whose DSR is > T1 (T1 = 0.2), as in the
  formula (the text's "not less than" is read as the formula's strict >).
* False tracks: confirmed tracks whose points mostly (more than half) lie farther
  than the gate from every target in view in that frame.
* OSPA (Schuhmacher et al. 2008) per frame, with cut-off c (px) and order p,
  averaged over frames 0..n_frames−1 (0 where both sets are empty).
"""
from __future__ import annotations

from itertools import permutations

import numpy as np
from scipy.optimize import linear_sum_assignment

T0 = 2.0  # px, Eq. 48
T1 = 0.2  # Eq. 49
OSPA_C = 5.0  # px
OSPA_P = 2.0


def edt(est_x, est_y, true_x, true_y) -> np.ndarray:
    """Eq. 47: √((x̂ − x)² + (ŷ − y)²), px."""
    return np.hypot(np.asarray(est_x, float) - true_x, np.asarray(est_y, float) - true_y)


def _points_by_frame(table: np.ndarray) -> dict[int, np.ndarray]:
    """{frame: (n, 2) array of x, y}."""
    out: dict[int, list] = {}
    for f, x, y in zip(table["frame"], table["x"], table["y"]):
        out.setdefault(int(f), []).append((x, y))
    return {f: np.asarray(p, float) for f, p in out.items()}


def nearest_edt(tracks: np.ndarray, truth_rows: np.ndarray) -> np.ndarray:
    """EDT of each truth row to the nearest track point in its frame (NaN where there is none)."""
    by_frame = _points_by_frame(tracks)
    out = np.full(len(truth_rows), np.nan)
    for k, row in enumerate(truth_rows):
        pts = by_frame.get(int(row["frame"]))
        if pts is not None:
            out[k] = edt(pts[:, 0], pts[:, 1], row["x"], row["y"]).min()
    return out


def target_scores(tracks: np.ndarray, truth: np.ndarray, t0: float = T0) -> dict[int, dict]:
    """Per target id: DSR (Eq. 48), mean EDT over frames with an estimate, frames in view."""
    scores = {}
    for target in np.unique(truth["target_id"]):
        rows = truth[truth["target_id"] == target]
        d = nearest_edt(tracks, rows)
        hit = np.nan_to_num(d, nan=np.inf) < t0
        scores[int(target)] = {"dsr": float(hit.mean()) if len(rows) else 0.0,
                               "edt_mean": float(np.nanmean(d)) if np.isfinite(d).any() else float("nan"),
                               "frames": int(len(rows))}
    return scores


def dsr(tracks: np.ndarray, truth: np.ndarray, t0: float = T0) -> float:
    """Eq. 48 averaged over the targets of ``truth``."""
    scores = target_scores(tracks, truth, t0)
    return float(np.mean([s["dsr"] for s in scores.values()])) if scores else float("nan")


def tsr(dsr_values, t1: float = T1) -> float:
    """Eq. 49: fraction of runs with DSR > T1 (multiply by 100 for the paper's %)."""
    values = np.asarray(list(dsr_values), float)
    return float((values > t1).mean()) if values.size else float("nan")


def false_tracks(tracks: np.ndarray, truth: np.ndarray, gate: float = T0) -> int:
    """Number of track ids whose points mostly match no target (distance ≥ gate)."""
    truth_by_frame = _points_by_frame(truth)
    count = 0
    for track in np.unique(tracks["track_id"]):
        rows = tracks[tracks["track_id"] == track]
        matched = 0
        for row in rows:
            pts = truth_by_frame.get(int(row["frame"]))
            if pts is not None and edt(pts[:, 0], pts[:, 1], row["x"], row["y"]).min() < gate:
                matched += 1
        count += matched * 2 < len(rows)
    return count


def ospa(estimates, truths, c: float = OSPA_C, p: float = OSPA_P) -> float:
    """OSPA distance between two point sets (n, 2) and (m, 2), cut-off c px, order p."""
    a = np.asarray(estimates, float).reshape(-1, 2)
    b = np.asarray(truths, float).reshape(-1, 2)
    if len(a) > len(b):
        a, b = b, a
    m, n = len(a), len(b)
    if n == 0:
        return 0.0
    if m == 0:
        return float(c)
    cost = np.minimum(np.hypot(a[:, None, 0] - b[None, :, 0], a[:, None, 1] - b[None, :, 1]), c) ** p
    rows, cols = linear_sum_assignment(cost)
    return float(((cost[rows, cols].sum() + c ** p * (n - m)) / n) ** (1.0 / p))


def ospa_brute_force(estimates, truths, c: float = OSPA_C, p: float = OSPA_P) -> float:
    """OSPA by enumerating every assignment (small sets only; the reference for tests)."""
    a = np.asarray(estimates, float).reshape(-1, 2)
    b = np.asarray(truths, float).reshape(-1, 2)
    if len(a) > len(b):
        a, b = b, a
    m, n = len(a), len(b)
    if n == 0:
        return 0.0
    best = min(sum(min(float(np.hypot(*(a[i] - b[j]))), c) ** p for i, j in enumerate(perm))
               for perm in permutations(range(n), m))
    return float(((best + c ** p * (n - m)) / n) ** (1.0 / p))


def mean_ospa(tracks: np.ndarray, truth: np.ndarray, c: float = OSPA_C, p: float = OSPA_P,
              n_frames: int | None = None) -> float:
    """OSPA averaged over frames 0..n_frames−1 (default: up to the last frame of either table)."""
    est, tru = _points_by_frame(tracks), _points_by_frame(truth)
    if n_frames is None:
        n_frames = max(list(est) + list(tru), default=-1) + 1
    if n_frames == 0:
        return 0.0
    empty = np.zeros((0, 2))
    return float(np.mean([ospa(est.get(f, empty), tru.get(f, empty), c, p) for f in range(n_frames)]))


def evaluate(tracks: np.ndarray, truth: np.ndarray, t0: float = T0, ospa_c: float = OSPA_C,
             ospa_p: float = OSPA_P, n_frames: int | None = None) -> dict:
    """All metrics for one run: dsr, edt_mean, false_tracks, ospa, and per-target scores."""
    scores = target_scores(tracks, truth, t0)
    edts = [s["edt_mean"] for s in scores.values() if np.isfinite(s["edt_mean"])]
    return {
        "dsr": float(np.mean([s["dsr"] for s in scores.values()])) if scores else float("nan"),
        "edt_mean": float(np.mean(edts)) if edts else float("nan"),
        "false_tracks": false_tracks(tracks, truth, t0),
        "ospa": mean_ospa(tracks, truth, ospa_c, ospa_p, n_frames),
        "tracks": int(len(np.unique(tracks["track_id"]))),
        "targets": {str(k): v for k, v in scores.items()},
    }


def box_scores(tracks: np.ndarray, boxes: np.ndarray, n_frames: int, grow: float = 2.0) -> dict:
    """Real-data scores against labelled boxes (frame,x,y,w,h), each box grown by ``grow`` px:

    * ``detection_rate``: fraction of labelled frames with a track point inside the grown box;
    * ``false_points``: track points outside every grown box, per frame of the sequence;
    * ``first_confirmation``: frames from the first labelled frame to the first hit (NaN: none).
    """
    box = {int(b["frame"]): (b["x"] - grow, b["x"] + b["w"] + grow, b["y"] - grow, b["y"] + b["h"] + grow)
           for b in boxes}
    hits, false = set(), 0
    for f, x, y in zip(tracks["frame"].tolist(), tracks["x"].tolist(), tracks["y"].tolist()):
        b = box.get(int(f))
        if b is not None and b[0] <= x <= b[1] and b[2] <= y <= b[3]:
            hits.add(int(f))
        else:
            false += 1
    first = min(box) if box else 0
    return dict(detection_rate=len(hits) / len(box) if box else float("nan"),
                false_points=false / max(n_frames, 1),
                first_confirmation=float(min(hits) - first) if hits else float("nan"))
