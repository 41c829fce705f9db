"""The suite and batch-track on real Dask clusters (issue 42): a distributed.LocalCluster, and a `dask scheduler`
with two `dask worker` processes on 127.0.0.1, one of which is killed during the suite.  Per-run results must
equal the local process pool's, timing fields aside."""
import csv
import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("distributed", reason="the cluster extra: pip install '.[test,cluster]'")

from tbd_taichi import cli, suite  # noqa: E402
from tbd_taichi.executor import Fanout  # noqa: E402
from tbd_taichi.simulate import simulate  # noqa: E402

# SNR 2.0, 50x50 (70 frames), 4 tests, SGDS-PF and the PF: 8 runs
RUNS = suite.plan(snrs=(2.0,), sizes=((50, 70),), methods=("sgds", "pf"), tests=4, seed=0)
TIMING = {"ms_per_frame", "workers", "machine"}


def per_run(results):
    """Each run's scores by key, timing fields dropped (NaN as a string, so that equal NaNs compare equal)."""
    return {r["key"]: {k: (repr(v) if isinstance(v, float) else v) for k, v in r.items() if k not in TIMING}
            for r in results}


@pytest.fixture(scope="module")
def pool_results(tmp_path_factory):
    """The reference: the suite's runs on the local pool of 2 spawned processes."""
    results, completed = suite.execute(RUNS, tmp_path_factory.mktemp("pool") / "runs.jsonl", workers=2, progress=False)
    assert completed and len(results) == len(RUNS)
    return per_run(results)


def test_local_cluster_gives_the_pool_s_results(pool_results, tmp_path):
    results, completed = suite.execute(RUNS, tmp_path / "runs.jsonl", workers=2, progress=False,
                                       scheduler="local-dask")
    assert completed and per_run(results) == pool_results
    assert {r["workers"] for r in results} == {"2 (LocalCluster)"}


def test_a_worker_without_its_backend_fails_fast_on_a_cluster():
    from tbd_taichi import backend

    missing = next((a for a in backend.GPU_ARCHS if a not in backend.available_archs()), None)
    if missing is None:
        pytest.skip("every GPU backend is available here")
    with Fanout(workers=1, arch=missing, scheduler="local-dask") as fanout:
        outcomes = list(fanout.run(abs, [-1, -2]))
    assert len(outcomes) == 2 and all(o.fatal and "could not start" in o.error for o in outcomes)


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture
def dask_cluster(tmp_path):
    """A `dask scheduler` and two single-thread `dask worker` processes (no nanny: a killed worker stays dead);
    yields (address, {name: Popen}); every process is stopped by its id at the end."""
    port = free_port()
    address = f"tcp://127.0.0.1:{port}"
    logs = tmp_path / "dask-logs"
    logs.mkdir()
    started = []

    def start(name, *args):  # `dask scheduler ...`, `dask worker ...` by their modules (no PATH needed)
        log = open(logs / f"{name}.log", "w")
        proc = subprocess.Popen([sys.executable, "-m", f"distributed.cli.dask_{name.split('-')[0]}", *args],
                                stdout=log, stderr=subprocess.STDOUT, start_new_session=True)
        started.append(proc)
        return proc

    try:
        start("scheduler", "--host", "127.0.0.1", "--port", str(port), "--no-dashboard")
        workers = {f"worker-{k}": start(f"worker-{k}", address, "--nthreads", "1", "--no-nanny", "--no-dashboard",
                                        "--name", f"w{k}", "--host", "127.0.0.1") for k in (1, 2)}
        wait_for_workers(address, 2)
        yield address, workers
    finally:
        for proc in started:
            if proc.poll() is None:
                os.kill(proc.pid, signal.SIGTERM)
        for proc in started:
            try:
                proc.wait(timeout=5)
            except subprocess.TimeoutExpired:
                os.kill(proc.pid, signal.SIGKILL)
                proc.wait()
        assert all(proc.poll() is not None for proc in started)


def wait_for_workers(address: str, n: int, timeout: float = 60) -> None:
    import distributed

    with distributed.Client(address, timeout=timeout) as client:
        client.wait_for_workers(n, timeout=timeout)


def test_scheduler_cluster_survives_a_killed_worker_and_runs_a_batch(dask_cluster, pool_results, tmp_path):
    address, workers = dask_cluster
    out_dir = tmp_path / "suite"
    command = [sys.executable, "-m", "tbd_taichi", "evaluate-suite", "--snrs", "2", "--size", "50", "--tests", "4",
               "--methods", "sgds,pf", "--seed", "0", "--out-dir", str(out_dir), "--no-progress",
               "--scheduler", address]
    suite_proc = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    runs_file = out_dir / "suite_runs.jsonl"
    try:
        deadline = time.monotonic() + 240
        while not (runs_file.is_file() and runs_file.read_text().count("\n") >= 1):  # the workers are warm
            assert suite_proc.poll() is None, suite_proc.stdout.read()
            assert time.monotonic() < deadline, "no run finished"
            time.sleep(0.05)
        done_at_kill = runs_file.read_text().count("\n")
        os.kill(workers["worker-2"].pid, signal.SIGKILL)
        output, _ = suite_proc.communicate(timeout=240)
    finally:
        if suite_proc.poll() is None:  # stopped by its id whatever failed above
            os.kill(suite_proc.pid, signal.SIGKILL)
            suite_proc.wait()
    assert suite_proc.returncode == 0, output
    assert done_at_kill < len(RUNS)  # the kill came while runs were left
    results = [json.loads(line) for line in runs_file.read_text().splitlines()]
    assert per_run(results) == pool_results  # every run, once, with the same scores

    clips = tmp_path / "clips"
    clips.mkdir()
    for seed in range(3):
        np.save(clips / f"clip{seed}.npy", simulate((40, 48), frames=20, snr=3.0, seed=seed).frames)
    batch_out = tmp_path / "batch"
    assert cli.main(["batch-track", str(clips / "*.npy"), "--out-dir", str(batch_out), "--no-progress",
                     "--scheduler", address]) == 0
    with open(batch_out / "summary.csv", newline="") as handle:
        rows = list(csv.DictReader(handle))
    assert sorted(r["name"] for r in rows) == ["clip0", "clip1", "clip2"] and {r["status"] for r in rows} == {"ok"}
    for seed in range(3):  # the cluster's CSV is the one track writes here
        single = tmp_path / f"single{seed}.csv"
        assert cli.main(["track", str(clips / f"clip{seed}.npy"), "--out", str(single), "--progress", "off"]) == 0
        assert Path(batch_out / f"clip{seed}.csv").read_bytes() == single.read_bytes()
