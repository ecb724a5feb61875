"""The motor law's compiled closed form (toolkit._compiled.motors) at its thresholds: the ramp
that starts only beyond a gap of rate x lag, the lag phase with libm's exponential, the play
taken up from the turn on, and the take-up time's bracket and bisection written again. Run
compiled, and as Python under NUMBA_DISABLE_JIT=1 (how its mutants run)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from toolkit import _compiled
from toolkit.model.motors import MotorPiece

INF = math.inf


def _table(module, start, u, tau, rate):
    table = np.empty((5, len(start)))
    module.motor_build(np.asarray(start, dtype=float), np.asarray(u, dtype=float), tau, rate, table)
    return table


@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_a_motor_ramps_only_beyond_a_gap_of_rate_times_lag(sign):
    # Rate 4 m/s^2, lag 0.25 s: a gap of exactly rate tau = 1 m/s (dyadic: exact) is taken by
    # the lag alone (no ramp, no ramp end, the lag from the start), as MotorPiece builds it;
    # one float more and the motor ramps at the rate, up or down, until the gap left is rate
    # tau (after = u -+ 1).
    module = _compiled.load("core")
    start = sign * 0.25
    u = start + sign * 1.0
    table = _table(module, [start], [u], 0.25, 4.0)
    piece = MotorPiece.build(0.0, np.array([start]), np.array([u]), 0.25, 4.0)
    assert table[:, 0].tolist() == [start, u, 0.0, 0.0, start]
    assert table[:, 0].tolist() == [piece.start[0], piece.u[0], piece.ramp[0], piece.ramp_end[0], piece.after[0]]
    beyond = float(np.nextafter(u, sign * INF))
    table = _table(module, [start], [beyond], 0.25, 4.0)
    assert table[2, 0] == sign * 4.0 and table[3, 0] > 0.0 and table[4, 0] == beyond - sign * 1.0


def test_the_lag_phase_is_the_closed_form_with_libms_exponential():
    # After the ramp: v = u + (after - u) exp(-(s - end) / tau) and the distance its integral
    # u x + (after - u) tau (1 - exp(-x / tau)) with math.exp and math.expm1 (libm: what the
    # compiled kernel calls), to the bit, on 1000 offsets; two motors stop (u = 0, one without
    # a ramp), where a last-bit difference of the exponential shows in the result (NumPy's
    # own exp and expm1 differ from libm's in the last bit on some of these offsets).
    module = _compiled.load("core")
    tau, rate = 0.0075, 5.0
    start, u = np.array([0.3, -0.2, 0.25, 0.03]), np.array([-0.1, 0.25, 0.0, 0.0])
    table = _table(module, start, u, tau, rate)
    assert table[3, 3] == 0.0 and (table[3, :3] > 0.0).all()
    out = np.empty(4)
    for s in np.linspace(0.0, 0.1, 1000).tolist():
        module.motor_displacement(table, tau, s, out)
        for i in range(4):
            end, after = table[3, i], table[4, i]
            if s < end:
                continue
            x = s - end
            assert module.motor_speed(table, tau, i, s) == u[i] + (after - u[i]) * math.exp(-x / tau)
            ramp = start[i] * end + 0.5 * table[2, i] * end * end
            assert out[i] == ramp + (u[i] * x + (after - u[i]) * (tau * -math.expm1(-x / tau)))


def _reversal(module):
    """One motor from -0.5 to 0.5 m/s at 2 m/s^2 without a lag (dyadic: exact arithmetic): it
    turns at 0.25 s, where it has travelled -0.0625 m, and at 0.75 s it has travelled 0.125 m:
    0.1875 m from the turn."""
    table = _table(module, [-0.5], [0.5], 0.0, 2.0)
    out = np.empty(1)
    module.motor_displacement(table, 0.0, 0.25, out)
    assert out[0] == -0.0625
    return table, np.array([0.25]), np.array([-0.0625])


def test_the_play_is_taken_up_from_the_turn_on():
    # Without play, a motor has taken it up the moment it turns, not a float before; with a
    # play of 0.1875 m, exactly at 0.75 s (the distance reaches it), not with a float more of
    # play.
    module = _compiled.load("core")
    table, turn, at_turn = _reversal(module)
    out = np.empty(1)
    assert module.play_taken_up(table, 0.0, turn, at_turn, 0.0, 0.25, out)
    assert not module.play_taken_up(table, 0.0, turn, at_turn, 0.0, float(np.nextafter(0.25, 0.0)), out)
    assert module.play_taken_up(table, 0.0, turn, at_turn, 0.1875, 0.75, out)
    assert not module.play_taken_up(table, 0.0, turn, at_turn, float(np.nextafter(0.1875, 1.0)), 0.75, out)


@pytest.mark.parametrize("coarse", [False, True])
@pytest.mark.parametrize("latest", [0, 1, 2])
def test_the_take_up_time_is_the_bisection_from_the_latest_turn(latest, coarse):
    # Three motors reversing (lag 7.5 ms), the one that turns last first, second or third:
    # play_take_up_time is the search written again here on the kernel's own test
    # (play_taken_up): from the latest turn, steps of `step` until every play is taken up,
    # then 50 halvings, the upper end; the same doubles, to the bit. Steps of a tenth of the
    # time needed (several steps), or of 1 s (one step; 50 halvings of it end on an interval
    # of 1e-15 s, wider than a float there, so the end depends on where the bracket starts).
    module = _compiled.load("core")
    tau, play = 0.0075, 2e-4
    # Each motor turns at tau log(1 + r), r = -v0 / u: r = 6 for the latest, 3 and 1.5.
    u = np.array([-0.3, 0.1, -0.05])
    r = np.full(3, 1.5)
    r[latest], r[(latest + 1) % 3] = 6.0, 3.0
    v0 = -r * u
    turn = tau * np.log((u - v0) / u)
    assert int(np.argmax(turn)) == latest
    step = 1.0 if coarse else 0.1 * play / float(np.abs(u).min())
    found = module.play_take_up_time(v0, u, tau, turn, play, step)

    table = _table(module, v0, u, tau, INF)
    out, at_turn = np.empty(3), np.empty(3)
    for i in range(3):
        module.motor_displacement(table, tau, float(turn[i]), out)
        at_turn[i] = out[i]

    def taken_up(s):
        return module.play_taken_up(table, tau, turn, at_turn, play, s, out)

    lo = float(turn.max())
    hi, steps = lo + step, 1
    while not taken_up(hi):
        hi, steps = hi + step, steps + 1
    for _ in range(50):
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if taken_up(mid) else (mid, hi)
    assert steps == 1 if coarse else steps > 3
    assert found == hi
