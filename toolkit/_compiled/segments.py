"""Kernels shared by the exact engines: closed forms, segment rows, buffers and the loop state.

``expm1_ratio`` and its integral, the segment rows ``(t0, V0, c1, B, lam, C, D)`` of
``V(t0 + s) = V0 + c1 s + B x(lam, s) + C x(mu, s) + D s exp(-mu s)`` with ``x = expm1_ratio``
(evaluated, integrated, sampled), the event rows ``(t, kind, contact, V)``, the budget check of a
round, NumPy's pairwise sum, and the codes and state layout the engines share.
"""

from __future__ import annotations

import math

import numpy as np


EPS = 2.220446049250313e-16          # float64 machine epsilon
INF = math.inf

# Event kinds (the caller maps these codes to its names).
CROSS, STICK, RELEASE, SATURATION, COMMAND = 0, 1, 2, 3, 4
# Return codes of the loops.
DONE, MAX_STEPS, ZENO, PAUSE, FAILED_STEP = 0, 1, 2, 3, 4
# Layout of the loop state arrays (fstate: floats, istate: ints).
# The dynamic-motor engine (dynamic_run) also keeps its piece's offset and its mode there.
F_T, F_V, F_TSUM, F_TERR, F_RATE, F_OFF, F_REL = range(7)
(I_J, I_AT, I_STUCK, I_NSEG, I_NEV, I_ROUNDS, I_NEVAL, I_STARTED, I_MAXSTEPS, I_WINDOW,
 I_CHUNK, I_HINT, I_PIECE) = range(13)
N_FSTATE, N_ISTATE = 7, 13

#: ``(-1)^k / (k + 2)!`` for k = 0..14, highest first: the series of
#: ``(x + expm1(-x)) / x^2``, truncated below ``1e-17`` relative for ``0 <= x < 0.5``.
RATIO_INTEGRAL_SERIES = tuple((-1.0) ** k / math.factorial(k + 2) for k in range(14, -1, -1))

_IEEE = {"error_model": "numpy"}   # IEEE division: x / 0 is inf or NaN (as NumPy), never raises
#: The kernels of this module and their numba options (toolkit._compiled.load compiles them).
KERNELS = {"expm1_ratio": {}, "expm1_ratio_integral": {}, "reach_time": {}, "sign": _IEEE,
           "segment_value": {}, "dense_values": {}, "displacement": {}, "samples": {},
           "ordered_within": {}, "push_segment": {}, "push_event": {},
           "budget_code": {}, "grown": {}, "pairwise_sum": _IEEE, "pairwise_block": {}}


def expm1_ratio(rate: float, s: float) -> float:
    """``(1 - exp(-rate s)) / rate``, continuous at ``rate = 0`` (``= s``)."""
    return -math.expm1(-rate * s) / rate if rate > 0 else s


def expm1_ratio_integral(rate: float, s: float) -> float:
    """``int_0^s expm1_ratio(rate, x) dx = (s - expm1_ratio(rate, s)) / rate`` (``s^2 / 2`` at
    ``rate = 0``), to a few ulp: a series where the difference would cancel (``rate s < 0.5``),
    written without overflow for rates up to the largest double."""
    x = rate * s
    if x == 0.0:
        return s * s * 0.5                          # (the series below at x = 0)
    if x < 0.5:
        h = 0.0
        for c in RATIO_INTEGRAL_SERIES:             # Horner
            h = h * x + c
        return s * s * h
    return s * ((x + math.expm1(-x)) / x) / rate


def reach_time(V: float, r0: float, lam: float, target: float) -> float:
    """Time for ``V + r0 expm1_ratio(lam, s)`` to reach ``target`` (``inf`` if it never does, or
    when ``target`` or ``r0`` is not finite)."""
    if not (math.isfinite(target) and math.isfinite(r0)):
        return INF
    y = (target - V) / r0
    if not y >= 0:                                  # negative, or NaN from an infinite V
        return INF
    if lam == 0:
        return y
    x = lam * y
    if x >= 1.0:
        return INF
    return -math.log1p(-x) / lam


def sign(x: float) -> float:
    """``np.sign``: -1, 0 or 1, NaN for NaN."""
    if x > 0:
        return 1.0
    if x < 0:
        return -1.0
    return x if x != x else 0.0


def segment_value(V0: float, c1: float, B: float, lam: float, C: float, D: float, mu: float,
                  s: float) -> tuple[float, float]:
    """``(V, dV/dt)`` of one segment row at offset ``s`` (s), zero terms left out."""
    value = V0
    rate = c1
    if c1 != 0:
        value = V0 + c1 * s
    if B != 0:
        if lam > 0:
            value = value + B * (-math.expm1(-(lam * s)) / lam)
            rate = rate + B * math.exp(-lam * s)
        else:
            value = value + B * s
            rate = rate + B
    if C != 0 or D != 0:
        decay = math.exp(-mu * s)
        if C != 0:
            value = value + (C * (-math.expm1(-(mu * s)) / mu) if mu > 0 else C * s)
            rate = rate + C * decay
        if D != 0:
            value = value + D * s * decay
            rate = rate + D * (1.0 - mu * s) * decay
    return value, rate


