"""Virtual viscosity: a staircase of contact speeds centred on a reference speed.

The contacts are placed at the quantiles of the linear law ``F = -k (V - reference)`` by the
allocator (:func:`~toolkit.allocation.allocate` with a :class:`~toolkit.allocation.Viscosity`
target; for equal magnitudes the spacing is ``s = 2 f / k``): the friction itself then acts
as a damper of slope ``k`` around the reference, with no computation in the loop. The
allocation is solved once, when the controller is bound to a plant.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import as_float
from ..allocation import Viscosity, allocate
from ..model import Plant
from ..simulation import SampledLaw
from .base import Action, StatelessLaw, speed_limits

__all__ = ["VirtualViscosity"]


@dataclass(frozen=True)
class VirtualViscosity:
    """Realize the viscosity ``slope`` (N s/m) around ``reference`` (m/s).

    Parameters
    ----------
    slope : float, N s/m
        Commanded ``dF/dV``, ``> 0``.
    reference : float, m/s
        Speed of zero force.
    band : float, m/s, optional
        Half-width over which the law should hold; default: the whole spread the contacts
        allow, ``F_tot / slope`` (where the linear law reaches ``+-F_tot``).
    """

    slope: float
    reference: float = 0.0
    band: float | None = None

    def __post_init__(self) -> None:
        owner = "VirtualViscosity"
        object.__setattr__(self, "slope", as_float(self.slope, "slope", owner, low=0.0, low_open=True))
        object.__setattr__(self, "reference", as_float(self.reference, "reference", owner))
        if self.band is not None:
            object.__setattr__(self, "band", as_float(self.band, "band", owner, low=0.0, low_open=True))

    def speeds(self, plant: Plant) -> np.ndarray:
        """The contact speeds (m/s, shape (n,)) the law commands on ``plant``."""
        band = self.band if self.band is not None else plant.contacts.total_force / self.slope
        target = Viscosity(self.slope, self.reference, band)
        return allocate(target, plant.contacts, speed_limits=speed_limits(plant)).speeds

    def bind(self, plant: Plant, period: float) -> _ConstantLaw:
        return _ConstantLaw(self.speeds(plant))


class _ConstantLaw(StatelessLaw):
    def __init__(self, speeds: np.ndarray) -> None:
        self.speeds = speeds

    def output(self, t: float, z: np.ndarray, estimate: float) -> Action:
        return Action(self.speeds)

    def sampled(self) -> SampledLaw:
        """One constant row: the staircase."""
        return SampledLaw(self.speeds[None, :])
