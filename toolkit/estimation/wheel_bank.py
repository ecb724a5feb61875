"""Each contact's speed from its wheel's counts, through command changes and reversals.

:class:`WheelSpeedBank` is a bank of Kalman filters per wheel, one per hypothesis of the
motors' wander, carried by the motor law and read through the gearbox play. Derivations:
docs/estimation.md.
"""

from __future__ import annotations

import math

import numpy as np

from .._compiled import kernels
from ..laws import cell_centre, quantization_variance
from ..model.motors import MotorPiece, unsaturated_response
from ..model.sensors import play
from ._input import EstimatorModel

__all__ = ["WheelSpeedBank"]


class WheelSpeedBank:
    """Each contact's speed from its wheel's counts, through command changes and reversals.

    The motor law (:class:`~toolkit.model.motors.MotorPiece` at the identified lag) carries
    each contact's *nominal* speed ``n_i`` under the commands sent; the contact runs at ``n_i +
    o_i``, its offset ``o_i`` the motor's wander about its command (a random walk) and the
    error of the start. Per wheel and per hypothesis of the wander's intensity
    (:data:`DRIFTS`) a Kalman filter of ``(x_i, o_i)`` (the encoder's position and the
    offset): over a period the encoder moves by the law's displacement plus ``h o_i``, except
    while the gearbox play is being taken up (after a reversal, or a start from rest: the
    encoder stands still until the contact has travelled the play, the sensor law's play
    operator). The hypotheses are weighted by the likelihood of all wheels' readings (the
    wander is the motors', shared), with a fading memory :data:`FORGET`; each reading's noise
    is what its wheel's window residuals show (``ContactSpeedTracker.reading_variance``);
    the law's own error adds :data:`LAW_ERROR` of each speed change it predicts. The
    arithmetic is compiled: :func:`toolkit._compiled.imm.bank_push` (one call per sample
    while every play stays loaded), else :func:`~toolkit._compiled.imm.bank_step` after the
    play operator.
    """

    #: Hypotheses of the wander's intensity, m/s per sqrt(s).
    DRIFTS = (0.0, 3e-5, 1e-4, 3e-4, 1e-3, 3e-3)
    #: Fading memory of the hypotheses' log-likelihoods per sample (about 100 samples).
    FORGET = 0.99
    #: Relative error of the speed change the motor law predicts over a period (its std).
    LAW_ERROR = 0.3

    def __init__(self, model: EstimatorModel) -> None:
        self.n = model.n
        self.h = model.sensors.period
        self.q = model.sensors.wheel.distance_per_count
        self.play = model.sensors.backlash
        self._substeps, self._h_all, self._Q = self._over(self.h)
        self._drifts = np.array(self.DRIFTS)
        self._log_weights = np.zeros(len(self.DRIFTS))
        self._drift = float(np.mean(self._drifts))
        self._x: np.ndarray | None = None
        self._P = np.zeros((len(self.DRIFTS), self.n, 3))
        self._nominal = np.zeros(self.n)          # the law's speeds, m/s
        self._y = np.zeros(self.n)                # the encoders' side of the play, m
        self._loaded = np.zeros(self.n)

    def _over(self, h: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Over a time ``h`` (s): the sub-steps at which the contact's path meets the play
        operator, ``h`` per wheel, and each hypothesis's process noise of ``(x, o)``."""
        Q = np.array([[d * d * h ** 3 / 3.0, d * d * h * h / 2.0, d * d * h] for d in self.DRIFTS])
        return h * np.arange(1, 9) / 8.0, np.full(self.n, h), Q

    @property
    def weights(self) -> np.ndarray:
        """The hypotheses' posterior weights."""
        w = np.exp(self._log_weights - self._log_weights.max())
        return w / w.sum()

    @property
    def drift(self) -> float:
        """The weighted mean of the wander's intensity, m/s per sqrt(s)."""
        return self._drift

    def start(self, wheels: np.ndarray, speeds: np.ndarray, variance: np.ndarray) -> None:
        """The first readings and the contacts' speeds then (m/s) with their variances; the
        play as the sensor law starts it (loaded behind a moving contact, centred at rest)."""
        q, H = self.q, len(self.DRIFTS)
        self._nominal = np.array(speeds, dtype=float)
        self._y = cell_centre(np.asarray(wheels, dtype=float), q)          # the encoder side, m
        self._x = np.zeros((H, self.n, 2))
        self._x[:, :, 0] = self._y + np.sign(self._nominal) * 0.5 * self.play
        self._P[:] = 0.0
        self._P[:, :, 0] = quantization_variance(q)
        self._P[:, :, 2] = variance

    def restart(self, which: np.ndarray, wheels: np.ndarray, speeds: np.ndarray, variance: np.ndarray) -> None:
        """Restart the filters of the wheels ``which`` (bool, (n,)) from their readings and
        window estimates (a large transient has ended: see :class:`AdaptiveKalman`)."""
        if not which.any():
            return
        q = self.q
        y = cell_centre(np.asarray(wheels, dtype=float), q)
        self._nominal = np.where(which, speeds, self._nominal)
        self._y = np.where(which, y, self._y)
        self._x[:, which, 0] = (y + np.sign(speeds) * 0.5 * self.play)[which]
        self._x[:, which, 1] = 0.0
        self._P[:, which, 0] = quantization_variance(q)
        self._P[:, which, 1] = 0.0
        self._P[:, which, 2] = np.broadcast_to(variance, (self.n,))[which]

    def push(self, wheels: np.ndarray, command: np.ndarray, lag: float, noise: np.ndarray, periods: int = 1
             ) -> tuple[np.ndarray, np.ndarray]:
        """The readings at the end of ``periods`` periods (the samples between were lost)
        over which ``command`` (m/s, clipped) was held, with the motors' ``lag`` (s) and each
        reading's noise variance (m^2); the contacts' speeds (m/s) and their variances
        ((m/s)^2) at the readings."""
        h = periods * self.h
        s, h_all, Q = (self._substeps, self._h_all, self._Q) if periods == 1 else self._over(h)
        u = np.asarray(command, dtype=float)
        start = self._nominal
        if lag > 0.0 and start.tolist() != u.tolist():            # (lists: cheaper on a few contacts)
            piece = MotorPiece.build(0.0, start, u, lag, math.inf)
            moved = piece.displacement(s[:, None])                     # (substeps, n)
            end = piece.speeds_at(h)
            cx = moved[-1]
        else:
            # Settled motors hold the command; ideal ones take it at once (the motor law
            # without a lag).
            end = unsaturated_response(start, u, h, 0.0, math.inf)
            moved = None                                               # (s[:, None] * end)
            cx = h * end                                               # (s[-1] = h exactly)
        self._nominal = end
        # The encoder sees the contact through the play (the sensor law's play operator) along
        # the most likely path over the period: where it ends engaged it reads the contact
        # shifted by the play's half width; where it stands in the play it reads nothing new.
        # Engaged behind a contact that keeps moving the same way over the whole period: the
        # play stays loaded (the operator's fixed point); where every wheel's does, one kernel
        # call; else only the others walk its path.
        K = kernels("imm", 20 * Q.shape[0] * self.n)
        noise = np.asarray(noise, dtype=float)
        wheels = np.asarray(wheels)
        shift, loaded, speeds, var = np.empty(self.n), self._loaded, np.empty(self.n), np.empty(self.n)
        drift = K.bank_push(self._x, self._P, Q, start, end, cx, h_all, self.LAW_ERROR, self._y,
                            wheels, self.q, noise, self._log_weights, self.FORGET, 0.5 * self.play, self._drifts,
                            shift, loaded, speeds, var)
        if drift >= 0.0:
            self._drift = drift
            return speeds, var
        z = cell_centre(np.asarray(wheels, dtype=float), self.q)
        if moved is None:
            moved = s[:, None] * end
        best = int(np.argmax(self._log_weights))
        x, ob = self._x[best, :, 0], self._x[best, :, 1]          # (views: read before the step)
        half = 0.5 * self.play
        seen = loaded.copy()
        walk = loaded == 0.0
        path = x[walk] + moved[:, walk] + s[:, None] * ob[walk]
        y = play(path, self.play, self._y[walk])[-1]
        shift[walk] = y - path[-1]
        seen[walk] = np.abs(np.abs(shift[walk]) - half) <= 1e-9 * max(half, 1e-12)
        law_error = (self.LAW_ERROR * (end - start)) ** 2
        K.bank_step(self._x, self._P, Q, cx, h_all, law_error, shift, seen, z, noise,
                    self._log_weights, self.FORGET)
        # The encoder side: the contact after the step (updated where the play is engaged)
        # shifted by the play as the operator leaves it.
        self._y = self._x[best, :, 0] + shift
        o = np.empty(self.n)
        self._drift = K.bank_moments(self._x, self._P, self._log_weights, self._drifts, o, var)
        return end + o, var
