"""The record of an exact run: the segments and events the kernels write (with the budget's
guards), the dense output read from them, and the contact speeds at any time (commanded, or
the closed-form tracks of lagging and rate-limited motors).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from .._compiled import budget_clock
from .._compiled import core as _core     # the kernels' source module (imports no numba)
from ..model import MotorPiece, PiecewiseConstant, Plant
from ._kernel import _kernels
from ._result import Budget, Event, SimulationStatus

_ZENO_FLOOR = 1000          # events a Zeno window holds beyond the per-interval cascade bound
_SUCCESS = SimulationStatus.SUCCESS  # (a module constant is faster to read than an Enum member)


# -- segment store, events and guards ---------------------------------------------------------
#: Event kind names by kernel code (toolkit._compiled.core: CROSS, STICK, RELEASE, ...).
_KIND_NAMES = ("cross", "stick", "release", "saturation", "command")
_KIND_CODES = {name: code for code, name in enumerate(_KIND_NAMES)}
_ROWS = 32                  # initial rows of the segment and event buffers (doubled on demand)
_MAX_CHUNK = 1 << 14        # kernel rounds between two looks at the wall clock
_STEP_CAP = (1 << 62)       # max_steps beyond this is unlimited in practice (an int64 count)


_INITIAL_STATES: dict[tuple[int, float, int], tuple[np.ndarray, np.ndarray]] = {}


class _Recorder:
    """Segments and events in growing buffers, and the budget (private, mutable while running).

    The kernels write rows into ``seg`` (segments ``(t0, V0, c1, B, lam, C, D)``) and ``ev``
    (events ``(t, kind code, contact or -1, V)``) and keep their counts and the loop state in
    ``istate`` / ``fstate`` (layout: :mod:`toolkit._compiled.core`). The buffers start small
    and double when a kernel pauses for room, so they hold what the run produced: at most
    two segment and two event rows per round, and a run has at most ``Budget.max_steps``
    rounds, and at most ``Budget.max_samples // 2`` (the memory cap: at most
    ``max_samples`` segments stored).
    """

    __slots__ = ("budget", "mu", "window", "seg", "ev", "fstate", "istate", "deadline",
                 "status", "detail", "output")

    def __init__(self, budget: Budget, cascade: int, mu: float) -> None:
        self.budget = budget
        self.mu = mu
        self.window = 2 * cascade + _ZENO_FLOOR
        self.seg = np.empty((_ROWS, 7))
        self.ev = np.empty((_ROWS, 4))
        key = (budget.max_steps, budget.max_samples, budget.max_event_rate, self.window)
        initial = _INITIAL_STATES.get(key)
        if initial is None:                       # the initial loop state of this budget
            fstate = np.zeros(_core.N_FSTATE)
            istate = np.zeros(_core.N_ISTATE, dtype=np.int64)
            istate[_core.I_STUCK] = -1
            istate[_core.I_HINT] = -1
            istate[_core.I_MAXSTEPS] = min(budget.max_steps, _STEP_CAP, max(budget.max_samples // 2, 1))
            istate[_core.I_WINDOW] = self.window
            istate[_core.I_CHUNK] = _MAX_CHUNK
            fstate[_core.F_RATE] = budget.max_event_rate
            if len(_INITIAL_STATES) > 64:
                _INITIAL_STATES.clear()
            initial = _INITIAL_STATES[key] = (fstate, istate)
        self.fstate, self.istate = initial[0].copy(), initial[1].copy()
        self.deadline = budget_clock() + budget.wall_time
        self.status = _SUCCESS
        self.detail = ""

    @property
    def n_segments(self) -> int:
        return int(self.istate[_core.I_NSEG])

    @property
    def n_events(self) -> int:
        return int(self.istate[_core.I_NEV])

    @property
    def n_evaluations(self) -> int:
        return int(self.istate[_core.I_NEVAL])

    @n_evaluations.setter
    def n_evaluations(self, value: int) -> None:
        self.istate[_core.I_NEVAL] = value

    def room(self) -> None:
        """Make sure the buffers have room for a few more rows (the kernel pauses when they
        could fill up within its next round; it sizes its chunks of rounds to fit)."""
        istate = self.istate
        free = min(self.seg.shape[0] - istate[_core.I_NSEG],
                   self.ev.shape[0] - istate[_core.I_NEV])
        if free < 16:
            for name, width in (("seg", 7), ("ev", 4)):
                old = getattr(self, name)
                new = np.empty((2 * old.shape[0] + 16, width))
                new[:old.shape[0]] = old
                setattr(self, name, new)

    def segment(self, t0: float, V0: float, B: float = 0.0, lam: float = 0.0, c1: float = 0.0,
                C: float = 0.0, D: float = 0.0) -> None:
        self.room()
        istate = self.istate
        istate[_core.I_NSEG] = _core.push_segment(self.seg, int(istate[_core.I_NSEG]), t0, V0,
                                                  c1, B, lam, C, D)

    def event(self, t: float, kind: str, contact: int | None, V: float) -> None:
        self.room()
        istate = self.istate
        istate[_core.I_NEV] = _core.push_event(self.ev, int(istate[_core.I_NEV]), t,
                                               _KIND_CODES[kind],
                                               -1 if contact is None else contact, V)

    def stop(self, t: float) -> bool:
        """Check the budget at simulated time ``t``; True when the run must stop."""
        istate = self.istate
        istate[_core.I_ROUNDS] += 1
        rounds = int(istate[_core.I_ROUNDS])
        if rounds > istate[_core.I_MAXSTEPS]:
            return self.stopped(_core.MAX_STEPS, t)
        if budget_clock() > self.deadline:
            return self.stopped(-1, t)
        code = _core.budget_code(rounds, int(istate[_core.I_MAXSTEPS]), self.ev,
                                 int(istate[_core.I_NEV]), self.window,
                                 float(self.fstate[_core.F_RATE]))
        return code != _core.DONE and self.stopped(code, t)

    def stopped(self, code: int, t: float) -> bool:
        """Record why the run stopped at ``t`` (a kernel code, -1 for the wall clock): True."""
        budget = self.budget
        if code == _core.MAX_STEPS:
            self.status = SimulationStatus.MAX_STEPS
            if budget.max_samples // 2 < budget.max_steps:     # the memory cap came first
                self.detail = (f"{int(self.istate[_core.I_NSEG])} segments stored, max_samples = "
                               f"{budget.max_samples}, at t = {t:.6g} s")
            else:
                self.detail = f"{budget.max_steps} rounds at t = {t:.6g} s"
        elif code == _core.ZENO:
            nev, w = self.n_events, self.window
            span = float(self.ev[nev - 1, 0] - self.ev[nev - 1 - w, 0])
            self.status = SimulationStatus.ZENO
            self.detail = f"{w} events within {span:.3g} s before t = {t:.6g} s"
        else:
            self.status = SimulationStatus.WALL_TIME
            self.detail = f"{budget.wall_time:g} s at t = {t:.6g} s"
        return True

    # -- output -----------------------------------------------------------------------------
    def field(self, name: str) -> Any:
        """A lazy field of the finished run's :class:`SimulationResult` (``events``,
        ``contact_speeds`` or ``dense``; ``SimulationResult._trusted``), from this record and
        ``output = (plant, times, t_stop, success, t_end, linear)``, set when the run ended
        (nothing writes to the buffers after that)."""
        plant, times, t_stop, success, t_end, linear = self.output
        if name == "events":
            return self.events()
        if name == "contact_speeds":
            return _contact_speeds(plant, times)
        return self.dense(t_stop, success, t_end, linear)

    def events(self) -> tuple[Event, ...]:
        """The recorded events as :class:`Event` objects."""
        n = int(self.istate[_core.I_NEV])
        if not n:
            return ()
        names, new, events = _KIND_NAMES, object.__new__, []
        for t, kind, contact, V in self.ev[:n].tolist():     # (Event._trusted, inlined)
            event = new(Event)
            event.__dict__.update(time=t, kind=names[int(kind)],
                                  contact=None if contact < 0 else int(contact), speed=V)
            events.append(event)
        return tuple(events)

    def drop_non_finite(self) -> tuple[float, float]:
        """Forget the trailing segments whose start is not finite (an overflowed run) and
        return the last finite ``(t0, V0)``."""
        seg, n = self.seg, self.n_segments
        while n > 1 and not (math.isfinite(seg[n - 1, 0]) and math.isfinite(seg[n - 1, 1])):
            n -= 1
        self.istate[_core.I_NSEG] = n
        return float(seg[n - 1, 0]), float(seg[n - 1, 1])

    def displacement(self, t_stop: float) -> float:
        """The exact integral of ``V`` (m) from the first segment's start to ``t_stop`` (s)
        (:func:`toolkit._compiled.core.displacement`)."""
        n = self.istate[_core.I_NSEG]
        return _kernels(2 * int(n)).displacement(self.seg, n, self.mu, t_stop)

    def dense(self, t_stop: float, success: bool, t_end: float, linear: bool) -> _Dense:
        """The dense output: a read-only view of the segment rows (the run is over: nothing
        writes to this buffer again)."""
        seg = self.seg
        seg.setflags(write=False)
        return _Dense(seg[:int(self.istate[_core.I_NSEG])], self.mu, t_stop, success, t_end,
                      linear)

    def samples(self, t_stop: float, V_stop: float,
                mass: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Segment starts and the final time: ``t`` (s), ``V`` (m/s) and the force ``m dV/dt``
        (N) from the right, exact, as fresh read-only arrays of shape (T,)."""
        n = self.istate[_core.I_NSEG]
        table = _kernels(2 * int(n)).samples(self.seg, n, self.mu, t_stop,
                                   V_stop, mass)
        table.setflags(write=False)
        return table[0], table[1], table[2]


