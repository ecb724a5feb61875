"""The baselines: finite differences of the encoder counts.

- :class:`CentralDifference`: ``V_k = (c_k - c_{k-1}) q_c / (t_k - t_{k-1})``, the central
  encoder's backward difference. Its error is the difference of two quantization errors
  (a sawtooth at constant speed, up to one count, ``q_c / h`` = 10.2 mm/s for the carousel)
  plus the lag of a backward difference under acceleration (``a h / 2``).
- :class:`WheelDifference`: each contact's speed from its wheel's backward difference
  (3.9 mm/s per count, 40 mm/s through a backlash reversal); the body-speed estimate is the
  **weighted median of the estimated contact speeds**, the equilibrium set of
  :meth:`ContactSet.equilibrium <toolkit.model.ContactSet.equilibrium>` (its midpoint when
  it is a band). That is the body's speed only once it has settled on the contacts: it
  ignores inertia entirely and serves as the no-central-encoder baseline.

Both report the variance of a difference of two independent uniform quantization errors,
``2 (q^2 / 12) / h^2``, honest only while the count changes irregularly.
"""

from __future__ import annotations

import numpy as np

from ..laws import quantization_variance
from ..model.contacts import ContactSet
from ..model.sensors import EncoderSample, Sensors
from ..errors import ParameterTypeError, parameter_message
from ..errors import as_float
from ._base import Estimator

__all__ = ["CentralDifference", "WheelDifference"]


class CentralDifference(Estimator):
    """Backward difference of the central encoder.

    Parameters
    ----------
    sensors : Sensors
    """

    name = "central_difference"

    def __init__(self, sensors: Sensors) -> None:
        if not isinstance(sensors, Sensors):
            raise ParameterTypeError(parameter_message("sensors", type(self).__name__, "be a Sensors", sensors))
        self.sensors = sensors
        self.reset()

    def reset(self, *, speed: float = 0.0, speed_std: float | None = None,
              contact_speeds: object = None) -> None:
        self._speed = as_float(speed, "speed", f"{type(self).__name__}.reset")
        self._last: tuple[float, int] | None = None

    def observe(self, sample: EncoderSample) -> tuple[float, float]:
        q = self.sensors.central.distance_per_count
        last, self._last = self._last, (sample.time, sample.central_count)
        if last is None:
            return self._speed, 2.0 * quantization_variance(q * self.sensors.rate)
        h = sample.time - last[0]
        return (sample.central_count - last[1]) * q / h, 2.0 * quantization_variance(q / h)

    def commanded(self, command: object, force: float = 0.0) -> None:
        """Unused: finite differences do not predict."""


class WheelDifference(Estimator):
    """Contact speeds by backward differences of the wheels; body speed = their weighted median.

    Parameters
    ----------
    sensors : Sensors
    forces : array_like of shape (n,), N
        Friction magnitudes (the weights of the median).

    Attributes
    ----------
    contact_speeds : ndarray of shape (n,), m/s
        The latest contact-speed estimates.
    """

    name = "wheel_difference"

    def __init__(self, sensors: Sensors, forces: object) -> None:
        if not isinstance(sensors, Sensors):
            raise ParameterTypeError(parameter_message("sensors", type(self).__name__, "be a Sensors", sensors))
        self.sensors = sensors
        self.contacts = ContactSet(np.zeros(sensors.n_wheels), forces)
        self.reset()

    def reset(self, *, speed: float = 0.0, speed_std: float | None = None,
              contact_speeds: object = None) -> None:
        self._speed = as_float(speed, "speed", f"{type(self).__name__}.reset")
        self._last: tuple[float, np.ndarray] | None = None
        self.contact_speeds = np.zeros(self.sensors.n_wheels)
        self._first = False

    def observe(self, sample: EncoderSample) -> tuple[float, float]:
        q = self.sensors.wheel.distance_per_count
        counts = np.asarray(sample.wheel_counts)
        last, self._last = self._last, (sample.time, counts)
        self._first = last is None
        if last is None:
            return self._speed, 2.0 * quantization_variance(q * self.sensors.rate)
        h = sample.time - last[0]
        self.contact_speeds = (counts - last[1]) * q / h
        lo, hi = self.contacts.with_speeds(self.contact_speeds).equilibrium()
        return 0.5 * (lo + hi), 2.0 * quantization_variance(q / h)

    def commanded(self, command: object, force: float = 0.0) -> None:
        """With no wheel history yet, the commands are the contact speeds' best guess."""
        if self._first:
            self.contact_speeds = np.asarray(command, dtype=float)
