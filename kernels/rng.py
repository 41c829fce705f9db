"""Counter-based random numbers as ``ti.func`` (Taichi side).

A variate is a pure function of the key (seed, frame, stream, index), so results do
not depend on the thread count, the launch order or the backend.  ``ti.random`` keeps
per-thread state and is not reproducible on a multi-threaded CPU.

The hash is a chain of Wellons' ``lowbias32`` integer mixers (bijective on u32), one
round per key word plus a final round; only 32-bit unsigned operations are used, so
every backend (CPU, CUDA, Vulkan, Metal) gives the same bits.  The NumPy twin is
``tbd_taichi.numpy_kernels.rng``.
"""
import taichi as ti

GOLDEN = 0x9E3779B9
MIX1 = 0x7FEB352D
MIX2 = 0x846CA68B
TWO_PI = 6.283185307179586
INV_2_24 = 1.0 / 16777216.0
INV_2_53 = 1.0 / 9007199254740992.0
POLAR_TRIES = 32  # attempts of the polar method per normal pair


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
def normal_pair(prefix: ti.u32, index) -> ti.types.vector(2, ti.f32):
    """Two independent N(0, 1) variates for the key with this prefix: Marsaglia's polar method.

    Attempt k (k < POLAR_TRIES) hashes index·POLAR_TRIES + k into v1, v2 ~ U(−1, 1) and is kept if
    s = v1² + v2² < 1; the pair is v·√(−2 ln s / s).  One log and one square root, no sine or
    cosine (faster than Box–Muller on the CPU).  If every attempt fails (probability
    (1 − π/4)^32 ≈ 4e-22) the last one is used through Box–Muller."""
    out = ti.Vector([0.0, 0.0], dt=ti.f32)
    base = ti.cast(index, ti.u32) * ti.u32(POLAR_TRIES)
    for k in range(POLAR_TRIES):
        h = hash_index(prefix, base + ti.cast(k, ti.u32))
        u1 = unit_from_bits(h)
        u2 = unit_from_bits(lowbias32(h + ti.u32(GOLDEN)))
        v1, v2 = ti.f32(2.0) * u1 - ti.f32(1.0), ti.f32(2.0) * u2 - ti.f32(1.0)
        s = v1 * v1 + v2 * v2
        if s < ti.f32(1.0):
            f = ti.sqrt(ti.f32(-2.0) * ti.log(s) / s)
            out = ti.Vector([v1 * f, v2 * f], dt=ti.f32)
            break
        if k == POLAR_TRIES - 1:
            r = ti.sqrt(ti.f32(-2.0) * ti.log(u1))
            out = ti.Vector([r * ti.cos(ti.f32(TWO_PI) * u2), r * ti.sin(ti.f32(TWO_PI) * u2)], dt=ti.f32)
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
def fill_normal_pair(out1: ti.types.ndarray(dtype=ti.f32, ndim=1), out2: ti.types.ndarray(dtype=ti.f32, ndim=1),
                     seed: ti.u32, frame: ti.u32, stream: ti.u32, offset: ti.u32):
    """(out1[i], out2[i]) = normal_pair(key_prefix(seed, frame, stream), offset + i)."""
    key = key_prefix(seed, frame, stream)
    for i in range(out1.shape[0]):
        p = normal_pair(key, offset + ti.cast(i, ti.u32))
        out1[i] = p[0]
        out2[i] = p[1]
