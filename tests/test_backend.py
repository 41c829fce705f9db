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


@pytest.mark.parametrize("n", [0, 1, 6, 10])
@pytest.mark.parametrize("dtype", [np.int32, np.float32])
def test_leading_host_copies_fill_the_start_and_keep_the_rest(n, dtype):
    """backend.from_host_leading: a frame into the start of a field (or array) of its size class."""
    before = np.arange(10, 20).astype(dtype)
    values = (np.arange(n) * -3).astype(dtype)
    expected = np.concatenate([values, before[n:]])
    for target in (ti.field(ti.lang.util.to_taichi_type(dtype), shape=10), before.copy()):
        backend.from_host(target, before)
        backend.from_host_leading(target, values)
        np.testing.assert_array_equal(backend.to_host(target), expected)
    with pytest.raises(ValueError, match="does not fit"):
        backend.from_host_leading(ti.field(ti.f32, shape=10), np.zeros(11, np.float32))


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


class Holder:
    """Fields (or NumPy arrays) as attributes, as a kernels object holds them."""


@pytest.mark.parametrize("seed", [0, 1])
def test_batch_writes_equal_one_copy_per_field(seed):
    """from_host_many / zero_many against from_numpy / fill, on 1-D, 2-D and 3-D fields of odd sizes and every batched
    dtype, with extreme values (f32 max, u32 max, i32 min) that an f64 carrier must keep exact."""
    tbd_taichi.init(TEST_ARCH)
    rng = np.random.default_rng(seed)
    specs = {"a": (ti.f32, np.float32, (7,)), "b": (ti.i32, np.int32, (3, 5)), "c": (ti.u32, np.uint32, (1,)),
             "d": (ti.f64, np.float64, (4, 1)), "e": (ti.f32, np.float32, (2, 3)), "g": (ti.i32, np.int32, (2, 3, 5))}
    values = {"a": rng.normal(size=7).astype(np.float32), "b": rng.integers(-2**31, 2**31 - 1, (3, 5)).astype(np.int32),
              "c": np.array([2**32 - 1], np.uint32), "d": rng.normal(size=(4, 1)) * 1e300,
              "e": np.array([[np.finfo(np.float32).max, -1.5, 0.1], [np.finfo(np.float32).tiny, 0, -0.0]], np.float32)}
    values["g"] = rng.integers(-1000, 1000, (2, 3, 5)).astype(np.int32)
    values["b"][0, 0] = -2**31
    ours, theirs = Holder(), Holder()
    for name, (dtype, _, shape) in specs.items():
        setattr(ours, name, ti.field(dtype, shape))
        setattr(theirs, name, ti.field(dtype, shape))
    backend.from_host_many(ours, values)
    for name, (_, np_dtype, _) in specs.items():
        getattr(theirs, name).from_numpy(values[name].astype(np_dtype))
        assert np.array_equal(getattr(ours, name).to_numpy(), getattr(theirs, name).to_numpy()), name
    backend.zero_many(ours, ("a", "b", "e", "g"))
    for name in ("a", "b", "e", "g"):
        assert not getattr(ours, name).to_numpy().any()
    assert np.array_equal(ours.c.to_numpy(), values["c"])  # not zeroed


def test_batch_writes_to_numpy_and_other_fields():
    tbd_taichi.init(TEST_ARCH)
    target = Holder()
    target.arr = np.ones((2, 3), np.float32)
    target.vec = ti.Vector.field(2, ti.f32, 3)  # not a scalar field: copied on its own
    target.i64 = ti.field(ti.i64, 2)  # not held exactly in f64: copied on its own
    vec = np.arange(6, dtype=np.float32).reshape(3, 2)
    backend.from_host_many(target, {"arr": np.full((2, 3), 4.0), "vec": vec, "i64": np.array([2**60 + 1, -3])})
    assert (target.arr == 4).all() and np.array_equal(target.vec.to_numpy(), vec)
    assert target.i64.to_numpy().tolist() == [2**60 + 1, -3]
    backend.zero_many(target, ("arr", "vec", "i64"))  # zero is exact in any dtype: one batch kernel for the fields
    assert not target.arr.any() and not target.vec.to_numpy().any() and not target.i64.to_numpy().any()
    target.f = ti.field(ti.f32, 4)
    with pytest.raises(ValueError, match=r"f: array of shape \(5,\)"):
        backend.from_host_many(target, {"f": np.zeros(5)})


def test_new_fields_are_zeros_and_reused_sets_say_so():
    """The set-up skips zeroing new fields (backend.holds_old_values): Taichi must zero-fill every new field,
    also after other fields were written and their memory freed; a reused set is reported as holding values."""
    import gc

    backend.init("cpu")

    class Owner:
        pass

    class Fields:
        def __init__(self):
            self.all = (ti.field(ti.f32, 5000), ti.field(ti.i32, (70, 90)))

    make = Fields

    first = Owner()
    fields = backend.reusable(first, ("zero-test", 5000), make)
    assert not backend.holds_old_values(fields)
    for f in fields.all:
        f.fill(7)
    fb = ti.FieldsBuilder()
    tmp = ti.field(ti.f64)
    fb.dense(ti.i, 20000).place(tmp)
    tree = fb.finalize()
    tmp.fill(-3.5)
    tree.destroy()
    for _ in range(3):
        fresh = make()
        assert all(not np.any(f.to_numpy()) for f in fresh.all)
    del first
    gc.collect()
    second = Owner()
    again = backend.reusable(second, ("zero-test", 5000), make)
    assert again is fields and backend.holds_old_values(again)
    assert again.all[0].to_numpy().max() == 7
