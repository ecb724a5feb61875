"""A body riding a settled contact, estimated from the exact set of lines its counts allow.

While the contacts hold their speeds and the body sticks to one of them, body and that
contact's wheel move on one straight line: each ideal reading confines the line to a strip,
the readings to a convex polygon (:mod:`toolkit._compiled.lines`), and the posterior of
``(X, V)`` with uniform grid phases is uniform over it, mixed over the wheels the body may
ride by their evidence. :class:`WheelLines` keeps each wheel's polygon; :class:`HoldLayer` is
the optional layer of a filter's step that uses them. Needs ideal encoders, motors that
hold their speeds, no drag and known friction. Derivations: docs/estimation.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..laws import cell_centre, quantization_variance
from .._compiled import kernels
from ..model.motors import lag_settling_time
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
#: Readings a wheel's line must have held before a reading that leaves it may be repaired as a
#: missed count (:meth:`WheelLines.push`).
REPAIR_AFTER = 5
#: How far behind the line's positions a reading must lie to be repaired, counts.
REPAIR_GAP = 0.25
#: Half sides of the starting box (m of intercept, m/s of speed): any line; the first two
#: readings cut it to one count and ``2 q / h``.
_BOX = (1.0e3, 1.0e3)
#: Its corners, counter-clockwise (the polygons' first four rows).
_CORNERS = np.array(((-_BOX[0], -_BOX[1]), (_BOX[0], -_BOX[1]), (_BOX[0], _BOX[1]), (-_BOX[0], _BOX[1])))


def _behind(poly: np.ndarray, n: int, tau: float, lo: float, q: float, direction: float) -> bool:
    """The reading's strip ``[lo, lo + q)`` lies at least :data:`REPAIR_GAP` counts behind
    (against ``direction``) every position ``x + tau v`` the polygon's lines reach at ``tau``."""
    return bool(kernels("lines", n).behind(poly, n, tau, lo, q, direction, REPAIR_GAP))


