"""Kernels of the exact engine with lagging or rate-limited motors.

:func:`dynamic_run` runs every piece of constant command: the motors' closed form, the contacts
tied with the body, the Filippov solution among them, compliant contacts, each segment's first
event, the budget and Zeno guards. :func:`quiet_piece` is the no-event certificate and
:func:`advance_dynamic` one sample period of a closed loop (certificate, else the engine).
"""

from __future__ import annotations

import math

import numpy as np

from ..laws import lag_response, lag_travel, tie_tolerance
from .segments import (COMMAND, CROSS, DONE, EPS, F_OFF, F_RATE, F_REL, F_T, F_V, INF, I_CHUNK,
                       I_HINT, I_MAXSTEPS, I_NEV, I_NEVAL, I_NSEG, I_PIECE, I_ROUNDS, I_STARTED,
                       I_STUCK, I_WINDOW, PAUSE, RELEASE, SATURATION, STICK, budget_code,
                       displacement, expm1_ratio, expm1_ratio_integral, pairwise_sum, push_event,
                       push_segment, sign)
from .roots import first_root, free_first_root, stuck_first_root
from .motors import M_START, motor_build, motor_coefficients, motor_displacement, motor_speed

# A lagging-motor plant's constants, one array (advance_dynamic).
(P_TOTAL, P_MASS, P_DAMPING, P_COMPLIANCE, P_TAU, P_RATE, P_RAMP_GAP, P_SPEED_BOUND,
 P_MARGIN) = range(9)
N_PARAMS = 9

_IEEE = {"error_model": "numpy"}   # IEEE division: x / 0 is inf or NaN (as NumPy), never raises
#: The kernels of this module and their numba options (toolkit._compiled.load compiles them).
KERNELS = {"quiet_piece": {}, "filippov": _IEEE, "compliant_round": _IEEE, "dynamic_run": _IEEE,
           "piece_begin": _IEEE, "compliant_segment": _IEEE, "tied_solution": _IEEE,
           "instant_events": _IEEE, "free_segment": _IEEE, "stuck_segment": _IEEE,
           "advance_dynamic": _IEEE, "advance_outputs": _IEEE, "lag_response": _IEEE,
           "lag_travel": _IEEE, "tie_tolerance": _IEEE}


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
    """The lagging-motor engine (lag ``tau`` s, rate limit ``rate`` m/s^2; compliance ``k``
    (m/s)/N or Coulomb contacts of magnitudes ``f`` (N, total ``total``); mass ``m`` kg, drag
    ``c`` N s/m) over the pieces ``[bounds[p], bounds[p + 1])`` of constant command
    ``commands[p]`` (m/s, clipped) and external force ``externals[p]`` (N): the engine of
    ``simulate`` and ``advance`` with lagging or rate-limited motors.

    State as :func:`ideal_piece` keeps it, plus the piece ``I_PIECE``, its offset ``F_OFF``, the
    contact followed ``I_STUCK``, the contact whose event ended the last segment ``I_HINT`` and
    ``F_REL`` (+-1 while the body leaves ``I_STUCK`` upward / downward); ``motor`` (5, n) the
    current piece (:func:`motor_build`). Each round: the motors' coefficients, the contacts tied
    with the body and their Filippov solution, the events of this instant, one closed-form
    segment and its first event. Returns ``DONE``, ``MAX_STEPS``, ``ZENO`` or ``PAUSE``.
    """
    n = f.size
    P = bounds.size - 1
    mu = 1.0 / tau if tau > 0 else 0.0
    t, V, off, releasing, rate_ev = fstate[F_T], fstate[F_V], fstate[F_OFF], fstate[F_REL], fstate[F_RATE]
    p, stuck, hint, started = istate[I_PIECE], istate[I_STUCK], istate[I_HINT], istate[I_STARTED] != 0
    nseg, nev, rounds, n_eval = istate[I_NSEG], istate[I_NEV], istate[I_ROUNDS], istate[I_NEVAL]
    max_steps, window = istate[I_MAXSTEPS], istate[I_WINDOW]
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
    rows = np.empty(2 * n, dtype=np.int64)
    index = np.empty((2, n), dtype=np.int64)                  # the tied contacts, scratch
    small = np.empty((4, n))                                  # their slopes, weights, scratch
    code = DONE
    done = 0
    while p < P:
        a = bounds[p]
        b = bounds[p + 1]
        if not started:
            nev = piece_begin(p, bounds, commands, tau, rate, motor, v, V, ev, nev)
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
                s, r, V, nseg = compliant_segment(f, m, c, k, mu, E, horizon, t, V, v, q, e, hint, tie_v,
                                                  region, slip, on_edge, gather, fns, rows, seg, nseg)
                if r >= 0:
                    off += s
                    t = a + off
                    hint = rows[r]
                    nev = push_event(ev, nev, t, SATURATION, hint, V)
                else:
                    off = off_next
                    t = t_next
                    hint = -1
            else:
                V, T, acc, follows, level, new_stuck = tied_solution(
                    f, m, c, E, tol, tie_v, v, q, e, V, hint, stuck, releasing, tied, index, side,
                    gather, small)
                nev = instant_events(t, V, stuck, new_stuck, hint, ev, nev)
                stuck = new_stuck
                releasing = 0.0
                if stuck < 0:
                    step, r, V_new, nseg = free_segment(f, m, c, E, mu, horizon, t, V, v, q, e, tied,
                                                        index[0], T, side, signs, gather, small[0],
                                                        acc, seg, nseg)
                else:
                    step, r, releasing, V_new, nseg = stuck_segment(
                        f, m, c, E, mu, tol, horizon, t, V, v, q, e, tied, group, index[0], T,
                        follows, level, stuck, side, signs, gather, small[0], acc, seg, nseg)
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
    fstate[F_T], fstate[F_V], fstate[F_OFF], fstate[F_REL] = t, V, off, releasing
    istate[I_PIECE], istate[I_STUCK], istate[I_HINT], istate[I_STARTED] = p, stuck, hint, 1 if started else 0
    istate[I_NSEG], istate[I_NEV], istate[I_ROUNDS], istate[I_NEVAL] = nseg, nev, rounds, n_eval
    return code


