"""The method registry: specs, parameters declared once (validation, KEY=VALUE conversion, --help-params),
make_tracker's errors, the CLI's registry-driven flags, the README's methods table, the adding-a-method
walkthrough, and the package run from the repository root."""
import dataclasses
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import tbd_taichi as tbd
from tbd_taichi import cli, methods
from tbd_taichi.errors import ParameterError
from tbd_taichi.methods.registry import Range, Tracker, convert_text, param_infos

ROOT = Path(__file__).resolve().parents[1]


def test_registry_lists_the_methods_with_kind_and_paper():
    assert methods.names()[:2] == ["sgds", "pf"]
    for spec in methods.specs():
        assert spec.kind in methods.KINDS and spec.paper and spec.title and spec.description
        assert dataclasses.is_dataclass(spec.params) and spec.params.__dataclass_params__.frozen
        for info in spec.param_infos():  # every parameter is declared with a description
            assert info.doc, f"{spec.name}.{info.name} has no description"
        assert spec.make_params((64, 80)) is not None  # the defaults are valid


@pytest.mark.parametrize("name", ["sgds", "pf"])
def test_make_tracker_gives_a_tracker(name):
    tracker = tbd.make_tracker(name, (40, 48), seed=3)
    assert isinstance(tracker, Tracker)
    assert tracker.frames_in == 0 and set(tracker.timings) and all(v == 0 for v in tracker.timings.values())


@pytest.mark.parametrize("kwargs,message", [
    (dict(name="nope"), r"unknown method 'nope'; choose one of sgds, pf"),
    (dict(name="sgds", Pe=0.1), r"unknown SGDS-PF parameter\(s\) Pe; parameters: .*P_e"),
    (dict(name="pf", n_particles=0), r"original PF parameter n_particles = 0 must be an integer ≥ 1"),
    (dict(name="pf", threshold=1.0), r"threshold = 1.0 must be in \(0, 1\)"),
    (dict(name="sgds", N_sump=8000.5), r"N_sump = 8000.5 must be an integer ≥ 10"),
    (dict(name="sgds", msw_reference="x"), r"msw_reference = 'x' must be one of candidates, search"),
    (dict(name="pf", systematic="yes"), r"systematic = 'yes' must be a bool"),
    (dict(name="sgds", seed=-1), r"seed must be a whole number in \[0, 4294967295\], got -1"),
    (dict(name="sgds", seed=1.5), r"seed must be a whole number in \[0, 4294967295\], got 1.5"),
    (dict(name="sgds", engine="cupy"), r"engine must be one of taichi, numpy"),
    (dict(name="sgds", init_box=(1, 2, 3, 4)), r"method sgds takes no --init-box"),
])
def test_make_tracker_errors_name_the_offender(kwargs, message):
    kwargs = dict(kwargs)
    name = kwargs.pop("name")
    with pytest.raises(ParameterError, match=message):
        tbd.make_tracker(name, (40, 48), **kwargs)


def test_range_reads_as_the_errors_say():
    assert str(Range(0, 1, high_closed=False)) == "in [0, 1)"
    assert str(Range(0, low_closed=False)) == "> 0"
    assert str(Range(1, integer=True)) == "an integer ≥ 1"
    assert str(Range(choices=("a", "b"))) == "one of a, b"
    r = Range(0, 1, low_closed=False)
    assert not r.contains(0) and r.contains(1) and not r.contains(float("nan")) and not r.contains(float("inf"))
    assert not Range(0).contains(True)  # a bool is not a number here


def test_key_value_text_converts_by_the_declared_type():
    infos = {i.name: i for i in param_infos(methods.get("pf").params)}
    assert convert_text(infos["n_particles"], "20000") == 20000
    assert convert_text(infos["n_particles"], "auto") is None
    assert convert_text(infos["systematic"], "yes") is True and convert_text(infos["systematic"], "0") is False
    assert convert_text(infos["pb"], "0.1") == 0.1
    for info, text in ((infos["n_particles"], "1.5"), (infos["pb"], "x"), (infos["systematic"], "maybe")):
        with pytest.raises(ParameterError, match=f"--param {info.name}={re.escape(text)}"):
            convert_text(info, text)
    spec = methods.get("sgds")
    assert spec.parse_assignments(["N_sump=6000", "lef_memory=0"]) == {"N_sump": 6000, "lef_memory": 0.0}
    with pytest.raises(ParameterError, match=r"unknown SGDS-PF parameter 'Nsump' \(--param\); known: snr, L_ib"):
        spec.parse_assignments(["Nsump=6000"])
    with pytest.raises(ParameterError, match="--param takes KEY=VALUE"):
        spec.parse_assignments(["N_sump"])


