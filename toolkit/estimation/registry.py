"""The estimators by name, as a scene or the command line asks for them.

:func:`build_estimator` maps a name of :data:`ESTIMATOR_NAMES` to an estimator built from the
nominal model and the prior knowledge (``[estimation.model]``), so that a caller only maps
keys to arguments.
"""

from __future__ import annotations

from typing import Any

from ..errors import check_option
from ._input import EstimatorModel
from ..model.truth import ModelPrior

__all__ = ["ESTIMATOR_NAMES", "build_estimator"]

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
        ``kalman_nominal`` (:class:`NominalKalman`, trusting the scene); the RTS smoother; the
        unscented filter.
    model : EstimatorModel
        The nominal scene.
    prior : ModelPrior, optional
        The adaptive filter's prior knowledge (``kalman``; default ``ModelPrior()``).
    initial_covariance : array_like of shape (2, 2), optional
        The Kalman filters' prior covariance of ``(X, V)``.
    """
    from .alpha_beta import AlphaBetaTracker
    from .adaptive import KalmanEstimator
    from .finite_difference import CentralDifference, WheelDifference
    from .kalman import NominalKalman, RTSSmoother
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
    make = {"kalman_nominal": NominalKalman, "rts": RTSSmoother, "ukf": UnscentedEstimator}[name]
    return make(model, initial_covariance=initial_covariance)
