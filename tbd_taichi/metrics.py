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
* Güler 2016's MSE (Eq. 4.1b: mean over frames of the squared Euclidean error, px²) and max error (px) of the
  track matched to a target (:func:`thesis_errors`).
* Against labelled boxes: :func:`box_scores`; for a box tracker also the OTB measures (CLE, DP@20, mean IoU,
  AUC) of :mod:`tbd_taichi.otb`.
"""
from __future__ import annotations

from itertools import permutations

import numpy as np

from .errors import ParameterError

T0 = 2.0  # px, Eq. 48
T1 = 0.2  # Eq. 49
MATCH_GATE = 5.0  # px: thesis_errors's track matched to a target
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


def _ospa_sets(estimates, truths) -> tuple[np.ndarray, np.ndarray]:
    """The two point sets as (k, 2) float arrays, the smaller first (OSPA is symmetric)."""
    a = np.asarray(estimates, float).reshape(-1, 2)
    b = np.asarray(truths, float).reshape(-1, 2)
    return (b, a) if len(a) > len(b) else (a, b)


def ospa(estimates, truths, c: float = OSPA_C, p: float = OSPA_P) -> float:
    """OSPA distance between two point sets (n, 2) and (m, 2), cut-off c px, order p."""
    a, b = _ospa_sets(estimates, truths)
    m, n = len(a), len(b)
    if n == 0:
        return 0.0
    if m == 0:
        return float(c)
    cost = np.minimum(np.hypot(a[:, None, 0] - b[None, :, 0], a[:, None, 1] - b[None, :, 1]), c) ** p
    from scipy.optimize import linear_sum_assignment  # imported here: 0.4 s the CLI's early errors don't pay

    rows, cols = linear_sum_assignment(cost)
    return float(((cost[rows, cols].sum() + c ** p * (n - m)) / n) ** (1.0 / p))


def ospa_brute_force(estimates, truths, c: float = OSPA_C, p: float = OSPA_P) -> float:
    """OSPA by enumerating every assignment (small sets only; the reference for tests)."""
    a, b = _ospa_sets(estimates, truths)
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
    empty = np.zeros((0, 2))  # a frame with neither set scores 0: only the frames with rows need the sum
    seen = sorted(f for f in set(est) | set(tru) if 0 <= f < n_frames)
    return float(sum(ospa(est.get(f, empty), tru.get(f, empty), c, p) for f in seen) / n_frames)


def thesis_errors(tracks: np.ndarray, truth: np.ndarray, gate: float = MATCH_GATE) -> dict:
    """Güler 2016's errors of the track matched to the target of ``truth`` (one target: one row per frame):
    the track id with the most rows within ``gate`` px of the truth of their frame (a tie: the lower id), over
    the frames where both have a row: ``mse`` = mean squared Euclidean error (Eq. 4.1b, px²), ``max_error`` =
    the largest Euclidean error (px), ``frames`` = their count, ``track_id``.  No track within the gate in any
    frame: NaNs, 0 frames, track_id None."""
    where = {int(f): (x, y) for f, x, y in zip(truth["frame"], truth["x"], truth["y"])}
    best = dict(mse=float("nan"), max_error=float("nan"), frames=0, track_id=None)
    most = 0
    for track in np.unique(tracks["track_id"]):
        rows = tracks[(tracks["track_id"] == track) & np.isin(tracks["frame"], list(where))]
        if not len(rows):
            continue
        true_xy = np.array([where[int(f)] for f in rows["frame"]], float)
        d = edt(rows["x"], rows["y"], true_xy[:, 0], true_xy[:, 1])
        near = int((d <= gate).sum())
        if near > most:
            most = near
            best = dict(mse=float(np.mean(d ** 2)), max_error=float(d.max()), frames=int(len(d)),
                        track_id=int(track))
    return best


def as_table(obj, columns: tuple[str, ...], name: str, optional: tuple[str, ...] = ()) -> np.ndarray:
    """``obj`` as a structured table with ``columns``: a structured array (or a dict of columns) that has them, or
    rows (a list of tuples, a 2-D array) in the order ``columns`` + ``optional``; else a ParameterError naming
    what ``name`` needs."""
    from .tables import _dtype, make_table

    need = f"{name} needs a table with columns {','.join(columns)} (a tbd_taichi.tables table, a dict of columns " \
           f"or rows in that order)"
    names = getattr(getattr(obj, "dtype", None), "names", None)
    try:
        if names is not None or isinstance(obj, dict):
            keys = names if names is not None else tuple(obj)
            missing = [c for c in columns if c not in keys]
            if missing:
                raise ParameterError(f"{need}; it lacks {','.join(missing)}")
            cols = columns + tuple(c for c in optional if c in keys)
            n = len(np.asarray(obj[columns[0]]))
            return make_table(zip(*[np.broadcast_to(np.asarray(obj[c], float), n) for c in cols]), _dtype(cols))
        rows = np.asarray(obj, dtype=float)
    except ParameterError:  # the columns it lacks (a ValueError too: not to be replaced by the plain message)
        raise
    except (TypeError, ValueError):
        raise ParameterError(need) from None
    if rows.size == 0:
        return np.zeros(0, _dtype(columns))
    if rows.ndim != 2 or rows.shape[1] not in range(len(columns), len(columns) + len(optional) + 1):
        raise ParameterError(f"{need}; got shape {rows.shape}")
    if not np.isfinite(rows).all():
        raise ParameterError(f"{name} holds NaN or infinite values")
    cols = (columns + optional)[: rows.shape[1]]
    return make_table(map(tuple, rows), _dtype(cols))


def evaluate(tracks, truth, t0: float = T0, ospa_c: float = OSPA_C,
             ospa_p: float = OSPA_P, n_frames: int | None = None) -> dict:
    """All metrics for one run: dsr, edt_mean, false_tracks, ospa, mse and max_error (:func:`thesis_errors`: the
    mean MSE and the largest max error over the targets with a matched track), and per-target scores.  ``tracks``, ``truth``:
    tables (or array-likes, :func:`as_table`); T0 ≥ 0, OSPA c > 0 and p ≥ 1 (px)."""
    from .validate import positive

    tracks = as_table(tracks, ("frame", "track_id", "x", "y"), "tracks")
    truth = as_table(truth, ("frame", "target_id", "x", "y"), "truth")
    positive("t0", t0, 0.0, closed=True)
    positive("ospa_c", ospa_c)
    positive("ospa_p", ospa_p, 1.0, closed=True)
    scores = target_scores(tracks, truth, t0)
    for target, s in scores.items():
        e = thesis_errors(tracks, truth[truth["target_id"] == target])
        s.update(mse=e["mse"], max_error=e["max_error"], matched_track=e["track_id"])
    matched = [s for s in scores.values() if s["matched_track"] is not None]
    edts = [s["edt_mean"] for s in scores.values() if np.isfinite(s["edt_mean"])]
    return {
        "dsr": float(np.mean([s["dsr"] for s in scores.values()])) if scores else float("nan"),
        "edt_mean": float(np.mean(edts)) if edts else float("nan"),
        "false_tracks": false_tracks(tracks, truth, t0),
        "ospa": mean_ospa(tracks, truth, ospa_c, ospa_p, n_frames),
        "mse": float(np.mean([s["mse"] for s in matched])) if matched else float("nan"),
        "max_error": float(max(s["max_error"] for s in matched)) if matched else float("nan"),
        "tracks": int(len(np.unique(tracks["track_id"]))),
        "targets": {str(k): v for k, v in scores.items()},
    }


BOX_MARGIN = 2.0  # px: a box grows by this on every side before a track point is tested against it


def box_scores(tracks, boxes, n_frames: int, grow: float = BOX_MARGIN) -> dict:
    """Scores against labelled boxes (frame,x,y,w,h[,target_id]), each box grown by ``grow`` px on every side:

    * ``detection_rate``: fraction of labelled boxes (frame, target) with a track point inside the grown box;
    * ``false_points``: track points outside every grown box of their frame, per frame of the sequence;
    * ``first_confirmation``: frames from the first labelled frame to the first hit (NaN: none);
    * ``centre_error``: mean distance (px) from each hit box's centre to the nearest track point inside it;
    * ``iou``: mean intersection over union of each hit box and the track's box, for tracks with w and h
      (box trackers; NaN for point trackers).
    """
    from .validate import positive

    tracks = as_table(tracks, ("frame", "track_id", "x", "y"), "tracks", ("w", "h"))
    boxes = as_table(boxes, ("frame", "x", "y", "w", "h"), "boxes", ("target_id",))
    positive("grow", grow, 0.0, closed=True)
    has_size = "w" in (tracks.dtype.names or ()) and len(tracks)
    by_frame: dict[int, list] = {}
    for b in boxes:
        by_frame.setdefault(int(b["frame"]), []).append(b)
    hits, false, centre, overlap, hit_frames = set(), 0, [], [], []
    for t in tracks:
        inside = [k for k, b in enumerate(by_frame.get(int(t["frame"]), ()))
                  if b["x"] - grow <= t["x"] <= b["x"] + b["w"] + grow and b["y"] - grow <= t["y"] <= b["y"] + b["h"] + grow]
        if not inside:
            false += 1
        for k in inside:
            hits.add((int(t["frame"]), k))
    for f, k in sorted(hits):
        b = by_frame[f][k]
        pts = tracks[tracks["frame"] == f]
        d = np.hypot(pts["x"] - (b["x"] + b["w"] / 2), pts["y"] - (b["y"] + b["h"] / 2))
        j = int(np.argmin(d))
        centre.append(float(d[j]))
        hit_frames.append(f)
        if has_size:
            overlap.append(box_iou(b, pts[j]))
    first = min(by_frame) if by_frame else 0
    return dict(detection_rate=len(hits) / len(boxes) if len(boxes) else float("nan"),
                false_points=false / max(n_frames, 1),
                first_confirmation=float(min(hit_frames) - first) if hit_frames else float("nan"),
                centre_error=float(np.mean(centre)) if centre else float("nan"),
                iou=float(np.mean(overlap)) if overlap else float("nan"))


def box_iou(box, track) -> float:
    """Intersection over union of a labelled box (x, y corner, w, h) and a track's box (x, y centre, w, h)."""
    tx0, ty0 = track["x"] - track["w"] / 2, track["y"] - track["h"] / 2
    ix = max(0.0, min(box["x"] + box["w"], tx0 + track["w"]) - max(box["x"], tx0))
    iy = max(0.0, min(box["y"] + box["h"], ty0 + track["h"]) - max(box["y"], ty0))
    inter = ix * iy
    union = box["w"] * box["h"] + track["w"] * track["h"] - inter
    return float(inter / union) if union > 0 else 0.0


