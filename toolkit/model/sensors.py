"""Encoders as the hardware has them: integer counts of position sampled at a fixed rate.

An encoder with ``counts_per_rev`` counts on a shaft whose contact point sits at ``radius``
resolves ``2 pi radius / counts_per_rev`` metres; differencing counts at ``rate`` Hz gives
speed in steps of that distance times the rate. At constant speed the quantization error
is a deterministic sawtooth, not white noise (PHYSICS.md section 3).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from .._validation import as_float

__all__ = ["Encoder"]


@dataclass(frozen=True)
class Encoder:
    """A position encoder read at a fixed rate.

    Parameters
    ----------
    counts_per_rev : float
        Counts per revolution of the measured shaft (gear ratio included), > 0.
    radius : float, m
        Radius at which the measured motion happens (wheel radius, or contact radius L
        for the central encoder), > 0.
    rate : float, Hz
        Sampling rate, > 0.
    backlash : float, m
        Dead band of the gearbox at the contact, >= 0 (0: none).
    """

    counts_per_rev: float
    radius: float
    rate: float = 50.0
    backlash: float = 0.0

    def __post_init__(self) -> None:
        for name in ("counts_per_rev", "radius", "rate"):
            object.__setattr__(self, name, as_float(getattr(self, name), name, "Encoder", low=0.0, low_open=True))
        object.__setattr__(self, "backlash", as_float(self.backlash, "backlash", "Encoder", low=0.0))

    @property
    def distance_per_count(self) -> float:
        """Linear distance of one count at ``radius``, m."""
        return 2.0 * math.pi * self.radius / self.counts_per_rev

    @property
    def speed_step(self) -> float:
        """Speed resolution of differencing consecutive samples, m/s."""
        return self.distance_per_count * self.rate

    @property
    def backlash_speed_step(self) -> float:
        """Speed error one backlash width causes over one sample period, m/s."""
        return self.backlash * self.rate

    def counts(self, position: Any) -> np.ndarray:
        """Integer counts for positions (m at ``radius``): ``floor(position / distance_per_count)``."""
        return np.floor(np.asarray(position, dtype=float) / self.distance_per_count).astype(np.int64)

    def summary(self) -> dict[str, float]:
        """The resolutions as a JSON-able dict (SI units)."""
        return {"distance_per_count": self.distance_per_count, "speed_step": self.speed_step,
                "backlash_speed_step": self.backlash_speed_step, "rate": self.rate}
