"""Counter-based random numbers as ``ti.func`` (Taichi side).

A variate is a pure function of the key (seed, frame, stream, index), so results do
not depend on the thread count, the launch order or the backend.  ``ti.random`` keeps
per-thread state and is not reproducible on a multi-threaded CPU.

The hash is a chain of Wellons' ``lowbias32`` integer mixers (bijective on u32), one
round per key word plus a final round; only 32-bit unsigned operations are used, so
every backend (CPU, CUDA, Vulkan, Metal) gives the same bits.  The NumPy twin is
``tbd_taichi.numpy_kernels.rng``.
"""
import math

import numpy as np
import taichi as ti

GOLDEN = 0x9E3779B9
MIX1 = 0x7FEB352D
MIX2 = 0x846CA68B
INV_2_24 = 1.0 / 16777216.0
INV_2_53 = 1.0 / 9007199254740992.0
ZIG_LAYERS = 128  # ziggurat for N(0, 1), Marsaglia & Tsang (2000): 128 layers of equal area ZIG_V
ZIG_R = 3.442619855899  # x_1, where the tail begins
ZIG_V = 9.91256303526217e-3
ZIG_TRIES = 32  # hashes one normal may use (accepts at the first with probability 0.988)
EXP_LAYERS = 256  # ziggurat for Exp(1), Marsaglia & Tsang (2000): 256 layers of equal area EXP_V
EXP_R = 7.69711747013104972  # x_1, where the tail begins
EXP_V = 3.949659822581572e-3
INV_2_25 = 1.0 / 33554432.0


def ziggurat_layers() -> tuple[np.ndarray, np.ndarray]:
    """Layer edges x_0 = V/φ(R) > x_1 = R > … > x_127 > x_128 = 0 and φ_i = exp(−x_i²/2) (f64).
    Layer i ≥ 1 is the box [0, x_i] × [φ_i, φ_{i+1}] of area V; layer 0 is [0, R] × [0, φ(R)] plus the tail."""
    x = np.zeros(ZIG_LAYERS + 1)
    x[0], x[1] = ZIG_V / math.exp(-0.5 * ZIG_R * ZIG_R), ZIG_R
    for i in range(1, ZIG_LAYERS - 1):
        x[i + 1] = math.sqrt(-2.0 * math.log(ZIG_V / x[i] + math.exp(-0.5 * x[i] * x[i])))
    return x, np.exp(-0.5 * x * x)


def fast_accept_bounds(x: np.ndarray, bits: int) -> np.ndarray:
    """k_i with m < k_i ⇒ u·x_i < x_{i+1} for a ``bits``-bit position m and u = (2m + 1)·2^-(bits+1):
    the draws that lie under the curve without evaluating it."""
    return np.clip(np.floor(2.0 ** bits * x[1:] / x[:-1] - 0.5), 0, None).astype(np.uint32)


def ziggurat_tables() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(w, k, phi): layer widths x_i as f32, the 23-bit fast-accept bounds k_i and φ_0…φ_128 in f64."""
    x, phi = ziggurat_layers()
    return x[:-1].astype(np.float32), fast_accept_bounds(x, 23), phi


def exponential_layers() -> tuple[np.ndarray, np.ndarray]:
    """Layer edges x_0 = V·e^R > x_1 = R > … > x_255 > x_256 = 0 and f_i = exp(−x_i) (f64).  Layer i ≥ 1 is
    the box [0, x_i] × [f_i, f_{i+1}] of area V; layer 0 is [0, R] × [0, f(R)] plus the tail."""
    x = np.zeros(EXP_LAYERS + 1)
    x[0], x[1] = EXP_V * math.exp(EXP_R), EXP_R
    for i in range(1, EXP_LAYERS - 1):
        x[i + 1] = -math.log(EXP_V / x[i] + math.exp(-x[i]))
    return x, np.exp(-x)


def exponential_tables() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(w, k, f): layer widths x_i (f64), the 24-bit fast-accept bounds k_i and f_0…f_256."""
    x, f = exponential_layers()
    return x[:-1], fast_accept_bounds(x, 24), f


def table_field(values: np.ndarray, dtype):
    """A 1-D field holding ``values`` (after ``ti.init``)."""
    return table_fields((values, dtype))[0]


