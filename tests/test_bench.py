"""``tbd-taichi bench``: the JSON contract, and that a result names where it was measured."""
import json

import pytest

from tbd_taichi import bench
from tbd_taichi.bench import format_table, run_bench
from tbd_taichi.methods.sgds import PIPELINE_STAGES


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


def test_paired_runs_give_the_engines_each_frame_in_turn(monkeypatch):
    """--paired: within a run both trackers exist and take every frame in turn, the order reversed from one frame to
    the next and from one run to the next; without it, one engine's whole run, then the other's."""
    calls = []

    def recording_stepper(shape, snr, engine, frontend_process=False, method="sgds", settings=None):
        def step(frame):
            calls.append(engine)
            return {"normalise": 1e-3}
        return step, lambda: None

    monkeypatch.setattr(bench, "pipeline_stepper", recording_stepper)
    n = 3 + bench.WARMUP
    result = run_bench((32, 32), snr=3.0, n_frames=3, runs=2, paired=True)
    run_1 = ["taichi", "numpy", "numpy", "taichi"] * (n // 2)  # n is even: frames 0, 1 | 2, 3 | …
    run_2 = ["numpy", "taichi", "taichi", "numpy"] * (n // 2)
    assert n % 2 == 0 and calls == run_1 + run_2 and result["paired"]
    assert result["engines"]["taichi"]["run_update_ms"] and len(result["engines"]["numpy"]["run_update_ms"]) == 2
    calls.clear()
    run_bench((32, 32), snr=3.0, n_frames=3, runs=2)
    assert calls == ["taichi"] * n + ["numpy"] * n + ["numpy"] * n + ["taichi"] * n


def test_threads_reach_the_benchmarks_backend(monkeypatch):
    """--threads: the benchmark's CPU backend runs that many worker threads (it used to start its own with every
    core), and the result and its table say how many."""
    from tbd_taichi import backend

    monkeypatch.setattr(bench, "pipeline_stepper", lambda *a, **k: (lambda frame: {"normalise": 1e-3}, lambda: None))
    try:
        result = run_bench((32, 32), snr=3.0, n_frames=2, threads=1)
        assert result["threads"] == 1 == backend.cpu_threads()
        assert ", 1 thread(s)" in format_table(result).splitlines()[0]
    finally:
        backend.init("cpu")
    assert run_bench((32, 32), snr=3.0, n_frames=2)["threads"] == backend.cpu_threads()


@pytest.mark.slow
def test_cpu_results_split_update_into_kernel_launches_and_host_work():
    """kernels_ms: the median time in kernel launches (none for the NumPy engine), kernel_ms per kernel; host_ms:
    the rest of update.  Both in the table, without a ratio (NumPy's host work is its whole update)."""
    result = run_bench((64, 64), snr=3.0, n_frames=4, paired=True)
    taichi, numpy = result["engines"]["taichi"], result["engines"]["numpy"]
    assert numpy["kernels_ms"] == 0 and numpy["host_ms"] == pytest.approx(numpy["update_ms"]) and not numpy["kernel_ms"]
    assert {"frame_to_first_layer", "second_layer_and_lef"} <= set(taichi["kernel_ms"])  # the saliency launches
    assert all(v > 0 for v in taichi["kernel_ms"].values())
    assert 0 < taichi["kernels_ms"] < max(taichi["run_update_ms"]) * 2 and 0 < taichi["host_ms"] < taichi["update_ms"]
    rows = {line.split()[0]: line.split() for line in format_table(result).splitlines()[3:]}
    assert len(rows["kernels"]) == len(rows["host"]) == 3 and rows["update"][-1].endswith("x")
    assert "engines frame by frame in turn" in format_table(result)
