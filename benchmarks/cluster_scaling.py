"""Wall time of the quick evaluation suite and of a batch of clips on each executor (issue 42's table).

Executors: this process (1 worker, all Taichi threads), the local pool of 2 processes, a Dask LocalCluster of 2
workers, and a `dask scheduler` with two `dask worker` processes on 127.0.0.1.  Each command runs as a user runs
it (a subprocess of the command line) into a fresh folder, so nothing is skipped; the offline kernel cache is
whatever this machine has (run each command once before to time a warm cache).  Writes a JSON file and prints
the markdown table of docs/cluster.md.

    python benchmarks/cluster_scaling.py [--clips ../shared/data/drone-ir] [--out docs/results/cluster_scaling.json]
"""
from __future__ import annotations

import argparse
import json
import os
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
EXECUTORS = {"1 local worker": ["--workers", "1"], "2 local workers": ["--workers", "2"],
             "Dask LocalCluster, 2 workers": ["--workers", "2", "--scheduler", "local-dask"],
             "dask scheduler + 2 dask workers": None}  # None: the address of the cluster started here
SUITES = {"quick suite (16 runs)": ["--quick"], "suite of 80 runs": ["--tests", "10", "--snrs", "1.4,2.0"]}


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def start_dask_cluster(workers: int = 2) -> tuple[str, list[subprocess.Popen]]:
    """`dask scheduler` and ``workers`` single-thread `dask worker` processes; (address, processes)."""
    import distributed

    port = free_port()
    address = f"tcp://127.0.0.1:{port}"
    quiet = dict(stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    procs = [subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_scheduler", "--host", "127.0.0.1",
                               "--port", str(port), "--no-dashboard"], **quiet)]
    procs += [subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_worker", address, "--nthreads", "1",
                                "--no-dashboard", "--host", "127.0.0.1"], **quiet) for _ in range(workers)]
    with distributed.Client(address, timeout=60) as client:
        client.wait_for_workers(workers, timeout=60)
    return address, procs


def timed(command: list[str]) -> float:
    """Wall seconds of one command (it must succeed)."""
    started = time.perf_counter()
    subprocess.run(command, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return time.perf_counter() - started


def measure(clips: Path, work: Path) -> list[dict]:
    cli = [sys.executable, "-m", "tbd_taichi"]
    rows = []
    for label, options in EXECUTORS.items():
        procs = []
        if options is None:
            address, procs = start_dask_cluster()
            options = ["--scheduler", address]
        try:
            row = dict(executor=label)
            for k, (name, suite_options) in enumerate(SUITES.items()):
                row[name] = round(timed([*cli, "evaluate-suite", *suite_options, "--no-progress", *options,
                                         "--out-dir", str(work / f"suite-{len(rows)}-{k}")]), 1)
            row["batch"] = round(timed([*cli, "batch-track", str(clips), "--no-progress", *options,
                                        "--out-dir", str(work / f"batch-{len(rows)}")]), 1)
        finally:
            for proc in procs:
                os.kill(proc.pid, signal.SIGTERM)
                proc.wait()
        rows.append(row)
        print(rows[-1], flush=True)
    return rows


def markdown(rows: list[dict], n_clips: int) -> str:
    """Wall seconds and the speed-up over the first executor, per job."""
    jobs = [*SUITES, "batch"]
    titles = [*SUITES, f"{n_clips}-clip batch-track"]
    lines = ["| executor | " + " | ".join(f"{t}, s | speed-up" for t in titles) + " |",
             "|---|" + "---:|---:|" * len(jobs)]
    lines += ["| " + r["executor"] + " | " + " | ".join(f"{r[j]:.0f} | {rows[0][j] / r[j]:.2f}×" for j in jobs) + " |"
              for r in rows]
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--clips", default=str(ROOT.parent / "shared" / "data" / "drone-ir"))
    parser.add_argument("--out", default=str(ROOT / "docs" / "results" / "cluster_scaling.json"))
    args = parser.parse_args()
    clips = Path(args.clips)
    n_clips = len([p for p in clips.iterdir() if p.suffix == ".mp4"])
    with tempfile.TemporaryDirectory() as work:
        rows = measure(clips, Path(work))
    from tbd_taichi.bench import machine_description

    Path(args.out).write_text(json.dumps(dict(machine=machine_description(), clips=n_clips, rows=rows), indent=1))
    print(markdown(rows, n_clips))


if __name__ == "__main__":
    main()
