"""A particle pool whose fields do not grow with the frame (the tracking PFs') compiles its kernels once for every
frame size: a second process at another frame size finds all of them in Taichi's offline cache and writes no new
kernel file.  As in SGDS-PF, fields sized by the frame are made first (there: the searching pool's), then the shared
random tables and the pool.  Before the pools read the frame size from a field, and before the shared tables had an
SNode tree of their own (they shared the tree of the fields made before them), the step compiled again at each
size; each of the two fails this test alone.  A marked (light IR) kernel launched through the lean path is built
once, under the light setting: one kernel file, the one Taichi's own launch writes, not the unmarked kernel's.
SGDS-PF's searching pool, whose per-pixel tables follow the frame's size class, compiles once per class."""
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

POOL_AT_SIZE = """
import sys
import numpy as np
import taichi as ti
import tbd_taichi
from tbd_taichi.kernels.rng import ExponentialTables, NormalTables
from tbd_taichi.particles import ParticlePool
h, w = int(sys.argv[1]), int(sys.argv[2])
tbd_taichi.init("cpu")
frame_sized = ti.field(ti.f32, shape=(h, w))  # fields made first, sized by the frame (SGDS-PF: the searching pool's)
NormalTables.shared(), ExponentialTables.shared()
pool = ParticlePool([600] * 3, (h, w), seed=1)
pool.configure_groups(np.arange(3), "copy", vmax=1.0, intensity=(1.0, 3.0))
z = np.random.default_rng(0).standard_normal((h, w)).astype(np.float32)
for frame in range(2):
    pool.step(frame, z)
print(int(pool.estimates().n.sum() >= 0))
"""


SEARCHING_AT_SIZE = """
import sys
import numpy as np
import tbd_taichi
from tbd_taichi.kernels.populations import pixel_class
from tbd_taichi.methods.sgds.searching_pool import SearchingPool
from tbd_taichi.particles import ParticlePool
h, w = int(sys.argv[1]), int(sys.argv[2])
tbd_taichi.init("cpu")
search = SearchingPool([700] * 2, (h, w), seed=1, map_capacity=pixel_class((h, w)))
search.configure_groups([0, 1], "map", pb=0.3, pd=0.05, intensity=(1.0, 3.0))
pixels = np.arange(0, h * w, 7)
search.set_proposal_map({g: (pixels, np.ones(len(pixels))) for g in (0, 1)}, np.arange(h * w, dtype=np.int32).reshape(h, w) % 5)
tracks = ParticlePool([300] * 2, (h, w), seed=2)
tracks.configure_groups([0, 1], "copy", vmax=1.0, intensity=(1.0, 3.0))
z = np.random.default_rng(0).standard_normal((h, w)).astype(np.float32)
index = np.zeros((h, w), np.int32)
assert search.pairs_with(tracks)
for frame in range(3):
    n_pp, _ = search.step_with(tracks, frame, z, top_up=[700, 700], quota=70)
    search.eliminate_and_hand_over_numbered(np.full(n_pp, 0.5), index, 0.0, 0.0, [], 3.0, 1)
print(int((index >= 0).all()))
"""


SGDS_AT_SIZE = """
import sys
import numpy as np
import tbd_taichi as tbd
h, w = int(sys.argv[1]), int(sys.argv[2])
blocks = dict(L_ib=int(sys.argv[3])) if len(sys.argv) > 3 else {}
tbd.init("cpu")
scene = tbd.simulate((h, w), 14, snr=3.0, seed=1)
tracker = tbd.SGDSPF((h, w), snr=3.0, **blocks)
rows = [row for frame in scene.frames for row in tracker.update(frame)]
print(int(len(tracker.finish()) >= 0))
"""


METHOD_AT_SIZE = """
import sys
import tbd_taichi as tbd
from tbd_taichi import methods
h, w, method = int(sys.argv[1]), int(sys.argv[2]), sys.argv[3]
tbd.init("cpu")
scene = tbd.simulate((h, w), 10, snr=8.0 if method == "tophat-pf" else 3.0, seed=1)
first = scene.truth[0]
box = {"init_box": (first["x"] - 3, first["y"] - 3, 7, 7)} if method == "feature-fusion" else {}
tracker = methods.make_tracker(method, (h, w), **box)
rows = [row for frame in scene.frames for row in tracker.update(frame)]
if method == "tophat-pf":
    assert tracker.k.live_count > 0  # the particle filters ran
    for step in ("step_by_particle", "step_by_group"):  # the step's two loop layouts (chosen by the live count)
        getattr(tracker.k, step)(len(scene.frames), 1, 1, 1)
print(int(len(tracker.finish()) >= 0))
"""