def table_fields(*tables) -> tuple:
    """1-D fields holding each (values, dtype) of ``tables``, filled by one kernel
    (``transfer.arrays_to_fields``; ``from_numpy`` compiles one kernel per field).  The fields form an SNode tree
    of their own: in the tree of fields made before them (a particle pool's, sized by the frame) their place would
    depend on the frame size, and so would every kernel that reads them, which would then compile again at each
    new frame size."""
    from .transfer import arrays_to_fields

    builder = ti.FieldsBuilder()
    fields = tuple(ti.field(dtype) for _, dtype in tables)
    for field, (values, _) in zip(fields, tables):
        builder.dense(ti.i, values.shape[0]).place(field)
    builder.finalize()
    sizes = [values.shape[0] for values, _ in tables]
    offsets = tuple(int(v) for v in np.cumsum([0] + sizes[:-1]))
    arrays_to_fields(np.concatenate([np.asarray(values, np.float64) for values, _ in tables]), fields, offsets)
    return fields


_SHARED: dict = {}  # tables class -> (the Taichi program they belong to, the instance)


def shared_tables(cls):
    """The one instance of tables class ``cls`` in the running Taichi program, built at the first call: every
    kernel class reads the same constant fields (each field filled from NumPy compiles a kernel of its own)."""
    from taichi.lang import impl

    program = impl.get_runtime().prog
    entry = _SHARED.get(cls)
    if entry is None or entry[0] is not program:
        entry = _SHARED[cls] = (program, cls())
    return entry[1]


class SharedTables:
    """Constant tables as fields, built after ``ti.init``: kernel classes take the :meth:`shared` instance."""

    @classmethod
    def shared(cls):
        """This program's one instance of the class (:func:`shared_tables`)."""
        return shared_tables(cls)


@ti.data_oriented
class NormalTables(SharedTables):
    """The ziggurat tables as fields; pass ``w, k, phi`` to :func:`normal_at`."""

    def __init__(self):
        w, k, phi = ziggurat_tables()
        self.w, self.k, self.phi = table_fields((w, ti.f32), (k, ti.u32), (phi, ti.f64))


@ti.data_oriented
class ExponentialTables(SharedTables):
    """The exponential ziggurat's tables as fields; pass ``w, k, f`` to :func:`exponential_at`."""

    def __init__(self):
        w, k, f = exponential_tables()
        self.w, self.k, self.f = table_fields((w, ti.f64), (k, ti.u32), (f, ti.f64))


@ti.func
def lowbias32(x: ti.u32) -> ti.u32:
    """Wellons' lowbias32 integer mixer (bijective on 32-bit words)."""
    x ^= x >> 16
    x *= ti.u32(MIX1)
    x ^= x >> 15
    x *= ti.u32(MIX2)
    x ^= x >> 16
    return x


@ti.func
def key_prefix(seed, frame, stream) -> ti.u32:
    """The hash state after (seed, frame, stream): compute it once per launch, outside the particle loop."""
    h = lowbias32(ti.cast(seed, ti.u32) ^ ti.u32(GOLDEN))
    h = lowbias32(h ^ ti.cast(frame, ti.u32))
    return lowbias32(h ^ ti.cast(stream, ti.u32))


@ti.func
def hash_index(prefix: ti.u32, index) -> ti.u32:
    """Finish the hash of a key from its prefix: hash_key(s, f, st, i) = hash_index(key_prefix(s, f, st), i)."""
    return lowbias32(lowbias32(prefix ^ ti.cast(index, ti.u32)) + ti.u32(GOLDEN))


@ti.func
def hash_key(seed, frame, stream, index) -> ti.u32:
    """32-bit hash of the key (seed, frame, stream, index); any integer types."""
    return hash_index(key_prefix(seed, frame, stream), index)


@ti.func
def unit_from_bits(h: ti.u32) -> ti.f32:
    """Map 32 random bits to the open interval (0, 1): (2·(h>>9)+1)·2^-24, exact in f32."""
    return ti.cast((h >> 9) * ti.u32(2) + ti.u32(1), ti.f32) * ti.f32(INV_2_24)


@ti.func
def uniform(seed, frame, stream, index) -> ti.f32:
    """U(0, 1) variate for the key, never exactly 0 or 1."""
    return unit_from_bits(hash_key(seed, frame, stream, index))


@ti.func
def uniform_at(prefix: ti.u32, index) -> ti.f32:
    """U(0, 1) for the key whose prefix is given (see key_prefix)."""
    return unit_from_bits(hash_index(prefix, index))


@ti.func
def uniform_f64(seed, frame, stream, index) -> ti.f64:
    """U(0, 1) in f64 with 53 random bits (two hashes of the key), for long cumulative sums."""
    return uniform_f64_at(key_prefix(seed, frame, stream), index)


@ti.func
def uniform_f64_at(prefix: ti.u32, index) -> ti.f64:
    """uniform_f64 for the key whose prefix is given."""
    h = hash_index(prefix, index)
    h2 = lowbias32(h + ti.u32(GOLDEN))
    hi = ti.cast(h >> 5, ti.f64)  # 27 bits
    lo = ti.cast(h2 >> 6, ti.f64)  # 26 bits
    return (hi * ti.f64(67108864.0) + lo + ti.f64(0.5)) * ti.f64(INV_2_53)


