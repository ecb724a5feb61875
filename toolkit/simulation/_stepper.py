"""Continue an exact simulation from a state, one sample period at a time: :func:`advance`.

From the state at ``t0`` (:class:`ExactState`: body speed, contact speeds, the contact
followed) under one command held on ``[t0, t1)`` and a constant external force, the state at
``t1`` with the exact displacements and the events inside (:class:`ExactStep`): the engine of
``simulate(method="exact")`` itself, so stepping a schedule gives one ``simulate`` run of it to
rounding. A no-event certificate shortcuts quiet steps. Details: docs/physics.md, section 11.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..errors import as_float, as_float_array, as_int
from ..errors import ParameterError, ParameterTypeError, parameter_message
from .._compiled import budget_clock
from .._compiled import core as _core
from ..model import Plant
from ._exact import _build_landscape, _dynamic_plant, _ideal_piece, _kernels, _Recorder
from ._result import Budget, Event, SimulationStatus, refuse_backlash, status_message

__all__ = ["ExactState", "ExactStep", "advance"]

_DEFAULT_BUDGET = Budget()
_SUCCESS = SimulationStatus.SUCCESS
_NO_PENDING: tuple[int | None, float] = (None, 0.0)
_QUIET_MESSAGE = status_message(_SUCCESS, "0 events")
#: Take the certified no-event shortcut (:func:`toolkit._compiled.core.quiet_piece`)
#: when it applies; False runs the full engine on every step (tests compare the two).
_QUIET = True
#: Wall-time budgets below this (s) always run the engine, which checks the clock.
_QUIET_WALL_TIME = 1e-3
#: Interpreted work (about us) of a step: the certificate, and the engine per contact.
_QUIET_WORK, _ENGINE_WORK = 20, 20


@dataclass(frozen=True, eq=False)
class ExactState:
    """Where an exact simulation stands at one instant: enough to continue it exactly.

    Parameters
    ----------
    t : float, s
    V : float, m/s
        Body speed.
    contact_speeds : array_like of shape (n,), m/s
        Actual contact speeds: the states of lagging or rate-limited motors (not necessarily
        settled on their command); with ideal motors, ignored by :func:`advance` (the
        contacts take each command at once).
    stuck : int or None
        The contact the body follows in a sliding mode, ``None`` when it slides freely. A
        state built by hand may leave it ``None``: the engine finds a body tied with a
        contact (within rounding) itself.

    Examples
    --------
    >>> from toolkit import ContactSet, Plant
    >>> state = ExactState.initial(Plant(ContactSet([-0.1, 0.2]), mass=1.0))
    >>> state.t, state.V
    (0.0, 0.0)
    """

    t: float
    V: float
    contact_speeds: np.ndarray
    stuck: int | None = None
    _pending: tuple[int | None, float] = field(default=(None, 0.0), repr=False)

    def __post_init__(self) -> None:
        owner = "ExactState"
        object.__setattr__(self, "t", as_float(self.t, "t", owner))
        object.__setattr__(self, "V", as_float(self.V, "V", owner))
        object.__setattr__(self, "contact_speeds",
                           as_float_array(self.contact_speeds, "contact_speeds", owner))
        if self.stuck is not None:
            stuck = as_int(self.stuck, "stuck", owner, low=0)
            if stuck >= self.contact_speeds.size:
                raise ParameterError(parameter_message(
                    "stuck", owner, f"be None or a contact index < {self.contact_speeds.size}",
                    stuck))
            object.__setattr__(self, "stuck", stuck)

    @classmethod
    def initial(cls, plant: Plant, v0: float = 0.0, t: float = 0.0) -> ExactState:
        """The state :func:`~toolkit.simulation.simulate` starts from: body speed ``v0``
        (m/s) at time ``t`` (s), motors settled on the plant's command at ``t``."""
        return cls(t, v0, plant.command(t))

    @classmethod
    def _trusted(cls, t: float, V: float, contact_speeds: np.ndarray, stuck: int | None,
                 pending: tuple[int | None, float]) -> ExactState:
        """A state the engine produced (floats, a fresh read-only array): no re-validation."""
        state = object.__new__(cls)
        state.__dict__.update(t=t, V=V, contact_speeds=contact_speeds, stuck=stuck,
                              _pending=pending)
        return state