class WheelLines:
    """Each wheel's polygon of lines since its window started.

    Push every sample, in order, with the period that ends there (its track and whether the
    contacts held their speeds over it).

    Parameters
    ----------
    model : EstimatorModel
    tell_missed : bool
        Tell a missed count apart from a broken line even where it is not repaired, and
        measure the exposure there too (see :meth:`push`: the missed-count rate's evidence).
    """

    def __init__(self, model: EstimatorModel, tell_missed: bool = False) -> None:
        n = model.n
        self.tell_missed = bool(tell_missed)
        self._q = self.wheel_count = model.sensors.wheel.distance_per_count
        self._play = model.sensors.wheel.backlash
        self._lag = model.motor_lag
        self._period = model.sensors.period
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
        self._motion: np.ndarray | None = None   # the contacts' directions at this row
        self._repair = False
        self._gaps = np.empty(n)
        self._repairable = self._told = np.zeros(n, dtype=bool)
        #: Per row: lines that broke; of those, the missed counts told apart (not repaired);
        #: the transitions read where a lost one would have been told apart.
        self.deaths = self.spared = 0
        self.exposure = 0.0
        #: Per wheel: the transitions read since its window started where a lost one would not
        #: have been repaired (:meth:`_seen` false): a loss there is absorbed (measured with
        #: ``repair`` or :attr:`tell_missed`, else 0).
        self.unseen = np.zeros(n)

    def push(self, t: float, wheels: Any, track: np.ndarray | None, steady: bool,
             repair: bool = False) -> np.ndarray | None:
        """Row at time ``t`` (s) with wheel counts ``wheels`` (copied); ``track`` and
        ``steady`` of the period ending at it (``track`` None for the first row).

        With ``repair``, a wheel whose reading leaves every line of its window but whose
        reading one count further along its motion (``sign`` of its speed) does not is taken
        to have missed a count (the counter lost a transition for good): its line goes on
        with the repaired reading. Returns the counts added to each wheel's reading from
        now on (ints, shape (n,); None when nothing was repaired).

        Without ``repair`` such a wheel's window restarts (a death); with :attr:`tell_missed`
        it is counted in :attr:`spared`. With ``repair`` or :attr:`tell_missed`,
        :attr:`exposure` is the transitions read where a lost one would have been told apart
        (:meth:`_seen`)."""
        wheels = np.array(wheels, dtype=float)
        self._repair = repair
        # The motion's direction only where the repair (or telling a loss apart) reads it.
        self._motion = None if track is None or not (repair or self.tell_missed) else np.sign(track[0])
        self.repaired = None
        self.deaths = self.spared = 0
        self.exposure = 0.0
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
        seen = self._seen(t, wheels) if self._motion is not None else None
        self._extend(t, wheels, seen is not None)
        dead = self.counts <= 0
        if seen is not None:
            # The transitions read where a lost one would have been repaired (the repaired
            # readings' steps: the true transitions), for the rate's identification.
            self.exposure = kernels("lines", self.counts.size).seen_steps(wheels, last[1], seen, self.counts,
                                                                              self.unseen)
            if self.spared and seen.any():
                # Told apart, not repaired: their true transitions are one more.
                self.exposure += float(np.abs(wheels + self._motion - last[1])[self._told].sum())
        self.deaths = int(np.count_nonzero(dead))
        if self.deaths:
            # No line (or no room) for these readings: a new window from this row.
            self._restart(dead, t, wheels)
        return self.repaired

    def _seen(self, t: float, wheels: np.ndarray) -> np.ndarray:
        """Per wheel, before its line takes the reading at ``t``: a reading one count short of
        this one (against the motion) would be repaired in :meth:`_extend` (the line has held
        :data:`REPAIR_AFTER` readings and reaches :data:`REPAIR_GAP` counts past that
        reading's cell, :func:`_behind`). Whether a transition is lost is drawn apart from
        all of this, so the repairs over the transitions read where this holds count the
        rate without bias (:class:`~toolkit.estimation.MissedCountRate`)."""
        q, n = self._q, self.counts.size
        # And whether this reading itself, should it leave its line, would be repaired: the
        # reach past its own cell is a count less than past the short one.
        seen, self._repairable = np.empty(n, dtype=bool), np.empty(n, dtype=bool)
        kernels("lines", 10 * n).reach_seen(self.polys, self.counts, t, self.starts, wheels, self._first, q,
                                            self._motion, REPAIR_AFTER * self._period, REPAIR_GAP * q,
                                            (1.0 + REPAIR_GAP) * q, self._gaps, seen, self._repairable)
        return seen

    def _restart(self, which: np.ndarray, t: float, wheels: np.ndarray) -> None:
        """New windows for the wheels ``which`` (bool mask) from the row at ``t`` (s)."""
        self.polys[which, :4] = _CORNERS
        self.counts[which] = 4
        self.unseen[which] = 0.0
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
        if lag > 0.0:
            # The lag law's remaining travel under TRANSIENT counts.
            ready = t_c + lag_settling_time(float(gap.max()), lag, TRANSIENT * q)
        turning = (start * target <= 0.0) & (target != 0.0)
        if play > 0.0 and turning.any() and lag <= 0.0:
            # Without a lag a motor turns at once and runs at its command: the play takes
            # play / |u|.
            ready = max(ready, t_c + play / float(np.abs(target[turning]).min()))
        elif play > 0.0 and turning.any():
            # A motor that turns (or starts from rest) passes no motion through the play until
            # it has travelled the play from where it turned: bisect the time at which every
            # turning motor has, on the motor law's own displacement (core.play_take_up_time
            # on core.motor_displacement, MotorPiece.displacement's closed form compiled).
            v0, u = start[turning], target[turning]
            turn = lag * np.log((u - v0) / u)
            step = play / float(np.abs(u).min()) + lag
            hi = kernels("core", 60 * (12 + u.size)).play_take_up_time(
                np.ascontiguousarray(v0), np.ascontiguousarray(u), lag, turn, play, step)
            ready = max(ready, t_c + hi)
        return ready

    def _extend(self, t: float, wheels: np.ndarray, gapped: bool = False) -> None:
        """Clip each live line by its reading; where one dies, the repair (or telling a loss
        apart) of :meth:`push` (``gapped``: :meth:`_seen` has measured this row's reach; a
        restart's clip, which no line fails, passes False)."""
        before = self.counts.copy() if gapped else None
        kernels("lines", 30 * self.counts.size).extend_lines(
            self.polys, self.counts, t, self.starts, wheels, self._first, self._q, self._tol,
            self._scratch, self._out)
        if gapped and self.counts.min() <= 0:
            # Only lines that held for REPAIR_AFTER readings: a count missed by an encoder
            # that otherwise reads exactly, not noise that breaks lines within a few samples.
            # A missed count leaves the reading a whole count behind the line's range; a line
            # that only bends (a wandering motor) misses it by a sliver.
            dead = (self.counts == 0) & self._repairable       # the tests, from _seen
            if dead.any():
                # A failed clip leaves the polygon's rows untouched: retry the dead wheels
                # with their reading one count along the motion.
                shift = np.where(dead, self._motion, 0.0)
                counts = np.where(dead, before, 0)
                kernels("lines", 30 * int(dead.sum())).extend_lines(
                    self.polys, counts, t, self.starts, wheels + shift, self._first, self._q, self._tol,
                    self._scratch, self._out)
                fixed = dead & (counts > 0)
                if not self._repair:
                    # Told apart, not repaired: the window restarts (its rows are rebuilt).
                    self.spared = int(np.count_nonzero(fixed))
                    self._told = fixed
                elif fixed.any():
                    self.counts[fixed] = counts[fixed]
                    wheels[fixed] += shift[fixed]
                    self.repaired = np.where(fixed, shift, 0.0).astype(np.int64)


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
        poly[:4] = _CORNERS
        # The anchor's own reading: X_a in [c_a q, (c_a + 1) q), i.e. x in [0, q).
        self._n = kernels("lines", 1).clip_strip(poly, 4, 1.0, 0.0, 0.0, self._q, self._tol,
                                                 self._scratch, self._polys[1])
        self._polys = (self._polys[1], self._polys[0])

    def behind(self, t: float, count: int, direction: float) -> bool:
        """The reading ``count`` at ``t`` lies at least half a count behind (against
        ``direction``) every position the hold's lines reach then (:func:`_behind`)."""
        return _behind(self._polys[0], self._n, t - self.t_a, (count - self.c_a) * self._q, self._q, direction)

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


