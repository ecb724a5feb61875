"""The adaptive filter the default ``kalman`` hands over to where the nominal model fails.

:class:`~toolkit.estimation.kalman.KalmanEstimator` (``kalman``) runs the nominal filter
under a consistency monitor; at the first sample where the data contradict the nominal model
it hands over, for good, to :class:`AdaptiveKalman`, replayed from the start of the run.
:class:`AdaptiveKalman` is an interacting multiple model
(free: the flow at the identified parameters; stuck: riding the nearest contact; free-form:
no model) over an extended filter of ``(X, V)``, the friction errors and the drag, with the
motor lag, the missed-count rate and the reading noise identified from the wheels, the told
ranges and a command's timing within its period as noise of the known input, and a monitor
that acts: gross innovations widen the filter, a failing window falls back towards the
window estimate.
Its parts: :mod:`~toolkit.estimation.wheel_bank`, :mod:`~toolkit.estimation.input_noise`,
:mod:`~toolkit.estimation.missed_counts`, :mod:`~toolkit.estimation.model_cache`. Derivations:
docs/estimation.md.
"""

from __future__ import annotations

import math
from collections import deque
from typing import Any

import numpy as np

from .._compiled import budget_clock
from .._compiled import kernels
from ..errors import as_float
from ..errors import ParameterTypeError, parameter_message
from ..model.friction import contact_forces
from ..laws import cell_centre, lag_response, quantization_variance
from ..model.motors import MotorPiece
from ..model.sensors import MAX_JITTER_PERIODS, EncoderRecord, EncoderSample
from ._base import EstimationResult, Estimator, lost_between, score
from ._hold import HoldLayer
from ._input import EstimatorModel
from .consider import prior_moments
from .contact_speeds import ContactSpeedTracker
from .input_noise import command_timing_variance, unknown_force_noise
from .missed_counts import absorbed_variance, told_missed_rate
from .model_cache import ModelCache
from .wheel_bank import WheelSpeedBank
from ..model.truth import DEFAULT_LAG, ModelPrior
from .identification import LagIdentifier, MissedCountRate, RideCheck
from .monitor import ConsistencyMonitor, NoiseMatcher, fit_noise
from .window import AdaptiveWindow

__all__ = ["AdaptiveKalman", "NOMINAL", "ADAPTING", "FALLBACK"]

#: Verdicts of :attr:`KalmanEstimator.verdicts` (per sample): the nominal filter's model
#: holds; the adaptive filter runs; the adaptive filter's own monitor fails and it falls back
#: towards the window estimate.
NOMINAL, ADAPTING, FALLBACK = 0, 1, 2


def _checked(model: Any, prior: Any, owner: str) -> tuple[EstimatorModel, ModelPrior]:
    """``model`` an EstimatorModel and ``prior`` a ModelPrior (None: the default), or the
    template error naming them."""
    if not isinstance(model, EstimatorModel):
        raise ParameterTypeError(parameter_message("model", owner, "be an EstimatorModel", model))
    prior = ModelPrior() if prior is None else prior
    if not isinstance(prior, ModelPrior):
        raise ParameterTypeError(parameter_message("prior", owner, "be a ModelPrior or None", prior))
    return model, prior


