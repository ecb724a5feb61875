"""The estimator interface, its result and the consistency statistics (private base).

Every estimator maps an :class:`~toolkit.model.sensors.EncoderRecord` to body-speed estimates
with their variances, offline (:meth:`Estimator.run`) or sample by sample in a loop
(:meth:`Estimator.reset`, :meth:`Estimator.observe`, :meth:`Estimator.commanded`), as a 50 Hz controller calls it.
The known inputs of a sample period are the commanded contact speeds and the outside force
a controller applies (``commanded(command, force)``; offline the record's ``commands`` and
``force``). Scores
against the truth (RMS and max speed error, NEES, NIS) are computed when the record carries
the truth; estimators never read it.
"""

from __future__ import annotations

import abc
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from .._compiled import budget_clock
from ..errors import as_float, as_float_array
from ..errors import ParameterError, ParameterTypeError, parameter_message
from ..model.sensors import EncoderRecord, EncoderSample

__all__ = ["Estimator", "EstimationResult", "chi2_band", "check_covariance", "PHASES", "phase_masks",
           "nees_band", "GROSS_NEES"]

#: The phases of a record scored separately (:func:`phase_masks`).
PHASES = ("startup", "cruise", "brake", "braked")
#: Length of the startup and brake phases after their command, s (:func:`phase_masks`).
SETTLE_TIME = 1.0
#: A NEES above this is gross overconfidence (:attr:`EstimationResult.nees_over_100`): a
#: consistent 2-dimensional NEES exceeds it with probability ``exp(-50)``.
GROSS_NEES = 100.0


def chi2_band(samples: int, dim: int, level: float = 0.95) -> tuple[float, float]:
    """Two-sided band of the mean of ``samples`` independent ``dim``-dimensional NEES (or NIS).

    The sum of ``K`` such statistics is chi-square with ``K dim`` degrees of freedom, so the
    mean lies in ``chi2.ppf([(1 - level) / 2, (1 + level) / 2], K dim) / K`` with
    probability ``level`` for a consistent filter.
    """
    from scipy.stats import chi2

    tail = 0.5 * (1.0 - level)
    lo, hi = chi2.ppf([tail, 1.0 - tail], samples * dim) / samples
    return float(lo), float(hi)


def nees_band(dim: int = 2, level: float = 0.95) -> tuple[float, float]:
    """Two-sided ``level`` interval of one ``dim``-dimensional NEES: ``chi2(dim)`` quantiles."""
    from scipy.stats import chi2

    tail = 0.5 * (1.0 - level)
    lo, hi = chi2.ppf([tail, 1.0 - tail], dim)
    return float(lo), float(hi)


def phase_masks(record: EncoderRecord, settle: float = SETTLE_TIME) -> dict[str, np.ndarray | None]:
    """Which samples of ``record`` belong to each phase of :data:`PHASES`.

    The rule, from the commands alone: the *brake* is the largest command change after the
    first sample (the largest ``max_i |u_i(t_k) - u_i(t_k-1)|``; the first such row when
    several tie); *startup* is the first ``settle`` seconds of the record, *cruise* from
    there to the brake, *brake* the ``settle`` seconds from the brake's sample, *braked* the
    rest. ``settle`` (default 1 s) covers the carousel's arrival on its contacts after a
    change (0.1-0.15 s of sliding) and the creep across a zero-force band of unequal wheels
    (up to about 0.5 s with a 5 % spread). A record whose commands never change after the
    first sample has no brake: its *brake* and *braked* are ``None`` (so is *cruise* when
    the record is shorter than ``settle``).

    Returns
    -------
    dict of str to ndarray of shape (k,), bool, or None
    """
    t = record.times
    start = t[0]
    jumps = np.zeros(t.size)
    if t.size > 1:
        jumps[1:] = np.max(np.abs(np.diff(record.commands, axis=0)), axis=1)
    brake = int(np.argmax(jumps)) if jumps.max(initial=0.0) > 0.0 else None
    startup = t < start + settle
    if brake is None or t[brake] < start + settle:
        # No brake, or one inside the startup: the startup then ends at it.
        if brake is not None:
            startup = t < t[brake]
        end = t.size if brake is None else brake
        cruise = ~startup & (np.arange(t.size) < end)
    else:
        cruise = ~startup & (t < t[brake])
    masks: dict[str, np.ndarray | None] = {"startup": startup, "cruise": cruise, "brake": None, "braked": None}
    if brake is not None:
        masks["brake"] = (t >= t[brake]) & (t < t[brake] + settle)
        masks["braked"] = t >= t[brake] + settle
    return {name: (mask if mask is not None and mask.any() else None) for name, mask in masks.items()}