@ti.func
def zig_signed(h: ti.u32, x: ti.f32) -> ti.f32:
    """x with the sign of bit 7 of the draw."""
    return ti.select((h & ti.u32(128)) != 0, -x, x)


@ti.func
def normal_at(w: ti.template(), k: ti.template(), phi: ti.template(), prefix: ti.u32, index) -> ti.f32:
    """One N(0, 1) variate for the key with this prefix by the ziggurat (Marsaglia & Tsang 2000).

    Draw d hashes index·ZIG_TRIES + d: bits 0–6 pick layer i, bit 7 the sign, bits 9–31 the
    position u = (2m + 1)·2^-24 and x = u·x_i.  Accept at once if m < k_i (x under the curve: 98.8 %);
    the rest goes to :func:`normal_rejection`.  One hash and a table lookup for most variates
    (:func:`normals_at` with this one prefix)."""
    return normals_at(w, k, phi, [prefix], index)[0]


@ti.func
def normals_at(w: ti.template(), k: ti.template(), phi: ti.template(), prefixes: ti.template(), index):
    """One N(0, 1) variate per key prefix (u32) of the Python list ``prefixes``, as a ti.f32 vector, each equal to
    ``normal_at(w, k, phi, prefixes[d], index)`` (the ziggurat described there).  The fast draws run for every
    prefix; the slow path (:func:`normal_rejection`, taken by 1.2 % of the variates) has one call site, in a loop
    over the rejected ones, so a kernel that draws several normals per particle compiles it once instead of once
    per variate."""
    n = ti.static(len(prefixes))
    base = ti.cast(index, ti.u32) * ti.u32(ZIG_TRIES)
    out = ti.Vector([0.0] * n, dt=ti.f32)
    slow = ti.u32(0)
    for d in ti.static(range(n)):
        h = hash_index(prefixes[d], base)
        i = ti.cast(h & ti.u32(ZIG_LAYERS - 1), ti.i32)
        out[d] = zig_signed(h, unit_from_bits(h) * w[i])
        if (h >> 9) >= k[i]:
            slow |= ti.u32(1 << d)
    if slow != 0:
        for d in range(n):
            if (slow >> ti.cast(d, ti.u32)) & ti.u32(1) != 0:
                prefix = prefixes[0]
                for e in ti.static(range(1, n)):
                    if d == e:
                        prefix = prefixes[e]
                x = normal_rejection(w, k, phi, prefix, base, hash_index(prefix, base))
                for e in ti.static(range(n)):
                    if d == e:
                        out[e] = x
    return out


@ti.func
def normal_rejection(w: ti.template(), k: ti.template(), phi: ti.template(), prefix: ti.u32, base: ti.u32,
                     h0: ti.u32) -> ti.f32:
    """The ziggurat's slow path, from the rejected fast draw h0 on: in layer i ≥ 1 accept x if
    φ_i + U·(φ_{i+1} − φ_i) < exp(−x²/2) (f64), U from a second hash of the draw; in layer 0 switch to
    Marsaglia's tail, x = R − ln(U1)/R, kept if −2 ln U2 > (x − R)², until it accepts; otherwise a
    new draw.  After ZIG_TRIES draws (probability < 1e-50) the last x is used."""
    out = ti.f32(0.0)
    tail = False
    h = h0
    for d in range(ZIG_TRIES):
        if d > 0:
            h = hash_index(prefix, base + ti.cast(d, ti.u32))
        u2 = ti.cast(unit_from_bits(lowbias32(h + ti.u32(GOLDEN))), ti.f64)
        accept = False
        x = ti.f32(0.0)
        if not tail:
            i = ti.cast(h & ti.u32(ZIG_LAYERS - 1), ti.i32)
            x = unit_from_bits(h) * w[i]
            if (h >> 9) < k[i]:
                accept = True
            elif i == 0:
                tail = True
            else:
                x64 = ti.cast(x, ti.f64)
                accept = phi[i] + u2 * (phi[i + 1] - phi[i]) < ti.exp(ti.f64(-0.5) * x64 * x64)
        else:
            xt = -ti.log(ti.cast(unit_from_bits(h), ti.f64)) / ti.f64(ZIG_R)
            x = ti.cast(ti.f64(ZIG_R) + xt, ti.f32)
            accept = ti.f64(-2.0) * ti.log(u2) > xt * xt
        out = zig_signed(h, x)
        if accept:
            break
    return out


@ti.func
def exponential_position(h: ti.u32) -> ti.f64:
    """Bits 8–31 of a draw as u = (2m + 1)·2^-25 in (0, 1), exact in f64."""
    return ti.cast((h >> 8) * ti.u32(2) + ti.u32(1), ti.f64) * ti.f64(INV_2_25)


