"""What an experimenter reads off sampled speeds and forces: numerics only, no simulation.

- the startup time constant under its two definitions (:data:`TIME_CONSTANTS`,
  :func:`startup_time_constant`): ``"least_squares"``, an exponential fitted by least
  squares to the whole startup (:func:`exponential_time_constant`, the paper's way), and
  ``"crossing_63"``, the 63.2 % crossing of the exponential through the start and the
  settled speed (:func:`crossing_time_constant`);
- :func:`crossing_duration`: a transition time from two level crossings, extrapolated to
  the full swing;
- :func:`proportional_fit`: least squares ``y = b x`` through the origin and its R^2;
- :func:`rig_friction`: the contacts' force from a test rig's force over a window, with the
  body's inertia removed.
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import check_option

__all__ = ["TIME_CONSTANTS", "ONE_MINUS_INV_E", "startup_time_constant", "exponential_time_constant",
           "crossing_time_constant", "crossing_time", "crossing_duration", "proportional_fit",
           "rig_friction"]

#: The fraction of the way covered after one time constant of an exponential.
ONE_MINUS_INV_E = 1.0 - math.exp(-1.0)
#: The definitions of a startup's time constant, the paper's first (docs/physics.md section 6).
TIME_CONSTANTS = ("least_squares", "crossing_63")
#: Log-spaced trial time constants of the least-squares fit's first pass, per decade.
_GRID_PER_DECADE = 16


def crossing_time(times: np.ndarray, values: np.ndarray, level: float, direction: float) -> float:
    """First time the samples reach ``level`` going in ``direction`` (+1 up, -1 down), s.

    Linear interpolation between the two samples around the crossing (exact for a signal
    that is linear between them); ``nan`` when the level is never reached; ``times[0]``
    when the first sample is already past it.
    """
    past = np.flatnonzero(direction * (values - level) >= 0.0)
    if past.size == 0:
        return math.nan
    k = int(past[0])
    if k == 0:
        return float(times[0])
    v0, v1 = values[k - 1], values[k]
    return float(times[k - 1] + (level - v0) * (times[k] - times[k - 1]) / (v1 - v0))


def _unmoved(v0: float, settled: float, speed: np.ndarray) -> bool:
    """No startup to read: the settled mean within a few rounding errors of the start."""
    return abs(settled - v0) <= 8.0 * np.finfo(float).eps * float(np.max(np.abs(speed)))


def crossing_time_constant(times: np.ndarray, speed: np.ndarray, tail: int) -> tuple[float, float]:
    """Time constant ``"crossing_63"``: the 63.2 % time of the exponential through the start
    and the settled speed.

    The exponential ``V(t) = V_inf + (V_0 - V_inf) exp(-t / tau)`` through the first sample
    (``V_0`` at ``times[0]``) and the settled speed ``V_inf`` (mean of the last ``tail``
    samples) reaches ``V_0 + (1 - 1/e)(V_inf - V_0)`` at ``t = tau``; the samples' crossing
    of that level (:func:`crossing_time`) gives ``tau``. For the ideal staircase this is the
    quantity whose correction :func:`~toolkit.predictions.theory.staircase_correction`
    gives in closed form.

    Parameters
    ----------
    times : ndarray of shape (k,), s
        Sample times from the start of the startup.
    speed : ndarray of shape (k,), m/s
    tail : int
        Samples averaged for the settled speed, ``>= 1``.

    Returns
    -------
    tau : float, s
        ``nan`` when the speed does not move (the settled mean within a few rounding errors of
        the start) or never crosses the level.
    settled : float, m/s
    """
    settled = float(np.mean(speed[-tail:]))
    v0 = float(speed[0])
    if _unmoved(v0, settled, speed):
        return math.nan, settled
    level = v0 + ONE_MINUS_INV_E * (settled - v0)
    return crossing_time(times, speed, level, math.copysign(1.0, settled - v0)) - float(times[0]), settled


def exponential_time_constant(times: np.ndarray, speed: np.ndarray, tail: int) -> tuple[float, float]:
    """Time constant ``"least_squares"``: the exponential fitted to the whole startup.

    ``V(t) = V_inf + (V_0 - V_inf) exp(-(t - t_0) / tau)`` with ``V_0`` the first sample (the
    speed when the staircase is switched on: the paper's start from rest) and ``V_inf`` the
    settled speed (mean of the last ``tail`` samples), both read off the record and held
    fixed; ``tau`` alone is fitted, minimising the sum of squared speed errors over every
    sample from ``t_0 = times[0]`` to the end (the window: the whole record, which must run
    on past the stop). Holding both ends keeps ``tau`` nearly independent of how long the
    record runs on after the stop; a free final value trades itself against ``tau`` on a
    startup that is not exponential (docs/physics.md section 6 gives the numbers).

    Minimisation: the squared error on 16 trial values per decade of ``tau`` from 1e-3 to 10
    times the record's length, then Brent's method (``scipy.optimize.minimize_scalar``) on
    ``log tau`` between the best trial's neighbours, to a relative ``1e-10``.

    Parameters
    ----------
    times : ndarray of shape (k,), s
        Sample times from the start of the startup, ``k >= 2``.
    speed : ndarray of shape (k,), m/s
    tail : int
        Samples averaged for the settled speed, ``>= 1``.

    Returns
    -------
    tau : float, s
        ``nan`` when the speed does not move.
    settled : float, m/s
    """
    from scipy.optimize import minimize_scalar

    t = np.asarray(times, dtype=float) - float(times[0])
    v = np.asarray(speed, dtype=float)
    settled = float(np.mean(v[-tail:]))
    v0 = float(v[0])
    if _unmoved(v0, settled, v) or t[-1] <= 0:
        return math.nan, settled
    amplitude = v0 - settled
    rest = v - settled

    def error(log_tau: float) -> float:
        return float(np.sum((amplitude * np.exp(-t / math.exp(log_tau)) - rest) ** 2))

    trials = np.log(t[-1]) + np.linspace(-3.0, 1.0, 4 * _GRID_PER_DECADE + 1) * math.log(10.0)
    values = np.sum((amplitude * np.exp(-t[None, :] / np.exp(trials)[:, None]) - rest[None, :]) ** 2, axis=1)
    best = int(np.argmin(values))
    a, b = trials[max(best - 1, 0)], trials[min(best + 1, trials.size - 1)]
    found = minimize_scalar(error, bounds=(a, b), method="bounded", options={"xatol": 1e-10})
    return math.exp(float(found.x)), settled


def startup_time_constant(definition: str, times: np.ndarray, speed: np.ndarray,
                          tail: int) -> tuple[float, float]:
    """A startup's time constant under one of :data:`TIME_CONSTANTS` (see
    :func:`exponential_time_constant` and :func:`crossing_time_constant`); returns ``(tau,
    settled)`` in s and m/s."""
    definition = check_option(definition, "definition", "startup_time_constant", TIME_CONSTANTS)
    if definition == "least_squares":
        return exponential_time_constant(times, speed, tail)
    return crossing_time_constant(times, speed, tail)


def crossing_duration(times: np.ndarray, speed: np.ndarray, upper: float, lower: float,
                      margin: float) -> float:
    """Duration of a fall from ``upper`` to ``lower`` (m/s) read from two level crossings.

    The samples' crossings of ``upper - margin`` and ``lower + margin`` (linearly
    interpolated) are ``(upper - lower - 2 margin) / a`` apart for a constant deceleration
    ``a``; scaled to the full swing: ``dT = (t_lower - t_upper) (upper - lower) / (upper -
    lower - 2 margin)``. The margins keep the end points, where the speed settles onto its
    plateaus, out of the reading.

    Returns
    -------
    float, s
        ``inf`` when the lower level is never reached (no transition).
    """
    t_hi = crossing_time(times, speed, upper - margin, -1.0)
    t_lo = crossing_time(times, speed, lower + margin, -1.0)
    if math.isnan(t_lo) or math.isnan(t_hi):
        return math.inf
    return (t_lo - t_hi) * (upper - lower) / (upper - lower - 2.0 * margin)


def proportional_fit(x: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    """Least-squares slope of ``y = b x`` through the origin and its coefficient of determination.

    ``R^2 = 1 - sum (y - b x)^2 / sum (y - mean y)^2``: the share of the scatter of ``y``
    about its mean that the proportional law explains (the centred form; it is lower than
    the uncentred ``1 - SS_res / sum y^2`` often quoted for fits through the origin).

    Returns
    -------
    slope, r2 : float
    """
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    slope = float(np.dot(x, y) / np.dot(x, x))
    total = float(np.sum((y - y.mean()) ** 2))
    residual = float(np.sum((y - slope * x) ** 2))
    return slope, (1.0 - residual / total) if total > 0 else math.nan


def rig_friction(times: np.ndarray, speed: np.ndarray, force: np.ndarray, mass: float,
                 first: int, last: int) -> float:
    """The contacts' mean force over samples ``first..last`` from the rig's force, N.

    Over the window the body obeys ``m dV/dt = F_contacts + F_rig`` (no drag), so
    ``mean F_contacts = m (V_last - V_first) / (t_last - t_first) - mean F_rig``, with the rig
    force held over each period (``force[k]`` on ``[t_k, t_{k+1})``) and the speeds the
    rig's own measurement. A quasi-static sweep makes the inertia term small; it is removed
    rather than neglected.
    """
    span = times[last] - times[first]
    pushed = float(np.dot(force[first:last], np.diff(times[first:last + 1]))) / span
    return mass * float(speed[last] - speed[first]) / span - pushed