@dataclass(frozen=True, eq=False)
class ExactStep:
    """The outcome of one :func:`advance`.

    Attributes
    ----------
    state : ExactState
        The state at ``t1`` (at the stop time when a budget stopped the step).
    body_displacement : float, m
        ``int V dt`` over the step, exact (closed form per segment).
    contact_displacements : ndarray of shape (n,), m
        ``int v_i dt`` over the step for each contact, exact (closed form of the motor law).
    events : tuple of Event
        Crossings, sticks, releases and saturations inside the step.
    status : SimulationStatus
    message : str
        ``status.value`` plus specifics.
    shortcut : bool
        The certified no-event shortcut gave the step (see :func:`advance`'s ``shortcut``).
    """

    state: ExactState
    body_displacement: float
    contact_displacements: np.ndarray
    events: tuple[Event, ...]
    status: SimulationStatus
    message: str
    shortcut: bool = field(default=False, repr=False)

    @property
    def success(self) -> bool:
        """True when the step reached ``t1``."""
        return self.status is _SUCCESS

    @classmethod
    def _trusted(cls, state: ExactState, body_displacement: float,
                 contact_displacements: np.ndarray, events: tuple[Event, ...],
                 status: SimulationStatus, message: str, quiet: bool) -> ExactStep:
        """A step the engine produced: no dataclass ``__init__`` (frozen fields set once)."""
        step = object.__new__(cls)
        step.__dict__.update(state=state, body_displacement=body_displacement,
                             contact_displacements=contact_displacements, events=events,
                             status=status, message=message, shortcut=quiet)
        return step


