"""The exact event-driven method: closed-form segments between events, Filippov sliding modes.

Between events every segment is ``V(t0 + s) = V0 + c1 s + B expm1_ratio(lam, s) +
C expm1_ratio(mu, s) + D s exp(-mu s)``; events (crossings, sticks, releases, saturations,
command switches) are found as first roots of closed-form functions. This module holds the
drivers of the kernels :func:`toolkit._compiled.core.ideal_piece` (ideal motors) and
:func:`toolkit._compiled.core.dynamic_run` (lagging or rate-limited motors) and
:func:`simulate_exact`; the landscapes are in ``_landscape``, the recorder of segments and
events and the dense output in ``_record``. The derivation, the tie and Zeno rules:
docs/physics.md, section 11.
"""

from __future__ import annotations

import math
import weakref
from dataclasses import dataclass
from typing import Any

import numpy as np

from .. import _compiled
from .._compiled import budget_clock
from .._compiled import core as _core     # the kernels' source module (imports no numba)
from ..model import PiecewiseConstant, Plant
from ._kernel import _COMPILED, _kernels
from ._landscape import _Landscape, _landscape
from ._record import _SUCCESS, _Recorder, _piece_bounds
from ._result import Budget, SimulationResult, SimulationStatus, status_message
# Read here by the package's other engines and by the tests (each defined beside its kin).
from ._landscape import _LANDSCAPES, _CoulombLandscape, _build_landscape, clear_cache  # noqa: F401
from ._record import _STEP_CAP, _ZENO_FLOOR, _motor_speeds  # noqa: F401

__all__ = ["simulate_exact"]

_ROOT_WORK = 15             # interpreted work (about us) of the first-root search per function


# -- closed forms (the kernels' own source, run as Python by the dynamic-motor engine) --------
_scalar_expm1_ratio = _core.expm1_ratio
_expm1_ratio_integral = _core.expm1_ratio_integral
_reach_time = _core.reach_time


# -- the ideal-motor engine -------------------------------------------------------------------
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
