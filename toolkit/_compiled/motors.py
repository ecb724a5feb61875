"""Kernels of the motor law's closed form over one piece of constant command.

The compiled form of :class:`toolkit.model.motors.MotorPiece`: a ramp at the rate limit while
the gap exceeds ``rate tau``, then the first-order lag of :mod:`toolkit.laws`. A piece is
a table (5, n) with rows ``start``, ``u``, ``ramp`` (m/s^2), ``ramp_end`` (s) and ``after`` (m/s).
"""

from __future__ import annotations

import math

import numpy as np

from ..laws import lag_response, lag_travel
from .segments import INF, sign

M_START, M_U, M_RAMP, M_END, M_AFTER = 0, 1, 2, 3, 4      # the rows of a piece's table

_IEEE = {"error_model": "numpy"}   # IEEE division: x / 0 is inf or NaN (as NumPy), never raises
#: The kernels of this module and their numba options (toolkit._compiled.load compiles them).
KERNELS = {"motor_build": _IEEE, "motor_speed": _IEEE,
           "motor_coefficients": _IEEE, "motor_displacement": _IEEE, "play_taken_up": _IEEE,
           "play_take_up_time": _IEEE, "lag_response": _IEEE, "lag_travel": _IEEE}


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
