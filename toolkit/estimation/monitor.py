"""Consistency of a filter with its data: the windowed NIS test and covariance matching.

A consistent filter's normalized innovations squared (NIS, ``y^2 / S`` of a scalar
measurement) are independent chi-square(1) draws, so the sum over the last ``W`` samples is
chi-square(``W``). :class:`ConsistencyMonitor` tests that sum against its upper quantile at a
small false-alarm level at every sample, and an estimator acts on the verdict: the default
filter leaves the nominal model for the adaptive one (:mod:`toolkit.estimation.adaptive`),
which in turn widens its measurement noise and falls back towards the window estimate while
its own test fails. :func:`matched_variance` is covariance matching: the measurement noise
that makes the recent innovations consistent (Mehra, IEEE Trans. AC 17(5), 1972: ``R = C_y
- H P H^T`` with ``C_y`` the innovations' sample second moment).
"""

from __future__ import annotations

import functools
import math
from collections import deque
from dataclasses import dataclass

import numpy as np

from ..errors import ParameterError, as_float, as_int, parameter_message

__all__ = ["ConsistencyMonitor", "MonitorVerdict", "matched_variance"]


@dataclass(frozen=True)
class MonitorVerdict:
    """One sample's verdict.

    Attributes
    ----------
    passes : bool
        The windowed NIS lies below its threshold (and nothing else failed).
    statistic : float
        The sum of the last ``window`` NIS values (NaN ones count as 0).
    threshold : float
        Its ``1 - false_alarm`` chi-square(``window``) quantile.
    reason : str
        Why it fails (``""`` when it passes).
    """

    passes: bool
    statistic: float
    threshold: float
    reason: str = ""


@functools.lru_cache(maxsize=64)
def _chi2_quantile(level: float, dof: int) -> float:
    """The ``level`` quantile of chi^2 with ``dof`` degrees of freedom (scipy's ``chi2.ppf``),
    kept: every filter of a Monte Carlo study asks for the same few."""
    from scipy.stats import chi2

    return float(chi2.ppf(level, dof))


class ConsistencyMonitor:
    """The windowed NIS test (see the module).

    Parameters
    ----------
    window : int
        ``W``, samples (``>= 1``).
    false_alarm : float
        Level of each window's test, in ``(0, 1)``: a consistent filter's sum exceeds the
        threshold with this probability.
    """

    def __init__(self, window: int = 10, false_alarm: float = 1e-4) -> None:
        owner = "ConsistencyMonitor"
        self.window = as_int(window, "window", owner, low=1)
        self.false_alarm = as_float(false_alarm, "false_alarm", owner, low=0.0, high=1.0, low_open=True)
        if self.false_alarm == 1.0:                  # (a threshold of 0: every window would fail)
            raise ParameterError(parameter_message("false_alarm", owner, "be < 1", false_alarm))
        self.threshold = _chi2_quantile(1.0 - self.false_alarm, self.window)
        self.reset()

    def reset(self) -> None:
        self._values: deque[float] = deque(maxlen=self.window)
        self._sum = 0.0

    def push(self, nis: float, failure: str = "") -> MonitorVerdict:
        """Take one sample's NIS (NaN: no update this sample) and, when something else
        failed at it (``failure``: its reason), fail the sample whatever the sum."""
        value = 0.0 if not math.isfinite(nis) else float(nis)
        if len(self._values) == self.window:
            self._sum -= self._values[0]
        self._values.append(value)
        self._sum += value
        statistic = max(self._sum, 0.0)
        if failure:
            return MonitorVerdict(False, statistic, self.threshold, failure)
        if statistic > self.threshold:
            return MonitorVerdict(False, statistic, self.threshold,
                                  f"NIS over the last {self.window} samples {statistic:.3g} > {self.threshold:.3g}")
        return MonitorVerdict(True, statistic, self.threshold)

    @property
    def mean(self) -> float:
        """Mean NIS over the window (1 for a consistent filter)."""
        return self._sum / len(self._values) if self._values else math.nan


def matched_variance(innovations: np.ndarray, predicted: np.ndarray, floor: float) -> float:
    """Covariance matching: the measurement variance that makes ``innovations`` consistent.

    Parameters
    ----------
    innovations : ndarray of shape (W,)
        The last ``W`` innovations ``y_k``.
    predicted : ndarray of shape (W,)
        Their predicted variances without the measurement noise, ``H P H^T`` (the prior's).
    floor : float
        The model's own measurement variance (the result is never below it).

    Returns
    -------
    float
        ``max(floor, mean(y^2) - mean(H P H^T))``.
    """
    return max(floor, float(np.mean(innovations * innovations) - np.mean(predicted)))


