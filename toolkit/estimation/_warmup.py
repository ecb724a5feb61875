"""Compile the estimators' kernels ahead of timing: ``warm_up`` (``active-contacts warm`` and
the tests call it)."""

from __future__ import annotations

import time

import numpy as np

from ..model.carousel import CAROUSEL
from ._input import EstimatorModel
from .registry import ESTIMATOR_NAMES, build_estimator

__all__ = ["warm_up"]


def warm_up() -> float:
    """Compile (or load from numba's cache) the kernels every estimator of
    :data:`~toolkit.estimation.registry.ESTIMATOR_NAMES` runs, each warmed on its short record
    (:meth:`~toolkit.estimation._base.Estimator.warm_up`) of the paper's carousel (its
    encoders with backlash, lagging motors with speed limits) on unequal wheels. Returns the
    time it took (s)."""
    started = time.perf_counter()
    model = EstimatorModel(np.linspace(0.8, 1.2, CAROUSEL.n_wheels), CAROUSEL.moving_mass, CAROUSEL.sensors(),
                           motor_lag=CAROUSEL.motor_lag, speed_limits=CAROUSEL.motors().speed_limits)
    for name in ESTIMATOR_NAMES:
        build_estimator(name, model).warm_up()
    return time.perf_counter() - started
