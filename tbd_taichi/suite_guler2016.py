"""``tbd-taichi evaluate-suite --methods tophat-pf,sgds,pf --scenario guler2016``: Güler's 2016 thesis (Ch. 4)
on the ``guler2016`` scenario (:mod:`tbd_taichi.guler2016`; the thesis's recordings are not public, the walls are
synthetic).

* Tables 4.6–4.8: max error (px) and MSE (Eq. 4.1b, px²) per wall × motion × Δ where the thesis has them
  (AVAILABLE), for every method: run r simulates ``simulate_guler2016(wall, motion, Δ, seed=SEED + r)`` (the
  wall's one recording, the noise of seed SEED + r) and runs the tracker with seed SEED + r — tophat-pf with
  its defaults (one setting for every Δ, as issue 40 asks: the thesis retuned α, B, the motion term and N per
  Δ) and ``paths="whole"``, sgds and pf with their defaults (``make_tracker``'s profile auto: the real-video settings for the uint16 frames).
* Tables 4.9–4.11: tophat-pf's MSE against N, S (``s_drift``) and C (SWEEPS: the setups the project's notes
  guess, and S and C again at Δ 15).
* The SNR of each Δ: Δ/σ and the thesis's Δ/(100σ) (Tables 4.1–4.3).

Per run, the track matched to the target (:func:`tbd_taichi.metrics.thesis_errors`: the most rows within 5 px)
gives the MSE and the max error; no such track: the run is **lost** (left out of the MSE averages).  Also: held
(MSE < 1 px²), false tracks (rows mostly ≥ 5 px from the target, :func:`~tbd_taichi.metrics.false_tracks`) and
the confirmation frame: the 0-based frame of the ``update`` call that first returned a row of the matched track
(tophat-pf with paths = whole returns the rows from frame 3 at its confirmation; sgds reports with its
front-end's 2-frame lag; a track first given by ``finish`` counts as the frame count).

Writes ``guler2016.md`` (the tables beside the thesis's values) and ``guler2016_runs.json`` (every run's figures)
to ``out_dir``."""
from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from . import metrics
from .guler2016 import simulate_guler2016

