"""Value objects shared by every simulation method: status, budget, events and the result."""

from __future__ import annotations

import enum
from collections.abc import Callable
from dataclasses import dataclass, fields
from typing import Any

import numpy as np

from ..errors import as_float, as_int, check_option
from ..errors import ParameterError, ParameterTypeError, parameter_message

__all__ = ["SimulationStatus", "Budget", "Event", "SimulationResult", "EVENT_KINDS", "status_message"]

#: The kinds of :class:`Event`.
EVENT_KINDS = ("cross", "stick", "release", "command", "saturation")


class SimulationStatus(enum.Enum):
    """How a simulation ended; the value is a message a user can act on."""

    SUCCESS = "finished: reached t_end"
    ZENO = ("stopped: too many events per unit time (Zeno behaviour); "
            "raise max_event_rate or smooth the model")
    WALL_TIME = "stopped: wall-clock budget exhausted"
    MAX_STEPS = "stopped: step budget exhausted"
    FAILED = "stopped: the integrator failed"


@dataclass(frozen=True)
class Budget:
    """Limits under which every method runs, so that a stalled method returns a status.

    Parameters
    ----------
    wall_time : float, s
        Wall-clock budget (``> 0``; ``inf`` allowed).
    max_steps : int
        Steps, events or right-hand-side evaluations, whichever the method counts (``>= 1``).
    max_event_rate : float, 1/s
        Zeno guard of the exact method: more events than ``max_event_rate`` per simulated
        second, counted over the run so far (and at least 1000 events), stops the run.
    max_samples : int
        Memory cap: the most samples a run keeps (``>= 2``). The exact method stores one
        closed-form segment per event (its dense output needs them all): a run that would
        store more stops with ``MAX_STEPS``. The stepping methods (scipy, moreau) asked for
        their own steps (``t_eval=None``) keep every step up to this many, then a decimated
        record (every 2nd step, then every 4th, ..., always the first and the last). Requested
        ``t_eval`` times are all reported (their number is the caller's choice) and nothing
        else is stored per step. The default, 2**18, bounds a record to a few MB of arrays
        (the exact method's segments, Python objects, to about 170 MB).
    """

    wall_time: float = 60.0
    max_steps: int = 10**7
    max_event_rate: float = 1e6
    max_samples: int = 2**18

    def __post_init__(self) -> None:
        object.__setattr__(self, "wall_time", as_float(
            self.wall_time, "wall_time", "Budget", low=0.0, low_open=True, finite=False))
        object.__setattr__(self, "max_steps", as_int(self.max_steps, "max_steps", "Budget", low=1))
        object.__setattr__(self, "max_event_rate", as_float(
            self.max_event_rate, "max_event_rate", "Budget", low=0.0, low_open=True, finite=False))
        object.__setattr__(self, "max_samples", as_int(self.max_samples, "max_samples", "Budget", low=2))


@dataclass(frozen=True)
class Event:
    """Something that happened at one instant of a simulation.

    Parameters
    ----------
    time : float, s
    kind : {"cross", "stick", "release", "command", "saturation"}
        ``cross``: the body passed a contact speed; ``stick``: it locked onto one (sliding
        mode); ``release``: it left a contact speed it was stuck to; ``command``: a command
        or the external force switched; ``saturation``: a compliant contact's slip reached
        ``+-k f_i`` (its force enters or leaves saturation).
    contact : int or None
        Index of the contact involved (the lowest index among coincident ones), ``None``
        for ``command`` events.
    speed : float, m/s
        Body speed at the event.
    """

    time: float
    kind: str
    contact: int | None
    speed: float

    def __post_init__(self) -> None:
        if self.kind not in EVENT_KINDS:
            check_option(self.kind, "kind", "Event", EVENT_KINDS)
        for name in ("time", "speed"):
            if type(getattr(self, name)) is not float:
                object.__setattr__(self, name, float(getattr(self, name)))
        if self.contact is not None and (type(self.contact) is not int or self.contact < 0):
            object.__setattr__(self, "contact", as_int(self.contact, "contact", "Event", low=0))

    @classmethod
    def _trusted(cls, time: float, kind: str, contact: int | None, speed: float) -> Event:
        """An event whose fields the simulator already produced checked (a float time and
        speed, a known kind, a contact index or None): built without re-validation."""
        event = object.__new__(cls)
        event.__dict__.update(time=time, kind=kind, contact=contact, speed=speed)
        return event


