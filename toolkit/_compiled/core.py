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
- :func:`dynamic_run`: the engine with lagging or rate-limited motors, whole: the motors'
  closed form (:func:`motor_build`, :func:`motor_coefficients`), the contacts tied with the
  body, the Filippov solution among them (:func:`filippov`), compliant contacts
  (:func:`compliant_round`), each segment's first event, the budget and Zeno guards, over
  every piece of constant command; :func:`advance_dynamic`: one sample period of a closed
  loop (the no-event certificate, else the engine) with its exact displacements.
- :func:`batch`: many constant-speed scenes, each through :func:`ideal_piece` (so each
  equals the single run), in parallel over scenes (``prange``).
- :func:`linearize_step`: the estimators' linearization of one exact step along its events
  (``toolkit.estimation.EstimatorModel``: slopes, the contacts' noise, the response to an
  outside force), the contacts' forces as the engine's per-contact signs and the motors' as
  :func:`motor_coefficients`.

How the laws stay written once. The friction law is evaluated here from the prefix sums that
:class:`toolkit.model.ContactSet` builds (``net force = magnitude above - magnitude below``,
snapped within the tie tolerance): :meth:`ContactSet.force` and the exact engine both call
:func:`net_force`. The compliant landscape comes from
:func:`toolkit.model.friction.compliant_breakpoints`. The motor law of
:mod:`toolkit.model.motors` (``motor_rate``, solved by ``MotorPiece``) has its one compiled form
here, :func:`motor_build`, :func:`motor_speed`, :func:`motor_coefficients` and
:func:`motor_displacement` (and the lag-only closed form :func:`quiet_piece` evaluates);
``tests/test_compiled.py`` evaluates both on one grid. Sums are NumPy's own
(:func:`pairwise_sum`), so the engine's numbers are the NumPy engine's it replaced.

Segment rows are ``(t0, V0, c1, B, lam, C, D)`` with
``V(t0 + s) = V0 + c1 s + B x(lam, s) + C x(mu, s) + D s exp(-mu s)``,
``x(r, s) = expm1_ratio(r, s) = (1 - exp(-r s)) / r`` (``= s`` at ``r = 0``). Event rows are
``(t, kind, contact, V)`` with the kind codes below and contact ``-1`` for none.
"""

from __future__ import annotations

import math

import numpy as np

from ..model.laws import lag_decay, lag_response, lag_travel, tie_tolerance

#: Replaced by ``numba.prange`` when compiled (a parallel loop); ``range`` as Python.
prange = range

EPS = 2.220446049250313e-16          # float64 machine epsilon
INF = math.inf

# Event kinds (the order of toolkit.simulation._result.EVENT_KINDS is not assumed: the
# caller maps these codes to its names).
CROSS, STICK, RELEASE, SATURATION, COMMAND = 0, 1, 2, 3, 4
# Return codes of the loops.
DONE, MAX_STEPS, ZENO, PAUSE, FAILED_STEP = 0, 1, 2, 3, 4
# Layout of the loop state arrays (fstate: floats, istate: ints).
# The dynamic-motor engine (dynamic_run) also keeps its piece's offset and its mode there.
F_T, F_V, F_TSUM, F_TERR, F_RATE, F_OFF, F_REL = range(7)
(I_J, I_AT, I_STUCK, I_NSEG, I_NEV, I_ROUNDS, I_NEVAL, I_STARTED, I_MAXSTEPS, I_WINDOW,
 I_CHUNK, I_HINT, I_PIECE) = range(13)
N_FSTATE, N_ISTATE = 7, 13
# A dynamic-motor plant's constants, one array (advance_dynamic).
(P_TOTAL, P_MASS, P_DAMPING, P_COMPLIANCE, P_TAU, P_RATE, P_RAMP_GAP, P_SPEED_BOUND,
 P_MARGIN) = range(9)
N_PARAMS = 9

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
    "quiet_piece": {}, "sorted_landscape": {}, "sorted_steps": _INLINE,
    "staircase_sums": _INLINE, "contact_table": {}, "staircase_median": {}, "median_row": {},
    "median_edges": {}, "period_bounds": {}, "window_line": {},
    "kalman_step": {}, "linearize_step": {}, "gathered_sum": _INLINE, "contains": _INLINE,
    "stuck_stretch": {},
    "batch_scene": {}, "batch": {"parallel": True},
    "ordered_within": {},
    # The event roots of the dynamic-motor engine: IEEE division (inf, NaN) as NumPy's.
    "event_value": _IEEE, "event_slope": _IEEE, "event_inflection": _IEEE,
    "sign": _IEEE, "midpoint": _IEEE, "bisect": _IEEE, "newton_root": _IEEE,
    "brent_root": _IEEE, "polish_root": _IEEE, "all_zero": _INLINE, "first_root_all": _IEEE,
    "first_root": _IEEE,
    "free_first_root": _IEEE, "stuck_first_root": _IEEE,
    # The dynamic-motor engine: the motor law's closed form and the rounds of the engine.
    "motor_build": _IEEE, "motor_speed": {"inline": "always", "error_model": "numpy"},
    "motor_coefficients": _IEEE, "motor_displacement": _IEEE, "pairwise_sum": _IEEE, "pairwise_block": _INLINE,
    "play_taken_up": _IEEE, "play_take_up_time": _IEEE,
    "filippov": _IEEE, "compliant_round": _IEEE, "dynamic_run": _IEEE,
    "advance_dynamic": _IEEE, "advance_outputs": _IEEE,
    # Sampled loops: the sensor law's and the laws' compiled forms, one loop, many loops.
    "sensor_read": _INLINE, "law_output": _IEEE, "sampled_steps": _IEEE, "grown": {},
    "sampled_batch": {"parallel": True, "error_model": "numpy"},
    # Counter-based random numbers for sweeps.
    "mulhilo": _INLINE, "philox_block": _INLINE, "philox_uniform": {},
    # The model's laws (toolkit.model.laws), compiled as they are written.
    "tie_tolerance": _IEEE, "lag_decay": _IEEE, "lag_response": _IEEE, "lag_travel": _IEEE,
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
    tol = tie_tolerance(K, total)                  # the prefix sums' rounding
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
            tol_G = tie_tolerance(K, push_scale + c * abs(V))
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
    ``stuck`` (-1: free), external force ``E`` (N), when it shows that :func:`dynamic_run`
    would run it as one closed-form segment without an event. When certified, returns
    ``(True, V_end, body_displacement)`` and fills ``out[0]`` with the contact speeds at ``S``
    and ``out[1]`` with their displacements (m); else ``(False, nan, nan)`` (the caller runs
    the engine).

    The certificate uses the engine's own closed forms on ``[0, S]``. Without a ramp phase
    (no motor on its rate limit) contact ``i`` moves as ``v_i(s) = v_i + e_i x_mu(s)`` with
    ``x_r(s) = expm1_ratio(r, s)``, and the body

    - free (no contact tied now): ``V(s) = V + r0 x_lam(s)`` under the constant force ``m r0``
      of the current signs. The crossing function ``g_i = V(s) - v_i(s)`` has
      ``g_i' = r0 exp(-lam s) - e_i exp(-mu s)``, zero at most once, at
      ``s* = log(e_i / r0) / (mu - lam)``: its range on ``[0, S]`` is spanned by ``g_i(0)``,
      ``g_i(S)`` and ``g_i(s*)`` when ``0 < s* < S``. No crossing when these share a sign.
    - stuck to contact ``k`` (and any contacts on its very track: the same start and
      command, e.g. at a speed limit): ``V = v_k(s)``; the gap
      ``v_k(s) - v_i(s) = (v_k - v_i) + (e_k - e_i) x_mu(s)`` is monotone (no crossing when
      its ends share a sign), and so is the stiction margin
      ``h(s) = G - c v_k - m dv_k/dt = h0 + e_k (m mu - c) x_mu(s)``: it stays stuck when
      ``|h| <= W`` (the group's total force) at both ends.

    "Share a sign" and "``<= W``" hold with a relative margin ``margin_rel`` (``2^-40``) of
    the speed or force scale, far above the rounding of the engine's tie tests and event
    functions (``64 eps``, ``4 (N + 1) eps``, a few ulp), so the engine finds no tie and no
    event either and the two evaluate the same closed forms: they agree to rounding."""
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
    for i in range(n):
        out[0, i] = lag_response(u[i], start[i], S, tau, math.exp)   # MotorPiece.speeds(S)
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
    for i in range(n):                                     # MotorPiece.displacement, no ramp
        out[1, i] = lag_travel(u[i], start[i], S, tau, math.expm1)
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


# -- dynamic motors: the motor law's closed form ------------------------------------------------
# One piece of constant command ``u`` from speeds ``start``: the solution of the motor law of
# :mod:`toolkit.model.motors` (:class:`~toolkit.model.motors.MotorPiece`, its one compiled form
# here; ``tests/test_compiled.py`` evaluates both on one grid). ``motor`` is a table (5, n):
# rows ``start``, ``u``, ``ramp`` (slope at the rate limit, m/s^2, 0 where no ramp),
# ``ramp_end`` (offset where the ramp ends, s) and ``after`` (speed there, m/s).
M_START, M_U, M_RAMP, M_END, M_AFTER = 0, 1, 2, 3, 4