METHODS = ("tophat-pf", "sgds", "pf")
FLAGSHIP = "tophat-pf"  # the thesis's method: whole paths, the sweeps
RUNS, SWEEP_RUNS = 20, 10
HELD_MSE = 1.0  # px²: a run "holds" the target
AVAILABLE = {  # the thesis's wall × motion × Δ (a dash in Tables 4.6–4.8: not available)
    ("S1", 1): (100, 60, 50, 30, 20, 15, 14, 13, 10),
    ("S1", 2): (100, 60, 50, 30, 20, 15, 10),
    ("S2", 1): (100, 60, 50, 30, 20, 15, 14, 10),
    ("S2", 2): (30, 20),
}
# Tables 4.6-4.8 (thesis, single runs, N = 5000 or 7000): (max error px, MSE px²); None: "NO TRACK".  Copied from
# the project's notes on the thesis (docs: /work/shared/papers/notes/tophat-pf.md §5.3).
THESIS_TABLES = {
    ("S1", 1, 100): (0.4274, 0.0504), ("S1", 1, 60): (0.4738, 0.0532), ("S1", 1, 50): (0.4294, 0.0528),
    ("S1", 1, 30): (3.4665, 0.1742), ("S1", 1, 20): (3.8947, 0.7032), ("S1", 1, 15): (9.0340, 12.320),
    ("S1", 1, 14): (8.3779, 14.901), ("S1", 1, 13): (12.840, 55.306), ("S1", 1, 10): (37.242, 379.87),
    ("S1", 2, 100): (0.2859, 0.0254), ("S1", 2, 60): (0.2744, 0.0233), ("S1", 2, 50): (0.2845, 0.0261),
    ("S1", 2, 30): (0.2901, 0.0244), ("S1", 2, 20): (0.5785, 0.1677), ("S1", 2, 15): (2.6710, 0.2260),
    ("S1", 2, 10): (2.4577, 0.5166),
    ("S2", 1, 100): (0.4031, 0.0523), ("S2", 1, 60): (0.4842, 0.0537), ("S2", 1, 50): (0.4236, 0.0536),
    ("S2", 1, 30): (0.4261, 0.0496), ("S2", 1, 20): (1.7588, 0.3710), ("S2", 1, 15): (1.2659, 0.4094),
    ("S2", 1, 14): (6.8281, 3.2369), ("S2", 1, 10): None,
    ("S2", 2, 30): (0.2805, 0.0246), ("S2", 2, 20): (0.5841, 0.1701),
}
THESIS_NOTES = {("S1", 1, 10): "track lost", ("S2", 1, 10): "NO TRACK"}
# Tables 4.1-4.3: the thesis's mean SNR, = Δ/(100σ) of its frames (notes §5.2)
THESIS_SNR = {
    "S1": {100: 0.1093, 60: 0.0656, 50: 0.0546, 30: 0.0328, 20: 0.0219, 15: 0.0164, 14: 0.0153, 13: 0.0142,
           10: 0.0109},
    "S2": {100: 0.2423, 60: 0.1454, 50: 0.1212, 30: 0.0727, 20: 0.0485, 15: 0.0363, 14: 0.0339, 10: 0.0242},
}
# Tables 4.9-4.11 (mean of 10 runs in the thesis; None: "No track"), the tophat-pf parameter each sweeps and the
# setups (wall, motion, Δ). The thesis does not state its setup; the first is the notes' guess (§5.4): S1 Δ 30
# Motion 1 for N and C (C = 0.5 matches Table 4.9), S1 Motion 2 Δ 20 for S (S = 3 matches Table 4.7's 0.1677).
# There the likelihood pins the estimate to the lit pixel and S and C change little; the second setup, Δ 15 (the
# faintest the thesis reports on S1), is where the filter must coast on B and a wide walk loses the pixel.
SWEEPS = {
    "N": dict(table="4.9", param="n_particles", setups=(("S1", 1, 30),), thesis={
        250: 0.39605, 500: 0.36482, 750: 0.35549, 1000: 0.35629, 1250: 0.34512, 1500: 0.3459, 1750: 0.34662,
        2000: 0.3514, 2250: 0.34502, 2500: 0.34423, 2750: 0.34776, 3000: 0.35508, 3500: 0.34867, 4000: 0.35218,
        5000: 0.34457}),
    "S": dict(table="4.10", param="s_drift", setups=(("S1", 2, 20), ("S1", 2, 15)), thesis={
        3: 0.1667, 5: 0.1641, 10: 0.1598, 15: 0.1499, 20: 0.1426, 25: 0.1356, 30: 0.1381, 35: 0.1229, 40: 0.1190,
        45: 0.1089, 50: 0.0985}),
    "C": dict(table="4.11", param="c", setups=(("S1", 1, 30), ("S1", 1, 15)), thesis={
        0.005: None, 0.05: None, 0.1: None, 0.5: 0.34240, 1: 0.46484, 1.5: 0.86140, 2: 3.55750}),
}
QUICK = dict(cells=(("S1", 1, 30),), runs=2, sweeps={"N": (1000,), "S": (10,), "C": (0.5,)})


def cells(quick: bool = False) -> list[tuple[str, int, int]]:
    """Every (wall, motion, Δ) of Tables 4.6–4.8 (QUICK's one with ``quick``)."""
    if quick:
        return list(QUICK["cells"])
    return [(w, m, d) for (w, m), deltas in AVAILABLE.items() for d in deltas]


def plan(chosen, runs: int, compare_runs: int | None = None, seed: int = 0, quick: bool = False) -> list[dict]:
    """Every run: the table cells for each method in ``chosen`` (``runs`` for tophat-pf, ``compare_runs`` —
    default ``runs`` — for the others), then with tophat-pf the sweeps, min(runs, SWEEP_RUNS) runs per value."""
    out = []
    for method in chosen:
        n = runs if method == FLAGSHIP or compare_runs is None else compare_runs
        for wall, motion, delta in cells(quick):
            settings = {}
            out += [dict(table="main", method=method, wall=wall, motion=motion, delta=delta, seed=seed + r,
                         settings=settings) for r in range(n)]
    if FLAGSHIP in chosen:
        for name, sweep in SWEEPS.items():
            for wall, motion, delta in sweep["setups"][:1] if quick else sweep["setups"]:
                for value in (QUICK["sweeps"][name] if quick else sweep["thesis"]):
                    out += [dict(table=name, method=FLAGSHIP, wall=wall, motion=motion, delta=delta, seed=seed + r,
                                 settings={sweep["param"]: value}) for r in range(min(runs, SWEEP_RUNS))]
    return out


