"""Targets of a schedule: what the body should do.

- :class:`SpeedTrajectory`: follow a body speed ``V_ref(t)`` (tracking);
- :class:`Braking`: take the body from ``v0`` to a target speed as fast as possible, or
  along a constant deceleration that lasts a given time.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import as_float, as_float_array
from ..errors import ParameterError, parameter_message

__all__ = ["SpeedTrajectory", "Braking"]


@dataclass(frozen=True, eq=False)
class SpeedTrajectory:
    """A target body speed over time, linear between samples and held after the last one.

    Parameters
    ----------
    times : array_like of shape (k,), s
        Sample times, ``>= 0`` and strictly increasing.
    speeds : array_like of shape (k,), m/s
        Target body speed at each sample time.

    Examples
    --------
    >>> ref = SpeedTrajectory([0.0, 1.0], [0.0, 0.2])
    >>> float(ref(0.5))
    0.1
    """

    times: np.ndarray
    speeds: np.ndarray

    def __post_init__(self) -> None:
        owner = "SpeedTrajectory"
        times = as_float_array(self.times, "times", owner)
        speeds = as_float_array(self.speeds, "speeds", owner)
        if speeds.shape != times.shape:
            raise ParameterError(parameter_message(
                "speeds", owner, f"have the same length as 'times' ({times.size})",
                f"an array of length {speeds.size}"))
        if times[0] < 0 or np.any(np.diff(times) <= 0):
            raise ParameterError(parameter_message(
                "times", owner, "be >= 0 and strictly increasing",
                times.tolist() if times.size <= 8 else f"[{times[0]:g} .. {times[-1]:g}]"))
        object.__setattr__(self, "times", times)
        object.__setattr__(self, "speeds", speeds)

    def __call__(self, t: Any) -> np.ndarray:
        """Target speed (m/s) at times ``t`` (s); constant before the first/after the last sample."""
        return np.interp(np.asarray(t, dtype=float), self.times, self.speeds)

    @property
    def end(self) -> float:
        """Time of the last sample, s."""
        return float(self.times[-1])


@dataclass(frozen=True)
class Braking:
    """Bring the body from its initial speed to ``speed``.

    Parameters
    ----------
    speed : float, m/s
        Final body speed.
    duration : float or None, s
        ``None``: as fast as possible (the objective ``int (V - speed)^2 dt`` is minimized,
        whose optimum reaches ``speed`` at the earliest time, see
        :func:`~toolkit.schedule.braking_time`).
        A positive number: follow the constant deceleration from ``v0`` to ``speed`` over
        this time (the paper's ``dT``), then hold.
    """

    speed: float
    duration: float | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "speed", as_float(self.speed, "speed", "Braking"))
        if self.duration is not None:
            object.__setattr__(self, "duration", as_float(
                self.duration, "duration", "Braking", low=0.0, low_open=True))
