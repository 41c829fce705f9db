"""Monte Carlo evaluation in the style of the SGDS-PF paper's section 3.3 (Figs. 14–15).

Conditions: SNR ∈ {1.2, 1.4, 1.6, 1.8, 2.0} × {50×50 with 70 frames, 200×200 with 150
frames} × N tests; methods SGDS-PF and the original PF (Table 3 particle numbers).  Test k
of every condition simulates scenario seed ``seed + k`` (one target that stays in view), so
both methods and all SNRs see the same trajectories.  Each tracker gets the condition's SNR
as its ``snr`` (Table 2 / Table 3 column), as in the paper.

Per condition and method: TSR (Eq. 49, T0 = 2 px, T1 = 0.2), mean EDT (Eq. 47, px, over
the frames where the target is detected within T0, runs with DSR > T1), mean DSR (Eq. 48),
confirmed false tracks per sequence and ms/frame.  Runs go to a JSON-lines file as they
finish, so an interrupted suite keeps (and a rerun skips) what is done.
"""
from __future__ import annotations

import json
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from . import metrics
from .bench import machine_description
from .errors import TBDError
from .progress import progress_bar

SNRS = (1.2, 1.4, 1.6, 1.8, 2.0)
SIZES = ((50, 70), (200, 150))  # (side px, frames)
DEFAULT_METHODS = ("sgds", "pf")  # the paper's comparison (any registered method may be given)
QUICK = dict(snrs=(1.4, 2.0), sizes=((50, 70), (200, 150)), tests=2)


@dataclass(frozen=True)
class Run:
    """One tracker on one simulated sequence."""

    method: str
    side: int
    frames: int
    snr: float
    test: int
    seed: int
    preset_snr: float = 0.0  # the trackers' snr parameter; 0: the condition's SNR
    explain: bool = False  # SGDS-PF: record which stage lost the target (methods/sgds/explain.py)
    params: tuple = ()  # (name, value) pairs over the tracker's preset (evaluate-suite --param), sorted

    @property
    def key(self) -> str:
        preset = f"/preset{self.preset_snr:g}" if self.preset_snr else ""
        return f"{self.method}/{self.side}/{self.snr:g}/{self.seed}{preset}" + ("/explain" if self.explain else "") \
            + (f"/{params_label(self.params)}" if self.params else "")


def params_label(params) -> str:
    """(name, value) pairs as "name=value,…" (a run's key, a table's method column)."""
    return ",".join(f"{k}={v:g}" if isinstance(v, float) else f"{k}={v}" for k, v in params)


def plan(snrs=SNRS, sizes=SIZES, methods=DEFAULT_METHODS, tests: int = 100, seed: int = 0, preset_snr: float = 0.0,
         explain: bool = False, params=None) -> list[Run]:
    """Every run of the suite; test k uses scenario seed ``seed + k``.  ``preset_snr`` > 0 gives
    every tracker that ``snr`` (Table 2 / Table 3 column) instead of the condition's SNR; ``explain`` records
    the stages of SGDS-PF's runs; ``params`` ({name: value}) sets parameters of every tracker over its preset."""
    pairs = tuple(sorted((params or {}).items()))
    return [Run(m, side, frames, float(snr), k, seed + k, float(preset_snr), explain and m == "sgds", pairs)
            for side, frames in sizes for snr in snrs for k in range(tests) for m in methods]


def edt_when_detected(tracks: np.ndarray, truth: np.ndarray, t0: float = metrics.T0) -> float:
    """Mean EDT (Eq. 47, px) over the frames where a track point lies within T0 of the target."""
    d = metrics.nearest_edt(tracks, truth)
    d = d[np.isfinite(d) & (d < t0)]
    return float(d.mean()) if d.size else float("nan")


_WARM: set = set()  # configurations this process has compiled


