"""``tbd-taichi warmup``: compiles a method's kernels for a frame size and writes the offline cache; bad arguments
are one line each, before any work."""
import contextlib
import io
import json
import os
import subprocess
import sys

import numpy as np
import pytest

import tbd_taichi
from tbd_taichi import backend, cli, methods
from tbd_taichi.cli_warmup import profile_runs
from conftest import TEST_ARCH

PF_ARGS = ["warmup", "--method", "pf", "--shape", "40", "48", "--frames", "12", "--json"]


def last_json(text: str) -> dict:
    return json.loads(text.strip().splitlines()[-1])


@pytest.fixture(scope="module")
def warmed():
    """``tbd-taichi warmup`` of pf at 40x48 in this process: (exit status, whether the runtime was up after it,
    stdout, stderr); the session's runtime is restarted after it."""
    out, err = io.StringIO(), io.StringIO()
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            code = cli.main(PF_ARGS + ["--arch", TEST_ARCH])
        running = backend.current() is not None
    finally:
        tbd_taichi.init(TEST_ARCH)
    return code, running, out.getvalue(), err.getvalue()


def test_warmup_reports_each_profile_and_the_cache_and_leaves_a_runtime(warmed):
    code, running, out, err = warmed
    assert code == 0 and running  # each run's runtime was ended (the cache written); an in-process caller gets one back
    result = last_json(out)
    assert result["shape"] == [40, 48]
    assert [(r["method"], r["profile"]) for r in result["runs"]] == [("pf", "paper"), ("pf", "real-video")]
    for run in result["runs"]:  # each run has a fresh runtime, so it builds every kernel it launches
        assert run["kernels"] > 0 and 0 < run["compile_s"] <= run["seconds"] + 0.01
    cache = result["cache"]
    assert os.path.isdir(cache["path"]) and cache["files"] >= cache["new_files"] >= 0
    lines = err.strip().splitlines()  # with --json the report lines go to stderr
    assert lines[0].startswith("warmup pf (paper, 40x48): ") and " kernel(s) built in " in lines[0]
    assert lines[-1].startswith(f"offline cache: {cache['path']}, {cache['files']} files (+")


def test_the_runtime_restarts_after_a_warmup(warmed):
    tracker = methods.make_tracker("pf", (40, 48), profile="paper")
    for _ in range(3):
        tracker.update(np.random.default_rng(0).normal(size=(40, 48)).astype(np.float32))
    tracker.finish()


def test_a_second_process_finds_every_kernel_in_the_cache(warmed):
    """The warm-up wrote the cache: the same warm-up in a new process adds no file to it."""
    done = subprocess.run([sys.executable, "-m", "tbd_taichi", *PF_ARGS, "--arch", TEST_ARCH],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert last_json(done.stdout)["cache"]["new_files"] == 0


def test_methods_whose_profiles_agree_run_once():
    both = {name: [label for label, _ in profile_runs(methods.get(name), "both")] for name in methods.names()}
    assert both["sgds"] == both["pf"] == ["paper", "real-video"]
    assert both["ma-rs"] == ["any"]
    assert profile_runs(methods.get("ma-rs"), "real-video") == [("any", "paper")]
    assert profile_runs(methods.get("pf"), "paper") == [("paper", "paper")]


def run_cli(argv):
    """The exit status of ``tbd-taichi ARGV``, whether returned or argparse's SystemExit."""
    try:
        return cli.main(argv)
    except SystemExit as exc:
        return exc.code


@pytest.mark.parametrize("argv, named", [
    (["--method", "sgds,kalman"], "--method 'kalman' is not a method; choose from sgds, "),
    (["--method", "sgds", "--frames", "3"], "--frames 3 is too few for --method sgds: it needs at least 5"),
    (["--shape", "2", "2"], "argument --shape"),
    (["--method", "pf", "--shape", "20000", "20000"], "GiB"),
    (["--frames", "0"], "argument --frames"),
    (["--profile", "nonsense"], "argument --profile: invalid choice: 'nonsense'"),
])
def test_bad_arguments_are_one_line_before_any_work(argv, named, capsys, monkeypatch):
    def no_work(*args, **kwargs):
        raise AssertionError("the backend was started before the arguments were checked")

    monkeypatch.setattr(backend, "init", no_work)
    assert run_cli(["warmup", *argv]) == 2
    err = capsys.readouterr().err
    assert err.startswith("tbd-taichi warmup: error: ") and err.count("\n") == 1, err
    assert named in err


def test_help_explains_every_option(capsys):
    with pytest.raises(SystemExit) as done:
        cli.main(["warmup", "--help"])
    assert done.value.code == 0
    text = capsys.readouterr().out
    sub = cli.build_parser()._subparsers._group_actions[0].choices["warmup"]
    for action in sub._actions:
        assert all(flag in text for flag in action.option_strings) and action.help, action.option_strings
