"""Body-speed estimation from encoder counts: interchangeable estimators behind one interface.

Each estimator can ``run(record) -> EstimationResult`` offline and be stepped sample by
sample (``reset``, ``observe``, ``commanded``) in a closed loop. The baselines:
:mod:`~toolkit.estimation.finite_difference`, :mod:`~toolkit.estimation.window` (FOAW) and
:mod:`~toolkit.estimation.alpha_beta`. The model-based filters:
:mod:`~toolkit.estimation.kalman` (the default ``kalman``: the nominal filter of
:mod:`~toolkit.estimation.nominal` while the data agree with the scene, the adaptive one of
:mod:`~toolkit.estimation.adaptive` after; its parts :mod:`~toolkit.estimation.consider`,
:mod:`~toolkit.estimation.monitor`, :mod:`~toolkit.estimation.identification`,
:mod:`~toolkit.estimation._hold`), :mod:`~toolkit.estimation.smoother` (RTS) and
:mod:`~toolkit.estimation.unscented`. :mod:`~toolkit.estimation.registry` builds them by name,
and the default told the true world (``truth_told``). Derivations: docs/estimation.md.
"""

from __future__ import annotations

from ._base import EstimationResult, Estimator, chi2_band
from ._input import EstimatorModel
from .contact_speeds import ContactSpeedTracker, contact_speed_estimates
from ..model.truth import ModelPrior
from .adaptive import ADAPTING, FALLBACK, NOMINAL, AdaptiveKalman
from .wheel_bank import WheelSpeedBank
from .identification import LagIdentifier, MissedCountRate, RideCheck
from .monitor import ConsistencyMonitor, NoiseMatcher
from .alpha_beta import AlphaBetaTracker, kalata_gains
from .finite_difference import CentralDifference, WheelDifference
from .kalman import KalmanEstimator
from .nominal import FilterPass, NominalKalman, steady_state_gain
from .smoother import RTSSmoother

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
