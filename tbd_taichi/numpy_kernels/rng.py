"""NumPy twin of ``tbd_taichi.kernels.rng``: the same bits for the same keys."""
import numpy as np

from ..kernels.rng import GOLDEN, INV_2_24, INV_2_53, MIX1, MIX2, POLAR_TRIES, TWO_PI

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


def uniform_f64(seed, frame, stream, index) -> np.ndarray:
    """U(0, 1) float64 with 53 random bits, the same values as the kernel."""
    h = hash_key(seed, frame, stream, index)
    with np.errstate(over="ignore"):
        h2 = lowbias32(h + _U32(GOLDEN))
    hi = (h >> _U32(5)).astype(np.float64)
    lo = (h2 >> _U32(6)).astype(np.float64)
    return (hi * 67108864.0 + lo + 0.5) * INV_2_53


def normal_pair(seed, frame, stream, index) -> tuple[np.ndarray, np.ndarray]:
    """Two float32 N(0, 1) arrays for the keys by the polar method, attempt for attempt as the
    kernel's ``normal_pair(key_prefix(seed, frame, stream), index)``."""
    index = np.asarray(index, dtype=np.int64).reshape(-1)
    out1, out2 = np.zeros(len(index), np.float32), np.zeros(len(index), np.float32)
    todo = np.arange(len(index))
    for k in range(POLAR_TRIES):
        h = hash_key(seed, frame, stream, _as_u32(index[todo]) * _U32(POLAR_TRIES) + _U32(k))
        u1 = unit_from_bits(h)
        with np.errstate(over="ignore"):
            u2 = unit_from_bits(lowbias32(h + _U32(GOLDEN)))
        v1, v2 = np.float32(2.0) * u1 - np.float32(1.0), np.float32(2.0) * u2 - np.float32(1.0)
        s = v1 * v1 + v2 * v2
        ok = s < np.float32(1.0)
        if k == POLAR_TRIES - 1:  # Box–Muller on the last attempt's uniforms
            r = np.sqrt(np.float32(-2.0) * np.log(u1[~ok]))
            a = np.float32(TWO_PI) * u2[~ok]
            out1[todo[~ok]], out2[todo[~ok]] = r * np.cos(a), r * np.sin(a)
        f = np.sqrt(np.float32(-2.0) * np.log(s[ok]) / s[ok])
        out1[todo[ok]], out2[todo[ok]] = v1[ok] * f, v2[ok] * f
        todo = todo[~ok]
        if not len(todo):
            break
    return out1, out2
