"""Kernels of counter-based random numbers: Philox4x64-10, as ``numpy.random.Philox``.

Block ``b`` of run ``i``'s stream ``s`` under key ``(k0, k1)`` is the Philox of the counter
``(b + 1, 0, i, s)`` (Salmon et al., SC 2011): a draw depends on (key, run, stream, position)
only, not on how runs are grouped.
"""

from __future__ import annotations

import math

import numpy as np


PHILOX_M0 = np.uint64(0xD2E7470EE14C6C93)
PHILOX_M1 = np.uint64(0xCA5A826395121157)
PHILOX_W0 = np.uint64(0x9E3779B97F4A7C15)
PHILOX_W1 = np.uint64(0xBB67AE8584CAA73B)
LOW32 = np.uint64(0xFFFFFFFF)
SHIFT32 = np.uint64(32)
SHIFT11 = np.uint64(11)
DOUBLE_UNIT = 1.0 / 9007199254740992.0          # 2^-53

_IEEE = {"error_model": "numpy"}   # IEEE division: x / 0 is inf or NaN (as NumPy), never raises
#: The kernels of this module and their numba options (toolkit._compiled.load compiles them).
KERNELS = {"mulhilo": {}, "philox_block": {}, "philox_uniform": {}}


def mulhilo(a: np.uint64, b: np.uint64) -> tuple[np.uint64, np.uint64]:
    """The high and low 64-bit words of the 128-bit product ``a b`` (unsigned)."""
    a_lo, a_hi = a & LOW32, a >> SHIFT32
    b_lo, b_hi = b & LOW32, b >> SHIFT32
    p0 = a_lo * b_lo
    p1 = a_lo * b_hi
    p2 = a_hi * b_lo
    p3 = a_hi * b_hi
    carry = ((p0 >> SHIFT32) + (p1 & LOW32) + (p2 & LOW32)) >> SHIFT32
    return p3 + (p1 >> SHIFT32) + (p2 >> SHIFT32) + carry, a * b


def philox_block(c0: np.uint64, c1: np.uint64, c2: np.uint64, c3: np.uint64, k0: np.uint64,
                 k1: np.uint64, out: np.ndarray) -> None:
    """Ten Philox4x64 rounds of the counter ``(c0, c1, c2, c3)`` under the key ``(k0, k1)``:
    four 64-bit words into ``out`` (4,), uint64."""
    for r in range(10):
        if r > 0:
            k0 = k0 + PHILOX_W0
            k1 = k1 + PHILOX_W1
        hi0, lo0 = mulhilo(PHILOX_M0, c0)
        hi1, lo1 = mulhilo(PHILOX_M1, c2)
        c0, c1, c2, c3 = hi1 ^ c1 ^ k0, lo1, hi0 ^ c3 ^ k1, lo0
    out[0] = c0
    out[1] = c1
    out[2] = c2
    out[3] = c3


def philox_uniform(k0: np.uint64, k1: np.uint64, first: int, stream: int, out: np.ndarray) -> None:
    """Uniform doubles in ``[0, 1)`` (``(word >> 11) 2^-53``, as NumPy's ``random()``): row
    ``j`` of ``out`` (runs, m) holds the first ``m`` draws of run ``first + j``'s stream
    ``stream`` (about 15 ns a draw: one thread is enough)."""
    runs, m = out.shape
    blocks = (m + 3) // 4
    words = np.empty(4, dtype=np.uint64)
    for j in range(runs):
        c2 = np.uint64(first + j)
        c3 = np.uint64(stream)
        zero = np.uint64(0)
        for b in range(blocks):
            philox_block(np.uint64(b + 1), zero, c2, c3, k0, k1, words)
            for w in range(4):
                p = 4 * b + w
                if p < m:
                    out[j, p] = float(words[w] >> SHIFT11) * DOUBLE_UNIT
