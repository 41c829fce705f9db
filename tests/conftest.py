import os
import subprocess
import sys

import numpy as np
import pytest

import tbd_taichi

# The backend the kernels run on in tests: CPU unless TBD_TAICHI_TEST_ARCH names a GPU
# backend (e.g. ``TBD_TAICHI_TEST_ARCH=cuda pytest -q`` on a GPU machine).
TEST_ARCH = os.environ.get("TBD_TAICHI_TEST_ARCH", "cpu")


@pytest.fixture(scope="session", autouse=True)
def taichi_runtime():
    """One runtime for the whole session (tests that restart it restore it)."""
    return tbd_taichi.init(TEST_ARCH)


@pytest.fixture
def rng():
    return np.random.default_rng(12345)


@pytest.fixture
def csv_by_threads(tmp_path):
    """``run(frames, *track_args)``: ``python -m tbd_taichi track`` on the frames (saved as .npy) with 1 and with 2
    CPU threads; the two tracks CSVs' bytes (the same, where the kernels are thread-count independent)."""
    def run(frames, *args):
        source = tmp_path / "threads_input.npy"
        np.save(source, frames)
        outs = []
        for threads in (1, 2):
            out = tmp_path / f"threads{threads}.csv"
            subprocess.run([sys.executable, "-m", "tbd_taichi", "track", str(source), *args, "--threads", str(threads),
                            "--out", str(out), "--progress", "off"], check=True, capture_output=True)
            outs.append(out.read_bytes())
        return outs
    return run


@pytest.fixture
def simulate_error(tmp_path, capsys):
    """``run(scenario, argv)``: ``tbd-taichi simulate --scenario SCENARIO *argv --out …`` in this process; returns
    (exit code, stderr, whether the .npz was written)."""
    def run(scenario, argv):
        from tbd_taichi import cli

        out = tmp_path / "scene.npz"
        try:
            code = cli.main(["simulate", "--scenario", scenario, *argv, "--out", str(out)])
        except SystemExit as exc:
            code = exc.code
        return code, capsys.readouterr().err, out.exists()
    return run
