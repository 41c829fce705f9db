"""OTB measures of a box tracker against box truth (tbd_taichi.otb, Wu, Lim & Yang 2013): CLE, DP curve, IoU,
success curve and AUC over the frames after the first labelled one; the evaluate command's output."""
import json
import math
import re

import cv2
import numpy as np
import pytest

from tbd_taichi import cli, metrics, tables
from tbd_taichi.errors import ParameterError
from tbd_taichi.otb import CLE_CAP, otb_scores

BOX_DTYPE = np.dtype([("frame", np.int64), ("x", float), ("y", float), ("w", float), ("h", float),
                      ("target_id", np.int64)])
BOX_TRACK_DTYPE = np.dtype(tables.TRACK_DTYPE.descr + [("w", float), ("h", float)])
OLD_BOX_KEYS = {"truth", "box_margin", "detection_rate", "false_points", "first_confirmation", "centre_error", "iou"}
OTB_KEYS = {"cle", "dp20", "dp5", "dp_curve", "mean_iou", "success_curve", "auc", "scored_frames", "missed_frames"}


def make_boxes(n=10, first=0, size=20.0):
    """A 20×20 truth box (top-left corner) moving 3 px right and 1 px down per frame, frames first..first+n−1."""
    return np.array([(f, 5.0 + 3 * f, 8.0 + f, size, size, 0) for f in range(first, first + n)], BOX_DTYPE)


def tracks_on(boxes, dx=0.0, dy=0.0, frames=None, conf=1.0, track_id=1):
    """Box-tracker rows centred on each truth box (shifted by dx, dy), same size; only ``frames`` if given."""
    rows = [(b["frame"], track_id, b["x"] + b["w"] / 2 + dx, b["y"] + b["h"] / 2 + dy, 0, 0, 1, conf, b["w"], b["h"])
            for b in boxes if frames is None or b["frame"] in frames]
    return np.array(rows, BOX_TRACK_DTYPE)


def test_perfect_tracks_score_cle_0_dp_1_iou_1_and_auc_20_of_21():
    boxes = make_boxes()
    s = otb_scores(tracks_on(boxes), boxes)
    assert s["cle"] == 0 and s["dp20"] == 1 and s["dp5"] == 1 and s["dp_curve"] == [1.0] * 51
    assert s["mean_iou"] == pytest.approx(1.0)
    # IoU > 1.0 is impossible: the success curve's last value (t = 1.0) is 0, so a perfect tracker's AUC is 20/21
    assert s["success_curve"] == [1.0] * 20 + [0.0]
    assert s["auc"] == pytest.approx(20 / 21)
    assert s["scored_frames"] == 9 and s["missed_frames"] == 0 and s["first_frame"] == 0 and s["cle_cap"] == CLE_CAP


def test_track_shifted_10_px_on_a_20_px_box():
    boxes = make_boxes()
    s = otb_scores(tracks_on(boxes, dx=10.0), boxes)
    assert s["cle"] == pytest.approx(10.0)
    assert s["mean_iou"] == pytest.approx(10 * 20 / (2 * 400 - 10 * 20))  # = 1/3
    assert s["dp5"] == 0 and s["dp20"] == 1
    assert s["dp_curve"][9] == 0 and s["dp_curve"][10] == 1  # CLE ≤ t: exactly 10 px counts at t = 10
    assert s["success_curve"][6] == 1 and s["success_curve"][7] == 0  # t = 0.30 and 0.35
    assert s["auc"] == pytest.approx(7 / 21)
    diagonal = otb_scores(tracks_on(boxes, dx=3.0, dy=4.0), boxes)
    assert diagonal["cle"] == pytest.approx(5.0) and diagonal["dp5"] == 1 and diagonal["dp_curve"][4] == 0


def test_missed_frames_count_with_the_cle_cap_and_iou_0():
    boxes = make_boxes()
    kept = {0, 1, 2, 4, 5, 7, 8, 9}  # frames 3 and 6 have a truth box and no track row
    s = otb_scores(tracks_on(boxes, frames=kept), boxes)
    assert s["scored_frames"] == 9 and s["missed_frames"] == 2
    assert s["cle"] == pytest.approx(2 * CLE_CAP / 9) and CLE_CAP == 100.0
    assert s["mean_iou"] == pytest.approx(7 / 9)
    assert s["dp20"] == pytest.approx(7 / 9) and s["dp_curve"][50] == pytest.approx(7 / 9)  # 100 px > every t
    assert s["success_curve"][0] == pytest.approx(7 / 9)  # IoU 0 is not > 0
    none = otb_scores(np.zeros(0, BOX_TRACK_DTYPE), boxes)
    assert none["missed_frames"] == none["scored_frames"] == 9 and none["cle"] == CLE_CAP and none["auc"] == 0


