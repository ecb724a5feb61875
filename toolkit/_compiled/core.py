"""Kernels of the exact method and of the Coulomb force: plain Python over arrays, one source.

Compiled by :func:`toolkit._compiled.load` (``load("core")``); as written, this module
imports nothing but ``math`` and NumPy and runs as Python (``NUMBA_DISABLE_JIT=1``). The
callers keep validation, result assembly and I/O; the kernels do the loops.

- :func:`coulomb_force`: ``F(V) = above[right] - below[left]`` of a :class:`ContactSet`'s
  prefix sums at many body speeds (the sorted-search evaluation of the friction law), with
  a bucket index over the levels so that each speed costs ``O(1)`` expected.
- :func:`ideal_piece`: the event loop of the exact method with piecewise-constant contact
  speeds (Coulomb staircase or compliant piecewise-linear landscape, drag, external force,
  Filippov stick and release, the budget and Zeno guards); segments and events go to
  caller-owned buffers, and the loop pauses when they are full or after a chunk of rounds
  (the caller then checks the wall clock, grows the buffers and resumes).
- :func:`dense_values`, :func:`displacement`, :func:`samples`: the closed-form segments
  evaluated, integrated and sampled.
- :func:`quiet_piece`: the no-event certificate of :func:`toolkit.simulation.advance`.
- :func:`first_root`: the event root finder of the dynamic-motor engine (the earliest root
  of many functions ``alpha + beta s + gamma x(lam, s) + delta x(mu, s) + D s exp(-mu s)``:
  brackets on monotone pieces, bisection at any scale, Newton's or Brent's method);
  :func:`free_first_root`, :func:`stuck_first_root`: its event functions built from the
  engine's state (a body sliding free; a body stuck to a contact) and their first root.
- :func:`batch`: many constant-speed scenes, each through :func:`ideal_piece` (so each
  equals the single run), in parallel over scenes (``prange``).

How the laws stay written once. The friction law is evaluated here from the prefix sums that
:class:`toolkit.model.ContactSet` builds (``net force = magnitude above - magnitude below``,
snapped within the tie tolerance): :meth:`ContactSet.force` and the exact engine both call
:func:`net_force`. The compliant landscape comes from
:func:`toolkit.model.friction.compliant_breakpoints`. The motor law is not evaluated here
except in :func:`quiet_piece`, which evaluates :class:`toolkit.model.motors.MotorPiece`'s
closed form of a lag without a ramp phase (the certificate refuses any other phase).

Segment rows are ``(t0, V0, c1, B, lam, C, D)`` with
``V(t0 + s) = V0 + c1 s + B x(lam, s) + C x(mu, s) + D s exp(-mu s)``,
``x(r, s) = expm1_ratio(r, s) = (1 - exp(-r s)) / r`` (``= s`` at ``r = 0``). Event rows are
``(t, kind, contact, V)`` with the kind codes below and contact ``-1`` for none.
"""

from __future__ import annotations

import math

import numpy as np

#: Replaced by ``numba.prange`` when compiled (a parallel loop); ``range`` as Python.
prange = range

EPS = 2.220446049250313e-16          # float64 machine epsilon
INF = math.inf

# Event kinds (the order of toolkit.simulation._result.EVENT_KINDS is not assumed: the
# caller maps these codes to its names).
CROSS, STICK, RELEASE, SATURATION, COMMAND = 0, 1, 2, 3, 4
# Return codes of the loops.
DONE, MAX_STEPS, ZENO, PAUSE = 0, 1, 2, 3
# Layout of the loop state arrays (fstate: floats, istate: ints).
F_T, F_V, F_TSUM, F_TERR, F_RATE = 0, 1, 2, 3, 4
(I_J, I_AT, I_STUCK, I_NSEG, I_NEV, I_ROUNDS, I_NEVAL, I_STARTED, I_MAXSTEPS, I_WINDOW,
 I_CHUNK) = range(11)
N_FSTATE, N_ISTATE = 5, 11

#: ``(-1)^k / (k + 2)!`` for k = 0..14, highest first: the series of
#: ``(x + expm1(-x)) / x^2``, truncated below ``1e-17`` relative for ``0 <= x < 0.5``.
RATIO_INTEGRAL_SERIES = tuple((-1.0) ** k / math.factorial(k + 2) for k in range(14, -1, -1))

#: Contacts up to which the lowest index at a level is found by a scan (else one sort).
SMALL = 64

# Kernels and their numba options (toolkit._compiled.load compiles these names).
_INLINE = {"inline": "always"}      # small helpers: inlined into their callers by numba
_IEEE = {"error_model": "numpy"}   # IEEE division: x / 0 is inf or NaN (as NumPy), never raises
KERNELS = {
    "expm1_ratio": _INLINE, "expm1_ratio_integral": {}, "reach_time": _INLINE,
    "net_force": _INLINE, "coulomb_force": {}, "lowest_contact": {}, "push_segment": _INLINE,
    "push_event": _INLINE, "budget_code": _INLINE, "ideal_piece": {}, "ideal_run": {},
    "dense_values": {}, "segment_value": _INLINE, "displacement": {}, "samples": {},
    "quiet_piece": {}, "sorted_landscape": {}, "batch_scene": {}, "batch": {"parallel": True},
    "ordered_within": {},
    # The event roots of the dynamic-motor engine: IEEE division (inf, NaN) as NumPy's.
    "event_value": _IEEE, "event_slope": _IEEE, "event_inflection": _IEEE,
    "sign": _IEEE, "midpoint": _IEEE, "bisect": _IEEE, "newton_root": _IEEE,
    "brent_root": _IEEE, "polish_root": _IEEE, "all_zero": _INLINE, "first_root_all": _IEEE,
    "first_root": _IEEE,
    "free_first_root": _IEEE, "stuck_first_root": _IEEE,
}


# -- closed forms ---------------------------------------------------------------------------
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


# -- the Coulomb force from prefix sums ------------------------------------------------------
def net_force(above: float, below: float, tol: float) -> float:
    """The net Coulomb force ``above - below`` (N: the magnitudes of the contacts faster and
    slower than the body), exactly 0 within ``tol`` (:attr:`ContactSet.tie_tolerance`)."""
    force = above - below
    return force if abs(force) > tol else 0.0