def motor_build(start: np.ndarray, u: np.ndarray, tau: float, rate: float,
                motor: np.ndarray) -> None:
    """:meth:`MotorPiece.build`: each motor ramps at the rate limit ``rate`` (m/s^2) while its
    gap to the command exceeds ``rate tau``, then approaches it with time constant ``tau``."""
    n = start.size
    for i in range(n):
        s0 = start[i]
        ui = u[i]
        motor[M_START, i] = s0
        motor[M_U, i] = ui
        motor[M_RAMP, i] = 0.0
        motor[M_END, i] = 0.0
        motor[M_AFTER, i] = s0
        if rate < INF:
            gap = ui - s0
            direction = sign(gap)
            excess = abs(gap) - rate * tau
            if excess > 0:
                motor[M_RAMP, i] = direction * rate
                motor[M_END, i] = excess / rate
                motor[M_AFTER, i] = ui - direction * rate * tau


def motor_speed(motor: np.ndarray, tau: float, i: int, s: float) -> float:
    """Speed of contact ``i`` at offset ``s`` (s) of the piece (:meth:`MotorPiece.speeds_at`)."""
    end = motor[M_END, i]
    if s < end:
        return motor[M_START, i] + motor[M_RAMP, i] * s
    if tau > 0:
        return lag_response(motor[M_U, i], motor[M_AFTER, i], s - end, tau, math.exp)
    return motor[M_AFTER, i]


def motor_coefficients(motor: np.ndarray, tau: float, s: float, v: np.ndarray, q: np.ndarray,
                       e: np.ndarray) -> float:
    """:meth:`MotorPiece.coefficients` at offset ``s``: speeds ``v``, ramp slopes ``q`` and
    exponential rates ``e`` (``v(s + x) = v + q x + e expm1_ratio(1 / tau, x)``) into the
    arrays given; returns the offset of the next phase change (``inf``: none)."""
    phase_end = INF
    for i in range(v.size):
        v[i] = motor_speed(motor, tau, i, s)
        end = motor[M_END, i]
        if s < end:
            q[i] = motor[M_RAMP, i]
            e[i] = 0.0
            phase_end = min(phase_end, end)
        else:
            q[i] = 0.0
            e[i] = (motor[M_U, i] - v[i]) / tau if tau > 0 else 0.0
    return phase_end


def motor_displacement(motor: np.ndarray, tau: float, s: float, out: np.ndarray) -> None:
    """Distance (m) each contact travels over the offsets ``[0, s]``: the exact integral of
    :func:`motor_speed` (:meth:`MotorPiece.displacement`), into ``out`` (n,)."""
    for i in range(out.size):
        on_ramp = min(s, motor[M_END, i])
        rest = s - on_ramp
        distance = motor[M_START, i] * on_ramp + 0.5 * motor[M_RAMP, i] * on_ramp * on_ramp
        if tau > 0:
            out[i] = distance + lag_travel(motor[M_U, i], motor[M_AFTER, i], rest, tau, math.expm1)
        else:
            out[i] = distance + motor[M_AFTER, i] * rest


def play_taken_up(motor: np.ndarray, tau: float, turn: np.ndarray, at_turn: np.ndarray,
                  play: float, s: float, out: np.ndarray) -> bool:
    """Whether, at offset ``s`` (s) of the piece ``motor`` (:func:`motor_build`), every motor
    has turned (``s >= turn``) and travelled at least ``play`` (m) from where it turned
    (its displacement there ``at_turn``, m); ``out`` (n,) is scratch."""
    motor_displacement(motor, tau, s, out)
    for i in range(out.size):
        if not (s >= turn[i] and abs(out[i] - at_turn[i]) >= play):
            return False
    return True


def play_take_up_time(start: np.ndarray, u: np.ndarray, tau: float, turn: np.ndarray,
                      play: float, step: float) -> float:
    """The offset (s) from a command change at which every motor that turns (speeds ``start``
    to commands ``u``, lag ``tau``, no rate limit; each turning at offset ``turn``) has
    travelled ``play`` (m) from where it turned, on the motor law's displacement
    (:func:`motor_displacement`): bracketed from ``max(turn)`` by steps of ``step`` (s), then
    50 bisections; the upper end."""
    n = start.size
    motor = np.empty((5, n))
    motor_build(start, u, tau, INF, motor)
    out = np.empty(n)
    at_turn = np.empty(n)
    for i in range(n):
        motor_displacement(motor, tau, turn[i], out)
        at_turn[i] = out[i]
    lo = turn[0]
    for i in range(1, n):
        lo = max(lo, turn[i])
    hi = lo + step
    while not play_taken_up(motor, tau, turn, at_turn, play, hi, out):
        hi += step
    for _ in range(50):
        mid = 0.5 * (lo + hi)
        if play_taken_up(motor, tau, turn, at_turn, play, mid, out):
            hi = mid
        else:
            lo = mid
    return hi


# -- dynamic motors: the engine -----------------------------------------------------------------
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


def filippov(G_out: float, slopes: np.ndarray, weights: np.ndarray, T: int, mass: float,
             tol: float, order: np.ndarray, levels: np.ndarray,
             level_w: np.ndarray) -> tuple[float, bool, float]:
    """Solve ``0 in G_out + sum_j w_j Sign(slope_j - a) - m a`` for the body's acceleration
    ``a`` over the ``T`` tied contacts (``slopes``, ``weights``; ``order``, ``levels`` and
    ``level_w`` (T,) are scratch). Returns ``(a, follows, level)``: ``follows`` when the body
    follows the contacts whose slope is ``level`` (then ``a = level``). The left side
    decreases in ``a``, so the levels are tried in ascending order."""
    if T == 0:
        return (G_out - 0.0) / mass, False, 0.0
    if T == 1:                                  # (the loop below for one level, unrolled)
        level, w0 = slopes[0], weights[0]
        if abs(G_out + 0.0 - 0.0 - mass * level) <= w0 + tol:
            return level, True, level
        a = (G_out + (w0 - 0.0) - 0.0) / mass
        if a < level:
            return a, False, 0.0
        return (G_out - w0) / mass, False, 0.0
    for j in range(T):                          # stable insertion sort of the slopes
        x = slopes[j]
        p = j
        while p > 0 and slopes[order[p - 1]] > x:
            order[p] = order[p - 1]
            p -= 1
        order[p] = j
    K = 0                                       # the distinct levels and the weight at each
    for p in range(T):
        x = slopes[order[p]]
        if K == 0 or x != levels[K - 1]:
            levels[K] = x
            level_w[K] = weights[order[p]]
            K += 1
        else:
            level_w[K - 1] += weights[order[p]]
    total = 0.0
    for k in range(K):
        total += level_w[k]
    below = 0.0
    for k in range(K):
        level = levels[k]
        below_next = below + level_w[k]
        base = G_out + (total - below_next) - below - mass * level
        if abs(base) <= level_w[k] + tol:
            return level, True, level
        a = (G_out + (total - below) - below) / mass
        if a < level:
            return a, False, 0.0
        below = below_next
    return (G_out - total) / mass, False, 0.0