@ti.func
def exponential_at(w: ti.template(), k: ti.template(), f: ti.template(), prefix: ti.u32, index) -> ti.f64:
    """One Exp(1) variate (f64) for the key with this prefix by the ziggurat (Marsaglia & Tsang 2000).

    Draw d hashes index·ZIG_TRIES + d: bits 0–7 pick layer i, bits 8–31 the position u and x = u·x_i.
    Accept at once if m < k_i (x under the curve: 98.9 %); the rest goes to
    :func:`exponential_rejection`.  One hash, no logarithm, for most variates."""
    base = ti.cast(index, ti.u32) * ti.u32(ZIG_TRIES)
    h = hash_index(prefix, base)
    i = ti.cast(h & ti.u32(EXP_LAYERS - 1), ti.i32)
    out = exponential_position(h) * w[i]
    if (h >> 8) >= k[i]:
        out = exponential_rejection(w, k, f, prefix, base, h)
    return out


@ti.func
def exponential_rejection(w: ti.template(), k: ti.template(), f: ti.template(), prefix: ti.u32, base: ti.u32,
                          h0: ti.u32) -> ti.f64:
    """The exponential ziggurat's slow path, from the rejected fast draw h0 on: in layer i ≥ 1 accept x if
    f_i + U·(f_{i+1} − f_i) < exp(−x), U from a second hash of the draw; in layer 0 return the tail
    R − ln U (the tail of Exp(1) beyond R is R plus an Exp(1)); otherwise a new draw.  After
    ZIG_TRIES draws (probability < 1e-60) the last x is used."""
    out = ti.f64(0.0)
    h = h0
    for d in range(ZIG_TRIES):
        if d > 0:
            h = hash_index(prefix, base + ti.cast(d, ti.u32))
        u2 = ti.cast(unit_from_bits(lowbias32(h + ti.u32(GOLDEN))), ti.f64)
        i = ti.cast(h & ti.u32(EXP_LAYERS - 1), ti.i32)
        out = exponential_position(h) * w[i]
        accept = (h >> 8) < k[i]
        if not accept:
            if i == 0:
                out = ti.f64(EXP_R) - ti.log(u2)
                accept = True
            else:
                accept = f[i] + u2 * (f[i + 1] - f[i]) < ti.exp(-out)
        if accept:
            break
    return out


@ti.kernel
def fill_hash(out: ti.types.ndarray(dtype=ti.u32, ndim=1), seed: ti.u32, frame: ti.u32, stream: ti.u32, offset: ti.u32):
    """out[i] = hash_key(seed, frame, stream, offset + i)."""
    for i in range(out.shape[0]):
        out[i] = hash_key(seed, frame, stream, offset + ti.cast(i, ti.u32))


@ti.kernel
def fill_uniform(out: ti.types.ndarray(dtype=ti.f32, ndim=1), seed: ti.u32, frame: ti.u32, stream: ti.u32, offset: ti.u32):
    """out[i] = uniform(seed, frame, stream, offset + i)."""
    for i in range(out.shape[0]):
        out[i] = uniform(seed, frame, stream, offset + ti.cast(i, ti.u32))


@ti.kernel
def fill_uniform_f64(out: ti.types.ndarray(dtype=ti.f64, ndim=1), seed: ti.u32, frame: ti.u32, stream: ti.u32,
                     offset: ti.u32):
    """out[i] = uniform_f64(seed, frame, stream, offset + i)."""
    for i in range(out.shape[0]):
        out[i] = uniform_f64(seed, frame, stream, offset + ti.cast(i, ti.u32))


@ti.kernel
def fill_normal(out: ti.types.ndarray(dtype=ti.f32, ndim=1), w: ti.template(), k: ti.template(), phi: ti.template(),
                seed: ti.u32, frame: ti.u32, stream: ti.u32, offset: ti.u32):
    """out[i] = normal_at(tables, key_prefix(seed, frame, stream), offset + i)."""
    key = key_prefix(seed, frame, stream)
    for i in range(out.shape[0]):
        out[i] = normal_at(w, k, phi, key, offset + ti.cast(i, ti.u32))


@ti.kernel
def fill_exponential(out: ti.types.ndarray(dtype=ti.f64, ndim=1), w: ti.template(), k: ti.template(),
                     f: ti.template(), seed: ti.u32, frame: ti.u32, stream: ti.u32, offset: ti.u32):
    """out[i] = exponential_at(tables, key_prefix(seed, frame, stream), offset + i)."""
    key = key_prefix(seed, frame, stream)
    for i in range(out.shape[0]):
        out[i] = exponential_at(w, k, f, key, offset + ti.cast(i, ti.u32))
