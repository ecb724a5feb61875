"""The exact event-driven method: closed-form segments between events, Filippov sliding modes.

Between events every segment is ``V(t0 + s) = V0 + c1 s + B expm1_ratio(lam, s) +
C expm1_ratio(mu, s) + D s exp(-mu s)``; events (crossings, sticks, releases, saturations,
command switches) are found as first roots of closed-form functions. This module holds the
landscapes (Coulomb staircase, compliant piecewise-linear force), the recorder of segments
and events, the dense output, and the drivers of the kernels :func:`toolkit._compiled.core.ideal_piece`
(ideal motors) and :func:`toolkit._compiled.core.dynamic_run` (lagging or rate-limited
motors). The derivation, the tie and Zeno rules: docs/physics.md, section 11.
"""

from __future__ import annotations

import math
import weakref
from dataclasses import dataclass
from types import ModuleType
from typing import Any

import numpy as np

from .. import _compiled
from .._compiled import budget_clock
from .._compiled import core as _core     # the kernels' source module (imports no numba)
from ..model import ContactSet, MotorPiece, PiecewiseConstant, Plant, compliant_breakpoints
from ..laws import tie_tolerance
from ._result import Budget, Event, SimulationResult, SimulationStatus, status_message

__all__ = ["simulate_exact"]

_ZENO_FLOOR = 1000          # events a Zeno window holds beyond the per-interval cascade bound
_ROOT_WORK = 15             # interpreted work (about us) of the first-root search per function
_SUCCESS = SimulationStatus.SUCCESS  # (a module constant is faster to read than an Enum member)
_EMPTY = np.empty(0)
_EMPTY.setflags(write=False)
_NO_FIRST = np.empty(0, dtype=np.int64)      # (never written: the kernel caches nothing in it)
_COMPILED: list[ModuleType] = []     # the kernel module, once compiled in this process


def _kernels(work: int = 0) -> Any:
    """The kernel module :mod:`toolkit._compiled.core` to call: compiled, or its source run as
    Python while the process has not done enough work to pay for compiling
    (:func:`toolkit._compiled.kernels`; ``work``: this call's, about one unit per
    interpreted microsecond)."""
    if _COMPILED:
        return _COMPILED[0]
    module = _compiled.kernels("core", work)
    if "core" in _compiled.loaded():
        _COMPILED.append(module)
    return module


# -- closed forms (the kernels' own source, run as Python by the dynamic-motor engine) --------
_scalar_expm1_ratio = _core.expm1_ratio
_expm1_ratio_integral = _core.expm1_ratio_integral
_reach_time = _core.reach_time


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


# -- the force landscape of constant contact speeds ----------------------------------------
# Both landscapes answer the ideal engine's three questions: where is ``V``, what is the force
# and its slope inside an interval (:meth:`force`), and what holds at a breakpoint
# (:meth:`stiction`, :meth:`contact`); the kernel (toolkit._compiled.core.ideal_piece) asks
# them of the arrays in ``args``. Interval ``j`` is ``(xs[j-1], xs[j])`` (``xs[-1] = -inf``,
# ``xs[K] = +inf``).
class _CoulombLandscape:
    """The staircase of Coulomb contacts, read from the prefix sums a :class:`ContactSet`
    already holds (its sorted distinct speeds and the magnitudes below / above each).

    Nothing is rebuilt: each event reads two prefix sums, snapped to zero within
    ``4 (K + 1) eps F_tot`` (the rule of :attr:`ContactSet.tie_tolerance`). Breakpoint ``k``
    holds the stiction magnitude ``W = below[k+1] - below[k]``; the other contacts push with
    ``G``, the mean of the two plateaus beside it.
    """

    __slots__ = ("total", "first", "args", "_contacts")
    kind = "cross"

    def __init__(self, contacts: ContactSet) -> None:
        # The private prefix sums of ContactSet (levels, below, above: its _table) are exactly
        # the staircase; reading them spares an O(N log N) sort per new plant.
        table = contacts._table
        K = table.shape[1] - 1
        self.total = contacts._prefix_total        # F_tot as the prefix sums add it up
        # The lowest contact per level, filled by the kernel as events need it; few contacts
        # are scanned instead (toolkit._compiled.core.lowest_contact): no array needed.
        self.first = np.full(K, -1, dtype=np.int64) if contacts.n > _core.SMALL else _NO_FIRST
        self._contacts = contacts
        self.args = (True, K, table, self.first, contacts.speeds, contacts.forces, self.total)

    @property
    def levels(self) -> np.ndarray:
        return self._contacts._levels

    @property
    def below(self) -> np.ndarray:
        return self._contacts._below

    @property
    def above(self) -> np.ndarray:
        return self._contacts._above

    @property
    def xs(self) -> list[float]:
        """The breakpoints: the distinct speeds of the touching contacts, ascending, m/s."""
        return self.levels.tolist()

    @property
    def _tol(self) -> float:
        return tie_tolerance(self.levels.size, self.total)

    def force(self, j: int, V: float) -> tuple[float, float]:
        """Force (N) at ``V`` inside interval ``j`` (the plateau), and its slope: 0."""
        return _core.net_force(float(self.above[j]), float(self.below[j]), self._tol), 0.0

    def stiction(self, k: int) -> tuple[float, float]:
        """``(W, G)`` at breakpoint ``k``: stiction magnitude there and the others' push, N."""
        above, below, tol = self.above, self.below, self._tol
        lower = _core.net_force(float(above[k]), float(below[k]), tol)
        upper = _core.net_force(float(above[k + 1]), float(below[k + 1]), tol)
        push = 0.5 * (lower + upper)
        return float(below[k + 1] - below[k]), (push if abs(push) > tol else 0.0)

    def contact(self, k: int) -> int:
        """The lowest index of the touching contacts at breakpoint ``k``."""
        contacts = self._contacts
        return int(_core.lowest_contact(contacts._table, contacts.speeds, contacts.forces,
                                        self.first, k))