class AdaptiveKalman(Estimator):
    """The adaptive filter (the module; docs/estimation.md): an interacting multiple model of the body's
    modes over an augmented-state EKF of the friction errors and the drag.

    Parameters
    ----------
    model : EstimatorModel
        The nominal scene (never the truth).
    prior : ModelPrior, optional
        What the filter believes beyond the nominal scene (default ``ModelPrior()``).
    forgetting : float, 1/s
        Random-walk intensity of the parameters (``e_i`` per s, ``dc`` N s/m per s, squared
        per second), ``>= 0``: slow changes are tracked.
    switching : float
        Probability per sample that the physical modes (free, stuck) switch, in ``(0,
        0.5)``.
    reference : bool
        Run filterpy's ``IMMEstimator`` over ``KalmanFilter`` objects instead of the compiled
        kernels (the same arithmetic; slower; the tests' reference).
    """

    name = "kalman_adaptive"
    KERNELS = ("core", "lines", "window", "imm")
    #: Modes: the flow decides; riding the nearest contact; no model.
    FREE, STUCK, FREEFORM = 0, 1, 2
    #: The stuck probability (among the physical modes) from which a hold may start.
    HOLD_START = 0.9
    #: Samples over which the encoders must look ideal for the exact lines (:meth:`_ideal`).
    IDEAL_WINDOW = 50
    #: Twice chi-square(1)'s 90th percentile (2.706): the edge of the central innovations'
    #: NIS that the 90th percentile of the window must keep within (:meth:`_ideal`).
    NIS_EDGE = 2.0 * 2.706
    #: Largest share of wheel readings that may break their lines in that window.
    LINE_BREAKS = 0.03
    #: Largest widening of the covariances per failing sample (a factor).
    WIDEN_MAX = 10.0
    #: Probability per sample of leaving a physical mode for the free-form one.
    ESCAPE = 1e-3
    #: A command step (m/s) beyond which, with the lag not yet identified, the contact's
    #: transient is taken from the windows rather than the motor law (:meth:`commanded`).
    LARGE_STEP = 0.02

    def __init__(self, model: EstimatorModel, prior: ModelPrior | None = None, *,
                 forgetting: float = 1e-4, switching: float = 0.02, reference: bool = False) -> None:
        owner = type(self).__name__
        self.model, self.prior = _checked(model, prior, owner)
        self.forgetting = as_float(forgetting, "forgetting", owner, low=0.0)
        switching = as_float(switching, "switching", owner, low=0.0, high=0.5, low_open=True)
        if not isinstance(reference, bool):
            raise ParameterTypeError(parameter_message("reference", owner, "be a bool", reference))
        self.reference = reference
        self.n = model.n
        self.d = self.n + 3
        self.h = model.sensors.period
        self.q = model.sensors.central.distance_per_count
        self._lag_range = self.prior.lag_range if self.prior.lag_range is not None else (
            0.0, max(DEFAULT_LAG, model.motor_lag))
        self.monitor = ConsistencyMonitor(10, 1e-3)
        self._foaw = AdaptiveWindow(model.sensors, fit="best", band=self.q)
        # The free-form mode's intensity while the contacts move: the force the prior's
        # friction spread leaves unknown, as an acceleration held over a period (m/s per
        # sqrt(s): sigma_F / m sqrt(h)).
        spread_force = self.prior.friction_spread * float(np.sqrt(np.sum(model.forces ** 2)))
        self._moving_rate = max(spread_force, 1e-3 * float(model.forces.sum())) / model.mass * math.sqrt(self.h)
        e = self.ESCAPE
        # Row i to column j (row-stochastic, as filterpy's IMMEstimator uses it).
        self.M = np.array([[1.0 - switching - e, switching, e],
                           [switching, 1.0 - switching - e, e],
                           [0.5 * switching, 0.5 * switching, 1.0 - switching]])
        self._primed: tuple[float, float] | None = None
        #: The largest jitter the sensor law allows (s): the noise fits' bound on it.
        self._jitter_max = MAX_JITTER_PERIODS * self.h
        self.reset()

    # -- parameters ----------------------------------------------------------------------------
    def _model_at(self, theta: np.ndarray) -> EstimatorModel:
        """The model at the estimated magnitudes ``f (1 + e)``, the identified lag and the
        motors' wander (:class:`~toolkit.estimation.model_cache.ModelCache`); its magnitudes'
        errors are ``self._cache.built``."""
        return self._cache.at(theta[:self.n], self.lag, max(self._bank.drift, self.model.contact_drift))

    @property
    def lag(self) -> float:
        """The motor lag the flow uses, s: the identified one (within the prior's range) once
        a command change has been seen through, else the nominal one."""
        lag = self._lag_id.lag
        lo, hi = self._lag_range
        return self.model.motor_lag if lag is None else min(max(lag, lo), hi)

    @property
    def parameters(self) -> dict[str, Any]:
        """What the filter has identified: ``friction`` (the magnitudes' estimates, N, shape
        (n,)) and their std, ``drag`` (N s/m) and its std, ``lag`` (s; None before a change
        was seen through) and its std, ``wander`` (the motors', m/s per sqrt(s)), ``read_noise``
        (counts) and ``jitter`` (s) from the wheels, ``missed_count_prob`` (the rate's
        posterior mean per count transition) and its std."""
        n, x, P = self.n, self.x, self.P
        f = self.model.forces
        return {"friction": f * (1.0 + x[2:2 + n]), "friction_std": f * np.sqrt(np.diag(P)[2:2 + n]),
                "drag": float(self.model.damping + x[2 + n]), "drag_std": float(math.sqrt(P[2 + n, 2 + n])),
                "lag": self._lag_id.lag, "lag_std": self._lag_id.lag_std, "wander": self._bank.drift,
                "read_noise": math.sqrt(self._wheel_noise[0]), "jitter": math.sqrt(self._wheel_noise[1]),
                "missed_count_prob": self.missed_rate.mean, "missed_count_std": math.sqrt(self.missed_rate.variance)}

    def prime(self, samples: list[EncoderSample], commands: list[Any], initial: Any = None) -> None:
        """Learn the encoders' read noise and jitter from the wheels over ``samples`` (with
        the commands sent at them) before a run from the first of them: what the filter knows
        of its encoders by the last one (a replay starts from it). Kept by :meth:`reset`."""
        tracker = ContactSpeedTracker(self.model, initial, residuals=True)
        q_w = self.model.sensors.wheel.distance_per_count
        noise = None
        for sample, command in zip(samples, commands):
            speeds, _, steady, _ = tracker.push(sample.time, sample.wheel_counts, command)
            if steady and tracker.window_length >= 5:
                a, b = fit_noise(tracker.reading_variance - quantization_variance(q_w), speeds * speeds,
                                 self._jitter_max ** 2)
                noise = (a / (q_w * q_w), b)
        self._primed = noise

    # -- the recursion --------------------------------------------------------------------------
    def reset(self, *, speed: float = 0.0, speed_std: float | None = None,
              contact_speeds: Any = None) -> None:
        owner = f"{type(self).__name__}.reset"
        speed = as_float(speed, "speed", owner)
        std = 0.05 if speed_std is None else as_float(speed_std, "speed_std", owner, low=0.0, low_open=True)
        d, n = self.d, self.n
        mean, var = prior_moments(self.model, self.prior)
        x = np.zeros(d)
        x[1] = speed
        x[2:] = mean
        P = np.zeros((d, d))
        P[1, 1] = std * std
        P[2:, 2:] = np.diag(var)
        self.xs = np.array([x, x, x])
        self.Ps = np.array([P, P, P])
        self.mu = np.array([1.0 - 2e-3, 1e-3, 1e-3])
        self.xs, self.Ps = self.xs.copy(), self.Ps.copy()
        self.x, self.P = x.copy(), P.copy()
        self.out_x, self.out_P = self.x, self.P
        self._xs0, self._Ps0 = np.empty_like(self.xs), np.empty_like(self.Ps)
        self._cbar = np.empty(3)
        h = self.h
        self._h3 = h ** 3
        self._walk = np.array([h ** 3 / 3.0, h * h / 2.0, h])
        # The largest acceleration friction can give (all contacts one way), m/s^2.
        self._largest_accel = float(self.model.forces.sum()) / self.model.mass
        self._means, self._rows0, self._rows1 = np.empty((3, d)), np.empty((3, d)), np.empty((3, d))
        self._noises, self._nis = np.empty((3, 2, 2)), np.empty(3)
        self._noise_models = np.empty(4)
        self._cache = ModelCache(self.model)       # the models built at estimated magnitudes
        self._gains = np.zeros((2, n + 1))
        self._stuck_on: int | None = None
        self._mu_prev = self.mu
        sensors = self.model.sensors
        self._lag_id = LagIdentifier(sensors.wheel.distance_per_count, sensors.backlash, sensors.period,
                                     self._lag_range[1])
        self._lag_id.start(contact_speeds)
        self._tracker = ContactSpeedTracker(self.model, contact_speeds, residuals=True)
        self._bank = WheelSpeedBank(self.model)
        self._initial = None if contact_speeds is None else np.array(contact_speeds, dtype=float)
        self._held: np.ndarray | None = None
        self._noise = NoiseMatcher(100, self._jitter_max)
        self._wheel_noise = self._primed or (0.0, 0.0)
        self._layer = HoldLayer(self.model, tell_missed=True)
        self._lines = self._layer.lines
        #: The missed-count rate's posterior; per observed sample its mean and variance, and
        #: whether a central count lost there would have been repaired (:class:`HoldLayer`).
        self.missed_rate = MissedCountRate(self.prior.missed_count_mean)
        self.missed_history: list[tuple[float, float, bool]] = []
        self._ride = RideCheck(self.q, sensors.wheel.distance_per_count, self.missed_rate, self.h,
                               sensors.backlash)
        self._moments, self._empty = np.zeros(5), np.zeros((1, 2))
        self._timing = 0.0
        self.monitor.reset()
        self._foaw.reset(speed=speed)
        self.fallback = False
        self.holding = self.hold_failed = False
        self._anchor = (math.nan, 0)
        self._pending: tuple | None = None
        self._observed: tuple | None = None
        self._stepped_at: float | None = None            # the last stepped sample's time, s
        self._wheels_at: float | None = None             # the last wheel readings' time, s
        self._count_prev: int | None = None
        self._repeats = 0
        self._central_offset = 0
        self._wheel_offset = np.zeros(n, dtype=np.int64)
        self._repairs = False
        self._deaths: deque[int] = deque(maxlen=self.IDEAL_WINDOW)
        self._told_apart: deque[int] = deque(maxlen=self.IDEAL_WINDOW)
        self._nis_history: deque[float] = deque(maxlen=self.IDEAL_WINDOW)
        self._nis_over = 0                   # of those, above twice chi-square(1)'s 90 % (or NaN)
        self._first = True
        self.last_nis = math.nan
        self.imm = self._reference_imm() if self.reference else None

    def _reference_imm(self) -> Any:
        """filterpy's IMMEstimator over three KalmanFilter objects (``reference=True``)."""
        from filterpy.kalman import IMMEstimator, KalmanFilter

        filters = []
        for j in range(3):
            kf = KalmanFilter(dim_x=self.d, dim_z=1)
            kf.x = self.xs[j].copy()
            kf.P = self.Ps[j].copy()
            kf.H = np.zeros((1, self.d))
            kf.H[0, 0] = 1.0
            filters.append(kf)
        return IMMEstimator(filters, self.mu.copy(), self.M)

    # -- the modes' transitions (each writes mode j's predicted mean, its transition's rows 0 and 1
    # and its process noise of (X, V) into means[j], rows0[j], rows1[j], noises[j]) -----------
    def _predict_free(self, j: int, x: np.ndarray, P: np.ndarray, track: np.ndarray, var: np.ndarray,
                      steady: bool, force: float) -> None:
        """The free mode: the flow at the estimated parameters, or the stuck mode's motion
        where that flow keeps the body on a contact."""
        n, h = self.n, self.h
        theta = x[2:]
        V = float(x[1])
        k = self._stuck_on
        if (steady and k is not None and self._sticks(theta, track[0], k, force)
                and abs(V - track[0, k]) <= 2.0 * math.sqrt(max(P[1, 1], 0.0) + var[k]) + 1e-9):
            # Stuck at the last step on contact k, which still holds it (the set-valued
            # friction at the estimated magnitudes): the stuck mode's motion, no flow needed.
            self._predict_stuck(j, x, track, var, k)
            return
        hat = self._model_at(theta)
        delta = theta.copy()
        delta[:n] -= self._cache.built                 # what the built model does not hold yet
        gains = self._gains
        var_v = float(var[int(np.abs(track[0] - V).argmin())])
        dx, dV, Q, slopes, _, on_set = hat.increment(V, track, math.sqrt(var_v), math.sqrt(max(P[1, 1], 0.0)),
                                                     steady, None, force, gains)
        JX, J = slopes if slopes is not None else (h, 1.0)
        correction = gains @ delta
        V_new = V + dV + correction[1]
        gap = np.abs((track[1] if steady else hat.end_speeds(track)) - V_new)   # (held: they end as they start)
        k = int(gap.argmin())
        self._stuck_on = k if (on_set and gap[k] <= 1e-9) else None
        if self._stuck_on is not None:
            # The flow ends with the body on a contact's speed: the stuck mode's motion.
            self._predict_stuck(j, x, track, var, k)
            return
        mean, row0, row1 = self._means[j], self._rows0[j], self._rows1[j]
        mean[:] = x
        mean[0] = x[0] + h * V + dx + correction[0]
        mean[1] = V_new
        row0[0], row0[1], row1[0], row1[1] = 1.0, JX, 0.0, J
        row0[2:] = gains[0]
        row1[2:] = gains[1]
        self._noises[j] = Q

    def _sticks(self, theta: np.ndarray, speeds: np.ndarray, k: int, force: float) -> bool:
        """A body at contact ``k``'s speed stays on it at the magnitudes ``f (1 + e)``: the
        other contacts' force (the friction law), the outside force and the drag lie within
        contact ``k``'s set-valued ``[-f_k, f_k]``."""
        forces = self.model.forces * np.maximum(1.0 + theta[:self.n], 1e-3)
        v = float(speeds[k])
        G = float(contact_forces(speeds - v, forces).sum()) + force - (self.model.damping + theta[self.n]) * v
        return abs(G) <= forces[k]

    def _predict_stuck(self, j: int, x: np.ndarray, track: np.ndarray, var: np.ndarray, k: int | None = None
                       ) -> None:
        """The stuck mode: the body rides contact ``k`` (the nearest to its speed): its speed is
        the contact's (the motor law in a transient), its position moves with it; the
        contact's estimate errs by ``var[k]`` and wanders (the bank's intensity). While the
        contact holds its speed, the compiled :func:`toolkit._compiled.imm.predict_held`."""
        h = self.h
        drift = self._bank.drift ** 2
        mean, row0, row1, Q = self._means[j], self._rows0[j], self._rows1[j], self._noises[j]
        k = kernels("imm").predict_held(x, track[0], track[1], var, -1 if k is None else k, h, self._h3, drift,
                                        mean, row0, row1, Q)
        if k >= 0:
            return
        k = -1 - k
        piece = MotorPiece.build(0.0, track[0, k:k + 1], track[1, k:k + 1], self.lag, math.inf)
        mean[:] = x
        mean[0] = x[0] + float(piece.displacement(h)[0])
        mean[1] = float(piece.speeds_at(h)[0])
        row0[:] = 0.0
        row1[:] = 0.0
        row0[0] = 1.0
        kernels("imm").held_noise(float(var[k]), h, self._h3, drift, Q)

    def _predict_freeform(self, j: int, x: np.ndarray, steady: bool) -> None:
        """The free-form mode: the speed a random walk (the motors' wander where the contacts
        hold their speeds; while they move, at least the force the prior's friction spread
        leaves unknown, held over a period); :func:`toolkit._compiled.imm.predict_walk`."""
        s2 = (self._bank.drift if steady else max(self._bank.drift, self._moving_rate)) ** 2
        kernels("imm").predict_walk(x, self.h, self._walk, s2, self._means[j], self._rows0[j], self._rows1[j],
                                    self._noises[j])

    # -- one sample -----------------------------------------------------------------------------
    def _contact_speeds(self, t: float, track: np.ndarray, var_v: np.ndarray, steady: bool
                        ) -> tuple[np.ndarray, np.ndarray]:
        """The period's track with each settled contact at its wheel's exact line where the
        encoders look ideal and that line is sharper: the speed's uniform posterior over the
        polygon of lines the wheel's counts allow since its window started, its variance with
        the chance of a missed count the line absorbed (:func:`absorbed_variance`)."""
        var = np.array(var_v, dtype=float)
        lines = self._lines
        if not (steady and lines.active and self._repairs):
            return track, var
        p, p_var = self._missed_rate()
        given_var = var.copy() if p > 0.0 else var
        track = track.copy()
        # The contacts the body may meet within the period: the three nearest its speed.
        kernels("lines", 150 * self.n).sharper_lines(lines.polys, lines.counts,
                                                     np.abs(track[0] - self.x[1]).argsort()[:3], self._empty,
                                                     self._moments, track, var)
        if p > 0.0:
            # A loss the line absorbed: its speed's variance gains that chance times the bias
            # (the contact's window absorbed it as well: the line stays where it was sharper).
            for k in np.flatnonzero(var != given_var).tolist():
                var[k] += absorbed_variance(p, p_var, float(lines.unseen[k]), lines.wheel_count,
                                            t - float(lines.starts[k]))
        return track, var

    def _missed_rate(self) -> tuple[float, float]:
        """The missed-count rate and its variance for :func:`absorbed_variance`: the told one
        (known); else the posterior's (:class:`~toolkit.estimation.MissedCountRate`) once a
        loss has been repaired, 0 before (the prior alone is no evidence that the encoders
        miss counts at all: an ideal world's lines stay as they are)."""
        told = told_missed_rate(self.model, self.prior)
        if told > 0.0:
            return told, 0.0
        rate = self.missed_rate
        return (rate.mean, rate.variance) if rate.repairs else (0.0, 0.0)

    def _step(self, c: int, t: float, anchor: tuple[float, int], track: np.ndarray, var_v: np.ndarray,
              steady: bool, force: float) -> None:
        """Predict (the modes), the optional layer (an exact hold), update (the modes)."""
        q = self.q
        self._repairs = ideal = self._ideal()
        track, var = self._contact_speeds(t, track, var_v, steady)
        prior_x, prior_P = (float(self.x[0]), float(self.x[1])), self.P[:2, :2].copy()
        # The layer needs only the last posterior: where the modes say the body rides a
        # settled contact and the encoders look ideal, the exact hold's posterior is the
        # estimate, and a reading a count short of every line is a missed count, repaired.
        out = None
        if steady and self._layer.ready:
            k = int(np.abs(track[0] - prior_x[1]).argmin())
            out = self._layer.step(t, c, anchor, track[0], float(var[k]), prior_x, prior_P,
                                   self._stuck_share(self._mu_prev) >= self.HOLD_START and ideal, repair=ideal)
            if out is not None and out.repaired:
                self._central_offset += out.repaired
                c += out.repaired
                self._anchor = (t, c)
        else:
            self._layer.stop()
        self.hold_failed = out is not None and out.failed
        self._repeats = self._repeats + 1 if c == self._count_prev else 0
        self._count_prev = c
        R0 = quantization_variance(q) * (1 + self._repeats)
        z = cell_centre(c, q)
        elapsed = self.h if self._stepped_at is None else t - self._stepped_at
        self._stepped_at = t
        self._modes(z, R0, track, var, steady, force, elapsed)
        self.holding = out is not None and not out.failed
        if self.holding:
            self.last_nis = out.nis
            self.x = self.x.copy()
            self.P = self.P.copy()
            self.x[:2] = out.state
            self.P[:2, :] = 0.0
            self.P[:, :2] = 0.0
            self.P[:2, :2] = out.covariance
            # A missed count the hold's central line or its wheel's absorbed (the wheels
            # weighted by the hold's evidence).
            p, p_var = self._missed_rate()
            if p > 0.0:
                lines, layer = self._lines, self._layer
                evidence = layer.evidence
                total, added = float(evidence.sum()), 0.0
                for i in np.flatnonzero(evidence > 0.0).tolist():
                    added += float(evidence[i]) / total * absorbed_variance(
                        p, p_var, float(lines.unseen[i]), lines.wheel_count, t - float(lines.starts[i]))
                self.P[1, 1] += added + absorbed_variance(p, p_var, layer.unseen, self.q, t - layer.started)
        self._mu_prev = self.mu

    def _check_ride(self, c: int, wheels: np.ndarray, track: np.ndarray, steady: bool) -> None:
        """No line shows a loss: the body's count ``c`` against the wheel it rides does
        (:class:`~toolkit.estimation.identification.RideCheck`): the contact nearest the
        estimated speed where the modes say the body rides one and the contacts hold their
        speeds."""
        if not steady or self._stuck_share(self.mu) < self.HOLD_START:
            self._ride.stop()
            return
        k = int(np.abs(track[0] - self.x[1]).argmin())
        self._ride.push(c, int(wheels[k]), k, float(track[0, k]))

    def _stuck_share(self, mu: np.ndarray) -> float:
        """The probability that the body rides a contact, among the physical modes (the free
        mode counts where its flow left the body on a contact)."""
        return (mu[1] + (mu[0] if self._stuck_on is not None else 0.0)) / max(mu[0] + mu[1], 1e-300)

    def _predict_modes(self, track: np.ndarray, var: np.ndarray, steady: bool, force: float) -> Any:
        """The IMM's mixing and each mode's prediction over a period (into :attr:`_means`,
        :attr:`_rows0`, :attr:`_rows1`, :attr:`_noises`); returns the kernels."""
        K = kernels("imm", 40 * self.d * self.d)
        K.mix(self.mu, self.M, self.xs, self.Ps, self._xs0, self._Ps0, self._cbar)
        xs0, Ps0 = self._xs0, self._Ps0
        large = not steady and float(np.abs(track[1] - track[0]).max()) > self.LARGE_STEP
        for j in range(3):
            if j == self.FREE or (j == self.FREEFORM and large):
                # In a large transient (the contacts sweep past the body) the free-form mode
                # follows the flow, which knows the motor law; elsewhere it is the model-free
                # alternative (a random walk of the speed).
                self._predict_free(j, xs0[j], Ps0[j], track, var, steady, force)
            elif j == self.STUCK:
                self._predict_stuck(j, xs0[j], track, var)
            else:
                self._predict_freeform(j, xs0[j], steady)
        return K

    def _timing_noise(self) -> None:
        """A command change's timing within its period (:func:`command_timing_variance`),
        added to every mode's process noise once."""
        if self._timing > 0.0:
            h = self.h
            self._noises += self._timing * np.array([[h * h, h], [h, 1.0]])
            self._timing = 0.0

    def _coast(self, t: float, track: np.ndarray, var: np.ndarray, steady: bool, force: float
               ) -> tuple[np.ndarray, np.ndarray, bool, float]:
        """A period whose sample was lost (ending at ``t``, s): the IMM's prediction with no
        update (the modes' probabilities the mixing's ``cbar``), the last command held;
        returns the next period's ``(track, var, steady, force)``: the contacts where the
        motor law takes them, their variance grown by the motors' wander."""
        K = self._predict_modes(track, var, steady, force)
        self._timing_noise()
        if self.reference:
            self._modes_reference(math.nan, math.inf, self._means, list(zip(self._rows0.copy(), self._rows1.copy())),
                                  self._noises.copy(), update=False)
        else:
            xs, Ps, forget = np.empty_like(self.xs), np.empty_like(self.Ps), self.forgetting * self.h
            for j in range(3):
                K.predict_rows(self._Ps0[j], self._rows0[j], self._rows1[j], self._noises[j], forget, Ps[j])
                xs[j] = self._means[j]
            self.xs, self.Ps, self.mu = xs, Ps, self._cbar.copy()
            self.x, self.P = np.empty(self.d), np.empty((self.d, self.d))
            K.combine(self.mu, self.xs, self.Ps, self.x, self.P)
        self._stepped_at = t
        self._mu_prev = self.mu
        if not steady:
            lag = self.lag
            start = lag_response(track[1], track[0], self.h, lag) if lag > 0.0 else track[1].copy()
            track = np.array((start, track[1]))
        return track, var + self._bank.drift ** 2 * self.h, steady, force

    def _modes(self, z: float, R0: float, track: np.ndarray, var: np.ndarray, steady: bool, force: float,
               elapsed: float) -> None:
        """The IMM cycle: mix, each mode's prediction, the measurement noise, update, combine."""
        K = self._predict_modes(track, var, steady, force)
        Ps0, cbar = self._Ps0, self._cbar
        means, rows0, rows1, noises = self._means, self._rows0, self._rows1, self._noises
        # The measurement noise: the quantization's plus what covariance matching finds in
        # the innovations against the modes' combined prediction, or in the wheels' residuals
        # (read noise, jitter: the same electronics read all encoders at the same instants).
        # The mixture's predicted X (its variance: (A P0 A^T)[0, 0] + Q[0, 0] with row 0 of A,
        # per mode, and the modes' spread) and V.
        q = self.q
        x_pred, predicted, speed = K.predicted_first(cbar, means, rows0, Ps0, noises)
        wheel = q * q * self._wheel_noise[0] + self._wheel_noise[1] * speed * speed
        R = R0 + max(self._noise.extra(speed), wheel)
        # (The unknown force is read off a one-period prediction: after lost samples the
        # periods between are coasted; a sample off the grid is left to the other layers.)
        gross = unknown_force_noise(z - x_pred, predicted + R, q, self.h,
                                    self._largest_accel + abs(force) / self.model.mass)
        if gross is not None and abs(elapsed - self.h) <= 0.5 * self.h:
            noises += gross                  # (every mode's, before the update)
        self._timing_noise()
        if self.reference:
            self._modes_reference(z, R, means, list(zip(rows0.copy(), rows1.copy())), noises.copy())
        else:
            x, P = self.x, self.P = np.empty(self.d), np.empty((self.d, self.d))
            noise = self._noise_models
            noise[0], noise[1], noise[2], noise[3] = self._noise.a, self._noise.b, q * q * self._wheel_noise[0], \
                self._wheel_noise[1]
            x_pred, predicted, speed, self.last_nis = K.measure_cycle(
                Ps0, means, rows0, rows1, noises, self.forgetting * self.h, cbar, z, R0, noise, self.xs, self.Ps,
                self.mu, x, P, self._nis)
        self._noise.push(z - x_pred, predicted, R0, speed)
        history, nis = self._nis_history, (z - x_pred) ** 2 / (predicted + R0)
        if len(history) == history.maxlen and not history[0] <= self.NIS_EDGE:
            self._nis_over -= 1
        history.append(nis)
        if not nis <= self.NIS_EDGE:
            self._nis_over += 1

    def _modes_reference(self, z: float, R: float, means: list, rows: list, noises: list,
                         update: bool = True) -> None:
        """The same cycle on filterpy's IMMEstimator: each filter's transition ``F`` (the
        identity but for the rows of ``(X, V)``), ``Q``, and the input that makes ``F x0 +
        B u`` the mode's prediction from the mixed state ``x0``. Without ``update`` (a lost
        sample) the prediction alone, the modes' probabilities the mixing's ``cbar``."""
        imm = self.imm
        xs0 = self._xs0
        for j, kf in enumerate(imm.filters):
            F = np.eye(self.d)
            F[0], F[1] = rows[j]
            kf.F = F
            Q = np.eye(self.d) * (self.forgetting * self.h)
            Q[:2, :2] = noises[j]
            kf.Q = Q
            kf.B = (means[j] - F @ xs0[j])[:, None]
            kf.R = np.array([[R]])
        imm.predict(u=np.array([1.0]))
        if update:
            imm.update(np.array([z]))
        else:
            # (filterpy's update(None) keeps each filter's last likelihood: no update is the
            # predicted probabilities, and the mixing that follows from them.)
            imm.mu = imm.cbar.copy()
            imm._compute_mixing_probabilities()
            imm._compute_state_estimate()
        self.xs = np.array([kf.x.ravel() for kf in imm.filters])
        self.Ps = np.array([kf.P for kf in imm.filters])
        self.mu = imm.mu.copy()
        self.x, self.P = imm.x.ravel().copy(), imm.P.copy()
        if update:
            self.last_nis = float(self.mu @ np.array([(kf.y.item() ** 2) / kf.S.item() for kf in imm.filters]))

    def _ideal(self, told_apart: bool = False) -> bool:
        """The encoders look ideal (they only quantize, and may miss a count): over the last
        :attr:`IDEAL_WINDOW` samples the wheels' exact lines broke (a reading no line of the
        window allows, missed counts repaired) on at most :attr:`LINE_BREAKS` of the wheel
        readings, and the central innovations' 90th percentile NIS is within twice that of
        chi-square(1) (2.71): rare outliers (a missed count) pass; read noise, jitter or a
        wandering motor, which break lines within a few readings, do not. ``told_apart``:
        the lines broken by a missed count told apart but not repaired do not count (the
        missed-count rate's evidence, :meth:`observe`)."""
        if len(self._nis_history) < self.IDEAL_WINDOW:
            return False
        deaths = sum(self._deaths) - (sum(self._told_apart) if told_apart else 0)
        if deaths > self.LINE_BREAKS * self.n * len(self._deaths):
            return False
        # The 45th of 50 within the edge: at most 5 above it.
        return self._nis_over <= self.IDEAL_WINDOW // 10

    def _act(self) -> None:
        """The consistency monitor's verdict on this sample, and what the filter does: while
        the windowed NIS fails, widen the modes' ``(X, V)`` covariances by the window's mean
        NIS (at most :attr:`WIDEN_MAX`) and fall back towards the window (FOAW) estimate:
        the output's speed is the covariance intersection of the filter's and the window's
        (consistent whatever their correlation; for two scalars it keeps the sharper)."""
        verdict = self.monitor.push(self.last_nis)
        self.fallback = not verdict.passes
        self.out_x, self.out_P = self.x, self.P
        if not self.fallback:
            return
        root = math.sqrt(min(max(self.monitor.mean, 1.0), self.WIDEN_MAX))
        self.Ps[:, :2, :] *= root
        self.Ps[:, :, :2] *= root
        self.x, self.P = np.empty(self.d), np.empty((self.d, self.d))
        kernels("imm").combine(self.mu, self.xs, self.Ps, self.x, self.P)
        if self.reference:
            for j, kf in enumerate(self.imm.filters):
                kf.P = self.Ps[j].copy()
        speed = self._foaw.estimate()[0]
        variance = self._foaw.matched_variance
        if variance > 0.0 and math.isfinite(speed) and variance < self.P[1, 1]:
            x, P = self.x.copy(), self.P.copy()
            x[1] = speed
            P[1, :] = 0.0
            P[:, 1] = 0.0
            P[1, 1] = variance
            self.out_x, self.out_P = x, P
        else:
            self.out_x, self.out_P = self.x, self.P

    # -- the interface --------------------------------------------------------------------------
    def observe(self, sample: EncoderSample) -> tuple[float, float]:
        if self._observed is not None:
            self.commanded(self._last_command, self._last_force)
        c = sample.central_count + self._central_offset
        wheels = np.asarray(sample.wheel_counts) + self._wheel_offset
        pending = self._pending
        repairing, lines = self._repairs, self._lines
        repaired = self._layer.wheels(sample.time, wheels, None if pending is None else pending[0],
                                      True if pending is None else pending[2], repair=repairing)
        if repaired is not None:
            self._wheel_offset = self._wheel_offset + repaired
            wheels = wheels + repaired
        # The missed-count rate's evidence from the wheels: the repairs, or where the filter
        # does not repair (its encoders' test counts a missed count as a break), the losses
        # told apart while the encoders look ideal but for them (decided on the samples
        # before: no noise that breaks lines), over the exposure.
        lost, exposure, lined = 0, lines.exposure, repairing
        if repairing:
            lost = 0 if repaired is None else int(np.abs(repaired).sum())
        elif exposure or lines.spared:
            lined = self._ideal(told_apart=True)
            lost, exposure = (lines.spared, exposure) if lined else (0, 0.0)
        central = self._central_offset
        self._deaths.append(lines.deaths if lines.active else 0)
        self._told_apart.append(lines.spared if lines.active else 0)
        if self._first:
            q = self.q
            self.xs[:, 0] = cell_centre(c, q)
            self.Ps[:, 0, :] = 0.0
            self.Ps[:, :, 0] = 0.0
            self.Ps[:, 0, 0] = quantization_variance(q)
            self.x, self.P = self.xs[0].copy(), self.Ps[0].copy()
            if self.reference:
                self.imm = self._reference_imm()
            self._first = False
            self._count_prev = c
            self._anchor = (sample.time, c)
        else:
            anchor, self._anchor = self._anchor, (sample.time, c)
            missing = int(lost_between(sample.time - anchor[0], self.h))
            if missing:
                # Lost samples: their periods are predicted without an update, the command
                # held (the ride check counts one period between its readings: it restarts).
                self._ride.stop()
                for j in range(1, missing + 1):
                    pending = self._coast(anchor[0] + j * self.h, *pending)
            self._step(c, sample.time, anchor, *pending)
            if lined or self._layer.exposure:
                # The lines or a hold count this sample's evidence.
                self._ride.stop()
            else:
                self._check_ride(c + self._central_offset - central, wheels, pending[0], pending[2])
        # The missed-count rate from the repairs (wheels' and, in holds, the central count's)
        # over the transitions where a loss would have shown.
        layer, rate = self._layer, self.missed_rate
        rate.push(lost + abs(self._central_offset - central), exposure + layer.exposure)
        self.missed_history.append((rate.mean, rate.variance, layer.seen))
        self._observed = (sample.time, wheels)
        self._foaw.push(sample.time, c)
        self._act()
        return float(self.out_x[1]), float(self.out_P[1, 1])

    def commanded(self, command: Any, force: float = 0.0) -> None:
        (t, wheels), force = self._take_observed(force)
        periods = 1 if self._wheels_at is None else int(lost_between(t - self._wheels_at, self.h)) + 1
        self._wheels_at = t
        self._last_command, self._last_force = command, force
        tracker = self._tracker
        speeds, _, steady, track = tracker.push(t, wheels, command)
        self._lag_id.push(t, wheels, command)
        if steady and tracker.window_length >= 15 and tracker.window_length % 5 == 0:
            # Read noise (counts) and jitter (s) from the wheels' residuals against their
            # speeds (windows of 15 readings: clear of the transient).
            q_w = self.model.sensors.wheel.distance_per_count
            a, b = fit_noise(tracker.reading_variance - quantization_variance(q_w), speeds * speeds,
                             self._jitter_max ** 2)
            self._wheel_noise = (a / (q_w * q_w), b)
        u = tracker.command                                 # (clipped to the speed limits)
        if self._held is None:
            # The first sample: the motors run at their initial speeds (or the first command).
            initial = u if self._initial is None else self._initial
            var = np.full(self.n, tracker.white_variance)
            self._bank.start(wheels, initial, var)
            self._large = np.zeros(self.n, dtype=bool)
            speeds = initial
        else:
            banked, var_b = self._bank.push(wheels, self._held, self.lag, tracker.reading_variance, periods)
            # A large transient (a reversal, or a step beyond LARGE_STEP) under a lag not yet
            # identified: the law's path is not trusted there; the window estimates (the motor
            # law from the change, then the settled lines) stand in until the windows hold
            # five readings, when the bank restarts from them.
            if tracker.changed and self._lag_id.lag is None and self._lag_range[0] != self._lag_range[1]:
                held = self._held
                self._large |= (np.abs(u - held) > self.LARGE_STEP) | (np.sign(u) != np.sign(held))
            if self._large.any():
                back = self._large & steady & (tracker.window_length >= 5)
                self._bank.restart(back, wheels, speeds, tracker.contact_variance)
                self._large &= ~back
                var = np.where(self._large, tracker.contact_variance, var_b)
                speeds = np.where(self._large | back, speeds, banked)
            else:
                var, speeds = var_b, banked
        if tracker.changed and self._held is not None:
            self._timing = command_timing_variance(self._held, u, self.h, self.lag,
                                                   self._largest_accel + abs(force) / self.model.mass)
        self._held = u
        track = np.array((speeds, speeds if steady else u))
        if not steady:
            # The lag within its prior range moves the contacts' speeds over the coming period
            # by this much: its spread (uniform over the range) is noise of the known input.
            lo, hi = self._lag_range
            if self._lag_id.lag is not None:
                # Identified: two standard deviations about it, within the range.
                spread = 2.0 * self._lag_id.lag_std
                lo, hi = max(lo, self._lag_id.lag - spread), min(hi, self._lag_id.lag + spread)
            ends = [lag_response(u, speeds, self.h, lag) if lag > 0.0 else u for lag in (lo, hi)]
            var = var + quantization_variance(ends[0] - ends[1])
        self._pending = (track, var, steady, force)

    def run(self, record: EncoderRecord, *, speed: float = 0.0,
            speed_std: float | None = None) -> EstimationResult:
        self._check_record(record)
        started = budget_clock()
        self.reset(speed=speed, speed_std=speed_std, contact_speeds=record.initial_commands)
        K = record.n_samples
        X, P = np.empty((K, 2)), np.empty((K, 2, 2))
        fallback = np.zeros(K, dtype=bool)
        for k in range(K):
            self.step(record.sample(k))
            X[k], P[k], fallback[k] = self.out_x[:2], self.out_P[:2, :2], self.fallback
        #: Per sample of the last run: the filter fell back towards the window estimate.
        self.fallbacks = fallback
        wall = budget_clock() - started
        return score(record, self.name, X[:, 1], P[:, 1, 1], wall, position=X[:, 0], covariance=P)