@dataclass(frozen=True)
class HoldStep:
    """What the hold layer did at one sample.

    Attributes
    ----------
    failed : bool
        The reading left every line (or no wheel's speeds meet the body's): the hold ended.
    state : ndarray of shape (2,)
        The body's ``(X, V)`` after the sample (m, m/s): the posterior's mean on a hold; on a
        failure, what the reading and the one-period difference of the readings know.
    covariance : ndarray of shape (2, 2)
        Its covariance (exact on a hold; ``(q^2 / 12) [[1, 1 / dt], [1 / dt, 2 / dt^2]]`` on a
        failure, the reading's error being in both).
    nis : float
        The reading's NIS against the straight line's prediction from the prior, with the
        count's ``q^2 / 12``.
    repaired : int
        Counts added to the central reading (and to every later one): 1 or -1 where the
        reading left every line but the reading one count further along the motion did not
        (a missed count, with ``repair``); 0 otherwise.
    """

    failed: bool
    state: np.ndarray
    covariance: np.ndarray
    nis: float
    repaired: int = 0


class HoldLayer:
    """The exact holds as one optional layer of a filter's step (predict, layer, update).

    The filter pushes every sample's wheel counts (:meth:`wheels`); where it believes the
    body rides a settled contact it lets the layer start a hold, and while a hold lasts the
    layer's posterior replaces the filter's Gaussian update (:meth:`step`). Which conditions
    allow a start is the filter's to say (the nominal filter: the body reached the set after
    the wheels' lines became exact; the adaptive one: its consistency monitor passes and its
    modes say stuck).

    Parameters
    ----------
    model : EstimatorModel
    tell_missed : bool
        Of the wheels' lines (:class:`WheelLines`).
    """

    def __init__(self, model: EstimatorModel, tell_missed: bool = False) -> None:
        self.lines = WheelLines(model, tell_missed)
        self._q = model.sensors.central.distance_per_count
        self._h = model.sensors.period
        self._hold = Hold(self._q, model.n)
        self.holding = False
        #: Whether a central count lost at the last :meth:`step` would have been repaired (a
        #: hold that goes on, with ``repair``, whose lines reach :data:`REPAIR_GAP` counts past
        #: the cell one count short), and the transitions read there (0 elsewhere).
        self.exposure = 0
        self.seen = False
        #: The central transitions read since the hold started where a lost one would not have
        #: been repaired: a loss there is absorbed.
        self.unseen = 0.0
        self.started = math.nan

    def wheels(self, t: float, wheels: Any, track: np.ndarray | None, steady: bool,
               repair: bool = False) -> np.ndarray | None:
        """Push one sample's wheel counts with the period ending at it (:meth:`WheelLines.push`;
        with ``repair`` the counts it adds to missed wheels, else None)."""
        return self.lines.push(t, wheels, track, steady, repair)

    @property
    def evidence(self) -> np.ndarray:
        """Of the hold: each wheel's posterior weight of being the one the body rides."""
        return self._hold.evidence

    @property
    def ready(self) -> bool:
        """The wheels' lines are exact (the contacts settled since the last change)."""
        return self.lines.active

    def stop(self) -> None:
        """End a hold (the contacts or the outside force changed, or the filter says so)."""
        self.holding = False
        self.exposure = 0
        self.seen = False

    def step(self, t: float, count: int, anchor: tuple[float, int], speeds: np.ndarray, var_v: float,
             x: tuple[float, float], P: np.ndarray, start: bool, repair: bool = False) -> HoldStep | None:
        """The layer at one sample: continue the hold, or start one when ``start`` (from the
        previous sample ``anchor = (time, count)``), and push the reading.

        Parameters
        ----------
        t : float, s
        count : int
            The central count read at ``t``.
        anchor : tuple of (float, int)
            Time and central count of the previous sample.
        speeds : ndarray of shape (n,), m/s
            The contacts' estimated speeds; with ``var_v`` ((m/s)^2) and the prior belief in
            the body's speed ``x[1]`` (variance ``P[1, 1]``) they give the prior odds of the
            wheels (``exp(-d_i^2 / 2)`` in stds of the difference, floored at 1e-300 of the
            largest: the counts may show the belief wrong).
        x, P : the prior ``(X, V)`` at the previous sample and its covariance (2, 2).
        repair : bool
            Take a reading that leaves every line, but would not one count further along the
            motion, as a missed count (:attr:`HoldStep.repaired`).

        Returns
        -------
        HoldStep or None
            None when no hold runs at this sample (the filter's Gaussian update follows).
        """
        hold, q, h = self._hold, self._q, self._h
        self.exposure = 0
        self.seen = False
        # A loss at this reading would show (and be repaired): the hold goes on and its lines
        # reach past the cell one count short (the repair's own test, on that reading).
        seen = repair and self.holding and x[1] != 0.0 and hold.behind(
            t, count - (1 if x[1] > 0.0 else -1), 1.0 if x[1] > 0.0 else -1.0)
        if not self.holding:
            if not start:
                return None
            d2 = (speeds - x[1]) ** 2 / (P[1, 1] + var_v)
            hold.start(anchor[0], anchor[1], np.maximum(np.exp(-0.5 * (d2 - d2.min())), 1e-300))
            self.unseen = 0.0
            self.started = anchor[0]
        z = cell_centre(count, q)
        innovation = z - (x[0] + h * x[1])
        nis = innovation * innovation / (P[0, 0] + 2.0 * h * P[0, 1] + h * h * P[1, 1] + quantization_variance(q))
        state = hold.push(t, count, self.lines)
        repaired = 0
        if state is None and repair and x[1] != 0.0 and hold.behind(t, count, 1.0 if x[1] > 0.0 else -1.0):
            # A failed push leaves the polygons untouched: the reading one count along.
            repaired = 1 if x[1] > 0.0 else -1
            state = hold.push(t, count + repaired, self.lines)
            if state is None:
                repaired = 0
        if state is None:
            self.holding = False
            dt = t - anchor[0]
            restart = quantization_variance(q) * np.array([[1.0, 1.0 / dt], [1.0 / dt, 2.0 / (dt * dt)]])
            return HoldStep(True, np.array([z, (count - anchor[1]) * q / dt]), restart, nis)
        self.holding = True
        if seen:
            self.seen = True
            self.exposure = abs(count + repaired - anchor[1])
        else:
            self.unseen += abs(count + repaired - anchor[1])
        X, V, pxx, pxv, pvv = state
        return HoldStep(False, np.array([X, V]), np.array([[pxx, pxv], [pxv, pvv]]), nis, repaired)