def advance(plant: Plant, state: ExactState, command: Any, t1: float, *,
            external: float = 0.0, budget: Budget | None = None, shortcut: bool = True) -> ExactStep:
    """Continue an exact simulation from ``state`` to ``t1`` under one held command.

    Parameters
    ----------
    plant : Plant
        The contacts, mass, drag and motors; its own ``commands`` and ``external_force``
        are not used (``command`` and ``external`` are).
    state : ExactState
        The state at ``t0 = state.t``.
    command : array_like of shape (n,), m/s
        Commanded contact speeds, held on ``[t0, t1)``; clipped to the motor speed limits.
    t1 : float, s
        End of the step, ``> state.t``.
    external : float, N
        External force, constant over the step.
    shortcut : bool
        Take the certified no-event shortcut where it applies (default); False runs the full
        engine on every step (the same result: benchmarks and tests compare the two).
    budget : Budget, optional
        Limits of the step (default ``Budget()``): the same guards as ``simulate``.

    Returns
    -------
    ExactStep
        The state at ``t1``, the exact displacements over the step and its events.

    Notes
    -----
    Stepping ``0 .. T`` with the values of a command schedule whose switches lie on the
    step times gives, to rounding, the trajectory of one exact ``simulate`` run of that
    schedule (the same engine runs each piece of constant command).
    """
    if type(plant) is not Plant and not isinstance(plant, Plant):
        raise ParameterTypeError(parameter_message("plant", "advance", "be a Plant", plant))
    if plant.motors is not None and plant.motors.backlash > 0:
        refuse_backlash(plant, "advance")
    if not isinstance(state, ExactState):
        raise ParameterTypeError(parameter_message("state", "advance", "be an ExactState",
                                                   state))
    n = plant.n
    u = command if type(command) is np.ndarray and command.dtype == np.float64 else \
        np.asarray(command, dtype=float)
    if u.shape != (n,) or not np.isfinite(u).all():
        raise ParameterError(parameter_message(
            "command", "advance", f"be {n} finite speeds (one per contact)", command))
    t0 = state.t
    if not (type(t1) is float and t0 < t1 < math.inf):
        t1 = as_float(t1, "t1", "advance", low=t0, low_open=True)
    if not (type(external) is float and math.isfinite(external)):
        external = as_float(external, "external", "advance")
    budget = _DEFAULT_BUDGET if budget is None else budget
    if not isinstance(budget, Budget):
        raise ParameterTypeError(parameter_message("budget", "advance", "be a Budget", budget))
    motors = plant.motors
    if motors is not None:
        low, high = motors.speed_limits
        if low > -math.inf:
            u = np.maximum(u, low)
        if high < math.inf:
            u = np.minimum(u, high)
    if plant.dynamic_motors:
        speeds = state.contact_speeds
        if speeds.shape != (n,):
            raise ParameterError(parameter_message(
                "state", "advance", f"hold {n} contact speeds", speeds.shape))
        dyn = _dynamic_plant(plant)
        hint, releasing = state._pending
        try_quiet = (_QUIET and shortcut is not False and dyn.quiet and hint is None and releasing == 0.0
                     and budget.wall_time >= _QUIET_WALL_TIME)
        rec = _Recorder(budget, 2 * n + 2, dyn.mu)
        out = np.empty((2, n))
        motor = np.empty((5, n))
        u = np.ascontiguousarray(u)
        stuck = -1 if state.stuck is None else state.stuck
        code, quiet, body = _kernels(_QUIET_WORK + _ENGINE_WORK * n).advance_dynamic(
            dyn.forces, dyn.params, try_quiet, t0, t1, state.V, stuck,
            -1 if hint is None else hint, releasing, speeds, u, external, motor, rec.fstate,
            rec.istate, rec.seg, rec.ev, out)
        if quiet:
            speeds_end, travelled = out[0], out[1]
            speeds_end.setflags(write=False)
            travelled.setflags(write=False)
            return ExactStep._trusted(
                ExactState._trusted(t1, float(rec.fstate[_core.F_V]), speeds_end, state.stuck,
                                    _NO_PENDING), body, travelled, (), _SUCCESS,
                _QUIET_MESSAGE, True)
        if code == _core.PAUSE:          # the buffers filled up or a chunk of rounds ran
            code = dyn.run(np.array([t0, t1]), u.reshape(1, n), np.array([external]), motor,
                           rec)
            body = _kernels().advance_outputs(motor, dyn.tau, t0, rec.fstate, rec.istate,
                                              rec.seg, out)
        elif code == _core.DONE and budget_clock() > rec.deadline:
            code = -1                    # (the wall clock, looked at after the kernel)
        t, V = float(rec.fstate[_core.F_T]), float(rec.fstate[_core.F_V])
        if code != _core.DONE:
            rec.stopped(code, t)
        k, h = int(rec.istate[_core.I_STUCK]), int(rec.istate[_core.I_HINT])
        stuck = None if k < 0 else k
        pending = (None if h < 0 else h, float(rec.fstate[_core.F_REL]))
        speeds_end, travelled = out[0], out[1]
    else:
        rec = _Recorder(budget, 2 * n + 2, 0.0)
        t, V, stuck, _ = _ideal_piece(plant, _build_landscape(plant, u), external, t0, t1,
                                      state.V, state.stuck, rec)
        speeds_end = u.copy()
        travelled = u * (t - t0)
        pending = _NO_PENDING
        body = rec.displacement(t)
    speeds_end.setflags(write=False)
    travelled.setflags(write=False)
    status = rec.status
    if status is _SUCCESS and not (math.isfinite(t) and math.isfinite(V)):
        status = SimulationStatus.FAILED
        rec.detail = f"the body speed left the floating-point range (V = {V:g} m/s)"
    events = rec.events()
    detail = rec.detail if status is not _SUCCESS else f"{len(events)} events"
    return ExactStep._trusted(ExactState._trusted(float(t), float(V), speeds_end, stuck, pending),
                              body, travelled, events, status, status_message(status, detail), False)
