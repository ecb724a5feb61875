"""The models an adaptive filter builds at its estimated friction magnitudes, kept for reuse.

:class:`ModelCache` keeps the last few models built at estimated magnitudes, motor lags and
wanders, and returns the nearest within a relative tolerance (the filter's sensitivities
carry the rest, linearly), else one rebuilt in place of the oldest.
"""

from __future__ import annotations

import numpy as np

from ._input import EstimatorModel

__all__ = ["ModelCache"]


class ModelCache:
    """The last :attr:`MODELS` models built at estimated magnitudes (:meth:`at`).

    Parameters
    ----------
    model : EstimatorModel
        The nominal model; the magnitudes' errors are relative to its forces.

    Attributes
    ----------
    built : ndarray of shape (n,)
        The magnitudes' relative errors of the model :meth:`at` returned last.
    """

    #: Relative move of an estimated friction magnitude that rebuilds the flow's model (below
    #: it the sensitivities carry the change, linearly).
    REBUILD = 1e-2
    #: Models at estimated magnitudes kept for reuse.
    MODELS = 4

    def __init__(self, model: EstimatorModel) -> None:
        self.model = model
        # The models built at estimated magnitudes: their magnitudes' errors (inf: none yet),
        # wander, lag; the next to replace and the last built.
        self._models: list[EstimatorModel | None] = [None] * self.MODELS
        self._built_e = np.full((self.MODELS, model.n), np.inf)
        self._built_drift = [1e-12] * self.MODELS
        self._built_lag = [model.motor_lag] * self.MODELS
        self.built = self._built_e[0]
        self._oldest = self._newest = 0

    def at(self, e: np.ndarray, lag: float, drift: float) -> EstimatorModel:
        """The model at the estimated magnitudes ``f (1 + e)``, the motor ``lag`` (s) and the
        motors' wander ``drift`` (m/s per sqrt(s)): the nearest of the last :attr:`MODELS`
        built ones whose magnitudes lie within :attr:`REBUILD` relative (the rest is the
        linear correction), brought to this lag and wander where they differ (by more than a
        factor 1.5 for the wander); else one rebuilt here, in place of the oldest. Its
        magnitudes' errors are :attr:`built` (the free mode's mixed estimates may cycle among
        a few values: a quantized reading's pattern repeats)."""
        gap = np.abs(self._built_e - e).max(axis=1)
        i = int(gap.argmin())
        if not gap[i] <= self.REBUILD:                 # (NaN: built, and refused by name)
            i = self._oldest
            self._oldest = (i + 1) % self.MODELS
            m = self.model
            forces = m.forces * np.maximum(1.0 + e, 1e-3)
            last = self._models[self._newest]
            if last is None:
                hat = EstimatorModel(forces, m.mass, m.sensors, motor_lag=lag, damping=m.damping,
                                     max_window=m.max_window, speed_limits=m.speed_limits, contact_drift=drift)
            else:
                hat = last.adjusted(forces, lag, drift)
            self._built_e[i] = e
        elif lag != self._built_lag[i] or not self._built_drift[i] / 1.5 <= drift <= 1.5 * self._built_drift[i]:
            hat = self._models[i].adjusted(self._models[i].forces, lag, drift)
        else:
            self.built = self._built_e[i]
            return self._models[i]
        self._models[i] = hat
        self._newest = i
        self._built_drift[i] = max(drift, 1e-12)
        self._built_lag[i] = lag
        self.built = self._built_e[i]
        return hat