def run_one(run: Run) -> dict:
    """Simulate, track and score one run (a worker's job)."""
    from .methods import make_tracker
    from .simulate import simulate

    scene = simulate((run.side, run.side), frames=run.frames, snr=run.snr, seed=run.seed)
    preset, params = run.preset_snr or run.snr, dict(run.params)
    warm_up = (run.method, run.side, preset, run.params)
    if warm_up not in _WARM:  # compile this configuration's kernels outside the timing: the same run, untimed
        warm = make_tracker(run.method, (run.side, run.side), snr=preset, seed=run.seed, profile="paper", **params)
        for frame in scene.frames:  # whole: kernels first used late (the first hand-over, a track's step) too
            warm.update(frame)
        warm.finish()
        del warm
        _WARM.add(warm_up)
    tracker = make_tracker(run.method, (run.side, run.side), snr=preset, seed=run.seed, profile="paper", **params)
    recorder = None
    if run.explain:  # watches the tracker; the tracks are the same
        from .methods.sgds.explain import StageRecorder

        recorder = StageRecorder(tracker.tracker, scene.truth)
    t0 = time.perf_counter()
    for frame in scene.frames:
        tracker.update(frame)
    tracks = tracker.finish()
    ms = (time.perf_counter() - t0) / run.frames * 1e3
    scores = metrics.evaluate(tracks, scene.truth, n_frames=run.frames)
    row = dict(asdict(run), key=run.key, params=[list(p) for p in run.params],  # as the runs file holds it
               dsr=scores["dsr"], edt=edt_when_detected(tracks, scene.truth),
               false_tracks=int(scores["false_tracks"]), ospa=scores["ospa"], ms_per_frame=ms,
               machine=machine_description())
    if recorder is not None:
        from .methods.sgds.explain import explained_fields

        row.update(explained_fields(recorder, scene.truth, scores["dsr"]))
    return row


def load_runs(path: Path) -> dict[str, dict]:
    """Finished runs in a JSON-lines file, by key (a torn last line is ignored)."""
    done = {}
    if path.is_file():
        for line in path.read_text().splitlines():
            try:
                row = json.loads(line)
            except json.JSONDecodeError:
                continue
            done[row["key"]] = row
    return done


def execute(runs: list[Run], runs_file: Path, workers: int = 1, arch: str = "cpu", threads: int | None = None,
            progress: bool = True, scheduler: str | None = None, say=None) -> tuple[list[dict], bool]:
    """Run what ``runs_file`` lacks, appending each result as it finishes; returns (all results of
    ``runs``, completed).  ``workers``, ``threads`` and ``scheduler`` choose where (:class:`.executor.Fanout`;
    ``say`` gets one line naming it).
    Ctrl-C stops the workers and keeps the finished results; a run that fails raises a TBDError naming it
    (the runs finished before it are kept)."""
    from .executor import Fanout

    done = load_runs(runs_file)
    todo = [r for r in runs if r.key not in done]
    completed = True
    runs_file.parent.mkdir(parents=True, exist_ok=True)
    with open(runs_file, "a") as out, progress_bar("evaluation runs", progress, rate_unit="runs") as bar, \
            Fanout(workers, arch, threads, scheduler) as fanout:
        task = bar.add_task("runs", total=len(runs), completed=len(runs) - len(todo)) if bar is not None else None
        if say is not None:
            say(f"{len(todo)} run(s) to do on {fanout.describe()}")
        try:
            for outcome in fanout.run(run_one, todo):
                if outcome.error:
                    raise TBDError(f"run {outcome.item.key}: {outcome.error}")
                row = dict(outcome.value, workers=fanout.label)
                done[row["key"]] = row
                out.write(json.dumps(row) + "\n")
                out.flush()
                if bar is not None:
                    bar.advance(task)
        except KeyboardInterrupt:
            completed = False
    return [done[r.key] for r in runs if r.key in done], completed


def machine_label(result: dict) -> str:
    """Where a run was timed: the CPU and the number of parallel workers."""
    return f"{result.get('machine', 'unrecorded machine')}, {result.get('workers', '?')} worker(s)"


