"""``tbd-taichi bench``: the JSON contract, and that a result names where it was measured."""
import json

import pytest

from tbd_taichi.bench import format_table, run_bench
from tbd_taichi.sgds import PIPELINE_STAGES


@pytest.mark.slow
def test_pipeline_bench_reports_every_stage_for_both_engines_and_the_machine():
    """Both engines on the same frames: each pipeline stage's median ms, their sum, the update's wall time and
    fps, peak memory; the machine and versions; a table with the NumPy/Taichi ratio per stage."""
    result = run_bench((64, 64), snr=3.0, n_frames=3)
    assert json.loads(json.dumps(result)) == result  # JSON-ready
    assert "CPUs" in result["machine"] and set(result["versions"]) == {"python", "taichi", "numpy"}
    assert result["versions"]["taichi"].startswith("1.7")
    for name in ("taichi", "numpy"):
        engine = result["engines"][name]
        assert list(engine["stages"]) == list(PIPELINE_STAGES)
        assert all(v > 0 for v in engine["stages"].values())
        assert engine["total"] == pytest.approx(sum(engine["stages"].values()))
        assert engine["update_ms"] > 0 and engine["fps"] == pytest.approx(1e3 / engine["update_ms"])
        assert engine["peak_rss_mib"] > 50
    lines = format_table(result).splitlines()
    assert lines[1] == f"on {result['machine']}"
    total = next(line for line in lines if line.startswith("total")).split()
    ratio = result["engines"]["numpy"]["total"] / result["engines"]["taichi"]["total"]
    assert total[-1] == f"{ratio:.1f}x"


@pytest.mark.slow
def test_runs_alternate_the_engines_and_report_each_run():
    """--runs 2: every run's median update time per engine and their ratio; the stage medians pool both runs."""
    result = run_bench((64, 64), snr=3.0, n_frames=3, runs=2)
    taichi, numpy = result["engines"]["taichi"], result["engines"]["numpy"]
    assert result["runs"] == 2 and len(taichi["run_update_ms"]) == len(numpy["run_update_ms"]) == 2
    assert result["run_ratios"] == pytest.approx([n / t for n, t in zip(numpy["run_update_ms"], taichi["run_update_ms"])])
    assert min(taichi["run_update_ms"]) <= taichi["update_ms"] <= max(taichi["run_update_ms"])
    table = format_table(result)
    assert "2 runs each" in table and "numpy/taichi per run: " in table
    with pytest.raises(ValueError, match="runs must be"):
        run_bench((64, 64), runs=0)
