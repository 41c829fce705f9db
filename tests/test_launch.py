"""The lean kernel launch (tbd_taichi.launch): the same results as Taichi's own launch for every
argument kind, Taichi's path for what it does not handle, and recompilation after a restart."""
import time
import types

import numpy as np
import pytest
import taichi as ti

import tbd_taichi
from tbd_taichi import backend, launch
from conftest import TEST_ARCH

VEC3 = ti.types.vector(3, ti.f32)


@ti.kernel
def mixed(a: ti.i32, u: ti.u32, x: ti.f32, d: ti.f64, src: ti.types.ndarray(dtype=ti.f32, ndim=2),
          vec: ti.types.ndarray(dtype=VEC3, ndim=1), table: ti.template(), flag: ti.template(),
          out: ti.types.ndarray(dtype=ti.f64, ndim=1)):
    for i in range(out.shape[0]):
        s = ti.cast(0.0, ti.f64)
        for j in range(src.shape[1]):
            s += ti.cast(src[i, j], ti.f64) * (j + 1)
        v = vec[i]
        s += ti.cast(v[0] - 2 * v[1] + 3 * v[2], ti.f64) + ti.cast(table[i], ti.f64)
        if ti.static(flag):
            s = -s
        out[i] = s + a * 1000 + ti.cast(u, ti.f64) * 0.5 + ti.cast(x, ti.f64) * 0.25 + d


@ti.kernel
def add_into(src: ti.types.ndarray(ndim=1), dst: ti.types.ndarray(ndim=1)):
    for i in range(src.shape[0]):
        dst[i] += src[i]


@ti.kernel
def total(src: ti.types.ndarray(dtype=ti.f32, ndim=1)) -> ti.f32:
    s = ti.f32(0.0)
    for i in range(src.shape[0]):
        s += src[i]
    return s


@ti.data_oriented
class Scaled:
    def __init__(self, n):
        self.values = ti.field(ti.f32, shape=n)
        self.factor = 3.0

    @ti.kernel
    def scale(self, factor: ti.f32, src: ti.types.ndarray(dtype=ti.f32, ndim=1)):
        for i in range(src.shape[0]):
            self.values[i] = factor * src[i]


def reference(a, u, x, d, src, vec, table, flag):
    """``mixed`` in NumPy (f64, the kernel's f32 inputs converted exactly)."""
    s = (src.astype(np.float64) * np.arange(1, src.shape[1] + 1)).sum(axis=1)
    s += (vec[:, 0] - 2 * vec[:, 1] + 3 * vec[:, 2]).astype(np.float32).astype(np.float64) + table
    return (-s if flag else s) + a * 1000 + u * 0.5 + np.float64(np.float32(x)) * 0.25 + d


@pytest.fixture
def taichi_calls(monkeypatch):
    """How many launches went through Taichi's own path."""
    calls = []
    original = launch.FastKernel._through_taichi

    def counted(self, *args):
        calls.append(self.kernel.func.__name__)
        return original(self, *args)

    monkeypatch.setattr(launch.FastKernel, "_through_taichi", counted)
    return calls


def mixed_inputs(rng, n=37, m=5):
    table = ti.field(ti.f32, shape=n)
    table.from_numpy(rng.normal(size=n).astype(np.float32))
    src = rng.normal(size=(n, m)).astype(np.float32)
    vec = rng.normal(size=(n, 3)).astype(np.float32)
    return src, vec, table


def test_lean_launch_gives_taichis_results_for_every_argument_kind(rng, taichi_calls):
    kernels = launch.Launcher(types.SimpleNamespace(mixed=mixed))
    src, vec, table = mixed_inputs(rng)
    out = np.empty(len(src))
    for k, (a, u, x, d, flag) in enumerate([(3, 7, 1.5, -2.25, False), (-4, 2**32 - 1, -0.1, 1e10, False),
                                            (0, 0, 3.3, 0.0, True), (9, 5, 2.0, 0.5, True)]):
        out[:] = np.nan
        kernels.mixed(a, u, x, d, src, vec, table, flag, out)
        expected = np.empty_like(out)
        mixed(a, u, x, d, src, vec, table, flag, expected)
        np.testing.assert_array_equal(out, expected)
        np.testing.assert_allclose(out, reference(a, u, x, d, src, vec, table.to_numpy(), flag), rtol=1e-6)
        src += 1  # new values each call: the lean path reads the arrays it is given
    # one Taichi launch per template value (flag False, flag True); the other two were lean
    assert taichi_calls == ["mixed", "mixed"]
    assert len(kernels.mixed.compiled) == 2


