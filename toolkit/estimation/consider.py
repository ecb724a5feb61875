"""What a filter takes as known adds to its covariance (the consider analysis).

:class:`Consider` steps the sensitivity ``S`` of a linear filter's error to parameters it
takes as known (Schmidt's consider parameters) along the filter's own steps, and gives the
covariance their second moments add. :class:`OtherContact` weighs, from the same parameters
and the counts, the chance that a body the filter has stuck on one contact rides its
neighbour. Derivation: docs/estimation.md.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.special import erfcx, expit, logit

from ..model.friction import contact_forces
from ..model.truth import DEFAULT_DRAG, ModelPrior
from ._input import EstimatorModel

__all__ = ["Consider", "OtherContact", "prior_moments"]


def prior_moments(model: EstimatorModel, prior: ModelPrior) -> tuple[np.ndarray, np.ndarray]:
    """The prior's mean and variance of the force errors ``(e_1 .. e_n, dc)`` about
    ``model``: each magnitude's relative error the spread's; the drag's error (N s/m) its
    range as a Gaussian of its midpoint and half-width (the default: the nominal drag, std
    ``DEFAULT_DRAG``)."""
    n = model.n
    mean = np.zeros(n + 1)
    var = np.full(n + 1, prior.friction_spread ** 2)
    if prior.drag_range is None:
        var[n] = DEFAULT_DRAG ** 2
    else:
        lo, hi = prior.drag_range
        mean[n] = 0.5 * (lo + hi) - model.damping
        var[n] = max(0.5 * (hi - lo), 1e-9) ** 2
    return mean, var


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
        self.m2 = m2
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


class OtherContact:
    """The chance that the body has slid on from the contact a filter has it stuck on, and
    what that adds to the filter's covariance.

    The friction law holds the body on contact ``k`` while the others' net force ``G`` (with
    the outside force and the drag) lies within ``f_k``: the margin ``M = f_k - |G|``. Under
    force errors of second moments ``m2`` (the magnitudes' relative errors, then the drag's)
    the excess force ``Y = |G| - f_k`` is ``N(-M, sigma^2)``, ``sigma^2 = sum_i f_i^2 m2_i +
    v_k^2 m2_drag``: the body slides on with the prior probability ``Phi(-M / sigma)``,
    pushed by ``Y`` given ``Y > 0`` (a truncated normal: mean ``-M + sigma lambda``, variance
    ``sigma^2 (1 + alpha lambda - lambda^2)``, ``alpha = M / sigma``, ``lambda = phi(alpha) /
    Phi(-alpha)``) towards the next contact speed in the direction of ``G`` (``d`` away),
    where it sticks. That alternative's ``(X, V)`` from where the filter had the body stick
    is Gaussian (the acceleration's uncertainty through the motion's slopes), and each count
    weighs it against the filter's prediction by their likelihoods. With posterior
    probability ``p`` the body is ``u = (X_alt, V_alt) - (X, V)`` away from the estimate,
    within the alternative's covariance ``C``: ``p (u u^T + C)`` is added.

    Parameters
    ----------
    forces : ndarray of shape (n,), N
    mass : float, kg
    damping : float, N s/m
    m2 : ndarray of shape (n + 1,)
        Second moments of ``(e_1 .. e_n, dc)``.
    """

    def __init__(self, forces: np.ndarray, mass: float, damping: float, m2: np.ndarray) -> None:
        self.forces, self.mass, self.damping, self.m2 = forces, mass, damping, m2
        self._force_var = float(np.sum(forces ** 2 * m2[:-1]))
        self.reset()

    def reset(self) -> None:
        """No contact held: no alternative (its log-odds and motion are set when one is)."""
        self.k: int | None = None
        self.covariance = np.zeros((2, 2))
        #: Whether an alternative is weighed (:attr:`covariance` then holds what it adds).
        self.weighed = False

    def start(self, t: float, X: float, speeds: np.ndarray, k: int, force: float) -> float:
        """A body stuck at ``t`` (s, at position ``X``, m) on contact ``k`` of ``speeds``
        (m/s) under the outside force ``force`` (N): the alternative's motion, and its prior
        probability (returned; 0 where nothing is uncertain). With no contact speed beyond, the
        alternative slides on without end (``d`` infinite)."""
        v = float(speeds[k])
        G = float(contact_forces(speeds - v, self.forces).sum()) + force - self.damping * v
        sign = 1.0 if G >= 0.0 else -1.0
        ahead = (speeds - v) * sign
        beyond = ahead[ahead > 0.0]
        sigma = math.sqrt(self._force_var + v * v * float(self.m2[-1]))
        self._motion: tuple[float, ...] | None = None      # (t0, X0, v_k, sign, d, a, var_a)
        if sigma <= 0.0:
            return 0.0
        alpha = (float(self.forces[k]) - abs(G)) / sigma
        # lambda = phi(alpha) / Phi(-alpha), without cancellation: Phi(-alpha) = erfc(alpha /
        # sqrt(2)) / 2 = exp(-alpha^2 / 2) erfcx(alpha / sqrt(2)) / 2.
        lam = math.sqrt(2.0 / math.pi) / float(erfcx(alpha / math.sqrt(2.0)))
        a = sigma * (lam - alpha) / self.mass
        var_a = max(sigma * sigma * (1.0 + alpha * lam - lam * lam), 0.0) / self.mass ** 2
        self._motion = (t, X, v, sign, float(beyond.min()) if beyond.size else math.inf, a, var_a)
        return 0.5 * math.erfc(alpha / math.sqrt(2.0))

    def _motion_at(self, t: float) -> tuple[float, float, float, float]:
        """The alternative's mean ``(X, V)`` at ``t`` and their slopes in the acceleration."""
        t0, X0, v, sign, d, a, var_a = self._motion
        tau = t - t0
        if a * tau < d:                       # still accelerating towards the next contact
            dv, dx, gv, gx = a * tau, 0.5 * a * tau * tau, tau, 0.5 * tau * tau
        else:                                 # stuck on it since d / a
            dv, dx, gv, gx = d, d * tau - d * d / (2.0 * a), 0.0, d * d / (2.0 * a * a)
        return X0 + v * tau + sign * dx, v + sign * dv, gx, gv

    def _alternative(self, t: float) -> tuple[float, float, np.ndarray]:
        """The alternative's mean ``(X, V)`` at ``t`` and its covariance ``var_a g g^T``."""
        X, V, gx, gv = self._motion_at(t)
        g = np.array([gx, gv])
        return X, V, self._motion[6] * np.outer(g, g)

    def step(self, t: float, h: float, k: int | None, speeds: np.ndarray, force: float, X: float, V: float,
             z: float, x_pred: float, S: float) -> None:
        """One sample at ``t`` (s), ``h`` (s) after the last: the filter has the body on contact
        ``k`` of the settled ``speeds`` (None: not on one) at posterior ``(X, V)``; the reading
        ``z`` (m) against the filter's prediction ``x_pred`` (m) of innovation variance ``S``
        (m^2). A body first found on a contact may have stuck on it, or slid on, from the
        last sample on."""
        if k is None:
            if self.k is not None:
                self.reset()
            return
        if k != self.k:
            self.k = k
            self._logit = float(logit(self.start(t - h, X - float(speeds[k]) * h, speeds, k, force)))
            if self._logit == -math.inf:
                self.covariance = np.zeros((2, 2))
                self.weighed = False
                return
            X_alt, V_alt, gx, gv = self._motion_at(t)
        elif self._logit == -math.inf:
            return
        else:
            X_alt, V_alt, gx, gv = self._motion_at(t)
            S_alt = S + self._motion[6] * gx * gx
            self._logit += 0.5 * ((z - x_pred) ** 2 / S - (z - X_alt) ** 2 / S_alt + math.log(S / S_alt))
        # p (u u^T + var_a g g^T), written out (per sample, while the body is held). An
        # alternative the counts have rejected beyond floating point (p = 0) is dropped while
        # the body stays on this contact.
        p = float(expit(self._logit))
        if p == 0.0:
            self._logit = -math.inf
            self.covariance = np.zeros((2, 2))
            self.weighed = False
            return
        self.weighed = True
        u0, u1, var_a = X_alt - X, V_alt - V, self._motion[6]
        cross = p * (u0 * u1 + var_a * gx * gv)
        self.covariance = np.array([[p * (u0 * u0 + var_a * gx * gx), cross], [cross, p * (u1 * u1 + var_a * gv * gv)]])
