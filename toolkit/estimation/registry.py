"""The estimators by name, as a scene or the command line asks for them.

:func:`build_estimator` maps a name of :data:`ESTIMATOR_NAMES` to an estimator built from the
nominal model and the prior knowledge (``[estimation.model]``), so that a caller only maps
keys to arguments. :func:`truth_told` is the default filter told the true world: a reference
of what is achievable, for simulated records only.
"""

from __future__ import annotations

import math
from typing import Any

from ..errors import check_option
from ._input import EstimatorModel
from ..errors import ParameterTypeError, parameter_message
from ..model.truth import ModelPrior, TrueWorld

__all__ = ["ESTIMATOR_NAMES", "build_estimator", "truth_told", "TRUTH_TOLD"]

#: The name of :func:`truth_told`'s results.
TRUTH_TOLD = "truth_told"

#: Every estimator name, baselines first.
ESTIMATOR_NAMES = ("central_difference", "wheel_difference", "foaw_end", "foaw_best", "alpha_beta", "kalman",
                   "kalman_nominal", "rts", "ukf")


def build_estimator(name: str, model: EstimatorModel, *, prior: ModelPrior | None = None,
                    initial_covariance: Any = None) -> Any:
    """The estimator ``name`` on the nominal ``model``.

    Parameters
    ----------
    name : str
        One of :data:`ESTIMATOR_NAMES`: the finite differences of the central encoder and of
        the wheels; FOAW end- and best-fit (its band at one count, :class:`AdaptiveWindow`);
        the alpha-beta tracker (Kalata's gains at ``F_tot / (2 m)``); ``kalman``, the default
        (:class:`KalmanEstimator`: the nominal filter while it holds, the adaptive one after);
        ``kalman_nominal`` (:class:`NominalKalman`, trusting the scene); the RTS smoother over
        the default's pass (refused, and the filter's result, where the default's monitor
        tripped); the unscented filter.
    model : EstimatorModel
        The nominal scene.
    prior : ModelPrior, optional
        The adaptive filter's prior knowledge (``kalman``, ``rts``; default ``ModelPrior()``).
    initial_covariance : array_like of shape (2, 2), optional
        The Kalman filters' prior covariance of ``(X, V)``.
    """
    from .alpha_beta import AlphaBetaTracker
    from .kalman import KalmanEstimator
    from .finite_difference import CentralDifference, WheelDifference
    from .nominal import NominalKalman
    from .smoother import RTSSmoother
    from .unscented import UnscentedEstimator
    from .window import AdaptiveWindow

    check_option(name, "name", "build_estimator", ESTIMATOR_NAMES)
    sensors = model.sensors
    q = sensors.central.distance_per_count
    if name == "central_difference":
        return CentralDifference(sensors)
    if name == "wheel_difference":
        return WheelDifference(sensors, model.forces)
    if name in ("foaw_end", "foaw_best"):
        return AdaptiveWindow(sensors, fit=name[5:], band=q)
    if name == "alpha_beta":
        return AlphaBetaTracker.tuned(sensors, float(model.forces.sum()), model.mass)
    if name == "kalman":
        return KalmanEstimator(model, prior, initial_covariance=initial_covariance)
    if name == "rts":
        return RTSSmoother(model, prior=prior, initial_covariance=initial_covariance)
    make = {"kalman_nominal": NominalKalman, "ukf": UnscentedEstimator}[name]
    return make(model, initial_covariance=initial_covariance)


def truth_told(world: TrueWorld, *, initial_covariance: Any = None) -> Any:
    """The default ``kalman`` told the true world: the reference of what is achievable.

    Its model is built from the true plant and encoders (each wheel's friction magnitude,
    the mass, drag, motor lag and speed limits; the read noise, missed-count rate and jitter;
    the motors' wander) and its prior is the truth itself (no friction spread, the drag and
    lag ranges a single point, the wander's intensity, the missed-count rate told). Its
    results are named :data:`TRUTH_TOLD`. It reads the world, so it scores simulated records
    only; the gap between it and the default is the price of not knowing.

    Parameters
    ----------
    world : TrueWorld
        The world the record was simulated in (:func:`~toolkit.model.truth.realize`).
    initial_covariance : array_like of shape (2, 2), optional
        As :func:`build_estimator`'s.
    """
    from .kalman import KalmanEstimator
    from ._input import EstimatorModel

    if not isinstance(world, TrueWorld):
        raise ParameterTypeError(parameter_message("world", "truth_told", "be a TrueWorld", world))
    plant, sensors = world.plant, world.sensors
    motors = plant.motors
    lag = motors.lag if motors is not None else 0.0
    drift = world.truth.contact_drift
    model = EstimatorModel(plant.contacts.forces, plant.mass, sensors, motor_lag=lag, damping=plant.damping,
                           contact_drift=drift,
                           speed_limits=motors.speed_limits if motors is not None else (-math.inf, math.inf))
    prior = ModelPrior(friction_spread=0.0, drag_range=(plant.damping, plant.damping), lag_range=(lag, lag),
                       contact_drift=drift, missed_count_prob=min(sensors.missed_count_prob, 0.5))
    estimator = KalmanEstimator(model, prior, initial_covariance=initial_covariance)
    estimator.name = TRUTH_TOLD
    return estimator
