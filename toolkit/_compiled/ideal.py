"""Kernels of the exact engine with ideal motors (piecewise-constant contact speeds).

:func:`ideal_piece` runs the event loop of one piece (Coulomb staircase or compliant landscape,
drag, external force, stick and release, the budget and Zeno guards) into caller-owned
buffers, pausing when they are full; :func:`ideal_run` is one whole piece with its samples;
:func:`batch` runs many constant-speed scenes, each through :func:`ideal_piece`, in parallel.
"""

from __future__ import annotations

import math

import numpy as np

from ..laws import tie_tolerance
from .segments import (CROSS, DONE, F_RATE, F_T, F_TERR, F_TSUM, F_V, INF, I_AT, I_CHUNK, I_J,
                       I_MAXSTEPS, I_NEV, I_NEVAL, I_NSEG, I_ROUNDS, I_STARTED, I_STUCK, I_WINDOW,
                       N_FSTATE, N_ISTATE, PAUSE, RELEASE, SATURATION, STICK, budget_code,
                       dense_values, expm1_ratio, push_event, push_segment, reach_time,
                       segment_value)
from .tables import lowest_contact, net_force, sorted_landscape

#: Replaced by ``numba.prange`` when compiled (a parallel loop); ``range`` as Python.
prange = range

_IEEE = {"error_model": "numpy"}   # IEEE division: x / 0 is inf or NaN (as NumPy), never raises
#: The kernels of this module and their numba options (toolkit._compiled.load compiles them).
KERNELS = {"piece_start": {}, "at_breakpoint": {}, "ideal_piece": {}, "ideal_run": {},
           "batch_scene": {}, "batch": {"parallel": True}, "tie_tolerance": _IEEE}


def ideal_piece(coulomb: bool, K: int, land: np.ndarray, first: np.ndarray,
                speeds: np.ndarray, forces: np.ndarray, total: float, m: float, c: float,
                E: float, b: float, fstate: np.ndarray, istate: np.ndarray, seg: np.ndarray,
                ev: np.ndarray) -> int:
    """Integrate up to time ``b`` (s) with constant contact speeds from the state in ``fstate``
    / ``istate`` (``I_STARTED = 0``: a new piece from ``fstate[F_T]``) under external force
    ``E`` (N), mass ``m`` (kg) and drag ``c`` (N s/m): the engine of ``simulate`` and
    ``advance`` for ideal motors. ``K`` breakpoints in one table ``land``: Coulomb (``coulomb``)
    the distinct speeds and prefix sums ``below``, ``above`` (``ContactSet._table``) with the
    set's ``speeds``, ``forces`` and ``first`` (:func:`lowest_contact`); compliant the limits,
    ``base_F``, ``slope``, ``base_x`` and ``G_at`` (rows 0-4), ``first[k]`` the lowest contact.

    Returns ``DONE`` (reached ``b``), ``MAX_STEPS`` or ``ZENO`` (stopped at ``fstate[F_T]``),
    or ``PAUSE`` (``istate[I_CHUNK]`` rounds done, or the buffers may not hold another round).
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
    tol = tie_tolerance(K, total)                  # the prefix sums' rounding
    push_scale = total + abs(E)
    code = DONE
    if istate[I_STARTED] == 0:                     # a new piece: locate V
        istate[I_STARTED] = 1
        t_sum = t
        t_err = 0.0                                # compensated sum of the segment times
        j, at, stuck, nev = piece_start(coulomb, K, land, V, t, stuck, ev, nev)
    done = 0
    finished = False
    while True:
        if at:
            n_eval += 1
            finished, j, stuck, nev = at_breakpoint(coulomb, K, land, first, speeds, forces, tol,
                                                    push_scale, c, E, t, V, j, stuck, ev, nev)
            if finished:                            # stuck (or at rest at a balance)
                nseg = push_segment(seg, nseg, t, V, 0.0, 0.0, 0.0, 0.0, 0.0)
                break
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


def piece_start(coulomb: bool, K: int, land: np.ndarray, V: float, t: float, stuck: int,
                ev: np.ndarray, nev: int) -> tuple[int, bool, int, int]:
    """Where a new piece starts: the interval ``j`` of speed ``V`` (m/s) among the ``K``
    breakpoints ``land[0]`` (binary search), whether ``V`` is at breakpoint ``j``, and the
    contact still stuck (a stuck body released, at time ``t`` (s), where no stiction holds it);
    returns ``(j, at, stuck, nev)``."""
    lo, hi = 0, K
    while lo < hi:
        mid = (lo + hi) >> 1
        if land[0, mid] < V:
            lo = mid + 1
        else:
            hi = mid
    j = lo
    at = j < K and land[0, j] == V
    if stuck >= 0:
        holds = at and coulomb and land[1, j + 1] - land[1, j] > 0
        if not holds:
            nev = push_event(ev, nev, t, RELEASE, stuck, V)
            stuck = -1
    return j, at, stuck, nev


def at_breakpoint(coulomb: bool, K: int, land: np.ndarray, first: np.ndarray, speeds: np.ndarray,
                  forces: np.ndarray, tol: float, push_scale: float, c: float, E: float, t: float,
                  V: float, j: int, stuck: int, ev: np.ndarray, nev: int) -> tuple[bool, int, int, int]:
    """A body at breakpoint ``j`` at time ``t`` (s): it sticks (or rests at a balance) when the
    others' push ``G`` is within the stiction magnitude ``W`` there, else it leaves (a release,
    or a crossing) into the interval ``G`` points to. Returns ``(stays, j, stuck, nev)``."""
    if coulomb:                                    # (W, G) at breakpoint j
        W = land[1, j + 1] - land[1, j]
        lower = net_force(land[2, j], land[1, j], tol)
        upper = net_force(land[2, j + 1], land[1, j + 1], tol)
        G = 0.5 * (lower + upper)
        G = G if abs(G) > tol else 0.0
    else:
        W = 0.0
        G = land[4, j]
    G += E - c * V
    if abs(G) <= W + tie_tolerance(K, push_scale + c * abs(V)):
        contact = lowest_contact(land, speeds, forces, first, j) if coulomb else first[j]
        if W > 0 and stuck != contact:
            if stuck >= 0:
                nev = push_event(ev, nev, t, RELEASE, stuck, V)
            nev = push_event(ev, nev, t, STICK, contact, V)
            stuck = contact
        return True, j, stuck, nev
    if stuck >= 0:
        nev = push_event(ev, nev, t, RELEASE, stuck, V)
        stuck = -1
    else:
        contact = lowest_contact(land, speeds, forces, first, j) if coulomb else first[j]
        nev = push_event(ev, nev, t, CROSS if coulomb else SATURATION, contact, V)
    return False, j + 1 if G > 0 else j, stuck, nev


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