class _CompliantLandscape:
    """Force-speed map of compliant contacts: saturation limits ``v_i +- k f_i`` as
    breakpoints, the force linear between them (``base_F[j] + slope[j] (V - base_x[j])``
    in interval ``j``). Breakpoints hold no stiction; ``G[k]`` is the force there."""

    __slots__ = ("x", "G", "first", "base_x", "base_F", "slope", "total", "args")
    kind = "saturation"

    def __init__(self, plant: Plant, speeds: np.ndarray) -> None:
        x, at_x, first, slope, total = compliant_breakpoints(speeds, plant.contacts.forces,
                                                             plant.compliance)
        self.x, self.G, self.first, self.slope, self.total = x, at_x, first, slope, total
        self.base_x = np.concatenate(([x[0]], x))
        self.base_F = np.concatenate(([total], at_x))
        self.base_F[-1] = -total
        K = x.size
        land = np.zeros((5, K + 1))            # the kernel's table (toolkit._compiled.core)
        land[0, :K], land[1], land[2], land[3], land[4, :K] = x, self.base_F, slope, \
            self.base_x, at_x
        land.setflags(write=False)             # (read-only like ContactSet._table: one kernel)
        self.args = (False, K, land, first.astype(np.int64), _EMPTY, _EMPTY, total)

    @property
    def xs(self) -> list[float]:
        return self.x.tolist()

    def force(self, j: int, V: float) -> tuple[float, float]:
        """Force (N) at ``V`` inside interval ``j``, and its slope ``dF/dV`` (N s/m)."""
        slope = float(self.slope[j])
        base = float(self.base_F[j])
        return (base if slope == 0 else base + slope * (V - float(self.base_x[j])), slope)

    def stiction(self, k: int) -> tuple[float, float]:
        """``(0, G)``: no stiction at a saturation limit, the force there, N."""
        return 0.0, float(self.G[k])

    def contact(self, k: int) -> int:
        """The lowest index of the contacts saturating at breakpoint ``k``."""
        return int(self.first[k])


_Landscape = _CoulombLandscape | _CompliantLandscape


# The exact method's own cache (a Plant holds no solver state): per plant, the landscape of
# each distinct command, so repeated simulations of one plant skip rebuilding them. Keyed
# weakly: a plant's entry goes with the plant.
_LANDSCAPES: weakref.WeakKeyDictionary[Plant, dict[bytes | None, _Landscape]] = (
    weakref.WeakKeyDictionary())


def clear_cache(plant: Plant) -> None:
    """Forget the landscapes cached for ``plant``: its next run pays what a new plant would
    (benchmarks time runs from scratch this way)."""
    _LANDSCAPES.pop(plant, None)


