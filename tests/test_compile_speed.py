"""The front-end savings (tbd_taichi.compile_speed) and the compile accounting (tbd_taichi.compile_stats): the
Taichi names they replace exist, kernels built through them compute the same, a compile error still names the
file, line and function, and the counters count each kernel once."""
import inspect

import numpy as np
import pytest
import taichi as ti

import tbd_taichi
from tbd_taichi import backend, compile_speed, compile_stats


@pytest.fixture(autouse=True)
def cpu():
    tbd_taichi.init("cpu")


@ti.func
def squared_plus(v, k):
    return v * v + k


@ti.kernel
def free_kernel(out: ti.types.ndarray(dtype=ti.f32, ndim=1), k: ti.f32):
    for i in range(out.shape[0]):
        out[i] = squared_plus(ti.cast(i, ti.f32), k) + squared_plus(1.0, k)


@ti.data_oriented
class Owner:
    def __init__(self, n):
        self.a = ti.field(ti.f32, n)

    @ti.kernel
    def fill(self, k: ti.f32):
        for i in self.a:
            self.a[i] = squared_plus(ti.cast(i, ti.f32), k)


def test_the_replaced_taichi_names_exist_and_are_replaced():
    """A Taichi upgrade that renames them fails here instead of silently losing the speed."""
    assert compile_speed.taichi_front_end() is not None
    assert compile_speed.installed()
    from taichi.lang import kernel_impl
    from taichi.lang.ast.ast_transformer_utils import ASTTransformerContext

    assert kernel_impl._get_tree_and_ctx is compile_speed.cached_tree_and_ctx
    assert kernel_impl._inside_class is compile_speed.inside_class
    assert ASTTransformerContext.get_pos_info is compile_speed.brief_position
    assert all(m.get_traceback is compile_speed.brief_traceback for m in compile_speed.traceback_modules())


def test_class_kernels_are_told_from_free_kernels_as_taichi_does():
    assert free_kernel._is_classkernel is False
    assert Owner.fill._is_classkernel is True
    original = compile_speed._ORIGINAL["_inside_class"]

    class Probe:  # asked from a class body: two frames up, this function runs the ``class`` line
        ours = compile_speed.inside_class(2)
        theirs = original(2)

    assert Probe.ours is True and Probe.theirs is True
    assert compile_speed.inside_class(1) is False and original(1) is False


def test_kernels_built_through_the_cached_front_end_compute_the_same():
    out = np.zeros(7, np.float32)
    free_kernel(out, 2.0)
    assert np.array_equal(out, np.arange(7, dtype=np.float32) ** 2 + 2.0 + 3.0)
    owner = Owner(5)
    owner.fill(-1.0)
    assert np.array_equal(owner.a.to_numpy(), np.arange(5, dtype=np.float32) ** 2 - 1.0)
    file, lines, start, text = compile_speed.function_source(squared_plus.func.func)  # read once, kept
    assert file == inspect.getsourcefile(squared_plus.func.func) and start == inspect.getsourcelines(squared_plus.func.func)[1]
    assert text.startswith("@ti.func\ndef squared_plus")


def test_source_lines_match_inspect_for_every_taichi_function_of_the_project():
    """Every ti.func and ti.kernel of tbd_taichi and tbd_taichi.kernels: the file's one parse gives the lines that
    inspect's tokenising lookup gives (a decorated def, a class's method, a one-line body, a nested def)."""
    import importlib
    import pkgutil
    import sys

    from tbd_taichi import kernels

    for package in (kernels, tbd_taichi, tbd_taichi.methods):  # each package's own imports bring its submodules
        for info in pkgutil.iter_modules(package.__path__, package.__name__ + "."):
            if not info.name.endswith("__main__"):
                importlib.import_module(info.name)
    seen = 0
    for name, module in list(sys.modules.items()):
        if name.split(".")[0] == "tbd_taichi":
            for value in list(vars(module).values()) + [f for c in vars(module).values() if isinstance(c, type)
                                                        for f in vars(c).values()]:
                func = getattr(getattr(value, "_primal", value), "func", None)  # ti.kernel / ti.func wrappers
                func = getattr(func, "func", func)
                if not inspect.isfunction(func) or func.__module__ != module.__name__:
                    continue
                lines, start = inspect.getsourcelines(func)
                assert compile_speed.source_lines(func) == (inspect.getsourcefile(func), lines, start), func
                seen += 1
    assert seen > 100

    def outer():
        @ti.func
        def one_line(v): return v + 1  # noqa: E704

        return one_line

    nested = outer().func.func
    assert compile_speed.source_lines(nested)[1:] == tuple(inspect.getsourcelines(nested))


