"""Each contact's speed from its wheel's counts (toolkit.estimation.wheel_bank): the bank of
Kalman filters per wheel and hypothesis of the motors' wander, against the filters written
again with matrices; its start and restart; what it does with a wheel standing in the
gearbox play."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from toolkit.estimation import EstimatorModel, WheelSpeedBank
from toolkit.laws import lag_response, lag_travel
from toolkit.model.carousel import CAROUSEL
from toolkit.model.motors import MotorPiece
from toolkit.model.sensors import play

FORCES = np.array([1.0, 2.0, 1.5])


def _model(lag: float, backlash: float = 0.0) -> EstimatorModel:
    sensors = dataclasses.replace(CAROUSEL, wheel_backlash=backlash).sensors(3)
    return EstimatorModel(FORCES, 3.0, sensors, motor_lag=lag)


class _BankAgain:
    """The bank written again without play: per hypothesis d and wheel, a Kalman filter of
    (x, o) with F = [[1, h], [0, 1]] plus the motor law's displacement, process noise d^2
    [[h^3 / 3, h^2 / 2], [h^2 / 2, h]] plus (0.3 x the law's speed change)^2 on o, the reading
    (count + 1/2) q of x (through the encoders' side: see push); each hypothesis weighted by
    its readings' Gaussian likelihood with the memory 0.99 per sample; the contacts' speeds
    the law's end speeds plus the weighted mean offset, their variance the mixture's."""

    def __init__(self, model, wheels, speeds, variance):
        self.h, self.q, self.tau = model.sensors.period, model.sensors.wheel.distance_per_count, model.motor_lag
        self.drifts = np.array(WheelSpeedBank.DRIFTS)
        n = len(speeds)
        self.x = np.zeros((self.drifts.size, n, 2))
        self.x[:, :, 0] = (np.asarray(wheels) + 0.5) * self.q
        self.P = np.zeros((self.drifts.size, n, 2, 2))
        self.P[:, :, 0, 0] = self.q * self.q / 12.0
        self.P[:, :, 1, 1] = variance
        self.logw = np.zeros(self.drifts.size)
        self.nominal = np.array(speeds, dtype=float)
        self.y = self.x[0, :, 0].copy()          # the encoders' side (no play: the contacts')

    def push(self, wheels, command, noise):
        h, u, v0 = self.h, np.asarray(command, dtype=float), self.nominal
        if self.tau > 0.0:
            end, cx = lag_response(u, v0, h, self.tau), lag_travel(u, v0, h, self.tau)
        else:
            end, cx = u, h * u
        F = np.array([[1.0, h], [0.0, 1.0]])
        # Every hypothesis reads its contact through the encoders' side as the most likely
        # hypothesis has it: x + (y - x_best), y carried from that hypothesis.
        best = int(np.argmax(self.logw))
        shift = self.y - self.x[best, :, 0]
        for k, d in enumerate(self.drifts):
            for i in range(u.size):
                Q = d * d * np.array([[h ** 3 / 3, h * h / 2], [h * h / 2, h]])
                Q[1, 1] += (0.3 * (end[i] - v0[i])) ** 2
                x = F @ self.x[k, i] + np.array([cx[i], 0.0])
                P = F @ self.P[k, i] @ F.T + Q
                S = P[0, 0] + noise[i]
                y = (wheels[i] + 0.5) * self.q - (x[0] + shift[i])
                gain = P[:, 0] / S
                self.x[k, i] = x + gain * y
                self.P[k, i] = P - np.outer(gain, gain) * S
                self.logw[k] -= 0.5 * (y * y / S + math.log(S))
        self.nominal = end
        self.y = self.x[best, :, 0] + shift
        return end

    def weights(self):
        w = np.exp(self.logw - self.logw.max())
        return w / w.sum()


def _run(lag):
    """The bank and its transcription over 30 periods: commands held, stepped down (a brake
    to lower speeds of either sign) at period 10 and back up at 20; the counts of contacts
    that follow the commands a little off (0.7 mm/s) with whole-count read noise."""
    model = _model(lag)
    q, h = model.sensors.wheel.distance_per_count, model.sensors.period
    rng = np.random.default_rng(9)
    up, down = np.array([0.12, 0.2, 0.15]), np.array([-0.05, 0.02, -0.1])
    wheels = np.array([10, -40, 300])
    bank = WheelSpeedBank(model)
    bank.start(wheels, up, np.full(3, 1e-6))
    again = _BankAgain(model, wheels, up, np.full(3, 1e-6))
    position = (wheels + 0.5) * q
    noise = np.array([1.0, 1.5, 2.0]) * q * q / 12.0
    out = []
    for k in range(30):
        command = down if 10 <= k < 20 else up
        position = position + h * (command + 7e-4)
        counts = np.floor(position / q).astype(np.int64) + rng.integers(-1, 2, 3)
        speeds, var = bank.push(counts, command, lag, noise)
        # The transcription's log weights carry the memory: forget the old ones first.
        again.logw *= WheelSpeedBank.FORGET
        end = again.push(counts, command, noise)
        out.append((bank.weights, bank.drift, again.weights(), again.x.copy(), again.P.copy(), speeds, var, end))
    return out


@pytest.mark.parametrize("lag", [0.0075, 0.0])
def test_the_bank_is_a_kalman_filter_per_wheel_and_wander(lag):
    # Without play (every encoder engaged), with the motors' lag and without: each period's
    # speeds and variances, the hypotheses' weights and the wander's mean intensity against
    # the filters written with matrices (1e-9 relative: the kernel's unrolled updates against
    # matrix products; the weights to 1e-9 absolute).
    drifts = np.array(WheelSpeedBank.DRIFTS)
    for weights, drift, w, x, P, speeds, var, end in _run(lag):
        o = np.einsum("h,hi->i", w, x[:, :, 1])
        spread = np.einsum("h,hi->i", w, P[:, :, 1, 1] + (x[:, :, 1] - o) ** 2)
        np.testing.assert_allclose(speeds, end + o, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(var, spread, rtol=1e-9)
        np.testing.assert_allclose(weights, w, rtol=0.0, atol=1e-9)
        assert drift == pytest.approx(float(w @ drifts), rel=1e-9)
    assert w.argmax() > 0 and w.min() < 1e-3                # (the readings weigh the hypotheses)


def test_the_bank_starts_from_the_readings_behind_the_contacts():
    # Before any reading the hypotheses weigh alike and the wander's intensity is their mean.
    # The first readings: each contact half the play ahead of its encoder's cell centre in
    # the direction it moves (centred at rest), the quantization's variance on the position,
    # the given variance on the offset, no covariance between them.
    model = _model(0.0075, backlash=8e-4)
    bank = WheelSpeedBank(model)
    H = len(WheelSpeedBank.DRIFTS)
    np.testing.assert_array_equal(bank.weights, np.full(H, 1.0 / H))
    assert bank.drift == pytest.approx(float(np.mean(WheelSpeedBank.DRIFTS)), rel=1e-15)
    q = model.sensors.wheel.distance_per_count
    wheels, speeds, variance = np.array([7, -3, 0]), np.array([0.1, -0.2, 0.0]), np.array([1e-6, 4e-6, 9e-6])
    bank.start(wheels, speeds, variance)
    centre = (wheels + 0.5) * q
    for h in range(H):
        np.testing.assert_array_equal(bank._x[h, :, 0], centre + np.array([4e-4, -4e-4, 0.0]))
        np.testing.assert_array_equal(bank._x[h, :, 1], 0.0)
        np.testing.assert_allclose(bank._P[h], np.column_stack((np.full(3, q * q / 12), np.zeros(3), variance)),
                                   rtol=1e-15)
    np.testing.assert_array_equal(bank._y, centre)


def test_a_restart_resets_only_the_wheels_named():
    # After a few periods, wheel 1 restarts from new readings and estimates: its filters as
    # at the start (offset 0, the quantization's and the given variances), the others as
    # they were; a restart naming no wheel changes nothing.
    model = _model(0.0075, backlash=8e-4)
    q = model.sensors.wheel.distance_per_count
    bank = WheelSpeedBank(model)
    bank.start(np.array([0, 0, 0]), np.array([0.1, 0.1, 0.1]), np.full(3, 1e-6))
    for k in range(1, 4):
        bank.push(np.array([25, 25, 25]) * k, np.array([0.1, 0.1, 0.1]), 0.0075, np.full(3, q * q / 12))
    before = (bank._x.copy(), bank._P.copy(), bank._y.copy(), bank._nominal.copy())
    bank.restart(np.zeros(3, dtype=bool), np.array([1, 2, 3]), np.array([0.3, -0.3, 0.3]), np.full(3, 5e-6))
    for got, was in zip((bank._x, bank._P, bank._y, bank._nominal), before):
        np.testing.assert_array_equal(got, was)
    which = np.array([False, True, False])
    bank.restart(which, np.array([1, 80, 3]), np.array([0.3, -0.25, 0.3]), np.array([5e-6, 7e-6, 5e-6]))
    keep = ~which
    np.testing.assert_array_equal(bank._x[:, keep], before[0][:, keep])
    np.testing.assert_array_equal(bank._P[:, keep], before[1][:, keep])
    np.testing.assert_array_equal(bank._y[keep], before[2][keep])
    np.testing.assert_array_equal(bank._nominal, [before[3][0], -0.25, before[3][2]])
    assert bank._y[1] == 80.5 * q
    np.testing.assert_array_equal(bank._x[:, 1, 0], 80.5 * q - 4e-4)
    np.testing.assert_array_equal(bank._x[:, 1, 1], 0.0)
    np.testing.assert_allclose(bank._P[:, 1], np.tile([q * q / 12, 0.0, 7e-6], (6, 1)), rtol=1e-15)


def _step_again(bank, wheels, command, lag, noise, periods):
    """One push of the bank written again from its state before it, with the gearbox play:
    the motor law's speeds and displacements (lag_response, lag_travel: u at once without a
    lag), the encoders' side of the most likely hypothesis; a wheel whose encoder stays
    engaged behind its contact (|shift| = half the play, the contact's speed keeping the sign
    opposite to the shift's over the period) reads it shifted; the others follow the play
    operator along that hypothesis's path at 8 sub-steps and are read only where they end
    engaged. Then the filters (as _BankAgain) and the mixture. Returns the speeds, their
    variances, the weights, the drift, x and P, the encoders' side and which wheels were
    read through a walk and not seen (whose encoder side is not compared)."""
    h = periods * bank.h
    q, half, drifts = bank.q, 0.5 * bank.play, np.array(WheelSpeedBank.DRIFTS)
    x, P, logw, y = bank._x.copy(), bank._P.copy(), bank._log_weights.copy(), bank._y.copy()
    start, u = bank._nominal.copy(), np.asarray(command, dtype=float)
    sub = h * np.arange(1, 9) / 8.0
    if lag > 0.0 and start.tolist() != u.tolist():
        end, moved = lag_response(u, start, h, lag), lag_travel(u, start, sub[:, None], lag)
    else:
        end, moved = u.copy(), sub[:, None] * u
    best = int(np.argmax(logw))
    shift, o_best = y - x[best, :, 0], x[best, :, 1].copy()
    loaded = (half == 0.0) | ((np.abs(np.abs(shift) - half) <= 1e-9 * max(half, 1e-12))
                              & (np.sign(start + o_best) == np.sign(end + o_best))
                              & (np.sign(end + o_best) == -np.sign(shift)))
    seen = loaded.copy()
    walk = ~loaded
    if walk.any():
        path = x[best, :, 0] + moved + sub[:, None] * o_best
        ends = play(path[:, walk], bank.play, y[walk])[-1]
        shift[walk] = ends - path[-1, walk]
        seen[walk] = np.abs(np.abs(shift[walk]) - half) <= 1e-9 * max(half, 1e-12)
    F = np.array([[1.0, h], [0.0, 1.0]])
    for k, d in enumerate(drifts):
        total = 0.0
        for i in range(u.size):
            Q = d * d * np.array([[h ** 3 / 3, h * h / 2], [h * h / 2, h]])
            Q[1, 1] += (0.3 * (end[i] - start[i])) ** 2
            xi = F @ np.array([x[k, i, 0], x[k, i, 1]]) + np.array([moved[-1, i], 0.0])
            Pi = F @ np.array([[P[k, i, 0], P[k, i, 1]], [P[k, i, 1], P[k, i, 2]]]) @ F.T + Q
            if seen[i]:
                S = Pi[0, 0] + noise[i]
                r = (wheels[i] + 0.5) * q - (xi[0] + shift[i])
                gain = Pi[:, 0] / S
                xi, Pi = xi + gain * r, Pi - np.outer(gain, gain) * S
                total += r * r / S + math.log(S)
            x[k, i], P[k, i] = xi, (Pi[0, 0], Pi[0, 1], Pi[1, 1])
        logw[k] = WheelSpeedBank.FORGET * logw[k] - 0.5 * total
    w = np.exp(logw - logw.max())
    w /= w.sum()
    o = w @ x[:, :, 1]
    var = w @ (P[:, :, 2] + (x[:, :, 1] - o) ** 2)
    return end + o, var, w, float(w @ drifts), x, P, x[best, :, 0] + shift, walk & ~seen


@pytest.mark.parametrize("lag", [0.0075, 0.0])
def test_the_bank_reads_each_wheel_through_the_gearbox_play(lag):
    # Play of 0.8 mm. Three contacts: one reverses at period 5 and back at 15, one reverses
    # at period 8 from 0.2 to -0.3 m/s (with the lag it turns 3.8 ms into the period: between
    # the first two of the path's 8 sub-steps) and stops at 18, one keeps going; samples lost
    # before periods 10 and 20 (a push over two periods). Readings of contacts 0.5 mm/s off
    # their commands seen through the play operator (whole-count read noise). Each push
    # against the push written again from the bank's state before it: the speeds, variances,
    # weights and drift (1e-9 relative), the filters' states and covariances, the encoders'
    # side of the wheels read; walks through the play and wheels not read both occur.
    model = _model(lag, backlash=8e-4)
    q, h = model.sensors.wheel.distance_per_count, model.sensors.period
    rng = np.random.default_rng(12)
    bank = WheelSpeedBank(model)
    first = np.array([0.12, 0.2, -0.15])
    contact = np.array([0.001, 0.002, 0.003])
    encoder = contact - np.sign(first) * 4e-4
    bank.start(np.floor(encoder / q).astype(np.int64), first, np.full(3, 1e-6))
    noise = np.array([1.0, 1.5, 2.0]) * q * q / 12.0
    walked = unseen = 0
    for k in range(1, 26):
        command = np.array([-0.12 if 5 <= k < 15 else 0.12, 0.2 if k < 8 else (-0.3 if k < 18 else 0.0), -0.15])
        periods = 2 if k in (10, 20) else 1
        for _ in range(periods * 8):
            contact = contact + h / 8 * (command + 5e-4)
            encoder = np.clip(encoder, contact - 4e-4, contact + 4e-4)
        counts = np.floor(encoder / q).astype(np.int64) + rng.integers(-1, 2, 3)
        want = _step_again(bank, counts, command, lag, noise, periods)
        speeds, var = bank.push(counts, command, lag, noise, periods)
        np.testing.assert_allclose(speeds, want[0], rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(var, want[1], rtol=1e-9)
        np.testing.assert_allclose(bank.weights, want[2], rtol=0.0, atol=1e-9)
        assert bank.drift == pytest.approx(want[3], rel=1e-9)
        np.testing.assert_allclose(bank._x, want[4], rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(bank._P, want[5], rtol=1e-9, atol=1e-18)
        read = ~want[7]
        np.testing.assert_allclose(bank._y[read], want[6][read], rtol=1e-12, atol=1e-12)
        walked += int((bank._loaded == 0).any())
        unseen += int(want[7].any())
    assert walked > 2 and unseen > 0


def test_a_wheel_standing_in_the_play_keeps_its_encoder_side():
    # A contact that stops (command 0 from 0.1 m/s, lag 7.5 ms) comes to rest inside the
    # gearbox play: the play operator along the most likely path leaves its encoder where it
    # was, and the bank's encoder side must be that operator's output. (It failed when the
    # side was computed from the contact's position after the update: one period's travel
    # further, so that a slowed contact never engaged its play again.)
    model = _model(0.0075, backlash=8e-4)
    q, h = model.sensors.wheel.distance_per_count, model.sensors.period
    bank = WheelSpeedBank(model)
    wheels = np.array([100, 200, 300])
    bank.start(wheels, np.array([0.1, 0.15, -0.12]), np.full(3, 1e-6))
    command = np.array([0.0, 0.15, -0.12])
    s = h * np.arange(1, 9) / 8.0
    position = (wheels + 0.5) * q
    standing = 0
    for k in range(3):
        best = int(np.argmax(bank._log_weights))
        x, o, y = bank._x[best, :, 0].copy(), bank._x[best, :, 1].copy(), bank._y.copy()
        path = x + MotorPiece.build(0.0, bank._nominal, command, 0.0075, math.inf).displacement(s[:, None]) \
            + s[:, None] * o
        operator = play(path, 8e-4, y)[-1]
        position = position + h * np.array([0.0, 0.15, -0.12])
        bank.push(np.floor(position / q).astype(np.int64), command, 0.0075, np.full(3, q * q / 12))
        inside = np.abs(np.abs(operator - path[-1]) - 4e-4) > 1e-9 * 4e-4
        standing += int(inside[0])
        if inside[0]:
            assert bank._y[0] == pytest.approx(operator[0], rel=0.0, abs=1e-12)
    assert standing > 0