def fit_noise(excess: np.ndarray, speed2: np.ndarray, b_max: float = math.inf) -> tuple[float, float]:
    """Least squares of ``excess ~ a + b speed2`` with ``a >= 0`` and ``0 <= b <= b_max`` (the
    best fit on the boundary when the free fit lies outside: ``a = 0``, ``b = 0`` or
    ``b = b_max``, each with the other coefficient fitted and clipped)."""
    e, x = np.asarray(excess, dtype=float), np.asarray(speed2, dtype=float)
    n = e.size
    if n == 0:
        return 0.0, 0.0
    sx, sxx, se, sxe = x.sum(), x @ x, e.sum(), x @ e
    det = n * sxx - sx * sx
    a = b = -1.0
    if det > 1e-12 * max(n * sxx, 1e-300):
        a = (sxx * se - sx * sxe) / det
        b = (n * sxe - sx * se) / det
    if a < 0.0 or b < 0.0 or b > b_max:
        fits = [(max(se / n, 0.0), 0.0)]
        if sxx > 0.0:
            fits.append((0.0, min(max(sxe / sxx, 0.0), b_max)))
        if math.isfinite(b_max):
            fits.append((max((se - b_max * sx) / n, 0.0), b_max))
        a, b = min(fits, key=lambda ab: float(np.sum((e - ab[0] - ab[1] * x) ** 2)))
    return float(a), float(b)


class NoiseMatcher:
    """Covariance matching of a scalar measurement's extra noise, ``a + b V^2``, over a window.

    The model's measurement variance ``R0`` (the quantization) may miss read noise (a
    constant ``a``) and sample-time jitter (``b V^2``: a read ``d`` seconds late is ``V d``
    off, ``b = sigma_t^2``). Each Gaussian update pushes its innovation ``y``, predicted
    variance ``H P H^T``, ``R0`` and speed ``V``; ``e = y^2 - H P H^T - R0`` then has mean
    ``a + b V^2`` (Mehra's covariance matching), fitted by least squares over the last
    ``window`` samples with ``a >= 0`` and ``0 <= b <= jitter_max^2``, the largest 5 % of the
    excesses left out (rare outliers such as a missed count are not the noise of every
    reading). The bound keeps an excess seen at one speed (``a`` and ``b V^2`` are then one
    number) from being read as a jitter no encoder may have.

    Parameters
    ----------
    window : int
        Samples in the fit (``>= 2``).
    jitter_max : float, s
        The largest jitter the sensors may have (``>= 0``; the sensor law's
        ``MAX_JITTER_PERIODS`` of a period); default: unbounded.
    """

    def __init__(self, window: int = 100, jitter_max: float = math.inf) -> None:
        self.window = as_int(window, "window", "NoiseMatcher", low=2)
        self.jitter_max = as_float(jitter_max, "jitter_max", "NoiseMatcher", low=0.0, finite=False)
        self.reset()

    #: Updates between refits (the window moves little in between).
    REFIT = 5

    def reset(self) -> None:
        # The last `window` rows (excess, speed^2), a ring: row k at k % window. Until it is
        # full the rows stand in order; once trimmed (20 rows or more) they are sorted anyway
        # (a window under 20 that has wrapped fits them in ring order: the same least squares
        # but for the rounding of its sums).
        self._rows = np.empty((self.window, 2))
        self._count = 0
        self.a = 0.0
        self.b = 0.0

    def push(self, innovation: float, predicted: float, base: float, speed: float) -> None:
        """Take one update's innovation (m), ``H P H^T`` and ``R0`` (m^2) and speed (m/s);
        refit ``a`` (m^2) and ``b`` (s^2) every :data:`REFIT` updates."""
        row = self._rows[self._count % self.window]
        row[0] = innovation * innovation - predicted - base
        row[1] = speed * speed
        self._count += 1
        kept = min(self._count, self.window)
        if self._count % self.REFIT and kept >= 20:
            return
        rows = self._rows[:kept]
        if rows.shape[0] >= 20:
            # Trimmed: the largest 5 % of the excesses left out (rare outliers, such as a
            # missed count, are not noise of every reading).
            keep = np.argsort(rows[:, 0])[:rows.shape[0] - rows.shape[0] // 20]
            rows = rows[keep]
        self.a, self.b = fit_noise(rows[:, 0], rows[:, 1], self.jitter_max ** 2)

    def extra(self, speed: float) -> float:
        """The matched extra variance at ``speed``, ``a + b V^2`` (m^2)."""
        return self.a + self.b * speed * speed
