"""evaluate-suite --scenario guler2016 (Güler 2016, Tables 4.6–4.11): the plan, the summary, the report beside the
thesis's values, early argument errors and one quick run end to end."""
import json
import math

import numpy as np
import pytest

from tbd_taichi import cli, suite_guler2016 as sg


def test_thesis_tables_cover_the_available_cells():
    cells = sg.cells()
    assert len(cells) == 9 + 7 + 8 + 2 and set(sg.THESIS_TABLES) == set(cells)
    assert sg.THESIS_TABLES[("S1", 1, 30)] == (3.4665, 0.1742) and sg.THESIS_TABLES[("S2", 1, 10)] is None
    assert [len(s["thesis"]) for s in sg.SWEEPS.values()] == [15, 11, 7]


def test_plan_runs_per_method_and_the_sweeps():
    todo = sg.plan(("tophat-pf", "sgds"), runs=20, compare_runs=3, seed=5)
    main = [r for r in todo if r["table"] == "main"]
    assert sum(r["method"] == "tophat-pf" for r in main) == 26 * 20
    assert sum(r["method"] == "sgds" for r in main) == 26 * 3
    assert {r["seed"] for r in main} == set(range(5, 25))
    assert all(r["settings"] == {} for r in main)  # the defaults for every Δ (issue 40)
    sweeps = [r for r in todo if r["table"] != "main"]
    assert len(sweeps) == (15 + 2 * 11 + 2 * 7) * sg.SWEEP_RUNS and {r["method"] for r in sweeps} == {"tophat-pf"}
    hard = {(r["table"], r["wall"], r["motion"], r["delta"]) for r in sweeps if r["delta"] == 15}
    assert hard == {("S", "S1", 2, 15), ("C", "S1", 1, 15)}  # S and C again where the filter must coast
    assert not [r for r in sg.plan(("pf",), runs=2) if r["table"] != "main"]  # sweeps only with tophat-pf


def fake(method, mse, delta=30, lost=False, confirm=20, false=0):
    return dict(table="main", method=method, wall="S1", motion=1, delta=delta, seed=0, settings={}, frames=134,
                seconds=0.134, mse=float("nan") if lost else mse, max_error=float("nan") if lost else 2 * mse,
                scored_frames=0 if lost else 131, track_id=None if lost else 1, lost=lost,
                held=not lost and mse < 1.0, confirmation_frame=None if lost else confirm, tracks=1,
                false_tracks=false, sigma=9.2, snr=delta / 9.2, snr_thesis=delta / 920)


def test_summary_leaves_lost_runs_out_of_the_means():
    s = sg.summarise([fake("sgds", 0.1, confirm=10), fake("sgds", 3.0, confirm=30, false=2),
                      fake("sgds", 0, lost=True)])
    assert s["runs"] == 3 and s["lost"] == 1 and s["held"] == pytest.approx(1 / 3)
    assert s["mse_mean"] == pytest.approx(1.55) and s["max_mean"] == pytest.approx(3.1)
    assert s["confirm_median"] == 20 and s["false_tracks"] == pytest.approx(2 / 3)
    assert s["ms_per_frame"] == pytest.approx(1.0)


def test_report_beside_the_thesis_and_the_wins_paragraph():
    results = [fake("tophat-pf", 0.05), fake("tophat-pf", 0.07), fake("sgds", 0.02), fake("sgds", 0, lost=True)]
    text = sg.tables_markdown(results, "cmd", ("tophat-pf", "sgds"), 2, None)
    assert "| S1 Motion 1 | 0.120 / 0.060 (3.4665 / 0.1742) |" in text
    assert "| 30 | sgds | 2 | 1/2 | 50% |" in text and "| 30 | tophat-pf | 2 | 0/2 | 100% |" in text
    assert "| S1 | 30 | 3.26 | 0.0326 | 0.0328 |" in text
    assert "## Where SGDS-PF wins / loses" in text and "in as many in 0 and in fewer in the other 1;" in text
    assert "sgds's median MSE of its held runs is lower in 1 cells (S1 M1 Δ=30)" in text


def test_a_sweep_gets_one_table_per_setup():
    """Table 4.10 at S1 Motion 2 Δ 20 and again at Δ 15: each table holds its own setup's runs only."""
    runs = [dict(fake("tophat-pf", mse, delta=d), table="S", motion=2, settings={"s_drift": s})
            for d, s, mse in ((20, 3, 0.02), (20, 50, 0.03), (15, 3, 9.0), (15, 50, 0.1))]
    text = "\n".join(sg.sweep_tables(runs))
    assert text.count("### Table 4.10") == 2
    first, second = text.split("Motion 2, Δ 15")
    assert "Motion 2, Δ 20" in first and "| 3 | 0.1667 | 0.0200 / 0.0200 |" in first and "9.0000" not in first
    assert "| 3 | 0.1667 | 9.0000 / 9.0000 |" in second and "| 50 | 0.0985 | 0.1000 / 0.1000 |" in second


@pytest.mark.parametrize("argv, message", [
    (["--methods", "tophat-pf,ma-rs"], "--scenario guler2016 evaluates --methods of tophat-pf,sgds,pf"),
    (["--methods", "nope"], "--methods takes a comma list of"),
    (["--methods", "tophat-pf", "--out-dir", "FILE"], "is a file; give a folder"),
    (["--methods", "tophat-pf", "--out-dir", "missing/deeper"], "missing"),
])
def test_bad_arguments_are_one_line(tmp_path, capsys, argv, message):
    (tmp_path / "FILE").write_text("x")
    argv = [str(tmp_path / a) if a in ("FILE", "missing/deeper") else a for a in argv]
    assert cli.main(["evaluate-suite", "--scenario", "guler2016", *argv]) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1 and "Traceback" not in err


def test_bad_runs_and_foreign_compare_runs(capsys):
    with pytest.raises(SystemExit) as exc:
        cli.main(["evaluate-suite", "--scenario", "guler2016", "--methods", "tophat-pf", "--runs", "0"])
    assert exc.value.code == 2 and "--runs" in capsys.readouterr().err
    assert cli.main(["evaluate-suite", "--methods", "sgds", "--compare-runs", "2"]) == 2
    assert "--compare-runs applies to --scenario guler2016" in capsys.readouterr().err


def test_quick_suite_end_to_end(tmp_path, capsys):
    out = tmp_path / "g16"
    assert cli.main(["evaluate-suite", "--scenario", "guler2016", "--methods", "tophat-pf", "--quick",
                     "--out", str(out), "--no-progress"]) == 0
    data = json.loads((out / "guler2016_runs.json").read_text())
    runs = data["runs"]
    assert "--scenario guler2016" in data["command"]
    assert len(runs) == 2 + 3 * 2 and {r["table"] for r in runs} == {"main", "N", "S", "C"}
    assert all(math.isfinite(r["mse"]) and math.isfinite(r["max_error"]) for r in runs)  # held at Δ 30
    assert all(r["confirmation_frame"] is not None and 3 <= r["confirmation_frame"] < 134 for r in runs)
    text = (out / "guler2016.md").read_text()
    assert "(3.4665 / 0.1742)" in text and "| 1000 | 0.35629 |" in text and "| 10 | 0.1598 |" in text
    assert "| 0.5 | 0.3424 |" in text
    main = [r for r in runs if r["table"] == "main"]
    held = np.mean([r["mse"] < 1.0 for r in main])
    assert f"| 30 | tophat-pf | 2 | 0/2 | {100 * held:.0f}% | {np.mean([r['mse'] for r in main]):.4f} /" in text
