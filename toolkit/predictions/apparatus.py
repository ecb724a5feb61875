"""The hardware the prediction checks run on, and the experiment protocol's carry phase.

:class:`Apparatus` is the paper's kind of rig: ``n`` contacts of equal friction ``f`` on a
body of moving inertia ``m``, motors with a lag and symmetric speed limits ``+-v_max``, and
the encoders. It builds the plant of each run in one of two modes:

- ``"ideal"``: no motor lag and the controller reads the true speed (the model the
  predictions of :mod:`.theory` are about);
- ``"loop"``: the motors' lag, the encoders and an estimator in the loop.

:class:`CarryThen` is the protocol of every run: the wheels carry the body at a speed
(``V0``) for a while, so that the motors and the estimator have settled, then a controller
takes over; the run's clock for the measurement starts there.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ..errors import as_float, check_option
from ..controllers.base import Action, Controller
from ..errors import ParameterError, ParameterTypeError, parameter_message
from ..model import ContactSet, Motors, Plant
from ..model.carousel import CAROUSEL
from ..model.sensors import Sensors
from ..simulation import SampledLaw

__all__ = ["Apparatus", "CarryThen", "MODES"]

#: The two ways a check runs: the ideal model, or sensors + estimator + motor lag in the loop.
MODES = ("ideal", "loop")
#: Most contacts an apparatus built by :meth:`Apparatus.with_contacts` may have.
MAX_CONTACTS = 10_000


@dataclass(frozen=True, eq=False)
class Apparatus:
    """A body on ``n`` equal contacts with motors and encoders.

    Parameters
    ----------
    plant : Plant
        Friction magnitudes (all equal), mass, drag and motors (finite, symmetric speed
        limits ``(-v_max, v_max)``); its contact speeds, commands and outside force are not
        used (each run sets its own).
    sensors : Sensors or None
        The encoders, one wheel encoder per contact; ``None``: only the ideal mode runs.

    Notes
    -----
    The predictions neglect drag: a plant with ``damping > 0`` runs as declared and the
    checks show the difference.
    """

    plant: Plant
    sensors: Sensors | None = None

    def __post_init__(self) -> None:
        owner = "Apparatus"
        plant = self.plant
        if not isinstance(plant, Plant):
            raise ParameterTypeError(parameter_message("plant", owner, "be a Plant", plant))
        forces = plant.contacts.forces
        if not np.all(forces == forces[0]) or forces[0] <= 0:
            raise ParameterError(parameter_message(
                "plant.contacts.forces", owner, "be one equal friction magnitude > 0 (the paper's "
                "equal load)", forces.tolist()))
        lo, hi = (plant.motors.speed_limits if plant.motors is not None else (-np.inf, np.inf))
        if not (np.isfinite(hi) and hi > 0 and lo == -hi):
            raise ParameterError(parameter_message(
                "plant.motors.speed_limits", owner, "be finite and symmetric (-v_max, v_max)",
                (lo, hi)))
        if self.sensors is not None:
            Sensors.checked(self.sensors, plant.n, owner)

    @classmethod
    def carousel(cls, mass: float = 1.0, n: int = 10) -> Apparatus:
        """The paper's carousel (:data:`toolkit.model.carousel.CAROUSEL`): ``n`` (ten) equal
        wheels with ``F_tot / m = 2 m/s^2``, motors of lag 7.5 ms within ``+-0.35 m/s``, the
        encoders of :meth:`CAROUSEL.sensors <toolkit.model.carousel.CarouselHardware.sensors>` at 50 Hz. Without drag only ``F_tot / m``
        matters, so ``mass`` (kg) only sets the unit of the forces."""
        mass = as_float(mass, "mass", "Apparatus.carousel", low=0.0, low_open=True)
        return cls.with_total_force(n, CAROUSEL.acceleration * mass,
                                    Plant(ContactSet([0.0], [1.0]), mass=mass, motors=CAROUSEL.motors()),
                                    CAROUSEL.sensors(1), "Apparatus.carousel")

    def with_contacts(self, n: int) -> Apparatus:
        """The same apparatus with ``n`` equal contacts sharing its total friction ``F_tot``
        (each ``F_tot / n``): the same body, motors, drag and kind of encoders, one wheel
        encoder per contact."""
        return self.with_total_force(n, self.total_force, self.plant, self.sensors, "Apparatus.with_contacts")

    @classmethod
    def with_total_force(cls, n: Any, total_force: float, plant: Plant, sensors: Sensors | None,
                         owner: str) -> Apparatus:
        """``n`` contacts of ``total_force / n`` (N) on ``plant``'s body and motors, with
        ``sensors``' kind of encoders for ``n`` wheels."""
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or not 1 <= n <= MAX_CONTACTS:
            raise ParameterError(parameter_message("n", owner, f"be an integer in [1, {MAX_CONTACTS}]", n))
        contacts = ContactSet(np.zeros(int(n)), np.full(int(n), total_force / int(n)))
        return cls(replace(plant, contacts=contacts, commands=None, external_force=0.0),
                   None if sensors is None else replace(sensors, n_wheels=int(n)))

    # -- properties -----------------------------------------------------------------------
    @property
    def n(self) -> int:
        """Number of contacts."""
        return self.plant.n

    @property
    def force(self) -> float:
        """Friction magnitude of each contact ``f``, N."""
        return float(self.plant.contacts.forces[0])

    @property
    def total_force(self) -> float:
        """``F_tot = n f``, N."""
        return float(self.plant.contacts.total_force)

    @property
    def mass(self) -> float:
        """Moving inertia ``m``, kg."""
        return float(self.plant.mass)

    @property
    def speed_limit(self) -> float:
        """``v_max``, m/s."""
        return float(self.plant.motors.speed_limits[1])

    def check_mode(self, mode: Any, owner: str) -> str:
        """``mode`` checked: one of :data:`MODES`; ``"loop"`` needs sensors."""
        mode = check_option(mode, "mode", owner, MODES)
        if mode == "loop" and self.sensors is None:
            raise ParameterError(parameter_message(
                "mode", owner, "be 'ideal' on an apparatus without sensors (the loop reads encoders)",
                mode))
        return mode

    def run_plant(self, speeds: Any, mode: str) -> Plant:
        """The plant of one run: motors settled at ``speeds`` (m/s, shape (n,)) at ``t = 0``;
        in the ideal mode without motor lag."""
        motors = self.plant.motors
        if mode == "ideal":
            motors = Motors(speed_limits=motors.speed_limits)
        contacts = ContactSet(np.broadcast_to(np.asarray(speeds, dtype=float), (self.n,)).copy(),
                              self.plant.contacts.forces)
        return replace(self.plant, contacts=contacts, motors=motors, commands=None, external_force=0.0)


