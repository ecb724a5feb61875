"""Compile the estimators' kernels ahead of timing: ``warm_up`` (``active-contacts warm`` and
the tests call it)."""

from __future__ import annotations

import time

import numpy as np

from ..model.sensors import Encoder, Sensors
from ._input import EstimatorModel
from .registry import ESTIMATOR_NAMES, build_estimator

__all__ = ["warm_up"]


def warm_up() -> float:
    """Compile (or load from numba's cache) the kernels every estimator of
    :data:`~toolkit.estimation.registry.ESTIMATOR_NAMES` runs, each warmed on its short record
    (:meth:`~toolkit.estimation._base.Estimator.warm_up`) of a carousel-like model: ten unequal
    wheels, lagging motors with speed limits, the paper's encoders with backlash. Returns the
    time it took (s)."""
    started = time.perf_counter()
    rate = 50.0
    sensors = Sensors(Encoder(8192.0, 0.266, rate), Encoder(3591.84, 0.045, rate, backlash=8e-4), 10)
    model = EstimatorModel(np.linspace(0.8, 1.2, 10), 5.0, sensors, motor_lag=0.0075,
                           speed_limits=(-0.35, 0.35))
    for name in ESTIMATOR_NAMES:
        build_estimator(name, model).warm_up()
    return time.perf_counter() - started
