"""A body riding a settled contact, estimated from the exact set of lines its counts allow.

While the contacts hold their speeds and the body sticks to one of them (contact ``i``, an
edge of the equilibrium set: the carousel cruising or braked), body and wheel ``i`` move at
one speed ``V``: the body passes ``X_a + V tau + r(tau)`` (``tau`` the time since the hold's
first sample ``a``) and the wheel ``x_0 + V tau' + r(tau')`` (``tau'`` since its window
start), ``r`` what remains of the last motor transient
(:func:`~toolkit.model.motors.transient_displacement` of the motor law's gap, known). An
ideal encoder reads ``c = floor(position / q)``, so each reading confines the line's
intercept and speed to a strip ``c q - r <= x + tau V < (c + 1) q - r``, and the readings
together to a convex polygon: exactly the lines that give these counts
(:mod:`toolkit._compiled.lines`).

Why not the white model. The quantization error of a body at constant speed is not noise
but a deterministic sawtooth ``q (frac(X_0 / q + k V h / q) - 1/2)`` (the Kalman filter's
module docstring): for most speeds it pins ``V`` far better than ``q^2 / 12`` white readings
would (the polygon's speed width falls like ``1 / k^2``, the white model's std like ``k^{-3/2}``),
and near a rational ``V h / q`` far worse (the pattern repeats and stops informing). A filter
with white ``R`` is then overconfident or underconfident depending on the grid phase, which
it cannot know. The polygon is the exact likelihood: with the grid phases uniform (the
encoders' zero is wherever the parts were at power-up) and no other prior, the posterior of
``(X_a, V)`` is uniform over the central polygon, weighted by the width of wheel ``i``'s
polygon at the same ``V`` (the wheel's intercept integrated out). Its mean and covariance
(:func:`~toolkit._compiled.lines.line_moments`, exact) are the filter's state while the hold
lasts; both the central and the wheel windows start only where the model is exact (the
contacts settled: ``steady``), and any reading outside every line the model allows (an
empty polygon: a motor that wandered, a count the model did not expect) ends the hold.

The hold needs ideal encoders (no read noise, no missed counts, no jitter) and motors that
hold their speeds (``contact_drift = 0``); otherwise the filter keeps its Gaussian model.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from .._compiled import kernels
from ..model.motors import transient_displacement
from ._input import EstimatorModel

#: Vertices a polygon may hold (a run of counts of one line allows a quadrilateral; the
#: starting box and rounding add a few).
CAPACITY = 32
#: Half sides of the starting box, m and m/s: any intercept and speed (the first two
#: readings cut it to one count and ``2 q / h``).
_BOX = (1.0e3, 1.0e3)


def _box(poly: np.ndarray) -> None:
    bx, bv = _BOX
    poly[:4] = ((-bx, -bv), (bx, -bv), (bx, bv), (-bx, bv))


class WheelLines:
    """Each wheel's polygon of lines since the contacts last settled.

    Push every sample, in order, with the period that ends there (its track and whether
    the contacts held their speeds over it). A steady period after a moving one starts the
    windows at its first sample; a moving period stops them.

    Parameters
    ----------
    model : EstimatorModel
    """

    def __init__(self, model: EstimatorModel) -> None:
        self.model = model
        n = model.n
        self._q = model.sensors.wheel.distance_per_count
        self._lag = model.motor_lag
        self.polys = np.empty((n, CAPACITY, 2))
        self.counts = np.zeros(n, dtype=np.int64)
        self._scratch = np.empty((CAPACITY, 2))
        self._out = np.empty((CAPACITY, 2))
        self.active = False
        self.t0 = math.nan
        self._c0 = np.zeros(n)
        self.ref = np.zeros(n)               # reference speeds of the windows, m/s
        self.gap0 = np.zeros(n)              # speed minus asymptote at t0 (motor law), m/s
        self._moving: tuple[float, np.ndarray] | None = None  # (end time, track) of the last moving period
        self._last: tuple[float, np.ndarray] | None = None

    def gap_at(self, t: float) -> np.ndarray:
        """Each contact's speed minus its settled speed at time ``t`` (s), m/s."""
        if self._lag <= 0.0 or not self.gap0.any():
            return np.zeros_like(self.gap0)
        return self.gap0 * math.exp(-(t - self.t0) / self._lag)

    def push(self, t: float, wheels: Any, track: np.ndarray | None, steady: bool) -> None:
        """Row at time ``t`` (s) with wheel counts ``wheels``; ``track`` and ``steady`` of
        the period ending at it (``track`` None for the first row)."""
        wheels = np.asarray(wheels)
        last, self._last = self._last, (t, wheels)
        if track is None:
            return
        if not steady:
            self.active = False
            self._moving = (t, track)
            return
        if not self.active:
            t0, w0 = last
            self.active = True
            self.t0 = t0
            self._c0 = np.asarray(w0, dtype=float)
            self.ref = np.array(track[0], dtype=float)
            # The motors ended their last moving period a motor-law gap away from the speeds
            # they settle at; it decays with the lag into the window.
            moving = self._moving
            if moving is None or self._lag <= 0.0:
                self.gap0 = np.zeros_like(self.ref)
            else:
                end, track_moving = moving
                gap = self.model.end_speeds(track_moving) - track_moving[1]
                self.gap0 = gap * math.exp(-(t0 - end) / self._lag)
            for i in range(self.polys.shape[0]):
                _box(self.polys[i])
            self.counts[:] = 4
            self._extend(0.0, self._c0)
        self._extend(t - self.t0, wheels)

    def _extend(self, tau: float, wheels: Any) -> None:
        transient = transient_displacement(1.0, tau, self._lag) if self._lag > 0.0 else 0.0
        kernels("lines", 30 * self.counts.size).extend_lines(
            self.polys, self.counts, tau, wheels, self._c0, self.ref, self._q, self.gap0, transient,
            self._scratch, self._out)


