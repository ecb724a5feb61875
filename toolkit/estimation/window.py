"""First-order adaptive windowing (FOAW): the practitioner's window estimator of speed.

Janabi-Sharifi, Hayward and Chen, IEEE Trans. Control Systems Technology 8(6), 2000: the
speed at a sample is the slope of the line over the longest window of recent central
readings that all lie within the band ``d`` of that line (end-fit: through the window's end
readings; best-fit: least squares; kernels in :mod:`toolkit._compiled.window`), with ``d``
the quantization's half count. Variances with the quantization taken as white.
Derivations: docs/estimation.md.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..laws import cell_centre, quantization_variance
from .._compiled import kernels
from ..errors import as_float, as_int, check_option
from ..errors import ParameterTypeError, parameter_message
from ..model.sensors import EncoderSample, Sensors
from ._base import Estimator

__all__ = ["AdaptiveWindow", "DEFAULT_MAX_WINDOW"]

#: Default longest window, samples (1 s at 50 Hz).
DEFAULT_MAX_WINDOW = 50


class AdaptiveWindow(Estimator):
    """FOAW on the central encoder (the module; docs/estimation.md).

    Parameters
    ----------
    sensors : Sensors
    fit : {"end", "best"}
        End-fit (line through the window's ends) or best-fit (least squares).
    max_window : int
        ``n_max``, the longest window in sample periods (``>= 1``).
    band : float, m, optional
        The uncertainty band ``d``; default the quantization's ``q / 2``.

    Attributes
    ----------
    window : int
        The window ``n`` of the last estimate (sample periods; 0 before two readings).
    matched_variance : float, (m/s)^2
        The last estimate's variance with the per-reading noise taken from the window's
        residuals about its line (at least the quantization's; best-fit windows of at least
        three periods), for a filter that falls back on the window.
    """

    KERNELS = ("window",)

    def __init__(self, sensors: Sensors, *, fit: str = "end", max_window: int = DEFAULT_MAX_WINDOW,
                 band: float | None = None) -> None:
        owner = type(self).__name__
        if not isinstance(sensors, Sensors):
            raise ParameterTypeError(parameter_message("sensors", owner, "be a Sensors", sensors))
        self.sensors = sensors
        self.fit = check_option(fit, "fit", owner, ("end", "best"))
        self.name = f"foaw_{self.fit}"
        self.max_window = as_int(max_window, "max_window", owner, low=1)
        q = sensors.central.distance_per_count
        self.band = 0.5 * q if band is None else as_float(band, "band", owner, low=0.0, low_open=True)
        self._q = q
        self._keep = self.max_window + 1
        self._cap = 4 * self._keep
        self.reset()

    def reset(self, *, speed: float = 0.0, speed_std: float | None = None,
              contact_speeds: object = None) -> None:
        self._speed = as_float(speed, "speed", f"{type(self).__name__}.reset")
        self._t = np.empty(self._cap)
        self._y = np.empty(self._cap)
        self._m = 0
        self.window = 0

    def observe(self, sample: EncoderSample) -> tuple[float, float]:
        return self.observe_count(sample.time, sample.central_count)

    def observe_count(self, time: float, count: int) -> tuple[float, float]:
        """:meth:`observe` of a central ``count`` read at ``time`` (s)."""
        self.push(time, count)
        return self.estimate()

    def push(self, time: float, count: int) -> None:
        """Keep a central ``count`` read at ``time`` (s) without estimating (:meth:`estimate`
        then gives what :meth:`observe_count` would have)."""
        if self._m == self._cap:                        # keep the newest keep - 1, then append
            kept = self._keep - 1
            self._t[:kept] = self._t[self._m - kept:self._m]
            self._y[:kept] = self._y[self._m - kept:self._m]
            self._m = kept
        m = self._m
        self._t[m] = time
        self._y[m] = cell_centre(count, self._q)
        self._m = m + 1

    def estimate(self) -> tuple[float, float]:
        """The estimate at the last reading kept (``(speed, variance)``, m/s and (m/s)^2)."""
        m = self._m
        a = max(0, m - self._keep)
        count = m - a
        slope, n = kernels("window", 2 * count * count).foaw(self._t[a:m], self._y[a:m], count, self.band,
                                                            self.fit == "best")
        self.window = n
        white = quantization_variance(self._q)
        if n == 0:
            self.matched_variance = white * 2.0 * self.sensors.rate ** 2
            return self._speed, self.matched_variance
        if self.fit == "end":
            span = self._t[m - 1] - self._t[m - 1 - n]
            self.matched_variance = 2.0 * white / (span * span)
            return slope, self.matched_variance
        t = self._t[m - 1 - n:m]
        dt = t - t.mean()
        S = float(dt @ dt)
        if n >= 3:
            # The window's own residuals about its line (covariance matching): at least the
            # quantization's q^2 / 12 per reading.
            y = self._y[m - 1 - n:m]
            r = y - y.mean() - slope * dt
            self.matched_variance = max(white, float(r @ r) / (n - 1)) / S
        else:
            self.matched_variance = white / S
        return slope, white / S

    def commanded(self, command: Any, force: float = 0.0) -> None:
        """Unused: a window estimator does not predict."""
