"""The Monte Carlo evaluation suite: plan, resumable execution, summary, report and CLI."""
import json

import numpy as np
import pytest

from tbd_taichi import cli, suite


def test_plan_pairs_methods_on_the_same_scenarios():
    runs = suite.plan(snrs=(1.2, 2.0), sizes=((50, 70),), methods=("sgds", "pf"), tests=3, seed=10)
    assert len(runs) == 12 and len({r.key for r in runs}) == 12
    assert {r.seed for r in runs} == {10, 11, 12}
    by_seed = {(r.snr, r.test): {x.method for x in runs if (x.snr, x.test) == (r.snr, r.test)} for r in runs}
    assert all(m == {"sgds", "pf"} for m in by_seed.values())


def fake(run, dsr, edt=0.5):
    return dict(vars(run), key=run.key, dsr=dsr, edt=edt, false_tracks=1 if dsr < 0.2 else 0, ospa=1.0,
                ms_per_frame=10.0)


def test_summary_follows_eqs_47_to_49():
    runs = suite.plan(snrs=(1.4,), sizes=((50, 70),), methods=("sgds",), tests=4)
    results = [fake(r, d, e) for r, d, e in zip(runs, [0.9, 0.5, 0.1, 0.2], [0.4, 0.6, 3.0, 9.0])]
    (row,) = suite.summarise(results)
    assert row["tsr"] == 0.5  # DSR > T1 = 0.2 in two of four runs (Eq. 49, strict)
    assert row["edt"] == pytest.approx(0.5)  # EDT over the successful runs only
    assert row["dsr"] == pytest.approx(0.425) and row["false_tracks"] == 0.25


def test_execute_keeps_finished_runs_and_resumes(tmp_path, monkeypatch):
    runs = suite.plan(snrs=(1.4, 2.0), sizes=((50, 70),), methods=("sgds",), tests=2)
    calls = []

    def interrupted(run):
        if len(calls) == 2:
            raise KeyboardInterrupt
        calls.append(run.key)
        return fake(run, 0.9)

    monkeypatch.setattr(suite, "run_one", interrupted)
    path = tmp_path / "runs.jsonl"
    results, completed = suite.execute(runs, path, workers=1, progress=False)
    assert not completed and [r["key"] for r in results] == calls
    monkeypatch.setattr(suite, "run_one", lambda run: fake(run, 0.3))
    results, completed = suite.execute(runs, path, workers=1, progress=False)
    assert completed and len(results) == 4
    assert [r["dsr"] for r in results] == [0.9, 0.9, 0.3, 0.3]  # the first two were not rerun
    assert len(path.read_text().splitlines()) == 4
    report = suite.write_report(results, tmp_path, "cmd", True, 4)
    text = report.read_text()
    assert "| 50×50×70 | 1.4 | SGDS-PF | 1.4 | 8,000 | 2 | 1.00 |" in text  # Table 2: 8,000 searching particles
    assert "Runs made on: unrecorded machine" in text
    assert (tmp_path / "suite_50x50.png").stat().st_size > 5000


def test_tracker_snr_preset_is_its_own_condition():
    """--tracker-snr runs are keyed apart from the paper's matched presets (so both can share a
    results file) and the table names the preset and its particle numbers (Tables 2 and 3)."""
    matched = suite.plan(snrs=(1.8,), sizes=((200, 150),), tests=1)
    fixed = suite.plan(snrs=(1.8,), sizes=((200, 150),), tests=1, preset_snr=1.4)
    assert not {r.key for r in matched} & {r.key for r in fixed}
    rows = suite.summarise([fake(r, 0.9) for r in matched + fixed])
    assert [r["preset"] for r in rows] == [[1.4, 1.8], [1.4, 1.8]]
    table = suite.markdown_table(suite.summarise([fake(r, 0.9) for r in fixed]))
    assert "| SGDS-PF | 1.4 | 32,000 |" in table and "| original PF | 1.4 | 30,000 |" in table
    assert suite.configured_particles("pf", 200, 1.8) == 20_000
    assert suite.configured_particles("sgds", 200, 1.8) == 6_000  # one 200-px block


def test_one_real_run_scores_the_tracker():
    (run,) = suite.plan(snrs=(3.0,), sizes=((40, 40),), methods=("sgds",), tests=1, seed=2)
    row = suite.run_one(run)
    assert row["dsr"] > 0.6 and row["edt"] < 1.0 and row["false_tracks"] == 0 and row["ms_per_frame"] > 0