def truth_scores(kind: str, tracks: np.ndarray, truth: np.ndarray, n_frames: int | None = None, *,
                 box_margin: float = BOX_MARGIN, t0: float = T0, ospa_c: float = OSPA_C,
                 ospa_p: float = OSPA_P) -> dict:
    """The report against truth of ``kind`` (:func:`~tbd_taichi.tables.read_any_truth`), with its settings, over
    ``n_frames`` frames (default: the last frame in either table + 1): ``boxes``, :func:`box_scores` and, for tracks
    with w and h (box trackers), the OTB measures of :func:`tbd_taichi.otb.otb_scores`; ``points``,
    :func:`evaluate` and Long et al.'s track-detection measures (:mod:`~tbd_taichi.track_detection`, 5 px gate):
    ``cardinality_error`` (mean |tracks − targets| per frame), ``p_td`` (fraction of targets detected) and per
    target id the 0-based ``detection_frame`` and ``halt_frame`` of its track (None: not detected)."""
    frames = n_frames if n_frames is not None else \
        int(max(tracks["frame"].max(initial=-1), truth["frame"].max(initial=-1))) + 1
    if kind == "boxes":
        scores = dict(truth="boxes", box_margin=box_margin, **box_scores(tracks, truth, frames, grow=box_margin))
        from .otb import has_box_size, otb_scores

        if has_box_size(tracks):
            scores.update(otb_scores(tracks, truth))
        return scores
    from .track_detection import track_detection

    scores = evaluate(tracks, truth, t0=t0, ospa_c=ospa_c, ospa_p=ospa_p, n_frames=n_frames)
    long = track_detection(tracks, truth, frames)
    scores.update(truth="points", t0=t0, ospa_c=ospa_c, ospa_p=ospa_p, cardinality_error=long["cardinality_error"],
                  p_td=long["p_td"], detection_frame=_detected(long["targets"], "detection_frame"),
                  halt_frame=_detected(long["targets"], "halt_frame"))
    return scores


def _detected(targets: dict, key: str) -> dict:
    """{target id as text: ``key`` of a :func:`~tbd_taichi.track_detection.track_detection` target entry, or None
    where the target was not detected}."""
    return {str(t): e[key] if e["detected"] else None for t, e in targets.items()}