def test_param_reaches_the_tracker():
    tracker = tbd.make_tracker("sgds", (64, 64), seed=0, N_sump=1234, max_tracks=5, T_rt=3)
    assert (tracker.p.N_sump, tracker.p.max_tracks, tracker.p.T_rt) == (1234, 5, 3)
    assert tracker.tracks_pool.n_groups == 5 and set(tracker.search.caps.tolist()) == {1234}
    pf = tbd.make_tracker("pf", (64, 64), n_particles=5000, systematic=True)
    assert pf.n_particles == 5000 and pf.systematic


def run_cli(*args, cwd=ROOT, env=None):
    return subprocess.run([sys.executable, "-m", "tbd_taichi", *map(str, args)], capture_output=True, text=True,
                          cwd=cwd, env=env)


def test_methods_command_lists_every_method(capsys):
    assert cli.main(["methods"]) == 0
    out = capsys.readouterr().out
    for spec in methods.specs():
        assert re.search(rf"^{spec.name}\s+{spec.kind}\s+{re.escape(spec.paper)}", out, re.M)


@pytest.mark.parametrize("name", ["sgds", "pf"])
def test_help_params_lists_each_parameter_with_default_range_and_symbol(name, capsys):
    assert cli.main(["track", "--method", name, "--help-params"]) == 0
    out = capsys.readouterr().out
    for info in methods.get(name).param_infos():
        assert re.search(rf"^{info.name}\s", out, re.M), info.name
    if name == "sgds":
        assert re.search(r"^N_sump\s+8000\s+particles\s+an integer ≥ 10\s+N_sump\^b \(Table 2\)", out, re.M)


def write_scene(path, frames=12, shape=(32, 40)):
    scene = tbd.simulate(shape, frames=frames, snr=3.0, seed=4)
    np.save(path, scene.frames)
    return path


@pytest.mark.parametrize("args,message", [
    (["--method", "pf", "--param", "foo=1"], r"unknown original PF parameter 'foo' \(--param\); known: snr"),
    (["--method", "sgds", "--param", "P_e=1.5"], r"SGDS-PF parameter P_e = 1.5 must be in \[0, 1\)"),
    (["--method", "sgds", "--param", "N_sump=many"], r"--param N_sump=many: N_sump takes a whole number"),
    (["--method", "sgds", "--particles", "100"], r"--particles applies to --method pf or mm-phd or .*, not sgds"),
    (["--method", "tophat-pf", "--min-peak-z", "3"], r"--min-peak-z applies to --method sgds or pf or mm-phd, not tophat-pf"),
    (["--method", "pf", "--paths", "online"], r"--paths online applies to --method sgds or tophat-pf only"),
    (["--method", "pf", "--init-box", "1,2,3,4"], r"method pf takes no --init-box"),
    (["--method", "sgds", "--init-box", "1,2,3"], r"--init-box takes X,Y,W,H"),
    (["--method", "pf", "--snr", "2", "--param", "snr=3"], r"--param snr=3.0 contradicts the flag"),
])
def test_track_flag_errors_are_one_clear_line(tmp_path, args, message):
    seq = write_scene(tmp_path / "seq.npy")
    res = run_cli("track", seq, "--out", tmp_path / "t.csv", *args)
    assert res.returncode == 2, res.stderr
    assert re.search(message, res.stderr), res.stderr
    assert "Traceback" not in res.stderr and len(res.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "t.csv").exists()  # refused before any work


def test_track_with_param_matches_the_same_setting_by_flag(tmp_path):
    seq = write_scene(tmp_path / "seq.npy", frames=20)
    a, b = tmp_path / "a.csv", tmp_path / "b.csv"
    assert cli.main(["track", str(seq), "--method", "pf", "--particles", "3000", "--out", str(a)]) == 0
    assert cli.main(["track", str(seq), "--method", "pf", "--param", "n_particles=3000", "--out", str(b)]) == 0
    assert a.read_bytes() == b.read_bytes()


