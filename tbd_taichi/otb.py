"""OTB measures of a box tracker against labelled boxes (Wu, Lim & Yang 2013, "Online Object Tracking: A
Benchmark"), as Huo et al. 2022 report them: centre pixel error, distance accuracy at 20 px, overlap rate.

Inputs: a box tracker's tracks (``frame,x,y,w,h`` with x, y the box *centre*, x = column, y = row, 0-based, pixel
centres at integers; ``confidence`` if it has one) and box truth as :func:`~tbd_taichi.tables.read_boxes` gives
it (``frame,x,y,w,h[,target_id]`` with x, y the *top-left corner*, so the truth centre is x + w/2, y + h/2).

The protocol is single-target, one-pass: the tracker is started from the box of the first labelled frame, which
is therefore not scored; every later frame with a truth box is.  Per scored frame the tracker's box is the frame's
track row of highest ``confidence``, and

* CLE, the centre location error: the distance (px) between the two box centres;
* IoU: :func:`~tbd_taichi.metrics.box_iou` of the truth box and the track's box.

A frame with a truth box but no track row is a *miss*: IoU 0 and CLE = :data:`CLE_CAP` (100 px; the OTB toolkit
leaves a lost target's error to whatever the tracker reported, so a tracker that reports nothing needs a stated
value: 100 px is past every threshold of the precision plot, so a miss never counts as precise, and it keeps the
mean CLE finite).  Frames without a truth box are not scored, whatever the tracker reports there.

* ``dp_curve`` (precision plot): the fraction of scored frames with CLE ≤ t, t = 0, 1, …, 50 px (51 values);
  ``dp20`` and ``dp5`` are its values at 20 px (OTB's representative precision, the paper's "distance accuracy")
  and 5 px;
* ``success_curve`` (success plot): the fraction of scored frames with IoU > t, t = 0, 0.05, …, 1.0 (21 values);
  ``auc`` is its mean.  IoU > 1 is impossible, so the last value is always 0 and a perfect tracker's AUC is
  20/21 ≈ 0.952, not 1;
* ``cle``: mean CLE, px (the paper's "center pixel error"); ``mean_iou``: mean IoU (its "overlap rate").

Comparisons allow :data:`EPS` for the rounding of the centre arithmetic (a track exactly on the truth has CLE 0
to within it).
"""
from __future__ import annotations

import numpy as np

from .errors import ParameterError
from .metrics import as_table, box_iou
from .tables import BOX_SIZE_COLUMNS  # a tracks table with these (w, h) is a box tracker's

CLE_CAP = 100.0  # px: the centre error of a frame with a truth box and no track row (a miss)
DP_THRESHOLDS = np.arange(51.0)  # px: the precision plot's thresholds 0, 1, …, 50
SUCCESS_THRESHOLDS = np.arange(21) / 20.0  # the success plot's overlap thresholds 0, 0.05, …, 1.0
EPS = 1e-9  # slack of the threshold comparisons (CLE px, IoU)


def has_box_size(tracks) -> bool:
    """Whether a tracks table (structured array or dict of columns) carries the box size columns w and h."""
    names = getattr(getattr(tracks, "dtype", None), "names", None)
    keys = names if names is not None else (tuple(tracks) if isinstance(tracks, dict) else ())
    return set(BOX_SIZE_COLUMNS) <= set(keys)


def _one_per_frame(tracks: np.ndarray) -> dict[int, np.void]:
    """{frame: the frame's track row of highest confidence (ties: the first in the table's order)}."""
    if not len(tracks):
        return {}
    conf = tracks["confidence"] if "confidence" in tracks.dtype.names else np.zeros(len(tracks))
    order = np.lexsort((-conf, tracks["frame"]))  # stable: by frame, then by falling confidence
    frames = tracks["frame"][order]
    _, first = np.unique(frames, return_index=True)
    return {int(frames[i]): tracks[order[i]] for i in first}


def _pick_target(boxes: np.ndarray, target_id) -> np.ndarray:
    """The boxes of one target: ``target_id``, or by default the lowest id labelled in the first labelled frame."""
    if "target_id" not in boxes.dtype.names:
        if target_id is not None:
            raise ParameterError(f"target_id={target_id!r} given but the boxes have no target_id column")
        return boxes
    ids = boxes["target_id"]
    if target_id is None:
        if not len(boxes):
            return boxes
        target_id = int(ids[boxes["frame"] == boxes["frame"].min()].min())
    elif isinstance(target_id, bool) or not isinstance(target_id, (int, np.integer)) or target_id not in ids:
        have = ",".join(str(int(t)) for t in np.unique(ids)) or "none"
        raise ParameterError(f"target_id must be one of the boxes' target ids ({have}), got {target_id!r}")
    return boxes[ids == target_id]


