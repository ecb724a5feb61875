"""Online identification of what the nominal model does not know, from the wheel counts.

:class:`LagIdentifier`: the motors' first-order lag, from the intercepts of the wheels'
lines after each command change. :class:`MissedCountRate`: the encoders' missed-count rate,
a Gamma posterior over the repaired counts and their exposure. :class:`RideCheck`: the same
rate where no line lasts long enough to show a loss, from the level between the body's
count and the wheel it rides. Derivations: docs/estimation.md.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..laws import cell_centre, quantization_variance
from .._compiled import kernels
from ..errors import as_float
from ..model.motors import MotorPiece
from ..model.truth import DEFAULT_MISSED, MAX_MISSED_MEAN

__all__ = ["LagIdentifier", "MissedCountRate", "RideCheck"]


class LagIdentifier:
    """The motors' lag from the wheel counts around command changes (see the module).

    Parameters
    ----------
    wheel_resolution : float, m per count
    backlash : float, m
        The wheels' gearbox play.
    period : float, s
    longest_lag : float, s
        The largest lag the prior allows: the line is fitted from eight of it (and at least
        ``settle_time``) after the change.
    settle_time : float, s
        At least this long after a change before the line (the play's take-up).

    Attributes
    ----------
    lag : float or None, s
        The pooled estimate (None before a change has been seen through).
    lag_std : float or None, s
        Its standard deviation from the quantization (white readings).
    estimates : list of (float, float)
        ``(lag, std)`` of each change seen through.
    """

    def __init__(self, wheel_resolution: float, backlash: float, period: float, longest_lag: float,
                 settle_time: float = 0.1) -> None:
        owner = "LagIdentifier"
        self.q = as_float(wheel_resolution, "wheel_resolution", owner, low=0.0, low_open=True)
        self.backlash = as_float(backlash, "backlash", owner, low=0.0)
        self.period = as_float(period, "period", owner, low=0.0, low_open=True)
        longest = as_float(longest_lag, "longest_lag", owner, low=0.0)
        self.delay = max(8.0 * longest, as_float(settle_time, "settle_time", owner, low=0.0))
        self.lag: float | None = None
        self.lag_std: float | None = None
        self.estimates: list[tuple[float, float]] = []
        self._change: dict[str, Any] | None = None
        self._last: tuple[float, np.ndarray, np.ndarray] | None = None   # (t, positions, command)
        self._initial: np.ndarray | None = None

    def start(self, initial: Any) -> None:
        """The speeds the motors had settled at before the first sample (None: the first
        command)."""
        self._initial = None if initial is None else np.array(initial, dtype=float)

    def push(self, t: float, wheels: Any, command: Any) -> None:
        """One sample: its time (s), wheel counts and the command sent then (m/s)."""
        x = cell_centre(np.asarray(wheels, dtype=float), self.q)
        u = np.asarray(command, dtype=float)
        last = self._last
        before = self._initial if last is None else last[2]
        if before is not None and u.tolist() != before.tolist():    # (lists: cheaper on a few contacts)
            # A change at this sample (the command acts from t on): finish the open one first.
            self._finish()
            self._change = {"t": t, "x": x.copy(), "v0": before.copy(), "u": u.copy(), "rows": []}
        elif self._change is not None and t - self._change["t"] >= self.delay:
            self._change["rows"].append((t, x.copy()))
        self._last = (t, x, u)

    def finish(self) -> float | None:
        """Close the open change (use its line so far); the pooled lag (s) or None."""
        self._finish()
        return self.lag

    def _finish(self) -> None:
        change, self._change = self._change, None
        if change is None or len(change["rows"]) < 3:
            return
        v0, u = change["v0"], change["u"]
        step = v0 - u
        use = np.abs(step) > 1e-9
        if not use.any():
            return
        times = np.array([r[0] for r in change["rows"]]) - change["t"]
        X = np.array([r[1] for r in change["rows"]])
        tbar = times.mean()
        tt = times - tbar
        S = float(tt @ tt)
        slope = (tt @ (X - X.mean(axis=0))) / S
        intercept = X.mean(axis=0) - slope * tbar                   # the line at the change
        # The play's shift of the encoder's line: half the play from rest, all of it at a
        # reversal, none when the motion keeps its sign.
        shift = -0.5 * (np.sign(u) - np.sign(v0)) * self.backlash
        # The law's displacement past its transient is linear in tau: its slope from the law.
        horizon = float(times[-1])
        slope_tau = self._tau_slope(v0, u, horizon)
        offset = intercept - change["x"] - shift                     # (v0 - u) tau, per wheel
        lags = offset[use] / slope_tau[use]
        weights = step[use] ** 2
        lag = float(weights @ lags / weights.sum())
        # Each intercept errs by the line's intercept error and the start reading's: q^2 / 12
        # (1 / m + tbar^2 / S) + q^2 / 12, white.
        m = times.size
        var_offset = quantization_variance(self.q) * (1.0 / m + tbar * tbar / S + 1.0)
        std = math.sqrt(var_offset / float(weights.sum()))
        self.estimates.append((lag, std))
        values = np.array(self.estimates)
        w = 1.0 / values[:, 1] ** 2
        self.lag = float(w @ values[:, 0] / w.sum())
        self.lag_std = float(1.0 / math.sqrt(w.sum()))

    @staticmethod
    def _tau_slope(v0: np.ndarray, u: np.ndarray, horizon: float) -> np.ndarray:
        """d/dtau of the motor law's displacement beyond ``u t`` at ``horizon`` (its
        transient over): ``v0 - u``, taken from the law at two small lags."""
        a, b = 1e-4, 2e-4
        da = MotorPiece.build(0.0, v0, u, a, math.inf).displacement(horizon) - u * horizon
        db = MotorPiece.build(0.0, v0, u, b, math.inf).displacement(horizon) - u * horizon
        return (db - da) / (b - a)


class MissedCountRate:
    """The missed-count rate's posterior from repairs over the transitions they could see, and
    from the ridden wheel's check.

    A Gamma posterior (shape ``a``, rate ``b``, 1 / transition) on ``p``: the prior
    ``Gamma(shape, shape / mean)`` (default: Jeffreys' shape 1/2, the rate's prior mean
    ``toolkit.model.truth.DEFAULT_MISSED``, its std ``sqrt(2)`` times that), then per
    sample ``a += repairs``, ``b += exposure``. Its mean and variance are ``a / b`` and ``a /
    b^2``; with no repair over ``E`` transitions the mean falls as ``1 / (2 E)``. Once the
    ridden wheel's check has read a sample (:class:`RideCheck`), its log-likelihood
    ``loglik`` on :attr:`GRID` multiplies that density, and the moments are sums over the
    grid (:func:`toolkit._compiled.imm.rate_moments`).

    Parameters
    ----------
    mean : float
        The prior's mean rate, ``> 0`` (per count transition).
    shape : float
        The prior's shape, ``> 0`` (its weight: ``shape`` pseudo-repairs).

    Attributes
    ----------
    repairs : int
        Repairs seen.
    exposure : float
        Count transitions read where a missed one would have been repaired.
    loglik : ndarray of shape (161,)
        The ridden wheel's check's log-likelihood of each rate of :attr:`GRID`.
    checked : int
        Samples the check has read.
    """

    #: The rates the check weighs, per transition: 20 a decade from 1e-10 to
    #: ``toolkit.model.truth.MAX_MISSED_MEAN`` (1e-2, far above what an encoder that works
    #: misses); a posterior whose mass lies above it is the Gamma alone.
    GRID = np.geomspace(1e-10, MAX_MISSED_MEAN, 161)
    LOG_GRID = np.log(GRID)

    def __init__(self, mean: float | None = None, shape: float = 0.5) -> None:
        owner = "MissedCountRate"
        mean = DEFAULT_MISSED if mean is None else mean
        self.prior_mean = as_float(mean, "mean", owner, low=0.0, high=MAX_MISSED_MEAN, low_open=True)
        self.prior_shape = as_float(shape, "shape", owner, low=0.0, low_open=True)
        self.repairs = 0
        self.exposure = 0.0
        self.loglik = np.zeros(self.GRID.size)
        self.checked = 0
        self._moments = np.empty(2)
        self._stale = True

    def push(self, repairs: int, exposure: float) -> None:
        """One sample's repairs and its exposure (transitions where a loss would show)."""
        if repairs:
            self.repairs += int(repairs)
            self._stale = True
        if exposure:
            self.exposure += float(exposure)
            self._stale = True

    def checked_sample(self) -> None:
        """The check added one sample's log-likelihood to ``loglik``."""
        self.checked += 1
        self._stale = True

    @property
    def shape(self) -> float:
        return self.prior_shape + self.repairs

    @property
    def rate(self) -> float:
        """The posterior's rate parameter (transitions)."""
        return self.prior_shape / self.prior_mean + self.exposure

    def _moment(self, which: int) -> float:
        if self._stale:
            if self.checked:
                kernels("imm", 4 * self.GRID.size).rate_moments(self.GRID, self.LOG_GRID, self.loglik, self.shape,
                                                                 self.rate, self._moments)
            else:
                self._moments[0] = self.shape / self.rate
                self._moments[1] = self.shape / self.rate ** 2
            self._stale = False
        return float(self._moments[which])

    @property
    def mean(self) -> float:
        """The posterior mean of ``p``."""
        return self._moment(0)

    @property
    def variance(self) -> float:
        """The posterior variance of ``p``."""
        return self._moment(1)