def test_new_array_dtype_compiles_again_and_each_stays_right(taichi_calls):
    kernels = launch.Launcher(types.SimpleNamespace(add_into=add_into))
    for dtype in (np.float32, np.int32, np.float32, np.float64, np.int32):
        src, dst = np.arange(11, dtype=dtype), np.ones(11, dtype=dtype)
        kernels.add_into(src, dst)
        np.testing.assert_array_equal(dst, np.arange(11, dtype=dtype) + 1)
    assert taichi_calls == ["add_into"] * 3  # f32, i32, f64 once each


def test_what_the_lean_path_does_not_handle_goes_through_taichi(rng, taichi_calls):
    kernels = launch.Launcher(types.SimpleNamespace(add_into=add_into, total=total, mixed=mixed))
    src = np.arange(12, dtype=np.float32)
    dst = np.zeros(12, np.float32)
    kernels.add_into(src, dst)
    kernels.add_into(src=src, dst=dst)  # keywords
    np.testing.assert_array_equal(dst, 2 * src)
    assert kernels.total(src) == pytest.approx(66.0)  # a return value
    assert kernels.total(src) == pytest.approx(66.0)
    image, vec, table = mixed_inputs(rng)
    out_c, out_f = np.empty(len(image)), np.empty(len(image))
    kernels.mixed(1, 2, 0.5, 0.25, image, vec, table, False, out_c)
    kernels.mixed(1, 2, 0.5, 0.25, np.asfortranarray(image), vec, table, False, out_f)  # Taichi copies it
    np.testing.assert_array_equal(out_f, out_c)
    assert taichi_calls == ["add_into", "add_into", "total", "total", "mixed", "mixed"]


def test_non_contiguous_array_is_taichis_error_not_a_wrong_result():
    kernels = launch.Launcher(types.SimpleNamespace(add_into=add_into))
    src = np.arange(10, dtype=np.float32)
    kernels.add_into(src, np.zeros(10, np.float32))  # compiled, so the next call could be lean
    with pytest.raises(ValueError, match="Non contiguous"):
        kernels.add_into(src[::2].copy(), np.zeros(20, np.float32)[::2])


def test_wrong_dtype_is_taichis_error():
    kernels = launch.Launcher(types.SimpleNamespace(mixed=mixed))
    src, vec, table = mixed_inputs(np.random.default_rng(1), n=4)
    kernels.mixed(1, 1, 1.0, 1.0, src, vec, table, False, np.empty(4))
    with pytest.raises(ValueError, match="dtype"):
        kernels.mixed(1, 1, 1.0, 1.0, src.astype(np.float64), vec, table, False, np.empty(4))
    with pytest.raises(Exception, match="cannot be converted|int"):
        kernels.mixed(1.5, 1, 1.0, 1.0, src, vec, table, False, np.empty(4))  # a float for an i32


def test_data_oriented_kernels_and_attributes(taichi_calls):
    obj = Scaled(9)
    kernels = launch.Launcher(obj)
    src = np.linspace(-1, 1, 9).astype(np.float32)
    for factor in (2.0, -0.5):
        kernels.scale(factor, src)
        np.testing.assert_array_equal(kernels.values.to_numpy(), np.float32(factor) * src)
    assert kernels.factor == 3.0
    kernels.factor = 4.0  # attributes are the target's own
    assert obj.factor == 4.0
    assert taichi_calls == ["scale"]


def test_runtime_restart_recompiles():
    kernels = launch.Launcher(types.SimpleNamespace(add_into=add_into))
    src = np.arange(5, dtype=np.float32)
    dst = np.zeros(5, np.float32)
    kernels.add_into(src, dst)
    try:
        tbd_taichi.init("cpu", threads=1)
        kernels.add_into(src, dst)
        kernels.add_into(src, dst)
    finally:
        tbd_taichi.init(TEST_ARCH)
    kernels.add_into(src, dst)
    np.testing.assert_array_equal(dst, 4 * src)
    assert backend.current().arch == TEST_ARCH