def _build_landscape(plant: Plant, speeds: np.ndarray | None) -> _Landscape:
    """The landscape of contact speeds ``speeds`` (m/s; ``None``: the plant's own constant
    contact speeds)."""
    if plant.compliance > 0:
        return _CompliantLandscape(plant, plant.contacts.speeds if speeds is None else speeds)
    contacts = plant.contacts
    return _CoulombLandscape(contacts if speeds is None else contacts.with_speeds(speeds))


def _landscape(plant: Plant, a: float) -> _Landscape:
    """The landscape of the contact speeds commanded at time ``a`` (s), kept in this module's
    cache (one entry per plant and distinct command)."""
    cache = _LANDSCAPES.get(plant)
    if cache is None:
        cache = _LANDSCAPES[plant] = {}
    constant = plant.commands is None and plant.motors is None
    speeds = None if constant else plant.command(a)
    key = None if constant else speeds.tobytes()
    land = cache.get(key)
    if land is None:
        land = cache[key] = _build_landscape(plant, speeds)
    return land


# -- the ideal-motor engine -------------------------------------------------------------------
def _piece_bounds(plant: Plant, t_end: float) -> list[float]:
    if plant.commands is None and not isinstance(plant.external_force, PiecewiseConstant):
        return [0.0, t_end]
    switches = plant.switching_times()
    return [0.0, *switches[(switches > 0) & (switches < t_end)].tolist(), t_end]


def _run_ideal(plant: Plant, t_end: float, v0: float, rec: _Recorder) -> tuple[float, float]:
    """Integrate with piecewise-constant contact speeds; returns the final ``(t, V)``."""
    bounds = _piece_bounds(plant, t_end)
    V = v0
    stuck: int | None = None         # contact the body is stuck to (Coulomb only)
    for a, b in zip(bounds[:-1], bounds[1:]):
        land = _landscape(plant, a)
        if a > 0:
            rec.event(a, "command", None, V)
        t, V, stuck, stopped = _ideal_piece(plant, land, plant.external(a), a, b, V, stuck, rec)
        if stopped:
            return t, V
    return t_end, V


def _ideal_piece(plant: Plant, land: _Landscape, E: float, a: float, b: float, V: float,
                 stuck: int | None, rec: _Recorder) -> tuple[float, float, int | None, bool]:
    """Integrate over ``[a, b]`` (s) with constant contact speeds (landscape ``land``) and
    external force ``E`` (N) from speed ``V`` (m/s), the body stuck to contact ``stuck`` (or
    None); the one engine of :func:`simulate_exact` and :func:`advance`: the compiled
    :func:`toolkit._compiled.core.ideal_piece`, resumed while it pauses (to grow the buffers
    and look at the wall clock).

    Returns
    -------
    (t, V, stuck, stopped)
        The time and speed reached (``b`` unless the budget stopped the run, then
        ``stopped``), and the contact the body is stuck to there.
    """
    fstate, istate = rec.fstate, rec.istate
    fstate[0] = a                                   # (core.F_T, F_V, I_STUCK, I_STARTED)
    fstate[1] = V
    istate[2] = -1 if stuck is None else stuck
    istate[7] = 0
    code = _kernels(20).ideal_piece(*land.args, plant.mass, plant.damping, E, b, fstate,
                                    istate, rec.seg, rec.ev)
    return _finish_piece(plant, land, E, b, rec, code)


def _finish_piece(plant: Plant, land: _Landscape, E: float, b: float, rec: _Recorder,
                  code: int) -> tuple[float, float, int | None, bool]:
    """Resume the kernel's piece (state in ``rec``) while it pauses, looking at the wall clock
    and growing the buffers; then :func:`_ideal_piece`'s ``(t, V, stuck, stopped)``."""
    fstate, istate = rec.fstate, rec.istate
    if code == _core.DONE and _COMPILED and budget_clock() <= rec.deadline:
        k = int(istate[2])                          # (the common case, written out)
        return b, float(fstate[1]), (None if k < 0 else k), False
    while True:
        if code == _core.PAUSE:
            if budget_clock() > rec.deadline:
                code = -1
            else:
                rec.room()
                code = _kernels().ideal_piece(*land.args, plant.mass, plant.damping, E, b,
                                              fstate, istate, rec.seg, rec.ev)
                continue
        elif code == _core.DONE and budget_clock() > rec.deadline:
            code = -1
        break
    if not _COMPILED:
        _compiled.charge(10 * int(istate[5]))         # (core.I_ROUNDS) interpreted rounds
    t, V, k = float(fstate[0]), float(fstate[1]), int(istate[2])
    stuck = None if k < 0 else k
    if code != _core.DONE:
        return t, V, stuck, rec.stopped(code, t)
    return b, V, stuck, False