def test_init_box_reaches_a_method_that_needs_one():
    seen = {}

    @dataclasses.dataclass(frozen=True)
    class BoxParams:
        pass

    def factory(shape, params, *, seed, engine, arch, init_box=None):
        seen["box"] = init_box
        return tbd.make_tracker("pf", shape, seed=seed, engine=engine)

    spec = methods.MethodSpec(name="boxtest", title="box test", paper="-", kind="box-tracker", description="-",
                              params=BoxParams, factory=factory, make_params=lambda shape, **kw: BoxParams(**kw),
                              needs_init_box=True)
    methods.register(spec)
    try:
        with pytest.raises(ParameterError, match="method boxtest needs the target's first-frame box"):
            tbd.make_tracker("boxtest", (40, 48))
        with pytest.raises(ParameterError, match="lies outside the 40x48 frame"):
            tbd.make_tracker("boxtest", (40, 48), init_box=(60, 2, 4, 4))
        with pytest.raises(ParameterError, match="W, H > 0"):
            tbd.make_tracker("boxtest", (40, 48), init_box=(1, 2, 0, 4))
        tbd.make_tracker("boxtest", (40, 48), init_box=("10.5", 3, 6, 4)).tracker  # built (auto: lazily)
        assert seen["box"] == (10.5, 3.0, 6.0, 4.0)
    finally:
        methods.unregister("boxtest")
    assert "boxtest" not in methods.names()


def test_readme_methods_table_is_the_registry_s():
    text = (ROOT / "README.md").read_text()
    match = re.search(r"<!-- methods-table:start -->\n(.*?)\n<!-- methods-table:end -->", text, re.S)
    assert match, "README.md needs the methods table between its markers"
    assert match.group(1).strip() == methods.methods_table().strip(), \
        "README's methods table differs from the registry: paste tbd_taichi.methods.methods_table()"


def test_suite_and_bench_take_any_registered_method(tmp_path):
    from tbd_taichi import suite

    assert suite.configured_particles("pf", 200, 1.8) == 20_000
    res = run_cli("evaluate-suite", "--methods", "sgds,nope", "--out-dir", tmp_path)
    assert res.returncode == 2 and "--methods takes a comma list of sgds,pf" in res.stderr
    res = run_cli("bench", "--method", "nope")
    assert res.returncode == 2 and "invalid choice: 'nope'" in res.stderr


def python_blocks(markdown: str) -> list[str]:
    return re.findall(r"```python\n(.*?)```", markdown, re.S)


def test_adding_a_method_walkthrough_runs(capsys):
    blocks = python_blocks((ROOT / "docs" / "adding-a-method.md").read_text())
    assert len(blocks) >= 4
    namespace = {"__name__": "walkthrough"}
    try:
        for block in blocks:
            exec(compile(block, "docs/adding-a-method.md", "exec"), namespace)
        assert "bootstrap" in methods.names()
        out = capsys.readouterr().out
        dsr = float(re.search(r"bootstrap PF: DSR ([0-9.]+)", out).group(1))
        assert dsr >= 0.6, out  # SNR 3, 60 frames: 0.9 measured (0.65-0.9 over scene seeds 2-4); a miss gives < 0.2
        assert "bootstrap PF parameter declare = 1.5 must be in (0, 1)" in out
        assert cli.main(["track", "--method", "bootstrap", "--help-params"]) == 0
        assert re.search(r"^n_particles\s+20000\s+particles", capsys.readouterr().out, re.M)
    finally:
        if "bootstrap" in methods.names():
            methods.unregister("bootstrap")


@pytest.mark.skipif(os.environ.get("TBD_FROM_ROOT_CHILD") == "1", reason="inside the child run")
def test_commands_run_from_the_repository_root():
    """From the root, the checkout's tbd_taichi/ shadows an installed copy; its kernels/ must still load."""
    env = {**os.environ, "TBD_FROM_ROOT_CHILD": "1"}
    res = run_cli("--help", env=env)
    assert res.returncode == 0 and "track" in res.stdout, res.stderr
    code = ("import tbd_taichi, pathlib; t = tbd_taichi.make_tracker('sgds', (40, 48)); "
            "import tbd_taichi.kernels as k; print(pathlib.Path(tbd_taichi.__file__).parent.parent, k.__name__)")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, env=env)
    assert res.returncode == 0, res.stderr
    assert res.stdout.split()[-1] == "tbd_taichi.kernels" and Path(res.stdout.split()[-2]) == ROOT
    res = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                          "tests/test_registry.py::test_range_reads_as_the_errors_say"],
                         capture_output=True, text=True, cwd=ROOT, env=env)
    assert res.returncode == 0 and "1 passed" in res.stdout, res.stdout + res.stderr


def test_listing_the_methods_imports_no_scipy_submodule():
    """The CLI lists every method (parser, --help, early errors) without importing a scipy submodule: each costs
    0.1–0.2 s of every command's start-up (ndimage, special, fft, cluster), and the methods import them where
    they run."""
    import subprocess
    import sys

    code = ("import sys, tbd_taichi.cli, tbd_taichi.methods as m; m.specs(); "
            "print(sorted(k for k in sys.modules if k.startswith('scipy.') and k.count('.') == 1 "
            "and not k.startswith('scipy._')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip().splitlines()[-1] == "[]", out
