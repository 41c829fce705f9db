"""A lean launch path for Taichi kernels that run every frame.

Taichi 1.7's Python launch (``Kernel.__call__``) costs far more than a small kernel's work: it rebuilds
the template key of every argument, looks the compiled kernel up through ``prog.compile_kernel`` and
sets each NumPy argument through several checks, on every call.

``Launcher(target)`` wraps a kernels module or a ``@ti.data_oriented`` object: its kernels, looked
up as attributes, are ``FastKernel`` objects.  A ``FastKernel`` makes its first call with each
argument signature through Taichi itself (which compiles and checks everything), keeps the
compiled kernel, and launches later calls with the same signature directly: a launch context, one
setter call per argument and ``prog.launch_kernel``, the same C++ calls Taichi's own path ends in
(a small fraction of the public call's cost).  Anything the lean path does not handle goes through Taichi: keyword arguments,
kernels with a return value or ``print``, debug mode, and arguments other than NumPy C-contiguous
arrays, Python/NumPy scalars and template values.  Every other attribute is the target's own.

The lean path runs on the CPU backends only (``LEAN_ARCHS``).  On a GPU the same C++ calls would also
copy host arrays to the device and back, but that has not been tested on a device yet, so GPU
backends keep Taichi's own launch.

Taichi has no public API for this, so every private Taichi name used here comes from one function,
:func:`taichi_internals`, checked once at import: where this Taichi lacks one of them, ``INTERNALS`` is None
and :class:`Launcher` hands out the kernels themselves (Taichi's public call, the same results).
``tests/test_launch.py`` asserts that they exist and behave as assumed, so a Taichi upgrade that changes
them fails there loudly instead of only falling back silently.
"""
from __future__ import annotations

import time

import types

import numpy as np
import taichi as ti
from taichi.types import template

from .light_ir import compile_setting

SCALAR_KEYS = (bool, int, float, str)  # template values that key a compiled kernel by value
INTS = (int, np.integer)
FLOATS = (float, int, np.floating, np.integer)
MAX_SIGNATURES = 16  # compiled signatures kept per kernel (a caller passing fresh objects as templates adds one per call)
LEAN_ARCHS = (ti.x64, ti.arm64)  # the CPU backends; GPU backends launch through Taichi (module notes)
LAUNCH_CLOCKS: list = []  # the active LaunchClock objects
PRIVATE_METHODS = {  # Taichi's C++ classes (``taichi._lib.core``) and the methods the lean path calls
    "Program": ("compile_kernel", "launch_kernel", "config", "get_device_caps"),
    "Kernel": ("make_launch_context",),
    "KernelLaunchContext": ("set_arg_external_array_with_shape", "set_arg_float", "set_arg_int", "set_arg_uint"),
}


def taichi_internals():
    """The private Taichi (1.7) names the lean path uses, as one namespace, or None where this Taichi lacks
    one of them (then kernels launch through Taichi's public call).  Per-kernel attributes
    (``arguments``, ``compiled_kernels``, ``ensure_compiled``, ``has_print``) are checked by the tests."""
    try:
        from taichi._lib import core
        from taichi.lang import impl
        from taichi.lang.kernel_impl import Kernel, _BoundedDifferentiableMethod
        from taichi.lang.util import cook_dtype
        from taichi.types import ndarray_type, primitive_types
        from taichi.types.utils import is_signed
    except ImportError:
        return None
    present = all(hasattr(getattr(core, cls, None), m) for cls, methods in PRIVATE_METHODS.items() for m in methods)
    present = present and all(hasattr(impl, n) for n in ("get_runtime", "_root_fb")) and \
        hasattr(Kernel, "ensure_compiled") and hasattr(ndarray_type, "NdarrayType") and \
        all(hasattr(primitive_types, n) for n in ("type_ids", "real_type_ids", "integer_type_ids"))
    if not present:
        return None
    return types.SimpleNamespace(impl=impl, bound_method=_BoundedDifferentiableMethod, ndarray_type=ndarray_type,
                                 primitive_types=primitive_types, cook_dtype=cook_dtype, is_signed=is_signed)