def lost_between(elapsed: Any, period: float) -> Any:
    """The samples lost in ``elapsed`` seconds between two samples on a grid of ``period``
    (s): the whole periods less one (0 on the grid, and for a stamp off it by less than half
    a period); a float for a float (one sample's check, no array built), else an array."""
    return np.maximum(np.rint(elapsed / period) - 1.0, 0.0)


def lost_samples(times: Any, period: float) -> np.ndarray:
    """:func:`lost_between` each pair of consecutive sample ``times`` (s), shape
    ``(len(times) - 1,)``."""
    return lost_between(np.diff(times), period).astype(np.int64)


def refuse_gaps(times: np.ndarray, period: float, owner: str, first: int = 0) -> None:
    """Refuse samples that are not one ``period`` (s) apart at ``times`` (s), for a filter
    that predicts one period per sample: the error names the first sample after lost ones
    (its index counted from ``first``) and the filter that predicts over them."""
    lost = lost_samples(times, period)
    gaps = np.flatnonzero(lost)
    if gaps.size:
        k = int(gaps[0]) + 1
        raise ParameterError(parameter_message(
            "record", owner, "have its samples one period apart (this filter predicts one period per sample; "
            "'kalman' predicts over lost samples)",
            f"sample {first + k} at t = {times[k]:g} s after {int(lost[k - 1])} lost"))


def check_covariance(value: Any, name: str, owner: str, dim: int) -> np.ndarray:
    """A ``dim x dim`` symmetric positive definite matrix, or the template error naming it."""
    array = as_float_array(value, name, owner, ndim=2)
    if array.shape != (dim, dim):
        raise ParameterError(parameter_message(name, owner, f"have shape ({dim}, {dim})",
                                               f"an array of shape {array.shape}"))
    scale = float(np.max(np.abs(array)))
    if not np.allclose(array, array.T, rtol=1e-12, atol=1e-14 * scale):
        raise ParameterError(parameter_message(name, owner, "be symmetric", array.tolist()))
    try:
        np.linalg.cholesky(array)
    except np.linalg.LinAlgError:
        raise ParameterError(parameter_message(name, owner, "be positive definite",
                                               array.tolist())) from None
    return array


@dataclass(frozen=True, eq=False)
class EstimationResult:
    """Body-speed estimates over a record and, when the record has the truth, their scores.

    Attributes
    ----------
    method : str
    times : ndarray of shape (k,), s
    speed : ndarray of shape (k,), m/s
    variance : ndarray of shape (k,), (m/s)^2
        The estimator's own variance of ``speed``.
    wall_time : float, s
        Time :meth:`Estimator.run` took (estimation only, scoring excluded).
    position : ndarray of shape (k,), m, or None
        Position estimates (state-space estimators).
    covariance : ndarray of shape (k, d, d) or None
        State covariances (state-space estimators).
    rms_error, max_error : float or None, m/s
        RMS and largest ``|speed - truth|``.
    nees, nis : ndarray of shape (k,) or None
        Normalized estimation error squared of the state ``(position, speed)`` against the
        truth, and normalized innovation squared of the central-encoder measurement.
    nees_mean, nis_mean : float or None
    nees_band, nis_band : tuple of float or None
        The 95 % chi-square bands of those means (:func:`chi2_band`).
    rms_phases : dict of str to float or None, m/s
        RMS error in each phase of :func:`phase_masks` (``None`` for a phase the record
        lacks); ``None`` without the truth.
    nees_in_band : float or None
        Fraction of the samples whose NEES lies in the two-sided 95 % interval of one
        chi-square(2) (``nees_band``); ``None`` without a covariance or the truth.
    nees_over_100 : float or None
        Fraction of the samples whose NEES exceeds ``GROSS_NEES`` (100): gross
        overconfidence, which the in-band share hides; ``None`` as ``nees_in_band``.
    nees_max : float or None
        The largest NEES of the record; ``None`` as ``nees_in_band``.
    missed_count_prob, missed_count_std : float or None
        The encoders' missed-count rate (per count transition) the position was reported
        under and its std at the record's end: the told rate (std 0) or the identified one
        (``kalman``: docs/physics.md section 10); ``None`` for estimators that do not use it.
    """

    method: str
    times: np.ndarray
    speed: np.ndarray
    variance: np.ndarray
    wall_time: float
    position: np.ndarray | None = None
    covariance: np.ndarray | None = None
    rms_error: float | None = None
    max_error: float | None = None
    nees: np.ndarray | None = None
    nis: np.ndarray | None = None
    nees_mean: float | None = None
    nis_mean: float | None = None
    nees_band: tuple[float, float] | None = None
    nis_band: tuple[float, float] | None = None
    rms_phases: dict[str, float | None] | None = None
    nees_in_band: float | None = None
    nees_over_100: float | None = None
    nees_max: float | None = None
    missed_count_prob: float | None = None
    missed_count_std: float | None = None

    @property
    def real_time_ratio(self) -> float:
        """Record duration over wall time: how many times faster than real time."""
        span = float(self.times[-1] - self.times[0]) if self.times.size > 1 else 0.0
        return span / self.wall_time if self.wall_time > 0 else math.inf

    @property
    def nees_consistent(self) -> bool | None:
        """True when the mean NEES lies in its 95 % band (None without the truth)."""
        if self.nees_mean is None or self.nees_band is None:
            return None
        return self.nees_band[0] <= self.nees_mean <= self.nees_band[1]

    def to_dict(self) -> dict[str, Any]:
        """A JSON-able summary (scalars only)."""
        return {"method": self.method, "samples": int(self.times.size), "wall_time": self.wall_time,
                "real_time_ratio": self.real_time_ratio, "rms_error": self.rms_error,
                "max_error": self.max_error, "nees_mean": self.nees_mean, "nees_band": self.nees_band,
                "nis_mean": self.nis_mean, "nis_band": self.nis_band,
                "rms_phases": None if self.rms_phases is None else dict(self.rms_phases),
                "nees_in_band": self.nees_in_band, "nees_over_100": self.nees_over_100,
                "nees_max": self.nees_max}