def run_once(method: str, wall: str, motion: int, delta: float, seed: int, engine: str = "taichi",
             **settings) -> dict:
    """One sequence and one tracker: the matched track's errors, false tracks, the confirmation frame."""
    from . import methods

    sc = simulate_guler2016(wall, motion, delta, seed=seed)
    options = {"paths": "whole"} if method == FLAGSHIP else {}
    started = time.perf_counter()
    tracker = methods.make_tracker(method, sc.frames.shape[1:], seed=seed, engine=engine, **options, **settings)
    first_online: dict[int, int] = {}
    for k, frame in enumerate(sc.frames):
        for row in tracker.update(frame):
            first_online.setdefault(int(row[1]), k)
    tracks = tracker.finish()
    seconds = time.perf_counter() - started
    e = metrics.thesis_errors(tracks, sc.truth)
    matched = e["track_id"]
    p = sc.params
    return dict(method=method, wall=wall, motion=motion, delta=delta, seed=seed, settings=settings,
                frames=len(sc.frames), seconds=seconds, mse=e["mse"], max_error=e["max_error"],
                scored_frames=e["frames"], track_id=matched, lost=matched is None,
                held=bool(matched is not None and e["mse"] < HELD_MSE),
                confirmation_frame=None if matched is None else first_online.get(matched, len(sc.frames)),
                tracks=int(len(np.unique(tracks["track_id"]))),
                false_tracks=int(metrics.false_tracks(tracks, sc.truth, metrics.MATCH_GATE)),
                sigma=p["sigma"], snr=p["snr"], snr_thesis=p["snr_thesis"])


def execute(todo: list[dict], out_dir: Path, progress=None, engine: str = "taichi",
            meta: dict | None = None) -> list[dict]:
    """Run ``todo`` (:func:`plan`) in this process (Taichi's kernels are reused run to run) and keep the results
    in ``out_dir/guler2016_runs.json``."""
    results = []
    for run in todo:
        row = run_once(run["method"], run["wall"], run["motion"], run["delta"], run["seed"], engine,
                       **run["settings"])
        results.append(dict(row, table=run["table"]))
        if progress is not None:
            progress.advance()
    write_runs(results, out_dir / "guler2016_runs.json", meta)
    return results


def _rounded(value):
    """Floats to 6 significant digits (the JSON's size), in dicts and lists too."""
    if isinstance(value, float):
        return float(f"{value:.6g}")
    if isinstance(value, dict):
        return {k: _rounded(v) for k, v in value.items()}
    return [_rounded(v) for v in value] if isinstance(value, list) else value


def write_runs(results: list[dict], path: Path, meta: dict | None = None) -> None:
    """``meta`` and every run's figures as JSON, one run a line (floats to 6 significant digits; NaN for a lost
    run's errors)."""
    head = json.dumps(dict(meta or {}))[:-1] + (", " if meta else "")
    runs = ",\n".join(json.dumps(_rounded(r), allow_nan=True) for r in results)
    path.write_text(f'{head}"runs": [\n{runs}\n]}}\n')


def summarise(sel: list[dict]) -> dict:
    """The figures of a set of runs: runs, lost, held share, mean/median MSE and max error over the runs with a
    matched track, false tracks per run, mean/median confirmation frame, the median run's ms per frame (a first
    run's compilation left out)."""
    found = [r for r in sel if not r["lost"]]
    mse = np.array([r["mse"] for r in found], float)
    mx = np.array([r["max_error"] for r in found], float)
    conf = np.array([r["confirmation_frame"] for r in found], float)

    def stat(f, a):
        return float(f(a)) if a.size else float("nan")

    return dict(runs=len(sel), lost=len(sel) - len(found), held=sum(r["held"] for r in sel) / max(len(sel), 1),
                mse_mean=stat(np.mean, mse), mse_median=stat(np.median, mse),
                max_mean=stat(np.mean, mx), max_median=stat(np.median, mx),
                false_tracks=float(np.mean([r["false_tracks"] for r in sel])) if sel else float("nan"),
                confirm_mean=stat(np.mean, conf), confirm_median=stat(np.median, conf),
                ms_per_frame=float(np.median([1000 * r["seconds"] / r["frames"] for r in sel])) if sel else
                float("nan"))