def test_gpu_backends_and_fresh_template_objects_keep_taichis_launch(monkeypatch, taichi_calls):
    kernels = launch.Launcher(types.SimpleNamespace(add_into=add_into, mixed=mixed))
    src, dst = np.arange(6, dtype=np.float32), np.zeros(6, np.float32)
    monkeypatch.setattr(launch, "LEAN_ARCHS", ())  # as on CUDA, Vulkan or Metal
    for _ in range(3):
        kernels.add_into(src, dst)
    np.testing.assert_array_equal(dst, 3 * src)
    assert taichi_calls == ["add_into"] * 3 and not kernels.add_into.compiled
    monkeypatch.undo()
    image, vec, _ = mixed_inputs(np.random.default_rng(2), n=3)
    out = np.empty(3)
    for k in range(launch.MAX_SIGNATURES + 4):  # a new field (template) each call: a new signature each call
        table = ti.field(ti.f32, shape=3)
        table.fill(k)
        kernels.mixed(0, 0, 0.0, 0.0, image, vec, table, False, out)
        np.testing.assert_allclose(out, reference(0, 0, 0.0, 0.0, image, vec, np.full(3, k), False), rtol=1e-6)
    assert len(kernels.mixed.compiled) == launch.MAX_SIGNATURES


def test_debug_mode_keeps_taichis_launch(taichi_calls):
    kernels = launch.Launcher(types.SimpleNamespace(add_into=add_into))
    src = np.arange(7, dtype=np.float32)
    dst = np.zeros(7, np.float32)
    try:
        tbd_taichi.init("cpu", debug=True)
        for _ in range(3):
            kernels.add_into(src, dst)
    finally:
        tbd_taichi.init(TEST_ARCH)
    np.testing.assert_array_equal(dst, 3 * src)
    assert taichi_calls == ["add_into"] * 3 and not kernels.add_into.compiled


def test_big_endian_array_is_taichis_error_not_a_wrong_result(taichi_calls):
    kernels = launch.Launcher(types.SimpleNamespace(add_into=add_into))
    src, dst = np.arange(8, dtype=np.float32), np.zeros(8, np.float32)
    kernels.add_into(src, dst)
    assert launch.lean_arguments(kernels.add_into.kinds, (src.astype(">f4"), dst)) == (None, None)
    with pytest.raises(AssertionError, match="Unknown type"):  # Taichi's own check, not the bytes as they are
        kernels.add_into(src.astype(">f4"), dst)
    np.testing.assert_array_equal(dst, src)
    assert taichi_calls == ["add_into", "add_into"]


def test_fields_made_between_lean_launches_are_materialised():
    kernels = launch.Launcher(types.SimpleNamespace(add_into=add_into))
    src, dst = np.arange(6, dtype=np.float32), np.zeros(6, np.float32)
    kernels.add_into(src, dst)
    runtime = launch.INTERNALS.impl.get_runtime()
    assert launch.fields_unchanged(runtime)
    late = ti.field(ti.f32, shape=6)  # a new field: the next launch must place it, as Taichi's own would
    assert not launch.fields_unchanged(runtime)
    kernels.add_into(src, dst)
    assert launch.fields_unchanged(runtime)
    late.from_numpy(src)
    np.testing.assert_array_equal(late.to_numpy(), src)
    np.testing.assert_array_equal(dst, 2 * src)


def test_launch_clock_adds_the_time_of_launches_made_while_it_is_active(monkeypatch):
    """Every active clock gets each launch's wall time (nested clocks both); none outside a clock, and a clock ends
    even when its block raises.  The launch is slowed by a known 20 ms so that the sums are checkable."""
    kernels = launch.Launcher(types.SimpleNamespace(add_into=add_into))
    src, dst = np.arange(5, dtype=np.float32), np.zeros(5, np.float32)
    kernels.add_into(src, dst)  # compiled outside the clocks
    original = launch.FastKernel._launch

    def slow(self, args, kwargs):
        time.sleep(0.02)
        return original(self, args, kwargs)

    monkeypatch.setattr(launch.FastKernel, "_launch", slow)
    with launch.LaunchClock() as outer:
        kernels.add_into(src, dst)
        with launch.LaunchClock() as inner:
            kernels.add_into(src, dst)
        time.sleep(0.05)  # host time: counted by neither
    kernels.add_into(src, dst)  # after the clocks: counted by neither
    assert 0.02 <= inner.seconds < 0.04 and 0.04 <= outer.seconds < 0.07
    np.testing.assert_array_equal(dst, 4 * src)
    with pytest.raises(RuntimeError):
        with launch.LaunchClock():
            raise RuntimeError("stop")
    assert launch.LAUNCH_CLOCKS == []