# -- dynamic motors: closed-form motor tracks -------------------------------------------------
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


# -- dynamic motors: first root of the event functions --------------------------------------
@dataclass(frozen=True)
class _EventFunctions:
    """Event functions ``g(s) = alpha + beta s + gamma expm1_ratio(lam, s)
    + delta expm1_ratio(mu, s) + D s exp(-mu s)`` (vectors of coefficients, scalars ``lam``,
    ``mu``, ``D``): what :func:`_first_root` searches. Their value, slope and inflection are
    the kernels :func:`toolkit._compiled.core.event_value`, ``event_slope`` and
    ``event_inflection``."""

    alpha: np.ndarray
    beta: np.ndarray
    gamma: np.ndarray
    delta: np.ndarray
    lam: float
    mu: float
    D: float = 0.0

    def inflection(self) -> np.ndarray:
        """The root of ``g''`` of each function (at most one), NaN where there is none
        (:func:`toolkit._compiled.core.event_inflection`)."""
        kernel = _kernels(10 * self.gamma.size).event_inflection
        lam, mu, D = self.lam, self.mu, self.D
        return np.array([kernel(g, d, lam, mu, D)
                         for g, d in zip(self.gamma, self.delta)])


def _first_root(fns: _EventFunctions, horizon: float) -> tuple[float, int]:
    """Earliest ``s`` in ``(0, horizon]`` (s) at which some ``g_i`` changes sign or reaches
    zero, and the index ``i`` (``(inf, -1)`` when none does), to a few ulp at any time scale:
    the kernel :func:`toolkit._compiled.core.first_root` (brackets on the monotone pieces of
    each ``g_i``, bisection at any scale, then Newton's or Brent's method; with many
    functions a bound on ``|g_i'|`` first discards those that cannot change sign soon)."""
    # (Interpreted, about 14 us per function searched: at most 65 after the prefilter.)
    n = fns.alpha.size
    s, i = _kernels(_ROOT_WORK * min(n, _core.SMALL + 1) + n).first_root(
        fns.alpha, fns.beta, fns.gamma, fns.delta, fns.lam, fns.mu, fns.D, horizon)
    return float(s), int(i)


# -- dynamic motors: the engine ----------------------------------------------------------------
#: Relative margin of the no-event certificate (about 4500 ulp): far above the rounding of the
#: engine's event functions and tie tests (a few ulp, ``64 eps``, ``4 (N + 1) eps``), so that a
#: certified piece is one the engine would also run as one segment without an event
#: (:func:`toolkit._compiled.core.quiet_piece`).
_QUIET_MARGIN = 2.0 ** -40
#: Interpreted work (about us) of one round of the dynamic-motor engine, and per contact.
_ROUND_WORK, _CONTACT_WORK = 60, 12