class Hold:
    """The body riding contact ``i`` from sample ``a``: its polygon and the moments.

    Parameters
    ----------
    q : float, m
        The central encoder's count.
    lag : float, s
        The motors' lag (for the transient's remainder).
    """

    def __init__(self, q: float, lag: float) -> None:
        self._q = q
        self._lag = lag
        self._polys = (np.empty((CAPACITY, 2)), np.empty((CAPACITY, 2)))
        self._scratch = np.empty((CAPACITY, 2))
        self._n = 0
        self._moments = np.zeros(5)
        self.contact = -1

    def start(self, t: float, count: int, contact: int, lines: WheelLines) -> None:
        """Begin at sample time ``t`` (s) with central ``count`` on ``contact`` (its wheel
        window in ``lines`` already under way)."""
        self.t_a = t
        self.c_a = count
        self.contact = contact
        self.ref = float(lines.ref[contact])
        self.gap = float(lines.gap_at(t)[contact])
        poly = self._polys[0]
        _box(poly)
        # The anchor's own reading: X_a in [c_a q, (c_a + 1) q), i.e. x' in [0, q).
        self._n = kernels("lines", 1).clip_strip(poly, 4, 1.0, 0.0, 0.0, self._q, self._scratch,
                                                 self._polys[1])
        self._polys = (self._polys[1], self._polys[0])
        self._tau = 0.0
        self.step_input = (0.0, 0.0)

    def push(self, t: float, count: int, lines: WheelLines
             ) -> tuple[float, float, float, float, float] | None:
        """Take the central ``count`` read at ``t`` (s); the state's mean and covariance
        ``(X, V, P_XX, P_XV, P_VV)`` (m, m/s, m^2, m^2/s, (m/s)^2), or None when no line fits
        the counts (the hold ends)."""
        tau = t - self.t_a
        q = self._q
        r = 0.0
        if self.gap != 0.0:
            r = transient_displacement(self.gap, tau, self._lag)
        lo = (count - self.c_a) * q - self.ref * tau - r
        K = kernels("lines", 300)
        poly, spare = self._polys
        n = K.clip_strip(poly, self._n, 1.0, tau, lo, lo + q, self._scratch, spare)
        i = self.contact
        if n <= 0 or lines.counts[i] <= 0:
            return None
        weight = K.line_moments(spare, n, lines.polys[i], lines.counts[i], self._moments)
        if not weight > 0.0:
            return None
        self._polys = (spare, poly)
        self._n = n
        # x+ = F x + u over the step from the previous sample (F = [[1, dt], [0, 1]]): what
        # the transient's remainder adds beyond the straight line.
        before, self._tau = self._tau, tau
        if self.gap != 0.0:
            g0 = self.gap * math.exp(-before / self._lag)
            self.step_input = (transient_displacement(g0, tau - before, self._lag) - (tau - before) * g0,
                               g0 * math.expm1(-(tau - before) / self._lag))
        else:
            self.step_input = (0.0, 0.0)
        mx, mv, vxx, vxv, vvv = self._moments.tolist()
        speed = self.ref + mv
        residual_speed = self.gap * math.exp(-tau / self._lag) if self.gap != 0.0 else 0.0
        # (X, V) = A (x', v') + offsets with A = [[1, tau], [0, 1]].
        return (self.c_a * q + mx + speed * tau + r, speed + residual_speed,
                vxx + 2.0 * tau * vxv + tau * tau * vvv, vxv + tau * vvv, vvv)