def score(record: EncoderRecord, method: str, speed: np.ndarray, variance: np.ndarray,
          wall_time: float, *, position: np.ndarray | None = None,
          covariance: np.ndarray | None = None, nis: np.ndarray | None = None) -> EstimationResult:
    """Build the result and score it against the record's truth when there is one."""
    fields: dict[str, Any] = {}
    for name, value in (("speed", speed), ("variance", variance)):
        fields[name] = np.array(value, dtype=float)
        fields[name].setflags(write=False)
    K = record.n_samples
    if record.truth_speed is not None:
        error = fields["speed"] - record.truth_speed
        fields["rms_error"] = float(np.sqrt(np.mean(error**2)))
        fields["max_error"] = float(np.max(np.abs(error)))
        fields["rms_phases"] = {name: None if mask is None else float(np.sqrt(np.mean(error[mask] ** 2)))
                                for name, mask in phase_masks(record).items()}
        if covariance is not None and position is not None and record.truth_position is not None:
            e = np.stack((position - record.truth_position, error), axis=1)
            nees = np.einsum("ki,kij,kj->k", e, np.linalg.inv(covariance[:, :2, :2]), e)
            lo, hi = nees_band(2)
            finite = nees[~np.isnan(nees)]          # an infinite NEES counts: zero variance, an error
            fields.update(nees=nees, nees_mean=float(np.mean(nees)), nees_band=chi2_band(K, 2))
            if finite.size:
                fields.update(nees_in_band=float(np.mean((finite >= lo) & (finite <= hi))),
                              nees_over_100=float(np.mean(finite > GROSS_NEES)), nees_max=float(finite.max()))
    if nis is not None:
        fields.update(nis=np.asarray(nis, dtype=float), nis_mean=float(np.mean(nis)),
                      nis_band=chi2_band(K, 1))
    return EstimationResult(method, record.times, wall_time=wall_time, position=position,
                            covariance=covariance, **fields)