def _select(results, table="main", **where) -> list[dict]:
    return [r for r in results if r["table"] == table and all(r[k] == v for k, v in where.items())]


def _f(v: float, digits: int = 4) -> str:
    return "–" if v != v else f"{v:.{digits}g}" if abs(v) >= 1000 else f"{v:.{digits}f}"


def _thesis(key) -> str:
    if key not in THESIS_TABLES:
        return "–"
    v = THESIS_TABLES[key]
    if v is None:
        return THESIS_NOTES.get(key, "NO TRACK")
    note = THESIS_NOTES.get(key)
    return f"{v[0]:g} / {v[1]:g}" + (f" ({note})" if note else "")


def _ours(s: dict) -> str:
    """mean max error / mean MSE, and lost k/runs."""
    if s["runs"] == s["lost"]:
        return f"lost {s['lost']}/{s['runs']}"
    text = f"{_f(s['max_mean'], 3)} / {_f(s['mse_mean'], 3)}"
    return text + (f", lost {s['lost']}/{s['runs']}" if s["lost"] else "")


def _present(results) -> list[tuple]:
    keys = {(r["wall"], r["motion"], r["delta"]) for r in results if r["table"] == "main"}
    return [c for c in cells() if c in keys] + sorted(keys - set(cells()))


def overview_table(results, method: str = FLAGSHIP) -> list[str]:
    """Tables 4.6–4.8 in the thesis's layout: per wall × motion and Δ, our mean max error / mean MSE (the
    thesis's single run beside)."""
    present = _present(results)
    deltas = [d for d in sorted({c[2] for c in present}, reverse=True)]
    lines = ["| data | " + " | ".join(f"Δ={d:g}" for d in deltas) + " |", "|---" * (len(deltas) + 1) + "|"]
    for wall, motion in AVAILABLE:
        if not any(c[:2] == (wall, motion) for c in present):
            continue
        row = []
        for d in deltas:
            sel = _select(results, method=method, wall=wall, motion=motion, delta=d)
            row.append(f"{_ours(summarise(sel))} ({_thesis((wall, motion, d))})" if sel else
                       f"({_thesis((wall, motion, d))})" if (wall, motion, d) in THESIS_TABLES else "–")
        lines.append(f"| {wall} Motion {motion} | " + " | ".join(row) + " |")
    return lines


def snr_table(results) -> list[str]:
    lines = ["| wall | Δ | Δ/σ (ours) | Δ/(100σ) (ours) | thesis mean SNR (Tables 4.1–4.3) = Δ/(100σ) | "
             "σ (ours, counts) |",
             "|---|---|---|---|---|---|"]
    for wall in ("S1", "S2"):
        for d in sorted({r["delta"] for r in results if r["wall"] == wall and r["table"] == "main"}, reverse=True):
            sel = [r for r in results if r["wall"] == wall and r["delta"] == d]
            th = THESIS_SNR[wall].get(int(d)) if float(d).is_integer() else None
            lines.append(f"| {wall} | {d:g} | {np.mean([r['snr'] for r in sel]):.2f} | "
                         f"{np.mean([r['snr_thesis'] for r in sel]):.4f} | {'–' if th is None else f'{th:.4f}'} | "
                         f"{np.mean([r['sigma'] for r in sel]):.2f} |")
    return lines


def cell_tables(results, chosen) -> list[str]:
    lines = []
    for wall, motion in AVAILABLE:
        deltas = [c[2] for c in _present(results) if c[:2] == (wall, motion)]
        if not deltas:
            continue
        lines += ["", f"### {wall} Motion {motion}", "",
                  "| Δ | method | runs | lost | held (MSE < 1 px²) | MSE mean / median px² | "
                  "max error mean / median px "
                  "| thesis max / MSE | false tracks / run | confirmation frame mean / median | ms/frame |",
                  "|---|---|---|---|---|---|---|---|---|---|---|"]
        for d in deltas:
            for m in chosen:
                sel = _select(results, method=m, wall=wall, motion=motion, delta=d)
                if not sel:
                    continue
                s = summarise(sel)
                n = sel[0]["settings"].get("n_particles")
                name = m + (f" (N {n})" if n else "")
                lines.append(
                    f"| {d:g} | {name} | {s['runs']} | {s['lost']}/{s['runs']} | {100 * s['held']:.0f}% | "
                    f"{_f(s['mse_mean'])} / {_f(s['mse_median'])} | {_f(s['max_mean'], 3)} / {_f(s['max_median'], 3)} "
                    f"| {_thesis((wall, motion, d)) if m == FLAGSHIP else ''} | {s['false_tracks']:.2f} | "
                    f"{_f(s['confirm_mean'], 1)} / {_f(s['confirm_median'], 1)} | {s['ms_per_frame']:.2f} |")
    return lines


