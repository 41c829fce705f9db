"""Backend selection: clear errors, safe repeated init, offline cache."""
import numpy as np
import pytest
import taichi as ti

import tbd_taichi
from tbd_taichi import backend
from tbd_taichi.errors import BackendError
from conftest import TEST_ARCH


def test_cpu_is_default_and_repeated_init_is_a_no_op():
    try:
        cfg = tbd_taichi.init()
        gen = backend.generation()
        assert cfg.arch == "cpu"
        assert tbd_taichi.init("cpu") is cfg
        assert backend.generation() == gen
        assert ti.lang.impl.current_cfg().arch == ti.cpu
    finally:
        tbd_taichi.init(TEST_ARCH)


def test_offline_cache_is_on():
    tbd_taichi.init(TEST_ARCH)
    assert ti.lang.impl.current_cfg().offline_cache


def test_changed_settings_restart_the_runtime():
    gen = backend.generation()
    try:
        assert tbd_taichi.init("cpu", threads=1).threads == 1
        assert backend.generation() == gen + 1
        assert ti.lang.impl.current_cfg().cpu_max_num_threads == 1
    finally:
        tbd_taichi.init(TEST_ARCH)


def test_unknown_arch_is_a_clear_error():
    with pytest.raises(BackendError, match="unknown arch 'tpu'.*cpu, cuda, vulkan, metal, gpu, auto"):
        tbd_taichi.init("tpu")


@pytest.mark.parametrize("arch", ["cuda", "vulkan", "metal", "gpu"])
def test_missing_backend_lists_what_is_available(arch):
    available = tbd_taichi.available_archs()
    if arch in available or (arch == "gpu" and len(available) > 1):
        pytest.skip(f"{arch} is present on this machine")
    with pytest.raises(BackendError, match=r"not available|no GPU backend") as info:
        tbd_taichi.init(arch)
    assert "available: cpu" in str(info.value)
    assert tbd_taichi.init(TEST_ARCH).arch == TEST_ARCH


def test_auto_falls_back_to_cpu_silently():
    expected = tbd_taichi.available_archs()[1:2] or ["cpu"]
    try:
        assert tbd_taichi.init("auto").arch == expected[0]
    finally:
        tbd_taichi.init(TEST_ARCH)


def test_bad_thread_count():
    with pytest.raises(BackendError, match="threads"):
        tbd_taichi.init("cpu", threads=0)


@pytest.mark.parametrize("shape", [(7,), (1,), (5, 3), (33, 1)])
@pytest.mark.parametrize("dtype", [np.int32, np.float32, np.float64])
def test_host_copies_match_to_numpy(shape, dtype):
    """backend.to_host / from_host (typed kernels) against Taichi's own to_numpy / from_numpy."""
    rng = np.random.default_rng(3)
    values = (rng.standard_normal(shape) * 1e6).astype(dtype)
    values.flat[0] = np.iinfo(dtype).min if dtype == np.int32 else np.finfo(dtype).max  # extremes survive
    field = ti.field(ti.lang.util.to_taichi_type(dtype), shape=shape)
    backend.from_host(field, values)
    np.testing.assert_array_equal(field.to_numpy(), values)
    field.from_numpy(values[::-1].copy())
    out = backend.to_host(field)
    assert out.dtype == dtype and out.shape == shape
    np.testing.assert_array_equal(out, values[::-1])
    with pytest.raises(ValueError, match="does not fit"):
        backend.from_host(field, np.zeros(shape + (2,), dtype))


def test_host_copies_of_vector_fields_and_arrays():
    vec = ti.Vector.field(3, ti.f32, shape=4)
    values = np.arange(12, dtype=np.float32).reshape(4, 3)
    backend.from_host(vec, values)
    np.testing.assert_array_equal(backend.to_host(vec), values)
    arr = np.zeros(4)
    backend.from_host(arr, [1, 2, 3, 4])
    copy = backend.to_host(arr)
    copy[0] = 9
    np.testing.assert_array_equal(arr, [1, 2, 3, 4])


def test_cpu_workers_are_pinned_one_per_cpu_when_they_use_every_cpu():
    """With as many workers as CPUs (≥ 2) each worker thread is pinned to its own CPU, and these threads
    do the work of a parallel loop; fewer threads than CPUs are left to the scheduler."""
    import os

    cpus = sorted(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else []
    if len(cpus) < 2 or not os.path.isdir("/proc/self/task"):
        pytest.skip("needs Linux and at least two CPUs")
    try:
        backend.init("cpu", threads=len(cpus))
        workers = backend.pinned_workers()
        assert [os.sched_getaffinity(t) for t in workers] == [{c} for c in cpus]
        x = ti.field(ti.f32, 1 << 22)

        @ti.kernel
        def busy():
            for i in range(x.shape[0]):
                v = ti.cast(i, ti.f32)
                for _ in range(30):
                    v = ti.sin(v) + 1.0
                x[i] = v

        def cpu_ticks(tid):  # utime + stime of a thread
            fields = open(f"/proc/self/task/{tid}/stat").read().rsplit(")", 1)[1].split()
            return int(fields[11]) + int(fields[12])

        before = [cpu_ticks(t) for t in workers]
        for _ in range(3):
            busy()
        ti.sync()
        assert sum(cpu_ticks(t) for t in workers) > sum(before)  # the pinned threads are Taichi's workers
        backend.init("cpu", threads=1)
        assert backend.pinned_workers() == []
    finally:
        tbd_taichi.init(TEST_ARCH)


def test_pinning_can_be_turned_off(monkeypatch):
    monkeypatch.setenv("TBD_TAICHI_PIN_THREADS", "0")
    assert backend.pin_worker_threads(set(), 2) == []
