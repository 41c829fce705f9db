"""``tbd-taichi evaluate-suite --methods mm-phd --scenario long2012``: Long et al. 2012's Monte Carlo comparisons
on the ``long2012`` scenes (:mod:`tbd_taichi.long2012`), each run scored by :mod:`tbd_taichi.track_detection`.

Variants (``VARIANTS``; every one is MM-PHD with parameters set):

* ``mm-phd``: the defaults (three models); on §5.3 its §5.3 settings (``SECTION_5_3``);
* ``smc-phd``: one model (CV; CA on §5.3), the paper's SMC-PHD row (Table 2) and Fig. 2's "improved SMC-PHD";
* ``standard``: one model without adaptive Q, likelihood resampling and the backward recursion (Fig. 2's
  "standard SMC-PHD").

Writes to ``out_dir``: ``long2012.md`` (Tables 2–4 beside the paper's, Fig. 2's and Fig. 4's numbers), the figures
``long2012_fig2.png``, ``long2012_fig4.png``, ``long2012_fig5.png``, ``long2012_fig7.png`` and the runs
(``long2012_runs.json``).  Frames in the tables are the paper's (1-based)."""
from __future__ import annotations

import json
import math
import time
from pathlib import Path

import numpy as np

from .long2012 import CASES, simulate_long2012
from .metrics import _points_by_frame, ospa
from .motion_models import MODELS
from .track_detection import TRACK_GATE, associate_tracks, paper_frame, pool_runs, track_detection

FIG2_SNRS = (12.0, 10.0, 8.0)
PAPER = {  # Long et al. 2012, Tables 2–4 (frames 1-based)
    "table2": {"mm-phd": (95.3, 0), "smc-phd": (92.7, 0)},
    "table3": {"mm-phd": (10.7, 10.2, 20.6), "smc-phd": (10.9, 10.3, 20.8)},
    "table4": {"mm-phd": (31.2, 31.3, 36.3), "smc-phd": (31.4, 31.3, 35.7)},
}


def variant_settings(variant: str, case: str) -> dict:
    """MM-PHD's keywords for ``variant`` on ``case``."""
    from .methods.mm_phd import SECTION_5_3

    base = dict(SECTION_5_3) if case == "5.3" else {}
    one = "ca" if case == "5.3" else "cv"
    if variant == "smc-phd":
        return {**base, "models": one}
    if variant == "standard":
        return {**base, "models": one, "adaptive_q": False, "likelihood_resampling": False, "backward": False}
    return base


VARIANTS = ("mm-phd", "smc-phd", "standard")


def run_once(case: str, variant: str, seed: int, snr_db: float | None = None, engine: str = "taichi") -> dict:
    """One scene and one tracker: the track-detection result, per-frame OSPA (c = 5 px, p = 2), per target and
    frame the squared position error of its associated track (None where it has no row) and that track's model
    probabilities, the confirmation frames and the wall seconds."""
    from . import methods

    sc = simulate_long2012(case, seed=seed, snr_db=snr_db)
    started = time.perf_counter()
    tracker = methods.make_tracker("mm-phd", sc.frames.shape[1:], seed=seed, engine=engine,
                                   **variant_settings(variant, case))
    for frame in sc.frames:
        tracker.update(frame)
    tracks = tracker.finish()
    seconds = time.perf_counter() - started
    n = len(sc.frames)
    confirmed = dict(tracker.tracker.confirmations)
    result = track_detection(tracks, sc.truth, n, confirmed=confirmed)
    est, tru = _points_by_frame(tracks), _points_by_frame(sc.truth)
    empty = np.zeros((0, 2))
    result["ospa"] = [ospa(est.get(f, empty), tru.get(f, empty), TRACK_GATE, 2.0) for f in range(n)]
    pairs = associate_tracks(tracks, sc.truth)
    sq, probs = {}, {}
    names = [c for c in tracks.dtype.names if c.startswith("p_")]
    for gid in np.unique(sc.truth["target_id"]):
        gt = sc.truth[sc.truth["target_id"] == gid]
        tr = tracks[tracks["track_id"] == pairs.get(int(gid), -1)]
        by_frame = {int(r["frame"]): r for r in tr}
        sq[str(gid)] = [None if int(g["frame"]) not in by_frame else
                        float((by_frame[int(g["frame"])]["x"] - g["x"]) ** 2 + (by_frame[int(g["frame"])]["y"] - g["y"]) ** 2)
                        for g in gt]
        probs[str(gid)] = [[float(by_frame[int(g["frame"])][c]) for c in names] if int(g["frame"]) in by_frame else None
                           for g in gt]
    result.update(case=case, variant=variant, seed=seed, snr_db=snr_db, seconds=seconds,
                  sq_error=sq, model_probs=probs, model_names=[c[2:].replace("_", "-") for c in names],
                  truth_frames={str(g): sc.truth["frame"][sc.truth["target_id"] == g].astype(int).tolist()
                                for g in np.unique(sc.truth["target_id"])},
                  truth_models={str(g): sc.truth["model"][sc.truth["target_id"] == g].astype(int).tolist()
                                for g in np.unique(sc.truth["target_id"])})
    result["targets"] = {str(k): v for k, v in result["targets"].items()}
    result["confirmed"] = {str(k): v for k, v in confirmed.items()}
    return result


