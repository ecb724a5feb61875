"""What an estimator believes beyond the nominal scene: the prior of what it identifies.

The nominal scene gives the friction magnitudes, mass, motor lag, drag and encoders. A real
plant departs from them (unequal wheels, bearing drag, a slower motor, motors that wander);
:class:`ModelPrior` says how far the estimator believes it may depart, which is the prior of
what the adaptive filter identifies online (:mod:`toolkit.estimation.adaptive`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from ..errors import as_float
from ..errors import ParameterError, ParameterTypeError, parameter_message

__all__ = ["ModelPrior"]


def _range(value: Any, name: str, owner: str, high: float = math.inf) -> tuple[float, float] | None:
    if value is None:
        return None
    if isinstance(value, (str, bytes)) or not hasattr(value, "__len__") or len(value) != 2:
        raise ParameterTypeError(parameter_message(name, owner, "be a pair (low, high) or None", value))
    lo = as_float(value[0], name, owner, low=0.0, high=high)
    hi = as_float(value[1], name, owner, low=0.0, high=high)
    if not lo <= hi:
        raise ParameterError(parameter_message(name, owner, "satisfy low <= high", value))
    return lo, hi


@dataclass(frozen=True)
class ModelPrior:
    """The estimator's prior knowledge of how the plant departs from the nominal scene.

    Parameters
    ----------
    friction_spread : float
        Prior relative standard deviation of each wheel's friction magnitude about the
        nominal one, ``>= 0`` (the wheels of a real carousel differ: the default 0.3 covers
        the paper's residual friction). 0 trusts the nominal magnitudes.
    drag_range : tuple of 2 floats or None, N s/m
        The bearing drag lies in ``[low, high]`` (uniform prior); ``None``: the nominal
        scene's drag up to that plus :data:`DEFAULT_DRAG`.
    lag_range : tuple of 2 floats or None, s
        The motor lag lies in ``[low, high]``; the estimator identifies it from the wheel
        counts after each command change. ``None``: 0 to :data:`DEFAULT_LAG` (or the nominal
        lag, if larger).
    contact_drift : float or None, m/s per sqrt(s)
        Prior intensity of the motors' speed wander (a random walk about the command);
        ``None``: :data:`DEFAULT_DRIFT`; the filter adapts it from the wheel counts.
    """

    friction_spread: float = 0.3
    drag_range: tuple[float, float] | None = None
    lag_range: tuple[float, float] | None = None
    contact_drift: float | None = None

    def __post_init__(self) -> None:
        owner = "ModelPrior"
        object.__setattr__(self, "friction_spread", as_float(self.friction_spread, "friction_spread", owner,
                                                             low=0.0, high=10.0))
        object.__setattr__(self, "drag_range", _range(self.drag_range, "drag_range", owner))
        object.__setattr__(self, "lag_range", _range(self.lag_range, "lag_range", owner, high=10.0))
        if self.contact_drift is not None:
            object.__setattr__(self, "contact_drift", as_float(self.contact_drift, "contact_drift", owner,
                                                               low=0.0))


#: Default width of the drag prior above the nominal drag, N s/m.
DEFAULT_DRAG = 2.0
#: Default upper end of the motor-lag prior, s.
DEFAULT_LAG = 0.05
#: Default prior intensity of the motors' wander, m/s per sqrt(s).
DEFAULT_DRIFT = 1e-4
