"""The consider analysis: what parameters a filter does not estimate add to its covariance.

:class:`Consider` steps the sensitivity ``S`` of a linear filter's error to parameters it
takes as known (Schmidt's consider parameters) along the filter's own steps, and gives the
covariance their second moments add. Derivation: docs/estimation.md.
"""

from __future__ import annotations

import numpy as np

__all__ = ["Consider"]


class Consider:
    """Sensitivity of a filter's ``(X, V)`` error to parameters of second moments ``m2``.

    Parameters
    ----------
    m2 : ndarray of shape (p,)
        Second moments of the parameters about the values the filter uses.

    Attributes
    ----------
    covariance : ndarray of shape (2, 2)
        What the parameters add to the filter's covariance at its last step: ``S diag(m2)
        S^T``.
    """

    def __init__(self, m2: np.ndarray) -> None:
        self.m2 = np.asarray(m2, dtype=float)
        self.reset()

    def reset(self) -> None:
        """The state owes nothing to the parameters (``S = 0``): a start, or a posterior of
        the data alone."""
        self.S = np.zeros((2, self.m2.size))
        self.covariance = np.zeros((2, 2))

    def step(self, F: np.ndarray, G: np.ndarray | None, gain: tuple[float, float]) -> None:
        """One predict and position update: ``S+ = (I - K [1, 0]) (F S + G)``, with the step's
        transition ``F``, the response ``G`` (2, p) of the predicted state to the parameters
        (None: none) and the update's gain ``K``."""
        S = F @ self.S
        if G is not None:
            S += G
        S -= np.outer(gain, S[0])
        self.S = S
        self.covariance = (S * self.m2) @ S.T

    def measured_speed(self, gain: np.ndarray) -> None:
        """An update with a measurement of the speed and gain ``K``: ``S+ = (I - K [0, 1]) S``."""
        self.S = self.S - np.outer(gain, self.S[1])
        self.covariance = (self.S * self.m2) @ self.S.T
