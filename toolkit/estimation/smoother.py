"""The Rauch-Tung-Striebel smoother over the default estimator's pass (offline only).

:class:`RTSSmoother` runs the default ``kalman`` forward and, while its monitor passes (the
forward pass is the nominal filter's), filterpy's ``KalmanFilter.rts_smoother`` backwards on
the augmented state ``(X, V, 1)``; where the monitor tripped it is refused and returns the
filter's own result. Derivations: docs/estimation.md.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .._compiled import budget_clock
from ..model.sensors import EncoderRecord, EncoderSample
from ._base import EstimationResult, Estimator, score
from ._input import EstimatorModel
from .kalman import KalmanEstimator


class RTSSmoother(Estimator):
    """Rauch-Tung-Striebel smoother over the default filter's pass (offline only).

    The forward pass is the default ``kalman``'s
    (:class:`~toolkit.estimation.KalmanEstimator`). While its monitor passes, the
    forward pass is the nominal filter's, and the backward pass is filterpy's
    ``KalmanFilter.rts_smoother`` on the augmented state ``(X, V, 1)`` whose transitions carry
    the known input (exact for the affine model; docs/estimation.md). Where the monitor tripped, the model the smoother would run
    backwards is the one the data refuted: the smoother is refused and the result is the
    filter's own (``refused`` says when and why), so it is never worse than the filter.

    Parameters
    ----------
    model : EstimatorModel
    prior : ModelPrior, optional
        The default filter's prior (default ``ModelPrior()``).
    initial_covariance : array_like of shape (2, 2), optional
        As :class:`~toolkit.estimation.NominalKalman`'s.

    Attributes
    ----------
    refused : tuple of (float, str) or None
        After :meth:`run`: when (s) and why the forward filter's monitor tripped, so that
        the result is the filter's; ``None`` when the result is smoothed.
    """

    name = "rts"
    KERNELS = ("core", "lines", "window", "imm")

    def __init__(self, model: EstimatorModel, *, prior: Any = None, initial_covariance: Any = None) -> None:
        self.forward = KalmanEstimator(model, prior, initial_covariance=initial_covariance)
        self.model = model
        self.refused: tuple[float, str] | None = None

    @property
    def tripped(self) -> tuple[float, str] | None:
        """As ``refused`` (the forward filter's monitor verdict, as the default reports it)."""
        return self.refused

    def reset(self, *, speed: float = 0.0, speed_std: float | None = None,
              contact_speeds: Any = None) -> None:
        self.forward.reset(speed=speed, speed_std=speed_std, contact_speeds=contact_speeds)

    def observe(self, sample: EncoderSample) -> tuple[float, float]:
        """A smoother needs the future: it cannot be stepped. Use :meth:`run`."""
        raise NotImplementedError("The RTS smoother is offline: call run(record); step the KalmanEstimator.")

    def commanded(self, command: Any, force: float = 0.0) -> None:
        """A smoother needs the future: it cannot be stepped. Use :meth:`run`."""
        raise NotImplementedError("The RTS smoother is offline: call run(record); step the KalmanEstimator.")

    def run(self, record: EncoderRecord, *, speed: float = 0.0,
            speed_std: float | None = None) -> EstimationResult:
        # filterpy is imported here, not at module level: toolkit imports must not load it.
        from dataclasses import replace

        from filterpy.kalman import KalmanFilter

        filtered = self.forward.run(record, speed=speed, speed_std=speed_std)
        self.refused = self.forward.tripped
        if self.refused is not None:
            return replace(filtered, method=self.name)
        forward = self.forward.nominal_pass
        X, P = forward.states, forward.covariances
        started = budget_clock()
        K = X.shape[0]
        Xa = np.concatenate((X, np.ones((K, 1))), axis=1)
        Pa = np.zeros((K, 3, 3))
        Pa[:, :2, :2] = P
        Fa = np.broadcast_to(np.eye(3), (K, 3, 3)).copy()
        Fa[:, :2, :2] = forward.transitions
        Fa[:, :2, 2] = forward.inputs
        Qa = np.zeros((K, 3, 3))
        Qa[:, :2, :2] = forward.process_noises
        xs, ps, _, _ = KalmanFilter(dim_x=3, dim_z=1).rts_smoother(Xa, Pa, Fa, Qa, inv=np.linalg.pinv)
        wall = filtered.wall_time + budget_clock() - started
        return score(record, self.name, xs[:, 1], ps[:, 1, 1], wall, position=xs[:, 0],
                     covariance=ps[:, :2, :2])
