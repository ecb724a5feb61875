"""The default estimator ``kalman``.

:class:`KalmanEstimator` (``kalman``) is the nominal filter (:mod:`toolkit.estimation.nominal`)
while a consistency monitor finds the data in agreement with the scene, reported with what
the prior's unknown forces add (:mod:`toolkit.estimation.consider`), and from the first
sample where they are not the adaptive filter (:mod:`toolkit.estimation.adaptive`), replayed
from the start. Derivations: docs/estimation.md.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np

from .._compiled import budget_clock
from ..errors import as_int
from ..model.sensors import EncoderRecord, EncoderSample
from ..model.truth import ModelPrior
from ._base import EstimationResult, Estimator, check_covariance, lost_between, lost_samples, score, warm_record
from ._input import EstimatorModel
from .adaptive import ADAPTING, FALLBACK, NOMINAL, AdaptiveKalman, _checked
from .missed_counts import count_offset, told_missed_rate
from .monitor import ConsistencyMonitor
from .nominal import NominalKalman

__all__ = ["KalmanEstimator"]


#: The nominal filter fails a sample whose count cell has less than this probability under
#: its prediction (the quantized likelihood; over 40 ideal records its smallest value was
#: 0.04, under a 20 % friction spread it falls below 1e-6 from the third sample on).
CELL_ALARM = 1e-6


#: Why the default leaves the nominal filter at a sample after lost ones: the nominal filter
#: predicts one period per sample, the adaptive one coasts over the lost periods.
_LOST = "{} sample(s) lost before this one"


def _failure(hold_failed: bool, cell: float) -> str:
    """The nominal filter's hard failures at one sample, as the monitor's reason."""
    if hold_failed:
        return "an exact hold failed"
    if cell < CELL_ALARM:
        return f"the count's cell has probability {cell:.2g} under the nominal prediction"
    return ""


class KalmanEstimator(Estimator):
    """The default estimator (``kalman``): the nominal filter while it is consistent with the
    data, the adaptive filter from the first sample where it is not (the module; docs/estimation.md).

    Parameters
    ----------
    model : EstimatorModel
        The nominal scene.
    prior : ModelPrior, optional
        What is known beyond the scene (default ``ModelPrior()``): the adaptive filter's
        prior, and the unknown forces the nominal filter's estimates are reported with
        (:class:`NominalKalman`'s ``consider``).
    initial_covariance : array_like of shape (2, 2), optional
        The nominal filter's prior covariance of ``(X, V)`` (:class:`NominalKalman`).
    exact_holds : bool
        The nominal filter's exact holds (default True).
    window : int
        Samples of the monitor's windowed NIS (``>= 1``).
    false_alarm : float
        The monitor's false-alarm level per window, in ``(0, 1)`` (default 1e-6: a threshold
        of 46.9 on ten NIS; the nominal filter's windows stay below 35 over worlds that match
        it, declared read noise and jitter included, and reach 10^2-10^4 under the issue's
        mismatches, where exact holds also fail).

    Attributes
    ----------
    verdicts : list of int
        Per sample: :data:`NOMINAL`, :data:`ADAPTING` or :data:`FALLBACK`.
    tripped : tuple of (float, str) or None
        When (s) and why the nominal model was left.
    adaptive : AdaptiveKalman or None
        The adaptive filter once it runs.
    """

    name = "kalman"
    KERNELS = ("core", "lines", "window", "imm")

    def __init__(self, model: EstimatorModel, prior: ModelPrior | None = None, *,
                 initial_covariance: Any = None, exact_holds: bool = True, window: int = 10,
                 false_alarm: float = 1e-6) -> None:
        owner = type(self).__name__
        self.model, self.prior = _checked(model, prior, owner)
        if initial_covariance is not None:
            initial_covariance = check_covariance(initial_covariance, "initial_covariance", owner, 2)
        self.nominal = NominalKalman(model, initial_covariance=initial_covariance, exact_holds=exact_holds,
                                     consider=self.prior)
        self.monitor = ConsistencyMonitor(as_int(window, "window", owner, low=1), false_alarm)
        self.reset()

    def reset(self, *, speed: float = 0.0, speed_std: float | None = None,
              contact_speeds: Any = None) -> None:
        self._reset_args = dict(speed=speed, speed_std=speed_std, contact_speeds=contact_speeds)
        self.nominal.reset(**self._reset_args)
        self.monitor.reset()
        self.adaptive: AdaptiveKalman | None = None
        self._history: list[tuple[EncoderSample, Any, float]] = []
        self._waiting: EncoderSample | None = None
        self._last_command: Any = None
        self._last_force = 0.0
        self.verdicts: list[int] = []
        self.tripped: tuple[float, str] | None = None
        self._before: float | None = None          # the last sample's time, s

    def warm_up(self, record: Any = None) -> float:
        """Compile (or load from numba's cache) every kernel the nominal and the adaptive
        filters run, by running both over ``record`` (default: a short record of the nominal
        model, :func:`~toolkit.estimation._base.warm_record`; the estimator is reset after),
        so that a timed run pays no one-time compilation; returns the time it took (s)."""
        from .._compiled import load

        started = budget_clock()
        for name in self.KERNELS:
            load(name)
        args = self._reset_args
        record = warm_record(self.model.sensors, self.model) if record is None else record
        self.run(record)
        self._adaptive().run(record)
        self.reset(**args)
        return budget_clock() - started

    def _adaptive(self) -> AdaptiveKalman:
        return AdaptiveKalman(self.model, self.prior)

    def _switch(self, sample: EncoderSample, reason: str) -> tuple[float, float]:
        """The nominal model failed at ``sample``: the adaptive filter from the start of the
        run, replayed over the samples kept (it then stands where it would had it run all
        along)."""
        self.tripped = (sample.time, reason)
        adaptive = self.adaptive = self._adaptive()
        adaptive.prime([past for past, _, _ in self._history] + [sample],
                       [command for _, command, _ in self._history] + [sample.command],
                       self._reset_args["contact_speeds"])
        adaptive.reset(**self._reset_args)
        for past, command, force in self._history:
            adaptive.observe(past)
            adaptive.commanded(command, force)
        self._history = []
        return adaptive.observe(sample)

    def observe(self, sample: EncoderSample) -> tuple[float, float]:
        if self._waiting is not None:             # no command given after the last sample
            self.commanded(self._last_command, self._last_force)
        self._waiting = sample
        if self.adaptive is not None:
            out = self.adaptive.observe(sample)
            self.verdicts.append(FALLBACK if self.adaptive.fallback else ADAPTING)
            return out
        before, self._before = self._before, sample.time
        if before is not None and (lost := int(lost_between(sample.time - before, self.model.sensors.period))):
            out = self._switch(sample, _LOST.format(lost))
            self.verdicts.append(FALLBACK if self.adaptive.fallback else ADAPTING)
            return out
        out = self.nominal.observe(sample)
        verdict = self.monitor.push(self.nominal.last_nis,
                                    _failure(self.nominal.hold_failed, self.nominal.last_cell))
        if verdict.passes:
            self.verdicts.append(NOMINAL)
            return out[0], out[1] + self.nominal.considered.item(3)
        out = self._switch(sample, verdict.reason)
        self.verdicts.append(FALLBACK if self.adaptive.fallback else ADAPTING)
        return out

    def commanded(self, command: Any, force: float = 0.0) -> None:
        if self._waiting is None:
            raise RuntimeError("commanded() follows observe(): once per observed sample.")
        sample, self._waiting = self._waiting, None
        self._last_command, self._last_force = command, force
        if self.adaptive is not None:
            self.adaptive.commanded(command, force)
        else:
            self.nominal.commanded(command, force)
            self._history.append((sample, command, force))

    def run(self, record: EncoderRecord, *, speed: float = 0.0,
            speed_std: float | None = None) -> EstimationResult:
        """Offline: the nominal filter's pass (its vectorized wheel estimates), the monitor
        over its NIS and hold failures, and from the first failing sample on the adaptive
        filter's pass over the record (what stepping gives)."""
        self._check_record(record)
        started = budget_clock()
        self.reset(speed=speed, speed_std=speed_std, contact_speeds=record.initial_commands)
        nominal = self.nominal_pass = self.nominal.filter(record, speed=speed, speed_std=speed_std)
        # (Reported with what the prior's unknown forces add: NominalKalman's consider.)
        X, P, nis = nominal.states, nominal.covariances + nominal.considered, nominal.nis
        failures = nominal.hold_failures.tolist()
        cells = nominal.cell_probabilities.tolist()
        K = record.n_samples
        trip = None
        lost = lost_samples(record.times, self.model.sensors.period)
        gaps = np.flatnonzero(lost) + 1
        for k in range(K if gaps.size == 0 else int(gaps[0])):
            verdict = self.monitor.push(nis[k], _failure(failures[k], cells[k]))
            if not verdict.passes:
                trip = k
                self.tripped = (float(record.times[k]), verdict.reason)
                break
        if trip is None and gaps.size:
            trip = int(gaps[0])
            self.tripped = (float(record.times[trip]), _LOST.format(int(lost[trip - 1])))
        verdicts = np.full(K, NOMINAL, dtype=np.int64)
        if trip is not None:
            adaptive = self.adaptive = self._adaptive()
            adaptive.prime([record.sample(k) for k in range(trip + 1)], list(record.commands[:trip + 1]),
                           record.initial_commands)
            adaptive.reset(speed=speed, speed_std=speed_std, contact_speeds=record.initial_commands)
            X, P = X.copy(), P.copy()
            for k in range(K):
                adaptive.step(record.sample(k))
                if k >= trip:
                    X[k], P[k] = adaptive.out_x[:2], adaptive.out_P[:2, :2]
                    verdicts[k] = FALLBACK if adaptive.fallback else ADAPTING
        self.verdicts = verdicts.tolist()
        p, var, seen = told_missed_rate(self.model, self.prior), 0.0, None
        if self.adaptive is not None:
            # The adaptive filter ran from the start: where its holds would have repaired a
            # lost central count; not told, the rate it identified by each sample. While the
            # nominal model holds throughout, nothing contradicted it (not told: no offset).
            rate, rate_var, seen = np.array(self.adaptive.missed_history).T
            seen = seen > 0.0
            if p == 0.0:
                p, var = rate, rate_var
        if np.any(p > 0.0):
            X = X.copy()
            X[:, 0], P = count_offset(record.times, X[:, 0], P, X[:, 1], p,
                                      self.model.sensors.central.distance_per_count, var, seen)
        wall = budget_clock() - started
        result = score(record, self.name, X[:, 1], P[:, 1, 1], wall, position=X[:, 0], covariance=P,
                       nis=nis[1:])
        rate = (float(np.atleast_1d(p)[-1]), math.sqrt(float(np.atleast_1d(var)[-1])))
        return dataclasses.replace(result, missed_count_prob=rate[0], missed_count_std=rate[1])