def dense_values(table: np.ndarray, mu: float, query: np.ndarray, success: bool,
                 t_stop: float, scale: float, out: np.ndarray) -> None:
    """``out[0]``: ``V`` (m/s) and ``out[1]``: ``scale`` times its right derivative (``scale``
    1: m/s^2; the mass: the force ``m dV/dt``, N) at ``query`` times (s, any order, any
    values) from the segment rows ``table`` (S, 7), ``t0`` increasing; times before the first
    row use it; NaN in ``V`` past ``t_stop`` unless ``success``. Zero terms are left out (the
    same value: a dropped ``+ 0.0`` only turns ``-0.0`` into ``0.0``).

    Consecutive times on one segment (all of them, for sorted times) are evaluated as one run
    with that segment's coefficients; a line (``V0 + B s``, the ideal engine without drag or
    compliance) takes a loop of its own."""
    S = table.shape[0]
    T = query.size
    i = 0
    k = 0
    while i < T:
        q = query[i]
        if not (table[k, 0] <= q and (k + 1 == S or q < table[k + 1, 0])):
            a, z = 0, S                          # the last row with t0 <= q (or row 0)
            while a < z:
                mid = (a + z) >> 1
                if table[mid, 0] <= q:
                    a = mid + 1
                else:
                    z = mid
            k = a - 1 if a > 0 else 0
        t0 = table[k, 0]
        low = t0 if k > 0 else -INF              # row 0 also serves times before it
        high = table[k + 1, 0] if k + 1 < S else INF
        if not success and t_stop < high:
            high = t_stop                        # (later times: NaN, evaluated one by one)
        j = i + 1                                # the run: query[i:j] on this row
        while j < T and query[j] >= low and query[j] < high:
            j += 1
        V0, c1, B, lam = table[k, 1], table[k, 2], table[k, 3], table[k, 4]
        C, D = table[k, 5], table[k, 6]
        if c1 == 0 and C == 0 and D == 0 and (lam == 0 or B == 0) and (success or q <= t_stop):
            rate = 0.0 + B                       # (the general form's c1 + B)
            rate = rate if scale == 1.0 else scale * rate
            if B != 0:
                for p in range(i, j):
                    out[0, p] = V0 + B * (query[p] - t0)
                    out[1, p] = rate
            else:
                for p in range(i, j):
                    out[0, p] = V0
                    out[1, p] = rate
        else:
            for p in range(i, j):
                value, rate = segment_value(V0, c1, B, lam, C, D, mu, query[p] - t0)
                if not success and not query[p] <= t_stop:
                    value = math.nan
                out[0, p] = value
                out[1, p] = rate if scale == 1.0 else scale * rate
        i = j


def displacement(seg: np.ndarray, n: int, mu: float, t_stop: float) -> float:
    """The exact integral of ``V`` (m) from the first row's start to ``t_stop`` (s): each
    closed-form segment integrated in closed form, ``V0 S + c1 S^2 / 2 + B I(lam, S)
    + C I(mu, S) + D (S expm1_ratio(mu, S) - I(mu, S))`` with ``S`` its length and ``I``
    :func:`expm1_ratio_integral`."""
    total = 0.0
    for k in range(n):
        S = (seg[k + 1, 0] if k + 1 < n else t_stop) - seg[k, 0]
        if S <= 0.0:
            continue
        V0, c1, B, lam, C, D = seg[k, 1], seg[k, 2], seg[k, 3], seg[k, 4], seg[k, 5], seg[k, 6]
        part = V0 * S + 0.5 * c1 * S * S
        if B != 0.0:
            part += B * expm1_ratio_integral(lam, S)
        if C != 0.0 or D != 0.0:
            settle = expm1_ratio_integral(mu, S)
            part += C * settle + D * (S * expm1_ratio(mu, S) - settle)
        total += part
    return total


def samples(seg: np.ndarray, n: int, mu: float, t_stop: float, V_stop: float,
            mass: float) -> np.ndarray:
    """Segment starts and the final time as rows ``t`` (s), ``V`` (m/s) and the force
    ``m dV/dt`` (N, from the right, exact) of a fresh array of shape (3, T)."""
    last = seg[n - 1, 0]
    T = n + 1 if t_stop > last else n
    out = np.empty((3, T))
    for k in range(n):                                   # each segment at s = 0
        out[0, k] = seg[k, 0]
        out[1, k] = seg[k, 1]
        out[2, k] = mass * (seg[k, 2] + seg[k, 3] + seg[k, 5] + seg[k, 6])
    if T > n:                        # the last segment at its end
        s = t_stop - last
        c1, B, lam = seg[n - 1, 2], seg[n - 1, 3], seg[n - 1, 4]
        C, D = seg[n - 1, 5], seg[n - 1, 6]
        decay = math.exp(-mu * s)
        out[0, n] = t_stop
        out[1, n] = V_stop
        out[2, n] = mass * (c1 + B * math.exp(-lam * s) + C * decay + D * (1.0 - mu * s) * decay)
    return out


