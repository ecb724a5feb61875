"""Body-speed estimation from encoder counts: interchangeable estimators behind one interface.

Each estimator can ``run(record) -> EstimationResult`` offline and be stepped sample by
sample (``reset``, ``step``) in a closed loop:

- :mod:`~toolkit.estimation.finite_difference`: the baselines, finite differences of the
  central encoder and of the wheel encoders;
- :mod:`~toolkit.estimation.window`, :mod:`~toolkit.estimation.alpha_beta`: the
  practitioner's baselines, first-order adaptive windowing (FOAW) and the alpha-beta tracker;
- :mod:`~toolkit.estimation.kalman`: the nominal Kalman filter (filterpy) with the contact
  force as known input, and the Rauch-Tung-Striebel smoother (offline reference);
- :mod:`~toolkit.estimation.adaptive`: the default ``kalman``, the nominal filter while the
  data agree with the scene and an adaptive one (identification of friction, drag and lag,
  an interacting multiple model of the body's modes, matched noise, a consistency monitor
  that acts) from the first sample where they do not; :mod:`~toolkit.estimation.monitor`,
  :mod:`~toolkit.estimation.identification`, :mod:`~toolkit.estimation._hold` (the exact
  holds, one optional layer) are its parts;
- :mod:`~toolkit.estimation.unscented`: the unscented Kalman filter whose process model is
  the exact simulator over one sample;
- :mod:`~toolkit.estimation.registry`: the estimators by name, and the default told the true
  world (``truth_told``, a reference for simulated records).

filterpy is imported only where a filter is built.
"""

from __future__ import annotations

from ._base import EstimationResult, Estimator, chi2_band
from ._input import ContactSpeedTracker, EstimatorModel, contact_speed_estimates
from ..model.truth import ModelPrior
from .adaptive import ADAPTING, FALLBACK, NOMINAL, AdaptiveKalman, KalmanEstimator, WheelSpeedBank
from .identification import LagIdentifier, MissedCountRate, RideCheck
from .monitor import ConsistencyMonitor, NoiseMatcher
from .alpha_beta import AlphaBetaTracker, kalata_gains
from .finite_difference import CentralDifference, WheelDifference
from .kalman import FilterPass, NominalKalman, RTSSmoother, steady_state_gain

from .unscented import UnscentedEstimator
from .window import AdaptiveWindow
from .registry import ESTIMATOR_NAMES, TRUTH_TOLD, build_estimator, truth_told
from ._base import PHASES, phase_masks

__all__ = ["Estimator", "EstimationResult", "EstimatorModel", "ModelPrior", "chi2_band", "contact_speed_estimates", "FilterPass",
           "ContactSpeedTracker",
           "CentralDifference", "WheelDifference", "KalmanEstimator", "NominalKalman", "RTSSmoother",
           "steady_state_gain", "UnscentedEstimator", "AdaptiveWindow", "AlphaBetaTracker", "kalata_gains",
           "AdaptiveKalman", "WheelSpeedBank", "LagIdentifier", "MissedCountRate", "RideCheck", "ConsistencyMonitor", "NoiseMatcher",
           "NOMINAL", "ADAPTING", "FALLBACK", "ESTIMATOR_NAMES", "build_estimator", "truth_told", "TRUTH_TOLD", "PHASES", "phase_masks"]