INTERNALS = taichi_internals()


def argument_kinds(kernel, skip: int) -> tuple:
    """Per kernel argument after the first ``skip`` (the data-oriented owner): "t" template, "a" array
    (with its element dimensions), "f" float, "i" signed or "u" unsigned integer; None when an argument
    has another type (such kernels always launch through Taichi)."""
    kinds = []
    ndarray_type, primitive_types = INTERNALS.ndarray_type, INTERNALS.primitive_types
    for arg in kernel.arguments[skip:]:
        ann = arg.annotation
        if isinstance(ann, template):
            kinds.append(("t", 0))
        elif isinstance(ann, ndarray_type.NdarrayType):
            scalar = ann.dtype is None or id(ann.dtype) in primitive_types.type_ids
            kinds.append(("a", 0 if scalar else ann.dtype.ndim))
        elif id(ann) in primitive_types.real_type_ids:
            kinds.append(("f", 0))
        elif id(ann) in primitive_types.integer_type_ids:
            kinds.append(("i" if INTERNALS.is_signed(INTERNALS.cook_dtype(ann)) else "u", 0))
        else:
            return None
    return tuple(kinds)


def lean_arguments(kinds: tuple, args: tuple):
    """(key, values) of a call the lean path can launch, else (None, None).  ``key`` decides the compiled
    kernel and the setters: template values (by value for scalars, else by identity), array dtype and
    rank, scalar types.  ``values``: per non-template argument, (shape without element dimensions,
    address, bytes) for an array, else the scalar.  An array's ``__array_interface__`` gives its
    address, dtype and shape at once, and strides None exactly when it is C-contiguous."""
    if len(args) != len(kinds):
        return None, None
    key, values = [], []
    for (kind, element_dims), v in zip(kinds, args):
        if kind == "t":
            key.append((type(v), v) if type(v) in SCALAR_KEYS else id(v))
        elif kind == "a":
            if type(v) is not np.ndarray:
                return None, None
            face = v.__array_interface__
            typestr, shape = face["typestr"], face["shape"]
            if face["strides"] is not None or typestr[0] == ">":  # not C-contiguous, or big-endian
                return None, None
            key.append((typestr, len(shape)))
            values.append((shape[: len(shape) - element_dims] if element_dims else shape, face["data"][0], v.nbytes))
        elif isinstance(v, INTS if kind in "iu" else FLOATS):
            values.append(v)
        else:
            return None, None
    return tuple(key), values


def fields_unchanged(runtime) -> bool:
    """No field made, and no fields builder opened, since the last launch: then Taichi's
    ``materialize`` (which every launch calls) would do nothing."""
    builders = runtime.unfinalized_fields_builder
    return (runtime.materialized and not runtime.global_vars and not runtime.matrix_fields and not runtime.grad_vars
            and not runtime.dual_vars
            and (not builders or (len(builders) == 1 and INTERNALS.impl._root_fb in builders)))