def cache_files(path: Path) -> set:
    return {str(p.relative_to(path)) for p in path.rglob("*") if p.is_file()}


MARKED_KERNEL = """
import sys
import numpy as np
import taichi as ti
import tbd_taichi
from tbd_taichi.kernels.loops import light_ir
from tbd_taichi.launch import Launcher

@ti.kernel
def scaled(out: ti.types.ndarray(dtype=ti.f32, ndim=1), k: ti.f32):
    for i in range(out.shape[0]):
        out[i] = ti.exp(-ti.cast(i, ti.f32) * k)

if sys.argv[1] != "unmarked":
    scaled = light_ir(scaled)
tbd_taichi.init("cpu")
out = np.zeros(9, np.float32)
launch = Launcher(sys.modules[__name__]).scaled if sys.argv[1] == "lean" else scaled
for k in (0.5, 0.25, 0.125):
    launch(out, k)
print(int(out[1] == np.float32(np.exp(np.float32(-0.125)))))
"""


def run_script(cache: Path, script: str, *args) -> None:
    path = os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")]))
    env = dict(os.environ, TI_OFFLINE_CACHE_FILE_PATH=str(cache), PYTHONPATH=path)
    file = cache.parent / f"script_{abs(hash(script))}.py"  # a file: Taichi reads a kernel's source from it
    file.write_text(script)
    out = subprocess.run([sys.executable, str(file), *map(str, args)], env=env, cwd=ROOT,
                         capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.strip().endswith("1")


def run_pool(cache: Path, shape) -> None:
    run_script(cache, POOL_AT_SIZE, *shape)


def kernel_files(path: Path) -> set:
    return {name for name in cache_files(path) if name.endswith(".tic")}


def test_a_tracking_pool_at_a_new_frame_size_compiles_nothing(tmp_path):
    run_pool(tmp_path, (40, 50))
    first = cache_files(tmp_path)
    assert any(name.endswith(".tic") for name in first), sorted(first)  # the cache is where we look
    run_pool(tmp_path, (61, 37))
    new = kernel_files(tmp_path) - first
    assert not new, f"kernels compiled again at a new frame size: {sorted(new)}"


def assert_built_once_per_size_class(cache: Path, script: str, sizes: list, other) -> None:
    """``script`` at the first of ``sizes``, then at each other (the same size class) writes no new kernel file;
    then at ``other`` (another class) it writes some."""
    run_script(cache, script, *sizes[0])
    first = kernel_files(cache)
    for size in sizes[1:]:
        run_script(cache, script, *size)
        assert kernel_files(cache) == first, f"kernels compiled again within a size class, at {size}"
    run_script(cache, script, *other)
    assert kernel_files(cache) - first, "a new size class reused kernels built for another"


def test_a_searching_pool_at_a_new_frame_size_of_its_size_class_compiles_nothing(tmp_path):
    """SGDS-PF's searching pool (its paired step with the tracking pool, the set-up, elimination and hand-over):
    the per-pixel tables hold ``pixel_class`` entries (every frame up to 724 × 724 px: 2^19), so a new frame
    size of the class finds every kernel in the cache (40 × 50, 43 × 47, 70 × 37, 512 × 640); a frame of more
    pixels (730 × 730: 2^20) compiles again, as the exact frame size did for every size before."""
    assert_built_once_per_size_class(tmp_path, SEARCHING_AT_SIZE, [(40, 50), (43, 47), (70, 37), (512, 640)],
                                     (730, 730))


def test_sgds_at_a_new_frame_size_of_its_size_class_compiles_nothing(tmp_path):
    """SGDS-PF end to end (normalisation, the saliency stage, both particle pools, hand-over): every frame up to
    256 × 320 (the smallest size class) with blocks of the same class (256-px blocks: 1 or 2) finds every kernel in
    the cache; 40 × 330 (384 columns: another class of the saliency stage) compiles some."""
    assert_built_once_per_size_class(tmp_path, SGDS_AT_SIZE, [(40, 50), (43, 47), (70, 37), (250, 300)], (40, 330))


def test_sgds_at_another_block_count_of_its_class_compiles_nothing(tmp_path):
    """The searching pool holds the blocks' class of searching PFs (``block_class``: a power of two, at least
    8), the spare ones empty, and the saliency stage's block fields a power of two: 43 × 47 and 64 × 64 with
    20-px blocks (9 and 16 blocks, both of the 16-block class) share every kernel; 40 × 50 (6 blocks: the 8-block
    class) compiles some."""
    assert_built_once_per_size_class(tmp_path, SGDS_AT_SIZE, [(43, 47, 20), (64, 64, 20)], (40, 50, 20))


def test_sgds_with_the_default_blocks_compiles_nothing_up_to_256_by_320(tmp_path):
    """With the default preset's 150-px blocks, 256 × 320 (6 blocks, the class's edge) and 100 × 100 (1 block)
    share every kernel: the saliency stage's block fields and the searching pool take ``block_class`` (8) for
    both; 257 × 320 (512 rows: another class) compiles some."""
    assert_built_once_per_size_class(tmp_path, SGDS_AT_SIZE, [(256, 320, 150), (100, 100, 150)], (257, 320, 150))


def test_a_marked_kernel_through_the_lean_path_is_built_once_as_taichi_builds_it(tmp_path):
    builds = {mode: tmp_path / mode for mode in ("lean", "plain", "unmarked")}
    for mode, cache in builds.items():
        run_script(cache, MARKED_KERNEL, mode)
    lean, plain, unmarked = (kernel_files(cache) for cache in builds.values())
    assert len(lean) == 1 and lean == plain
    assert lean != unmarked  # the light build is another build (the offline cache keys on the setting)


def test_mm_phd_at_a_new_frame_size_of_its_size_class_compiles_nothing(tmp_path):
    """MM-PHD's per-pixel fields (the frames, the birth cells, Ψ) hold the pixels of the frames' size class, one
    row after another at the frame's own width, and its kernels read (H, W) from ``frame_hw``: 40 × 50, 43 × 47,
    §5.3's 100 × 80 and 256 × 320 (the class's edge) share every kernel; 257 × 320 (512 rows: another class)
    compiles some."""
    sizes = [(40, 50), (43, 47), (100, 80), (256, 320)]
    assert_built_once_per_size_class(tmp_path, METHOD_AT_SIZE, [size + ("mm-phd",) for size in sizes],
                                     (257, 320, "mm-phd"))


def test_tophat_pf_at_a_new_frame_size_of_its_size_class_compiles_nothing(tmp_path):
    """The top-hat + PF tracker's images (the top-hat's and the background's, held at the size class's extents
    or, for Total and S, row after row at the frame's width) with (H, W) read from ``frame_hw``: 40 × 50 and
    61 × 37 share every kernel; 40 × 330 (384 columns: another class) compiles some."""
    assert_built_once_per_size_class(tmp_path, METHOD_AT_SIZE, [(40, 50, "tophat-pf"), (61, 37, "tophat-pf")],
                                     (40, 330, "tophat-pf"))


def test_feature_fusion_at_a_new_frame_size_of_its_size_class_compiles_nothing(tmp_path):
    """The feature-fusion tracker's images (the zero-bordered frame, the Gabor row pass, the bin maps) take the
    size class's extents and its kernels read (H, W) from ``frame_hw``: 40 × 50 and 61 × 37 share every kernel;
    40 × 330 (384 columns: another class) compiles some."""
    assert_built_once_per_size_class(tmp_path, METHOD_AT_SIZE, [(40, 50, "feature-fusion"), (61, 37, "feature-fusion")],
                                     (40, 330, "feature-fusion"))


@pytest.mark.parametrize("method", ["ma-rs", "ma-apf"])
def test_multiaspect_at_a_new_frame_size_of_its_size_class_compiles_nothing(tmp_path, method):
    """The multiaspect filters' frame tables (the padded d-map, the energy tables, the birth proposal) take the size
    class's extents and the kernels read (H, W) from ``frame_hw``: 40 × 50 and 61 × 37 share every kernel;
    40 × 330 (384 columns: another class) compiles some."""
    assert_built_once_per_size_class(tmp_path, METHOD_AT_SIZE, [(40, 50, method), (61, 37, method)], (40, 330, method))
