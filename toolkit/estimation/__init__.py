"""Body-speed estimation from encoder counts: interchangeable estimators behind one interface.

Each estimator can ``run(record) -> EstimationResult`` offline and be stepped sample by
sample (``reset``, ``step``) in a closed loop:

- :mod:`~toolkit.estimation.finite_difference`: the baselines, finite differences of the
  central encoder and of the wheel encoders;
- :mod:`~toolkit.estimation.kalman`: the linear Kalman filter (filterpy) with the contact
  force as known input, and the Rauch-Tung-Striebel smoother (offline reference);
- :mod:`~toolkit.estimation.unscented`: the unscented Kalman filter whose process model is
  the exact simulator over one sample.

filterpy is imported only where a filter is built.
"""

from __future__ import annotations

from ._base import EstimationResult, Estimator, chi2_band
from ._input import ContactSpeedTracker, EstimatorModel, contact_speed_estimates
from ._prior import ModelPrior
from .adaptive import ADAPTING, FALLBACK, NOMINAL, AdaptiveKalman, KalmanEstimator, WheelSpeedBank
from .identification import LagIdentifier
from .monitor import ConsistencyMonitor, NoiseMatcher
from .alpha_beta import AlphaBetaTracker, kalata_gains
from .finite_difference import CentralDifference, WheelDifference
from .kalman import NominalKalman, RTSSmoother, steady_state_gain

from .unscented import UnscentedEstimator
from .window import AdaptiveWindow

__all__ = ["Estimator", "EstimationResult", "EstimatorModel", "ModelPrior", "chi2_band", "contact_speed_estimates",
           "ContactSpeedTracker",
           "CentralDifference", "WheelDifference", "KalmanEstimator", "NominalKalman", "RTSSmoother",
           "steady_state_gain", "UnscentedEstimator", "AdaptiveWindow", "AlphaBetaTracker", "kalata_gains",
           "AdaptiveKalman", "WheelSpeedBank", "LagIdentifier", "ConsistencyMonitor", "NoiseMatcher",
           "NOMINAL", "ADAPTING", "FALLBACK"]