def test_declaration_tracebacks_keep_the_innermost_frames():
    def declare():
        return compile_speed.brief_traceback(1)  # as Taichi calls it: drop the declaring function's own frame

    def user_code():
        return declare()

    text = compile_speed.brief_traceback(0)
    assert "test_declaration_tracebacks_keep_the_innermost_frames" in text and "in brief_traceback" not in text
    text = user_code()
    assert text.count("File ") == compile_speed.TRACEBACK_FRAMES and "in user_code" in text.splitlines()[-2]
    assert "in declare" not in text


def test_a_compile_error_still_names_file_line_and_function():
    @ti.kernel
    def broken(out: ti.types.ndarray(dtype=ti.f32, ndim=1)):
        for i in range(out.shape[0]):
            out[i] = undefined_name  # noqa: F821

    line = inspect.getsourcelines(broken)[1] + 3
    with pytest.raises(Exception) as raised:
        broken(np.zeros(3, np.float32))
    message = str(raised.value)
    assert f'test_compile_speed.py", line {line}, in broken' in message
    assert "undefined_name" in message


def test_debug_mode_restores_taichis_own_front_end_and_install_brings_it_back():
    from taichi.lang import kernel_impl

    compile_speed.install(debug=True)
    try:
        assert not compile_speed.installed()
        assert kernel_impl._get_tree_and_ctx is not compile_speed.cached_tree_and_ctx
    finally:
        assert compile_speed.install()
    assert kernel_impl._get_tree_and_ctx is compile_speed.cached_tree_and_ctx


def test_compile_counts_count_each_new_kernel_once():
    assert compile_stats.start_counting()

    @ti.kernel
    def fresh(out: ti.types.ndarray(dtype=ti.f32, ndim=1), k: ti.f32):
        for i in range(out.shape[0]):
            out[i] = k * i

    before = compile_stats.compile_totals()
    out = np.zeros(4, np.float32)
    fresh(out, 2.0)
    first = compile_stats.compile_totals().since(before)
    assert first.kernels == 1 and first.first_launches == 1
    assert first.front_end_s > 0 and first.first_launch_s > 0 and first.seconds == pytest.approx(
        first.front_end_s + first.first_launch_s)
    fresh(out, 3.0)
    assert compile_stats.compile_totals().since(before) == first  # a second call builds nothing
    assert np.array_equal(out, 3.0 * np.arange(4, dtype=np.float32))
    assert set(first.as_dict()) == {"kernels", "compile_s", "front_end_s", "first_launch_s"}


def test_the_offline_cache_folder_is_known_and_counted():
    path = compile_stats.cache_directory()
    assert path and compile_stats.cache_file_count(path) >= 0
    assert compile_stats.cache_file_count("/nonexistent/folder") == 0


def test_the_files_a_run_wrote_are_counted_even_when_the_cache_trims(tmp_path):
    """Taichi trims the oldest cache entries past its size cap, so 'after − before' can undercount (or go below 0);
    ``since`` counts the files written from a moment on."""
    import os
    import time

    old = [tmp_path / f"old{i}.tic" for i in range(3)]
    for f in old:
        f.write_text("x")
        os.utime(f, (1_000_000_000, 1_000_000_000))
    started = time.time() - 1.0  # file times come from a coarse clock (a tick behind time.time())
    old[0].unlink()  # trimmed during the run
    old[1].unlink()
    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / "new.tic").write_text("y")
    assert compile_stats.cache_file_count(str(tmp_path)) == 2
    assert compile_stats.cache_file_count(str(tmp_path), since=started) == 1
    assert backend.current() is not None
