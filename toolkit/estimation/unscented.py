"""Unscented Kalman filter whose process model is the exact simulator over one sample.

Same state ``(X, V)``, measurement, noise and known inputs as
:class:`~toolkit.estimation.nominal.NominalKalman` (whose per-sample loop it reuses), but
each sigma point is propagated through the plant's exact flow over the period
(:meth:`~toolkit.estimation.EstimatorModel.flow`), so the sign nonlinearity near sticking is
sampled, not linearized; sigma points that end stuck add the contact estimate's variance to
``Q_VV``. filterpy is imported where the filter is built. Derivations: docs/estimation.md.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..laws import quantization_variance
from .nominal import NominalKalman

__all__ = ["UnscentedEstimator"]


class UnscentedEstimator(NominalKalman):
    """UKF on ``filterpy.kalman.UnscentedKalmanFilter`` with Julier sigma points (kappa = 1).

    Parameters
    ----------
    model : EstimatorModel
    initial_covariance : array_like of shape (2, 2), optional
    """

    name = "unscented"
    KERNELS = ("core",)

    def __init__(self, model: Any, *, initial_covariance: Any = None) -> None:
        # The sigma points are the UKF's way with the sign nonlinearity: no exact holds.
        super().__init__(model, initial_covariance=initial_covariance, exact_holds=False)

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
                 else np.diag([quantization_variance(self._q), self._std0**2]))

    def _advance(self, z: float, R: float, track: np.ndarray | None, var_v: float, steady: bool,
                 bounds: Any = None, force: float = 0.0, count: int = 0, t: float = 0.0,
                 wheels: Any = None) -> None:
        if track is None:
            self._start(z)
            self.last_nis = np.nan
            return
        ukf = self.kf.ukf
        model = self.model
        V = float(ukf.x[1])
        # The process noise of what the filter does not know of the input (contact speeds,
        # friction spread), from the flow linearized at the mean; the spread of V itself is
        # carried by the sigma points through the exact flow.
        dx, dV, Q, _, arrival, _ = model.increment(V, track, math.sqrt(var_v), math.sqrt(ukf.P[1, 1]), steady,
                                                   bounds, force)
        sigmas = ukf.points_fn.sigma_points(ukf.x, ukf.P)
        moved = np.empty_like(sigmas)
        stuck = False
        for row, (X0, V0) in enumerate(sigmas):
            step = model.flow(float(V0), track, force)
            moved[row] = (X0 + step.body_displacement, step.state.V)
            stuck |= step.state.stuck is not None
        rows = iter(moved)
        if stuck and arrival is None:
            # Sigma points that end stuck end on the contact's estimated speed, which errs
            # by the contact estimate (var_v): the spread the collapse hides (the linear
            # filter fuses that estimate as a measurement instead). Unless the mean's own
            # flow stuck, whose noise holds it already.
            Q = Q + np.array([[0.0, 0.0], [0.0, var_v]])
        # The floor (1 um, 1 um/s) keeps the covariance positive definite for the Cholesky
        # factor when every sigma point ends on one contact speed.
        ukf.Q = Q + np.diag([1e-12, 1e-12])
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