def coulomb_force(levels: np.ndarray, below: np.ndarray, above: np.ndarray, tol: float,
                  query: np.ndarray, out: np.ndarray) -> None:
    """``out[i] = F(query[i])`` (N) from a :class:`ContactSet`'s sorted distinct speeds
    ``levels`` (K,) and prefix sums ``below``, ``above`` (K + 1,); query speeds not NaN.

    ``left`` (the first level ``>= V``) is found through a bucket index: ``K`` equal buckets
    over ``[levels[0], levels[-1]]``, each holding the first level of its bucket or above, so
    a search is a binary search inside one bucket (``O(1)`` expected, ``O(log K)`` at worst).
    The bucket of a speed is a non-decreasing function of the speed, so the bucket bounds are
    exact bounds on ``left`` whatever the rounding. Few queries: plain binary search.
    """
    K = levels.size
    M = query.size
    lo, hi = levels[0], levels[K - 1]
    buckets = K if M * 8 >= K and K > 16 and hi > lo else 0
    start = np.empty(buckets + 2, dtype=np.int64)
    scale = buckets / (hi - lo) if buckets else 0.0
    if buckets:
        b = 0
        start[0] = 0
        for i in range(K):
            bi = min(int((levels[i] - lo) * scale), buckets - 1)
            while b < bi:
                b += 1
                start[b] = i
        while b <= buckets:
            b += 1
            start[b] = K
    for m in range(M):
        V = query[m]
        if not V >= lo:
            left = 0
        elif V > hi:
            left = K
        else:
            if buckets:
                bq = min(int((V - lo) * scale), buckets - 1)
                a, z = start[bq], start[bq + 1]
            else:
                a, z = 0, K
            while a < z:                     # first level >= V in [a, z)
                mid = (a + z) >> 1
                if levels[mid] < V:
                    a = mid + 1
                else:
                    z = mid
            left = a
        right = left + 1 if left < K and levels[left] == V else left
        out[m] = net_force(above[right], below[left], tol)


def lowest_contact(land: np.ndarray, speeds: np.ndarray, forces: np.ndarray,
                   first: np.ndarray, k: int) -> int:
    """The lowest index of the touching contacts (``f > 0``) at level ``land[0, k]``, kept in
    ``first`` (``-1``: not known yet; an empty ``first`` keeps nothing). Few contacts: a
    scan; many: one stable sort fills every level's entry, so a run of many events stays
    ``O(N log N)``."""
    if k < first.size and first[k] >= 0:
        return first[k]
    n = speeds.size
    if n <= SMALL:
        x = land[0, k]
        for i in range(n):
            if speeds[i] == x and forces[i] > 0:
                if k < first.size:
                    first[k] = i
                return i
    order = np.argsort(speeds, kind="mergesort")          # stable: lower indices first
    kk = 0
    for p in range(n):
        i = order[p]
        if forces[i] > 0:
            while land[0, kk] < speeds[i]:
                kk += 1
            if first[kk] < 0:
                first[kk] = i
    return first[k]


# -- the recorder's buffers -------------------------------------------------------------------
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


