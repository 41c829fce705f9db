"""A particle pool whose fields do not grow with the frame (the tracking PFs') compiles its kernels once for every
frame size: a second process at another frame size finds all of them in Taichi's offline cache and writes no new
kernel file.  Before the pools read the frame size from a field (and the shared random tables had an SNode tree of
their own) the step compiled again at each size."""
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

POOL_AT_SIZE = """
import sys
import numpy as np
import tbd_taichi
from tbd_taichi.particles import ParticlePool
h, w = int(sys.argv[1]), int(sys.argv[2])
tbd_taichi.init("cpu")
pool = ParticlePool([600] * 3, (h, w), seed=1)
pool.configure_groups(np.arange(3), "copy", vmax=1.0, intensity=(1.0, 3.0))
z = np.random.default_rng(0).standard_normal((h, w)).astype(np.float32)
for frame in range(2):
    pool.step(frame, z)
print(int(pool.estimates().n.sum() >= 0))
"""


def cache_files(path: Path) -> set:
    return {str(p.relative_to(path)) for p in path.rglob("*") if p.is_file()}


def run_pool(cache: Path, shape) -> None:
    env = dict(os.environ, TI_OFFLINE_CACHE_FILE_PATH=str(cache), PYTHONPATH=str(ROOT))
    out = subprocess.run([sys.executable, "-c", POOL_AT_SIZE, *map(str, shape)], env=env, cwd=ROOT,
                         capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.strip().endswith("1")


def test_a_tracking_pool_at_a_new_frame_size_compiles_nothing(tmp_path):
    run_pool(tmp_path, (40, 50))
    first = cache_files(tmp_path)
    assert any(name.endswith(".tic") for name in first), sorted(first)  # the cache is where we look
    run_pool(tmp_path, (61, 37))
    new = {name for name in cache_files(tmp_path) - first if name.endswith(".tic")}
    assert not new, f"kernels compiled again at a new frame size: {sorted(new)}"
