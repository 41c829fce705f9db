"""Copies between Taichi fields and host (NumPy) arrays, as typed kernels.

``field.to_numpy()`` and ``field.from_numpy()`` pay Taichi's generic argument handling on every
call, whatever the size; these kernels take the field as a template and the array with a fixed
number of dimensions, so a call costs a fraction of that.  Shapes
are checked by the callers, ``tbd_taichi.backend.to_host`` / ``from_host``, which are
plain NumPy copies for the NumPy engine's arrays.  ``serial`` runs the loop on one thread
(the CPU, where a parallel launch costs more than the copy).
"""
import taichi as ti


@ti.kernel
def field_to_array_1d(src: ti.template(), dst: ti.types.ndarray(ndim=1), serial: ti.template()):
    """dst[i] = src[i]."""
    ti.loop_config(serialize=serial)
    for i in range(dst.shape[0]):
        dst[i] = src[i]


@ti.kernel
def field_to_array_2d(src: ti.template(), dst: ti.types.ndarray(ndim=2), serial: ti.template()):
    """dst[i, j] = src[i, j]."""
    ti.loop_config(serialize=serial)
    for i in range(dst.shape[0]):
        for j in range(dst.shape[1]):
            dst[i, j] = src[i, j]


@ti.kernel
def array_to_field_1d(src: ti.types.ndarray(ndim=1), dst: ti.template(), serial: ti.template()):
    """dst[i] = src[i]."""
    ti.loop_config(serialize=serial)
    for i in range(src.shape[0]):
        dst[i] = src[i]


@ti.kernel
def array_to_field_2d(src: ti.types.ndarray(ndim=2), dst: ti.template(), serial: ti.template()):
    """dst[i, j] = src[i, j]."""
    ti.loop_config(serialize=serial)
    for i in range(src.shape[0]):
        for j in range(src.shape[1]):
            dst[i, j] = src[i, j]


@ti.func
def flat_index(index, shape: ti.template()):
    """The row-major position of ``index`` in an array of ``shape``."""
    out = index[0]
    for d in ti.static(range(1, len(shape))):
        out = out * shape[d] + index[d]
    return out


@ti.kernel
def arrays_to_fields(src: ti.types.ndarray(dtype=ti.f64, ndim=1), fields: ti.template(), offsets: ti.template()):
    """fields[j] ← src[offsets[j] : offsets[j] + size] in row-major order, converted to the field's dtype (exact
    for f32, i32 and u32 values): one kernel for a batch of fields, where ``from_numpy`` compiles one per field."""
    for j in ti.static(range(len(fields))):
        for index in ti.grouped(fields[j]):
            fields[j][index] = ti.cast(src[offsets[j] + flat_index(index, fields[j].shape)], fields[j].dtype)


@ti.kernel
def zero_fields(fields: ti.template()):
    """Every element of each field in ``fields`` ← 0 (one kernel for the batch, where ``fill`` compiles one per
    field)."""
    for j in ti.static(range(len(fields))):
        for index in ti.grouped(fields[j]):
            fields[j][index] = 0
