"""Pictures of tracks: a PNG over the max-projection, an overlay video and an overlay GIF.

Coordinates as everywhere: x = column, y = row, 0-based, pixel centres at integers.
"""
from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from .errors import InputError

TRAIL = 30  # frames of trail drawn behind each track in the video
BOX = 6  # half-size of the box around a track, px
TRUTH_BGR = (0, 200, 0)  # truth is drawn in green
LEGEND_TRACKS = 8  # the plot's legend names the longest tracks only; every track's id is written beside its trail


def track_colour(track_id: int) -> tuple[int, int, int]:
    """A stable, distinct BGR colour per track id."""
    hue = (int(track_id) * 47) % 180
    bgr = cv2.cvtColor(np.uint8([[[hue, 220, 255]]]), cv2.COLOR_HSV2BGR)[0, 0]
    return int(bgr[0]), int(bgr[1]), int(bgr[2])


def stretched(frame: np.ndarray) -> np.ndarray:
    """A float frame as 8-bit BGR for the overlays, stretched from its 1st to its 99.9th percentile."""
    lo, hi = np.percentile(frame, (1, 99.9))
    return to_display(frame, lo, hi)


def to_display(frame: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """A float frame as 8-bit BGR, stretched from [lo, hi]."""
    grey = np.clip((frame - lo) * (255.0 / max(hi - lo, 1e-9)), 0, 255).astype(np.uint8)
    return cv2.cvtColor(grey, cv2.COLOR_GRAY2BGR)


def plot_tracks(max_projection: np.ndarray, tracks: np.ndarray, path, truth: np.ndarray | None = None,
                title: str = "") -> None:
    """Picture (PNG, PDF or SVG by ``path``'s suffix): tracks (one colour each, the id beside each trail's end)
    over the sequence's max-projection, truth in green; the legend lists the :data:`LEGEND_TRACKS` longest."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(7, 7 * max_projection.shape[0] / max(max_projection.shape[1], 1) + 0.5))
    ax.imshow(max_projection, cmap="gray", interpolation="nearest")
    if truth is not None and len(truth):
        for tid in np.unique(truth["target_id"]):
            t = truth[truth["target_id"] == tid]
            ax.plot(t["x"], t["y"], "-", color="lime", lw=2, alpha=0.6, label="truth" if tid == truth["target_id"][0] else None)
    ids, lengths = np.unique(tracks["track_id"], return_counts=True)
    in_legend = set(ids[np.argsort(-lengths, kind="stable")[:LEGEND_TRACKS]].tolist())
    for tid in ids:
        t = tracks[tracks["track_id"] == tid]
        b, g, r = track_colour(tid)
        label = f"track {tid} ({len(t)} frames)" if tid in in_legend else None
        ax.plot(t["x"], t["y"], ".-", color=(r / 255, g / 255, b / 255), ms=3, lw=1, label=label)
        ax.annotate(str(tid), (t["x"][-1], t["y"][-1]), xytext=(4, 4), textcoords="offset points",
                    color=(r / 255, g / 255, b / 255), fontsize=8)  # the id beside its trail's end
    if len(ids) > LEGEND_TRACKS:
        ax.plot([], [], " ", label=f"+ {len(ids) - LEGEND_TRACKS} shorter tracks (ids on the image)")
    ax.set_title(title or "tracks over the max-projection (x = column, y = row)")
    if len(tracks) or truth is not None:
        ax.legend(loc="lower right", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def plot_otb_curves(results: dict, path, title: str = "") -> None:
    """OTB precision plot (fraction of frames with centre error ≤ t, t = 0..50 px) beside the success plot
    (fraction with IoU > t, t = 0..1), one line per tracker, written to ``path`` (PNG, PDF or SVG by its suffix).
    ``results``: {label: scores with ``dp_curve`` and ``success_curve``, as :func:`tbd_taichi.otb.otb_scores`
    gives them}; the legends carry DP@20 and AUC, OTB's ranking values."""
    curves, path, plt = _checked_curves(results), _figure_path(path), _pyplot()
    fig, (pre, suc) = plt.subplots(1, 2, figsize=(11, 4.5))
    _otb_axes(pre, suc, curves, "precision plot (DP@20 in [])", "success plot (AUC in [])", 8)
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def plot_otb_per_sequence(per_sequence: dict, path, title: str = "", columns: int = 4) -> None:
    """Huo 2022's Fig. 7 per sequence: for each sequence its precision plot beside its success plot (as
    :func:`plot_otb_curves`), ``columns`` sequences a row.  ``per_sequence``: {sequence: {label: OTB scores}}."""
    from .errors import ParameterError
    from .validate import whole

    if not isinstance(per_sequence, dict) or not per_sequence:
        raise ParameterError("per_sequence must be a non-empty dict {sequence: {label: OTB scores}}")
    columns = whole("columns", columns, 1)
    checked = {name: _checked_curves(results) for name, results in per_sequence.items()}
    path, plt = _figure_path(path), _pyplot()
    rows = -(-len(checked) // columns)
    fig, axes = plt.subplots(rows, 2 * columns, figsize=(5.0 * columns, 2.8 * rows), squeeze=False)
    for i, (name, curves) in enumerate(checked.items()):
        pre, suc = axes[i // columns, 2 * (i % columns)], axes[i // columns, 2 * (i % columns) + 1]
        _otb_axes(pre, suc, curves, f"{name} (precision)", "(success)", 5)
        for ax in (pre, suc):
            ax.title.set_fontsize(8)
            ax.xaxis.label.set_fontsize(7)
            ax.yaxis.label.set_fontsize(7)
    for ax in axes.flat[2 * len(checked):]:
        ax.axis("off")
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=80)
    plt.close(fig)


def _pyplot():
    """matplotlib.pyplot on the Agg backend (files only, no display)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _figure_path(path):
    """``path`` checked as a PNG, PDF or SVG file to write."""
    from .validate import output_path

    return output_path("path", path, (".png", ".pdf", ".svg"))


def _checked_curves(results) -> dict:
    """{label: (dp_curve, success_curve)} of OTB scores, checked (a ParameterError names the first bad label)."""
    from .errors import ParameterError
    from .otb import DP_THRESHOLDS, SUCCESS_THRESHOLDS

    if not isinstance(results, dict) or not results:
        raise ParameterError("results must be a non-empty dict {label: OTB scores (tbd_taichi.otb.otb_scores)}")
    curves = {}
    for label, scores in results.items():
        try:
            dp, success = (np.asarray(scores[k], float) for k in ("dp_curve", "success_curve"))
        except (KeyError, TypeError, ValueError, IndexError):
            dp = success = None
        if dp is None or dp.shape != DP_THRESHOLDS.shape or success.shape != SUCCESS_THRESHOLDS.shape:
            raise ParameterError(f"results[{label!r}] needs dp_curve ({len(DP_THRESHOLDS)} values) and "
                                 f"success_curve ({len(SUCCESS_THRESHOLDS)} values), as otb_scores gives them")
        curves[str(label)] = (dp, success)
    return curves


def _otb_axes(pre, suc, curves: dict, pre_title: str, suc_title: str, fontsize: int) -> None:
    """One precision plot (``pre``) and one success plot (``suc``), legends with DP@20 and AUC."""
    from .otb import DP_THRESHOLDS, SUCCESS_THRESHOLDS

    for label, (dp, success) in curves.items():
        pre.plot(DP_THRESHOLDS, dp, lw=2, label=f"{label} [{dp[20]:.3f}]")
        suc.plot(SUCCESS_THRESHOLDS, success, lw=2, label=f"{label} [{success.mean():.3f}]")
    pre.set(xlabel="location error threshold (px)", ylabel="precision", title=pre_title,
            xlim=(0, DP_THRESHOLDS[-1]), ylim=(0, 1.02))
    suc.set(xlabel="overlap threshold", ylabel="success rate", title=suc_title, xlim=(0, 1), ylim=(0, 1.02))
    for ax in (pre, suc):
        ax.grid(alpha=0.3)
        ax.legend(loc="lower right" if ax is pre else "lower left", fontsize=fontsize)


def _rows_by_frame(table: np.ndarray | None) -> dict[int, np.ndarray]:
    """{frame: the rows of ``table`` in it} ({} for None)."""
    if table is None:
        return {}
    return {int(f): table[table["frame"] == f] for f in np.unique(table["frame"])}


def draw_overlay(img: np.ndarray, tracks: np.ndarray, rows: np.ndarray, f: int, truth=()) -> np.ndarray:
    """Draw on the BGR image ``img`` of frame ``f``: the ``truth`` rows in green (a box where they have w, h, with
    x, y its top-left corner; else a circle at the point x, y) and each track row in ``rows`` with its box (its
    w × h for box trackers, else a fixed marker), id and trail over the last :data:`TRAIL` frames of ``tracks``;
    returns ``img``."""
    for t in truth:
        x0, y0 = int(round(t["x"])), int(round(t["y"]))
        if "w" in t.dtype.names:
            cv2.rectangle(img, (x0, y0), (int(round(t["x"] + t["w"])), int(round(t["y"] + t["h"]))), TRUTH_BGR, 1)
        else:
            cv2.circle(img, (x0, y0), BOX + 2, TRUTH_BGR, 1)
    for row in rows:
        tid, colour = int(row["track_id"]), track_colour(row["track_id"])
        trail = tracks[(tracks["track_id"] == tid) & (tracks["frame"] <= f) & (tracks["frame"] > f - TRAIL)]
        pts = np.stack([trail["x"], trail["y"]], axis=1).round().astype(np.int32)
        cv2.polylines(img, [pts], False, colour, 1)
        x, y = int(round(row["x"])), int(round(row["y"]))
        bw, bh = (int(round(row["w"] / 2)), int(round(row["h"] / 2))) if "w" in tracks.dtype.names else (BOX, BOX)
        cv2.rectangle(img, (x - bw, y - bh), (x + bw, y + bh), colour, 1)
        cv2.putText(img, str(tid), (x + bw + 1, y - bh), cv2.FONT_HERSHEY_SIMPLEX, 0.35, colour, 1)
    return img


def write_overlay_video(frames, tracks: np.ndarray, path, fps: float = 15.0, truth: np.ndarray | None = None) -> int:
    """Video of ``frames`` (an iterable of float (H, W)) with each track's box, id and trail and the ``truth`` rows
    (boxes or points) in green (:func:`draw_overlay`); returns frames written."""
    path = Path(path)
    writer = None
    by_frame, truth_by_frame = _rows_by_frame(tracks), _rows_by_frame(truth)
    n = 0
    for f, frame in enumerate(frames):
        img = stretched(frame)
        if writer is None:
            fourcc = cv2.VideoWriter_fourcc(*("mp4v" if path.suffix.lower() == ".mp4" else "MJPG"))
            writer = cv2.VideoWriter(str(path), fourcc, fps, (img.shape[1], img.shape[0]))
            if not writer.isOpened():
                raise InputError(f"{path}: OpenCV cannot write a video of this type; use .mp4 or .avi")
        writer.write(draw_overlay(img, tracks, by_frame.get(f, ()), f, truth_by_frame.get(f, ())))
        n += 1
    if writer is not None:
        writer.release()
    return n


def write_overlay_gif(frames, tracks: np.ndarray, path, truth: np.ndarray | None = None, limit: int = 120,
                      step: int = 2, scale: int = 1, crop=None, ms_per_frame: int = 66) -> int:
    """A looping GIF (for the docs) of every ``step``-th of the first ``limit`` ``frames`` with the tracks and the
    ``truth`` rows (label boxes frame, x, y, w, h, or points) drawn by :func:`draw_overlay` and the frame number; ``crop``
    (column 0, row 0, column 1, row 1) keeps that part of each frame; ``scale`` > 1 shrinks by that factor.
    Returns the frames written; a ParameterError for a bad ``limit``, ``step``, ``scale``, ``crop`` or path, and
    when no frame is kept."""
    from PIL import Image

    from .errors import ParameterError
    from .validate import output_path, whole

    limit, step, scale = whole("limit", limit, 1), whole("step", step, 1), whole("scale", scale, 1)
    path = output_path("path", path, (".gif",))
    if crop is not None:
        crop = tuple(whole("crop", v, 0) for v in crop)
        if len(crop) != 4 or crop[2] <= crop[0] or crop[3] <= crop[1]:
            raise ParameterError(f"crop must be (column 0, row 0, column 1, row 1) with column 1 > column 0 and "
                                 f"row 1 > row 0, got {crop!r}")
    by_frame, truth_by_frame = _rows_by_frame(tracks), _rows_by_frame(truth)
    images = []
    for f, frame in enumerate(frames):
        if f >= limit:
            break
        if f % step:
            continue
        img = draw_overlay(stretched(frame), tracks, by_frame.get(f, ()), f, truth_by_frame.get(f, ()))
        if crop is not None:
            if crop[2] > img.shape[1] or crop[3] > img.shape[0]:
                raise ParameterError(f"crop {crop!r} reaches outside the {img.shape[1]}x{img.shape[0]} frame")
            img = np.ascontiguousarray(img[crop[1]:crop[3], crop[0]:crop[2]])
        cv2.putText(img, str(f), (4, 14), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (0, 255, 255), 1)
        images.append(Image.fromarray(cv2.cvtColor(img, cv2.COLOR_BGR2RGB)[::scale, ::scale]))
    if not images:
        raise ParameterError(f"no frame to write to {path}: the input has no frame below limit {limit}")
    images[0].save(path, save_all=True, append_images=images[1:], duration=ms_per_frame, loop=0, optimize=True)
    return len(images)
