"""The alpha-beta tracker of the central encoder, tuned by Kalata's tracking index.

A fixed-gain filter of position and speed, ``X- = X + h V``, ``r = z - X-``, ``X = X- +
alpha r``, ``V = V + (beta / h) r``, with ``z`` the count's cell centre and the gains
Kalata's (IEEE Trans. AES 20(2), 1984) for the tracking index ``sigma_a h^2 / sigma_z``: the
steady-state Kalman gains of the piecewise-constant white-acceleration model. Tuned with
``sigma_z`` the quantization's and ``sigma_a = F_tot / (2 m)``. Derivations and references:
docs/estimation.md.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..laws import cell_centre
from .._compiled import budget_clock
from ..errors import as_float
from ..errors import ParameterTypeError, parameter_message
from ..model.sensors import EncoderRecord, EncoderSample, Sensors
from ._base import EstimationResult, Estimator, score

__all__ = ["AlphaBetaTracker", "kalata_gains"]


def kalata_gains(index: float) -> tuple[float, float]:
    """``(alpha, beta)`` of the tracking index ``Lambda > 0`` (Kalata's relations)."""
    index = as_float(index, "index", "kalata_gains", low=0.0, low_open=True)
    root = math.sqrt(index * index + 8.0 * index)
    alpha = -(index * index + 8.0 * index - (index + 4.0) * root) / 8.0
    beta = (index * index + 4.0 * index - index * root) / 4.0
    return alpha, beta


class AlphaBetaTracker(Estimator):
    """Alpha-beta tracker of the central encoder (the module; docs/estimation.md).

    Parameters
    ----------
    sensors : Sensors
    accel_std : float, m/s^2
        ``sigma_a``, the white acceleration's std (``> 0``); see :meth:`tuned`.

    Attributes
    ----------
    alpha, beta : float
        The gains; ``covariance`` (2, 2) the steady posterior covariance of ``(X, V)``.
    """

    name = "alpha_beta"

    def __init__(self, sensors: Sensors, accel_std: float) -> None:
        owner = type(self).__name__
        if not isinstance(sensors, Sensors):
            raise ParameterTypeError(parameter_message("sensors", owner, "be a Sensors", sensors))
        self.sensors = sensors
        self.accel_std = as_float(accel_std, "accel_std", owner, low=0.0, low_open=True)
        h, q = sensors.period, sensors.central.distance_per_count
        sigma_z = q / math.sqrt(12.0)
        self.index = self.accel_std * h * h / sigma_z
        self.alpha, self.beta = kalata_gains(self.index)
        a, b = self.alpha, self.beta
        self.covariance = sigma_z**2 * np.array([[a, b / h], [b / h, b * (2 * a - b) / (2 * (1 - a) * h * h)]])
        self.covariance.setflags(write=False)
        self._h, self._q = h, q
        self.reset()

    @classmethod
    def tuned(cls, sensors: Sensors, total_force: float, mass: float) -> AlphaBetaTracker:
        """The tracker with ``sigma_a = F_tot / (2 m)`` (the module; docs/estimation.md)."""
        owner = f"{cls.__name__}.tuned"
        total_force = as_float(total_force, "total_force", owner, low=0.0, low_open=True)
        mass = as_float(mass, "mass", owner, low=0.0, low_open=True)
        return cls(sensors, 0.5 * total_force / mass)

    def reset(self, *, speed: float = 0.0, speed_std: float | None = None,
              contact_speeds: object = None) -> None:
        self._speed0 = as_float(speed, "speed", f"{type(self).__name__}.reset")
        self._x: tuple[float, float] | None = None

    def observe(self, sample: EncoderSample) -> tuple[float, float]:
        z = cell_centre(sample.central_count, self._q)
        if self._x is None:
            self._x = (z, self._speed0)
        else:
            X, V = self._x
            h = sample.time - self._t
            r = z - (X + h * V)
            self._x = (X + h * V + self.alpha * r, V + self.beta / h * r)
        self._t = sample.time
        return self._x[1], float(self.covariance[1, 1])

    def commanded(self, command: Any, force: float = 0.0) -> None:
        """Unused: the tracker knows no input."""

    def run(self, record: EncoderRecord, *, speed: float = 0.0,
            speed_std: float | None = None) -> EstimationResult:
        """Estimate every sample of ``record``; the result carries the position estimates
        and the steady covariance (the tracker's NEES)."""
        self._check_record(record)
        started = budget_clock()
        self.reset(speed=speed)
        states = []
        for k in range(record.n_samples):
            self.observe(record.sample(k))
            states.append(self._x)
        wall = budget_clock() - started
        x = np.array(states)
        K = record.n_samples
        return score(record, self.name, x[:, 1], np.full(K, self.covariance[1, 1]), wall,
                     position=x[:, 0], covariance=np.broadcast_to(self.covariance, (K, 2, 2)))
