"""Braking to a friction fraction, then holding the final speed once the estimate arrives.

The paper's friction-fraction experiment: ``5 - j`` of ten contacts at ``+v_max`` and
``5 + j`` at ``-v_max`` give ``mu / mu0 = j / 5`` for every speed between (the allocator
finds that split from :class:`~toolkit.allocation.FrictionFraction`). From time ``start``
the law commands that split; with ``hold`` set, once the estimate is within ``hold`` of the
lower limit it commands every contact there, so the body stays put (a closed-loop release).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import as_float
from ..allocation import FrictionFraction, allocate
from ..model import Plant
from .base import Action, finite_limits

__all__ = ["FrictionBrake"]


@dataclass(frozen=True)
class FrictionBrake:
    """Brake with friction fraction ``fraction`` from time ``start``.

    Parameters
    ----------
    fraction : float
        ``mu / mu0`` in ``[0, 1]`` (realized exactly when it is a subset-sum fraction of the
        magnitudes, e.g. ``j / 5`` for ten equal contacts; otherwise the allocator's best).
    start : float, s
        Before it every contact is commanded at the upper speed limit (the body is carried
        at ``+v_max``).
    hold : float or None, m/s
        With a value, once the estimate is within ``hold`` of the lower limit every contact
        is commanded to it; ``None``: keep braking.
    """

    fraction: float
    start: float = 0.0
    hold: float | None = None

    def __post_init__(self) -> None:
        owner = "FrictionBrake"
        object.__setattr__(self, "fraction", as_float(self.fraction, "fraction", owner, low=0.0, high=1.0))
        object.__setattr__(self, "start", as_float(self.start, "start", owner, low=0.0))
        if self.hold is not None:
            object.__setattr__(self, "hold", as_float(self.hold, "hold", owner, low=0.0, low_open=True))

    def bind(self, plant: Plant, period: float) -> _BrakeLaw:
        lo, hi = finite_limits(plant, "FrictionBrake")
        split = allocate(FrictionFraction(self.fraction, (lo, hi)), plant.contacts,
                         speed_limits=(lo, hi)).speeds
        return _BrakeLaw(self, np.full(plant.n, hi), split, np.full(plant.n, lo))


class _BrakeLaw:
    n_states = 1          # 1 once the hold has engaged (it latches)

    def __init__(self, settings: FrictionBrake, carry: np.ndarray, split: np.ndarray,
                 rest: np.ndarray) -> None:
        self.settings, self.carry, self.split, self.rest = settings, carry, split, rest

    def initial_state(self) -> np.ndarray:
        return np.zeros(1)

    def output(self, t: float, z: np.ndarray, estimate: float) -> Action:
        if t < self.settings.start:
            return Action(self.carry)
        return Action(self.rest if z[0] > 0 else self.split)

    def update(self, t: float, z: np.ndarray, estimate: float) -> np.ndarray:
        hold = self.settings.hold
        if z[0] > 0 or hold is None or t < self.settings.start:
            return z
        return np.ones(1) if estimate <= self.rest[0] + hold else z
