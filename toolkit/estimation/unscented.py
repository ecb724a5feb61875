"""Unscented Kalman filter whose process model is the exact simulator over one sample.

Same state ``(X, V)``, measurement, noise and known inputs (contact speeds and the outside
force, the latter as a contact out of reach) as
:class:`~toolkit.estimation.kalman.KalmanEstimator` (whose per-sample loop it reuses), but
the prediction propagates each sigma point through the exact model: all sigma points at
once by :func:`toolkit.simulation.simulate_batch` (one scene per sigma point, the contacts
held at the wheel-measured speeds averaged over the period, the body starting at the sigma
point's speed). The sign nonlinearity near sticking is then sampled, not linearized: sigma
points on both sides of a contact speed end where the exact model takes them (stuck on it,
or past it). The position advances by the trapezoid ``h (V0 + V1) / 2`` (exact for the
constant acceleration of a period without a crossing).

Limits: ``simulate_batch`` holds the contact speeds constant over the period, so during the
few samples of a motor transient the period's mean speeds stand in for the moving ones;
drag is not passed through (the carousel has none). filterpy is imported where the filter
is built.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from .kalman import KalmanEstimator

__all__ = ["UnscentedEstimator"]


class UnscentedEstimator(KalmanEstimator):
    """UKF on ``filterpy.kalman.UnscentedKalmanFilter`` with Julier sigma points (kappa = 1).

    Parameters
    ----------
    model : EstimatorModel
    initial_covariance : array_like of shape (2, 2), optional
    """

    name = "unscented"

    def _build(self) -> Any:
        # filterpy is imported here, not at module level: toolkit imports must not load it.
        from filterpy.kalman import JulierSigmaPoints, UnscentedKalmanFilter

        points = JulierSigmaPoints(2, kappa=1.0)
        ukf = UnscentedKalmanFilter(dim_x=2, dim_z=1, dt=self.model.sensors.period,
                                    hx=lambda s: s[:1], fx=lambda s, dt: s, points=points)
        return _ColumnView(ukf)

    def _start(self, z: float) -> None:
        ukf = self.kf.ukf
        ukf.x = np.array([z, self._speed0])
        ukf.P = (self.initial_covariance.copy() if self.initial_covariance is not None
                 else np.diag([self._q * self._q / 12.0, self._std0**2]))

    def _advance(self, z: float, R: float, sub: np.ndarray | None, var_v: float, steady: bool,
                 bounds: Any = None, force: float = 0.0) -> None:
        from ..simulation import simulate_batch

        if sub is None:
            self._start(z)
            self.last_nis = np.nan
            return
        ukf = self.kf.ukf
        model = self.model
        h = model.sensors.period
        V = float(ukf.x[1])
        dx, dV, force_var, _, _ = model.increment(V, sub, math.sqrt(var_v), math.sqrt(ukf.P[1, 1]), steady,
                                                  force=force)
        sigmas = ukf.points_fn.sigma_points(ukf.x, ukf.P)
        S = sigmas.shape[0]
        mean = sub.mean(axis=0)
        f = model.forces
        if force != 0.0:
            # The outside force as one more contact, of magnitude |F|, beyond every contact
            # speed and sigma point by more than the period's largest speed change (out of
            # reach: it pushes with F all period; see toolkit.estimation._input).
            far = (float(np.max(np.abs(mean))) + float(np.max(np.abs(sigmas[:, 1])))
                   + (float(f.sum()) + abs(force)) * h / model.mass + 1.0)
            mean = np.append(mean, math.copysign(far, force))
            f = np.append(f, abs(force))
        speeds = np.broadcast_to(mean, (S, mean.size))
        forces = np.broadcast_to(f, (S, f.size))
        final = simulate_batch(speeds, forces, model.mass, h, v0=sigmas[:, 1]).final_speeds
        moved = np.column_stack((sigmas[:, 0] + 0.5 * h * (sigmas[:, 1] + final), final))
        rows = iter(moved)
        # A stuck body's sigma points all end on the contact speed (zero spread); the floor
        # (1 um, 1 um/s) keeps the covariance positive definite for the Cholesky factor.
        ukf.Q = (force_var / model.mass**2) * self._gg + np.diag([1e-12, 1e-12])
        ukf.predict(fx=lambda s, dt: next(rows))
        ukf.update(np.array([z]), R=np.array([[R]]))
        self.last_input = np.array([dx, dV])
        self.last_Q = ukf.Q
        self.last_nis = float(ukf.y[0] ** 2 * ukf.SI[0, 0])


class _ColumnView:
    """The UKF's 1-d state seen as the linear filter's column (``x[i, 0]``), for the shared loop."""

    def __init__(self, ukf: Any) -> None:
        self.ukf = ukf

    @property
    def x(self) -> np.ndarray:
        return self.ukf.x[:, None]

    @property
    def P(self) -> np.ndarray:
        return self.ukf.P
