"""kernels/ installs as tbd_taichi.kernels, never as a top-level package."""
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

import tbd_taichi
import tbd_taichi.kernels

ROOT = Path(__file__).resolve().parents[1]
pytestmark = pytest.mark.skipif(not (ROOT / "pyproject.toml").exists(), reason="needs the source tree")


def pip(*args, cwd=ROOT):
    res = subprocess.run([sys.executable, "-m", "pip", *args], cwd=cwd, capture_output=True, text=True)
    assert res.returncode == 0, res.stdout + res.stderr
    return res


@pytest.fixture(scope="module")
def wheel(tmp_path_factory):
    out = tmp_path_factory.mktemp("wheel")
    pip("wheel", ".", "--no-deps", "--no-build-isolation", "-w", str(out))
    return next(out.glob("tbd_taichi-*.whl"))


def test_installed_layout():
    assert Path(tbd_taichi.kernels.__file__).parent.name in ("kernels",)
    assert tbd_taichi.kernels.__name__ == "tbd_taichi.kernels"


def test_wheel_has_no_top_level_kernels(wheel):
    names = zipfile.ZipFile(wheel).namelist()
    assert "tbd_taichi/kernels/__init__.py" in names and "tbd_taichi/kernels/rng.py" in names
    assert not [n for n in names if n.startswith("kernels/")]
    sources = {f"tbd_taichi/{p.relative_to(ROOT / 'tbd_taichi').as_posix()}" for p in (ROOT / "tbd_taichi").rglob("*.py")}
    sources |= {f"tbd_taichi/kernels/{p.relative_to(ROOT / 'kernels').as_posix()}" for p in (ROOT / "kernels").rglob("*.py")}
    assert sources <= set(names), f"missing from the wheel: {sorted(sources - set(names))}"
    for name in (n for n in names if n.endswith("top_level.txt")):
        assert zipfile.ZipFile(wheel).read(name).decode().split() == ["tbd_taichi"]


def test_regular_install_from_wheel(wheel, tmp_path):
    target = tmp_path / "site"
    pip("install", "--no-deps", "--target", str(target), str(wheel))
    assert not (target / "kernels").exists()
    code = ("import sys, importlib.util; sys.path.insert(0, sys.argv[1]); import tbd_taichi.kernels.rng as r; "
            "assert r.__file__.startswith(sys.argv[1]), r.__file__; assert importlib.util.find_spec('kernels') is None; "
            "print('ok')")
    res = subprocess.run([sys.executable, "-c", code, str(target)], cwd=tmp_path, capture_output=True, text=True)
    assert res.stdout.strip() == "ok", res.stderr


def test_editable_install_maps_kernels(tmp_path):
    prefix = tmp_path / "prefix"
    pip("install", "--no-deps", "--no-build-isolation", "--ignore-installed", "--prefix", str(prefix), "-e", ".")
    site = next(prefix.glob("lib/python*/site-packages"))
    code = ("import site, sys; site.addsitedir(sys.argv[1]); "
            "finder = next(f for f in sys.meta_path if 'Editable' in type(f).__name__ or 'editable' in str(f)); "
            "spec = finder.find_spec('tbd_taichi.kernels', None); print(spec.origin)")
    res = subprocess.run([sys.executable, "-c", code, str(site)], cwd=tmp_path, capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    assert Path(res.stdout.strip()) == ROOT / "kernels" / "__init__.py"
