"""The controller interface: a law from the speed estimate to contact-speed commands.

A controller is a frozen settings object; :meth:`Controller.bind` prepares it for one plant
and sample period and returns a :class:`ControlLaw`, whose two pure functions a closed loop
calls once per sample::

    action = law.output(t, z, estimate)     # commands (n,) m/s and an outside force (N)
    z = law.update(t, z, estimate)          # the controller's own state, shape (law.n_states,)

The same law runs in the toolkit's loop, as a ``control.NonlinearIOSystem``
(:mod:`toolkit.loop.interop`), and in the compiled loop when ``law.sampled()`` gives its
arithmetic as a :class:`toolkit.simulation.SampledLaw`."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np

from ..errors import ParameterError, parameter_message
from ..model import Plant
from ..simulation import SampledLaw

__all__ = ["Controller", "ControlLaw", "Action"]


@dataclass(frozen=True)
class Action:
    """What a controller sends for one sample period.

    Attributes
    ----------
    commands : ndarray of shape (n,), m/s
        Commanded contact speeds, held until the next sample.
    force : float, N
        Outside force applied to the body (0 unless the controller drives the body itself,
        as a test rig does).
    """

    commands: np.ndarray
    force: float = 0.0


@runtime_checkable
class ControlLaw(Protocol):
    """A controller bound to a plant and a sample period."""

    n_states: int

    def initial_state(self) -> np.ndarray:
        """The state at ``t = 0``, shape (n_states,)."""

    def output(self, t: float, z: np.ndarray, estimate: float) -> Action:
        """The action at sample time ``t`` (s) from the speed estimate (m/s)."""

    def update(self, t: float, z: np.ndarray, estimate: float) -> np.ndarray:
        """The state at the next sample."""


@runtime_checkable
class Controller(Protocol):
    """Settings of a controller (frozen dataclass)."""

    def bind(self, plant: Plant, period: float) -> ControlLaw:
        """Prepare the law for ``plant`` sampled every ``period`` seconds."""


class StatelessLaw:
    """Base of laws without a state of their own: ``update`` keeps the empty state."""

    n_states = 0

    def initial_state(self) -> np.ndarray:
        return np.zeros(0)

    def update(self, t: float, z: np.ndarray, estimate: float) -> np.ndarray:
        return z

    def output(self, t: float, z: np.ndarray, estimate: float) -> Action:  # pragma: no cover
        raise NotImplementedError

    def sampled(self) -> SampledLaw | None:
        """The law as the compiled loop runs it (None: no compiled form)."""
        return None


def speed_limits(plant: Plant) -> tuple[float, float]:
    """The plant's motor speed limits (m/s), ``(-inf, inf)`` for ideal motors."""
    return plant.motors.speed_limits if plant.motors is not None else (-np.inf, np.inf)


def finite_limits(plant: Plant, owner: str) -> tuple[float, float]:
    """The speed limits, refused with a clear error when a controller needs them finite."""
    lo, hi = speed_limits(plant)
    if not (np.isfinite(lo) and np.isfinite(hi)):
        raise ParameterError(parameter_message(
            "plant", owner, "have finite motor speed limits (Motors(speed_limits=(lo, hi)))",
            (lo, hi)))
    return float(lo), float(hi)