def test_the_first_labelled_frame_is_excluded_and_unlabelled_frames_are_not_scored():
    boxes = make_boxes(n=8, first=3)  # frames 0-2 unlabelled: the first labelled frame, 3, is the init box
    far = np.array([(f, 1, 500.0, 500.0, 0, 0, 1, 1, 20, 20) for f in (0, 1, 2, 3, 40)], BOX_TRACK_DTYPE)
    tracks = np.concatenate([far, tracks_on(boxes[1:])])  # wrong at the init frame and where there is no truth
    s = otb_scores(tracks, boxes)
    assert s["first_frame"] == 3 and s["scored_frames"] == 7 and s["missed_frames"] == 0 and s["cle"] == 0
    later = otb_scores(tracks, boxes, first_frame=6)  # an explicit first frame: only frames after it
    assert later["first_frame"] == 6 and later["scored_frames"] == 4
    with_init = otb_scores(tracks, boxes, first_frame=2)  # frame 3 is now scored, and its track is 500+ px away
    assert with_init["scored_frames"] == 8 and with_init["cle"] > 50 and with_init["dp20"] == pytest.approx(7 / 8)


def test_duplicate_rows_in_a_frame_use_the_most_confident():
    boxes = make_boxes()
    good = tracks_on(boxes, conf=0.9, track_id=1)
    bad = tracks_on(boxes, dx=30.0, conf=0.2, track_id=2)
    assert otb_scores(np.concatenate([bad, good]), boxes)["cle"] == 0
    good["confidence"], bad["confidence"] = 0.2, 0.9
    s = otb_scores(np.concatenate([good, bad]), boxes)
    assert s["cle"] == pytest.approx(30.0) and s["mean_iou"] == 0 and s["scored_frames"] == 9


@pytest.mark.parametrize("box, centre, size, expected", [
    ((0, 0, 10, 10), (5, 5), (10, 10), 1.0),  # the same box
    ((0, 0, 10, 10), (7, 5), (10, 10), 80 / 120),  # x 2..12 over 0..10: 8×10 of 200 − 80
    ((0, 0, 10, 10), (10, 10), (10, 10), 25 / 175),  # corner overlap 5×5
    ((2, 3, 4, 6), (5, 5), (4, 2), 6 / 26),  # x 3..7 ∩ 2..6 = 3, y 4..6 ∩ 3..9 = 2; 24 + 8 − 6
    ((0, 0, 10, 10), (5, 5), (4, 4), 16 / 100),  # inside
    ((0, 0, 10, 10), (20, 5), (10, 10), 0.0),  # x 15..25: apart
    ((0, 0, 10, 10), (15, 5), (10, 10), 0.0),  # sharing the edge x = 10
])
def test_box_iou_by_hand(box, centre, size, expected):
    truth = dict(zip(("x", "y", "w", "h"), map(float, box)))
    track = dict(x=float(centre[0]), y=float(centre[1]), w=float(size[0]), h=float(size[1]))
    assert metrics.box_iou(truth, track) == pytest.approx(expected)


def test_several_targets_score_the_first_frames_target_or_the_one_named():
    a = make_boxes()
    b = make_boxes()
    b["target_id"], b["x"] = 4, b["x"] + 100
    boxes = np.concatenate([b, a])
    assert otb_scores(tracks_on(a), boxes)["cle"] == 0  # target 0: the lowest id in the first labelled frame
    s = otb_scores(tracks_on(a), boxes, target_id=4)
    assert s["target_id"] == 4 and s["cle"] == pytest.approx(100.0) and s["mean_iou"] == 0


def test_nothing_to_score_gives_nan_and_bad_arguments_are_one_line_errors():
    boxes = make_boxes(n=1)
    s = otb_scores(tracks_on(boxes), boxes)
    assert s["scored_frames"] == 0 and math.isnan(s["cle"]) and math.isnan(s["auc"]) and len(s["dp_curve"]) == 51
    point_tracks = tables.make_table([(1, 1, 15.0, 18.0, 0, 0, 1, 1)], tables.TRACK_DTYPE)
    with pytest.raises(ParameterError, match="tracks needs .*frame,x,y,w,h.*lacks w,h"):
        otb_scores(point_tracks, make_boxes())
    with pytest.raises(ParameterError, match="first_frame must be a whole number"):
        otb_scores(tracks_on(make_boxes()), make_boxes(), first_frame=-1)
    with pytest.raises(ParameterError, match=r"target_id must be one of .*\(0\), got 7"):
        otb_scores(tracks_on(make_boxes()), make_boxes(), target_id=7)


