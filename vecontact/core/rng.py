"""Counter-based random numbers: a pure function of (seed, integer key(s), stream).

Nothing is sequential, so any rank can generate the numbers of any wavevector on its own and the result
does not depend on how the grid is split.  The mixing is SplitMix64's finaliser (Stafford "Mix13"
variant) applied in a chain: key words are absorbed one at a time, each one followed by a full mixing
round, which gives good avalanche for the small structured integer keys used here (wavevector indices).
Vectorised with numpy uint64 arithmetic (wrap-around modulo 2^64 is intended).
"""
from __future__ import annotations

import numpy as np

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)
_S30, _S27, _S31 = np.uint64(30), np.uint64(27), np.uint64(31)
_S11 = np.uint64(11)
_TWO53 = 1.0 / 9007199254740992.0  # 2^-53


def mix64(z):
    """SplitMix64 finaliser of a uint64 array (bijective)."""
    z = np.asarray(z, dtype=np.uint64)
    with np.errstate(over="ignore"):
        z = (z ^ (z >> _S30)) * _M1
        z = (z ^ (z >> _S27)) * _M2
        return z ^ (z >> _S31)


def _u64(x):
    """Signed or unsigned integers -> uint64 two's complement (no overflow errors)."""
    a = np.asarray(x)
    if a.dtype == np.uint64:
        return a
    return a.astype(np.int64).view(np.uint64) if a.dtype.kind in "iub" else np.asarray(a, dtype=np.int64).view(np.uint64)


def hash64(seed, *keys, stream=0):
    """uint64 hash of (seed, stream, key_1, key_2, ...); keys are integer arrays broadcast together."""
    s = np.uint64(int(seed) & 0xFFFFFFFFFFFFFFFF)
    with np.errstate(over="ignore"):
        h = mix64(s + _GOLDEN)
        h = mix64(h ^ (np.uint64(int(stream) & 0xFFFFFFFFFFFFFFFF) * _GOLDEN + _M2))
        for k in keys:
            h = mix64((h + _GOLDEN) ^ mix64(_u64(k) + _M1))
    return h


def uniform(seed, *keys, stream=0):
    """Uniform doubles in [0, 1) with 53 random bits, a pure function of (seed, keys, stream)."""
    h = hash64(seed, *keys, stream=stream)
    return (h >> _S11).astype(np.float64) * _TWO53


def normal_pair(seed, *keys, stream=0):
    """Two independent standard normal arrays (Box-Muller on streams 2*stream, 2*stream+1)."""
    u1 = uniform(seed, *keys, stream=2 * stream)
    u2 = uniform(seed, *keys, stream=2 * stream + 1)
    r = np.sqrt(-2.0 * np.log1p(-u1))  # 1 - u1 in (0, 1]
    t = 2.0 * np.pi * u2
    return r * np.cos(t), r * np.sin(t)