def summarise(results: list[dict]) -> list[dict]:
    """One row per (size, SNR, method, parameters set): n, TSR, mean EDT, mean DSR, false tracks/sequence,
    ms/frame."""
    rows = []

    def group(r) -> tuple:
        return r["side"], r["frames"], r["snr"], r["method"], tuple(tuple(p) for p in r.get("params") or ())

    keys = sorted({group(r) for r in results}, key=lambda k: (k[0], k[2], _rank(k[3]), k[4]))
    for side, frames, snr, method, params in keys:
        sel = [r for r in results if group(r) == (side, frames, snr, method, params)]
        presets = sorted({r.get("preset_snr") or r["snr"] for r in sel})
        machines = sorted({machine_label(r) for r in sel})
        dsr = np.array([r["dsr"] for r in sel], float)
        edt = np.array([r["edt"] for r in sel if r["dsr"] > metrics.T1], float)
        edt = edt[np.isfinite(edt)]
        rows.append(dict(side=side, frames=frames, snr=snr, method=method, params=params, preset=presets,
                         machines=machines,
                         n=len(sel), tsr=metrics.tsr(dsr),
                         edt=float(edt.mean()) if edt.size else float("nan"), dsr=float(np.nanmean(dsr)),
                         false_tracks=float(np.mean([r["false_tracks"] for r in sel])),
                         ms_per_frame=float(np.median([r["ms_per_frame"] for r in sel]))))
    return rows


def _rank(method: str) -> tuple:
    """A method's place in tables: the registry's listing order (unknown names last)."""
    from . import methods

    known = methods.names()
    return (known.index(method), "") if method in known else (len(known), method)


def method_title(method: str) -> str:
    from . import methods

    return methods.get(method).title if method in methods.names() else method


def configured_particles(method: str, side: int, preset: float, params=()) -> int:
    """Particles the tracker is configured with for a side × side frame at the ``preset`` SNR with ``params``
    ((name, value) pairs) over it (the method's ``particle_count``: the original PF's Table 3 count, SGDS-PF's
    N_sump × blocks); 0 if it does not say."""
    from . import methods

    spec = methods.get(method)
    shape = (side, side)
    return spec.particles(shape, spec.make_params(shape, snr=preset, **dict(params)))


def markdown_table(rows: list[dict]) -> str:
    """The summary table; where runs come from more than one machine, a last column numbers the
    machine behind each row's ms/frame (see :func:`machine_list`)."""
    machines = all_machines(rows)
    several = len(machines) > 1
    lines = ["| size | SNR | method | tracker snr | particles | tests | TSR | mean EDT (px) | mean DSR "
             "| false tracks / seq | ms/frame |" + (" machine |" if several else ""),
             "|---|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|" + ("---|" if several else "")]
    for r in rows:
        presets = r.get("preset") or [r["snr"]]
        params = r.get("params") or ()
        particles = "/".join(f"{configured_particles(r['method'], r['side'], v, params):,}" for v in presets)
        title = method_title(r["method"]) + (f" ({params_label(params)})" if params else "")
        lines.append(f"| {r['side']}×{r['side']}×{r['frames']} | {r['snr']:g} | {title} "
                     f"| {'/'.join(f'{v:g}' for v in presets)} | {particles} "
                     f"| {r['n']} | {r['tsr']:.2f} | {r['edt']:.2f} | {r['dsr']:.2f} | {r['false_tracks']:.2f} "
                     f"| {r['ms_per_frame']:.1f} |"
                     + (f" {', '.join(str(machines.index(m) + 1) for m in r.get('machines', []))} |" if several else ""))
    return "\n".join(lines)


def all_machines(rows: list[dict]) -> list[str]:
    return sorted({m for r in rows for m in r.get("machines", [])})


def machine_list(rows: list[dict]) -> str:
    """"Runs made on: …", numbered when there is more than one machine."""
    machines = all_machines(rows)
    if len(machines) <= 1:
        return "Runs made on: " + (machines[0] if machines else "no machine") + "."
    return "Runs made on: " + "; ".join(f"({k}) {m}" for k, m in enumerate(machines, 1)) + "."