def test_truth_scores_add_the_otb_keys_for_box_tracks_only():
    boxes = make_boxes()
    box = metrics.truth_scores("boxes", tracks_on(boxes, dx=10.0), boxes)
    assert OLD_BOX_KEYS | OTB_KEYS <= set(box) and box["cle"] == pytest.approx(10.0)
    point = tables.make_table([(r["frame"], 1, r["x"], r["y"], 0, 0, 1, 1) for r in tracks_on(boxes)],
                              tables.TRACK_DTYPE)
    assert set(metrics.truth_scores("boxes", point, boxes)) == OLD_BOX_KEYS


def write_box_files(d, dx=10.0, with_size=True):
    boxes = make_boxes()
    d.joinpath("boxes.csv").write_text("frame,x,y,w,h\n" + "".join(
        f"{b['frame']},{b['x']},{b['y']},{b['w']},{b['h']}\n" for b in boxes))
    tracks = tracks_on(boxes, dx=dx)
    tables.write_csv(tracks if with_size else tracks[list(tables.TRACK_COLUMNS)], d / "tracks.csv")
    return d / "tracks.csv", d / "boxes.csv"


def test_read_tracks_keeps_w_h_only_when_the_file_has_them(tmp_path):
    tracks_csv, _ = write_box_files(tmp_path)
    got = tables.read_tracks(tracks_csv)
    assert got.dtype.names == tables.TRACK_COLUMNS + ("w", "h") and np.all(got["w"] == 20)
    tracks_csv, _ = write_box_files(tmp_path, with_size=False)
    assert tables.read_tracks(tracks_csv).dtype == tables.TRACK_DTYPE


def test_evaluate_json_and_text_for_box_tracks(tmp_path, capsys):
    tracks_csv, boxes_csv = write_box_files(tmp_path)
    capsys.readouterr()
    assert cli.main(["evaluate", "--tracks", str(tracks_csv), "--truth", str(boxes_csv), "--json"]) == 0
    s = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert OLD_BOX_KEYS | OTB_KEYS <= set(s)
    assert s["cle"] == pytest.approx(10.0) and s["mean_iou"] == pytest.approx(1 / 3) and s["dp20"] == 1
    assert s["dp5"] == 0 and s["auc"] == pytest.approx(7 / 21) and s["scored_frames"] == 9 and s["missed_frames"] == 0
    assert len(s["dp_curve"]) == 51 and len(s["success_curve"]) == 21
    assert cli.main(["evaluate", "--tracks", str(tracks_csv), "--truth", str(boxes_csv)]) == 0
    text = capsys.readouterr().out
    for line in (r"CLE, centre error \(px\)\s+10\.00", r"DP@20 / DP@5\s+1\.000 / 0\.000",
                 r"mean IoU \(overlap rate\)\s+0\.333", r"AUC \(success plot\)\s+0\.333", r"9 scored after frame 0, 0 missed"):
        assert re.search(line, text), (line, text)


def test_evaluate_json_for_point_tracks_against_boxes_keeps_the_old_keys(tmp_path, capsys):
    tracks_csv, boxes_csv = write_box_files(tmp_path, with_size=False)
    capsys.readouterr()
    assert cli.main(["evaluate", "--tracks", str(tracks_csv), "--truth", str(boxes_csv), "--json"]) == 0
    assert set(json.loads(capsys.readouterr().out.strip().splitlines()[-1])) == OLD_BOX_KEYS