def ordered_within(times: np.ndarray, t_end: float) -> bool:
    """True when ``times`` (s, 1-d, at least one) are non-decreasing and within
    ``[0, t_end]``: the check of ``simulate(..., t_eval=...)``. NaN-safe as written (every
    comparison with NaN is False) and without early exit, so that it compiles to one
    vectorized pass (the same answer as
    ``(times[1:] >= times[:-1]).all() and times[0] >= 0 and times[-1] <= t_end``)."""
    n = times.size
    ok = times[0] >= 0.0 and times[n - 1] <= t_end
    for i in range(1, n):
        ok &= times[i] >= times[i - 1]
    return ok


def push_segment(seg: np.ndarray, n: int, t0: float, V0: float, c1: float, B: float,
                 lam: float, C: float, D: float) -> int:
    """Store a segment row at ``n`` (a zero-length segment, same ``t0`` as the last row, is
    superseded); returns the new count."""
    if n > 0 and seg[n - 1, 0] == t0:
        n -= 1
    seg[n, 0] = t0
    seg[n, 1] = V0
    seg[n, 2] = c1
    seg[n, 3] = B
    seg[n, 4] = lam
    seg[n, 5] = C
    seg[n, 6] = D
    return n + 1


def push_event(ev: np.ndarray, n: int, t: float, kind: int, contact: int, V: float) -> int:
    """Store an event row at ``n``; returns the new count."""
    ev[n, 0] = t
    ev[n, 1] = kind
    ev[n, 2] = contact
    ev[n, 3] = V
    return n + 1


def budget_code(rounds: int, max_steps: int, ev: np.ndarray, nev: int, window: int,
                rate: float) -> int:
    """The budget check of one round (the wall clock is the caller's, at each pause):
    ``MAX_STEPS`` past ``max_steps`` rounds, ``ZENO`` when the last ``window`` events span
    less than ``window / rate`` seconds, else ``DONE`` (go on)."""
    if rounds > max_steps:
        return MAX_STEPS
    if nev > window and (ev[nev - 1, 0] - ev[nev - 1 - window, 0]) * rate < window:
        return ZENO
    return DONE


def grown(buffer: np.ndarray) -> np.ndarray:
    """A copy of ``buffer`` with twice its rows plus 16."""
    rows, width = buffer.shape
    bigger = np.empty((2 * rows + 16, width))
    bigger[:rows] = buffer
    return bigger


def pairwise_sum(values: np.ndarray, lo: int, n: int) -> float:
    """``values[lo:lo + n]`` summed as NumPy sums a contiguous float64 array (``np.add.reduce``:
    blocks of up to 128 terms in 8 partial sums, halved recursively above), so that the
    engine's sums are the very doubles of NumPy's (tested against NumPy). The halving is
    walked with an explicit stack (numba caches no recursive kernel)."""
    if n <= 128:
        return pairwise_block(values, lo, n)
    los = np.empty(64, dtype=np.int64)         # depth log2(n / 128) + 1: far below 64
    ns = np.empty(64, dtype=np.int64)
    stage = np.zeros(64, dtype=np.int64)      # 0: new, 1: left half summed, 2: both
    lefts = np.empty(64)
    top = 0
    los[0] = lo
    ns[0] = n
    result = 0.0
    while top >= 0:
        count = ns[top]
        if count <= 128:
            result = pairwise_block(values, los[top], count)
            top -= 1
            continue
        half = count // 2
        half -= half % 8
        if stage[top] == 0:
            stage[top] = 1
            los[top + 1], ns[top + 1], stage[top + 1] = los[top], half, 0
            top += 1
        elif stage[top] == 1:
            lefts[top] = result
            stage[top] = 2
            los[top + 1], ns[top + 1], stage[top + 1] = los[top] + half, count - half, 0
            top += 1
        else:
            result = lefts[top] + result
            top -= 1
    return result


def pairwise_block(values: np.ndarray, lo: int, n: int) -> float:
    """:func:`pairwise_sum` of at most 128 terms: 8 partial sums (fewer than 8 terms: one)."""
    if n < 8:
        total = -0.0
        for i in range(lo, lo + n):
            total += values[i]
        return total
    r0, r1, r2, r3 = values[lo], values[lo + 1], values[lo + 2], values[lo + 3]
    r4, r5, r6, r7 = values[lo + 4], values[lo + 5], values[lo + 6], values[lo + 7]
    i = 8
    stop = n - n % 8
    while i < stop:
        r0 += values[lo + i]
        r1 += values[lo + i + 1]
        r2 += values[lo + i + 2]
        r3 += values[lo + i + 3]
        r4 += values[lo + i + 4]
        r5 += values[lo + i + 5]
        r6 += values[lo + i + 6]
        r7 += values[lo + i + 7]
        i += 8
    total = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < n:
        total += values[lo + i]
        i += 1
    return total