def piece_begin(p: int, bounds: np.ndarray, commands: np.ndarray, tau: float, rate: float,
                motor: np.ndarray, v: np.ndarray, V: float, ev: np.ndarray, nev: int) -> int:
    """Piece ``p`` of :func:`dynamic_run` begins: ``motor`` rebuilt from the speeds where the
    previous piece ended (a command event at its start) or, for the first, from
    ``motor[M_START]``; ``v`` (n,) scratch. Returns the event count."""
    n = v.size
    if p > 0:
        span = bounds[p] - bounds[p - 1]
        for i in range(n):
            v[i] = motor_speed(motor, tau, i, span)
        nev = push_event(ev, nev, bounds[p], COMMAND, -1, V)
    else:
        for i in range(n):
            v[i] = motor[M_START, i]
    motor_build(v, commands[p], tau, rate, motor)
    return nev


def compliant_segment(f: np.ndarray, m: float, c: float, k: float, mu: float, E: float,
                      horizon: float, t: float, V: float, v: np.ndarray, q: np.ndarray,
                      e: np.ndarray, hint: int, tie_v: float, region: np.ndarray, slip: np.ndarray,
                      on_edge: np.ndarray, gather: np.ndarray, fns: np.ndarray, rows: np.ndarray,
                      seg: np.ndarray, nseg: int) -> tuple[float, int, float, int]:
    """One segment of compliant contacts from time ``t`` (s) (:func:`compliant_round`) and its
    first saturation event within ``horizon`` (s): returns ``(s, r, V at the segment's end,
    nseg)`` with ``r`` the row of the event function that fired (-1: none, ``s`` unused)."""
    alpha, beta, gamma, delta = fns[0], fns[1], fns[2], fns[3]
    count, B, lam, c1, C, D = compliant_round(f, m, c, k, mu, E, V, v, q, e, hint, tie_v, region,
                                              slip, on_edge, gather, alpha, beta, gamma, delta, rows)
    nseg = push_segment(seg, nseg, t, V, c1, B, lam, C, D)
    s, r = first_root(alpha[:count], beta[:count], gamma[:count], delta[:count], lam, mu, D, horizon)
    x = s if r >= 0 else horizon
    V_new = (V + c1 * x + B * expm1_ratio(lam, x) + C * expm1_ratio(mu, x)
             + D * x * math.exp(-mu * x))
    return s, r, V_new, nseg


