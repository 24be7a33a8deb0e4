"""Counter-based random numbers: photon i's numbers are a pure function of (seed, stream, i).

No state is carried from one photon to the next, so a batch of photons can be traced in any
order, on any thread or machine, and an edit can retrace exactly the photons it affects.
Each (photon, bounce) draws from its own 64-bit hash; :func:`uniforms` turns one
(key, index, counter) triple into uniform doubles in [0, 1).
"""
from __future__ import annotations

import numpy as np

_M1 = np.uint64(0xFF51AFD7ED558CCD)
_M2 = np.uint64(0xC4CEB9FE1A85EC53)
_S33 = np.uint64(33)
_S32 = np.uint64(32)
_LOW32 = np.uint64(0xFFFFFFFF)
_INV32 = 1.0 / 4294967296.0
#: The 64-bit golden-ratio increment that spreads seeds and counters.
GOLDEN = 0x9E3779B97F4A7C15

#: Random dimensions each bounce may use (pairs of 32-bit uniforms per hash).
DIMS_PER_BOUNCE = 4


def fmix64(k: np.ndarray) -> np.ndarray:
    """MurmurHash3's 64-bit finaliser: a bijective avalanche mix of uint64 values."""
    k = k ^ (k >> _S33)
    k = k * _M1
    k = k ^ (k >> _S33)
    k = k * _M2
    return k ^ (k >> _S33)


def stream_key(seed: int, emitter_key: int) -> np.uint64:
    """The 64-bit key of one emitter's photon stream under one seed."""
    a = np.array([(seed * GOLDEN) & 0xFFFFFFFFFFFFFFFF], dtype=np.uint64)
    b = np.array([emitter_key & 0xFFFFFFFFFFFFFFFF], dtype=np.uint64)
    return fmix64(fmix64(a) ^ b)[0]


def photon_hash(key: np.uint64, index: np.ndarray) -> np.ndarray:
    """The per-photon 64-bit hash every draw of photons ``index`` (int64, (N,)) starts from."""
    return fmix64(index.astype(np.uint64, copy=False) ^ key)


def uniforms(key: np.uint64, index: np.ndarray, counter: int, count: int = 2) -> list[np.ndarray]:
    """``count`` arrays of uniform doubles in [0, 1) for photons ``index`` (int64, (N,)).

    ``counter`` identifies the draw along the path (bounce * DIMS_PER_BOUNCE + dimension);
    each hash gives two independent 32-bit numbers.
    """
    return uniforms_from(photon_hash(key, index), counter, count)


def uniforms_from(base: np.ndarray, counter: int, count: int = 2) -> list[np.ndarray]:
    """:func:`uniforms` from the photons' :func:`photon_hash` values (kept along the path)."""
    out: list[np.ndarray] = []
    for j in range((count + 1) // 2):
        c = np.uint64(((counter + j + 1) * GOLDEN) & 0xFFFFFFFFFFFFFFFF)
        h = fmix64(base + c)
        out.append((h >> _S32).astype(np.float64) * _INV32)
        if len(out) < count:
            out.append((h & _LOW32).astype(np.float64) * _INV32)
    return out
