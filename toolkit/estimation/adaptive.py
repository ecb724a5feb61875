"""The default estimator: the nominal filter while the model holds, an adaptive one after.

(Under construction: the adapting filter alone.)
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections import deque
from typing import Any

import numpy as np

from ..model.sensors import EncoderRecord, EncoderSample
from ._base import EstimationResult, Estimator, score
from ._input import ContactSpeedTracker, EstimatorModel
from ._prior import DEFAULT_DRAG, DEFAULT_LAG, ModelPrior
from .identification import LagIdentifier
from .monitor import ConsistencyMonitor, NoiseMatcher, fit_noise
from .window import AdaptiveWindow
from ..model.motors import MotorPiece
from .._compiled import kernels
from ._hold import HoldLayer

__all__ = ["KalmanEstimator", "RobustFilter"]


class WheelSpeedBank:
    """Each settled contact's speed as a random walk observed through its wheel's counts: a
    Kalman filter of ``(x_i, v_i)`` per wheel and per hypothesis of the walk's intensity
    (:data:`DRIFTS`), the hypotheses weighted by the likelihood of all wheels' readings (a
    multiple-model estimate of the motors' wander, shared by the wheels), and the read
    noise matched from the pooled innovations (:class:`~toolkit.estimation.monitor.NoiseMatcher`).

    Between command changes only (``steady``); a change restarts the filters (the motor law
    and the gearbox play then move the contacts), keeping the hypotheses' weights.
    """

    #: Hypotheses of the wander's intensity, m/s per sqrt(s).
    DRIFTS = (0.0, 3e-5, 1e-4, 3e-4, 1e-3, 3e-3)
    #: Fading memory of the hypotheses' log-likelihoods per sample (a window of ~100 samples).
    FORGET = 0.99

    def __init__(self, model: EstimatorModel) -> None:
        self.n = model.n
        self.h = model.sensors.period
        self.q = model.sensors.wheel.distance_per_count
        h = self.h
        unit = np.array([[h ** 3 / 3.0, h * h / 2.0], [h * h / 2.0, h]])
        self._Q = np.array([d * d * unit for d in self.DRIFTS])           # (H, 2, 2)
        self._log_weights = np.zeros(len(self.DRIFTS))
        self.reset_filters()

    def reset_filters(self) -> None:
        self._x = None
        self.samples = 0

    @property
    def weights(self) -> np.ndarray:
        w = np.exp(self._log_weights - self._log_weights.max())
        return w / w.sum()

    @property
    def drift(self) -> float:
        """The weighted mean of the wander's intensity, m/s per sqrt(s)."""
        return float(self.weights @ np.array(self.DRIFTS))

    def predicted(self) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """The next readings' predicted positions (m), their stds (m) and the contacts' speeds
        (m/s) under the most likely hypothesis; None without filters."""
        if self._x is None:
            return None
        best = int(np.argmax(self._log_weights))
        x, P, h = self._x[best], self._P[best], self.h
        var = P[:, 0, 0] + 2.0 * h * P[:, 0, 1] + h * h * P[:, 1, 1] + self._Q[best, 0, 0]
        return x[:, 0] + h * x[:, 1], np.sqrt(var), x[:, 1]

    def push(self, wheels: np.ndarray, steady: bool, speeds: np.ndarray, variance: np.ndarray,
             noise: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
        """One sample's wheel counts with the window estimates (speeds, m/s, their variances
        and each wheel's per-reading noise, m^2, :class:`ContactSpeedTracker`); the contacts'
        speeds (m/s) and variances ((m/s)^2), or None while there is no filter (a transient,
        or its first reading)."""
        q, h = self.q, self.h
        z = (np.asarray(wheels, dtype=float) + 0.5) * q
        noise = np.asarray(noise, dtype=float)
        if not steady:
            self.reset_filters()
            return None
        H = len(self.DRIFTS)
        R0 = q * q / 12.0
        if self._x is None:
            self._x = np.broadcast_to(np.stack((z, speeds), axis=1), (H, self.n, 2)).copy()
            P = np.zeros((H, self.n, 2, 2))
            P[:, :, 0, 0] = R0
            P[:, :, 1, 1] = variance
            self._P = P
            self.samples = 1
            return None
        x, P = self._x, self._P
        # Predict: x += h v; P = F P F^T + Q (F = [[1, h], [0, 1]]).
        x[..., 0] += h * x[..., 1]
        p00, p01, p11 = P[..., 0, 0], P[..., 0, 1], P[..., 1, 1]
        n00 = p00 + 2.0 * h * p01 + h * h * p11
        n01 = p01 + h * p11
        P[..., 0, 0] = n00 + self._Q[:, None, 0, 0]
        P[..., 0, 1] = P[..., 1, 0] = n01 + self._Q[:, None, 0, 1]
        P[..., 1, 1] = p11 + self._Q[:, None, 1, 1]
        # Update with the readings; their noise is what the windows' residuals show (the
        # quantization, read noise, jitter: white over a window, where a wander bends lines
        # only over longer spans).
        y = z - x[..., 0]
        S = P[..., 0, 0] + noise
        K0, K1 = P[..., 0, 0] / S, P[..., 1, 0] / S
        x[..., 0] += K0 * y
        x[..., 1] += K1 * y
        p00, p01, p11 = P[..., 0, 0].copy(), P[..., 0, 1].copy(), P[..., 1, 1].copy()
        P[..., 0, 0] = p00 - K0 * p00
        P[..., 0, 1] = P[..., 1, 0] = p01 - K0 * p01
        P[..., 1, 1] = p11 - K1 * p01
        self._log_weights = self.FORGET * self._log_weights - 0.5 * np.sum(y * y / S + np.log(S), axis=1)
        self._log_weights -= self._log_weights.max()
        self.samples += 1
        w = self.weights
        v = w @ x[..., 1]
        var = w @ (P[..., 1, 1] + (x[..., 1] - v) ** 2)
        return v, var


class RobustFilter(Estimator):
    """Interacting multiple model over the body's modes, each an augmented-state EKF of ``(X,
    V, e_1 .. e_n, dc)``: the body's position and speed, each wheel's relative friction error
    and the drag's error. Mode *free*: the exact flow of the model at the current parameter
    estimates (sliding, coasting or creeping, sticking where that model sticks); mode
    *stuck*: the body rides the contact nearest its speed."""

    name = "kalman_robust"
    FREE, STUCK = 0, 1
    #: The stuck mode's probability from which a hold may start.
    HOLD_START = 0.9
    #: Samples over which the encoders must look ideal for the exact lines (:meth:`_ideal`).
    IDEAL_WINDOW = 50
    #: Largest share of wheel readings that may break their lines in that window.
    LINE_BREAKS = 0.03
    #: Largest widening of the covariances per failing sample (a factor).
    WIDEN_MAX = 10.0

    def __init__(self, model: EstimatorModel, prior: ModelPrior | None = None, *,
                 forgetting: float = 0.0, switching: float = 0.02) -> None:
        self.model = model
        self.prior = ModelPrior() if prior is None else prior
        self.n = model.n
        self.d = self.n + 3
        self.h = model.sensors.period
        self.q = model.sensors.central.distance_per_count
        self.forgetting = forgetting
        lag_range = self.prior.lag_range
        if lag_range is None:
            lag_range = (0.0, max(DEFAULT_LAG, model.motor_lag))
        self._lag_range = lag_range
        self.monitor = ConsistencyMonitor(10, 1e-3)
        q_c = model.sensors.central.distance_per_count
        self._foaw = AdaptiveWindow(model.sensors, fit="best", band=q_c)
        # The contacts' largest acceleration as the model-free mode's intensity in a
        # transient: (F_tot / m) per sqrt(h) (an acceleration that may flip every period).
        self._reach_rate = float(model.forces.sum()) / model.mass / math.sqrt(model.sensors.period)
        # Row i to column j: the physical modes (free, stuck) switch between themselves with
        # probability ``switching`` per sample and into the model-free one with ``escape``;
        # the model-free one returns to either with ``switching / 2``.
        escape = 1e-3
        self.M = np.array([[1.0 - switching - escape, switching, escape],
                           [switching, 1.0 - switching - escape, escape],
                           [0.5 * switching, 0.5 * switching, 1.0 - switching]])
        self.reset()

    # -- parameters --------------------------------------------------------------------------
    def _prior_moments(self) -> tuple[np.ndarray, np.ndarray]:
        n = self.n
        mean = np.zeros(n + 1)
        var = np.full(n + 1, self.prior.friction_spread ** 2)
        if self.prior.drag_range is None:
            var[n] = DEFAULT_DRAG ** 2
        else:
            lo, hi = self.prior.drag_range
            mean[n] = 0.5 * (lo + hi) - self.model.damping
            var[n] = (0.5 * (hi - lo)) ** 2
        return mean, var

    def _model_at(self, theta: np.ndarray) -> EstimatorModel:
        """The model with the friction magnitudes ``f (1 + e)`` (rebuilt only when they moved
        by more than 1e-4 relative since the last build)."""
        e = theta[:self.n]
        drift = max(self._bank.drift, self.model.contact_drift)
        lag = self.lag
        if (self._built is None or np.max(np.abs(e - self._built)) > 1e-4 or lag != self._built_lag
                or not self._built_drift / 1.5 <= drift <= 1.5 * self._built_drift):
            m = self.model
            forces = m.forces * np.maximum(1.0 + e, 1e-3)
            self._hat = EstimatorModel(forces, m.mass, m.sensors, motor_lag=lag, damping=m.damping,
                                       max_window=m.max_window, speed_limits=m.speed_limits,
                                       contact_drift=drift)
            self._built = e.copy()
            self._built_drift = max(drift, 1e-12)
            self._built_lag = lag
        return self._hat

    @property
    def lag(self) -> float:
        """The motor lag the flow uses, s: the identified one once a command change has been
        seen through and it lies within the prior's range, else the nominal one."""
        lag = self._lag_id.lag
        lo, hi = self._lag_range
        return self.model.motor_lag if lag is None else min(max(lag, lo), hi)

    # -- the recursion --------------------------------------------------------------------------
    def reset(self, *, speed: float = 0.0, speed_std: float | None = None,
              contact_speeds: Any = None) -> None:
        d, n = self.d, self.n
        mean, var = self._prior_moments()
        x = np.zeros(d)
        x[1] = speed
        x[2:] = mean
        P = np.zeros((d, d))
        P[1, 1] = (0.05 if speed_std is None else speed_std) ** 2
        P[2:, 2:] = np.diag(var)
        self.xs = [x.copy(), x.copy(), x.copy()]
        self.Ps = [P.copy(), P.copy(), P.copy()]
        self.mu = np.array([1.0 - 2e-3, 1e-3, 1e-3])
        self.x, self.P = x, P
        self._built = None
        self._built_drift = 1e-12
        self._built_lag = self.model.motor_lag
        self._hat = None
        sensors = self.model.sensors
        self._lag_id = LagIdentifier(sensors.wheel.distance_per_count, sensors.backlash, sensors.period,
                                     self._lag_range[1])
        self._lag_id.start(contact_speeds)
        self.monitor.reset()
        self._foaw.reset(speed=speed)
        self.fallback = False
        self.out_x, self.out_P = self.x, self.P
        self._gains = np.zeros((2, n + 1))
        self._free_stuck = False
        self._mu_prev = self.mu
        self._tracker = ContactSpeedTracker(self.model, contact_speeds, residuals=True)
        self._bank = WheelSpeedBank(self.model)
        self._noise = NoiseMatcher(100)
        self._wheel_noise = getattr(self, "_primed", None) or (0.0, 0.0)
        self._layer = HoldLayer(self.model)
        self._lines = self._layer.lines
        self._anchor = (math.nan, 0)
        self.holding = False
        self.hold_failed = False
        self._moments = np.zeros(5)
        self._empty = np.zeros((1, 2))
        self._pending = None
        self._observed = None
        self._count_prev = None
        self._repeats = 0
        self._central_offset = 0
        self._repairs = False
        self._deaths: deque[int] = deque(maxlen=self.IDEAL_WINDOW)
        self._nis_history: deque[float] = deque(maxlen=self.IDEAL_WINDOW)
        self._wheel_offset = np.zeros(n, dtype=np.int64)
        self._first = True
        self.last_nis = math.nan

    def prime(self, samples: list[EncoderSample], commands: list[Any], initial: Any = None) -> None:
        """Learn the encoders' read noise and jitter from the wheels over ``samples`` (and the
        commands sent with them) before running from the first of them: what the filter would
        know of its encoders by the last one (a replay starts from it)."""
        tracker = ContactSpeedTracker(self.model, initial, residuals=True)
        noise = None
        for sample, command in zip(samples, commands):
            speeds, _, steady, _ = tracker.push(sample.time, sample.wheel_counts, command)
            if steady and tracker.window_length >= 5:
                q_w = self.model.sensors.wheel.distance_per_count
                a, b = fit_noise(tracker.reading_variance - q_w * q_w / 12.0, speeds * speeds)
                noise = (a / (q_w * q_w), b)
        self._primed = noise

    def _predict_free(self, x: np.ndarray, P: np.ndarray, track: np.ndarray, var: np.ndarray, steady: bool,
                      force: float) -> tuple[np.ndarray, np.ndarray]:
        n = self.n
        theta = x[2:]
        hat = self._model_at(theta)
        delta = theta.copy()
        delta[:n] -= self._built              # what the built model does not hold yet
        V = float(x[1])
        gains = self._gains
        var_v = float(var[int(np.argmin(np.abs(track[0] - V)))])
        dx, dV, Q, slopes, arrival, on_set = hat.increment(
            V, track, math.sqrt(var_v), math.sqrt(max(P[1, 1], 0.0)), steady, None, force, gains)
        JX, J = slopes if slopes is not None else (self.h, 1.0)
        A = np.eye(self.d)
        A[0, 1] = JX
        A[1, 1] = J
        A[0, 2:] = gains[0]
        A[1, 2:] = gains[1]
        correction = gains @ delta
        x_new = x.copy()
        x_new[0] = x[0] + self.h * V + dx + correction[0]
        x_new[1] = V + dV + correction[1]
        # The flow ends with the body on a contact's speed: the free mode predicts it stuck,
        # which is the stuck mode's motion (with that contact).
        ends = hat.end_speeds(track)
        self._free_stuck = bool(on_set and np.min(np.abs(ends - x_new[1])) <= 1e-9)
        if self._free_stuck:
            return self._predict_stuck(x, P, track, var, int(np.argmin(np.abs(ends - x_new[1]))))
        Qfull = np.zeros((self.d, self.d))
        Qfull[:2, :2] = Q
        if self.forgetting > 0:
            Qfull[2:, 2:] += np.diag(np.full(n + 1, self.forgetting * self.h))
        return x_new, A @ P @ A.T + Qfull

    def _predict_stuck(self, x: np.ndarray, P: np.ndarray, track: np.ndarray, var: np.ndarray,
                       k: int | None = None) -> tuple[np.ndarray, np.ndarray]:
        model, h = self.model, self.h
        if k is None:
            k = int(np.argmin(np.abs(track[0] - x[1])))
        start, target = track[0, k:k + 1], track[1, k:k + 1]
        piece = MotorPiece.build(0.0, start, target, model.motor_lag, math.inf)
        x_new = x.copy()
        x_new[0] = x[0] + float(piece.displacement(h)[0])
        x_new[1] = float(piece.speeds_at(h)[0])
        A = np.eye(self.d)
        A[0, 1] = 0.0
        A[1, 1] = 0.0
        Q = np.zeros((self.d, self.d))
        Q[:2, :2] = var[k] * np.array([[h * h, h], [h, 1.0]]) + model._held_noise
        return x_new, A @ P @ A.T + Q

    def _contact_speeds(self, track: np.ndarray, var_v: np.ndarray, steady: bool
                        ) -> tuple[np.ndarray, np.ndarray]:
        """The period's track with each settled contact at its wheel's exact line when that is
        sharper than the window's least-squares line: the speed's uniform posterior over the
        polygon of lines the wheel's counts allow since its window started."""
        var = np.array(var_v, dtype=float)
        lines = self._lines
        if not (steady and lines.active):
            return track, var
        track = track.copy()
        line_moments = kernels("lines", 50 * self.n).line_moments
        for k in range(self.n):
            if lines.counts[k] >= 3 and line_moments(lines.polys[k], int(lines.counts[k]), self._empty, 0,
                                                     self._moments) > 0.0:
                v, w = float(self._moments[1]), float(self._moments[4])
                if w < var[k]:
                    track[:, k] = v
                    var[k] = w
        return track, var

    def _mix(self) -> tuple[np.ndarray, list[np.ndarray], list[np.ndarray]]:
        """IMM mixing (filterpy's IMMEstimator: ``M`` row-stochastic, from row i to column j)."""
        M, mu = self.M, self.mu
        cbar = mu @ M
        omega = M * mu[:, None] / cbar
        xs, Ps = [], []
        for j in range(len(mu)):
            x = sum(omega[i, j] * self.xs[i] for i in range(len(mu)))
            P = np.zeros((self.d, self.d))
            for i in range(len(mu)):
                y = self.xs[i] - x
                P += omega[i, j] * (np.outer(y, y) + self.Ps[i])
            xs.append(x)
            Ps.append(P)
        return cbar, xs, Ps

    def _predict_kinematic(self, x: np.ndarray, P: np.ndarray, steady: bool) -> tuple[np.ndarray, np.ndarray]:
        """The model-free mode: the speed a random walk (the motors' wander the wheels show
        when the contacts hold, the contacts' whole acceleration otherwise), no parameters."""
        h = self.h
        x_new = x.copy()
        x_new[0] = x[0] + h * x[1]
        A = np.eye(self.d)
        A[0, 1] = h
        intensity = self._bank.drift if steady else self._reach_rate
        Q = np.zeros((self.d, self.d))
        Q[:2, :2] = intensity ** 2 * np.array([[h ** 3 / 3.0, h * h / 2.0], [h * h / 2.0, h]])
        return x_new, A @ P @ A.T + Q

    def _update(self, x: np.ndarray, P: np.ndarray, z: float, R: float
                ) -> tuple[np.ndarray, np.ndarray, float, float]:
        S = P[0, 0] + R
        K = P[:, 0] / S
        y = z - x[0]
        x = x + K * y
        P = P - np.outer(K, P[0, :])
        P = 0.5 * (P + P.T)
        likelihood = math.exp(-0.5 * y * y / S) / math.sqrt(2.0 * math.pi * S)
        return x, P, likelihood, y * y / S

    def _step(self, c: int, t: float, anchor: tuple[float, int], track: np.ndarray,
              var_v: np.ndarray, steady: bool, force: float) -> None:
        q = self.q
        track, var = self._contact_speeds(track, var_v, steady)
        prior = (float(self.x[0]), float(self.x[1])), self.P[:2, :2].copy()
        # The optional layer first (it needs only the last posterior): while the modes say the
        # body rides a settled contact and the encoders look ideal, the exact hold's posterior
        # is the estimate, and a reading one count short of every line is a missed count.
        out = None
        self.hold_failed = False
        ideal = self._repairs = self._ideal(var_v, prior[0][1])
        if steady and self._layer.ready:
            k = int(np.argmin(np.abs(track[0] - prior[0][1])))
            # Among the physical modes (the model-free one says nothing of sticking).
            physical = self._mu_prev[0] + self._mu_prev[1]
            stuck = (self._mu_prev[1] + (self._mu_prev[0] if self._free_stuck else 0.0)) / max(physical, 1e-300)
            out = self._layer.step(t, c, anchor, track[0], float(var[k]), prior[0], prior[1],
                                   stuck >= self.HOLD_START and ideal, repair=ideal)
            if out is not None:
                self.hold_failed = out.failed
                if out.repaired:
                    self._central_offset += out.repaired
                    c += out.repaired
                    self._anchor = (t, c)
        else:
            self._layer.stop()
        # The modes: mixing, prediction, update (the Gaussian filters run on beneath a hold).
        cbar, xs, Ps = self._mix()
        free = self._predict_free(xs[0], Ps[0], track, var, steady, force)
        preds = [free, self._predict_stuck(xs[1], Ps[1], track, var),
                 # The model-free mode speaks only where the contacts hold their speeds; in a
                 # transient it follows the free mode (the flow knows the motor law).
                 self._predict_kinematic(xs[2], Ps[2], steady) if steady
                 else self._predict_free(xs[2], Ps[2], track, var, steady, force)]
        x_pred = sum(cbar[j] * preds[j][0][0] for j in range(3))
        predicted = sum(cbar[j] * (preds[j][1][0, 0] + (preds[j][0][0] - x_pred) ** 2) for j in range(3))
        speed = sum(cbar[j] * preds[j][0][1] for j in range(3))
        if c == self._count_prev:
            self._repeats += 1
        else:
            self._repeats = 0
        self._count_prev = c
        R0 = q * q / 12.0 * (1 + self._repeats)
        z = (c + 0.5) * q
        # The measurement noise: the quantization's, plus what covariance matching finds in
        # the innovations (read noise, jitter) against the modes' combined prediction.
        R = R0 + max(self._noise.extra(speed), q * q * self._wheel_noise[0] + self._wheel_noise[1] * speed * speed)
        self._noise.push(z - x_pred, predicted, R0, speed)
        updated = [self._update(xp, Pp, z, R) for xp, Pp in preds]
        mu = cbar * np.array([u[2] for u in updated])
        total = mu.sum()
        self.mu = mu / total if total > 0 and np.isfinite(total) else cbar
        self.xs, self.Ps = [u[0] for u in updated], [u[1] for u in updated]
        self._combine()
        self.last_nis = float(self.mu @ np.array([u[3] for u in updated]))
        # The NIS of the reading against the combined prediction with the quantization alone
        # (the test of ideal encoders, :meth:`_ideal`).
        self._nis_history.append((z - x_pred) ** 2 / (predicted + R0))
        self.holding = out is not None and not out.failed
        if self.holding:
            self.last_nis = out.nis
            self.x = self.x.copy()
            self.P = self.P.copy()
            self.x[:2] = out.state
            self.P[:2, :] = 0.0
            self.P[:, :2] = 0.0
            self.P[:2, :2] = out.covariance
        self._mu_prev = self.mu

    def _ideal(self, var_v: np.ndarray, speed: float) -> bool:
        """The encoders look ideal (they only quantize, and may miss a count): over the last
        :attr:`IDEAL_WINDOW` samples, the wheels' exact lines broke (a reading no line of the
        window allows, after repairing missed counts) on at most :attr:`LINE_BREAKS` of the
        wheel readings, and the central innovations' 90th percentile NIS is within twice
        chi-square(1)'s (2.71). Rare outliers (a missed count) pass; read noise or jitter,
        which break lines within a few readings and spread a third of the innovations, do
        not."""
        if len(self._nis_history) < self.IDEAL_WINDOW:
            return False
        if sum(self._deaths) > self.LINE_BREAKS * self.n * len(self._deaths):
            return False
        return float(np.percentile(self._nis_history, 90)) <= 2.0 * 2.706

    def _combine(self) -> None:
        mu = self.mu
        x = sum(mu[i] * self.xs[i] for i in range(len(mu)))
        P = np.zeros((self.d, self.d))
        for i in range(len(mu)):
            y = self.xs[i] - x
            P += mu[i] * (np.outer(y, y) + self.Ps[i])
        self.x, self.P = x, P

    def observe(self, sample: EncoderSample) -> tuple[float, float]:
        if self._observed is not None:
            self.commanded(self._last_command, self._last_force)
        c = sample.central_count + self._central_offset
        wheels = np.asarray(sample.wheel_counts) + self._wheel_offset
        pending = self._pending
        repaired = self._layer.wheels(sample.time, wheels, None if pending is None else pending[0],
                                      True if pending is None else pending[2], repair=self._repairs)
        if repaired is not None:
            self._wheel_offset = self._wheel_offset + repaired
            wheels = wheels + repaired
        self._deaths.append(self._lines.deaths if self._lines.active else 0)
        if self._first:
            q = self.q
            for x, P in zip(self.xs, self.Ps):
                x[0] = (c + 0.5) * q
                P[0, 0] = q * q / 12.0
            self._combine()
            self._first = False
            self._count_prev = c
            self._anchor = (sample.time, c)
        else:
            anchor, self._anchor = self._anchor, (sample.time, c)
            self._step(c, sample.time, anchor, *pending)
        self._observed = (sample.time, wheels)
        speed = self._foaw.observe(dataclasses.replace(sample, central_count=c))[0]
        self._act((speed, self._foaw.matched_variance))
        return float(self.out_x[1]), float(self.out_P[1, 1])

    def _act(self, window: tuple[float, float]) -> None:
        """The consistency monitor's verdict on this sample and what the filter does about
        it: while the windowed NIS fails, widen the modes' ``(X, V)`` covariances by the
        window's mean NIS (at most :attr:`WIDEN_MAX` per sample) and fall back towards the
        window (FOAW) estimate: the output is the covariance intersection of the filter's
        speed and the window's (consistent whatever their correlation)."""
        verdict = self.monitor.push(self.last_nis)
        self.fallback = not verdict.passes
        self.out_x, self.out_P = self.x, self.P
        if not self.fallback:
            return
        factor = min(max(self.monitor.mean, 1.0), self.WIDEN_MAX)
        for P in self.Ps:
            P[:2, :] *= math.sqrt(factor)
            P[:, :2] *= math.sqrt(factor)
        self._combine()
        v1, p1 = float(self.x[1]), float(self.P[1, 1])
        v2, p2 = window
        if not (p2 > 0.0 and math.isfinite(v2)):
            self.out_x, self.out_P = self.x, self.P
            return
        # Covariance intersection of two scalar estimates: 1 / P = w / p1 + (1 - w) / p2 with
        # w minimizing P, which for scalars puts all the weight on the smaller variance; the
        # trace-optimal w is then 0 or 1, so the fused speed is the sharper of the two.
        x, P = self.x.copy(), self.P.copy()
        if p2 < p1:
            # The window's speed replaces the filter's; the position keeps its own estimate
            # (its correlation with the speed unknown: dropped).
            x[1] = v2
            P[1, :] = 0.0
            P[:, 1] = 0.0
            P[1, 1] = p2
        self.out_x, self.out_P = x, P

    def commanded(self, command: Any, force: float = 0.0) -> None:
        t, wheels = self._observed
        self._observed = None
        self._last_command, self._last_force = command, float(force)
        speeds, var, steady, track = self._tracker.push(t, wheels, command)
        self._lag_id.push(t, wheels, command)
        if steady and self._tracker.window_length >= 15:
            # The wheels' window residuals against their speeds: read noise (counts) and
            # jitter (s), which the central encoder shares (read by the same electronics at
            # the same instants).
            q_w = self._tracker.model.sensors.wheel.distance_per_count
            a, b = fit_noise(self._tracker.reading_variance - q_w * q_w / 12.0, speeds * speeds)
            self._wheel_noise = (a / (q_w * q_w), b)
        var_c = self._tracker.contact_variance.copy()
        track = np.array(track, dtype=float)
        banked = self._bank.push(wheels, steady, speeds, var_c, self._tracker.reading_variance)
        if banked is not None and self._bank.samples >= 5:
            track[:] = banked[0]
            var_c = banked[1]
        self._pending = (track, var_c, steady, float(force))

    def run(self, record: EncoderRecord, *, speed: float = 0.0,
            speed_std: float | None = None) -> EstimationResult:
        started = time.perf_counter()
        self.reset(speed=speed, speed_std=speed_std, contact_speeds=record.initial_commands)
        xs, Ps = [], []
        fallback = []
        for k in range(record.n_samples):
            self.step(record.sample(k))
            xs.append(self.out_x[:2].copy())
            Ps.append(self.out_P[:2, :2].copy())
            fallback.append(self.fallback)
        self.fallbacks = np.array(fallback)
        wall = time.perf_counter() - started
        X, P = np.array(xs), np.array(Ps)
        return score(record, self.name, X[:, 1], P[:, 1, 1], wall, position=X[:, 0], covariance=P)


#: Verdict codes of :attr:`KalmanEstimator.verdicts`.
NOMINAL, ADAPTING = 0, 1


class KalmanEstimator(Estimator):
    """The default estimator (``kalman``): the nominal filter while it is consistent with
    the data, the adaptive filter from the first sample where it is not (see the module)."""

    name = "kalman"

    def __init__(self, model: EstimatorModel, prior: ModelPrior | None = None, *,
                 initial_covariance: Any = None, exact_holds: bool = True, window: int = 10,
                 false_alarm: float = 1e-4) -> None:
        from .kalman import NominalKalman
        from .monitor import ConsistencyMonitor

        self.model = model
        self.prior = ModelPrior() if prior is None else prior
        self.nominal = NominalKalman(model, initial_covariance=initial_covariance, exact_holds=exact_holds)
        self.monitor = ConsistencyMonitor(window, false_alarm)
        self.reset()

    def reset(self, *, speed: float = 0.0, speed_std: float | None = None,
              contact_speeds: Any = None) -> None:
        self._reset_args = dict(speed=speed, speed_std=speed_std, contact_speeds=contact_speeds)
        self.nominal.reset(**self._reset_args)
        self.monitor.reset()
        self.robust: RobustFilter | None = None
        self._history: list[tuple[EncoderSample, Any, float]] = []
        self._waiting: EncoderSample | None = None
        self.verdicts: list[int] = []
        self.tripped: tuple[float, str] | None = None

    def _switch(self, sample: EncoderSample, reason: str) -> tuple[float, float]:
        """The model failed at ``sample``: the adaptive filter from the start of the run,
        replayed over the samples so far (it then stands where it would had it run all along)."""
        self.tripped = (sample.time, reason)
        robust = self.robust = RobustFilter(self.model, self.prior)
        robust.prime([past for past, _, _ in self._history] + [sample],
                     [command for _, command, _ in self._history] + [sample.command],
                     self._reset_args["contact_speeds"])
        robust.reset(**self._reset_args)
        for past, command, force in self._history:
            robust.observe(past)
            robust.commanded(command, force)
        return robust.observe(sample)

    def observe(self, sample: EncoderSample) -> tuple[float, float]:
        if self._waiting is not None:            # no command given after the last sample
            self.commanded(self._last_command, self._last_force)
        self._waiting = sample
        if self.robust is not None:
            self.verdicts.append(ADAPTING)
            return self.robust.observe(sample)
        out = self.nominal.observe(sample)
        verdict = self.monitor.push(self.nominal.last_nis, "an exact hold failed" if self.nominal.hold_failed else "")
        if verdict.passes:
            self.verdicts.append(NOMINAL)
            return out
        self.verdicts.append(ADAPTING)
        return self._switch(sample, verdict.reason)

    def commanded(self, command: Any, force: float = 0.0) -> None:
        sample, self._waiting = self._waiting, None
        self._last_command, self._last_force = command, force
        if self.robust is not None:
            self.robust.commanded(command, force)
        else:
            self.nominal.commanded(command, force)
            self._history.append((sample, command, force))

    def run(self, record: EncoderRecord, *, speed: float = 0.0,
            speed_std: float | None = None) -> EstimationResult:
        """Offline: the nominal filter's pass (its vectorized wheel estimates), the monitor
        over its NIS and hold failures, and from the first failing sample on the adaptive
        filter's pass over the whole record (what stepping gives)."""
        started = time.perf_counter()
        self.reset(speed=speed, speed_std=speed_std, contact_speeds=record.initial_commands)
        X, P, _, _, nis, _ = self.nominal.filter(record, speed=speed, speed_std=speed_std)
        failures = self.nominal.hold_failures
        trip = None
        for k in range(record.n_samples):
            verdict = self.monitor.push(nis[k], "an exact hold failed" if failures[k] else "")
            if not verdict.passes:
                trip = k
                self.tripped = (float(record.times[k]), verdict.reason)
                break
        verdicts = np.zeros(record.n_samples, dtype=np.int64)
        if trip is not None:
            robust = self.robust = RobustFilter(self.model, self.prior)
            robust.prime([record.sample(k) for k in range(trip + 1)], list(record.commands[:trip + 1]),
                         record.initial_commands)
            robust.reset(speed=speed, speed_std=speed_std, contact_speeds=record.initial_commands)
            X, P = X.copy(), P.copy()
            for k in range(record.n_samples):
                robust.step(record.sample(k))
                if k >= trip:
                    X[k] = robust.x[:2]
                    P[k] = robust.P[:2, :2]
            verdicts[trip:] = ADAPTING
        self.verdicts = verdicts.tolist()
        wall = time.perf_counter() - started
        return score(record, self.name, X[:, 1], P[:, 1, 1], wall, position=X[:, 0], covariance=P,
                     nis=nis[1:])
