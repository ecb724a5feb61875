"""What an experimenter reads off sampled speeds and forces: numerics only, no simulation.

- :func:`startup_time_constant`: the exponential through the start, the settled speed and
  the 63.2 % crossing (the crossing linearly interpolated between samples);
- :func:`crossing_duration`: a transition time from two level crossings, extrapolated to
  the full swing;
- :func:`proportional_fit`: least squares ``y = b x`` through the origin and its R^2;
- :func:`rig_friction`: the contacts' force from a test rig's force over a window, with the
  body's inertia removed.
"""

from __future__ import annotations

import math

import numpy as np

from .theory import ONE_MINUS_INV_E

__all__ = ["startup_time_constant", "crossing_time", "crossing_duration", "proportional_fit",
           "rig_friction"]


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


def startup_time_constant(times: np.ndarray, speed: np.ndarray, tail: int) -> tuple[float, float]:
    """Time constant of a startup that settles: the exponential's 63.2 % time.

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
        ``nan`` when the speed does not move or never crosses the level.
    settled : float, m/s
    """
    settled = float(np.mean(speed[-tail:]))
    v0 = float(speed[0])
    if settled == v0:
        return math.nan, settled
    level = v0 + ONE_MINUS_INV_E * (settled - v0)
    return crossing_time(times, speed, level, math.copysign(1.0, settled - v0)) - float(times[0]), settled


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
