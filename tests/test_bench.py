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