def plan(runs: int, seed: int = 0) -> list[tuple]:
    """Every (case, variant, seed, snr_db) of the suite: §5.3 and §5.2 with MM-PHD and SMC-PHD, §5.1 with the
    improved and the standard SMC-PHD at 12, 10 and 8 dB."""
    out = [("5.3", v, seed + k, None) for v in ("mm-phd", "smc-phd") for k in range(runs)]
    out += [("5.2", v, seed + k, None) for v in ("mm-phd", "smc-phd") for k in range(runs)]
    out += [("5.1", v, seed + k, db) for db in FIG2_SNRS for v in ("smc-phd", "standard") for k in range(runs)]
    return out


def execute(runs: int, out_dir: Path, seed: int = 0, progress=None) -> list[dict]:
    """Run the plan (one process; MM-PHD's pools are reused run to run) and keep the results in
    ``out_dir/long2012_runs.json``."""
    results = []
    for case, variant, s, db in plan(runs, seed):
        results.append(run_once(case, variant, s, db))
        if progress is not None:
            progress.advance()
    (out_dir / "long2012_runs.json").write_text(json.dumps(results))
    return results


def _select(results, case, variant, snr_db=None):
    return [r for r in results if r["case"] == case and r["variant"] == variant and r["snr_db"] == snr_db]


def _fmt(v, digits=1) -> str:
    return "–" if v is None or (isinstance(v, float) and math.isnan(v)) else f"{v:.{digits}f}"