def compliant_round(f: np.ndarray, m: float, c: float, k: float, mu: float, E: float,
                    V: float, v: np.ndarray, q: np.ndarray, e: np.ndarray, hint: int,
                    tie_v: float, region: np.ndarray, slip: np.ndarray, on_edge: np.ndarray,
                    gather: np.ndarray, alpha: np.ndarray, beta: np.ndarray,
                    gamma: np.ndarray, delta: np.ndarray,
                    rows: np.ndarray) -> tuple[int, float, float, float, float, float]:
    """One round of compliant contacts (saturated-linear force ``f clip((v - V) / (k f), -1,
    1)``, :func:`toolkit.model.friction.contact_forces`): the closed-form segment
    ``(B, lam, c1, C, D)`` of the contacts' current regions and the event functions of the
    slips reaching ``+-k f`` (rows of ``alpha`` .. ``delta``, the contact of each in ``rows``:
    every upper limit first, then every lower one). Returns ``(count, B, lam, c1, C, D)``; the
    other arrays (n,) are scratch."""
    n = v.size
    any_edge = False
    for i in range(n):
        kf = k * f[i]
        s = v[i] - V
        slip[i] = s
        region[i] = 1.0 if s > kf else (-1.0 if s < -kf else 0.0)
        edge = abs(abs(s) - kf) <= tie_v and f[i] > 0
        if i == hint:
            edge = f[i] > 0
        on_edge[i] = edge
        any_edge = any_edge or edge
    if any_edge:
        # The force is continuous: V' is known, and the slip's derivative picks the side.
        for i in range(n):
            kf = k * f[i]
            if kf > 0:
                gather[i] = f[i] * min(max(slip[i] / kf, -1.0), 1.0)
            else:
                gather[i] = 0.0
        acc = (pairwise_sum(gather, 0, n) + E - c * V) / m
        for i in range(n):
            if on_edge[i]:
                edge_sign = sign(slip[i])
                drift = (q[i] + e[i]) - acc
                region[i] = edge_sign if drift * edge_sign > 0 else 0.0
                slip[i] = edge_sign * (k * f[i])
    count = 0
    for i in range(n):
        if not f[i] > 0:
            region[i] = 2.0                     # lifted contacts never matter
        if region[i] == 0.0:
            count += 1
    b = c + float(count) / k
    used = 0
    for i in range(n):
        if region[i] == 0.0:
            gather[used] = v[i]
            used += 1
    alpha_a = pairwise_sum(gather, 0, used) / k
    used = 0
    for i in range(n):
        if abs(region[i]) == 1.0:
            gather[used] = f[i] * region[i]
            used += 1
    alpha_a = alpha_a + pairwise_sum(gather, 0, used) + E
    used = 0
    for i in range(n):
        if region[i] == 0.0:
            gather[used] = q[i]
            used += 1
    beta_a = pairwise_sum(gather, 0, used) / k
    used = 0
    for i in range(n):
        if region[i] == 0.0:
            gather[used] = e[i]
            used += 1
    gamma_a = pairwise_sum(gather, 0, used) / k
    C = 0.0
    D = 0.0
    if b == 0.0:
        c1, B, lam = 0.0, alpha_a / m, 0.0
    else:
        lam = b / m
        c1 = beta_a / b
        if gamma_a != 0.0:
            if b != m * mu:
                C = gamma_a / (b - m * mu)
            else:
                D = -gamma_a / b
        B = (alpha_a - b * V) / m - c1 - C - D
    count = 0
    for i in range(n):                          # slips reaching +k f (upper) from inside
        if region[i] == 0.0 or region[i] == 1.0:
            alpha[count] = 0.0 if (on_edge[i] and slip[i] > 0) else (V - v[i]) + k * f[i]
            rows[count] = i
            count += 1
    for i in range(n):                          # ... and -k f (lower)
        if region[i] == 0.0 or region[i] == -1.0:
            alpha[count] = 0.0 if (on_edge[i] and slip[i] < 0) else (V - v[i]) - k * f[i]
            rows[count] = i
            count += 1
    for r in range(count):
        i = rows[r]
        beta[r] = c1 - q[i]
        gamma[r] = B
        delta[r] = C - e[i]
    return count, B, lam, c1, C, D