@dataclass(frozen=True, eq=False)
class CarryThen:
    """Carry the body at ``speed`` (every contact commanded there) until ``start``, then run
    ``controller`` with its clock starting at ``start``.

    Parameters
    ----------
    controller : Controller
    start : float, s
        ``>= 0``.
    speed : float, m/s
        The carrying speed (within the motor limits).
    """

    controller: Controller
    start: float
    speed: float

    def __post_init__(self) -> None:
        owner = "CarryThen"
        if not hasattr(self.controller, "bind"):
            raise ParameterTypeError(parameter_message(
                "controller", owner, "be a controller (toolkit.controllers)", self.controller))
        object.__setattr__(self, "start", as_float(self.start, "start", owner, low=0.0))
        object.__setattr__(self, "speed", as_float(self.speed, "speed", owner))

    def bind(self, plant: Plant, period: float) -> _CarryLaw:
        return _CarryLaw(self.controller.bind(plant, period), self.start, float(period),
                         np.full(plant.n, self.speed))


class _CarryLaw:
    """Sample times within 1e-9 periods of ``start`` count as reached; the inner clock
    ``t - start`` is snapped to the sample grid when it lies that close to it, so that an
    inner law's own switching times on the grid are not lost to rounding."""

    def __init__(self, law: Any, start: float, period: float, carry: np.ndarray) -> None:
        self.law, self.start, self.period, self.carry = law, start, period, carry
        self.switch = start - 1e-9 * period
        self.n_states = law.n_states

    def _inner(self, t: float) -> float:
        inner = t - self.start
        grid = round(inner / self.period) * self.period
        return grid if abs(inner - grid) <= 1e-9 * self.period else inner

    def initial_state(self) -> np.ndarray:
        return self.law.initial_state()

    def output(self, t: float, z: np.ndarray, estimate: float) -> Action:
        if t < self.switch:
            return Action(self.carry)
        return self.law.output(self._inner(t), z, estimate)

    def update(self, t: float, z: np.ndarray, estimate: float) -> np.ndarray:
        if t < self.switch:
            return z
        return self.law.update(self._inner(t), z, estimate)

    def sampled(self) -> SampledLaw | None:
        """The inner law's compiled form after a carry phase (None when the inner law has
        none, or a carry phase of its own)."""
        inner = getattr(self.law, "sampled", None)
        inner = inner() if inner is not None else None
        if inner is None or inner.carry is not None:
            return None
        return replace(inner, carry=self.carry, switch=self.switch, start=self.start,
                       period=self.period)