def sweep_tables(results) -> list[str]:
    """Tables 4.9–4.11: one table per sweep and setup that ran, beside the thesis's values."""
    lines = []
    labels = {"N": "N (particles per candidate)", "S": "S (s_drift, frames)", "C": "C (process noise, px)"}
    for name, sweep in SWEEPS.items():
        for wall, motion, delta in sweep["setups"]:
            sel_all = [r for r in results if r["table"] == name and (r["wall"], r["motion"], r["delta"]) ==
                       (wall, motion, delta)]
            if sel_all:
                lines += sweep_table(name, sweep, labels[name], (wall, motion, delta), sel_all)
    return lines


def sweep_table(name: str, sweep: dict, label: str, setup: tuple, sel_all: list[dict]) -> list[str]:
    """One sweep's table for one setup: MSE mean / median, max error, lost and held runs per value."""
    wall, motion, delta = setup
    lines = ["", f"### Table {sweep['table']}: MSE vs {label}; {wall} Motion {motion}, Δ {delta}", "",
             f"| {name} | thesis MSE (10 runs) | MSE mean / median px² | max error mean px | runs | lost | held |",
             "|---|---|---|---|---|---|---|"]
    for value in sorted({r["settings"][sweep["param"]] for r in sel_all}):
        sel = [r for r in sel_all if r["settings"][sweep["param"]] == value]
        s = summarise(sel)
        th = sweep["thesis"].get(value, "–")
        th = "No track" if th is None else th if isinstance(th, str) else f"{th:g}"
        lines.append(f"| {value:g} | {th} | {_f(s['mse_mean'])} / {_f(s['mse_median'])} | "
                     f"{_f(s['max_mean'], 3)} | {s['runs']} | {s['lost']}/{s['runs']} | {100 * s['held']:.0f}% |")
    return lines


def _compare(results, a: str, b: str) -> str | None:
    """``a`` against ``b`` over the cells both ran: held shares, then median MSE where both hold."""
    more, fewer, same, lower, higher = [], [], [], [], []
    for key in _present(results):
        w, m, d = key
        sa, sb = _select(results, method=a, wall=w, motion=m, delta=d), _select(results, method=b, wall=w,
                                                                                 motion=m, delta=d)
        if not sa or not sb:
            continue
        ha, hb = summarise(sa), summarise(sb)
        name = f"{w} M{m} Δ={d:g}"
        (more if ha["held"] > hb["held"] else fewer if ha["held"] < hb["held"] else same).append(name)
        both = [r["mse"] for r in sa if r["held"]], [r["mse"] for r in sb if r["held"]]
        if both[0] and both[1]:
            (lower if np.median(both[0]) < np.median(both[1]) else higher).append(name)
    n = len(more) + len(fewer) + len(same)
    if not n:
        return None

    def names(v):
        return f" ({', '.join(v)})" if v else ""

    fewer_text = f"in fewer in {len(fewer)}{names(fewer)}" if len(fewer) * 2 <= n else \
        f"in fewer in the other {len(fewer)}"
    return (f"Against {b}, {a} holds the target (MSE < 1 px²) in more runs in {len(more)} of {n} cells"
            f"{names(more)}, in as many in {len(same)}{names(same)} and {fewer_text}; "
            f"where both hold it in some runs, {a}'s median MSE of its held runs is lower in {len(lower)} cells"
            f"{names(lower)} and higher in {len(higher)}{names(higher)}.")