class _Dense:
    """Exact ``V(t)`` from the stored closed-form segments (NaN past a stopped run's end).

    ``table`` holds one row ``(t0, V0, c1, B, lam, C, D)`` per segment; ``mu`` is the motor
    rate shared by all segments; ``linear`` says every row is a line ``V0 + B s`` (the
    engine that produced them knows it). Defined on ``[0, t_end]`` (the requested horizon);
    :meth:`SimulationResult.speed_at` refuses times outside it. Every evaluation is the one
    kernel :func:`toolkit._compiled.core.dense_values` (any order of times, any values).
    """

    __slots__ = ("table", "linear", "mu", "t_stop", "success", "t_end")

    def __init__(self, table: np.ndarray, mu: float, t_stop: float, success: bool,
                 t_end: float, linear: bool) -> None:
        self.table, self.mu, self.t_stop, self.success = table, mu, t_stop, success
        self.t_end, self.linear = t_end, linear

    def values(self, query: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(V, dV/dt)`` at ``query`` times (s, 1-d float64, any order and values): fresh
        arrays, m/s and m/s^2 (the right derivative)."""
        out = self.scaled(query, 1.0)
        return out[0], out[1]

    def scaled(self, query: np.ndarray, scale: float) -> np.ndarray:
        """Rows ``V`` (m/s) and ``scale dV/dt`` at ``query`` times (s, 1-d float64): one
        fresh array of shape (2, T)."""
        if query.flags.writeable or not query.flags.c_contiguous:
            query = np.ascontiguousarray(query).view()    # read-only: one kernel specialization
            query.setflags(write=False)
        out = np.empty((2, query.size))
        _kernels(2 * query.size).dense_values(self.table, self.mu, query, self.success,
                                              self.t_stop, scale, out)
        return out

    def linear_values(self, query: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
        """:meth:`values` when every segment is a straight line ``V0 + B s`` (``linear``),
        else None."""
        return self.values(query) if self.linear else None

    def sorted_values(self, query: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`values` (kept for callers that know their times are sorted)."""
        return self.values(query)

    def _anywhere(self, times: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`values` at any times (any shape, also non-finite or outside ``[0, t_end]``,
        where the closed forms may overflow quietly): ``(query, V, dV/dt)``."""
        query = np.asarray(times, dtype=float)
        V, dV = self.values(query.ravel())
        return query, V, dV

    def __call__(self, times: Any) -> np.ndarray:
        """Body speed at ``times`` (s, any shape), m/s."""
        query, V, _ = self._anywhere(times)
        return V.reshape(query.shape)

    def derivative(self, times: Any) -> np.ndarray:
        """Right derivative ``dV/dt`` at ``times`` (s, any shape), m/s^2."""
        query, _, dV = self._anywhere(times)
        return dV.reshape(query.shape)

    def gathered_values(self, query: np.ndarray) -> np.ndarray:
        """:meth:`__call__` at 1-d times in any order."""
        return self.values(np.asarray(query, dtype=float))[0]

    def gathered_derivative(self, query: np.ndarray) -> np.ndarray:
        """:meth:`derivative` at 1-d times in any order."""
        return self.values(np.asarray(query, dtype=float))[1]


# -- contact speeds in time: commanded, or the motors' closed-form tracks ----------------------
def _piece_bounds(plant: Plant, t_end: float) -> list[float]:
    if plant.commands is None and not isinstance(plant.external_force, PiecewiseConstant):
        return [0.0, t_end]
    switches = plant.switching_times()
    return [0.0, *switches[(switches > 0) & (switches < t_end)].tolist(), t_end]
def _motor_pieces(plant: Plant, t_end: float) -> list[tuple[float, float, MotorPiece]]:
    motors = plant.motors
    bounds = _piece_bounds(plant, t_end)
    v = plant.initial_speeds()
    pieces = []
    for a, b in zip(bounds[:-1], bounds[1:]):
        piece = MotorPiece.build(a, v, plant.command(a), motors.lag, motors.rate_limit)
        pieces.append((a, b, piece))
        v = piece.speeds(np.array([b - a]))[0]
    return pieces


def _motor_speeds(plant: Plant, times: np.ndarray) -> np.ndarray:
    """Exact contact speeds of dynamic motors at ``times`` (s): shape (T, n), m/s."""
    t_end = float(max(times.max(initial=0.0), 0.0)) or 1.0
    out = np.empty((times.size, plant.n))
    for a, b, piece in _motor_pieces(plant, t_end):
        inside = (times >= a) & ((times < b) | (b == t_end))
        out[inside] = piece.speeds(times[inside] - a)
    return out

def _contact_speeds(plant: Plant, times: np.ndarray) -> np.ndarray:
    """Contact speeds at ``times``: shape (T, n), read-only (a broadcast when constant)."""
    T = times.size
    if plant.commands is None:
        # Every row is the one speed vector: a zero-stride view of an immutable bytes copy
        # (read-only for good: a view of bytes cannot be made writeable).
        speeds = plant.command(0.0)
        return np.ndarray((T, speeds.size), buffer=speeds.tobytes(), strides=(0, speeds.itemsize))
    if plant.dynamic_motors:
        table = _motor_speeds(plant, times)
    else:
        low, high = plant.motors.speed_limits if plant.motors is not None else (-np.inf, np.inf)
        table = np.clip(plant.commands(times).reshape(T, plant.n), low, high)
    table.setflags(write=False)
    return table