# -- the ideal-motor engine -------------------------------------------------------------------
def ideal_piece(coulomb: bool, K: int, land: np.ndarray, first: np.ndarray,
                speeds: np.ndarray, forces: np.ndarray, total: float, m: float, c: float,
                E: float, b: float, fstate: np.ndarray, istate: np.ndarray, seg: np.ndarray,
                ev: np.ndarray) -> int:
    """Integrate up to time ``b`` (s) with constant contact speeds, from the state in
    ``fstate`` / ``istate`` (time ``t``, speed ``V``, the contact the body is stuck to or -1;
    ``I_STARTED = 0``: a new piece starting at ``fstate[F_T]``), under external force ``E``
    (N), mass ``m`` (kg) and drag ``c`` (N s/m); the one engine of ``simulate`` and
    ``advance`` for ideal motors.

    The landscape: ``K`` breakpoints, one table ``land`` of rows (few array arguments keep
    the call cheap: each costs reference counting). Coulomb (``coulomb``): the sorted
    distinct speeds ``xs = land[0]`` and the prefix sums ``below = land[1]``,
    ``above = land[2]`` (``ContactSet._table``), its ``speeds`` and ``forces`` and ``first``
    (lowest contact per level, -1 unknown; see :func:`lowest_contact`). Compliant: the
    saturation limits ``xs = land[0]``, the force ``base_F[j] + slope[j] (V - base_x[j])``
    inside interval ``j`` (``base_F = land[1]``, ``slope = land[2]``, ``base_x = land[3]``)
    and ``G_at[k] = land[4, k]`` at limit ``k``, ``first[k]`` its lowest contact.
    ``total``: ``F_tot``.

    Returns ``DONE`` (reached ``b``), ``MAX_STEPS`` or ``ZENO`` (stopped at ``fstate[F_T]``),
    or ``PAUSE`` (``istate[I_CHUNK]`` rounds done, or the buffers may not hold another
    round: the caller checks the wall clock, grows the buffers and calls again).
    """
    t = fstate[F_T]
    V = fstate[F_V]
    t_sum = fstate[F_TSUM]
    t_err = fstate[F_TERR]
    rate = fstate[F_RATE]
    j = istate[I_J]
    at = istate[I_AT] != 0
    stuck = istate[I_STUCK]
    nseg = istate[I_NSEG]
    nev = istate[I_NEV]
    rounds = istate[I_ROUNDS]
    n_eval = istate[I_NEVAL]
    max_steps = istate[I_MAXSTEPS]
    window = istate[I_WINDOW]
    # Rounds before pausing: the configured chunk, or fewer when the buffers would fill up
    # (a round stores at most two segment rows and two event rows).
    free = min(seg.shape[0] - nseg, ev.shape[0] - nev)
    if free < 8:
        return PAUSE                               # no room even to start: grow and resume
    chunk = min((free - 4) // 2, istate[I_CHUNK])
    kind = CROSS if coulomb else SATURATION
    tol = 4.0 * (K + 1) * EPS * total              # the prefix sums' rounding (tie_tolerance)
    push_scale = total + abs(E)
    code = DONE
    if istate[I_STARTED] == 0:                     # a new piece: locate V (binary search)
        istate[I_STARTED] = 1
        t_sum = t
        t_err = 0.0                                # compensated sum of the segment times
        lo_, hi_ = 0, K
        while lo_ < hi_:
            mid = (lo_ + hi_) >> 1
            if land[0, mid] < V:
                lo_ = mid + 1
            else:
                hi_ = mid
        j = lo_
        at = j < K and land[0, j] == V
        if stuck >= 0:
            holds = at and coulomb and land[1, j + 1] - land[1, j] > 0
            if not holds:
                nev = push_event(ev, nev, t, RELEASE, stuck, V)
                stuck = -1
    done = 0
    finished = False
    while True:
        if at:
            # (W, G): the stiction magnitude at breakpoint j and the others' push.
            if coulomb:
                W = land[1, j + 1] - land[1, j]
                lower = net_force(land[2, j], land[1, j], tol)
                upper = net_force(land[2, j + 1], land[1, j + 1], tol)
                G = 0.5 * (lower + upper)
                G = G if abs(G) > tol else 0.0
            else:
                W = 0.0
                G = land[4, j]
            G += E - c * V
            tol_G = 4.0 * (K + 1) * EPS * (push_scale + c * abs(V))
            n_eval += 1
            if abs(G) <= W + tol_G:                 # stick (or rest at a balance)
                if coulomb:
                    contact = lowest_contact(land, speeds, forces, first, j)
                else:
                    contact = first[j]
                if W > 0 and stuck != contact:
                    if stuck >= 0:
                        nev = push_event(ev, nev, t, RELEASE, stuck, V)
                    nev = push_event(ev, nev, t, STICK, contact, V)
                    stuck = contact
                nseg = push_segment(seg, nseg, t, V, 0.0, 0.0, 0.0, 0.0, 0.0)
                finished = True
                break
            if stuck >= 0:
                nev = push_event(ev, nev, t, RELEASE, stuck, V)
                stuck = -1
            else:
                contact = lowest_contact(land, speeds, forces, first, j) if coulomb else first[j]
                nev = push_event(ev, nev, t, kind, contact, V)
            if G > 0:
                j += 1
        # Free motion inside interval j.
        if coulomb:
            force = net_force(land[2, j], land[1, j], tol)
            dF = 0.0
        else:
            dF = land[2, j]
            force = land[1, j] if dF == 0 else land[1, j] + dF * (V - land[3, j])
        r0 = (force + E - c * V) / m
        lam = (c - dF) / m
        n_eval += 1
        nseg = push_segment(seg, nseg, t, V, 0.0, r0, lam, 0.0, 0.0)
        if r0 == 0.0:
            finished = True
            break
        up = r0 > 0
        if up:
            target = land[0, j] if j < K else INF
        else:
            target = land[0, j - 1] if j > 0 else -INF
        s = reach_time(V, r0, lam, target)          # inf for an infinite target
        if t + s >= b:
            V = V + r0 * expm1_ratio(lam, b - t)
            lo = land[0, j - 1] if j > 0 else -INF
            hi = land[0, j] if j < K else INF
            if V < lo:
                V = lo
            if V > hi:
                V = hi
            finished = True
            break
        # Compensated (Neumaier) sum of the segment times: exact over 1e5 segments.
        t_new = t_sum + s
        if abs(t_sum) >= abs(s):
            t_err += (t_sum - t_new) + s
        else:
            t_err += (s - t_new) + t_sum
        t_sum = t_new
        t = t_sum + t_err
        V = target
        at = True
        if not up:
            j -= 1
        rounds += 1
        code = budget_code(rounds, max_steps, ev, nev, window, rate)
        if code != DONE:
            break
        done += 1
        if done >= chunk:
            code = PAUSE
            break
    if finished:
        t = b
        rounds += 1
        code = budget_code(rounds, max_steps, ev, nev, window, rate)
    fstate[F_T] = t
    fstate[F_V] = V
    fstate[F_TSUM] = t_sum
    fstate[F_TERR] = t_err
    istate[I_J] = j
    istate[I_AT] = 1 if at else 0
    istate[I_STUCK] = stuck
    istate[I_NSEG] = nseg
    istate[I_NEV] = nev
    istate[I_ROUNDS] = rounds
    istate[I_NEVAL] = n_eval
    return code


def ideal_run(coulomb: bool, K: int, land: np.ndarray, first: np.ndarray,
              speeds: np.ndarray, forces: np.ndarray, total: float, m: float, c: float,
              E: float, b: float, fstate: np.ndarray, istate: np.ndarray, seg: np.ndarray,
              ev: np.ndarray, query: np.ndarray, out: np.ndarray) -> int:
    """A whole run of one piece (constant speeds) in one call: :func:`ideal_piece` from the
    state given, then, when it reached ``b`` (``DONE``), the dense output at ``query`` into
    ``out`` (rows ``V`` and the force ``m dV/dt``, :func:`dense_values`). Returns the code of
    :func:`ideal_piece` (``out`` is not written unless ``DONE``)."""
    code = ideal_piece(coulomb, K, land, first, speeds, forces, total, m, c, E, b, fstate,
                       istate, seg, ev)
    if code == DONE:
        dense_values(seg[:istate[I_NSEG]], 0.0, query, True, b, m, out)
    return code


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


# -- segments: evaluate, integrate, sample ---------------------------------------------------
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


# -- dynamic motors: a piece without events, certified ---------------------------------------
def quiet_piece(forces: np.ndarray, total_force: float, m: float, c: float, tau: float,
                ramp_gap: float, speed_bound: float, margin_rel: float, start: np.ndarray,
                u: np.ndarray, V: float, stuck: int, E: float, S: float,
                out: np.ndarray) -> tuple[bool, float, float]:
    """The no-event certificate of one piece of constant command ``u`` (clipped, m/s) over
    ``S`` seconds from contact speeds ``start`` and body speed ``V`` (m/s), stuck to contact
    ``stuck`` (-1: free), external force ``E`` (N); see
    :func:`toolkit.simulation._exact._quiet_piece` for the argument. When certified, returns
    ``(True, V_end, body_displacement)`` and fills ``out[0]`` with the contact speeds at ``S``
    and ``out[1]`` with their displacements (m); else ``(False, nan, nan)``."""
    n = start.size
    mu = 1.0 / tau
    lam = c / m
    spread = 0.0
    top = 0.0
    for i in range(n):
        spread = max(spread, abs(start[i] - u[i]))
        top = max(top, abs(u[i]))
    if spread > ramp_gap:
        return False, math.nan, math.nan     # a motor ramps at its rate limit: a phase change
    decay = math.exp(-S / tau)
    for i in range(n):
        d = start[i] - u[i]                  # MotorPiece: v(s) = u + d exp(-s / tau)
        out[0, i] = d * decay + u[i]         # MotorPiece.speeds(S)
    grow = expm1_ratio(mu, S)                # v_i(S) - v_i(0) = e_i grow
    reach = (speed_bound if speed_bound < INF else top) + spread
    if stuck < 0:
        push = 0.0
        for i in range(n):
            v0 = u[i] + (start[i] - u[i])    # MotorPiece.coefficients(0)
            push += forces[i] * (1.0 if v0 > V else (-1.0 if v0 < V else 0.0))
        r0 = (push + E - c * V) / m
        V_end = V + r0 * expm1_ratio(lam, S)
        margin = margin_rel * (abs(V) + abs(V_end) + reach)
        for i in range(n):
            v0 = u[i] + (start[i] - u[i])
            g0 = V - v0
            g1 = V_end - out[0, i]
            if not ((g0 > margin and g1 > margin) or (g0 < -margin and g1 < -margin)):
                return False, math.nan, math.nan
        if r0 != 0.0 and mu != lam:
            for i in range(n):
                v0 = u[i] + (start[i] - u[i])
                e = (u[i] - v0) / tau                        # MotorPiece.coefficients: e_i
                if (e > 0.0) if r0 > 0.0 else (e < 0.0):     # e_i / r0 > 0: an extremum
                    at = (math.log(abs(e)) - math.log(abs(r0))) / (mu - lam)
                    if at > 0.0 and at < S:
                        x_lam = -math.expm1(-lam * at) / lam if lam > 0 else at
                        g0 = V - v0
                        g = g0 + r0 * x_lam - e * (-math.expm1(-mu * at) / mu)
                        side = 1.0 if g0 > 0 else (-1.0 if g0 < 0 else 0.0)
                        if not g * side > margin:
                            return False, math.nan, math.nan
        body = V * S + r0 * expm1_ratio_integral(lam, S)     # displacement()
    else:
        d_k = start[stuck] - u[stuck]
        u_k = u[stuck]
        W = 0.0
        for i in range(n):
            if start[i] - u[i] == d_k and u[i] == u_k:      # the group on contact k's track
                if i < stuck:
                    return False, math.nan, math.nan       # k must be its lowest index
                W += forces[i]
        if not W > 0:
            return False, math.nan, math.nan
        vc = u_k + d_k
        ec = (u_k - vc) / tau                              # MotorPiece.coefficients: e_k
        V_end = vc + ec * grow
        margin = margin_rel * (abs(vc) + abs(V_end) + reach)
        end_k = out[0, stuck]
        G = E
        for i in range(n):
            if start[i] - u[i] == d_k and u[i] == u_k:
                continue
            v0 = u[i] + (start[i] - u[i])
            g0 = vc - v0
            g1 = end_k - out[0, i]
            if not ((g0 > margin and g1 > margin) or (g0 < -margin and g1 < -margin)):
                return False, math.nan, math.nan
            G += forces[i] * (1.0 if v0 > vc else -1.0)
        h0 = G - c * vc - m * ec
        h1 = h0 + ec * (m * mu - c) * grow
        scale = total_force + abs(E) + c * (abs(vc) + abs(V_end)) + m * abs(ec)
        if max(abs(h0), abs(h1)) > W - margin_rel * scale:
            return False, math.nan, math.nan
        body = vc * S + ec * expm1_ratio_integral(mu, S)     # displacement()
    ramp = tau * -math.expm1(-S / tau)
    for i in range(n):
        out[1, i] = u[i] * S + (start[i] - u[i]) * ramp    # MotorPiece.displacement, no ramp
    return True, V_end, body


# -- dynamic motors: the first root of the event functions -------------------------------------
# An event function of the dynamic-motor engine (toolkit.simulation._exact, ``_EventFunctions``)
# is ``g(s) = alpha + beta s + gamma x(lam, s) + delta x(mu, s) + D s exp(-mu s)`` with
# ``x = expm1_ratio``: one row ``i`` of the coefficient vectors, scalars ``lam``, ``mu``, ``D``.
ARITHMETIC_HALVINGS = 53     # bisection: arithmetic midpoints first, then scale-free ones
MAX_HALVINGS = ARITHMETIC_HALVINGS + 64
BRENT_RTOL = 4.0 * EPS       # Brent's method: relative tolerance (scipy.optimize.brentq's least)
BRENT_XTOL = 5e-324          # ... no absolute floor: the smallest subnormal (math.ulp(0.0))
BRENT_MAXITER = 500


def event_value(alpha: float, beta: float, gamma: float, delta: float, lam: float, mu: float,
                D: float, s: float) -> float:
    """``g(s)`` of one event function (a zero ``D`` term is left out: it could only turn a
    ``-0.0`` into ``0.0``)."""
    total = alpha + beta * s
    total = total + gamma * expm1_ratio(lam, s)
    total = total + delta * expm1_ratio(mu, s)
    if D != 0.0:
        total = total + D * s * math.exp(-mu * s)
    return total


def event_slope(beta: float, gamma: float, delta: float, lam: float, mu: float, D: float,
                s: float) -> float:
    """``g'(s) = beta + gamma exp(-lam s) + delta exp(-mu s) + D (1 - mu s) exp(-mu s)``
    (a zero ``D`` term left out)."""
    decay = math.exp(-mu * s)
    slope = beta + gamma * math.exp(-lam * s) + delta * decay
    if D != 0.0:
        slope = slope + D * (1.0 - mu * s) * decay
    return slope


def event_inflection(gamma: float, delta: float, lam: float, mu: float, D: float) -> float:
    """The root of ``g''`` (at most one), NaN where there is none.

    ``g''(s) = -gamma lam exp(-lam s) - delta mu exp(-mu s)`` vanishes where
    ``exp((mu - lam) s) = -(delta mu) / (gamma lam)``; the ratio is formed from logarithms
    because the products overflow with lag ~ 1e-300 (``mu = 1e300``), and an overflowed
    ratio would lose the knot that splits ``g'`` into monotone pieces. At resonance
    (``lam == mu``, ``D != 0``): ``s = 2 / mu + (gamma + delta) / (D mu)``.
    """
    if D != 0.0:
        return (2.0 + (gamma + delta) / D) / mu
    if lam > 0 and mu > 0 and lam != mu:
        if (gamma > 0 and delta < 0) or (gamma < 0 and delta > 0):    # the ratio is positive
            log_ratio = (math.log(abs(delta)) - math.log(abs(gamma))
                         + (math.log(mu) - math.log(lam)))
            return log_ratio / (mu - lam)
    return math.nan


def sign(x: float) -> float:
    """``np.sign``: -1, 0 or 1, NaN for NaN."""
    if x > 0:
        return 1.0
    if x < 0:
        return -1.0
    return x if x != x else 0.0


def midpoint(lo: float, hi: float, k: int, bits: np.ndarray, ibits: np.ndarray) -> float:
    """The midpoint of a bracket ``0 <= lo < hi`` (offsets, s) for the ``k``-th halving (from
    0); ``bits`` (2,) is scratch and ``ibits`` its int64 view.

    The first 53 halvings take the arithmetic midpoint, the fastest on a bracket on the scale
    of its root (the usual case): it ends on adjacent doubles within
    ``53 + log2(hi / root)`` halvings. A bracket still open after them is many binades wider
    than its root, e.g. a motor transient of ``tau = 1e-300`` s inside a bracket of 1.5 s,
    which arithmetic halving would reach only after about 1000 halvings. Later halvings are
    scale-free: the double halfway between the ends in the order of the doubles
    (non-negative doubles sort like their bit patterns), which ends on adjacent doubles within
    64 more halvings whatever the scale of the root.
    """
    if k < ARITHMETIC_HALVINGS:
        return 0.5 * (lo + hi)
    bits[0] = lo + 0.0                       # (+ 0.0 turns -0.0 into +0.0)
    bits[1] = hi
    a = ibits[0]
    ibits[0] = a + (ibits[1] - a) // 2
    return bits[0]


def bisect(alpha: float, beta: float, gamma: float, delta: float, lam: float, mu: float,
           D: float, lo: float, hi: float, derivative: bool, bits: np.ndarray,
           ibits: np.ndarray) -> float:
    """Bisection of ``g`` (``derivative``: of ``g'``) on a bracket ``[lo, hi]`` (a sign change,
    offsets ``>= 0``, s) to adjacent doubles at any scale (:func:`midpoint`); returns the
    upper end, which holds the new sign (or zero)."""
    if derivative:
        low = sign(event_slope(beta, gamma, delta, lam, mu, D, lo))
    else:
        low = sign(event_value(alpha, beta, gamma, delta, lam, mu, D, lo))
    for k in range(MAX_HALVINGS):
        mid = midpoint(lo, hi, k, bits, ibits)
        if not (mid > lo and mid < hi):
            break
        if derivative:
            here = sign(event_slope(beta, gamma, delta, lam, mu, D, mid))
        else:
            here = sign(event_value(alpha, beta, gamma, delta, lam, mu, D, mid))
        if here == low:
            lo = mid
        else:
            hi = mid
    return hi


def newton_root(alpha: float, beta: float, gamma: float, delta: float, lam: float, mu: float,
                lo: float, hi: float, g_lo: float, g_hi: float) -> tuple[float, bool]:
    """Newton's method for a root of a convex or concave ``g`` (``D = 0`` and one exponential
    term at most: ``g''`` keeps the sign of ``-(gamma lam + delta mu)``, not 0) in the
    sign-changing bracket ``[lo, hi]``, started from the end where ``g g'' > 0`` (Fourier's
    condition: the iterates then approach the root monotonically, quadratically near it,
    without leaving the bracket). Returns ``(root, True)`` to a few ulp, or ``(nan, False)``
    when the iteration does not settle (the caller then uses Brent's method)."""
    curvature = -(gamma * lam + delta * mu)
    if g_hi * curvature > 0:
        x, gx = hi, g_hi
    else:
        x, gx = lo, g_lo
    for _ in range(60):
        d = event_slope(beta, gamma, delta, lam, mu, 0.0, x)
        if d == 0.0 or not math.isfinite(d):
            return math.nan, False
        x_new = x - gx / d
        if not (lo <= x_new and x_new <= hi):
            return math.nan, False
        if abs(x_new - x) <= 4.0 * EPS * abs(x_new):
            return x_new, True
        x = x_new
        gx = event_value(alpha, beta, gamma, delta, lam, mu, 0.0, x)
        if gx == 0.0:
            return x, True
    return math.nan, False


def brent_root(alpha: float, beta: float, gamma: float, delta: float, lam: float, mu: float,
               D: float, lo: float, hi: float) -> tuple[float, bool]:
    """Brent's method (inverse quadratic extrapolation, secant and bisection steps: Brent
    1973, in the variant of ``scipy.optimize.brentq``) for the root of ``g`` in ``[lo, hi]``
    (a sign change): ``(root, converged)``. Tolerance ``BRENT_XTOL + BRENT_RTOL |x|``: no
    absolute floor, so the relative tolerance sets the precision at every scale (with lag
    1e-300 s the roots lie near 1e-300 s). Not converged after ``BRENT_MAXITER`` iterations,
    or a NaN value: ``(last iterate, False)``."""
    x_pre, x_cur = lo, hi
    f_pre = event_value(alpha, beta, gamma, delta, lam, mu, D, x_pre)
    f_cur = event_value(alpha, beta, gamma, delta, lam, mu, D, x_cur)
    if f_pre == 0.0:
        return x_pre, True
    if f_cur == 0.0:
        return x_cur, True
    if not (f_pre == f_pre and f_cur == f_cur):
        return x_cur, False
    if (math.copysign(1.0, f_pre) < 0) == (math.copysign(1.0, f_cur) < 0):
        return x_cur, False                                   # no sign change
    x_blk = f_blk = s_pre = s_cur = 0.0
    for _ in range(BRENT_MAXITER):
        if f_pre != 0.0 and f_cur != 0.0 and \
                (math.copysign(1.0, f_pre) < 0) != (math.copysign(1.0, f_cur) < 0):
            x_blk, f_blk = x_pre, f_pre                       # the bracket's other end
            s_pre = s_cur = x_cur - x_pre
        if abs(f_blk) < abs(f_cur):                           # x_cur: the best estimate
            x_pre, x_cur, x_blk = x_cur, x_blk, x_cur
            f_pre, f_cur, f_blk = f_cur, f_blk, f_cur
        tol = 0.5 * (BRENT_XTOL + BRENT_RTOL * abs(x_cur))
        s_bis = 0.5 * (x_blk - x_cur)
        if f_cur == 0.0 or abs(s_bis) < tol:
            return x_cur, True
        step = s_bis                                          # bisect, unless:
        if abs(s_pre) > tol and abs(f_cur) < abs(f_pre):
            if x_pre == x_blk:                                # secant
                s_try = -f_cur * (x_cur - x_pre) / (f_cur - f_pre)
            else:                                             # inverse quadratic
                d_pre = (f_pre - f_cur) / (x_pre - x_cur)
                d_blk = (f_blk - f_cur) / (x_blk - x_cur)
                s_try = -f_cur * (f_blk * d_blk - f_pre * d_pre) / (d_blk * d_pre * (f_blk - f_pre))
            limit = 3.0 * abs(s_bis) - tol
            if abs(s_pre) < limit:
                limit = abs(s_pre)
            if 2.0 * abs(s_try) < limit:
                step = s_try                                  # a good short step
                s_pre = s_cur
            else:
                s_pre = s_bis
        else:
            s_pre = s_bis
        s_cur = step
        x_pre, f_pre = x_cur, f_cur
        if abs(s_cur) > tol:
            x_cur += s_cur
        else:
            x_cur += tol if s_bis > 0 else -tol
        f_cur = event_value(alpha, beta, gamma, delta, lam, mu, D, x_cur)
        if f_cur != f_cur:
            return x_cur, False
    return x_cur, False


def polish_root(alpha: float, beta: float, gamma: float, delta: float, lam: float, mu: float,
                D: float, lo: float, hi: float, bits: np.ndarray, ibits: np.ndarray) -> float:
    """The root of ``g`` in the sign-changing bracket ``(lo, hi]`` to a few ulp: Newton's
    method when ``g`` is convex or concave (:func:`newton_root`), else or when Newton's does
    not settle Brent's method (:func:`brent_root`); if that does not converge either (a
    bracket spanning many binades, a stiff closed form without knots near its root), its
    last iterate may be far from the root: then bisection (:func:`bisect`), which ends on
    adjacent doubles at any scale."""
    g_lo = event_value(alpha, beta, gamma, delta, lam, mu, D, lo)
    g_hi = event_value(alpha, beta, gamma, delta, lam, mu, D, hi)
    if g_hi == 0.0 or g_lo * g_hi > 0.0:
        return hi          # (no sign change left at the ends: rounding of g; hi is a root)
    if D == 0.0 and (lam == 0.0 or mu == 0.0 or gamma == 0.0 or delta == 0.0) \
            and gamma * lam + delta * mu != 0.0:
        root, settled = newton_root(alpha, beta, gamma, delta, lam, mu, lo, hi, g_lo, g_hi)
        if settled:
            return root
    root, converged = brent_root(alpha, beta, gamma, delta, lam, mu, D, lo, hi)
    if converged:
        return root
    return bisect(alpha, beta, gamma, delta, lam, mu, D, lo, hi, False, bits, ibits)


def all_zero(values: np.ndarray, rows: np.ndarray, n: int) -> bool:
    """Whether ``values[rows[r]] == 0`` for every ``r < n``."""
    for r in range(n):
        if values[rows[r]] != 0.0:
            return False
    return True


def first_root_all(alpha: np.ndarray, beta: np.ndarray, gamma: np.ndarray, delta: np.ndarray,
                   lam: float, mu: float, D: float, horizon: float, rows: np.ndarray,
                   bits: np.ndarray, ibits: np.ndarray) -> tuple[float, int]:
    """:func:`first_root` over the functions ``rows`` (no prefilter): ``(s, p)`` with ``p``
    the position in ``rows`` of the function with the earliest root (``(inf, -1)``: none).

    ``g`` has at most one inflection, so ``g'`` is monotone on at most two pieces and ``g``
    on at most three: bracket on those pieces (knots ``0``, the inflection, the roots of
    ``g'``, ``horizon``) and take each function's first sign change. The candidates are
    halved together (:func:`midpoint`) until one can hold the earliest root, which is then
    polished on its own (:func:`polish_root`). A function with ``g(0) == 0`` (a contact tied
    at the start) has no root at 0 by construction.
    """
    n = rows.size
    # g' = base + amp exp(-rate s) for every function (no drag or compliance: lam = 0; ideal
    # motors: mu = 0; or one of the two terms absent): g is convex or concave, g' monotone.
    single = 0
    if D == 0.0:
        if lam == 0.0 or all_zero(gamma, rows, n):
            single = 1
        elif mu == 0.0 or all_zero(delta, rows, n):
            single = 2
    cand = np.empty(n, dtype=np.int64)          # candidates: position, bracket, sign at lo
    c_lo = np.empty(n)
    c_hi = np.empty(n)
    knots = np.empty(4)
    m = 0
    for r in range(n):
        i = rows[r]
        a, b, g, d = alpha[i], beta[i], gamma[i], delta[i]
        knots[0] = 0.0
        knots[1] = horizon
        knots[2] = horizon
        knots[3] = horizon
        if single != 0:
            if single == 1:
                base, amp, rate = b + (g if lam == 0.0 else 0.0), d, mu
            else:
                base, amp, rate = b + (d if mu == 0.0 else 0.0), g, lam
            if rate > 0 and (base > 0 or base < 0):
                ratio = amp / -base
                if ratio > 0:                        # g' = 0 at log(ratio) / rate
                    root = math.log(ratio) / rate
                    if root > 0 and root < horizon:
                        knots[2] = root
        else:
            infl = event_inflection(g, d, lam, mu, D)
            if infl > 0 and infl < horizon:
                knots[1] = infl
            # Roots of g' on [0, infl] and [infl, horizon].
            for col in range(2, 4):
                left = knots[0] if col == 2 else knots[1]
                right = knots[1] if col == 2 else horizon
                d_lo = event_slope(b, g, d, lam, mu, D, left)
                d_hi = event_slope(b, g, d, lam, mu, D, right)
                if d_lo * d_hi < 0:
                    knots[col] = bisect(a, b, g, d, lam, mu, D, left, right, True, bits, ibits)
        for p in range(1, 4):                         # sort the knots (insertion)
            x = knots[p]
            q = p
            while q > 0 and knots[q - 1] > x:
                knots[q] = knots[q - 1]
                q -= 1
            knots[q] = x
        v_lo = a                                      # exact g(0)
        for p in range(3):
            v_hi = event_value(a, b, g, d, lam, mu, D, knots[p + 1])
            if ((v_lo * v_hi < 0) or (v_hi == 0 and v_lo != 0)) and knots[p + 1] > knots[p]:
                cand[m] = r
                c_lo[m] = knots[p]
                c_hi[m] = knots[p + 1]
                m += 1
                break
            v_lo = v_hi
    if m == 0:
        return INF, -1
    # Halve the brackets together until one candidate can hold the earliest root.
    c_sign = np.empty(m)
    c_mid = np.empty(m)
    for c in range(m):
        i = rows[cand[c]]
        c_sign[c] = sign(event_value(alpha[i], beta[i], gamma[i], delta[i], lam, mu, D, c_lo[c]))
    k = 0
    while True:
        top = c_hi[0]
        for c in range(1, m):
            top = min(top, c_hi[c])
        kept = 0
        for c in range(m):                            # keep lo <= min(hi), in order
            if c_lo[c] <= top:
                cand[kept], c_lo[kept], c_hi[kept], c_sign[kept] = cand[c], c_lo[c], c_hi[c], \
                    c_sign[c]
                kept += 1
        m = kept
        if m == 1:
            break
        moving = False
        for c in range(m):
            c_mid[c] = midpoint(c_lo[c], c_hi[c], k, bits, ibits)
            moving = moving or (c_mid[c] > c_lo[c] and c_mid[c] < c_hi[c])
        k += 1
        if not moving:                                # adjacent doubles: the first lowest hi
            best = 0
            for c in range(1, m):
                if c_hi[c] < c_hi[best]:
                    best = c
            return c_hi[best], cand[best]
        for c in range(m):
            i = rows[cand[c]]
            here = sign(event_value(alpha[i], beta[i], gamma[i], delta[i], lam, mu, D, c_mid[c]))
            if here != c_sign[c]:
                c_hi[c] = c_mid[c]
            else:
                c_lo[c] = c_mid[c]
                c_sign[c] = here
    i = rows[cand[0]]
    root = polish_root(alpha[i], beta[i], gamma[i], delta[i], lam, mu, D, c_lo[0], c_hi[0],
                       bits, ibits)
    return root, cand[0]


def first_root(alpha: np.ndarray, beta: np.ndarray, gamma: np.ndarray, delta: np.ndarray,
               lam: float, mu: float, D: float, horizon: float) -> tuple[float, int]:
    """Earliest ``s`` in ``(0, horizon]`` (s) at which some event function ``g_i`` (rows of
    ``alpha``, ``beta``, ``gamma``, ``delta``, shape (n,)) changes sign or reaches zero, and
    the index ``i`` (``(inf, -1)`` when none does): :func:`first_root_all`, to a few ulp.

    With many functions, a cheap bound first: ``|g_i'| <= |beta| + |gamma| + |delta| + |D|``
    on ``s >= 0``, so ``g_i`` keeps its sign before ``|g_i(0)| / bound``. Only the functions
    whose bound falls inside a window are searched; the window doubles until a root is found
    inside it (then no other function can have an earlier one) or it covers the horizon.
    """
    n = alpha.size
    bits = np.zeros(2)
    ibits = bits.view(np.int64)
    if n <= SMALL:
        return first_root_all(alpha, beta, gamma, delta, lam, mu, D, horizon,
                              np.arange(n), bits, ibits)
    earliest = np.empty(n)
    lowest = np.empty(SMALL + 1)           # the SMALL + 1 lowest bounds, ascending
    count = 0
    for i in range(n):
        bound = abs(beta[i]) + abs(gamma[i]) + abs(delta[i]) + abs(D)
        if bound > 0:
            x = abs(alpha[i]) / bound
        else:
            x = 0.0 if alpha[i] == 0 else INF
        earliest[i] = x
        if x == x and (count <= SMALL or x < lowest[SMALL]):
            p = count if count <= SMALL else SMALL       # insert x, dropping the highest
            while p > 0 and lowest[p - 1] > x:
                lowest[p] = lowest[p - 1]
                p -= 1
            lowest[p] = x
            count = min(count + 1, SMALL + 1)
    window = lowest[SMALL] if count > SMALL else math.nan     # (NaN bounds sort last)
    rows = np.empty(n, dtype=np.int64)
    while True:
        picked = 0
        for i in range(n):
            if earliest[i] <= window:
                rows[picked] = i
                picked += 1
        s, p = first_root_all(alpha, beta, gamma, delta, lam, mu, D,
                              window if window < horizon else horizon, rows[:picked], bits,
                              ibits)
        if p >= 0:
            return s, rows[p]
        later = INF
        found = False
        for i in range(n):
            if earliest[i] > window:
                later = earliest[i] if not found else min(later, earliest[i])
                found = True
        if window >= horizon or not found:
            return INF, -1
        window = later if later > 2.0 * window else 2.0 * window


def free_first_root(v: np.ndarray, q: np.ndarray, e: np.ndarray, tied: np.ndarray, V: float,
                    r0: float, acc: float, lam: float, mu: float,
                    horizon: float) -> tuple[float, int]:
    """The first crossing of a body sliding free of every contact: :func:`first_root` of
    ``g_i(s) = V(s) - v_i(s)`` over ``(0, horizon]`` (s), the body's closed form
    ``V(s) = V + r0 x(lam, s)`` (m/s, ``r0`` m/s^2, ``lam`` 1/s) against contact ``i``'s
    ``v_i(s) = v_i + q_i s + e_i x(mu, s)`` (shape (n,): m/s, m/s^2, m/s^2), so
    ``alpha = V - v_i`` (0 where ``tied``: the body is on that contact now), ``beta = -q_i``,
    ``gamma = r0``, ``delta = -e_i``. A tied contact whose rate ``q_i + e_i`` is the body's
    acceleration ``acc`` (within ``1e-9`` relative) is grazed: ``beta = e_i - r0``, so that
    ``g_i'(0) = 0`` exactly."""
    n = v.size
    alpha = np.empty(n)
    beta = np.empty(n)
    gamma = np.empty(n)
    delta = np.empty(n)
    for i in range(n):
        alpha[i] = 0.0 if tied[i] else V - v[i]
        rate = q[i] + e[i]
        if tied[i] and abs(acc - rate) <= 1e-9 * (abs(acc) + abs(rate)):
            beta[i] = -(r0 - e[i])
        else:
            beta[i] = -q[i]
        gamma[i] = r0
        delta[i] = -e[i]
    return first_root(alpha, beta, gamma, delta, lam, mu, 0.0, horizon)


def stuck_first_root(v: np.ndarray, q: np.ndarray, e: np.ndarray, tied: np.ndarray,
                     group: np.ndarray, stuck: int, W: float, tol: float, h0: float, c: float,
                     m: float, mu: float, horizon: float) -> tuple[float, int, float]:
    """The first event of a body stuck to contact ``stuck`` (with the contacts of ``group``,
    which move with it): :func:`first_root` over ``(0, horizon]`` (s) of the crossings
    ``v_k(s) - v_i(s)`` of every other contact ``i`` (contact speeds
    ``v_i(s) = v_i + q_i s + e_i x(mu, s)``, shape (n,); ``alpha = 0`` where ``tied``) and of
    the stiction margins ``W + tol -+ h(s)``, with ``h(s) = h0 + c q_k s
    + e_k (c - m mu) x(mu, s)`` the force (N) the group must hold against (drag ``c`` N s/m,
    mass ``m`` kg), ``W`` (N) its stiction and ``tol`` (N) the tie tolerance.

    Returns ``(s, i, releasing)``: the time of the event, the contact crossed (or -1), and
    +1 / -1 when the body leaves the group upward / downward (``h`` exceeds ``W + tol`` / falls
    below ``-(W + tol)``; else 0); ``(inf, -1, 0.0)`` when nothing happens before ``horizon``.
    """
    n = v.size
    others = 0
    for i in range(n):
        if not group[i]:
            others += 1
    alpha = np.empty(others + 2)
    beta = np.empty(others + 2)
    gamma = np.zeros(others + 2)
    delta = np.empty(others + 2)
    rows = np.empty(others, dtype=np.int64)
    vc, qc, ec = v[stuck], q[stuck], e[stuck]
    k = 0
    for i in range(n):
        if not group[i]:
            alpha[k] = 0.0 if tied[i] else vc - v[i]
            beta[k] = qc - q[i]
            delta[k] = ec - e[i]
            rows[k] = i
            k += 1
    alpha[k] = W + tol - h0                       # h reaches +(W + tol): released upward
    beta[k] = c * qc
    delta[k] = ec * (c - m * mu)
    alpha[k + 1] = h0 + W + tol                   # h reaches -(W + tol): released downward
    beta[k + 1] = -c * qc
    delta[k + 1] = ec * (m * mu - c)
    s, p = first_root(alpha, beta, gamma, delta, 0.0, mu, 0.0, horizon)
    if p < 0:
        return s, -1, 0.0
    if p >= others:
        return s, -1, (1.0 if p == others else -1.0)
    return s, rows[p], 0.0


# -- many constant-speed scenes ----------------------------------------------------------------
def sorted_landscape(speeds: np.ndarray, forces: np.ndarray, s: int, order: np.ndarray,
                     land: np.ndarray, first: np.ndarray) -> int:
    """The staircase of scene ``s`` (row ``s`` of ``speeds``, ``forces``) into the rows
    ``xs``, ``below``, ``above`` of ``land`` as :class:`ContactSet` builds them (the distinct
    speeds of the touching contacts ascending, the magnitude at each summed in index order,
    prefix sums from below and from above), and ``first``: the lowest contact index at each
    level; ``order`` (n,) is scratch. Returns ``K``."""
    xs, below, above = land[0], land[1], land[2]
    n = speeds.shape[1]
    m = 0
    for i in range(n):                     # insertion sort of the touching contacts (stable)
        if forces[s, i] > 0:
            v = speeds[s, i]
            p = m
            while p > 0 and xs[p - 1] > v:
                xs[p] = xs[p - 1]
                order[p] = order[p - 1]
                p -= 1
            xs[p] = v
            order[p] = i
            m += 1
    K = 0
    for p in range(m):
        i = order[p]
        v = xs[p]
        if K == 0 or v != xs[K - 1]:
            xs[K] = v
            first[K] = i
            above[K] = forces[s, i]        # (the step at level K, summed below)
            K += 1
        else:
            above[K - 1] += forces[s, i]
    below[0] = 0.0
    for k in range(K):                     # np.cumsum of the steps
        below[k + 1] = below[k] + above[k]
    acc = 0.0
    above[K] = 0.0
    for k in range(K - 1, -1, -1):         # np.cumsum of the reversed steps
        acc += above[k]
        above[k] = acc
    return K


def batch_scene(speeds: np.ndarray, forces: np.ndarray, s: int, m: float, c: float, E: float,
                v0: float, t_end: float, order: np.ndarray, land: np.ndarray,
                first: np.ndarray, fstate: np.ndarray, istate: np.ndarray,
                seg: np.ndarray, ev: np.ndarray) -> tuple[float, int, bool, int]:
    """Scene ``s`` of :func:`batch` through :func:`ideal_piece` (scratch arrays given):
    ``(final speed, events, stuck at the end, code)``."""
    K = sorted_landscape(speeds, forces, s, order, land, first)
    n = speeds.shape[1]
    fstate[F_T] = 0.0
    fstate[F_V] = v0
    fstate[F_RATE] = INF
    istate[I_STUCK] = -1
    istate[I_NSEG] = 0
    istate[I_NEV] = 0
    istate[I_ROUNDS] = 0
    istate[I_NEVAL] = 0
    istate[I_STARTED] = 0
    istate[I_MAXSTEPS] = 4 * n + 8           # rounds: at most 2 n + 2 (one pass per level)
    istate[I_WINDOW] = 4 * n + 8             # (so Zeno never triggers)
    istate[I_CHUNK] = 4 * n + 8
    # ``first`` is complete, so the engine never reads the speeds and forces it is given.
    code = ideal_piece(True, K, land, first, fstate, fstate, land[1, K], m, c, E, t_end,
                       fstate, istate, seg, ev)
    return fstate[F_V], istate[I_NEV], istate[I_STUCK] >= 0, code


def batch(speeds: np.ndarray, forces: np.ndarray, mass: np.ndarray, damping: np.ndarray,
          external: np.ndarray, v0: np.ndarray, t_end: float, V: np.ndarray,
          events: np.ndarray, stuck: np.ndarray, codes: np.ndarray) -> None:
    """Every scene ``s`` (rows of ``speeds``, ``forces``; entries of the per-scene arrays)
    through :func:`batch_scene`, in parallel over blocks of scenes, each block with its own
    scratch arrays."""
    S, n = speeds.shape
    rows = 4 * n + 16                 # a scene has at most 2 n + 2 rounds of two rows each
    block = 256
    blocks = (S + block - 1) // block
    for blk in prange(blocks):
        order = np.empty(n, dtype=np.int64)
        land = np.empty((3, n + 1))
        first = np.empty(n, dtype=np.int64)
        fstate = np.zeros(N_FSTATE)
        istate = np.zeros(N_ISTATE, dtype=np.int64)
        seg = np.empty((rows, 7))
        ev = np.empty((rows, 4))
        for s in range(blk * block, min(S, (blk + 1) * block)):
            V[s], events[s], stuck[s], codes[s] = batch_scene(
                speeds, forces, s, mass[s], damping[s], external[s], v0[s], t_end,
                order, land, first, fstate, istate, seg, ev)
