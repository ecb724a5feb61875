"""Speed hold: a viscous staircase whose centre a PI law moves to hold a reference speed.

A staircase of slope ``k`` centred on ``c`` settles the body at ``c + F_ext / k`` under a
steady outside force ``F_ext`` (and at ``c (1 + c_drag / k)^-1``-like offsets under drag).
The law moves the centre with the speed error ``e = reference - estimate``::

    c = reference + kp e + ki integral e dt

so the integral removes the steady offset. The state is the integral (m). The staircase
shape (the allocation for slope ``k``) is solved once; moving its centre shifts every
contact speed by the same amount, clipped to the motor limits.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..errors import as_float
from ..model import Plant
from ..simulation import SampledLaw
from .base import Action, speed_limits
from .viscosity import VirtualViscosity

__all__ = ["SpeedHold"]


@dataclass(frozen=True)
class SpeedHold:
    """Hold ``reference`` (m/s) with a staircase of slope ``slope`` (N s/m) and a PI law.

    Parameters
    ----------
    reference : float, m/s
    slope : float, N s/m
        Viscosity of the staircase, ``> 0``.
    kp : float, dimensionless
        Proportional gain on the speed error (centre shift per m/s of error), ``>= 0``.
    ki : float, 1/s
        Integral gain, ``>= 0``.
    """

    reference: float
    slope: float
    kp: float = 0.5
    ki: float = 5.0

    def __post_init__(self) -> None:
        owner = "SpeedHold"
        object.__setattr__(self, "reference", as_float(self.reference, "reference", owner))
        object.__setattr__(self, "slope", as_float(self.slope, "slope", owner, low=0.0, low_open=True))
        object.__setattr__(self, "kp", as_float(self.kp, "kp", owner, low=0.0))
        object.__setattr__(self, "ki", as_float(self.ki, "ki", owner, low=0.0))

    def bind(self, plant: Plant, period: float) -> _SpeedHoldLaw:
        # The staircase's shape around 0 without limits: its centre moves, then it is clipped.
        shape = VirtualViscosity(self.slope, 0.0).speeds(replace(plant, motors=None))
        return _SpeedHoldLaw(self, shape, speed_limits(plant), float(period))


class _SpeedHoldLaw:
    n_states = 1

    def __init__(self, settings: SpeedHold, shape: np.ndarray, limits: tuple[float, float],
                 period: float) -> None:
        self.settings, self.shape, self.limits, self.period = settings, shape, limits, period

    def initial_state(self) -> np.ndarray:
        return np.zeros(1)

    def output(self, t: float, z: np.ndarray, estimate: float) -> Action:
        s = self.settings
        error = s.reference - estimate
        centre = s.reference + s.kp * error + s.ki * z[0]
        return Action(np.clip(self.shape + centre, *self.limits))

    def update(self, t: float, z: np.ndarray, estimate: float) -> np.ndarray:
        return z + (self.settings.reference - estimate) * self.period

    def sampled(self) -> SampledLaw:
        """The staircase's shape shifted by the PI law and clipped to the limits."""
        s = self.settings
        return SampledLaw(self.shape[None, :], pi=(s.reference, s.kp, s.ki), limits=self.limits,
                          period=self.period)