def test_cli_evaluate_suite(tmp_path, capsys):
    out = tmp_path / "res"
    assert cli.main(["evaluate-suite", "--snrs", "3", "--size", "50", "--tests", "1", "--workers", "1",
                     "--methods", "pf", "--no-progress", "--out-dir", str(out)]) == 0
    summary = json.loads((out / "suite.json").read_text())
    (row,) = summary["rows"]
    assert row["method"] == "pf" and row["n"] == 1 and np.isfinite(row["ms_per_frame"])
    assert "evaluate-suite" in summary["command"]
    (stored,) = [json.loads(line) for line in (out / "suite_runs.jsonl").read_text().splitlines()]
    assert "CPUs" in stored["machine"] and stored["workers"] == 1
    assert cli.main(["evaluate-suite", "--methods", "kalman", "--out-dir", str(out)]) == 2
    assert "--methods" in capsys.readouterr().err
    with pytest.raises(SystemExit) as usage:  # argparse's own one-line error
        cli.main(["evaluate-suite", "--tracker-snr", "0", "--out-dir", str(out)])
    assert usage.value.code == 2
    assert "--tracker-snr" in capsys.readouterr().err


def test_param_settings_are_their_own_condition_and_reach_the_tracker(tmp_path, capsys, monkeypatch):
    """--param runs are keyed and summarised apart from the presets' (a results file may hold both); the table
    names the setting and counts its particles; a real run's tracker gets it; a bad name, value or scenario is one
    line before any run."""
    preset = suite.plan(snrs=(1.4,), sizes=((200, 150),), methods=("sgds",), tests=2)
    fewer = suite.plan(snrs=(1.4,), sizes=((200, 150),), methods=("sgds",), tests=2, params={"N_sump": 6000})
    assert not {r.key for r in preset} & {r.key for r in fewer}
    assert fewer[0].key.endswith("/N_sump=6000") and fewer[0].params == (("N_sump", 6000),)
    rows = suite.summarise([fake(r, 0.9) for r in preset] + [fake(r, 0.1) for r in fewer])
    assert [(r["params"], r["tsr"]) for r in rows] == [((), 1.0), ((("N_sump", 6000),), 0.0)]
    table = suite.markdown_table(rows)
    assert "| SGDS-PF | 1.4 | 32,000 |" in table and "| SGDS-PF (N_sump=6000) | 1.4 | 24,000 |" in table
    from tbd_taichi import methods

    made, make = [], methods.make_tracker
    monkeypatch.setattr(methods, "make_tracker", lambda *a, **kw: made.append(kw) or make(*a, **kw))
    (run,) = suite.plan(snrs=(3.0,), sizes=((40, 40),), methods=("pf",), tests=1, params={"n_particles": 700})
    assert suite.run_one(run)["params"] == [["n_particles", 700]]  # JSON's shape, as the runs file holds it
    assert made and all(kw["n_particles"] == 700 for kw in made)
    monkeypatch.undo()
    out = tmp_path / "res"
    assert cli.main(["evaluate-suite", "--snrs", "3", "--size", "50", "--tests", "1", "--workers", "1",
                     "--methods", "pf", "--param", "n_particles=700", "--no-progress", "--out-dir", str(out)]) == 0
    (stored,) = [json.loads(line) for line in (out / "suite_runs.jsonl").read_text().splitlines()]
    assert stored["params"] == [["n_particles", 700]] and stored["key"].endswith("/n_particles=700")
    assert "--param n_particles=700" in json.loads((out / "suite.json").read_text())["command"]
    capsys.readouterr()
    for argv, message in ((["--methods", "sgds,pf", "--param", "N_sump=6000"], "unknown original PF parameter"),
                          (["--methods", "sgds", "--param", "N_sump=6"], "N_sump = 6 must be"),
                          (["--methods", "sgds", "--param", "snr=1.2"], "--tracker-snr"),
                          (["--scenario", "long2012", "--methods", "mm-phd", "--param", "births=10"],
                           "--param applies to --scenario jia2022")):
        assert cli.main(["evaluate-suite", *argv, "--out-dir", str(tmp_path / "bad")]) == 2
        err = capsys.readouterr().err.strip()
        assert message in err and len(err.splitlines()) == 1
    assert not (tmp_path / "bad").exists()