def dynamic_run(f: np.ndarray, total: float, m: float, c: float, k: float, tau: float,
                rate: float, bounds: np.ndarray, commands: np.ndarray, externals: np.ndarray,
                motor: np.ndarray, fstate: np.ndarray, istate: np.ndarray, seg: np.ndarray,
                ev: np.ndarray) -> int:
    """The dynamic-motor engine (motor lag ``tau`` s, rate limit ``rate`` m/s^2; compliance
    ``k`` (m/s)/N or Coulomb contacts of magnitudes ``f`` (N, total ``total``); mass ``m`` kg,
    drag ``c`` N s/m) over the pieces ``[bounds[p], bounds[p + 1])`` of constant command
    ``commands[p]`` (m/s, clipped to the speed limits) and external force ``externals[p]``
    (N); the one engine of ``simulate`` and ``advance`` with lagging or rate-limited motors.

    State in ``fstate`` / ``istate`` as :func:`ideal_piece` keeps it, plus the piece
    ``I_PIECE``, its offset ``F_OFF``, and the engine's mode: ``I_STUCK`` (the contact the body
    follows, -1 free), ``I_HINT`` (the contact whose event ended the last segment, -1 none)
    and ``F_REL`` (+-1 while the body leaves ``I_STUCK`` upward / downward). ``I_STARTED = 0``:
    piece ``I_PIECE`` starts now, from the contact speeds in ``motor[M_START]`` when it is the
    first (else from where the previous piece ended); ``motor`` (5, n) holds the current
    piece (:func:`motor_build`).

    Each round: the motors' coefficients (:func:`motor_coefficients`), the contacts tied with
    the body (within ``64 eps`` of the speed scale), the Filippov solution of the tied
    contacts (:func:`filippov`), the events of this instant, one closed-form segment and its
    first event (:func:`free_first_root`, :func:`stuck_first_root`; compliant contacts:
    :func:`compliant_round` and :func:`first_root`). Returns ``DONE``, ``MAX_STEPS``,
    ``ZENO`` (stopped at ``fstate[F_T]``) or ``PAUSE`` (as :func:`ideal_piece`).
    """
    n = f.size
    P = bounds.size - 1
    mu = 1.0 / tau if tau > 0 else 0.0
    t = fstate[F_T]
    V = fstate[F_V]
    off = fstate[F_OFF]
    releasing = fstate[F_REL]
    rate_ev = fstate[F_RATE]
    p = istate[I_PIECE]
    stuck = istate[I_STUCK]
    hint = istate[I_HINT]
    started = istate[I_STARTED] != 0
    nseg = istate[I_NSEG]
    nev = istate[I_NEV]
    rounds = istate[I_ROUNDS]
    n_eval = istate[I_NEVAL]
    max_steps = istate[I_MAXSTEPS]
    window = istate[I_WINDOW]
    free = min(seg.shape[0] - nseg, ev.shape[0] - nev)
    if free < 8:
        return PAUSE
    # A round stores one segment row and at most four event rows (a command, a release, a
    # stick and a crossing).
    chunk = min((free - 4) // 4, istate[I_CHUNK])
    work = np.empty((8, n))
    v, q, e, side, signs, gather, slip, region = (work[0], work[1], work[2], work[3],
                                                  work[4], work[5], work[6], work[7])
    flags = np.empty((3, n), dtype=np.bool_)
    tied, group, on_edge = flags[0], flags[1], flags[2]
    fns = np.empty((4, 2 * n))
    alpha, beta, gamma, delta = fns[0], fns[1], fns[2], fns[3]
    rows = np.empty(2 * n, dtype=np.int64)
    tied_idx = np.empty(n, dtype=np.int64)
    order = np.empty(n, dtype=np.int64)
    small = np.empty((4, n))
    t_slopes, t_weights, levels, level_w = small[0], small[1], small[2], small[3]
    code = DONE
    done = 0
    while p < P:
        a = bounds[p]
        b = bounds[p + 1]
        if not started:
            if p > 0:                           # the speeds where the previous piece ended
                span = a - bounds[p - 1]
                for i in range(n):
                    v[i] = motor_speed(motor, tau, i, span)
                nev = push_event(ev, nev, a, COMMAND, -1, V)
                motor_build(v, commands[p], tau, rate, motor)
            else:
                for i in range(n):
                    v[i] = motor[M_START, i]
                motor_build(v, commands[p], tau, rate, motor)
            started = True
            off = 0.0
            t = a
        E = externals[p]
        length = b - a                          # offsets from a keep phase ends exact
        while off < length:
            phase_end = motor_coefficients(motor, tau, off, v, q, e)
            off_next = min(length, phase_end)
            t_next = b if off_next == length else a + off_next
            horizon = off_next - off
            scale = abs(V)
            steepest = 0.0
            top = 0.0
            for i in range(n):
                top = max(top, abs(v[i]))
                steepest = max(steepest, abs(q[i] + e[i]))
            scale = max(scale, top)
            tie_v = 64.0 * EPS * scale
            tol = tie_tolerance(n, total + abs(E) + c * abs(V) + m * steepest)
            n_eval += 1
            if k > 0:
                count, B, lam, c1, C, D = compliant_round(
                    f, m, c, k, mu, E, V, v, q, e, hint, tie_v, region, slip, on_edge,
                    gather, alpha, beta, gamma, delta, rows)
                nseg = push_segment(seg, nseg, t, V, c1, B, lam, C, D)
                s, r = first_root(alpha[:count], beta[:count], gamma[:count], delta[:count],
                                  lam, mu, D, horizon)
                x = s if r >= 0 else horizon
                V_new = (V + c1 * x + B * expm1_ratio(lam, x) + C * expm1_ratio(mu, x)
                         + D * x * math.exp(-mu * x))
                if r >= 0:
                    off += s
                    t = a + off
                    V = V_new
                    hint = rows[r]
                    nev = push_event(ev, nev, t, SATURATION, hint, V)
                else:
                    off = off_next
                    t = t_next
                    V = V_new
                    hint = -1
            else:
                # Coulomb contacts: which are tied with the body now?
                for i in range(n):
                    tied[i] = abs(v[i] - V) <= tie_v
                if hint >= 0:
                    tied[hint] = True
                if stuck >= 0:
                    tied[stuck] = True
                T = 0
                for i in range(n):
                    tied[i] = tied[i] and f[i] > 0
                    if tied[i]:
                        tied_idx[T] = i
                        T += 1
                anchor = hint if hint >= 0 else stuck
                if anchor >= 0 and tied[anchor]:
                    V = v[anchor]
                used = 0
                for i in range(n):
                    side[i] = sign(v[i] - V)
                    if not tied[i]:
                        gather[used] = f[i] * side[i]
                        used += 1
                G_out = pairwise_sum(gather, 0, used) + E - c * V
                for j in range(T):
                    i = tied_idx[j]
                    t_slopes[j] = q[i] + e[i]
                    if releasing != 0.0 and i == stuck:
                        t_slopes[j] = -releasing * INF
                    t_weights[j] = f[i]
                acc, follows, level = filippov(G_out, t_slopes, t_weights, T, m, tol, order,
                                               levels, level_w)
                new_stuck = -1
                if follows:
                    for j in range(T):
                        if t_slopes[j] == level:
                            new_stuck = tied_idx[j]
                            break
                # Events at this instant.
                if stuck >= 0 and new_stuck != stuck:
                    nev = push_event(ev, nev, t, RELEASE, stuck, V)
                if new_stuck >= 0 and new_stuck != stuck:
                    nev = push_event(ev, nev, t, STICK, new_stuck, V)
                if hint >= 0 and (new_stuck < 0 or hint != new_stuck) and hint != stuck:
                    nev = push_event(ev, nev, t, CROSS, hint, V)
                stuck = new_stuck
                hint = -1
                releasing = 0.0
                if stuck < 0:
                    for i in range(n):
                        signs[i] = side[i]
                    for j in range(T):
                        signs[tied_idx[j]] = sign(t_slopes[j] - acc)
                    for i in range(n):
                        gather[i] = f[i] * signs[i]
                    r0 = (pairwise_sum(gather, 0, n) + E - c * V) / m
                    lam = c / m
                    nseg = push_segment(seg, nseg, t, V, 0.0, r0, lam, 0.0, 0.0)
                    s, r = free_first_root(v, q, e, tied, V, r0, acc, lam, mu, horizon)
                    step = horizon if r < 0 else s
                    V_new = V + r0 * expm1_ratio(lam, step)
                else:
                    for i in range(n):
                        group[i] = False
                    for j in range(T):
                        if follows and t_slopes[j] == level:
                            group[tied_idx[j]] = True
                    used = 0
                    for i in range(n):
                        if group[i]:
                            gather[used] = f[i]
                            used += 1
                    W = pairwise_sum(gather, 0, used)
                    used = 0
                    for i in range(n):
                        signs[i] = side[i]
                        if tied[i] and not group[i]:
                            signs[i] = sign((q[i] + e[i]) - acc)
                        if not group[i]:
                            gather[used] = f[i] * signs[i]
                            used += 1
                    G_fixed = pairwise_sum(gather, 0, used) + E
                    qc, ec, vc = q[stuck], e[stuck], v[stuck]
                    h0 = G_fixed - c * vc - m * (qc + ec)
                    nseg = push_segment(seg, nseg, t, V, qc, 0.0, 0.0, ec, 0.0)
                    s, r, releasing = stuck_first_root(v, q, e, tied, group, stuck, W, tol, h0,
                                                       c, m, mu, horizon)
                    step = horizon if r < 0 and releasing == 0.0 else s
                    V_new = vc + qc * step + ec * expm1_ratio(mu, step)
                if r >= 0 or releasing != 0.0:
                    off += step
                    t = a + off
                else:
                    off = off_next
                    t = t_next
                V = V_new
                hint = r if r >= 0 else -1
            rounds += 1
            code = budget_code(rounds, max_steps, ev, nev, window, rate_ev)
            done += 1
            if code == DONE and done >= chunk and (off < length or p + 1 < P):
                code = PAUSE
            if code != DONE:
                break
        if code != DONE:
            break
        t = b
        p += 1
        started = False
    fstate[F_T] = t
    fstate[F_V] = V
    fstate[F_OFF] = off
    fstate[F_REL] = releasing
    istate[I_PIECE] = p
    istate[I_STUCK] = stuck
    istate[I_HINT] = hint
    istate[I_STARTED] = 1 if started else 0
    istate[I_NSEG] = nseg
    istate[I_NEV] = nev
    istate[I_ROUNDS] = rounds
    istate[I_NEVAL] = n_eval
    return code


def advance_dynamic(f: np.ndarray, params: np.ndarray, try_quiet: bool, t0: float, t1: float,
                    V: float, stuck: int, hint: int, releasing: float, start: np.ndarray,
                    u: np.ndarray, E: float, motor: np.ndarray, fstate: np.ndarray,
                    istate: np.ndarray, seg: np.ndarray, ev: np.ndarray,
                    out: np.ndarray) -> tuple[int, bool, float]:
    """One step of :func:`toolkit.simulation.advance` with lagging or rate-limited motors:
    from body speed ``V`` (m/s; mode ``stuck``, ``hint``, ``releasing`` of
    :func:`dynamic_run`) and contact speeds ``start`` at ``t0`` to ``t1`` (s) under the
    command ``u`` (clipped, m/s) and external force ``E`` (N). ``params``: the plant's
    constants (``P_TOTAL`` .. ``P_MARGIN``).

    When ``try_quiet``, the no-event certificate first (:func:`quiet_piece`); else, or when it
    is unsure, :func:`dynamic_run` over the one piece. Returns ``(code, quiet, body)``: the
    engine's code (``PAUSE``: resume with :func:`dynamic_run`, then :func:`advance_outputs`),
    whether the certificate ran the step, and the body's displacement (m); ``out`` (2, n)
    receives the contact speeds at the end and their displacements (m); the end time and
    speed are ``fstate[F_T]``, ``fstate[F_V]``."""
    total, m, c, k = params[P_TOTAL], params[P_MASS], params[P_DAMPING], params[P_COMPLIANCE]
    tau, rate = params[P_TAU], params[P_RATE]
    if try_quiet:
        certified, V_end, body = quiet_piece(f, total, m, c, tau, params[P_RAMP_GAP],
                                             params[P_SPEED_BOUND], params[P_MARGIN], start,
                                             u, V, stuck, E, t1 - t0, out)
        if certified and V_end - V_end == 0.0:          # (finite)
            fstate[F_T] = t1
            fstate[F_V] = V_end
            return DONE, True, body
    n = f.size
    bounds = np.empty(2)
    bounds[0] = t0
    bounds[1] = t1
    externals = np.empty(1)
    externals[0] = E
    commands = u.reshape((1, n))
    for i in range(n):
        motor[M_START, i] = start[i]
    fstate[F_T] = t0
    fstate[F_V] = V
    fstate[F_OFF] = 0.0
    fstate[F_REL] = releasing
    istate[I_PIECE] = 0
    istate[I_STARTED] = 0
    istate[I_STUCK] = stuck
    istate[I_HINT] = hint
    code = dynamic_run(f, total, m, c, k, tau, rate, bounds, commands, externals, motor,
                       fstate, istate, seg, ev)
    body = 0.0
    if code != PAUSE:
        body = advance_outputs(motor, tau, t0, fstate, istate, seg, out)
    return code, False, body


def advance_outputs(motor: np.ndarray, tau: float, t0: float, fstate: np.ndarray,
                    istate: np.ndarray, seg: np.ndarray, out: np.ndarray) -> float:
    """The outputs of a finished (or stopped) :func:`advance_dynamic` step from ``t0`` (s):
    ``out[0]`` the contact speeds at ``fstate[F_T]``, ``out[1]`` their displacements (m);
    returns the body's displacement (m, :func:`displacement` of the segments)."""
    span = fstate[F_T] - t0
    for i in range(out.shape[1]):
        out[0, i] = motor_speed(motor, tau, i, span)
    motor_displacement(motor, tau, span, out[1])
    mu = 1.0 / tau if tau > 0 else 0.0
    return displacement(seg, istate[I_NSEG], mu, fstate[F_T])


# -- sampled loops: the exact plant under a law held over each sample period -------------------
# A law the kernels evaluate (toolkit.simulation.SampledLaw): a piecewise-constant table of
# commands (rows ``law_rows[j]`` on ``[law_times[j-1], law_times[j])``) and forces, optionally
# shifted by a PI law on the speed error and clipped (``law_i[L_SHIFT]``), optionally after a
# carry phase (``law_i[L_CARRY]``: the row ``carry`` until ``law_f[L_SWITCH]``, the inner
# law's clock starting at ``law_f[L_START]``). Estimates: the true speed (EST_TRUTH) or given
# by the caller per sample (EST_GIVEN); commands: the law's (LAW_TABLE) or given (LAW_GIVEN).
L_CARRY, L_SHIFT = 0, 1
L_SWITCH, L_START, L_REFERENCE, L_KP, L_KI, L_PERIOD, L_LOW, L_HIGH = range(8)
EST_TRUTH, EST_GIVEN = 0, 1
LAW_TABLE, LAW_GIVEN = 0, 1
# The loop's state between calls (floats: time, speed, body position, releasing; ints: the
# contact the body follows, the hint of the engine's last event).
S_T, S_V, S_X, S_REL = 0, 1, 2, 3
S_STUCK, S_HINT = 0, 1


def sensor_read(X: float, x: np.ndarray, motor: np.ndarray, half: float, qc: float,
                qw: float, wheel: np.ndarray) -> int:
    """The sensor law of :mod:`toolkit.model.sensors` at one read instant, noiseless (its one
    compiled form: :class:`~toolkit.model.sensors.SensorReader` without missed counts, noise
    or jitter; tested against it): the play operator of width ``2 half`` (m) moves the
    motor-side positions ``motor`` (n,) towards the contact positions ``x`` (m), then every
    position is quantized, ``floor(position / q)``. Returns the central count (body position
    ``X``, m, counts of ``qc`` m) and writes the wheel counts (counts of ``qw`` m) to
    ``wheel``."""
    for i in range(x.size):
        motor[i] = min(max(motor[i], x[i] - half), x[i] + half)
        wheel[i] = math.floor(motor[i] / qw)
    return math.floor(X / qc)


def law_output(law_i: np.ndarray, law_f: np.ndarray, carry: np.ndarray,
               law_times: np.ndarray, law_rows: np.ndarray, law_forces: np.ndarray,
               z: np.ndarray, t: float, estimate: float, out: np.ndarray) -> float:
    """The law's commands (m/s, into ``out`` (n,)) and outside force (N, returned) at sample
    time ``t`` (s) from the speed estimate (m/s), and its state ``z`` (1,) moved to the next
    sample (the PI law's integral of the speed error, m). The controllers' own arithmetic
    (:mod:`toolkit.controllers`: ``output`` then ``update``), in the same operations."""
    n = out.size
    if law_i[L_CARRY] != 0 and t < law_f[L_SWITCH]:
        for i in range(n):
            out[i] = carry[i]
        return 0.0
    inner = t
    if law_i[L_CARRY] != 0:              # the inner clock, snapped to the sample grid
        period = law_f[L_PERIOD]
        inner = t - law_f[L_START]
        grid = round(inner / period) * period
        if abs(inner - grid) <= 1e-9 * period:
            inner = grid
    K = law_times.size
    j = 0                                # the row of the table at the inner time
    while j < K and law_times[j] <= inner:
        j += 1
    if law_i[L_SHIFT] != 0:
        reference = law_f[L_REFERENCE]
        error = reference - estimate
        centre = reference + law_f[L_KP] * error + law_f[L_KI] * z[0]
        low, high = law_f[L_LOW], law_f[L_HIGH]
        for i in range(n):
            out[i] = min(max(law_rows[j, i] + centre, low), high)
        z[0] = z[0] + (reference - estimate) * law_f[L_PERIOD]
    else:
        for i in range(n):
            out[i] = law_rows[j, i]
    return law_forces[j]


def sampled_steps(k0: int, k1: int, times: np.ndarray, f: np.ndarray, params: np.ndarray,
                  dynamic: bool, try_quiet: bool, low: float, high: float,
                  budget_i: np.ndarray, rate_ev: float, est_kind: int, law_kind: int,
                  law_i: np.ndarray, law_f: np.ndarray, carry: np.ndarray,
                  law_times: np.ndarray, law_rows: np.ndarray, law_forces: np.ndarray,
                  z: np.ndarray, sensors: bool, sens_f: np.ndarray, play: np.ndarray,
                  state_f: np.ndarray, state_i: np.ndarray, speeds: np.ndarray,
                  x: np.ndarray, speed: np.ndarray, position: np.ndarray,
                  estimate: np.ndarray, variance: np.ndarray, commands: np.ndarray,
                  force: np.ndarray, contact: np.ndarray, central: np.ndarray,
                  wheel: np.ndarray) -> tuple[int, int]:
    """Samples ``k0 .. k1 - 1`` of a sampled loop (``times`` (S,), s): at each, the estimate
    (the true speed, or the caller's), the law's commands and force (or the caller's), the
    plant over the period (:func:`advance_dynamic` with lagging motors, :func:`ideal_piece`
    on the staircase of the commands otherwise: the engines of ``advance``, the same
    numbers), the exact displacements, and the next sample's record (speed, position,
    contact speeds, and with ``sensors`` the counts of :func:`sensor_read`). The plant:
    magnitudes ``f``, constants ``params`` (``P_TOTAL`` ..), command limits ``low``,
    ``high``; ``budget_i``: ``[max rounds, Zeno window]`` per step, ``rate_ev`` the event
    rate. ``sens_f``: ``[qc, qw, half]``. ``state_f``, ``state_i``, ``speeds``, ``x`` and
    ``play`` carry the plant's and the sensors' state between calls. Returns
    ``(code, k)``: ``DONE`` and the next sample to run, or the code of a step the budget
    stopped (``MAX_STEPS``, ``ZENO``; ``FAILED_STEP`` for a speed that left the
    floating-point range) and the number of samples recorded (the failed step's start is
    the last)."""
    n = f.size
    S = times.size
    tau = params[P_TAU]
    mu = 1.0 / tau if tau > 0 else 0.0
    m, c = params[P_MASS], params[P_DAMPING]
    seg = np.empty((64, 7))
    ev = np.empty((64, 4))
    fstate = np.zeros(N_FSTATE)
    istate = np.zeros(N_ISTATE, dtype=np.int64)
    motor = np.empty((5, n))
    out = np.empty((2, n))
    u = np.empty(n)
    bounds = np.empty(2)
    externals = np.empty(1)
    scratch = np.empty((3, n + 1))            # the staircase of ideal motors' commands
    first = np.empty(n, dtype=np.int64)
    order = np.empty(n, dtype=np.int64)
    rows2 = np.empty((1, n))
    forces2 = f.reshape((1, n))
    K = -1
    qc, qw, half = sens_f[0], sens_f[1], sens_f[2]
    for k in range(k0, k1):
        if est_kind == EST_TRUTH:
            estimate[k] = speed[k]
            variance[k] = 0.0
        if law_kind == LAW_TABLE:
            force[k] = law_output(law_i, law_f, carry, law_times, law_rows, law_forces, z,
                                  times[k], estimate[k], commands[k])
        if k + 1 == S:
            return DONE, k + 1
        t0, t1 = times[k], times[k + 1]
        V = state_f[S_V]
        E = force[k]
        for i in range(n):
            u[i] = min(max(commands[k, i], low), high)
        # One step of the plant, with fresh budget counters (advance's _Recorder).
        for j in range(N_FSTATE):
            fstate[j] = 0.0
        for j in range(N_ISTATE):
            istate[j] = 0
        istate[I_STUCK] = -1
        istate[I_HINT] = -1
        istate[I_MAXSTEPS] = budget_i[0]
        istate[I_WINDOW] = budget_i[1]
        istate[I_CHUNK] = 1 << 14
        fstate[F_RATE] = rate_ev
        if dynamic:
            code, quiet, body = advance_dynamic(
                f, params, try_quiet and state_i[S_HINT] < 0 and state_f[S_REL] == 0.0,
                t0, t1, V, state_i[S_STUCK], state_i[S_HINT], state_f[S_REL], speeds, u, E,
                motor, fstate, istate, seg, ev, out)
            if quiet:
                V = fstate[F_V]
                state_f[S_REL] = 0.0
                state_i[S_HINT] = -1
            else:
                while code == PAUSE:             # buffers full or a chunk of rounds: grow
                    if min(seg.shape[0] - istate[I_NSEG], ev.shape[0] - istate[I_NEV]) < 16:
                        seg = grown(seg)
                        ev = grown(ev)
                    bounds[0] = t0
                    bounds[1] = t1
                    externals[0] = E
                    code = dynamic_run(f, params[P_TOTAL], m, c, params[P_COMPLIANCE], tau,
                                       params[P_RATE], bounds, u.reshape((1, n)), externals,
                                       motor, fstate, istate, seg, ev)
                    if code != PAUSE:
                        body = advance_outputs(motor, tau, t0, fstate, istate, seg, out)
                if code != DONE:
                    return code, k + 1
                V = fstate[F_V]
                state_i[S_STUCK] = istate[I_STUCK]
                state_i[S_HINT] = istate[I_HINT]
                state_f[S_REL] = fstate[F_REL]
            for i in range(n):
                speeds[i] = out[0, i]
                x[i] = x[i] + out[1, i]
        else:
            same = K >= 0
            for i in range(n):
                same = same and rows2[0, i] == u[i]
            if not same:                         # the staircase of the new commands
                for i in range(n):
                    rows2[0, i] = u[i]
                K = sorted_landscape(rows2, forces2, 0, order, scratch, first)
            fstate[F_T] = t0
            fstate[F_V] = V
            istate[I_STUCK] = state_i[S_STUCK]
            code = ideal_piece(True, K, scratch, first, u, f, scratch[1, K], m, c, E, t1,
                               fstate, istate, seg, ev)
            while code == PAUSE:
                if min(seg.shape[0] - istate[I_NSEG], ev.shape[0] - istate[I_NEV]) < 16:
                    seg = grown(seg)
                    ev = grown(ev)
                code = ideal_piece(True, K, scratch, first, u, f, scratch[1, K], m, c, E, t1,
                                   fstate, istate, seg, ev)
            if code != DONE:
                return code, k + 1
            V = fstate[F_V]
            state_i[S_STUCK] = istate[I_STUCK]
            body = displacement(seg, istate[I_NSEG], 0.0, t1)
            span = t1 - t0
            for i in range(n):
                speeds[i] = u[i]
                x[i] = x[i] + u[i] * span
        if not (V - V == 0.0):
            return FAILED_STEP, k + 1
        state_f[S_T] = t1
        state_f[S_V] = V
        state_f[S_X] = state_f[S_X] + body
        speed[k + 1] = V
        position[k + 1] = state_f[S_X]
        for i in range(n):
            contact[k + 1, i] = speeds[i]
        if sensors:
            central[k + 1] = sensor_read(state_f[S_X], x, play, half, qc, qw, wheel[k + 1])
    return DONE, k1


def grown(buffer: np.ndarray) -> np.ndarray:
    """A copy of ``buffer`` with twice its rows plus 16."""
    rows, width = buffer.shape
    bigger = np.empty((2 * rows + 16, width))
    bigger[:rows] = buffer
    return bigger


def sampled_batch(samples: np.ndarray, times: np.ndarray, f: np.ndarray, params: np.ndarray,
                  dynamic: bool, try_quiet: bool, low: float, high: float,
                  budget_i: np.ndarray, rate_ev: float, law_i: np.ndarray, law_f: np.ndarray,
                  carry: np.ndarray, law_times: np.ndarray, law_rows: np.ndarray,
                  law_forces: np.ndarray, v0: np.ndarray, start_speeds: np.ndarray,
                  speed: np.ndarray, commands: np.ndarray, force: np.ndarray,
                  contact: np.ndarray, codes: np.ndarray, reached: np.ndarray) -> None:
    """Many sampled loops of one plant on the true speed (no sensors, no estimator), each
    through :func:`sampled_steps` from rest of its motors at ``start_speeds[r]`` and body
    speed ``v0[r]`` over ``samples[r]`` samples of ``times``, with its own law (row ``r`` of
    ``law_i`` .. ``law_forces``), in parallel over runs (``prange``). Per run: the speeds
    (rows of ``speed``, ``contact``), commands and forces, the code and the samples
    recorded."""
    R = samples.size
    n = f.size
    for r in prange(R):
        S = samples[r]
        state_f = np.zeros(4)
        state_i = np.full(2, -1, dtype=np.int64)
        state_f[S_V] = v0[r]
        speeds = start_speeds[r].copy()
        x = np.zeros(n)
        z = np.zeros(1)
        play = np.zeros(n)
        estimate = np.empty(S)
        variance = np.empty(S)
        position = np.empty(S)
        central = np.empty(0, dtype=np.int64)
        wheel = np.empty((0, n), dtype=np.int64)
        speed[r, 0] = v0[r]
        position[0] = 0.0
        for i in range(n):
            contact[r, 0, i] = speeds[i]
        codes[r], reached[r] = sampled_steps(
            0, S, times[:S], f, params, dynamic, try_quiet, low, high, budget_i, rate_ev,
            EST_TRUTH, LAW_TABLE, law_i[r], law_f[r], carry[r], law_times[r], law_rows[r],
            law_forces[r], z, False, np.zeros(3), play, state_f, state_i, speeds, x,
            speed[r], position, estimate, variance, commands[r], force[r], contact[r],
            central, wheel)


# -- counter-based random numbers: Philox4x64-10 ------------------------------------------------
# Salmon et al., "Parallel random numbers: as easy as 1, 2, 3" (SC 2011), the generator of
# numpy.random.Philox: block ``b`` of run ``i``'s stream ``s`` under key ``(k0, k1)`` is the
# Philox of the counter ``(b + 1, 0, i, s)`` (NumPy's Philox(counter=(0, 0, i, s), key=(k0, k1))
# increments its counter before each block: the same four words; tested against it). A draw
# depends on (key, run, stream, position) only: not on how runs are grouped.
PHILOX_M0 = np.uint64(0xD2E7470EE14C6C93)
PHILOX_M1 = np.uint64(0xCA5A826395121157)
PHILOX_W0 = np.uint64(0x9E3779B97F4A7C15)
PHILOX_W1 = np.uint64(0xBB67AE8584CAA73B)
LOW32 = np.uint64(0xFFFFFFFF)
SHIFT32 = np.uint64(32)
SHIFT11 = np.uint64(11)
DOUBLE_UNIT = 1.0 / 9007199254740992.0          # 2^-53


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


# -- many constant-speed scenes ----------------------------------------------------------------
def sorted_landscape(speeds: np.ndarray, forces: np.ndarray, s: int, order: np.ndarray,
                     land: np.ndarray, first: np.ndarray) -> int:
    """The staircase of scene ``s`` (row ``s`` of ``speeds``, ``forces``) into the rows
    ``xs``, ``below``, ``above`` of ``land`` as :class:`ContactSet` builds them (the distinct
    speeds of the touching contacts ascending, the magnitude at each summed in index order,
    prefix sums from below and from above), and ``first``: the lowest contact index at each
    level; ``order`` (n,) is scratch. Returns ``K``."""
    K = sorted_steps(speeds, forces, s, order, land, first)
    staircase_sums(land, K)
    return K


def contact_table(speeds: np.ndarray, forces: np.ndarray, order: np.ndarray, land: np.ndarray,
                  first: np.ndarray) -> tuple[int, float]:
    """:class:`ContactSet`'s staircase of one set (``speeds``, ``forces`` of shape (1, n)) into
    ``land`` (3, n + 1) as :func:`sorted_landscape`, and the sum of its steps as NumPy sums
    them (:func:`pairwise_sum`: the set's ``F_tot``). Returns ``(K, F_tot)``; ``(-1, 0)``
    where touching contacts sit at both ``0.0`` and ``-0.0`` (equal speeds whose level NumPy's
    sort may take from either: the caller's NumPy way decides)."""
    zeros = 0
    for i in range(speeds.shape[1]):
        if forces[0, i] > 0 and speeds[0, i] == 0.0:
            zeros |= 2 if math.copysign(1.0, speeds[0, i]) < 0 else 1
    if zeros == 3:
        return -1, 0.0
    K = sorted_steps(speeds, forces, 0, order, land, first)
    total = pairwise_sum(land[2], 0, K)
    staircase_sums(land, K)
    return K, total


def sorted_steps(speeds: np.ndarray, forces: np.ndarray, s: int, order: np.ndarray,
                 land: np.ndarray, first: np.ndarray) -> int:
    """:func:`sorted_landscape`'s levels into ``land[0]`` and the magnitude at each (its
    steps, summed in index order) into ``land[2]``, ``first`` as there. Returns ``K``."""
    xs, above = land[0], land[2]
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
    return K


def staircase_sums(land: np.ndarray, K: int) -> None:
    """The prefix sums of the steps ``land[2, :K]`` (:func:`sorted_steps`) from below into
    ``land[1, :K + 1]`` and from above into ``land[2, :K + 1]`` (``np.cumsum``'s order)."""
    below, above = land[1], land[2]
    below[0] = 0.0
    for k in range(K):                     # np.cumsum of the steps
        below[k + 1] = below[k] + above[k]
    acc = 0.0
    above[K] = 0.0
    for k in range(K - 1, -1, -1):         # np.cumsum of the reversed steps
        acc += above[k]
        above[k] = acc


def staircase_median(levels: np.ndarray, below: np.ndarray, above: np.ndarray, K: int,
                     tol: float) -> tuple[float, float]:
    """The weighted median ``(lo, hi)`` (m/s) of a staircase as :class:`ContactSet` holds it
    (``K >= 1`` distinct ``levels`` ascending, prefix sums ``below`` from below and ``above``
    from above): the set ``{V : 0 in F(V)}``. A plateau ``above[k] - below[k]`` within
    ``tol`` (:attr:`ContactSet.tie_tolerance`) is a zero-force band ``[levels[k-1],
    levels[k]]``; otherwise the force jumps over zero at one level ``(v, v)``. The one
    weighted median of the toolkit (docs/physics.md section 3)."""
    for k in range(1, K):
        if abs(above[k] - below[k]) <= tol:
            return levels[k - 1], levels[k]
    for k in range(K):
        if above[k + 1] - below[k + 1] < -tol:
            return levels[k], levels[k]
    return levels[K - 1], levels[K - 1]             # (not reached: plateau K is -F_tot)


def median_row(speeds: np.ndarray, forces: np.ndarray, F: float, row_s: np.ndarray,
               row_f: np.ndarray, order: np.ndarray, first: np.ndarray,
               land: np.ndarray) -> tuple[float, float]:
    """The weighted median ``(lo, hi)`` of one set of ``speeds`` (n,) (m/s) with magnitudes
    ``forces`` (n,) (N) and an outside force ``F`` (N) as a contact of magnitude ``|F|`` at
    ``sign(F) inf`` (a zero force changes nothing): the staircase built as
    :class:`ContactSet` builds it (:func:`sorted_landscape`) and read by
    :func:`staircase_median` with the tie tolerance ``4 (K + 1) eps F_tot``. Without any
    positive magnitude, the slowest speed twice. ``row_s``, ``row_f`` (1, n + 1), ``order``,
    ``first`` (n + 1,) and ``land`` (3, n + 2) are scratch."""
    n = speeds.shape[0]
    slowest = INF
    for i in range(n):
        row_s[0, i] = speeds[i]
        row_f[0, i] = forces[i]
        if speeds[i] < slowest:
            slowest = speeds[i]
    row_s[0, n] = INF if F >= 0.0 else -INF
    row_f[0, n] = abs(F)
    K = sorted_landscape(row_s, row_f, 0, order, land, first)
    if K == 0:
        return slowest, slowest
    return staircase_median(land[0], land[1], land[2], K, tie_tolerance(K, land[1, K]))


def median_edges(speeds: np.ndarray, forces: np.ndarray, outside: np.ndarray,
                 out: np.ndarray) -> None:
    """``out[r] = (lo, hi)``: :func:`median_row` of each row of ``speeds`` (R, n) (m/s) with
    magnitudes ``forces`` (n,) (N) and the outside force ``outside[r]`` (N); ``+-inf`` edges
    when ``|F|`` exceeds the contacts' total."""
    n = speeds.shape[1]
    row_s = np.empty((1, n + 1))
    row_f = np.empty((1, n + 1))
    order = np.empty(n + 1, dtype=np.int64)
    first = np.empty(n + 1, dtype=np.int64)
    land = np.empty((3, n + 2))
    for r in range(speeds.shape[0]):
        lo, hi = median_row(speeds[r], forces, outside[r], row_s, row_f, order, first, land)
        out[r, 0] = lo
        out[r, 1] = hi


def period_bounds(start: np.ndarray, end: np.ndarray, forces: np.ndarray, F: float,
                  out: np.ndarray) -> None:
    """What decides an estimator's input over one period, into ``out`` (6,), m/s: the
    slowest and fastest contact speed over it (the motor law is monotone in time: at its
    ``start`` or ``end``, (n,) each), the weighted median ``(lo, hi)`` of the ``end`` speeds
    and that of the ``start`` speeds (the same numbers when they are equal), with the
    outside force ``F`` (N) as in :func:`median_row`."""
    n = start.shape[0]
    low = INF
    high = -INF
    held = True
    for i in range(n):
        a = start[i]
        b = end[i]
        if a != b:
            held = False
        low = min(low, min(a, b))
        high = max(high, max(a, b))
    row_s = np.empty((1, n + 1))
    row_f = np.empty((1, n + 1))
    order = np.empty(n + 1, dtype=np.int64)
    first = np.empty(n + 1, dtype=np.int64)
    land = np.empty((3, n + 2))
    lo, hi = median_row(end, forces, F, row_s, row_f, order, first, land)
    out[0] = low
    out[1] = high
    out[2] = lo
    out[3] = hi
    if not held:
        lo, hi = median_row(start, forces, F, row_s, row_f, order, first, land)
    out[4] = lo
    out[5] = hi


def window_line(times: np.ndarray, counts: np.ndarray, a: int, b: int, q: float,
                speeds: np.ndarray) -> tuple[float, float]:
    """The least-squares slope of each wheel's readings ``a..b`` (rows of ``times`` (T,), s,
    and ``counts`` (T, n)), times ``q`` (m per count), into ``speeds`` (n,), m/s; returns
    ``S = sum (t - mean t)^2`` (s^2) and the largest ``|speed|`` (m/s). Times and counts relative to the window's first reading
    (no cancellation of large stamps or counts however long the run)."""
    m = b - a + 1
    t0 = times[a]
    total = 0.0
    for k in range(a, b + 1):
        total += times[k] - t0
    mean = total / m
    S = 0.0
    for k in range(a, b + 1):
        d = (times[k] - t0) - mean
        S += d * d
    n = counts.shape[1]
    scale = q / S
    peak = 0.0
    for i in range(n):
        c0 = counts[a, i]
        acc = 0.0
        for k in range(a, b + 1):
            acc += ((times[k] - t0) - mean) * (counts[k, i] - c0)
        speeds[i] = acc * scale
        peak = max(peak, abs(speeds[i]))
    return S, peak


def kalman_step(x: np.ndarray, P: np.ndarray, F: np.ndarray, Q: np.ndarray, R: float, z: float,
                x_out: np.ndarray, P_out: np.ndarray, prior: np.ndarray) -> float:
    """One predict and update of a two-state Kalman filter with a scalar reading of the
    first state (``H = [1, 0]``), filterpy's ``KalmanFilter.predict()`` then ``update(z)``
    with the same formulas (the Joseph form of the covariance update): ``x`` (2, 1), ``P``,
    ``F``, ``Q`` (2, 2), ``R`` (m^2) and the reading ``z`` (m) in; the posterior into
    ``x_out`` (2, 1) and ``P_out`` (2, 2), the prior ``(x0, x1, P00)`` into ``prior`` (3,).
    Returns the NIS ``y^2 / S``. The matrix products summed in index order (filterpy's BLAS
    may fuse or reorder them: equal to rounding)."""
    # Predict: x = F x, P = F P F^T + Q.
    a0 = F[0, 0] * x[0, 0] + F[0, 1] * x[1, 0]
    a1 = F[1, 0] * x[0, 0] + F[1, 1] * x[1, 0]
    FP00 = F[0, 0] * P[0, 0] + F[0, 1] * P[1, 0]
    FP01 = F[0, 0] * P[0, 1] + F[0, 1] * P[1, 1]
    FP10 = F[1, 0] * P[0, 0] + F[1, 1] * P[1, 0]
    FP11 = F[1, 0] * P[0, 1] + F[1, 1] * P[1, 1]
    p00 = (FP00 * F[0, 0] + FP01 * F[0, 1]) + Q[0, 0]
    p01 = (FP00 * F[1, 0] + FP01 * F[1, 1]) + Q[0, 1]
    p10 = (FP10 * F[0, 0] + FP11 * F[0, 1]) + Q[1, 0]
    p11 = (FP10 * F[1, 0] + FP11 * F[1, 1]) + Q[1, 1]
    prior[0] = a0
    prior[1] = a1
    prior[2] = p00
    # Update with H = [1, 0]: y = z - x0, S = P00 + R, K = P H^T / S.
    y = z - a0
    S = p00 + R
    SI = 1.0 / S
    k0 = p00 * SI
    k1 = p10 * SI
    x_out[0, 0] = a0 + k0 * y
    x_out[1, 0] = a1 + k1 * y
    # Joseph form: (I - K H) P (I - K H)^T + K R K^T, with I - K H = [[1 - k0, 0], [-k1, 1]].
    i00 = 1.0 - k0
    i10 = -k1
    A00 = i00 * p00
    A01 = i00 * p01
    A10 = i10 * p00 + p10
    A11 = i10 * p01 + p11
    P_out[0, 0] = A00 * i00 + (k0 * R) * k0
    P_out[0, 1] = (A00 * i10 + A01) + (k0 * R) * k1
    P_out[1, 0] = A10 * i00 + (k1 * R) * k0
    P_out[1, 1] = (A10 * i10 + A11) + (k1 * R) * k1
    return y * y * SI


def batch_scene(speeds: np.ndarray, forces: np.ndarray, s: int, m: float, c: float, E: float,
                v0: float, t_end: float, probe: float, order: np.ndarray, land: np.ndarray,
                first: np.ndarray, fstate: np.ndarray, istate: np.ndarray,
                seg: np.ndarray, ev: np.ndarray) -> tuple[float, int, bool, int, float]:
    """Scene ``s`` of :func:`batch` through :func:`ideal_piece` (scratch arrays given):
    ``(final speed, events, stuck at the end, code, speed at probe)``; the speed at ``probe``
    (s, in ``[0, t_end]``; NaN when ``probe`` is negative) is the run's own closed form there
    (its segments stay in ``seg``: no second run)."""
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
    at_probe = math.nan
    if probe >= 0.0 and code == DONE:
        nseg = istate[I_NSEG]
        k = nseg - 1
        while k > 0 and seg[k, 0] > probe:     # the segment that holds the probe time
            k -= 1
        at_probe = segment_value(seg[k, 1], seg[k, 2], seg[k, 3], seg[k, 4], seg[k, 5],
                                 seg[k, 6], 0.0, probe - seg[k, 0])[0]
    return fstate[F_V], istate[I_NEV], istate[I_STUCK] >= 0, code, at_probe


def batch(speeds: np.ndarray, forces: np.ndarray, mass: np.ndarray, damping: np.ndarray,
          external: np.ndarray, v0: np.ndarray, t_end: float, probe: float, V: np.ndarray,
          events: np.ndarray, stuck: np.ndarray, codes: np.ndarray,
          V_probe: np.ndarray) -> None:
    """Every scene ``s`` (rows of ``speeds``, ``forces``; entries of the per-scene arrays)
    through :func:`batch_scene`, in parallel over blocks of scenes, each block with its own
    scratch arrays; ``V_probe`` receives each speed at ``probe`` (NaN when negative)."""
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
            V[s], events[s], stuck[s], codes[s], V_probe[s] = batch_scene(
                speeds, forces, s, mass[s], damping[s], external[s], v0[s], t_end, probe,
                order, land, first, fstate, istate, seg, ev)


def gathered_sum(values: np.ndarray, mask: np.ndarray, scratch: np.ndarray) -> tuple[float, int]:
    """``values[mask].sum()`` as NumPy sums the gathered array (:func:`pairwise_sum`), and the
    number of terms."""
    k = 0
    for i in range(values.size):
        if mask[i]:
            scratch[k] = values[i]
            k += 1
    return pairwise_sum(scratch, 0, k), k


def linearize_step(ev: np.ndarray, nev: int, V: float, start: np.ndarray, target: np.ndarray,
                   lagging: bool, tau: float, f: np.ndarray, m: float, c: float, h: float, E: float,
                   var_v: float, noise: np.ndarray, motor: np.ndarray, work: np.ndarray,
                   masks: np.ndarray, order: np.ndarray, average: np.ndarray, out: np.ndarray) -> None:
    """The linearization of one exact step of held or lagging contacts (the estimators' known
    input: ``EstimatorModel._linearized`` and ``force_gains`` state the rules), from its events
    ``ev[:nev]`` (rows ``(t, kind, contact, V)``): into ``out`` ``(dX+/dV, dV+/dV, Q_xx, Q_xv,
    Q_vv, arrival (NaN: none), dX+/dF, dV+/dF)`` with ``Q`` accumulated on ``noise`` (3,) and
    the contacts' gains summed in the order they first take part; into ``average`` (n,) each
    contact's sign relative to the body averaged over the period. Scratch: ``motor`` (5, n),
    ``work`` (7, n), ``masks`` (3, n) bool, ``order`` (n,) int. Sums are NumPy's
    (:func:`pairwise_sum`); speeds along the motor law are :func:`motor_coefficients`'."""
    n = f.size
    speeds, rates, gx, gv, tmp, q_ramp, sgn = work[0], work[1], work[2], work[3], work[4], work[5], work[6]
    at, group, flip = masks[0], masks[1], masks[2]
    k = c / m
    if lagging:
        motor_build(start, target, tau, INF, motor)
    for i in range(n):
        gx[i] = 0.0
        gv[i] = 0.0
        group[i] = False
        sgn[i] = sign(start[i] - V)
        tmp[i] = f[i] * sgn[i]
        average[i] = 0.0
    touched = 0                              # contacts with a gain, in the order they got one
    F_seg = pairwise_sum(tmp, 0, n) + E
    J, JX, sX, sV = 1.0, 0.0, 0.0, 0.0
    arrival = math.nan
    stuck = False
    stick_at = 0.0
    t_prev = 0.0
    t_sign = 0.0
    for r in range(nev + 1):
        s = ev[r, 0] if r < nev else h
        dt = s - t_prev
        # A stretch without events: the drag decays J, the gains and the force response by
        # exp(-k t) (not while stuck: the body then moves with the contact).
        if k == 0.0 or stuck:
            area, decay = dt, 1.0
        else:
            area, decay = expm1_ratio(k, dt), math.exp(-k * dt)
        JX += J * area
        J *= decay
        for j in range(touched):
            i = order[j]
            gx[i] += gv[i] * area
            gv[i] *= decay
        if not stuck:
            sX += sV * area + expm1_ratio_integral(k, dt) / m
            sV = sV * decay + area / m
        t_prev = s
        if r == nev:
            break
        kind = int(ev[r, 1])
        contact = int(ev[r, 2])
        Ve = ev[r, 3]
        if lagging:
            motor_coefficients(motor, tau, s, speeds, q_ramp, rates)
        else:
            for i in range(n):
                speeds[i] = target[i]
                rates[i] = 0.0
        tol = 1e-12 * max(1.0, abs(Ve))
        for i in range(n):
            at[i] = abs(speeds[i] - Ve) <= tol
        if contact >= 0:
            at[contact] = True
        if kind == CROSS:
            # The force response's signs flip at every crossing (force_gains).
            wide = 1e-9 * max(1.0, abs(Ve))
            for i in range(n):
                average[i] += sgn[i] * (s - t_sign)
                flip[i] = abs(speeds[i] - Ve) <= wide
            if contact >= 0:
                flip[contact] = True
            for i in range(n):
                if flip[i]:
                    sgn[i] = -sgn[i]
            t_sign = s
            if stuck:
                continue                     # the stiction force absorbs it until a release
            for i in range(n):
                at[i] = at[i] and not group[i]
            f_at, _ = gathered_sum(f, at, tmp)
            total_rate, count = gathered_sum(rates, at, tmp)
            slope = total_rate / count if count > 0 else math.nan
            a_before = (F_seg - c * Ve) / m
            side = 1.0 if a_before - slope > 0.0 else -1.0
            if s == 0.0:
                # Contacts the body starts on (no force in the start's sum: sign 0) it leaves
                # at once: before the crossing they push as from behind the body (the
                # one-sided limit, + f side), after it they are behind it.
                f_on = 0.0
                for i in range(n):
                    if at[i] and start[i] - V == 0.0:
                        f_on += f[i]
                        sgn[i] = -side
                if f_on > 0.0:
                    F_seg += f_on * side
                    a_before = (F_seg - c * Ve) / m
            F_seg -= 2.0 * f_at * side
            a_after = (F_seg - c * Ve) / m
            factor = (a_after - slope) / (a_before - slope)
            J *= factor
            sV *= factor
            for j in range(touched):
                gv[order[j]] *= factor
            # The crossed contacts' common error, split by force (a group at one speed).
            share = (1.0 - factor) * (lag_decay(s, tau, math.exp) if lagging else 1.0)
            for i in range(n):
                if at[i]:
                    if not contains(order, touched, i):
                        order[touched] = i
                        touched += 1
                    if count == 1:
                        gv[i] += share
                    else:
                        gv[i] += share * (f[i] / f_at if f_at > 0 else 1.0 / count)
        elif kind == STICK:
            # From here V is the contact's speed: it errs as the contact's estimate does.
            J = 0.0
            sV = 0.0
            for j in range(touched):
                gv[order[j]] = 0.0
            jj = contact
            if jj < 0:
                jj = 0
                for i in range(n):
                    if at[i]:
                        jj = i
                        break
            # The body follows the contact(s) at its speed that move with the stuck-on one.
            rj = rates[jj]
            wide = 1e-9 * max(1.0, abs(rj))
            for i in range(n):
                group[i] = at[i] and abs(rates[i] - rj) <= wide
            arrival, stuck, stick_at = var_v, True, s
        elif kind == RELEASE:
            arrival, stuck = math.nan, False
            touched = stuck_stretch(f, group, tmp, order, touched, gx, gv, stick_at, s, lagging, tau)
            f_group, _ = gathered_sum(f, group, tmp)
            # The force just after: the contact law off the group; the group pulls ahead when
            # the body, pulled by it, still lags its acceleration, else behind; other contacts
            # at this speed count from the side they arrive from.
            total_rate, count = gathered_sum(rates, group, tmp)
            slope = total_rate / count if count > 0 else math.nan
            for i in range(n):
                tmp[i] = 0.0 if at[i] else f[i] * sign(speeds[i] - Ve)
            F_seg = pairwise_sum(tmp, 0, n) + E
            k2 = 0
            for i in range(n):
                if at[i] and not group[i]:
                    tmp[k2] = f[i] * (1.0 if slope - rates[i] > 0.0 else -1.0)
                    k2 += 1
            F_seg += pairwise_sum(tmp, 0, k2)
            F_seg += f_group if (F_seg + f_group - c * Ve) / m <= slope else -f_group
            for i in range(n):
                group[i] = False
    for i in range(n):
        average[i] = (average[i] + sgn[i] * (h - t_sign)) / h
    out[6], out[7] = sX, sV
    if stuck:
        touched = stuck_stretch(f, group, tmp, order, touched, gx, gv, stick_at, h, lagging, tau)
        w_end = lag_decay(h, tau, math.exp) if lagging else 1.0
        arrival = var_v * w_end ** 2
    q00, q01, q11 = noise[0], noise[1], noise[2]
    for j in range(touched):
        i = order[j]
        q00 += gx[i] * gx[i] * var_v
        q01 += gx[i] * gv[i] * var_v
        q11 += gv[i] * gv[i] * var_v
    out[0], out[1], out[2], out[3], out[4], out[5] = JX, J, q00, q01, q11, arrival


def stuck_stretch(f: np.ndarray, group: np.ndarray, scratch: np.ndarray, order: np.ndarray, touched: int,
                  gx: np.ndarray, gv: np.ndarray, t0: float, t1: float, lagging: bool, tau: float) -> int:
    """What a stretch stuck on the contacts ``group`` from ``t0`` to ``t1`` (s) leaves of their
    speed errors in ``X`` and ``V`` (:func:`linearize_step`): each member's share of the
    group's force times the error's integral and end value (``exp(-t / tau)`` along lagging
    motors, 1 held); ``scratch`` (n,) for the group's sum; returns the count of contacts in
    ``order``."""
    f_group, _ = gathered_sum(f, group, scratch)
    w1 = lag_decay(t1, tau, math.exp) if lagging else 1.0
    for i in range(f.size):
        if group[i]:
            if not contains(order, touched, i):
                order[touched] = i
                touched += 1
            share = f[i] / f_group
            if lagging:
                gx[i] += share * (tau * (lag_decay(t0, tau, math.exp) - w1))
            else:
                gx[i] += share * (t1 - t0)
            gv[i] += share * w1
    return touched


def contains(order: np.ndarray, count: int, i: int) -> bool:
    """Contact ``i`` is among the first ``count`` entries of ``order``."""
    for j in range(count):
        if order[j] == i:
            return True
    return False
