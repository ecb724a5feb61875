"""The paper's predictions: what the ideal model says (:mod:`.theory`) and the closed-loop checks.

- :func:`viscosity_check` (:mod:`.viscosity`): the startup time constant against the
  commanded viscosity over a seeded sweep (the paper's 490 runs), under two definitions of
  the time constant (``"least_squares"``, the paper's exponential fit, and ``"crossing_63"``),
  each against the exact ideal model's prediction (:func:`~.theory.startup_correction`);
- :func:`friction_fraction_check` (:mod:`.friction`): ``mu/mu0`` measured with a force rig
  and the ``+v_max -> -v_max`` transition time for ``j = 0..N/2`` reversed contacts;
- :func:`prediction_checks`: both, ideal and in the loop, with their shortfalls.

Each check runs on an :class:`Apparatus` (default: the paper's carousel) in the ``"ideal"``
mode (no motor lag, true speed) or the ``"loop"`` mode (motor lag, encoders, estimator).
"""

from .apparatus import MODES, Apparatus, CarryThen
from .checks import PredictionChecks, prediction_checks
from .friction import FrictionFractionCheck, FrictionFractionProblem, friction_fraction_check
from ._measure import TIME_CONSTANTS
from .viscosity import CheckStatus, ViscosityCheck, ViscosityFit, ViscosityProblem, viscosity_check

__all__ = ["Apparatus", "CarryThen", "MODES", "CheckStatus", "ViscosityProblem", "ViscosityCheck",
           "ViscosityFit", "TIME_CONSTANTS", "viscosity_check", "FrictionFractionProblem", "FrictionFractionCheck",
           "friction_fraction_check", "PredictionChecks", "prediction_checks"]
