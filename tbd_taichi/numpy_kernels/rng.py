"""NumPy twin of ``tbd_taichi.kernels.rng``: the same bits for the same keys."""
import numpy as np

from ..kernels.rng import GOLDEN, INV_2_24, INV_2_53, MIX1, MIX2, TWO_PI

_U32 = np.uint32


def lowbias32(x: np.ndarray) -> np.ndarray:
    """Wellons' lowbias32 mixer on uint32 arrays (wrapping arithmetic)."""
    x = np.array(x, dtype=_U32, copy=True)
    with np.errstate(over="ignore"):
        x ^= x >> _U32(16)
        x *= _U32(MIX1)
        x ^= x >> _U32(15)
        x *= _U32(MIX2)
        x ^= x >> _U32(16)
    return x


def _as_u32(v) -> np.ndarray:
    """Integers to uint32 by two's-complement wrap, like ``ti.cast(v, ti.u32)``."""
    return np.asarray(np.asarray(v, dtype=np.int64) & 0xFFFFFFFF, dtype=_U32)


def hash_key(seed, frame, stream, index) -> np.ndarray:
    """32-bit hash of the key (seed, frame, stream, index); arguments broadcast."""
    with np.errstate(over="ignore"):
        h = lowbias32(_as_u32(seed) ^ _U32(GOLDEN))
        h = lowbias32(h ^ _as_u32(frame))
        h = lowbias32(h ^ _as_u32(stream))
        h = lowbias32(h ^ _as_u32(index))
        return lowbias32(h + _U32(GOLDEN))


def unit_from_bits(h: np.ndarray) -> np.ndarray:
    """(2·(h>>9)+1)·2^-24 as float32, in (0, 1)."""
    return ((h >> _U32(9)) * _U32(2) + _U32(1)).astype(np.float32) * np.float32(INV_2_24)


def uniform(seed, frame, stream, index) -> np.ndarray:
    """U(0, 1) float32 variates for the keys."""
    return unit_from_bits(hash_key(seed, frame, stream, index))


def normal(seed, frame, stream, index) -> np.ndarray:
    """N(0, 1) float32 variates for the keys (Box–Muller, f32 like the kernel)."""
    h = hash_key(seed, frame, stream, index)
    u1 = unit_from_bits(h)
    with np.errstate(over="ignore"):
        u2 = unit_from_bits(lowbias32(h + _U32(GOLDEN)))
    return np.sqrt(np.float32(-2.0) * np.log(u1)) * np.cos(np.float32(TWO_PI) * u2)


def uniform_f64(seed, frame, stream, index) -> np.ndarray:
    """U(0, 1) float64 with 53 random bits, the same values as the kernel."""
    h = hash_key(seed, frame, stream, index)
    with np.errstate(over="ignore"):
        h2 = lowbias32(h + _U32(GOLDEN))
    hi = (h >> _U32(5)).astype(np.float64)
    lo = (h2 >> _U32(6)).astype(np.float64)
    return (hi * 67108864.0 + lo + 0.5) * INV_2_53


def normal_pair(seed, frame, stream, index) -> tuple[np.ndarray, np.ndarray]:
    """Two float32 N(0, 1) arrays for the keys: r·cos and r·sin of one Box–Muller draw
    (the kernel's ``normal_pair(key_prefix(seed, frame, stream), index)``)."""
    h = hash_key(seed, frame, stream, index)
    u1 = unit_from_bits(h)
    with np.errstate(over="ignore"):
        u2 = unit_from_bits(lowbias32(h + _U32(GOLDEN)))
    r = np.sqrt(np.float32(-2.0) * np.log(u1))
    a = np.float32(TWO_PI) * u2
    return r * np.cos(a), r * np.sin(a)