def _frozen(value: Any, name: str, ndim: int) -> np.ndarray:
    array = np.asarray(value, dtype=float)
    if array.flags.writeable:            # copy what the caller could still change
        array = array.copy()
    if array.ndim != ndim:
        raise ParameterError(parameter_message(
            name, "SimulationResult", f"be {ndim}-dimensional", f"an array of shape {array.shape}"))
    array.setflags(write=False)
    return array


@dataclass(frozen=True, eq=False)
class SimulationResult:
    """The outcome of :func:`toolkit.simulation.simulate`.

    Attributes
    ----------
    method, setting : str
        Method name (``"exact"``, ``"rk45"``, ...) and its setting in words
        (e.g. ``"sign rtol=1e-6"``).
    t : ndarray of shape (T,), s
        Sample times.
    V : ndarray of shape (T,), m/s
        Body speed at ``t``.
    contact_speeds : ndarray of shape (T, n), m/s
        Contact speeds at ``t``.
    force : ndarray of shape (T,), N
        Net force on the body at ``t`` (for the exact method, the force actually applied,
        i.e. ``m dV/dt`` from the right; inside a sliding mode the Filippov value).
    events : tuple of Event
    status : SimulationStatus
    message : str
        ``status.value`` plus specifics.
    n_events, n_evaluations, n_steps : int
        Events, right-hand-side (or closed-form) evaluations, and steps taken.
    wall_time : float, s
    dense : callable or None
        ``dense(times) -> V`` at any times in ``[0, t_end]`` (exact for the exact method).

    Notes
    -----
    The exact method builds ``events``, ``contact_speeds`` and ``dense`` on their first
    access (from its record of the run, the same values as if built at once) and keeps
    them; ``vars(result)`` lists them only once accessed. Pickling and copying compute them.
    """

    method: str
    setting: str
    t: np.ndarray
    V: np.ndarray
    contact_speeds: np.ndarray
    force: np.ndarray
    events: tuple[Event, ...]
    status: SimulationStatus
    message: str
    n_events: int
    n_evaluations: int
    n_steps: int
    wall_time: float
    dense: Callable[[np.ndarray], np.ndarray] | None = None

    def __post_init__(self) -> None:
        t = _frozen(self.t, "t", 1)
        for name, ndim in (("V", 1), ("force", 1), ("contact_speeds", 2)):
            array = _frozen(getattr(self, name), name, ndim)
            if array.shape[0] != t.size:
                raise ParameterError(parameter_message(
                    name, "SimulationResult", f"have {t.size} rows (one per sample time)",
                    f"an array of shape {array.shape}"))
            object.__setattr__(self, name, array)
        object.__setattr__(self, "t", t)
        if not isinstance(self.status, SimulationStatus):
            raise ParameterTypeError(parameter_message(
                "status", "SimulationResult", "be a SimulationStatus", self.status))
        object.__setattr__(self, "events", tuple(self.events))
        for name in ("n_events", "n_evaluations", "n_steps"):
            count = getattr(self, name)
            if type(count) is not int or count < 0:
                object.__setattr__(self, name, as_int(count, name, "SimulationResult", low=0))

    @classmethod
    def _trusted(cls, values: dict[str, Any]) -> SimulationResult:
        """A result from fields a simulator produced itself (``values``: field name -> value,
        every field given; the arrays fresh, read-only and of matching shapes, the counts
        ints, ``events`` a tuple of :class:`Event`). The dict becomes the instance's own,
        without re-validation or copies (private fast path).

        Fields in :data:`_LAZY_FIELDS` may be left out of ``values`` if ``values["_source"]``
        is an object whose method ``field(name)`` returns them (the simulator's own record
        of the run, which nothing writes to any more): each is then computed on its first
        access, from the same data as it would have been at once, and kept."""
        result = object.__new__(cls)
        object.__setattr__(result, "__dict__", values)
        return result

    def __getattr__(self, name: str) -> Any:
        # Called only for names the instance dict lacks: a lazy field's first access.
        if name in _LAZY_FIELDS:
            values = self.__dict__
            source = values.get("_source")
            if source is not None:
                value = values[name] = source.field(name)
                if len(values) == _FULL:          # every lazy field computed: let go of it
                    values.pop("_source", None)
                return value
        raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")

    def __getstate__(self) -> dict[str, Any]:
        """Every field computed (pickle, copy): the state holds no simulator internals."""
        return {f.name: getattr(self, f.name) for f in fields(self)}

    @property
    def success(self) -> bool:
        """True when the run reached ``t_end``."""
        return self.status is SimulationStatus.SUCCESS

    @property
    def t_final(self) -> float:
        """Last simulated time, s (``t_end`` on success)."""
        return float(self.t[-1]) if self.t.size else 0.0

    def to_dict(self, *, samples: bool = False) -> dict[str, Any]:
        """A JSON-able summary (``samples=True`` adds ``t``, ``V`` and ``force`` lists).

        Keys: ``method``, ``setting``, ``status`` (the SimulationStatus name), ``message``,
        ``t_final``, ``V_final``, ``n_events``, ``n_evaluations``, ``n_steps``,
        ``wall_time`` and ``events`` (``time``, ``kind``, ``contact``, ``speed`` each).
        """
        out: dict[str, Any] = {
            "method": self.method, "setting": self.setting, "status": self.status.name,
            "message": self.message, "t_final": self.t_final,
            "V_final": float(self.V[-1]) if self.V.size else None,
            "n_events": self.n_events, "n_evaluations": self.n_evaluations,
            "n_steps": self.n_steps, "wall_time": self.wall_time,
            "events": [{"time": e.time, "kind": e.kind, "contact": e.contact, "speed": e.speed}
                       for e in self.events],
        }
        if samples:
            out.update(t=self.t.tolist(), V=self.V.tolist(), force=self.force.tolist())
        return out

    def speed_at(self, times: Any) -> np.ndarray:
        """Body speed at ``times`` (s): the dense output if present, else linear interpolation.

        Parameters
        ----------
        times : array_like of any shape, s
            Within the simulated span: ``[0, t_end]`` for a dense output that knows its
            horizon (the exact method's; NaN past a stopped run's end), else
            ``[t[0], t_final]``. Nothing is extrapolated: times outside are refused.

        Returns
        -------
        ndarray of the shape of ``times``, m/s
        """
        query = np.asarray(times, dtype=float)
        if not np.all(np.isfinite(query)):
            raise ParameterError(parameter_message(
                "times", "SimulationResult.speed_at", "be finite", times))
        horizon = getattr(self.dense, "t_end", None)
        lo, hi = (0.0, horizon) if horizon is not None else (
            float(self.t[0]) if self.t.size else 0.0, self.t_final)
        if query.size and not (query.min() >= lo and query.max() <= hi):
            raise ParameterError(parameter_message(
                "times", "SimulationResult.speed_at",
                f"lie within the simulated span [{lo:g}, {hi:g}] s (no extrapolation)", times))
        if self.dense is not None:
            return np.asarray(self.dense(query), dtype=float).reshape(query.shape)
        return np.interp(query, self.t, self.V)

    def __repr__(self) -> str:
        final = f"{self.V[-1]:.6g} m/s" if self.V.size else "n/a"
        return (f"SimulationResult(method={self.method!r}, setting={self.setting!r}, "
                f"status={self.status.name}, t_final={self.t_final:.6g} s, V_final={final}, "
                f"events={self.n_events}, steps={self.n_steps}, wall_time={self.wall_time:.3g} s)")