def test_taichi_internals_the_lean_path_uses_are_there_and_behave_as_assumed(taichi_calls):
    """Fails loudly on a Taichi upgrade that moves or changes the private names of launch.taichi_internals
    (the lean path would otherwise fall back to Taichi's launch without a word)."""
    assert launch.INTERNALS is not None, "launch.taichi_internals: this Taichi lacks a private name the lean path uses"
    assert launch.taichi_internals() is not None
    assert isinstance(mixed._primal.arguments, list) and mixed._primal.return_type is None and total._primal.return_type
    assert launch.argument_kinds(mixed._primal, 0) == (("i", 0), ("u", 0), ("f", 0), ("f", 0), ("a", 0), ("a", 1),
                                                        ("t", 0), ("t", 0), ("a", 0))
    assert isinstance(Scaled(2).scale, launch.INTERNALS.bound_method)
    kernels = launch.Launcher(types.SimpleNamespace(add_into=add_into))
    src, dst = np.arange(4, dtype=np.float32), np.zeros(4, np.float32)
    kernels.add_into(src, dst)  # through Taichi: compiles, and the lean path keeps the compiled kernel
    prog, kernel_cpp, data, _ = next(iter(kernels.add_into.compiled.values()))
    assert prog is launch.INTERNALS.impl.get_runtime().prog and not add_into._primal.has_print
    assert kernel_cpp is add_into._primal.compiled_kernels[add_into._primal.ensure_compiled(src, dst)]
    kernels.add_into(src, dst)  # lean
    np.testing.assert_array_equal(dst, 2 * src)
    assert taichi_calls == ["add_into"]


def test_without_the_internals_kernels_launch_through_taichis_public_call(monkeypatch, rng):
    """The fallback: a Taichi lacking the private names (INTERNALS None) gets the kernels themselves."""
    monkeypatch.setattr(launch, "INTERNALS", None)
    kernels = launch.Launcher(types.SimpleNamespace(mixed=mixed, add_into=add_into))
    assert kernels.mixed is mixed and kernels.add_into is add_into
    src, vec, table = mixed_inputs(rng)
    out = np.empty(len(src))
    kernels.mixed(3, 7, 1.5, -2.25, src, vec, table, True, out)
    np.testing.assert_allclose(out, reference(3, 7, 1.5, -2.25, src, vec, table.to_numpy(), True), rtol=1e-6)
    obj = Scaled(3)
    assert launch.Launcher(obj).scale(2.0, np.ones(3, np.float32)) is None
    np.testing.assert_array_equal(obj.values.to_numpy(), np.full(3, 2.0, np.float32))


def test_a_kernel_whose_internals_differ_falls_back_to_taichis_launch(monkeypatch, taichi_calls):
    """Where a kernel's own private attributes are not as assumed, that kernel keeps Taichi's launch."""
    kernels = launch.Launcher(types.SimpleNamespace(add_into=add_into))
    fast = kernels.add_into
    monkeypatch.setattr(fast, "kernel", _NoInternals(add_into._primal))
    src, dst = np.arange(5, dtype=np.float32), np.zeros(5, np.float32)
    for _ in range(3):
        fast(src, dst)
    np.testing.assert_array_equal(dst, 3 * src)
    assert taichi_calls == ["add_into"] * 3 and not fast.compiled and fast.kinds is None


class _NoInternals:
    """A kernel that launches but has none of the compiled-kernel internals (as after a Taichi upgrade)."""

    def __init__(self, kernel):
        self._kernel, self.func, self.has_print = kernel, kernel.func, False

    def __call__(self, *args, **kwargs):
        return self._kernel(*args, **kwargs)