class Estimator(abc.ABC):
    """What every speed estimator offers.

    Offline: :meth:`run` over a whole record. In a loop (a 50 Hz controller):
    :meth:`reset`, then per sample, in order, :meth:`observe` (the estimate at the sample
    time, from its counts) and :meth:`commanded` (the command and outside force then sent,
    for the next prediction); :meth:`step` does both. All paths run the same per-sample code, so they
    give the same estimates.
    """

    #: Short name used in results and benchmarks.
    name: str = "estimator"
    #: The compiled kernel modules (:mod:`toolkit._compiled`) it runs, loaded by ``warm_up``
    #: (the exact flow's ``core`` for those that predict with the plant).
    KERNELS: tuple[str, ...] = ()

    @abc.abstractmethod
    def reset(self, *, speed: float = 0.0, speed_std: float | None = None,
              contact_speeds: Any = None) -> None:
        """Forget the past; the body is believed at ``speed`` (m/s) with std ``speed_std``;
        the motors had settled at ``contact_speeds`` (m/s, shape (n,)) before the first
        sample (``None``: at the first command)."""

    @abc.abstractmethod
    def observe(self, sample: EncoderSample) -> tuple[float, float]:
        """Take one sample's counts (in order); return the speed estimate (m/s) at its time
        and its variance ((m/s)^2). ``sample.command`` is not read: the command sent at this
        sample is given afterwards to :meth:`commanded`."""

    @abc.abstractmethod
    def commanded(self, command: Any, force: float = 0.0) -> None:
        """The contact speeds (m/s, shape (n,)) commanded at the last observed sample and the
        outside force (N) applied to the body with them (a rig's; held, like the command,
        until the next sample); used for the prediction to the next one."""

    def _check_record(self, record: Any) -> None:
        """Refuse anything but an :class:`EncoderRecord` for :meth:`run`."""
        if not isinstance(record, EncoderRecord):
            raise ParameterTypeError(parameter_message("record", f"{type(self).__name__}.run",
                                                       "be an EncoderRecord", record))

    def _take_observed(self, force: Any) -> tuple[Any, float]:
        """For :meth:`commanded`: the pending observation (``self._observed``, cleared) and
        ``force`` checked as a finite float (N)."""
        observed = self._observed
        if observed is None:
            raise RuntimeError("commanded() follows observe(): once per observed sample.")
        if type(force) is not float or not math.isfinite(force):
            force = as_float(force, "force", f"{type(self).__name__}.commanded")
        self._observed = None
        return observed, force

    def warm_up(self, record: EncoderRecord | None = None) -> float:
        """Compile (or load from numba's cache) the kernels this estimator runs, so that a
        timed :meth:`run` that follows pays no one-time cost (the policy of
        :mod:`toolkit._compiled`): :attr:`KERNELS` loaded, then the estimator run once,
        untimed, over ``record`` (default: a short record of its own model,
        ``warm_record``), and reset. Whoever times an estimator calls it first; returns
        the time it took (s)."""
        from .._compiled import load

        started = budget_clock()
        for name in self.KERNELS:
            load(name)
        if record is None:
            model = getattr(self, "model", None)
            sensors = model.sensors if model is not None else getattr(self, "sensors", None)
            record = None if sensors is None else warm_record(sensors, model)
        if record is not None:
            self.run(record)
            self.reset()
        return budget_clock() - started

    def step(self, sample: EncoderSample) -> tuple[float, float]:
        """:meth:`observe` the sample, then :meth:`commanded` with its command and force."""
        out = self.observe(sample)
        self.commanded(sample.command, sample.force)
        return out

    def run(self, record: EncoderRecord, *, speed: float = 0.0,
            speed_std: float | None = None) -> EstimationResult:
        """Estimate the body speed at every sample of ``record`` (reset first)."""
        self._check_record(record)
        started = budget_clock()
        self.reset(speed=speed, speed_std=speed_std, contact_speeds=record.initial_commands)
        out = np.array([self.step(record.sample(k)) for k in range(record.n_samples)])
        wall = budget_clock() - started
        return score(record, self.name, out[:, 0], out[:, 1], wall)


def warm_record(sensors: Any, model: Any = None) -> EncoderRecord:
    """A 1.5 s record for :meth:`Estimator.warm_up`: the model's wheels (``model``, an
    :class:`~toolkit.estimation.EstimatorModel`; without one, 1 N each on a 1 kg body) start
    from rest towards 0.1-0.2 m/s and step to -0.05 to -0.1 m/s at 0.8 s (within the motors'
    speed limits), read through ``sensors`` (noise drawn from seed 0)."""
    from ..model import ContactSet, Motors, PiecewiseConstant, Plant
    from ..model.sensors import record_simulation
    from ..simulation import simulate

    n = sensors.n_wheels
    forces = np.ones(n) if model is None else model.forces
    mass = 1.0 if model is None else model.mass
    limits = (-math.inf, math.inf) if model is None else model.speed_limits
    up = np.clip(np.linspace(0.1, 0.2, n), 0.5 * limits[0], 0.5 * limits[1])
    down = -0.5 * up
    motors = Motors(lag=0.0 if model is None else model.motor_lag, speed_limits=limits)
    plant = Plant(ContactSet(up, forces), mass, damping=0.0 if model is None else model.damping,
                  motors=motors, commands=PiecewiseConstant([0.8], [up, down]))
    return record_simulation(simulate(plant, 1.5), plant, sensors, rng=np.random.default_rng(0),
                             central_position=1e-5)


def positive(value: Any, name: str, owner: str) -> float:
    return as_float(value, name, owner, low=0.0, low_open=True)