def test_plot_otb_curves_writes_a_png(tmp_path):
    from tbd_taichi.plots import plot_otb_curves

    boxes = make_boxes()
    results = {"perfect": otb_scores(tracks_on(boxes), boxes), "shifted": otb_scores(tracks_on(boxes, dx=10), boxes)}
    plot_otb_curves(results, tmp_path / "otb.png")
    assert (tmp_path / "otb.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    with pytest.raises(ParameterError, match="results\\['bad'\\] needs dp_curve"):
        plot_otb_curves({"bad": {"dp_curve": [1.0]}}, tmp_path / "x.png")
    with pytest.raises(ParameterError, match="non-empty dict"):
        plot_otb_curves({}, tmp_path / "x.png")


def test_plot_otb_per_sequence_writes_one_grid_and_checks_every_sequence(tmp_path):
    from tbd_taichi.plots import plot_otb_per_sequence

    boxes = make_boxes()
    results = {"perfect": otb_scores(tracks_on(boxes), boxes), "shifted": otb_scores(tracks_on(boxes, dx=10), boxes)}
    plot_otb_per_sequence({"a": results, "b": results, "c": results}, tmp_path / "grid.png", columns=2)
    assert (tmp_path / "grid.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    with pytest.raises(ParameterError, match="results\\['bad'\\] needs dp_curve"):
        plot_otb_per_sequence({"a": results, "b": {"bad": {}}}, tmp_path / "x.png")
    with pytest.raises(ParameterError, match="non-empty dict"):
        plot_otb_per_sequence({}, tmp_path / "x.png")


def test_overlay_gif_draws_the_boxes_on_the_kept_frames(tmp_path):
    """Every second of the first 6 frames, cropped to 40×30 px: the track's box (its colour) and the label box
    (green) are drawn where the rows say."""
    from PIL import Image

    from tbd_taichi.plots import track_colour, write_overlay_gif

    boxes = make_boxes(n=8)
    frames = [np.zeros((60, 80), np.float32) for _ in range(8)]
    n = write_overlay_gif(frames, tracks_on(boxes, dx=4), tmp_path / "o.gif", truth=boxes, limit=6, step=2,
                          crop=(0, 0, 40, 30))
    gif = Image.open(tmp_path / "o.gif")
    assert n == 3 and gif.n_frames == 3 and gif.size == (40, 30)
    first = np.asarray(gif.convert("RGB"))
    b = boxes[0]  # label box: x 5..25, y 8..28 → its left edge at column 5
    assert tuple(first[15, 5]) == (0, 200, 0)
    bgr = track_colour(1)  # the track's box: centre (15 + 4, 18), 20×20 → left edge at column 9
    assert tuple(first[18, 9]) == (bgr[2], bgr[1], bgr[0])
    assert b["frame"] == 0


@pytest.mark.parametrize("kind", ["boxes", "points"])
def test_overlay_video_draws_the_truth_in_green(tmp_path, kind):
    """``track --video --truth``: label boxes as rectangles, point truth as circles, in green (the video codec
    blurs colours, hence the margins)."""
    from tbd_taichi.plots import write_overlay_video

    boxes = make_boxes(n=4)
    truth = boxes if kind == "boxes" else tracks_on(boxes)[["frame", "x", "y"]]
    frames = [np.zeros((60, 80), np.float32) for _ in range(4)]
    assert write_overlay_video(frames, tracks_on(boxes[:0]), tmp_path / "o.avi", truth=truth) == 4
    ok, img = cv2.VideoCapture(str(tmp_path / "o.avi")).read()
    assert ok
    b = boxes[0]
    column = 5 if kind == "boxes" else 7  # the box's left edge (x 5..25) or the circle's (radius 8 around x 15)
    near = img[16:21, column - 1:column + 2].astype(int)  # B, G, R around (column, 18)
    green = near[..., 1] - np.maximum(near[..., 0], near[..., 2])
    assert green.max() > 40 and near[..., 1].max() > 110, near
    assert img[40:, 50:].max() < 40  # nothing drawn far from the truth
    assert b["frame"] == 0


@pytest.mark.parametrize("bad, match", [({"step": 0}, "step"), ({"scale": 0}, "scale"), ({"limit": 0}, "limit"),
                                        ({"crop": (10, 0, 5, 20)}, "crop"), ({"crop": (0, 0, 200, 20)}, "outside"),
                                        ({"path": "o.png"}, "path")])
def test_overlay_gif_refuses_bad_arguments(tmp_path, bad, match):
    from tbd_taichi.plots import write_overlay_gif

    boxes = make_boxes(n=2)
    kw = {"path": "o.gif", **bad}
    from tbd_taichi.errors import TBDError

    with pytest.raises(TBDError, match=match):  # a ParameterError, or an InputError for the path
        write_overlay_gif([np.zeros((60, 80), np.float32)] * 2, tracks_on(boxes), tmp_path / kw.pop("path"), **kw)
    with pytest.raises(ParameterError, match="columns"):
        from tbd_taichi.plots import plot_otb_per_sequence

        plot_otb_per_sequence({"a": {"x": otb_scores(tracks_on(boxes), boxes)}}, tmp_path / "g.png", columns=0)
