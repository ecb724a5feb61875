"""Kernels of the estimators: one exact step linearized, input bounds, window lines, Kalman.

:func:`linearize_step` linearizes one step of held or lagging contacts along its events (slopes,
the contacts' noise, the response to an outside force); :func:`period_bounds` says what decides
an estimator's input over a period; :func:`window_line` and :func:`kalman_step` serve the filters.
"""

from __future__ import annotations

import math

import numpy as np

from ..laws import lag_decay
from .segments import (CROSS, INF, RELEASE, STICK, expm1_ratio, expm1_ratio_integral, pairwise_sum,
                       sign)
from .tables import median_row
from .motors import motor_build, motor_coefficients

_IEEE = {"error_model": "numpy"}   # IEEE division: x / 0 is inf or NaN (as NumPy), never raises
#: The kernels of this module and their numba options (toolkit._compiled.load compiles them).
KERNELS = {"linearize_step": {}, "flip_signs": {}, "cross_gains": {}, "stick_group": {},
           "release_force": {}, "stuck_stretch": {}, "gathered_sum": {}, "contains": {},
           "period_bounds": {}, "window_line": {}, "kalman_step": {}, "lag_decay": _IEEE}


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
        if kind == CROSS:                    # the force response's signs flip (force_gains)
            flip_signs(s, t_sign, Ve, contact, speeds, sgn, average, flip)
            t_sign = s
            if stuck:
                continue                     # the stiction force absorbs it until a release
            F_seg, J, sV, touched = cross_gains(s, V, Ve, F_seg, J, sV, f, start, speeds, rates, at,
                                                group, sgn, tmp, order, touched, gv, c, m, lagging,
                                                tau)
        elif kind == STICK:
            # From here V is the contact's speed: it errs as the contact's estimate does.
            J = 0.0
            sV = 0.0
            stick_group(contact, at, rates, group, gv, order, touched)
            arrival, stuck, stick_at = var_v, True, s
        elif kind == RELEASE:
            arrival, stuck = math.nan, False
            touched = stuck_stretch(f, group, tmp, order, touched, gx, gv, stick_at, s, lagging, tau)
            F_seg = release_force(Ve, E, c, m, f, speeds, rates, at, group, tmp)
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


def flip_signs(s: float, t_sign: float, Ve: float, contact: int, speeds: np.ndarray,
               sgn: np.ndarray, average: np.ndarray, flip: np.ndarray) -> None:
    """A crossing at offset ``s`` (s) and speed ``Ve`` (m/s): each sign's time since ``t_sign``
    added to ``average``, then the signs of the contacts at ``Ve`` (and ``contact``) flipped."""
    n = sgn.size
    wide = 1e-9 * max(1.0, abs(Ve))
    for i in range(n):
        average[i] += sgn[i] * (s - t_sign)
        flip[i] = abs(speeds[i] - Ve) <= wide
    if contact >= 0:
        flip[contact] = True
    for i in range(n):
        if flip[i]:
            sgn[i] = -sgn[i]


def cross_gains(s: float, V: float, Ve: float, F_seg: float, J: float, sV: float, f: np.ndarray,
                start: np.ndarray, speeds: np.ndarray, rates: np.ndarray, at: np.ndarray,
                group: np.ndarray, sgn: np.ndarray, tmp: np.ndarray, order: np.ndarray,
                touched: int, gv: np.ndarray, c: float, m: float, lagging: bool,
                tau: float) -> tuple[float, float, float, int]:
    """A crossing of the contacts ``at`` at offset ``s`` (s), speed ``Ve`` (m/s), of a sliding
    body: the segment's force ``F_seg`` (N) after it, the slopes ``J`` and ``sV`` and the
    gains ``gv`` scaled by the jump of the acceleration's gap to the contacts', and the crossed
    contacts' common error shared by force. Returns ``(F_seg, J, sV, touched)``."""
    n = f.size
    for i in range(n):
        at[i] = at[i] and not group[i]
    f_at, _ = gathered_sum(f, at, tmp)
    total_rate, count = gathered_sum(rates, at, tmp)
    slope = total_rate / count if count > 0 else math.nan
    a_before = (F_seg - c * Ve) / m
    side = 1.0 if a_before - slope > 0.0 else -1.0
    if s == 0.0:
        # Contacts the body starts on (no force in the start's sum: sign 0) it leaves at once:
        # before the crossing they push as from behind the body (the one-sided limit, + f
        # side), after it they are behind it.
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
    return F_seg, J, sV, touched


def stick_group(contact: int, at: np.ndarray, rates: np.ndarray, group: np.ndarray, gv: np.ndarray,
                order: np.ndarray, touched: int) -> None:
    """A stick on ``contact`` (-1: the first of ``at``): the gains ``gv`` cleared and the
    ``group`` the body follows from here, the contacts at its speed moving with it."""
    for j in range(touched):
        gv[order[j]] = 0.0
    jj = contact
    if jj < 0:
        jj = 0
        for i in range(at.size):
            if at[i]:
                jj = i
                break
    rj = rates[jj]
    wide = 1e-9 * max(1.0, abs(rj))
    for i in range(at.size):
        group[i] = at[i] and abs(rates[i] - rj) <= wide


def release_force(Ve: float, E: float, c: float, m: float, f: np.ndarray, speeds: np.ndarray,
                  rates: np.ndarray, at: np.ndarray, group: np.ndarray, tmp: np.ndarray) -> float:
    """The force (N) just after a release at speed ``Ve`` (m/s): the contact law off the
    ``group`` (cleared here); the group pulls ahead when the body, pulled by it, still lags
    its acceleration, else behind; other contacts at this speed count from the side they
    arrive from."""
    n = f.size
    f_group, _ = gathered_sum(f, group, tmp)
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
    return F_seg


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


def gathered_sum(values: np.ndarray, mask: np.ndarray, scratch: np.ndarray) -> tuple[float, int]:
    """``values[mask].sum()`` as NumPy sums the gathered array (:func:`pairwise_sum`), and the
    number of terms."""
    k = 0
    for i in range(values.size):
        if mask[i]:
            scratch[k] = values[i]
            k += 1
    return pairwise_sum(scratch, 0, k), k


def contains(order: np.ndarray, count: int, i: int) -> bool:
    """Contact ``i`` is among the first ``count`` entries of ``order``."""
    for j in range(count):
        if order[j] == i:
            return True
    return False


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