class RideCheck:
    """The missed-count rate's evidence from the body's counts against the wheel it rides (see
    the module).

    Push every sample with the contact the body rides (or None); a ride begins once that
    contact has moved one way by the gearbox play (the play operator passes no motion before:
    a reversal shifts the difference by the whole play), and ends when it stops, reverses or
    another contact is ridden. The check opens once the difference of the two positions has
    stayed level over :attr:`WINDOW` samples (its least-squares slope within :attr:`SLOPE` plus
    four of its standard deviations), and then adds each sample's log-likelihood of every rate
    to ``rate.loglik`` until the ride ends or the difference leaves level. The reads' noise
    variance is the difference's own, measured on the steps that end a level window
    (:attr:`read_variance`). The check reads only where the read noise is at least the
    quantizations' (:attr:`NOISE_OVER`): a quantization sawtooth alone passes for losses in the
    white model, and the exact lines see the losses there instead (docs/physics.md section 10).

    Parameters
    ----------
    central_count, wheel_count : float, m
        Distance per count of the body's encoder and of a wheel's (at the contact).
    rate : MissedCountRate
        Receives the evidence.
    period : float, s
        The sample period.
    backlash : float, m
        The wheels' gearbox play.
    """

    #: Samples over which a ride's difference must stay level before (and while) it counts.
    WINDOW = 25
    #: Slope of the difference (m/s) a ride allows besides its noise: a contact the body does
    #: not ride moves away from it at the contacts' spacing (11 mm/s on the carousel's brake).
    SLOPE = 2e-3
    #: The reads' noise variance over the quantizations' below which the check does not read.
    NOISE_OVER = 2.0

    def __init__(self, central_count: float, wheel_count: float, rate: MissedCountRate, period: float,
                 backlash: float = 0.0) -> None:
        self.qc, self.qw, self.rate, self.h = central_count, wheel_count, rate, period
        self.backlash = backlash
        self._ring = np.zeros(self.WINDOW)
        # The ride's readings, the window's two sums, the sums over the steps that end a level
        # window of the squared steps, the quantizations' share and the travel, those steps,
        # open (imm.ride_push).
        self._state = np.zeros(8)
        self._level = np.empty(rate.GRID.size)
        self._var = np.empty(rate.GRID.size)
        self._on: int | None = None
        self._sign = 0.0
        self._moved = 0.0

    def stop(self) -> None:
        """No ride now: the next ride starts afresh."""
        self._on = None
        self._sign = self._moved = 0.0
        self._state[0] = self._state[1] = self._state[2] = self._state[7] = 0.0

    @property
    def read_variance(self) -> float:
        """The variance ``R`` of the difference's reads, m^2: the quantizations' ``(q_c^2 +
        q_w^2) / 12`` plus half the mean square of its steps that end a level window less the
        quantizations' share (``alpha (1 - alpha)`` counts^2 a step, ``alpha`` the fraction
        of a count travelled per period) and the losses' at the rate's mean."""
        return float(kernels("imm").read_variance(self._state, self.qc, self.qw, self.rate.mean))

    def push(self, central: int, wheel: int, ridden: int | None, speed: float) -> None:
        """One sample: the body's count, the ridden wheel's count, which contact it rides
        (None: none) and that contact's speed (m/s)."""
        sign = 1.0 if speed > 0.0 else -1.0 if speed < 0.0 else 0.0
        if ridden is None or sign == 0.0 or not math.isfinite(speed):
            if self._on is not None:
                self.stop()
            return
        if ridden != self._on or sign != self._sign:
            self.stop()
            self._on, self._sign = ridden, sign
        travel = abs(speed) * self.h
        if self._moved < self.backlash:
            # The play is being taken up: the wheel's encoder does not follow yet.
            self._moved += travel
            return
        if kernels("imm", 10 * self._level.size).ride_push(
                self._state, self._ring, self._level, self._var, self.rate.GRID, self.rate.loglik,
                central * self.qc - wheel * self.qw, travel, self.qc, self.qw, self.h, self.SLOPE,
                self.NOISE_OVER, self.rate.mean):
            self.rate.checked_sample()
