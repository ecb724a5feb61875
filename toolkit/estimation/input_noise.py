"""The noise of the inputs a filter does not know: a force, and a command's timing.

:func:`unknown_force_noise` is the process noise a gross innovation implies (a force the
model does not know); :func:`command_timing_variance` is the body's speed variance from a
command that reached the motors at an unknown time within its period. Derivations:
docs/estimation.md.
"""

from __future__ import annotations

import math

import numpy as np

from ..laws import lag_response

__all__ = ["GROSS_NIS", "unknown_force_noise", "command_timing_variance"]

#: chi-square(1)'s quantile at 1 - 1e-6: one innovation beyond it is gross, and widens the filter.
GROSS_NIS = 23.93


def unknown_force_noise(innovation: float, variance: float, count: float, period: float,
                        largest: float) -> np.ndarray | None:
    """The process noise of ``(X, V)`` that a gross innovation implies, or None.

    The part of the innovation ``y`` beyond one count (a count lost) and the gate
    ``sqrt(GROSS_NIS S)`` of its predicted spread is what no measurement hypothesis explains:
    a force the model does not know (a command that reached the motors between two samples,
    a knock). The acceleration that explains it held over the period, ``a = 2 |y|_excess /
    h^2``, at most ``largest``, enters as filterpy's discrete white-noise acceleration,
    ``a^2 [[h^4 / 4, h^3 / 2], [h^3 / 2, h^2]]``.

    Parameters
    ----------
    innovation : float, m
        ``y = z - X-``.
    variance : float, m^2
        Its predicted variance ``S`` (prediction and reading).
    count : float, m
        The central encoder's count.
    period : float, s
        The sample period ``h``.
    largest : float, m/s^2
        The largest acceleration the forces can give (friction's all one way, and the
        outside force's).

    Returns
    -------
    ndarray of shape (2, 2) or None
        None where the innovation is within the gate.
    """
    from filterpy.common import Q_discrete_white_noise

    excess = abs(innovation) - count - math.sqrt(GROSS_NIS * variance)
    if not excess > 0.0:
        return None
    accel = min(2.0 * excess / (period * period), largest)
    return Q_discrete_white_noise(2, dt=period, var=accel * accel)


def command_timing_variance(before: np.ndarray, after: np.ndarray, period: float, lag: float,
                            largest: float) -> float:
    """The body's speed variance from a command that reached the motors at an unknown time
    within the period before the sample that records it, (m/s)^2.

    A record carries the command from the first sample after it was sent; the motors may have
    taken it anywhere in the period before (a command between samples, serial latency).
    Over that unseen time, uniform on ``[0, h]``, the body's speed departs from the old
    command's flow by at most the contacts' change, ``max_i |u_i - u_i'| (1 - exp(-h /
    tau))`` (the motor law over a period, :func:`~toolkit.laws.lag_response`; the
    whole step for ideal motors), and by at most
    what the largest force gives over the period, ``a_max h``: the smaller, ``e``, as the
    largest of a departure that grows with the unseen time, uniform on ``[0, e]``, whose
    second moment is ``e^2 / 3``.

    Parameters
    ----------
    before, after : ndarray of shape (n,), m/s
        The commands before and after the change.
    period : float, s
    lag : float, s
        The motors' lag (0: ideal motors).
    largest : float, m/s^2
        The largest acceleration the forces can give.
    """
    before, after = np.asarray(before, dtype=float), np.asarray(after, dtype=float)
    moved = lag_response(after, before, period, lag) if lag > 0.0 else after
    reach = min(float(np.max(np.abs(moved - before), initial=0.0)), largest * period)
    return reach * reach / 3.0