def tables_markdown(results: list[dict], command: str) -> str:
    """Tables 2–4 (§5.3) beside the paper's, and §5.2's and §5.1's summaries."""
    lines = ["# MM-PHD on Long et al. 2012's scenes", "", f"Reproduce with `{command}`.", "",
             "Frames are the paper's (1-based). §5.3's STK paths are unpublished: the scene is the substitute of "
             "`tbd_taichi/long2012.py` (launches at frames 8, 8 and 15, last present 29, 29 and 34).", ""]
    pooled = {v: pool_runs(_select(results, "5.3", v)) for v in ("mm-phd", "smc-phd")}
    lines += ["## Table 2: track detection (§5.3)", "",
              "| algorithm | runs | P_TD % | false tracks | mean |cardinality error| | paper P_TD % | paper false |",
              "|---|---|---|---|---|---|---|"]
    for v, s in pooled.items():
        p = PAPER["table2"][v]
        lines.append(f"| {v.upper()} | {s['runs']} | {_fmt(s['p_td'])} | {s['false_tracks']} | "
                     f"{_fmt(s['cardinality_error'], 3)} | {p[0]} | {p[1]} |")
    for title, key, paper_key in (("Table 3: detection (confirmation) frame", "detection_frame", "table3"),
                                  ("Table 4: halt frame", "halt_frame", "table4")):
        lines += ["", f"## {title} (§5.3)", "", "| algorithm | target 1 | target 2 | target 3 | paper |",
                  "|---|---|---|---|---|"]
        for v, s in pooled.items():
            vals = [s[key].get(str(t), float("nan")) for t in (0, 1, 2)]
            lines.append(f"| {v.upper()} | " + " | ".join(_fmt(paper_frame(x)) for x in vals)
                         + " | " + ", ".join(map(str, PAPER[paper_key][v])) + " |")
    lines += ["", "Detection with the backward recursion's start instead (the first frame of the whole path):", "",
              "| algorithm | target 1 | target 2 | target 3 |", "|---|---|---|---|"]
    for v, s in pooled.items():
        lines.append(f"| {v.upper()} | " + " | ".join(_fmt(paper_frame(s['start_frame'].get(str(t), float('nan'))))
                                                        for t in (0, 1, 2)) + " |")
    lines += ["", "## §5.2: three manoeuvring targets at 10 dB", "",
              "| algorithm | runs | P_TD % | false tracks | mean OSPA (c 5 px, p 2) | RMSE target 1, 2, 3 (px) |",
              "|---|---|---|---|---|---|"]
    for v in ("mm-phd", "smc-phd"):
        sel = _select(results, "5.2", v)
        s = pool_runs(sel)
        lines.append(f"| {v.upper()} | {s['runs']} | {_fmt(s['p_td'])} | {s['false_tracks']} | "
                     f"{_fmt(float(np.mean([np.mean(r['ospa']) for r in sel])), 2)} | "
                     + ", ".join(_fmt(rmse(sel, t), 2) for t in (0, 1, 2)) + " |")
    lines += ["", "## §5.1 (Fig. 2): standard against improved SMC-PHD, one CV target", "",
              "| SNR dB | variant | runs | P_TD % | mean OSPA | RMSE (px) |", "|---|---|---|---|---|---|"]
    for db in FIG2_SNRS:
        for v in ("standard", "smc-phd"):
            sel = _select(results, "5.1", v, db)
            s = pool_runs(sel)
            lines.append(f"| {db:g} | {'improved' if v == 'smc-phd' else 'standard'} | {s['runs']} | {_fmt(s['p_td'])} "
                         f"| {_fmt(float(np.mean([np.mean(r['ospa']) for r in sel])), 2)} | {_fmt(rmse(sel, 0), 2)} |")
    return "\n".join(lines) + "\n"


def rmse(results: list[dict], target: int) -> float:
    """Eq. 38 pooled over runs and frames: √(mean squared position error) where the target has a track row."""
    v = [e for r in results for e in r["sq_error"].get(str(target), []) if e is not None]
    return float(math.sqrt(np.mean(v))) if v else float("nan")


def rmse_by_frame(results: list[dict], target) -> tuple[np.ndarray, np.ndarray]:
    """(frames, RMSE per frame over the runs with a row) of one target (Eq. 38)."""
    key = str(target)
    frames = np.array(results[0]["truth_frames"][key])
    errs = np.array([[np.nan if e is None else e for e in r["sq_error"][key]] for r in results], float)
    with np.errstate(invalid="ignore"):
        return frames, np.sqrt(np.nanmean(errs, axis=0))


def write_report(results: list[dict], out_dir: Path, command: str) -> Path:
    """long2012.md and the figures."""
    from .plots_long2012 import plot_figures

    out_dir.mkdir(exist_ok=True)
    report = out_dir / "long2012.md"
    text = tables_markdown(results, command)
    figures = plot_figures(results, out_dir)
    text += "\n## Figures\n\n" + "\n".join(f"![{p.stem}]({p.name})" for p in figures) + "\n"
    report.write_text(text)
    return report


__all__ = ["CASES", "MODELS", "VARIANTS", "execute", "plan", "run_once", "tables_markdown", "write_report"]
