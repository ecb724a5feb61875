"""A test rig: drive the body along a slow speed ramp and record the force it takes.

The paper measured friction by moving the body quasi-statically through the band of
interest while measuring force. Here the rig pushes the body with the outside force of a PI
law on the speed estimate, ``F = kp m (V_ref(t) - estimate) + ki m integral(...)``, while the
contacts hold a fixed set of speeds; at quasi-static speeds the rig's force balances the
contacts' friction, so ``-F`` measures ``F_contacts(V)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import as_float
from ..errors import ParameterError, parameter_message
from ..model import Plant
from .base import Action

__all__ = ["ForceDrive"]


@dataclass(frozen=True)
class ForceDrive:
    """Ramp the body from ``v_start`` to ``v_end`` (m/s) over ``duration`` (s).

    Parameters
    ----------
    speeds : array_like of shape (n,), m/s
        Contact speeds held during the sweep.
    v_start, v_end : float, m/s
    duration : float, s
        Ramp length, ``> 0``; the reference then holds ``v_end``.
    bandwidth : float, 1/s
        ``kp``: the rig's speed-loop bandwidth (force per unit mass per m/s of error), ``> 0``.
    ki : float, 1/s^2
        Integral gain, ``>= 0``.
    """

    speeds: np.ndarray
    v_start: float
    v_end: float
    duration: float
    bandwidth: float = 20.0
    ki: float = 100.0

    def __post_init__(self) -> None:
        owner = "ForceDrive"
        speeds = np.array(self.speeds, dtype=float)
        if speeds.ndim != 1 or not np.all(np.isfinite(speeds)):
            raise ParameterError(parameter_message("speeds", owner, "be a finite 1-D array", self.speeds))
        object.__setattr__(self, "speeds", speeds)
        for name in ("v_start", "v_end"):
            object.__setattr__(self, name, as_float(getattr(self, name), name, owner))
        object.__setattr__(self, "duration", as_float(self.duration, "duration", owner, low=0.0, low_open=True))
        object.__setattr__(self, "bandwidth", as_float(self.bandwidth, "bandwidth", owner, low=0.0, low_open=True))
        object.__setattr__(self, "ki", as_float(self.ki, "ki", owner, low=0.0))

    def reference(self, t: float) -> float:
        """The speed the rig asks for at time ``t`` (s), m/s."""
        share = min(max(t / self.duration, 0.0), 1.0)
        return self.v_start + share * (self.v_end - self.v_start)

    def bind(self, plant: Plant, period: float) -> _DriveLaw:
        if self.speeds.size != plant.n:
            raise ParameterError(parameter_message(
                "speeds", "ForceDrive", f"have one speed per contact ({plant.n})", self.speeds.size))
        return _DriveLaw(self, plant.mass, float(period))


class _DriveLaw:
    n_states = 1

    def __init__(self, settings: ForceDrive, mass: float, period: float) -> None:
        self.settings, self.mass, self.period = settings, mass, period

    def initial_state(self) -> np.ndarray:
        return np.zeros(1)

    def output(self, t: float, z: np.ndarray, estimate: float) -> Action:
        s = self.settings
        error = s.reference(t) - estimate
        return Action(s.speeds, self.mass * (s.bandwidth * error + s.ki * z[0]))

    def update(self, t: float, z: np.ndarray, estimate: float) -> np.ndarray:
        return z + (self.settings.reference(t) - estimate) * self.period
