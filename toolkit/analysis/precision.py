"""Work-precision report: every simulation method against the exact one, error versus run time.

:func:`precision_report` runs each method of :mod:`toolkit.simulation` over a range of
tolerances, step sizes and smoothing widths (``default_settings``) on one plant, measures
its error against the exact event-driven solution and its run time, and flags the failure
modes that make plain integrators unfit for Coulomb contacts (see :class:`PrecisionRow` for the
precise definitions). ``work_precision_curves`` gives the data of the log-log plot (error
against run time); :func:`exact_speedup` the speed ratio the acceptance criterion
asks for. The reference scene, :func:`toolkit.model.carousel.carousel_startup_plant`, lives
with the model.

The exact method itself is checked against an independent solution computed in rational
arithmetic (``rational_trajectory``), so its error is measured, not assumed zero.

Pure numerics: no files, no matplotlib.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import timeit
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from fractions import Fraction
from typing import Any

import numpy as np

from .._compiled import budget_clock
from .._compiled import warm
from ..errors import as_float, as_int
from ..model import PiecewiseConstant, Plant
from ..errors import ParameterError, ParameterTypeError, SolverError, parameter_message
from ..shortfall import Shortfall
from ..simulation import METHODS, Budget, SimulationResult, SimulationStatus, clear_cache, simulate

__all__ = [
    "MethodSetting", "PrecisionRow", "PrecisionReport", "Speedup", "WorkPrecisionCurve",
    "precision_report", "default_settings", "work_precision_curves", "exact_speedup",
    "precision_shortfalls", "rational_trajectory", "ERROR_LEVEL",
    "CHATTER_MARGIN", "STEP_COLLAPSE_RATIO", "STEP_COLLAPSE_RUN", "CREEP_TOLERANCE",
    "MOTION_FLOOR", "EVALUATION_POINTS", "evaluation_times",
]

#: Speed increments at or below ``MOTION_FLOOR * max(1, max|V|)`` (m/s) count as no motion
#: when direction reversals are counted (a few ulps of rounding are not chattering).
MOTION_FLOOR = 1e-12
#: ``chattering``: more direction reversals than the exact solution has at the same times, plus this.
CHATTER_MARGIN = 3
#: ``step_collapse``: an adaptive solver takes at least ``STEP_COLLAPSE_RUN`` consecutive steps ...
STEP_COLLAPSE_RUN = 1000
#: ... each shorter than this fraction of the horizon ``t_end``.
STEP_COLLAPSE_RATIO = 1e-6
#: Methods with adaptive step control, whose sample times are their steps when t_eval is None.
#: (casadi's SUNDIALS steps are internal: it reports on its output grid only.)
_ADAPTIVE = ("rk45", "lsoda", "radau", "bdf")
#: ``creep``: deviation (m/s) inside a zero-force band, where the exact solution is constant.
CREEP_TOLERANCE = 1e-6
#: Each timing repeat runs a method back to back until it has used at least this long (s).
_MIN_REPEAT_TIME = 0.02
#: A first run at least this long (s) counts as a timing repeat.
_WARM_RUN = 0.2
#: Uniform times on [0, t_end] of the common evaluation grid (with the exact event times).
EVALUATION_POINTS = 1001
#: The accuracy the report is asked for (m/s): the speedup compares the exact method with the
#: fastest reference method reaching ``max_error <= ERROR_LEVEL``.
ERROR_LEVEL = 1e-6
_BUDGET_STALLING = Budget(wall_time=1.0, max_steps=300_000)
#: Most steps kept by the untimed own-steps run of an adaptive solver (``step_collapse``).
_OWN_STEPS = 2**22
_BUDGET_SMOOTH = Budget(wall_time=3.0, max_steps=2_000_000)


# -- independent exact reference -------------------------------------------------------------
def _rational_supported(plant: Plant) -> bool:
    return (plant.damping == 0.0 and plant.commands is None and plant.motors is None
            and not isinstance(plant.external_force, PiecewiseConstant))


def rational_trajectory(plant: Plant, v0: float, times: Any) -> np.ndarray:
    """The exact Coulomb trajectory in rational arithmetic, rounded once to float at the end.

    An event-driven solution written independently of :mod:`toolkit.simulation._exact`: the
    speeds, magnitudes, mass, external force, ``v0`` and the query times are converted exactly
    to :class:`fractions.Fraction`; forces are summed exactly (no tie snapping), so every
    crossing and sticking time is an exact rational number.

    Parameters
    ----------
    plant : Plant
        Constant commands, ideal motors, no drag, constant external force.
    v0 : float, m/s
    times : array_like of shape (T,), s, ``>= 0``

    Returns
    -------
    ndarray of shape (T,), m/s
        ``V(times)``, each within half an ulp of the exact value.
    """
    if not _rational_supported(plant):
        raise ParameterError(parameter_message(
            "plant", "rational_trajectory",
            "have constant commands, ideal motors, no drag and a constant external force", plant))
    grouped: dict[Fraction, Fraction] = {}
    for speed, force in zip(plant.contacts.speeds.tolist(), plant.contacts.forces.tolist()):
        if force > 0:
            key = Fraction(speed)
            grouped[key] = grouped.get(key, Fraction(0)) + Fraction(force)
    levels = sorted(grouped)
    weights = [grouped[s] for s in levels]
    mass, ext = Fraction(plant.mass), Fraction(float(plant.external_force))
    query = np.asarray(times, dtype=float)
    horizon = Fraction(float(query.max())) if query.size else Fraction(0)
    # segments: (start time, start speed, acceleration), last one runs forever
    segments: list[tuple[Fraction, Fraction, Fraction]] = []
    t, V = Fraction(0), Fraction(float(v0))
    while True:
        below = sum((w for s, w in zip(levels, weights) if s < V), Fraction(0))
        above = sum((w for s, w in zip(levels, weights) if s > V), Fraction(0))
        at = sum((w for s, w in zip(levels, weights) if s == V), Fraction(0))
        push = above - below + ext                      # force of everything not at V
        if at > 0 and abs(push) <= at:
            segments.append((t, V, Fraction(0)))         # sticks for ever
            break
        net = push - at if push > 0 else push + at if push < 0 else push
        if net == 0:
            segments.append((t, V, Fraction(0)))         # coasts in a zero-force band
            break
        ahead = [s for s in levels if (s > V if net > 0 else s < V)]
        segments.append((t, V, net / mass))
        if not ahead or t > horizon:
            break
        target = min(ahead) if net > 0 else max(ahead)
        t, V = t + (target - V) * mass / net, target
    starts = [s[0] for s in segments]
    out = np.empty(query.size)
    for i, tq in enumerate(query.tolist()):
        tq_r = Fraction(tq)
        j = max(k for k, start in enumerate(starts) if start <= tq_r) if tq_r >= 0 else 0
        t0, V0, acc = segments[j]
        out[i] = float(V0 + acc * (tq_r - t0))
    return out


# -- settings ---------------------------------------------------------------------------------
@dataclass(frozen=True)
class MethodSetting:
    """One method with one setting and the budget it runs under.

    Parameters
    ----------
    method : str
        One of :data:`toolkit.simulation.METHODS`.
    options : mapping of str to value
        Method options (``rtol``, ``epsilon``, ``step``, ...), stored as sorted pairs.
    budget : Budget
    """

    method: str
    options: tuple[tuple[str, Any], ...] = ()
    budget: Budget = field(default_factory=Budget)

    def __post_init__(self) -> None:
        if self.method not in METHODS:
            raise ParameterError(parameter_message(
                "method", "MethodSetting", f"be one of {list(METHODS)}", self.method))
        options = self.options
        if isinstance(options, Mapping):
            options = tuple(sorted(options.items()))
        object.__setattr__(self, "options", tuple(tuple(pair) for pair in options))
        if not isinstance(self.budget, Budget):
            raise ParameterTypeError(parameter_message(
                "budget", "MethodSetting", "be a Budget", self.budget))

    @property
    def kwargs(self) -> dict[str, Any]:
        """The options as keyword arguments of :func:`toolkit.simulation.simulate`."""
        return dict(self.options)


def default_settings(*, quick: bool = False) -> tuple[MethodSetting, ...]:
    """The tolerance, step-size and smoothing sweep of the report.

    ``sign`` runs of the adaptive solvers get a 1 s budget (they are expected to stall);
    the others 3 s. ``quick=True`` keeps one or two settings per method (for tests).
    """
    def s(method: str, budget: Budget = _BUDGET_SMOOTH, **options: Any) -> MethodSetting:
        return MethodSetting(method, tuple(sorted(options.items())), budget)

    stalling = _BUDGET_STALLING
    if quick:
        return (
            s("exact"),
            s("rk45", Budget(wall_time=0.3, max_steps=50_000), friction="sign", rtol=1e-6, atol=1e-9),
            s("radau", friction="tanh", epsilon=1e-4, rtol=1e-8, atol=1e-12),
            s("moreau", step=1e-3),
            s("casadi", integrator="cvodes", friction="tanh", epsilon=1e-6, rtol=1e-10, atol=1e-12),
        )
    rows = [s("exact")]
    for rtol in (1e-3, 1e-6, 1e-9):
        rows.append(s("rk45", stalling, friction="sign", rtol=rtol, atol=rtol * 1e-3))
    rows.append(s("lsoda", stalling, friction="sign", rtol=1e-6, atol=1e-9))
    for eps in (1e-2, 1e-4):
        rows.append(s("rk45", friction="tanh", epsilon=eps, rtol=1e-6, atol=1e-9))
    rows.append(s("lsoda", friction="tanh", epsilon=1e-6, rtol=1e-6, atol=1e-9))
    for solver in ("lsoda", "radau", "bdf"):
        for eps in (1e-4, 1e-6, 1e-8):
            rows.append(s(solver, friction="tanh", epsilon=eps, rtol=1e-8, atol=1e-12))
    rows.append(s("radau", friction="stribeck", epsilon=1e-6, rtol=1e-8, atol=1e-12))
    for step in (1e-2, 1e-3, 1e-4, 1e-5):
        rows.append(s("moreau", step=step))
    for integrator in ("cvodes", "idas"):          # loose and tight tolerances: the fastest
        for eps in (1e-4, 1e-6, 1e-8):             # run reaching an error level may be either
            for rtol, atol in ((1e-6, 1e-9), (1e-10, 1e-12)):
                rows.append(s("casadi", integrator=integrator, friction="tanh", epsilon=eps,
                              rtol=rtol, atol=atol))
    rows.append(s("casadi", integrator="cvodes", friction="stribeck", epsilon=1e-6,
                  rtol=1e-10, atol=1e-12))
    return tuple(rows)


# -- rows, report -----------------------------------------------------------------------------
def _json_float(value: float | None) -> float | None:
    return None if value is None or not math.isfinite(value) else float(value)


@dataclass(frozen=True)
class PrecisionRow:
    """One method at one setting: its error, cost and failure flags.

    Attributes
    ----------
    method, setting : str
        As in :class:`~toolkit.simulation.SimulationResult` (``setting`` lists the options).
    max_error : float, m/s
        ``max |V - V_exact|`` over the report's common evaluation times (up to where the run
        stopped): the exact event times together with 1001 uniform times on ``[0, t_end]``,
        which every method is asked for through ``t_eval`` (see :func:`precision_report`).
        ``V_exact`` is ``rational_trajectory`` when the plant is within what it supports,
        otherwise the exact method's dense output; the exact row itself is measured against
        the rational reference only (``nan`` when the plant is outside what it supports).
    final_error : float, m/s
        ``|V(t_end) - V_exact(t_end)|``; ``inf`` when the run stopped before ``t_end``.
    wall_time : float, s
        Minimum over the repeats of the run time of one call of ``simulate`` from scratch
        (the exact method's cache for the plant emptied before each call): after a first and a second
        (warm) call, each repeat times back-to-back calls for at least 20 ms
        with ``timeit.Timer`` (garbage collection off while timing, as ``timeit`` does)
        and divides; the repeats of all settings run round-robin. The minimum, as ``timeit``
        advises: a slower repeat measures other processes, not the method. A run that does
        not succeed is timed once; a first run of at least 0.2 s counts as one repeat and
        the others run once each.
    n_steps, n_evaluations, n_events : int
        From the result.
    status : SimulationStatus
    message : str
    chattering : bool
        The body speed reverses direction (sign change between successive increments larger
        than ``MOTION_FLOOR * max(1, max|V|)``) more than ``CHATTER_MARGIN`` times more often
        than the exact solution sampled at the same times. Counted at the solver's own steps
        for the adaptive solvers (the untimed run of ``step_collapse``: chattering happens
        between steps), at the common evaluation times for the others.
    step_collapse : bool or None
        The adaptive solver crawls: at least ``STEP_COLLAPSE_RUN`` (1000) consecutive steps
        are each shorter than ``STEP_COLLAPSE_RATIO * t_end`` (1e-6 of the horizon). Short
        steps that resolve a smoothing layer and then grow again do not count; a solver
        stuck in a chattering loop does. Read from one extra, untimed run that reports the
        solver's own steps (``t_eval=None``, every step kept up to 2**22). ``None`` for
        methods without adaptive steps (exact, moreau), whose steps casadi does not expose, or
        when more steps than that had to be decimated.
    creep : bool
        Only for plants whose final contacts have a zero-force band and no drag, external
        force, command schedule or compliance: the exact solution starts strictly inside the
        band (by more than ``CREEP_TOLERANCE``) and stays there constant, and the method's
        ``V`` departs from it by more than ``CREEP_TOLERANCE`` m/s. Otherwise ``False``.
    stalled : bool
        A budget stopped the run (``WALL_TIME``, ``MAX_STEPS`` or ``ZENO``).
    reversals : int
        Direction reversals counted for ``chattering``.
    min_step : float or None, s
        The smallest step of an adaptive solver (from the same untimed run as
        ``step_collapse``).
    options : tuple of (str, value) pairs
        The setting's options (``MethodSetting.options``), for grouping the rows into
        families (``work_precision_curves``).
    """

    method: str
    setting: str
    max_error: float
    final_error: float
    wall_time: float
    n_steps: int
    n_evaluations: int
    n_events: int
    status: SimulationStatus
    message: str
    chattering: bool
    step_collapse: bool | None
    creep: bool
    stalled: bool
    reversals: int
    min_step: float | None
    options: tuple[tuple[str, Any], ...] = ()

    @property
    def label(self) -> str:
        """``"method setting"``."""
        return f"{self.method} {self.setting}".strip()

    def to_dict(self) -> dict[str, Any]:
        """JSON-able: non-finite floats become ``None``, the status its name."""
        return {
            "method": self.method, "setting": self.setting,
            "max_error": _json_float(self.max_error), "final_error": _json_float(self.final_error),
            "wall_time": self.wall_time, "n_steps": self.n_steps,
            "n_evaluations": self.n_evaluations, "n_events": self.n_events,
            "status": self.status.name, "message": self.message,
            "chattering": self.chattering, "step_collapse": self.step_collapse,
            "creep": self.creep, "stalled": self.stalled, "reversals": self.reversals,
            "min_step": _json_float(self.min_step),
        }


@dataclass(frozen=True)
class Speedup:
    """How much faster the exact method is than the fastest accurate reference method.

    Attributes
    ----------
    ratio : float
        ``reference.wall_time / exact.wall_time`` (``nan`` when no reference reaches the level).
    error_level : float, m/s
    exact, reference : PrecisionRow or None
    """

    ratio: float
    error_level: float
    exact: PrecisionRow
    reference: PrecisionRow | None

    def to_dict(self) -> dict[str, Any]:
        """``{"ratio", "error_level", "exact", "reference"}`` (the two as labels), JSON-able;
        ``ratio`` and ``reference`` are None when no reference method reaches the level."""
        return {"ratio": _json_float(self.ratio), "error_level": self.error_level,
                "exact": self.exact.label,
                "reference": None if self.reference is None else self.reference.label}


@dataclass(frozen=True)
class WorkPrecisionCurve:
    """One line of the work-precision plot: a method family through its tolerance settings.

    A family is a method with what stays fixed along its line (the integrator, the friction
    law and its smoothing width ``epsilon``); its points are its tolerance settings
    (``rtol``/``atol``, or the step of a time-stepping method), as in DiffEqDevTools'
    work-precision diagrams.

    Attributes
    ----------
    method : str
    settings : tuple of str
    wall_time : ndarray of shape (k,), s
    max_error : ndarray of shape (k,), m/s
    success : ndarray of shape (k,), bool
        False for runs a budget stopped (their error covers only the part they simulated).
    family : str
        The method and its fixed options, e.g. ``"casadi cvodes tanh"`` (the line's name).
    smoothing : float or None
        The smoothing width ``epsilon`` (m/s) of a smoothed law, None for the others.
    """

    method: str
    settings: tuple[str, ...]
    wall_time: np.ndarray
    max_error: np.ndarray
    success: np.ndarray
    family: str = ""
    smoothing: float | None = None


@dataclass(frozen=True)
class PrecisionReport:
    """The work-precision table of one plant.

    Attributes
    ----------
    rows : tuple of PrecisionRow
    t_end : float, s
    v0 : float, m/s
    repeats : int
    compile_time : float, s
        The one-time cost paid before any run was timed: the compiled kernels loaded (or
        compiled) and the exact method's first call (:func:`toolkit._compiled.warm`); in no
        row's ``wall_time``.
    """

    rows: tuple[PrecisionRow, ...]
    t_end: float
    v0: float
    repeats: int
    compile_time: float = 0.0

    def to_dict(self) -> dict[str, Any]:
        """``{"t_end", "v0", "repeats", "rows": [row.to_dict(), ...]}``, JSON-able, and
        ``"speedup"`` (:meth:`Speedup.to_dict` at 1e-6 m/s) when the report has an exact row."""
        out = {"t_end": self.t_end, "v0": self.v0, "repeats": self.repeats,
               "compile_time": self.compile_time, "rows": [row.to_dict() for row in self.rows]}
        if any(row.method == "exact" for row in self.rows):
            out["speedup"] = exact_speedup(self).to_dict()
            out["shortfalls"] = [shortfall.to_dict() for shortfall in precision_shortfalls(self)]
        return out

    def row(self, method: str, setting: str | None = None) -> PrecisionRow:
        """The first row of ``method`` (and ``setting``, if given)."""
        for candidate in self.rows:
            if candidate.method == method and (setting is None or candidate.setting == setting):
                return candidate
        raise ParameterError(parameter_message(
            "method", "PrecisionReport.row", "name a row of the report",
            method if setting is None else f"{method} {setting}"))


# -- measurements -----------------------------------------------------------------------------
def _reversals(V: np.ndarray) -> int:
    """Sign changes between successive non-negligible increments of ``V``."""
    if V.size < 3:
        return 0
    step = np.diff(V)
    floor = MOTION_FLOOR * max(1.0, float(np.max(np.abs(V))))
    signs = np.sign(step[np.abs(step) > floor])
    return int(np.count_nonzero(signs[1:] != signs[:-1]))


def _step_collapse(result: SimulationResult, t_end: float) -> tuple[bool | None, float | None]:
    """``(step_collapse, min_step)`` of an adaptive method, ``(None, None)`` for the others."""
    if result.method not in _ADAPTIVE or result.t.size < 2:
        return None, None
    steps = np.diff(result.t)
    steps = steps[steps > 0]
    if steps.size == 0:
        return None, None
    tiny = np.concatenate(([0], (steps < STEP_COLLAPSE_RATIO * t_end).astype(np.int8), [0]))
    edges = np.flatnonzero(np.diff(tiny))            # starts and ends of runs of tiny steps
    longest = int(np.max(edges[1::2] - edges[::2])) if edges.size else 0
    return longest >= STEP_COLLAPSE_RUN, float(np.min(steps))


def _creep(V: np.ndarray, reference: np.ndarray, plant: Plant, v0: float) -> bool:
    if (plant.commands is not None or plant.damping != 0 or plant.compliance != 0
            or isinstance(plant.external_force, PiecewiseConstant) or plant.external_force != 0):
        return False
    band = plant.contacts.zero_force_band()
    if band is None or not band[0] + CREEP_TOLERANCE < v0 < band[1] - CREEP_TOLERANCE:
        return False
    inside = (reference > band[0] + CREEP_TOLERANCE) & (reference < band[1] - CREEP_TOLERANCE)
    return bool(np.any(np.abs(V[inside] - reference[inside]) > CREEP_TOLERANCE))


def evaluation_times(exact: SimulationResult, t_end: float) -> np.ndarray:
    """The common evaluation times of the report: exact event times and a uniform grid.

    Parameters
    ----------
    exact : SimulationResult
        An exact run without ``t_eval`` (its ``t`` holds 0, every event time and ``t_end``).
    t_end : float, s

    Returns
    -------
    ndarray of shape (T,), s
        Sorted, unique, read-only (methods may then use it without a copy): ``t``, the event
        times and ``EVALUATION_POINTS`` uniform times on ``[0, t_end]``. The kinks of the
        exact solution are all among them.
    """
    events = np.array([event.time for event in exact.events], dtype=float)
    grid = np.union1d(np.union1d(exact.t, events), np.linspace(0.0, t_end, EVALUATION_POINTS))
    grid = grid[(grid >= 0.0) & (grid <= t_end)]
    grid.setflags(write=False)
    return grid


def _timed(plant: Plant, t_end: float, v0: float, settings: Sequence[MethodSetting],
           repeats: int, t_eval: np.ndarray) -> list[tuple[SimulationResult, float]]:
    """Run every setting once, then time the repeats round-robin (see ``PrecisionRow.wall_time``).

    Repeat ``r`` of every setting runs before repeat ``r + 1`` of any, so each setting's
    repeats are spread over the whole report: a burst of load from other processes slows
    one repeat of several settings, not every repeat of one, and the minimum discards it.
    Every call asks for the report's common times ``t_eval``, so the measured time includes
    producing those outputs, and starts from scratch: the exact method's cached force
    landscapes of the plant are emptied first (:func:`toolkit.simulation._exact.clear_cache`), as casadi rebuilds its integrator.

    Returns
    -------
    list of (SimulationResult, float)
        The first run's result and the wall time of one call (s), per setting.
    """
    results, timers, numbers, times = [], [], [], []
    for setting in settings:
        run = functools.partial(simulate, plant, t_end, v0=v0, method=setting.method,
                                t_eval=t_eval, budget=setting.budget, **setting.kwargs)

        def call(run: Callable[[], SimulationResult] = run) -> SimulationResult:
            clear_cache(plant)
            return run()

        start = budget_clock()
        result = call()
        first = budget_clock() - start
        timer = timeit.Timer(call)
        if not result.success or repeats <= 1 and first >= _MIN_REPEAT_TIME:
            number, timed = 0, [first]              # timed once
        elif first >= _WARM_RUN:      # long runs: import and warm-up costs are negligible
            number, timed = 1, [first]
        else:                         # the first call may pay one-off costs (imports, caches)
            number = max(1, math.ceil(_MIN_REPEAT_TIME / max(timer.timeit(1), 1e-9)))
            timed = []
        results.append(result)
        timers.append(timer)
        numbers.append(number)
        times.append(timed)
    for _ in range(repeats):
        for timer, number, timed in zip(timers, numbers, times):
            if number and len(timed) < repeats:
                timed.append(timer.timeit(number) / number)
    return [(result, min(timed)) for result, timed in zip(results, times)]


def _row(setting: MethodSetting, result: SimulationResult, wall: float, plant: Plant,
         t_end: float, v0: float, grid: np.ndarray, truth: np.ndarray, rational: bool,
         exact_at: Callable[[np.ndarray], np.ndarray]) -> PrecisionRow:
    """Measure one run on the common times ``grid`` against ``truth`` (the exact values there)."""
    reached = np.searchsorted(grid, result.t)              # result.t is a prefix of grid
    if result.t.size and not (reached[-1] < grid.size and np.array_equal(grid[reached], result.t)):
        raise SolverError(f"{result.method} did not report at the requested times")
    reference = truth[reached]
    if result.method == "exact" and not rational:
        max_error = final_error = math.nan                 # no reference independent of itself
    else:
        errors = np.abs(result.V - reference)
        max_error = float(np.max(errors)) if errors.size else math.inf
        done = result.success and errors.size == grid.size
        final_error = float(errors[-1]) if done else math.inf
    collapse, min_step = None, None
    if result.method in _ADAPTIVE:                         # the solver's own steps, untimed
        # Every step is needed (a decimated record would hide short steps): room for as many
        # steps as the budget allows, up to 2**22 (64 MB of samples); a record decimated
        # beyond that leaves step_collapse and min_step unknown (None).
        budget = setting.budget
        room = max(budget.max_samples, min(budget.max_steps + 1, _OWN_STEPS))
        own = simulate(plant, t_end, v0=v0, method=setting.method,
                       budget=dataclasses.replace(budget, max_samples=room), **setting.kwargs)
        if "record decimated" not in own.message:
            collapse, min_step = _step_collapse(own, t_end)
        reversals = _reversals(own.V)
        chattering = reversals > _reversals(exact_at(own.t)) + CHATTER_MARGIN
    else:
        reversals = _reversals(result.V)
        chattering = reversals > _reversals(reference) + CHATTER_MARGIN
    stalled = result.status in (SimulationStatus.WALL_TIME, SimulationStatus.MAX_STEPS, SimulationStatus.ZENO)
    return PrecisionRow(
        method=result.method, setting=result.setting, max_error=max_error,
        final_error=final_error, wall_time=float(wall), n_steps=result.n_steps,
        n_evaluations=result.n_evaluations, n_events=result.n_events, status=result.status,
        message=result.message, chattering=bool(chattering), step_collapse=collapse,
        creep=_creep(result.V, reference, plant, v0), stalled=stalled, reversals=reversals,
        min_step=min_step, options=setting.options)


def precision_report(plant: Plant, t_end: float, *, v0: float = 0.0, repeats: int = 3,
                     settings: Sequence[MethodSetting] | None = None) -> PrecisionReport:
    """Run every method and setting on one plant and measure error against run time.

    The comparison is made on equal terms: every method, the exact one included, is asked
    for the same output times (``evaluation_times``: the exact event times, where the
    solution has its kinks, and 1001 uniform times) through ``t_eval``, each with its own way
    of producing them (dense output, interpolation between steps, an output grid); errors
    are measured at those times and the wall time is that of the same calls, so every method
    pays for producing them. A time-stepping method is thus judged over the whole run, not
    only at its own steps.

    Parameters
    ----------
    plant, t_end, v0
        The scene, as in :func:`toolkit.simulation.simulate`.
    repeats : int
        Timing repeats per successful run (the minimum is reported), ``>= 1``.
    settings : sequence of MethodSetting, optional
        Default ``default_settings``. Include ``"exact"`` to time the exact method.

    Returns
    -------
    PrecisionReport
        One row per setting, in order. The reference of every error is
        ``rational_trajectory`` when the plant is within what it supports, else the
        exact method's dense output.

    Raises
    ------
    SolverError
        If the exact reference does not reach ``t_end`` under a 60 s budget.
    """
    if not isinstance(plant, Plant):
        raise ParameterTypeError(parameter_message("plant", "precision_report", "be a Plant", plant))
    t_end = as_float(t_end, "t_end", "precision_report", low=0.0, low_open=True)
    v0 = as_float(v0, "v0", "precision_report")
    repeats = as_int(repeats, "repeats", "precision_report", low=1)
    chosen = default_settings() if settings is None else tuple(settings)
    for item in chosen:
        if not isinstance(item, MethodSetting):
            raise ParameterTypeError(parameter_message(
                "settings", "precision_report", "contain MethodSetting objects", item))
    # The timing policy (toolkit._compiled): the kernels compiled before any clock starts,
    # and the exact method's timed call (sample times included) once, untimed.
    compile_time = warm(None, "core")
    exact = simulate(plant, t_end, v0=v0, method="exact")
    if not exact.success:
        raise SolverError(f"The exact reference did not reach t_end = {t_end:g} s: {exact.message}")
    grid = evaluation_times(exact, t_end)
    compile_time += warm(lambda: simulate(plant, t_end, v0=v0, method="exact", t_eval=grid))
    rational = _rational_supported(plant)
    truth = rational_trajectory(plant, v0, grid) if rational else exact.speed_at(grid)
    timings = _timed(plant, t_end, v0, chosen, repeats, grid)
    rows = [_row(setting, result, wall, plant, t_end, v0, grid, truth, rational, exact.speed_at)
            for setting, (result, wall) in zip(chosen, timings)]
    return PrecisionReport(rows=tuple(rows), t_end=t_end, v0=v0, repeats=repeats,
                           compile_time=compile_time)


# -- derived data (pure) ----------------------------------------------------------------------
def exact_speedup(report: PrecisionReport, error: float = ERROR_LEVEL) -> Speedup:
    """Run time of the fastest reference method reaching ``max_error <= error`` over the exact one.

    Parameters
    ----------
    report : PrecisionReport
        Must contain an ``"exact"`` row.
    error : float, m/s
        Accuracy a reference run must reach (and finish) to count.

    Returns
    -------
    Speedup
    """
    error = as_float(error, "error", "exact_speedup", low=0.0, low_open=True)
    exact = report.row("exact")
    accurate = [row for row in report.rows if row.method != "exact"
                and row.status is SimulationStatus.SUCCESS and row.max_error <= error]
    if not accurate:
        return Speedup(math.nan, error, exact, None)
    fastest = min(accurate, key=lambda row: row.wall_time)
    return Speedup(fastest.wall_time / exact.wall_time, error, exact, fastest)


def precision_shortfalls(report: PrecisionReport, error: float = ERROR_LEVEL) -> list[Any]:
    """How a work-precision report missed its request (the ``precision`` command exits 3).

    The request of a report with an exact row is its headline: the exact method's speedup
    over the fastest reference method at the accuracy ``error`` (:func:`exact_speedup`),
    which needs two things, each a :class:`toolkit.shortfall.Shortfall` (stage ``"precision"``,
    amount in m/s) when missed:

    - the exact method, measured against the independent rational solution, is itself within
      ``error`` (amount: its error minus ``error``); a plant outside what
      ``rational_trajectory`` supports has no independent reference (``max_error`` NaN),
      which the report states and which is not a shortfall;
    - at least one reference method finishes with ``max_error <= error``, otherwise there is
      no ratio (amount: the closest finished reference's error minus ``error``, NaN when
      none finished).

    Not shortfalls: reference runs stopped by their budgets (showing those stalls is what the
    report is for; they are flagged in its rows) and the 100x speedup target (a
    benchmark target: ``python -m toolkit.bench precision`` exits 1 while it is missed).

    Parameters
    ----------
    report : PrecisionReport
    error : float, m/s

    Returns
    -------
    list of toolkit.shortfall.Shortfall
        Empty when the request was met or the report has no exact row (no speedup asked).
    """

    error = as_float(error, "error", "precision_shortfalls", low=0.0, low_open=True)
    if not any(row.method == "exact" for row in report.rows):
        return []
    shortfalls = []
    exact = report.row("exact")
    if math.isfinite(exact.max_error) and exact.max_error > error:
        shortfalls.append(Shortfall(
            "precision", f"the exact method's error {exact.max_error:.3g} m/s against the rational "
            f"solution is above the {error:g} m/s level", exact.max_error - error, "m/s"))
    speedup = exact_speedup(report, error)
    if speedup.reference is None:
        finished = [row for row in report.rows if row.method != "exact"
                    and row.status is SimulationStatus.SUCCESS and math.isfinite(row.max_error)]
        if finished:
            closest = min(finished, key=lambda row: row.max_error)
            what = (f"no reference method reached max_error <= {error:g} m/s, so no speedup "
                    f"(closest: {closest.label}, {closest.max_error:.3g} m/s)")
            amount = closest.max_error - error
        else:
            what = (f"no reference method reached max_error <= {error:g} m/s, so no speedup "
                    f"(none finished)")
            amount = math.nan
        shortfalls.append(Shortfall("precision", what, amount, "m/s"))
    return shortfalls


#: Options that move a point along its family's line (tolerances, step sizes).
TOLERANCE_OPTIONS = ("rtol", "atol", "step")


def _family(row: PrecisionRow) -> tuple[str, float | None]:
    """The family of a row: its method and fixed options (integrator, friction law) as a
    label, and its smoothing width (``epsilon``, None without)."""
    options = dict(row.options)
    fixed = [str(options[name]) for name in ("integrator", "friction") if name in options]
    smoothing = options.get("epsilon")
    return " ".join([row.method, *fixed]), None if smoothing is None else float(smoothing)


def work_precision_curves(report: PrecisionReport) -> tuple[WorkPrecisionCurve, ...]:
    """The data of the work-precision plot: one curve per method family and smoothing width
    (:class:`WorkPrecisionCurve`), through its tolerance settings.

    Families come in the order of their first row; points are sorted by run time; rows with
    a non-finite error are left out.
    """
    groups: dict[tuple[str, float | None], list[PrecisionRow]] = {}
    for row in report.rows:
        if math.isfinite(row.max_error):
            groups.setdefault(_family(row), []).append(row)
    curves = []
    for (family, smoothing), rows in groups.items():
        rows = sorted(rows, key=lambda row: row.wall_time)
        arrays = [np.array([row.wall_time for row in rows]),
                  np.array([row.max_error for row in rows]),
                  np.array([row.status is SimulationStatus.SUCCESS for row in rows])]
        for array in arrays:
            array.setflags(write=False)
        curves.append(WorkPrecisionCurve(rows[0].method, tuple(row.setting for row in rows),
                                         *arrays, family=family, smoothing=smoothing))
    return tuple(curves)