def _nan_scores() -> dict:
    nan = float("nan")
    return dict(cle=nan, dp20=nan, dp5=nan, mean_iou=nan, auc=nan, dp_curve=[nan] * len(DP_THRESHOLDS),
                success_curve=[nan] * len(SUCCESS_THRESHOLDS))


def otb_scores(tracks, boxes, first_frame: int | None = None, *, target_id: int | None = None) -> dict:
    """OTB measures (module doc) of a box tracker's ``tracks`` (columns frame,x,y,w,h, x, y the centre, and
    optionally confidence) against ``boxes`` (frame,x,y,w,h[,target_id], x, y the top-left corner), over the
    labelled frames after ``first_frame`` (default: the first labelled frame, the tracker's init box).  With
    several targets in ``boxes`` one is scored: ``target_id``, by default the lowest id of the first labelled frame.

    Returns ``cle``, ``dp20``, ``dp5``, ``dp_curve`` (51), ``mean_iou``, ``success_curve`` (21), ``auc`` (NaN, and
    curves of NaN, when no frame is scored), ``scored_frames``, ``missed_frames``, ``cle_cap``, ``first_frame``
    (the excluded frame; None without boxes) and ``target_id`` (None when the boxes have no ids)."""
    from .validate import whole

    tracks = as_table(tracks, ("frame", "x", "y", "w", "h"), "tracks", ("confidence",))
    boxes = _pick_target(as_table(boxes, ("frame", "x", "y", "w", "h"), "boxes", ("target_id",)), target_id)
    if first_frame is not None:
        first_frame = whole("first_frame", first_frame, 0)
    elif len(boxes):
        first_frame = int(boxes["frame"].min())
    target = int(boxes["target_id"][0]) if len(boxes) and "target_id" in boxes.dtype.names else None
    truth: dict[int, np.void] = {}
    for b in boxes:  # one box per frame: the first row of the frame
        if first_frame is None or b["frame"] > first_frame:
            truth.setdefault(int(b["frame"]), b)
    best = _one_per_frame(tracks)
    cle, iou, missed = [], [], 0
    for f, b in sorted(truth.items()):
        t = best.get(f)
        if t is None:
            missed += 1
            cle.append(CLE_CAP)
            iou.append(0.0)
        else:
            cle.append(float(np.hypot(t["x"] - (b["x"] + b["w"] / 2), t["y"] - (b["y"] + b["h"] / 2))))
            iou.append(box_iou(b, t))
    out = dict(scored_frames=len(cle), missed_frames=missed, cle_cap=CLE_CAP, first_frame=first_frame,
               target_id=target)
    if not cle:
        return {**_nan_scores(), **out}
    cle_a, iou_a = np.asarray(cle), np.asarray(iou)
    dp = [float(np.mean(cle_a <= t + EPS)) for t in DP_THRESHOLDS]
    success = [float(np.mean(iou_a > t + EPS)) for t in SUCCESS_THRESHOLDS]
    return dict(cle=float(cle_a.mean()), dp20=dp[20], dp5=dp[5], mean_iou=float(iou_a.mean()),
                auc=float(np.mean(success)), dp_curve=dp, success_curve=success, **out)


def format_otb(scores: dict) -> list[str]:
    """The OTB lines that ``evaluate`` and ``track --truth`` print for a box tracker."""
    def num(v, fmt):
        return "n/a" if v != v else format(v, fmt)

    first = "-" if scores["first_frame"] is None else scores["first_frame"]
    rows = [("OTB frames", f"{scores['scored_frames']} scored after frame {first}, {scores['missed_frames']} missed "
                           f"(a miss: IoU 0, CLE {scores['cle_cap']:g} px)"),
            ("CLE, centre error (px)", num(scores["cle"], ".2f")),
            ("DP@20 / DP@5", f"{num(scores['dp20'], '.3f')} / {num(scores['dp5'], '.3f')}"),
            ("mean IoU (overlap rate)", num(scores["mean_iou"], ".3f")),
            ("AUC (success plot)", num(scores["auc"], ".3f"))]
    return [f"{label:<27}{value}" for label, value in rows]

__all__ = ["BOX_SIZE_COLUMNS", "CLE_CAP", "DP_THRESHOLDS", "EPS", "SUCCESS_THRESHOLDS", "format_otb", "has_box_size",
           "otb_scores"]