def plot_figures(rows: list[dict], out_dir: Path) -> list[Path]:
    """Figs. 14–15 style: per image size, (a) TSR, (b) mean EDT, (c) ms/frame against SNR."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    paths = []
    for side in sorted({r["side"] for r in rows}):
        fig, axes = plt.subplots(1, 3, figsize=(12, 3.6))
        for method in sorted({r["method"] for r in rows}, key=_rank):
            sel = sorted((r for r in rows if r["side"] == side and r["method"] == method), key=lambda r: r["snr"])
            if not sel:
                continue
            snr = [r["snr"] for r in sel]
            for ax, col in zip(axes, ("tsr", "edt", "ms_per_frame")):
                ax.plot(snr, [r[col] for r in sel], "o-", label=method_title(method))
        for ax, title in zip(axes, ("(a) TSR", "(b) mean EDT (px)", "(c) time (ms/frame)")):
            ax.set_xlabel("SNR")
            ax.set_title(title)
            ax.grid(alpha=0.3)
        axes[0].set_ylim(-0.02, 1.02)
        axes[2].set_yscale("log")
        axes[0].legend()
        frames = next(r["frames"] for r in rows if r["side"] == side)
        fig.suptitle(f"{side}×{side} px, {frames} frames")
        fig.tight_layout()
        path = out_dir / f"suite_{side}x{side}.png"
        fig.savefig(path, dpi=110)
        plt.close(fig)
        paths.append(path)
    return paths


def write_report(results: list[dict], out_dir: Path, command: str, completed: bool, n_planned: int) -> Path:
    """suite.md (table, command, seed), suite.json (summary) and the PNG figures in ``out_dir``."""
    out_dir.mkdir(parents=True, exist_ok=True)
    rows = summarise(results)
    figures = plot_figures(rows, out_dir) if rows else []
    status = "" if completed else f"\n**Interrupted:** {len(results)} of {n_planned} runs finished; the table covers those.\n"
    text = "\n".join([
        "# Monte Carlo evaluation (SGDS-PF paper, section 3.3)", "",
        f"Reproduce with `{command}` (scenario seeds as below; reruns skip finished runs in `suite_runs.jsonl`).",
        status,
        "TSR: Eq. 49 with T0 = 2 px, T1 = 0.2. Mean EDT: Eq. 47 over frames detected within T0, runs with "
        "DSR > T1. False tracks: confirmed tracks whose points mostly lie ≥ 2 px from the target. ms/frame: median "
        "over runs of the tracker's update+finish time, one thread per worker.", "",
        machine_list(rows), "",
        markdown_table(rows), "",
        *[f"![{p.stem}]({p.name})" for p in figures], ""])
    path = out_dir / "suite.md"
    path.write_text(text)
    (out_dir / "suite.json").write_text(json.dumps(dict(command=command, completed=completed, rows=rows), indent=1))
    return path


def write_explained(results: list[dict], out_dir: Path, command: str) -> Path:
    """explain.md: SGDS-PF's missed and late runs split by the stage that lost the target
    (:mod:`.methods.sgds.explain`), and each such run's stage frames."""
    from .methods.sgds.explain import LATE_FRAMES, stage_table

    lost = [r for r in results if r.get("stage") not in (None, "detected")]
    lines = ["# Where SGDS-PF lost the target", "", f"Reproduce with `{command}`.", "",
             f"Missed: DSR ≤ {metrics.T1:g} (Eq. 49). Late: the tracks first come within {metrics.T0:g} px of the "
             f"target more than {LATE_FRAMES} frames after its first frame. Stages as in "
             "`tbd_taichi/methods/sgds/explain.py`.", "", stage_table(results), "",
             "| run | DSR | stage | candidate | hand-over | confirmed | drops | first detection |",
             "|---|---:|---|---:|---:|---:|---:|---:|"]
    lines += [f"| {r['key']} | {r['dsr']:.2f} | {r['stage']} | {r['candidate_at']} | {r['handover_at']} | "
              f"{r['confirmed_at']} | {r['drops']} | {r['detected_at']} |" for r in lost]
    path = out_dir / "explain.md"
    path.write_text("\n".join(lines) + "\n")
    return path