class _DynamicPlant:
    """What the dynamic-motor engine reads of a plant, read once (the plant is frozen): the
    magnitudes and one array of constants (:data:`toolkit._compiled.core.P_TOTAL` ..
    ``P_MARGIN``), and whether the no-event certificate of :func:`advance` applies (Coulomb
    contacts, motors with a lag)."""

    __slots__ = ("forces", "params", "quiet", "tau", "rate", "mu", "n", "__weakref__")

    def __init__(self, plant: Plant) -> None:
        motors = plant.motors
        self.forces = np.ascontiguousarray(plant.contacts.forces, dtype=float)
        self.n = self.forces.size
        self.tau, self.rate = motors.lag, motors.rate_limit
        self.mu = 1.0 / motors.lag if motors.lag > 0 else 0.0
        self.quiet = plant.compliance == 0 and motors.lag > 0
        params = np.empty(_core.N_PARAMS)
        params[_core.P_TOTAL] = float(plant.contacts.total_force)
        params[_core.P_MASS] = plant.mass
        params[_core.P_DAMPING] = plant.damping
        params[_core.P_COMPLIANCE] = plant.compliance
        params[_core.P_TAU] = motors.lag
        params[_core.P_RATE] = motors.rate_limit
        # Gap |u - v| above which a motor ramps at its rate limit (MotorPiece.build), and a
        # bound on |u| for clipped commands (inf without finite speed limits).
        params[_core.P_RAMP_GAP] = motors.rate_limit * motors.lag
        params[_core.P_SPEED_BOUND] = max(abs(motors.speed_limits[0]), abs(motors.speed_limits[1]))
        params[_core.P_MARGIN] = _QUIET_MARGIN
        params.setflags(write=False)
        self.params = params

    def run(self, bounds: np.ndarray, commands: np.ndarray, externals: np.ndarray,
            motor: np.ndarray, rec: _Recorder) -> int:
        """:func:`toolkit._compiled.core.dynamic_run` from the state in ``rec``: one call, or
        more while it pauses (the wall clock looked at, the buffers grown); returns its code
        (-1: the wall clock ran out)."""
        p = self.params
        n_rounds = int(rec.istate[_core.I_ROUNDS])
        work = (bounds.size - 1) * (_ROUND_WORK + _CONTACT_WORK * self.n)
        while True:
            code = _kernels(work).dynamic_run(
                self.forces, p[_core.P_TOTAL], p[_core.P_MASS], p[_core.P_DAMPING],
                p[_core.P_COMPLIANCE], self.tau, self.rate, bounds, commands, externals, motor,
                rec.fstate, rec.istate, rec.seg, rec.ev)
            if code != _core.PAUSE:
                break
            if budget_clock() > rec.deadline:
                return -1
            rec.room()
        if not _COMPILED:                 # the rounds run interpreted count towards compiling
            rounds = int(rec.istate[_core.I_ROUNDS]) - n_rounds
            _compiled.charge(rounds * (_ROUND_WORK + _CONTACT_WORK * self.n))
        if code == _core.DONE and budget_clock() > rec.deadline:
            return -1
        return code


_DYNAMIC_PLANTS: weakref.WeakKeyDictionary[Plant, _DynamicPlant] = weakref.WeakKeyDictionary()
_DYNAMIC_LAST: list[Any] = [None, None]  # the last plant asked for (a weak reference), its entry


def _dynamic_plant(plant: Plant) -> _DynamicPlant:
    """The per-plant constants of the dynamic-motor engine (cached weakly; a closed loop
    steps one plant, so the last one is kept at hand)."""
    last, entry = _DYNAMIC_LAST
    if last is not None and last() is plant:
        return entry
    entry = _DYNAMIC_PLANTS.get(plant)
    if entry is None:
        entry = _DYNAMIC_PLANTS[plant] = _DynamicPlant(plant)
    _DYNAMIC_LAST[:] = weakref.ref(plant), entry
    return entry


def _run_dynamic(plant: Plant, t_end: float, v0: float, rec: _Recorder) -> tuple[float, float]:
    """Integrate with lagging / rate-limited motors: one kernel call over every piece of
    constant command (:func:`toolkit._compiled.core.dynamic_run`); returns the final
    ``(t, V)``."""
    dyn = _dynamic_plant(plant)
    bounds = np.array(_piece_bounds(plant, t_end))
    starts = bounds[:-1]
    low, high = plant.motors.speed_limits
    commands = np.ascontiguousarray(np.clip(plant.commands(starts).reshape(starts.size, plant.n),
                                            low, high), dtype=float)
    ext = plant.external_force
    externals = (np.asarray(ext(starts), dtype=float).reshape(starts.size)
                 if isinstance(ext, PiecewiseConstant) else np.full(starts.size, float(ext)))
    motor = np.empty((5, plant.n))
    motor[_core.M_START] = plant.initial_speeds()
    rec.fstate[_core.F_V] = v0
    code = dyn.run(bounds, commands, externals, motor, rec)
    t, V = float(rec.fstate[_core.F_T]), float(rec.fstate[_core.F_V])
    if code != _core.DONE:
        rec.stopped(code, t)
        return t, V
    return t_end, V


