"""A body riding a settled contact, estimated from the exact set of lines its counts allow.

While the contacts hold their speeds and the body sticks to one of them (the carousel
cruising or braked), body and that contact's wheel move at one speed ``V``: the body passes
``X_a + V tau`` (``tau`` the time since the hold's first sample ``a``) and the wheel ``x_0 +
V tau'`` (``tau'`` since its window start). An ideal encoder reads ``c = floor(position /
q)``, so each reading confines the line's intercept and speed to a strip ``c q <= x + tau V <
(c + 1) q``, and the readings together to a convex polygon: exactly the lines that give these
counts (:mod:`toolkit._compiled.lines`).

Why not the white model. The quantization error of a body at constant speed is not noise
but a deterministic sawtooth ``q (frac(X_0 / q + k V h / q) - 1/2)`` (the Kalman filter's
module docstring): for most speeds it pins ``V`` far better than ``q^2 / 12`` white readings
would (the polygon's speed width falls like ``1 / k^2``, the white model's std like ``k^{-3/2}``),
and near a rational ``V h / q`` far worse (the pattern repeats and stops informing). A filter
with white ``R`` is then overconfident or underconfident depending on the grid phase, which
it cannot know. The polygon is the exact likelihood: with the grid phases uniform (the
encoders' zero is wherever the parts were at power-up) and no other prior, the posterior of
``(X_a, V)`` given that the body rides wheel ``i`` is uniform over the central polygon,
weighted by the width of wheel ``i``'s polygon at the same ``V`` (the wheel's intercept
integrated out). Which wheel the body rides is not assumed: the Gaussian filter's belief at
the hold's start gives the prior odds (``exp(-d_i^2 / 2)``, ``d_i`` the distance of wheel
``i``'s estimated speed from the body's in stds of their difference, floored at ``1e-300``
of the largest: the belief may be wrong), each wheel's evidence (the likelihood of the
central counts if the body rides it) updates them, and the filter's state is the mixture's
mean and covariance (:func:`~toolkit._compiled.lines.ride_moments`, exact). Wheels whose
speeds the counts exclude drop out; two wheels at nearly one speed share the weight.

Where the lines are exact. A wheel's window starts once the contacts hold their speeds
(``steady``), the motor law's remaining transient would move the contact by less than
:data:`TRANSIENT` counts, and, after a reversal (or a start from rest), the contact has
travelled the gearbox play since it turned (the encoder's play operator passes no motion
before). A wheel whose readings leave every line restarts its window there. A hold starts
only where the Gaussian filter has the body reach the equilibrium set after the wheels'
lines became exact (a body that meets an edge contact still settling towards it may stop
short inside a zero-force band and coast there, at a speed of its own). It ends when the
contacts move, and fails at a reading no line allows (or when no wheel's speeds meet the
body's, e.g. a hold begun before the body stuck): the filter's state then restarts from
what the reading and the one-period difference of the readings know, and the Gaussian
steps take the body until they see it reach the set again. A new outside force also ends a
hold. Not held, conservatively: a body that reached the set before the wheels' lines became
exact (the motors still settling) stays with the Gaussian model until it next arrives.

The hold needs ideal encoders (no read noise, no missed counts, no jitter), motors that
hold their speeds (``contact_drift = 0``), no drag, and the friction the model knows
(``friction_uncertainty = 0``: with an unknown spread the filter cannot tell that the body
stuck, it may still creep towards the weighted median); otherwise the filter keeps its
Gaussian model.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from .._compiled import kernels
from ..model.motors import MotorPiece
from ._input import EstimatorModel

#: Vertices a polygon may hold (a run of counts of one line allows at most a quadrilateral;
#: the starting box adds up to four).
CAPACITY = 16
#: A strip's bound within this many counts of a vertex takes it as on the bound (rounding;
#: positions of a 10 s run are about 1e4 counts, stored to 1e-16 relative).
TOLERANCE = 1e-8
#: The motor transient's remainder (the distance the motor law has still to travel beyond
#: its settled line) below which a wheel's line starts, in counts; the wheels' strips take
#: it as their tolerance (the polygon a thousandth of a count wider: no line is lost).
TRANSIENT = 1e-3
#: Half sides of the starting box (m of intercept, m/s of speed): any line; the first two
#: readings cut it to one count and ``2 q / h``.
_BOX = (1.0e3, 1.0e3)


def _box(poly: np.ndarray) -> None:
    bx, bv = _BOX
    poly[:4] = ((-bx, -bv), (bx, -bv), (bx, bv), (-bx, bv))


class WheelLines:
    """Each wheel's polygon of lines since its window started.

    Push every sample, in order, with the period that ends there (its track and whether the
    contacts held their speeds over it).

    Parameters
    ----------
    model : EstimatorModel
    """

    def __init__(self, model: EstimatorModel) -> None:
        n = model.n
        self._q = model.sensors.wheel.distance_per_count
        self._play = model.sensors.wheel.backlash
        self._lag = model.motor_lag
        self._tol = TRANSIENT * self._q      # the transient's remainder counts as on a bound
        self.polys = np.empty((n, CAPACITY, 2))
        self.counts = np.zeros(n, dtype=np.int64)
        self.starts = np.zeros(n)            # each window's first sample time, s
        self._first = np.zeros(n)            # each window's first reading, counts
        self._scratch = np.empty((CAPACITY, 2))
        self._out = np.empty((CAPACITY, 2))
        self.active = False
        self._change: tuple[float, np.ndarray, np.ndarray] | None = None   # (t, start, target)
        self._ready_at: float | None = -math.inf
        self._held: np.ndarray | None = None     # the speeds of the last steady period, m/s
        self._last: tuple[float, np.ndarray] | None = None

    def push(self, t: float, wheels: Any, track: np.ndarray | None, steady: bool) -> None:
        """Row at time ``t`` (s) with wheel counts ``wheels`` (copied); ``track`` and
        ``steady`` of the period ending at it (``track`` None for the first row)."""
        wheels = np.array(wheels, dtype=float)
        last, self._last = self._last, (t, wheels)
        if track is None:
            return
        if not steady:
            if self.active or self._change is None or not np.array_equal(track[1], self._change[2]):
                # A command change: the motors leave the speeds they held (without a lag the
                # track already starts at the target) towards a target (when their lines are
                # exact again is worked out once they settle).
                start = self._held if self._lag <= 0.0 and self._held is not None else track[0]
                self._change = (last[0], np.array(start), np.array(track[1]))
                self._ready_at = None
            self.active = False
            return
        self._held = track[0]
        if not self.active:
            t0, w0 = last
            if self._ready_at is None:
                self._ready_at = self._start_time() if self._change is not None else -math.inf
            if t0 < self._ready_at:
                return
            self.active = True
            self._restart(np.ones(self.counts.size, dtype=bool), t0, w0)
        self._extend(t, wheels)
        dead = self.counts <= 0
        if dead.any():
            # No line (or no room) for these readings: a new window from this row.
            self._restart(dead, t, wheels)

    def _restart(self, which: np.ndarray, t: float, wheels: np.ndarray) -> None:
        """New windows for the wheels ``which`` (bool mask) from the row at ``t`` (s)."""
        for i in np.flatnonzero(which):
            _box(self.polys[i])
        self.counts[which] = 4
        self.starts[which] = t
        self._first[which] = wheels[which]
        self._extend(t, wheels)

    def _start_time(self) -> float:
        """When every wheel's line is exact after the last change: the motor law's remainder
        under :data:`TRANSIENT` counts, and the gearbox play taken up after a reversal."""
        t_c, start, target = self._change
        lag, q, play = self._lag, self._q, self._play
        ready = t_c
        gap = np.abs(start - target)
        if lag > 0.0 and gap.max() * lag > TRANSIENT * q:
            # The lag law's remaining travel |start - target| lag exp(-s / lag) <= TRANSIENT q.
            ready = t_c + lag * math.log(gap.max() * lag / (TRANSIENT * q))
        turning = (start * target <= 0.0) & (target != 0.0)
        if play > 0.0 and turning.any() and lag <= 0.0:
            # Without a lag a motor turns at once and runs at its command: the play takes
            # play / |u|.
            ready = max(ready, t_c + play / float(np.abs(target[turning]).min()))
        elif play > 0.0 and turning.any():
            # A motor that turns (or starts from rest) passes no motion through the play until
            # it has travelled the play from where it turned: bisect the time at which every
            # turning motor has, on the motor law's own displacement (MotorPiece).
            piece = MotorPiece.build(0.0, start[turning], target[turning], lag, math.inf)
            v0, u = start[turning], target[turning]
            turn = lag * np.log((u - v0) / u)
            at_turn = np.array([piece.displacement(float(s_i))[i] for i, s_i in enumerate(turn)])

            def taken_up(s: float) -> bool:
                return bool(np.all((s >= turn) & (np.abs(piece.displacement(s) - at_turn) >= play)))

            lo = float(turn.max())
            hi = lo + play / float(np.abs(u).min()) + lag
            while not taken_up(hi):
                hi += play / float(np.abs(u).min()) + lag
            for _ in range(50):
                mid = 0.5 * (lo + hi)
                lo, hi = (lo, mid) if taken_up(mid) else (mid, hi)
            ready = max(ready, t_c + hi)
        return ready

    def _extend(self, t: float, wheels: np.ndarray) -> None:
        kernels("lines", 30 * self.counts.size).extend_lines(
            self.polys, self.counts, t, self.starts, wheels, self._first, self._q, self._tol,
            self._scratch, self._out)


class Hold:
    """The body on one line from sample ``a``, riding one of the wheels: polygon and moments.

    Parameters
    ----------
    q : float, m
        The central encoder's count.
    n : int
        Number of wheels.
    """

    def __init__(self, q: float, n: int) -> None:
        self._q = q
        self._tol = TOLERANCE * q
        self._polys = (np.empty((CAPACITY, 2)), np.empty((CAPACITY, 2)))
        self._scratch = np.empty((CAPACITY, 2))
        self._n = 0
        self._moments = np.zeros((n, 5))
        self.evidence = np.zeros(n)          # posterior weight of each wheel
        self._out = np.zeros(5)

    def start(self, t: float, count: int, prior: np.ndarray) -> None:
        """Begin at sample time ``t`` (s) with central ``count``; ``prior`` the odds of each
        wheel being the one the body rides."""
        self.t_a = t
        self.c_a = count
        self._prior = prior
        poly = self._polys[0]
        _box(poly)
        # The anchor's own reading: X_a in [c_a q, (c_a + 1) q), i.e. x in [0, q).
        self._n = kernels("lines", 1).clip_strip(poly, 4, 1.0, 0.0, 0.0, self._q, self._tol,
                                                 self._scratch, self._polys[1])
        self._polys = (self._polys[1], self._polys[0])

    def push(self, t: float, count: int, lines: WheelLines
             ) -> tuple[float, float, float, float, float] | None:
        """Take the central ``count`` read at ``t`` (s); the state's mean and covariance
        ``(X, V, P_XX, P_XV, P_VV)`` (m, m/s, m^2, m^2/s, (m/s)^2), or None when no line fits
        the counts or no wheel's speeds meet the body's (the hold fails)."""
        tau = t - self.t_a
        q = self._q
        lo = (count - self.c_a) * q
        K = kernels("lines", 300)
        poly, spare = self._polys
        n = K.clip_strip(poly, self._n, 1.0, tau, lo, lo + q, self._tol, self._scratch, spare)
        if n <= 0:
            return None
        if not K.ride_moments(spare, n, lines.polys, lines.counts, self._prior, self._moments,
                              self.evidence, self._out) > 0.0:
            return None
        self._polys = (spare, poly)
        self._n = n
        mx, mv, vxx, vxv, vvv = self._out.tolist()
        # (X, V) = A (x, v) + (c_a q + ..., 0) with A = [[1, tau], [0, 1]].
        return (self.c_a * q + mx + mv * tau, mv,
                vxx + 2.0 * tau * vxv + tau * tau * vvv, vxv + tau * vvv, vvv)