def wins_paragraph(results, chosen) -> list[str]:
    if "sgds" not in chosen:
        return []
    held = {m: np.mean([r["held"] for r in _select(results, method=m)]) for m in chosen if _select(results, method=m)}
    lost = {m: np.mean([r["lost"] for r in _select(results, method=m)]) for m in held}
    text = [f"{_compare(results, 'sgds', other)}" for other in chosen if other != "sgds"
            and _compare(results, "sgds", other)]
    text.append("Over all cells: held in " + ", ".join(f"{100 * held[m]:.0f}% ({m})" for m in held) +
                " of the runs; no track on the target in " + ", ".join(f"{100 * lost[m]:.0f}% ({m})" for m in lost)
                + ".")
    return ["", "## Where SGDS-PF wins / loses", "", " ".join(text)]


def tables_markdown(results: list[dict], command: str, chosen, runs: int, compare_runs: int | None,
                    seconds: float | None = None, seed: int = 0) -> str:
    """The whole report."""
    from .bench import machine_description

    others = [m for m in chosen if m != FLAGSHIP]
    per = f"{runs} runs per cell for {FLAGSHIP}" if FLAGSHIP in chosen else ""
    if others:
        per += ("; " if per else "") + f"{compare_runs or runs} for {', '.join(others)}"
    sweep_runs = min(runs, SWEEP_RUNS)
    seed_text = f"{seed} + r" if seed else "r"
    lines = ["# Güler 2016 (METU MSc thesis, Ch. 4) on the guler2016 scenario", "", f"Command: `{command}`", "",
             f"Runs: {per} (run r = 0, 1, …: `simulate_guler2016(wall, motion, Δ, seed={seed_text})` and the same "
             "tracker seed); "
             f"the sweeps {sweep_runs} runs per value. "
             + (f"Wall time {seconds:.0f} s on {machine_description()}. " if seconds is not None else "")
             + "The thesis's walls (two real recordings) are not public: ours are synthetic, one fixed recording "
             "per wall, the runs differ in the noise (tbd_taichi/guler2016.py). The thesis's values are single "
             "runs, ours means over runs.", "",
             f"{FLAGSHIP}: its defaults for every Δ (N 5000; the thesis retuned α, B, the motion term and N per Δ), "
             "the confirmed filter's whole path (`paths=whole`, rows from frame 3). sgds, pf: their defaults, "
             "`make_tracker`'s profile auto (the real-video settings for the uint16 frames).", "",
             "Scores: the track matched to the target is the one with the most rows within 5 px of it; its MSE "
             "(Eq. 4.1b, mean squared Euclidean error, px²) and max error (px) over the frames where both have a "
             "row. No track within 5 px: the run is lost (left out of the means, 'lost k/runs'). Held: MSE < 1 px². "
             "False tracks: tracks whose rows are mostly ≥ 5 px from the target. Confirmation frame: the 0-based "
             "frame of the `update` call that first returned a row of the matched track (tophat-pf returns its "
             "earlier rows at that call; sgds reports with a 2-frame lag).", "",
             f"## Tables 4.6–4.8: {FLAGSHIP}, mean max error px / mean MSE px² (thesis)", ""]
    if FLAGSHIP in chosen:
        lines += overview_table(results)
    lines += ["", "## SNR per Δ (Tables 4.1–4.3)", "",
              "The thesis's SNR equals Δ/(100σ): the √N_B of Eq. 4.1a is missing (tbd_taichi/guler2016.py); "
              "Δ/σ is the conventional SNR.", ""] + snr_table(results)
    lines += ["", "## Tables 4.6–4.8 per method"] + cell_tables(results, chosen)
    if any(r["table"] != "main" for r in results):
        lines += ["", f"## Parameter studies (Tables 4.9–4.11), {FLAGSHIP}", "",
                  "The thesis does not state the setups; the project's notes guess S1 Δ 30 Motion 1 for N and C "
                  "and S1 Motion 2 Δ 20 for S. Other parameters at their defaults (S = 80, C = 0.5, N = 5000)."]
        lines += sweep_tables(results)
    lines += wins_paragraph(results, chosen)
    return "\n".join(lines) + "\n"


def write_report(results: list[dict], out_dir: Path, command: str, chosen, runs: int, compare_runs: int | None,
                 seconds: float | None = None, seed: int = 0) -> Path:
    """guler2016.md (:func:`tables_markdown`)."""
    out_dir.mkdir(exist_ok=True)
    report = out_dir / "guler2016.md"
    report.write_text(tables_markdown(results, command, chosen, runs, compare_runs, seconds, seed))
    return report