# -- entry point ------------------------------------------------------------------------------
def simulate_exact(plant: Plant, t_end: float, *, v0: float, t_eval: np.ndarray | None,
                   budget: Budget) -> SimulationResult:
    """Simulate ``plant`` exactly (event-driven closed forms); see the module docstring.

    Parameters
    ----------
    plant : Plant
    t_end : float, s
    v0 : float, m/s
    t_eval : ndarray of shape (T,) or None, s
        Sample times; ``None``: the start of every closed-form segment (``0``, every event
        time, and with dynamic motors the ends of their ramp phases) and the final time.
    budget : Budget

    Returns
    -------
    SimulationResult
        ``dense`` evaluates the stored closed forms at any time (exactly); ``force`` is
        ``m dV/dt`` from the right (the Filippov force actually applied).
    """
    started = budget_clock()
    # Motors start settled, so with constant commands their speeds never move: the
    # ideal-motor engine (O(log N) per event) is exact for them too.
    dynamic = plant.dynamic_motors and plant.commands is not None
    mu = 1.0 / plant.motors.lag if dynamic and plant.motors.lag > 0 else 0.0
    n = plant.n
    rec = _Recorder(budget, 2 * n + 2, mu)
    m = plant.mass
    table = times = None
    if t_eval is not None:
        if t_eval.flags.writeable:
            times = t_eval.copy()
            times.setflags(write=False)
        else:
            times = t_eval
    if dynamic:
        t_stop, V_stop = _run_dynamic(plant, t_end, v0, rec)
    elif (times is not None and plant.commands is None
          and not isinstance(plant.external_force, PiecewiseConstant)):
        # One piece and sample times: one kernel call runs it and evaluates the dense output
        # (toolkit._compiled.core.ideal_run); Python only assembles the result.
        if plant.motors is None and n <= _core.SMALL:
            # Nothing to build or keep: the landscape is the ContactSet's own staircase.
            land: _Landscape = _CoulombLandscape(plant.contacts)
        else:
            land = _landscape(plant, 0.0)
        E = plant.external(0.0)
        rec.fstate[1] = v0                        # (core.F_V; t = 0, free, a new piece)
        table = np.empty((2, times.size))
        code = _kernels(20 + 2 * times.size).ideal_run(
            *land.args, m, plant.damping, E, t_end, rec.fstate, rec.istate, rec.seg, rec.ev,
            times, table)
        if code == _core.DONE and _COMPILED and budget_clock() <= rec.deadline:
            t_stop, V_stop = t_end, float(rec.fstate[1])          # (the common case)
        else:
            if code != _core.DONE:
                table = None                      # paused or stopped: evaluated below
            t_stop, V_stop, _, _ = _finish_piece(plant, land, E, t_end, rec, code)
    else:
        t_stop, V_stop = _run_ideal(plant, t_end, v0, rec)
    if rec.status is _SUCCESS and not (math.isfinite(t_stop) and math.isfinite(V_stop)):
        # Finite parameters (Plant refuses overflowing rates) can still overflow over a long
        # horizon, e.g. a huge external force for 1e10 s: report it, never as a success.
        rec.status = SimulationStatus.FAILED
        rec.detail = (f"the body speed left the floating-point range (V = {V_stop:g} m/s "
                      f"at t = {t_stop:g} s); shorten t_end or rescale the forces")
        t_stop, V_stop = rec.drop_non_finite()   # keep the finite part (up to its last segment)
    status = rec.status
    success = status is _SUCCESS
    # The ideal engine's segments are lines unless drag or compliance gives them a slope.
    linear = not dynamic and plant.damping == 0 and plant.compliance == 0
    if times is None:
        # Segment starts (events, switches, motor phase changes) and the end: exact values.
        times, V, force = rec.samples(t_stop, V_stop, m)
    else:
        if table is None or not success:
            table = rec.dense(t_stop, success, t_end, linear).scaled(times, m)  # V, m dV/dt
            if not success:
                table[1, np.isnan(table[0])] = np.nan
        table.setflags(write=False)
        V, force = table[0], table[1]                  # (indexing: faster than unpacking)
    istate = rec.istate
    n_events = int(istate[4])                          # (core.I_NEV, I_NEVAL, I_NSEG)
    rec.output = (plant, times, t_stop, success, t_end, linear)
    # Every array above is fresh and read-only, every count an int: no re-validation. The
    # events, the contact-speed table and the dense output are built from ``rec`` on first
    # access (SimulationResult._trusted): a caller that reads only t, V and force never pays.
    return SimulationResult._trusted({
        "method": "exact", "setting": "event-driven closed form", "t": times, "V": V,
        "force": force, "status": status,
        "message": status_message(status, rec.detail if not success else f"{n_events} events"),
        "n_events": n_events, "n_evaluations": int(istate[6]), "n_steps": int(istate[3]),
        "wall_time": budget_clock() - started, "_source": rec})


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
