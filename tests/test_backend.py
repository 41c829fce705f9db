"""Backend selection: clear errors, safe repeated init, offline cache."""
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
