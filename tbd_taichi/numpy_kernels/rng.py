"""NumPy twin of ``tbd_taichi.kernels.rng``: the same bits for the same keys."""
import numpy as np

from ..kernels.rng import (EXP_LAYERS, EXP_R, GOLDEN, INV_2_24, INV_2_25, INV_2_53, MIX1, MIX2, ZIG_LAYERS,
                           ZIG_R, ZIG_TRIES, exponential_tables, ziggurat_tables)

_U32 = np.uint32
ZIG_W, ZIG_K, ZIG_PHI = ziggurat_tables()
EXP_W, EXP_K, EXP_F = exponential_tables()


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


def normal(seed, frame, stream, index) -> np.ndarray:
    """float32 N(0, 1) for the keys by the ziggurat, draw for draw as the kernel's
    ``normal_at(tables, key_prefix(seed, frame, stream), index)``."""
    index = np.asarray(index, dtype=np.int64).reshape(-1)
    out = np.zeros(len(index), np.float32)
    todo = np.arange(len(index))
    tail = np.zeros(len(index), bool)
    for d in range(ZIG_TRIES):
        h = hash_key(seed, frame, stream, _as_u32(index[todo]) * _U32(ZIG_TRIES) + _U32(d))
        with np.errstate(over="ignore"):
            u2 = unit_from_bits(lowbias32(h + _U32(GOLDEN))).astype(np.float64)
        in_tail = tail[todo]
        i = (h & _U32(ZIG_LAYERS - 1)).astype(np.int64)
        u = unit_from_bits(h)
        x = u * ZIG_W[i]
        fast = ~in_tail & ((h >> _U32(9)) < ZIG_K[i])
        x64 = x.astype(np.float64)
        wedge = ~in_tail & ~fast & (i > 0) & (ZIG_PHI[i] + u2 * (ZIG_PHI[i + 1] - ZIG_PHI[i]) < np.exp(-0.5 * x64 * x64))
        xt = -np.log(u.astype(np.float64)) / ZIG_R
        tail_ok = in_tail & (-2.0 * np.log(u2) > xt * xt)
        x = np.where(in_tail, (ZIG_R + xt).astype(np.float32), x)
        x = np.where((h & _U32(128)) != 0, -x, x)
        accept = fast | wedge | tail_ok | (d == ZIG_TRIES - 1)
        out[todo[accept]] = x[accept]
        tail[todo[~in_tail & ~fast & (i == 0)]] = True
        todo = todo[~accept]
        if not len(todo):
            break
    return out


def exponential(seed, frame, stream, index) -> np.ndarray:
    """float64 Exp(1) for the keys by the ziggurat, draw for draw as the kernel's
    ``exponential_at(tables, key_prefix(seed, frame, stream), index)``."""
    index = np.asarray(index, dtype=np.int64).reshape(-1)
    out = np.zeros(len(index))
    todo = np.arange(len(index))
    for d in range(ZIG_TRIES):
        h = hash_key(seed, frame, stream, _as_u32(index[todo]) * _U32(ZIG_TRIES) + _U32(d))
        i = (h & _U32(EXP_LAYERS - 1)).astype(np.int64)
        x = ((h >> _U32(8)) * _U32(2) + _U32(1)).astype(np.float64) * INV_2_25 * EXP_W[i]
        fast = (h >> _U32(8)) < EXP_K[i]
        with np.errstate(over="ignore"):
            u2 = unit_from_bits(lowbias32(h + _U32(GOLDEN))).astype(np.float64)
        tail = ~fast & (i == 0)
        wedge = ~fast & (i > 0) & (EXP_F[i] + u2 * (EXP_F[np.minimum(i + 1, EXP_LAYERS)] - EXP_F[i]) < np.exp(-x))
        x = np.where(tail, EXP_R - np.log(u2), x)
        accept = fast | tail | wedge | (d == ZIG_TRIES - 1)
        out[todo[accept]] = x[accept]
        todo = todo[~accept]
        if not len(todo):
            break
    return out