def tied_solution(f: np.ndarray, m: float, c: float, E: float, tol: float, tie_v: float,
                  v: np.ndarray, q: np.ndarray, e: np.ndarray, V: float, hint: int, stuck: int,
                  releasing: float, tied: np.ndarray, index: np.ndarray, side: np.ndarray,
                  gather: np.ndarray, small: np.ndarray) -> tuple[float, int, float, bool, float, int]:
    """The Coulomb contacts tied with the body now (within ``tie_v`` m/s, and the contacts
    ``hint`` and ``stuck``), the body's speed snapped to the one it follows, the others' signs
    into ``side`` and the Filippov solution among the tied (:func:`filippov`; their indices,
    slopes and weights into ``index[0]``, ``small[0]``, ``small[1]``). Returns ``(V, T, acc,
    follows, level, new_stuck)``: ``T`` tied, the body's acceleration and the contact it
    follows (-1: none)."""
    n = f.size
    tied_idx, t_slopes, t_weights = index[0], small[0], small[1]
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
    acc, follows, level = filippov(G_out, t_slopes, t_weights, T, m, tol, index[1], small[2], small[3])
    new_stuck = -1
    if follows:
        for j in range(T):
            if t_slopes[j] == level:
                new_stuck = tied_idx[j]
                break
    return V, T, acc, follows, level, new_stuck


def instant_events(t: float, V: float, stuck: int, new_stuck: int, hint: int, ev: np.ndarray,
                   nev: int) -> int:
    """The events at time ``t`` (s) when the body goes from following ``stuck`` to following
    ``new_stuck`` (-1: none) after the event of contact ``hint``: a release, a stick, a crossing."""
    if stuck >= 0 and new_stuck != stuck:
        nev = push_event(ev, nev, t, RELEASE, stuck, V)
    if new_stuck >= 0 and new_stuck != stuck:
        nev = push_event(ev, nev, t, STICK, new_stuck, V)
    if hint >= 0 and (new_stuck < 0 or hint != new_stuck) and hint != stuck:
        nev = push_event(ev, nev, t, CROSS, hint, V)
    return nev


def free_segment(f: np.ndarray, m: float, c: float, E: float, mu: float, horizon: float, t: float,
                 V: float, v: np.ndarray, q: np.ndarray, e: np.ndarray, tied: np.ndarray,
                 tied_idx: np.ndarray, T: int, side: np.ndarray, signs: np.ndarray,
                 gather: np.ndarray, t_slopes: np.ndarray, acc: float, seg: np.ndarray,
                 nseg: int) -> tuple[float, int, float, int]:
    """One segment of a body sliding free from time ``t`` (s) under the contacts' signs (the tied
    ones' from their slopes against the acceleration ``acc``) and its first crossing within
    ``horizon`` (:func:`free_first_root`): returns ``(step, r, V after step, nseg)``."""
    n = f.size
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
    return step, r, V + r0 * expm1_ratio(lam, step), nseg


def stuck_segment(f: np.ndarray, m: float, c: float, E: float, mu: float, tol: float,
                  horizon: float, t: float, V: float, v: np.ndarray, q: np.ndarray, e: np.ndarray,
                  tied: np.ndarray, group: np.ndarray, tied_idx: np.ndarray, T: int, follows: bool,
                  level: float, stuck: int, side: np.ndarray, signs: np.ndarray, gather: np.ndarray,
                  t_slopes: np.ndarray, acc: float, seg: np.ndarray,
                  nseg: int) -> tuple[float, int, float, float, int]:
    """One segment of a body following contact ``stuck`` (with the tied contacts on its slope,
    ``group``) from time ``t`` (s) and its first event within ``horizon``
    (:func:`stuck_first_root`): returns ``(step, r, releasing, V after step, nseg)``."""
    n = f.size
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
    s, r, releasing = stuck_first_root(v, q, e, tied, group, stuck, W, tol, h0, c, m, mu, horizon)
    step = horizon if r < 0 and releasing == 0.0 else s
    return step, r, releasing, vc + qc * step + ec * expm1_ratio(mu, step), nseg


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