#: Fields a simulator may leave to be computed on first access (see ``SimulationResult._trusted``).
_LAZY_FIELDS = frozenset({"events", "contact_speeds", "dense"})
# A field with a default is also a class attribute, which would answer for a lazy field before
# ``__getattr__`` is asked: drop it (``__init__`` keeps its own default; every instance holds
# ``dense`` in its dict, or computes it lazily).
del SimulationResult.dense
_FULL = len(fields(SimulationResult)) + 1          # every field and the source

_MESSAGES = {status: status.value for status in SimulationStatus}     # Enum .value is a slow property


def status_message(status: SimulationStatus, detail: str = "") -> str:
    """``status.value`` followed by ``detail`` (a sentence of specifics), if any."""
    message = _MESSAGES[status]
    return message if not detail else f"{message} ({detail})"



def refuse_backlash(plant: Any, owner: str) -> None:
    """Refuse a plant with drive backlash (``plant.backlash > 0``) in ``owner``.

    Only the Moreau-Jean method models the gearbox play (its per-contact play state); every
    other solver, and everything built on them, calls this first.

    Raises
    ------
    ParameterError
        Naming the ``plant`` parameter of ``owner``, the rule and the backlash received.
    """
    if plant.backlash > 0:
        raise ParameterError(parameter_message(
            "plant", owner, "have motors.backlash = 0 (drive backlash is modelled by "
            "simulate(..., method='moreau') only)", f"motors.backlash = {plant.backlash:g} m"))