class FastKernel:
    """One kernel (``kernel``: Taichi's ``Kernel``; ``owner``: its data-oriented object, or None)
    called like the kernel itself."""

    def __init__(self, kernel, owner=None):
        self.kernel, self.lead = kernel, (() if owner is None else (owner,))
        self.kinds = None if kernel.return_type is not None else argument_kinds(kernel, len(self.lead))
        self.value_kinds = tuple(kind for kind, _ in self.kinds or () if kind != "t")  # the non-template arguments
        self.compiled = {}  # signature key → (program, kernel's C++ object, compiled data, template args kept alive)

    def __call__(self, *args, **kwargs):
        if not LAUNCH_CLOCKS:
            return self._launch(args, kwargs)
        t0 = time.perf_counter()
        try:
            return self._launch(args, kwargs)
        finally:
            elapsed = time.perf_counter() - t0
            for clock in LAUNCH_CLOCKS:
                clock.add(self.kernel.func.__name__, elapsed)

    def _launch(self, args: tuple, kwargs: dict):
        key, values = (None, None) if kwargs or self.kinds is None else lean_arguments(self.kinds, args)
        runtime = INTERNALS.impl.get_runtime()
        entry = self.compiled.get(key) if key is not None else None
        if entry is None or entry[0] is not runtime.prog:
            return self._through_taichi(key, runtime, args, kwargs)
        prog, kernel_cpp, data, _ = entry
        if not fields_unchanged(runtime):
            runtime.materialize()  # fields made since the last launch (as Taichi's launch does)
        ctx = kernel_cpp.make_launch_context()
        for slot, (kind, v) in enumerate(zip(self.value_kinds, values)):
            if kind == "a":
                shape, address, nbytes = v
                ctx.set_arg_external_array_with_shape((slot,), address, nbytes, shape, 0)
            elif kind == "f":
                ctx.set_arg_float((slot,), float(v))
            elif kind == "i":
                ctx.set_arg_int((slot,), int(v))
            else:
                ctx.set_arg_uint((slot,), int(v))
        prog.launch_kernel(data, ctx)
        return None

    def _through_taichi(self, key, runtime, args, kwargs):
        """Taichi's own launch (it compiles and checks); then keep the compiled kernel for ``key``."""
        out = self.kernel(*self.lead, *args, **kwargs)
        try:
            if key is not None and self._keeps(runtime):
                kernel_cpp = self.kernel.compiled_kernels[self.kernel.ensure_compiled(*self.lead, *args)]
                prog = runtime.prog
                with compile_setting(self.kernel):  # the build Taichi's launch made (light IR or not)
                    data = prog.compile_kernel(prog.config(), prog.get_device_caps(), kernel_cpp)
                templates = tuple(v for (kind, _), v in zip(self.kinds, args) if kind == "t")
                self.compiled[key] = (prog, kernel_cpp, data, templates)
        except (AttributeError, KeyError, TypeError):  # Taichi's kernel internals differ: its own launch from now on
            self.kinds = None
        return out

    def _keeps(self, runtime) -> bool:
        """Whether a compiled kernel is kept for the lean path: no ``print`` (known once compiled), a CPU
        backend out of debug mode (both fixed for the program, which every lean call checks is the same),
        and room for another signature."""
        config = runtime.prog.config()
        return (not self.kernel.has_print and config.arch in LEAN_ARCHS and not config.debug
                and len(self.compiled) < MAX_SIGNATURES)


class LaunchClock:
    """Wall seconds spent in :class:`FastKernel` launches while active
    (``with LaunchClock() as clock: …``, then ``clock.seconds``, and per kernel name ``clock.by_kernel``).
    On the CPU backends a launch returns when its kernel has run, so this is the kernels' time as the host
    sees it, launch costs included; on a GPU, launches are asynchronous and this is not the kernels' time."""

    def __init__(self):
        self.by_kernel: dict[str, float] = {}

    @property
    def seconds(self) -> float:
        return sum(self.by_kernel.values())

    def add(self, kernel: str, seconds: float) -> None:
        self.by_kernel[kernel] = self.by_kernel.get(kernel, 0.0) + seconds

    def __enter__(self) -> "LaunchClock":
        LAUNCH_CLOCKS.append(self)
        return self

    def __exit__(self, *exc) -> None:
        LAUNCH_CLOCKS.remove(self)


class Launcher:
    """``target``'s attributes, with its Taichi kernels as :class:`FastKernel` objects (made once)."""

    def __init__(self, target):
        object.__setattr__(self, "_target", target)

    def __getattr__(self, name):
        value = getattr(self._target, name)
        if INTERNALS is None:  # this Taichi lacks what the lean path needs: its own launch
            return value
        try:
            if isinstance(value, INTERNALS.bound_method) and not value._is_staticmethod:
                fast = FastKernel(value._primal, value._kernel_owner)
            elif getattr(value, "_is_wrapped_kernel", False) and not getattr(value, "_is_classkernel", True):
                fast = FastKernel(value._primal)
            else:
                return value
        except AttributeError:  # a kernel object laid out otherwise than in Taichi 1.7: its own launch
            return value
        object.__setattr__(self, name, fast)  # later lookups skip __getattr__
        return fast

    def __setattr__(self, name, value):
        setattr(self._target, name, value)
