"""The nominal Kalman filter: the scene taken as true.

:class:`NominalKalman` is filterpy's ``KalmanFilter`` over ``x = (X, V)`` (body position at
the central encoder's radius, m, and speed, m/s): ``predict`` with the plant's exact flow over
the period as known input, linearized at the estimate (``F``, ``u``; ``Q`` what the filter
does not know of that input), and ``update`` with the central count's cell centre ``z``
(``H = [1, 0]``, ``R`` the quantization's variance, growing while the count repeats, plus the
declared read noise and jitter). Where the body rides a settled contact and the encoders are
ideal, the exact posterior of the counts replaces the white update
(:mod:`toolkit.estimation._hold`). Derivations: docs/estimation.md. filterpy is imported where
a filter is built.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..laws import cell_centre, quantization_variance
from .._compiled import budget_clock
from .._compiled import kernels
from ..errors import as_float, as_float_array
from ..errors import ParameterError, ParameterTypeError, parameter_message
from ..model.sensors import EncoderRecord, EncoderSample
from ..model.truth import ModelPrior
from ._base import EstimationResult, Estimator, check_covariance, lost_between, refuse_gaps, score
from ._hold import HoldLayer
from ._input import EstimatorModel
from .consider import Consider, OtherContact, prior_moments
from .contact_speeds import ContactSpeedTracker, contact_speed_estimates

__all__ = ["FilterPass", "NominalKalman", "steady_state_gain", "measurement_variance"]

#: What nothing considered adds (shared, read-only).
_NOTHING = np.zeros((2, 2))
_NOTHING.setflags(write=False)


def _side(speed: float, bounds: Any) -> int | None:
    """Which edge of the equilibrium set (``bounds[2]`` or ``[3]``) ``speed`` is, if either
    (to the rounding of ``V + (edge - V)``: 1e-12 m/s)."""
    lo, hi = bounds[2], bounds[3]
    near = 2 if abs(speed - lo) <= abs(speed - hi) else 3
    return near if abs(speed - bounds[near]) <= 1e-12 else None


def _scalar_inverse(S: np.ndarray) -> np.ndarray:
    """Inverse of the 1 x 1 innovation covariance (filterpy's ``inv`` hook)."""
    return 1.0 / S


def measurement_variance(counts: np.ndarray, speed: np.ndarray, model: EstimatorModel) -> np.ndarray:
    """``R_k`` of the central encoder for each sample (docs/estimation.md), m^2.

    Parameters
    ----------
    counts : ndarray of shape (k,), int
    speed : ndarray of shape (k,), m/s
        Speed used for the jitter term.
    """
    sensors = model.sensors
    q = sensors.central.distance_per_count
    k = counts.size
    same = np.zeros(k, dtype=np.int64)
    same[1:] = counts[1:] == counts[:-1]
    # r_k: run length of repeats ending at k (a cumulative count reset where the count changes).
    run = np.cumsum(same)
    reset = np.maximum.accumulate(np.where(same == 0, run, 0))
    repeats = run - reset
    return quantization_variance(q) * (1.0 + repeats) + sensors.read_noise_variance * q * q + (speed * sensors.jitter) ** 2


def _measurement_variance_one(repeats: int, speed: float, q: float, sensors: Any) -> float:
    """:func:`measurement_variance` of one sample (same expression), m^2."""
    return quantization_variance(q) * (1.0 + repeats) + sensors.read_noise_variance * q * q + (speed * sensors.jitter) ** 2


def _make_filter(model: EstimatorModel) -> Any:
    # filterpy is imported here, not at module level: toolkit imports must not load it.
    from filterpy.kalman import KalmanFilter

    h = model.sensors.period
    kf = KalmanFilter(dim_x=2, dim_z=1)
    kf.F = np.array([[1.0, h], [0.0, 1.0]])
    kf.H = np.array([[1.0, 0.0]])
    kf.B = None                       # the known input enters the state before predict()
    kf.inv = _scalar_inverse          # 1-D measurement: no LAPACK call per step
    return kf


@dataclass(frozen=True, eq=False)
class FilterPass:
    """What :meth:`NominalKalman.filter` returns: the filter's pass over a record of ``k``
    samples (row ``j``: sample ``j``; the input, transition and process noise of row ``j``
    are of the period ending at sample ``j``).

    Attributes
    ----------
    states : ndarray of shape (k, 2)
        Filtered ``(X, V)``: m, m/s.
    covariances : ndarray of shape (k, 2, 2)
        Their covariances (m^2, m^2/s, (m/s)^2).
    inputs : ndarray of shape (k, 2)
        The known input ``u`` of each step (m, m/s).
    transitions : ndarray of shape (k, 2, 2)
        The flow's slopes ``F`` of each step (linearized at the estimate).
    process_noises : ndarray of shape (k, 2, 2)
        ``Q`` of each step.
    nis : ndarray of shape (k,)
        Normalized innovation squared of each reading (NaN at sample 0).
    hold_failures : ndarray of shape (k,), bool
        The reading left every line of an exact hold (the hold failed).
    cell_probabilities : ndarray of shape (k,)
        The probability of the reading's count cell under the prediction.
    wall_time : float, s
    considered : ndarray of shape (k, 2, 2)
        What the considered force errors add to ``covariances`` (zero without them).
    """

    states: np.ndarray
    covariances: np.ndarray
    inputs: np.ndarray
    transitions: np.ndarray
    process_noises: np.ndarray
    nis: np.ndarray
    hold_failures: np.ndarray
    cell_probabilities: np.ndarray
    wall_time: float
    considered: np.ndarray


class NominalKalman(Estimator):
    """Kalman filter of ``(X, V)`` with the contact force as known input (the module; docs/estimation.md).

    Parameters
    ----------
    model : EstimatorModel
    initial_covariance : array_like of shape (2, 2), optional
        Prior covariance of ``(X, V)`` (m^2, m^2/s, (m/s)^2), symmetric positive definite;
        default ``diag(q^2 / 12, speed_std^2)`` at :meth:`reset`.
    exact_holds : bool
        While the body rides a settled contact, take the exact posterior of the counts
        (:mod:`toolkit.estimation._hold`) instead of the white-noise update (default; used
        only with ideal encoders, ``contact_drift = 0``, no drag and no friction spread).
    consider : ModelPrior, optional
        Force errors the filter does not estimate but reports (a consider analysis,
        docs/estimation.md): the prior's friction magnitudes and drag, as second moments
        ``m2`` about the model (``prior_moments``), carried through the filter's own steps,
        and where the filter has the body stuck on a contact, the chance that they let it
        slide on to the next (``toolkit.estimation.consider.OtherContact``). The
        estimates and the filter's own covariance are unchanged. Default: none.

    Attributes
    ----------
    exact_holds : bool
        Whether the exact holds are in effect: asked for, and the model allows them.
    considered : ndarray of shape (2, 2)
        At the last sample, what the considered force errors add to the covariance of
        ``(X, V)``: ``S diag(m2) S^T``, with the sensitivity ``S`` of the filter's error
        to them stepped as ``S+ = (I - K H)(F S + G)`` (``G`` the flow's response to each
        over the period, the model's ``increment`` gains), plus the other contact's ``p (u
        u^T + C)``; zero without ``consider``.
    """

    name = "kalman_nominal"
    KERNELS = ("core", "lines")

    def __init__(self, model: EstimatorModel, *, initial_covariance: Any = None,
                 exact_holds: bool = True, consider: ModelPrior | None = None) -> None:
        if not isinstance(model, EstimatorModel):
            raise ParameterTypeError(parameter_message("model", type(self).__name__,
                                                       "be an EstimatorModel", model))
        if consider is not None and not isinstance(consider, ModelPrior):
            raise ParameterTypeError(parameter_message("consider", type(self).__name__,
                                                       "be a ModelPrior or None", consider))
        if not isinstance(exact_holds, bool):
            raise ParameterTypeError(parameter_message("exact_holds", type(self).__name__,
                                                       "be a bool", exact_holds))
        self.model = model
        sensors = model.sensors
        #: Whether holds use the exact posterior: asked for, ideal encoders (no read noise,
        #: missed counts or jitter), motors that hold their speeds, no drag, and friction
        #: the model knows (with an uncertain spread the filter cannot tell that the body
        #: stuck: it may still creep towards the weighted median).
        self.exact_holds = (exact_holds and sensors.count_noise == 0.0 and sensors.jitter == 0.0
                            and sensors.missed_count_prob == 0.0 and model.contact_drift == 0.0
                            and model.damping == 0.0 and model.friction_uncertainty == 0.0)
        self.initial_covariance = (None if initial_covariance is None else check_covariance(
            initial_covariance, "initial_covariance", type(self).__name__, 2))
        h = self._h = model.sensors.period
        self._q = model.sensors.central.distance_per_count
        self._H = np.array([[1.0, 0.0]])
        self._F = np.array([[1.0, h], [0.0, 1.0]])
        self._I2 = np.eye(2)
        self._Q0 = np.zeros((2, 2))
        self._F_reset = np.zeros((2, 2))
        self._H_speed = np.array([[0.0, 1.0]])
        self._consider = self._other = None   # (the considered force errors (e_1 .. e_n, dc))
        if consider is not None:
            mean, var = prior_moments(model, consider)
            if (m2 := var + mean * mean).any():
                self._consider = Consider(m2)
                self._other = OtherContact(model.forces, model.mass, model.damping, m2)
        self.reset()

    def _build(self) -> Any:
        return _make_filter(self.model)

    # -- the per-sample recursion, shared by run() and step() ------------------------------
    def reset(self, *, speed: float = 0.0, speed_std: float | None = None,
              contact_speeds: Any = None) -> None:
        owner = f"{type(self).__name__}.reset"
        speed = as_float(speed, "speed", owner)
        std = 0.05 if speed_std is None else as_float(speed_std, "speed_std", owner, low=0.0, low_open=True)
        if contact_speeds is not None:
            contact_speeds = as_float_array(contact_speeds, "contact_speeds", owner)
            if contact_speeds.shape != (self.model.n,):
                raise ParameterError(parameter_message(
                    "contact_speeds", owner, f"have shape ({self.model.n},)",
                    f"an array of shape {contact_speeds.shape}"))
        self._speed0, self._std0 = speed, std
        self._initial = contact_speeds
        self.kf = self._build()
        self._pending: tuple[np.ndarray, float, bool, Any, float] | None = None  # (track, var_v, steady, bounds, F)
        self._tracker = ContactSpeedTracker(self.model, contact_speeds)
        self._observed: tuple[float, np.ndarray] | None = None    # (t, wheels) awaiting a command
        self._last_command: np.ndarray | None = None
        self._last_force = 0.0
        self._t_prev = math.nan
        self._count_prev: int | None = None
        self._repeats = 0
        self._on_set = False
        self._edge, self._edge_var = None, math.inf
        self._increment = self.model.increment
        self._layer = HoldLayer(self.model)
        self._lines = self._layer.lines if self.exact_holds else None
        self._anchor = (math.nan, 0)          # (time, central count) of the last sample
        self.holding = False                   # the last step was an exact hold
        self.hold_failed = False               # the last step's reading left every line of a hold
        self._stuck_settled = False            # the body reached the set on settled contacts
        self._hold_force = 0.0                 # the last period's outside force (a change ends a hold), N
        self.last_input = (0.0, 0.0)
        self.last_F = self._F
        self.last_Q = np.zeros((2, 2))
        self.last_nis = np.nan
        self.last_cell = 1.0                   # probability of the last reading's count cell
        self._gains = None if self._consider is None else np.zeros((2, self.model.n + 1))
        self.considered = None                 # (what the considered errors add: set below)
        self._restart_consider()

    def _start(self, z: float) -> None:
        kf = self.kf
        kf.x = np.array([[z], [self._speed0]])
        kf.P = (self.initial_covariance.copy() if self.initial_covariance is not None
                else np.diag([quantization_variance(self._q), self._std0**2]))

    def _advance(self, z: float, R: float, track: np.ndarray | None, var_v: float, steady: bool,
                 bounds: Any = None, force: float = 0.0, count: int = 0, t: float = 0.0,
                 wheels: Any = None) -> None:
        """Predict over the last period with the input computed from its start (contact
        speeds and the outside force ``force``, N), then update with the sample (central
        ``count`` read at ``t``, s; ``wheels`` the wheel counts)."""
        kf = self.kf
        self.hold_failed = False
        anchor, self._anchor = self._anchor, (t, count)
        lines = self._lines if wheels is not None else None
        if lines is not None:
            self._layer.wheels(t, wheels, track, steady)
        self.last_cell = 1.0
        if track is None:
            self._start(z)
            self.last_nis = np.nan
            self._restart_consider()
            if self._other is not None:
                self._other.reset()
            return
        if force != self._hold_force:
            # A new outside force: the body may creep or slide off; the flow decides until
            # it sees the body reach the set again.
            self._hold_force = force
            self.holding = self._stuck_settled = False
            self._layer.stop()
        x0, P0, was_holding = kf.x, kf.P, self.holding
        if (lines is not None and steady and lines.active
                and self._held(t, count, anchor, track[0], var_v)):
            self._restart_consider()      # (the exact posterior of the counts: no model in it)
            # (A hold that goes on rides the same contact: an alternative the counts rejected
            # there stays rejected.)
            if self._other is not None and not (was_holding and self.holding and not self._other.weighed):
                h = self._h
                self._weigh(t, z, x0.item(0) + h * x0.item(1),
                            P0.item(0) + 2.0 * h * P0.item(1) + h * h * P0.item(3) + R, track, var_v, steady, force)
            return
        self.holding = False
        self._layer.stop()
        x = kf.x
        V = x.item(1)
        model = self.model
        kf.R[0, 0] = R
        if (self._on_set and steady and model.damping == 0.0 and (V < bounds[2] or V > bounds[3])
                and bounds[2] - (w := 2.0 * math.sqrt(kf.P.item(3) + var_v)) <= V <= bounds[3] + w):
            # Held on the set by the previous step, which a measurement update moved off it
            # by less than 2 sigma (sigma^2 = P_VV + var_v): with the contacts steady the body
            # has not left (stiction), so V is a second estimate of the near edge's speed.
            # Keep it (V+ = V, the settled contacts' noise); the contact estimate of the edge
            # is fused as a measurement of V below (once, then its information increments).
            dx, dV, Q, slopes, arrival, on_set = 0.0, 0.0, model._held_noise, None, None, True
            gains = None                  # (held: the stiction absorbs a force error)
        else:
            gains = self._gains
            dx, dV, Q, slopes, arrival, on_set = self._increment(V, track, math.sqrt(var_v), math.sqrt(kf.P.item(3)),
                                                             steady, bounds, force, gains)
        self._on_set = on_set
        # Stuck on a settled contact: the body reached the set once the wheels' lines were
        # exact (the motors' transient below the lines' resolution: it then sticks on the
        # edge contact); one that met an edge contact still settling towards it may have
        # stopped short, inside a zero-force band, and coast there.
        if arrival is not None or not (on_set and steady):
            self._stuck_settled = arrival is not None and steady and lines is not None and lines.active
        # On an edge of the set (arrived there, or held within 2 sigma of it from outside)
        # the body moves at that edge contact's speed: as the wheels' window lengthens, its
        # estimate gains information, fused as a measurement of V with the information
        # increment's variance 1 / (1 / var_now - 1 / var_fused) (the longer window holds
        # the shorter one's counts).
        inc = None
        if not (on_set and steady):
            self._edge = None
        elif arrival is not None:
            self._edge, self._edge_var = _side(V + dV, bounds), arrival
        elif self._edge is None:
            if V < bounds[2] or V > bounds[3]:
                self._edge = 2 if V < bounds[2] else 3
                inc = (bounds[self._edge], var_v)
                self._edge_var = var_v
        elif var_v < self._edge_var * (1.0 - 1e-9):
            # (Smaller by more than rounding: a window sliding at full length keeps its
            # variance and brings no new information.)
            inc = (bounds[self._edge], 1.0 / (1.0 / var_v - 1.0 / self._edge_var))
            self._edge_var = var_v
        if slopes is None:
            # Hot path (>= 1000x real time): F x + u = F (x + F^-1 u) with F^-1 u = (dx - h dV,
            # dV), added in place; then filterpy's predict() and update(z) in one kernel call
            # (the same formulas, tested equal to filterpy to rounding) into fresh arrays:
            # filterpy rebinds x and P at every step and callers keep references to the old ones.
            x[0, 0] = x.item(0) + dx - self._h * dV
            x[1, 0] = V + dV
            kf.Q = Q
            self.last_input = (dx, dV)
            self.last_F = self._F
            x_out, P_out, prior = np.empty((2, 1)), np.empty((2, 2)), np.empty(3)
            nis = kernels("core", 40).kalman_step(x, kf.P, self._F, Q, R, z, x_out, P_out, prior)
            kf.x, kf.P = x_out, P_out
            x_pred, S = prior.item(0), prior.item(2) + R
            gain = (P_out.item(0) / R, P_out.item(2) / R)     # (K = P+ H^T R^-1)
            self.last_cell = self._cell_probability(count, prior.item(0), prior.item(2), prior.item(1))
        else:
            # The flow linearized at V (events in the period, or drag): x+ = F x + u with
            # F = [[1, dX+/dV], [0, dV+/dV]] and u what makes F x + u the flow at V.
            JX, J = slopes
            F = np.array([[1.0, JX], [0.0, J]])
            u = ((self._h - JX) * V + dx, (1.0 - J) * V + dV)
            kf.predict(u=np.array([[u[0]], [u[1]]]), B=self._I2, F=F, Q=Q)
            self.last_input = u
            self.last_F = F
            self.last_cell = self._cell_probability(count, kf.x.item(0), kf.P.item(0), kf.x.item(1))
            # z as a float: filterpy's y = z - H x is the same (1, 1) array, and its deepcopy(z)
            # of a float is free (of an array it is not).
            kf.update(z, H=self._H)
            nis = kf.y.item() ** 2 * kf.SI.item()
            gain = (kf.K.item(0), kf.K.item(1))
            x_pred, S = z - kf.y.item(), kf.S.item()
        self.last_Q = Q
        self.last_nis = nis
        consider = self._consider
        if consider is not None:
            consider.step(self.last_F, gains, gain)
        if inc is not None:
            kf.update(inc[0], R=inc[1], H=self._H_speed)
            if consider is not None:
                consider.measured_speed(kf.K[:, 0])
        if consider is not None:
            self.considered = consider.covariance
            self._weigh(t, z, x_pred, S, track, var_v, steady, force)

    def _restart_consider(self) -> None:
        """The state owes nothing to the model: the considered errors' sensitivity restarts."""
        if self._consider is not None and self.considered is not _NOTHING:
            self._consider.reset()
        self.considered = _NOTHING

    def _weigh(self, t: float, z: float, x_pred: float, S: float, track: np.ndarray, var_v: float,
               steady: bool, force: float) -> None:
        """The other contact the body may ride (``consider``, :class:`OtherContact`): on the
        settled contact nearest the estimate, within three standard deviations of it and of
        that contact's estimate, where the filter has the body on the set; added to
        :attr:`considered`."""
        x = self.kf.x
        V, k = x.item(1), None
        if steady and (self._on_set or self.holding):
            speeds = track[0]
            j = int(np.abs(speeds - V).argmin())
            if abs(float(speeds[j]) - V) <= 3.0 * math.sqrt(self.kf.P.item(3) + var_v):
                k = j
        other = self._other
        other.step(t, self._h, k, track[0], force, x.item(0), V, z, x_pred, S)
        if k is not None and other.weighed:
            self.considered = self.considered + other.covariance

    def _cell_probability(self, count: int, mean: float, variance: float, speed: float) -> float:
        """The probability of the reading's count cell ``[c q, (c + 1) q)`` under the predicted
        position ``N(mean, variance + declared read noise and jitter)`` (m, m^2; ``speed``
        for the jitter, m/s): the quantized likelihood, where the Gaussian NIS (which
        spreads the cell into ``q^2 / 12`` of noise) understates how far off a reading is."""
        q = self._q
        sensors = self.model.sensors
        var = variance + sensors.read_noise_variance * q * q + (speed * sensors.jitter) ** 2
        if var <= 0.0:
            return 1.0 if count * q <= mean < (count + 1) * q else 0.0
        scale = 1.0 / math.sqrt(2.0 * var)
        lo, hi = (count * q - mean) * scale, ((count + 1) * q - mean) * scale
        # Phi(b) - Phi(a) from the tail on the mean's far side (no cancellation there).
        if lo > 0.0:
            return 0.5 * (math.erfc(lo) - math.erfc(hi))
        if hi < 0.0:
            return 0.5 * (math.erfc(-hi) - math.erfc(-lo))
        return 1.0 - 0.5 * (math.erfc(-lo) + math.erfc(hi))

    def _held(self, t: float, count: int, anchor: tuple[float, int], speeds: np.ndarray,
              var_v: float) -> bool:
        """The exact-hold layer (:class:`toolkit.estimation._hold.HoldLayer`) where the body
        rides a settled contact: continue the hold, or start one where the Gaussian filter has
        the body on the equilibrium set since it reached the set after the wheels' lines
        became exact (and the outside force has not changed since), and set the state to the
        posterior's moments. A failed hold resets the state to what the reading and the
        one-period difference of the readings know (the transition ``F = 0``: the smoother
        does not carry the failed hold's information back) and hands the body back to the
        Gaussian steps until they see it reach the set again. False when there is no hold
        (the Gaussian step follows)."""
        kf = self.kf
        x, P = kf.x, kf.P
        out = self._layer.step(t, count, anchor, speeds, var_v, (x.item(0), x.item(1)), P,
                               self._on_set and self._stuck_settled)
        if out is None:
            return False
        self.last_nis = out.nis
        kf.x = out.state[:, None].copy()
        kf.P = out.covariance
        if out.failed:
            self.hold_failed = True
            self.holding = False
            self._on_set = self._stuck_settled = False
            self.last_input = (float(out.state[0]), float(out.state[1]))
            self.last_F = self._F_reset
            self.last_Q = out.covariance
            return True
        # The hold's step as the smoother sees it: x+ = F x (Q = 0: the line is exact).
        self.last_input = (0.0, 0.0)
        self.last_F = self._F
        self.last_Q = self._Q0
        self._on_set = True
        self.holding = True
        return True

    def observe(self, sample: EncoderSample) -> tuple[float, float]:
        """Take one sample's counts (in order); return ``(speed, variance)`` at its time.

        The prediction up to this sample uses the command and force given to
        :meth:`commanded` after the previous sample (the previous ones again if none were
        given); this sample's ``command`` and ``force`` are not read.
        """
        if self._observed is not None:
            self.commanded(self._last_command, self._last_force)
        if self._count_prev is not None and lost_between(sample.time - self._t_prev, self._h):
            refuse_gaps(np.array((self._t_prev, sample.time)), self._h, f"{type(self).__name__}.observe")
        count = sample.central_count
        t = sample.time
        q = self._q
        fd = 0.0
        if self._count_prev is not None:
            fd = (count - self._count_prev) * q / (t - self._t_prev)
            self._repeats = self._repeats + 1 if count == self._count_prev else 0
        self._count_prev, self._t_prev = count, t
        R = _measurement_variance_one(self._repeats, fd, q, self.model.sensors)
        z = cell_centre(count, q)
        pending = self._pending
        self._advance(z, R, *(pending if pending is not None else (None, 0.0, True, None, 0.0)),
                      count, t, sample.wheel_counts)
        self._observed = (t, sample.wheel_counts)
        x, P = self.kf.x, self.kf.P
        return x.item(1), P.item(3)

    def commanded(self, command: Any, force: float = 0.0) -> None:
        """The contact speeds commanded at the last observed sample (m/s, shape (n,)) and
        the outside force applied with them (N, held to the next sample): they drive the
        prediction to the next sample."""
        (t, wheels), force = self._take_observed(force)
        self._last_command, self._last_force = command, force
        speeds, var, steady, track = self._tracker.push(t, wheels, command)
        self._pending = (track, var, steady, self.model.bounds_row(track, force), force)

    # -- offline --------------------------------------------------------------------------
    def filter(self, record: EncoderRecord, *, speed: float = 0.0, speed_std: float | None = None
               ) -> FilterPass:
        """Run over a record (initial speed ``speed``, m/s, of std ``speed_std``): the
        filter's pass, states and covariances with what made them."""
        self._check_record(record)
        started = budget_clock()
        model = self.model
        self.reset(speed=speed, speed_std=speed_std, contact_speeds=record.initial_commands)
        K = record.n_samples
        counts = record.central_counts
        speeds, var_v, steady = contact_speed_estimates(record.wheel_counts, record.commands, record.times,
                                                        model, initial=record.initial_commands)
        track = model.period_track(speeds, record.commands, steady)
        force = np.zeros(K) if record.force is None else record.force
        bounds = model.bounds(track, force).tolist()
        force_l = force.tolist()
        q = self._q
        z = cell_centre(counts, q)
        # Jitter term: speed from the counts over the last period (known before the update).
        fd = np.zeros(K)
        fd[1:] = np.diff(counts) * q / np.diff(record.times)
        R = measurement_variance(counts, fd, model)
        kf = self.kf
        steady_l = steady.tolist()
        var_l = var_v.tolist()
        z_l, R_l = z.tolist(), R.tolist()
        advance = self._advance
        # Per sample only filterpy's predict/update and the input: results go to lists of
        # floats and references (filterpy rebinds P at every step, never writes into it).
        counts_l, times_l = counts.tolist(), record.times.tolist()
        wheels = record.wheel_counts
        advance(z_l[0], R_l[0], None, 0.0, True, None, 0.0, counts_l[0], times_l[0], wheels[0])
        xs = [(kf.x.item(0), kf.x.item(1))]
        Ps = [kf.P]
        inputs = [(0.0, 0.0)]
        Fs = [self._F]
        Qs = [np.zeros((2, 2))]
        nis = [math.nan]
        failed = [False]
        cells = [1.0]
        considered = [self.considered]
        for k in range(1, K):
            advance(z_l[k], R_l[k], track[k - 1], var_l[k - 1], steady_l[k - 1], bounds[k - 1], force_l[k - 1],
                    counts_l[k], times_l[k], wheels[k])
            failed.append(self.hold_failed)
            cells.append(self.last_cell)
            x = kf.x
            xs.append((x.item(0), x.item(1)))
            Ps.append(kf.P)
            inputs.append(self.last_input)
            Fs.append(self.last_F)
            Qs.append(self.last_Q)
            nis.append(self.last_nis)
            considered.append(self.considered)
        self._pending = (track[-1], float(var_v[-1]), bool(steady[-1]), bounds[-1], force_l[-1])
        return FilterPass(np.array(xs), np.array(Ps), np.array(inputs, dtype=float), np.array(Fs),
                          np.array(Qs), np.array(nis), np.array(failed), np.array(cells),
                          budget_clock() - started, np.array(considered))

    def run(self, record: EncoderRecord, *, speed: float = 0.0,
            speed_std: float | None = None) -> EstimationResult:
        self._check_record(record)
        refuse_gaps(record.times, self._h, f"{type(self).__name__}.run")
        run = self.filter(record, speed=speed, speed_std=speed_std)
        X, P = run.states, run.covariances
        return score(record, self.name, X[:, 1], P[:, 1, 1], run.wall_time, position=X[:, 0],
                     covariance=P, nis=run.nis[1:])


def steady_state_gain(model: EstimatorModel, accel_std: float, *, tol: float = 1e-15,
                      max_steps: int = 100_000) -> tuple[np.ndarray, np.ndarray]:
    """Steady-state gain of the filter with constant noise, by iterating filterpy.

    Parameters
    ----------
    model : EstimatorModel
    accel_std : float, m/s^2
        Std of the piecewise-constant acceleration noise (``Q = accel_std^2 g g^T``).

    Returns
    -------
    gain : ndarray of shape (2, 1)
        ``K = P C^T (C P C^T + R)^-1`` with the converged prior ``P``.
    prior : ndarray of shape (2, 2)
        The converged prior covariance (the Riccati equation's fixed point).
    """
    accel_std = as_float(accel_std, "accel_std", "steady_state_gain", low=0.0, low_open=True)
    kf = _make_filter(model)
    h, q = model.sensors.period, model.sensors.central.distance_per_count
    g = np.array([[0.5 * h * h], [h]])
    kf.Q = accel_std**2 * (g @ g.T)
    kf.R = np.array([[quantization_variance(q)]])
    kf.P = np.diag([q * q, 1.0])
    previous = kf.P.copy()
    for _ in range(max_steps):
        kf.predict()
        prior = kf.P.copy()
        kf.update(np.array([[0.0]]))
        if np.allclose(prior, previous, rtol=tol, atol=0.0):
            break
        previous = prior
    return kf.K.copy(), prior
