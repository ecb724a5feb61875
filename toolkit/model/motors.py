"""The motor law: how a contact's speed follows its command.

:func:`motor_rate` writes it once: ``dv/dt = clip((u - v) / tau, -r, r)`` with a lag ``tau``
and a rate limit ``r``, ``u`` the command clipped to the speed limits (ideal motors: ``v =
u``). The rest is that law solved in closed form for the solvers that need it:
:class:`MotorPiece`, :func:`unsaturated_response`, :func:`lag_memory`,
:func:`lag_settling_time`, :func:`implicit_step` and :func:`reach` (docs/methods.md)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import as_float
from ..errors import ParameterError, ParameterTypeError, parameter_message
from ._xp import ops
from ..laws import lag_decay, lag_response, lag_travel

__all__ = ["Motors", "motor_rate", "MotorPiece", "unsaturated_response", "lag_memory",
           "lag_settling_time", "implicit_step", "reach"]


@dataclass(frozen=True)
class Motors:
    """A motor model shared by all contacts.

    Parameters
    ----------
    lag : float, s
        First-order time constant ``tau``: ``dv/dt = (u - v) / tau``; ``0`` = no lag.
    rate_limit : float, m/s^2
        Bound on ``|dv/dt|`` (``inf`` = none). With ``lag = 0`` a finite rate limit makes
        the speed ramp to each new command at exactly this rate.
    speed_limits : tuple of float, m/s
        ``(low, high)``: commands are clipped to this range (``low <= high``).
    compliance : float, (m/s)/N
        Slope ``k`` of the motor's torque-speed line: the contact's actual speed droops by
        ``k`` times its contact force, so the contact force becomes the saturated linear
        function ``f_i clip((v_i - V) / (k f_i), -1, 1)``; ``0`` = stiff motor (Coulomb law).
    backlash : float, m (at the contact)
        Width ``b >= 0`` of the gearbox play between each motor and its wheel; ``0`` = no
        play (nothing changes). Simulated by ``simulate(..., method="moreau")`` only (the
        other methods refuse ``b > 0``); see Notes.

    Notes
    -----
    **Drive backlash.** Wheel ``i`` is driven by its motor through a play of width ``b``;
    ``g_i`` (wheel position minus motor position, m) stays in ``[-b/2, b/2]``. While the
    gearbox is engaged the contact moves at the motor's speed ``v_i`` and carries the usual
    force ``f_i Sign(v_i - V)``, restricted to the sign the engaged edge can transmit: at
    ``g_i = -b/2`` the motor pushes the wheel forward (contact force in ``[0, f_i]``), at
    ``g_i = +b/2`` it pushes it back (force in ``[-f_i, 0]``). When the force the contact
    must carry reverses, the wheel leaves its edge: it carries no force (wheel inertia
    neglected, so it rolls with the body, contact speed ``V``) and ``dg_i/dt = V - v_i``
    until ``g_i`` reaches the other edge, where the gear re-engages and the contact pushes
    with the new sign. At ``t = 0`` each drive sits at the edge that pushes towards its
    contact's speed relative to the body, ``g_i = -(b/2) sign(v_i - V(0))``, or, for a
    contact riding with the body, towards its own speed, ``-(b/2) sign(v_i)`` (``g_i = 0``,
    mid-play, for a contact at rest under a body at rest).

    Closed form (checked in ``tests/test_backlash.py``): ``N`` contacts of total force
    ``F_tot`` at ``+v`` carrying the body at ``V = +v``, commanded to ``-v`` (ideal motors):
    every wheel crosses its play at relative speed ``2 v``, so the body coasts for
    ``b / (2 v)``, then decelerates under ``-F_tot`` and reaches ``-v`` at
    ``dT = b / (2 v) + 2 v m / F_tot``.
    """

    lag: float = 0.0
    rate_limit: float = float("inf")
    speed_limits: tuple[float, float] = (float("-inf"), float("inf"))
    compliance: float = 0.0
    backlash: float = 0.0

    def __post_init__(self) -> None:
        owner = "Motors"
        object.__setattr__(self, "lag", as_float(self.lag, "lag", owner, low=0.0))
        if self.lag > 0 and not math.isfinite(1.0 / self.lag):
            raise ParameterError(parameter_message(
                "lag", owner, "be 0 or have a finite rate 1 / lag", self.lag))
        object.__setattr__(self, "rate_limit", as_float(
            self.rate_limit, "rate_limit", owner, low=0.0, low_open=True, finite=False))
        object.__setattr__(self, "compliance", as_float(
            self.compliance, "compliance", owner, low=0.0))
        object.__setattr__(self, "backlash", as_float(self.backlash, "backlash", owner, low=0.0))
        limits = self.speed_limits
        if isinstance(limits, (str, bytes)) or not hasattr(limits, "__len__") or len(limits) != 2:
            raise ParameterTypeError(parameter_message(
                "speed_limits", owner, "be a pair (low, high) of speeds", limits))
        low = as_float(limits[0], "speed_limits", owner, finite=False)
        high = as_float(limits[1], "speed_limits", owner, finite=False)
        if not low <= high or low == float("inf") or high == float("-inf"):
            raise ParameterError(parameter_message(
                "speed_limits", owner, "satisfy low <= high with low < inf and high > -inf",
                limits))
        object.__setattr__(self, "speed_limits", (low, high))

    @property
    def dynamic(self) -> bool:
        """True when contact speeds lag behind the commands (a lag or a finite rate limit)."""
        return self.lag > 0 or math.isfinite(self.rate_limit)

    def clip(self, command: Any, xp: Any = np) -> Any:
        """Commands clipped to ``speed_limits``, m/s (numpy array or casadi expression)."""
        low, high = self.speed_limits
        if xp is np or xp is None:
            return np.clip(command, low, high)
        o = ops(xp)
        if math.isfinite(low):
            command = o.fmax(command, low)
        if math.isfinite(high):
            command = o.fmin(command, high)
        return command


def motor_rate(motors: Motors | None, command: Any, speeds: Any, xp: Any = np) -> Any:
    """``dv_i/dt`` of the motor law: the one definition every solver calls.

    Parameters
    ----------
    motors : Motors or None
        ``None`` (or motors that are not :attr:`~Motors.dynamic`): ideal, zero rate.
    command : array_like of shape (n,), m/s
        Commanded speeds, already clipped to the speed limits.
    speeds : array_like of shape (n,), m/s
        Current contact speeds.
    xp : module
        ``numpy`` or ``casadi``.

    Returns
    -------
    ndarray of shape (n,), m/s^2 (or a casadi expression)
        ``clip((u - v) / tau, -r, r)`` with a lag ``tau > 0``; ``r sign(u - v)`` with only
        a rate limit ``r``; zeros for ideal motors (their speeds jump with the commands).
    """
    o = ops(xp)
    if motors is None or not motors.dynamic:
        return 0.0 * speeds if o.symbolic else np.zeros_like(np.asarray(speeds, dtype=float))
    gap = command - speeds
    rate = motors.rate_limit
    if motors.lag > 0:
        pull = gap / motors.lag
        return o.fmin(o.fmax(pull, -rate), rate) if math.isfinite(rate) else pull
    return rate * o.sign(gap)


def unsaturated_response(start: Any, command: Any, s: Any, lag: float, rate: float,
                         xp: Any = np) -> Any:
    """Speeds ``s`` seconds after a constant command, exact while off the rate limit.

    ``u + (v0 - u) exp(-s / tau)`` with a lag; ``v0 + clip(u - v0, -r s, r s)`` with only a
    rate limit; ``u`` for ideal motors. With both a lag and a rate limit this is exact when
    ``|u - v0| <= r tau`` (the motor never saturates); :class:`MotorPiece` covers the rest.

    Parameters
    ----------
    start, command : array_like of shape (n,), m/s
    s : array_like of shape (T, 1) or scalar, s
        Offsets from the command's start (broadcast against ``(n,)``).
    lag, rate : float
        ``tau`` (s) and ``r`` (m/s^2).
    xp : module
        ``numpy`` or ``casadi``.
    """
    o = ops(xp)
    if lag > 0:
        return lag_response(command, start, s, lag, o.exp)
    if math.isfinite(rate):
        return start + o.fmin(o.fmax(command - start, -rate * s), rate * s)
    return command + 0.0 * s


def lag_memory(s: float, lag: float) -> tuple[float, float]:
    """The share of a lagging motor's start speed left after ``s`` seconds off its rate limit,
    ``exp(-s / tau)`` (:func:`unsaturated_response` is ``u + (v0 - u)`` times it: its slope
    in ``v0``), and that share's integral over ``[0, s]``, ``tau (1 - exp(-s / tau))`` (s).

    Parameters
    ----------
    s : float, s
    lag : float, s
        ``tau > 0``.
    """
    return lag_decay(s, lag, math.exp), lag_travel(0.0, 1.0, s, lag, math.expm1)


def lag_settling_time(gap: float, lag: float, travel: float) -> float:
    """Seconds after a command change at which a lagging motor that started ``gap`` (m/s)
    from its command has less than ``travel`` (m) left to go: the remaining travel of
    :func:`unsaturated_response` is ``gap tau exp(-s / tau)``; 0 when it starts below.

    Parameters
    ----------
    gap : float, m/s
    lag : float, s
        ``tau > 0``.
    travel : float, m
        Positive.
    """
    remaining = gap * lag
    return lag * math.log(remaining / travel) if remaining > travel else 0.0


@dataclass(frozen=True)
class MotorPiece:
    """Exact contact speeds over one constant command ``u`` starting at time ``a``.

    Each motor first ramps at the rate limit while its gap to the command exceeds
    ``rate * tau`` (the whole gap when ``tau = 0``), then approaches the command
    exponentially with time constant ``tau`` (or holds it when ``tau = 0``): the solution
    of :func:`motor_rate` for a constant command.
    """

    a: float
    start: np.ndarray
    u: np.ndarray
    tau: float
    ramp: np.ndarray           # ramp slope, m/s^2 (0 where no ramp)
    ramp_end: np.ndarray       # offset (s) at which the ramp ends (0 where none)
    after: np.ndarray          # speed at the ramp end, m/s

    @classmethod
    def build(cls, a: float, start: np.ndarray, u: np.ndarray, tau: float, rate: float) -> MotorPiece:
        """The piece from speeds ``start`` under command ``u`` (lag ``tau``, rate ``rate``)."""
        gap = u - start
        if not math.isfinite(rate):                        # lag only: no ramp phase
            zeros = np.zeros_like(gap)
            return cls(a, start, u, tau, zeros, zeros, start)
        direction = np.sign(gap)
        excess = np.abs(gap) - rate * tau
        ramping = excess > 0
        slope = np.where(ramping, direction * rate, 0.0)
        end = np.where(ramping, excess / rate, 0.0)
        after = np.where(ramping, u - direction * rate * tau, start)
        return cls(a, start, u, tau, slope, end, after)

    def speeds(self, s: np.ndarray) -> np.ndarray:
        """Speeds at offsets ``s`` (shape (T,)) from ``a``: shape (T, n), m/s."""
        s = np.asarray(s, dtype=float)[:, None]
        ramping = s < self.ramp_end
        on_ramp = self.start + self.ramp * s
        if self.tau > 0:
            with np.errstate(over="ignore", invalid="ignore"):    # only on the ramp, masked
                settle = unsaturated_response(self.after, self.u, s - self.ramp_end, self.tau,
                                              math.inf)
        else:
            settle = np.broadcast_to(self.after, on_ramp.shape)
        return np.where(ramping, on_ramp, settle)

    def speeds_at(self, s: float) -> np.ndarray:
        """Speeds at one offset ``s`` (s) from ``a``: shape (n,), m/s, fresh; the operations
        of ``speeds`` on one time (without the work of a ramp phase when none is left)."""
        ramping = s < self.ramp_end
        if self.tau > 0:
            with np.errstate(over="ignore", invalid="ignore"):    # only on the ramp, masked
                settle = lag_response(self.u, self.after, s - self.ramp_end, self.tau)
        else:
            settle = self.after.copy()
        if not ramping.any():
            return settle
        return np.where(ramping, self.start + self.ramp * s, settle)

    def coefficients(self, s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
        """At offset ``s``: speeds ``v0``, ramp slopes ``q``, exponential rates ``e`` (so that
        ``v(s + x) = v0 + q x + e expm1_ratio(1/tau, x)``) and the offset of the next phase
        change."""
        v0 = self.speeds_at(s)
        ramping = s < self.ramp_end
        if not ramping.any():              # (the general case below with no ramp left)
            e = (self.u - v0) / self.tau if self.tau > 0 else np.zeros_like(v0)
            return v0, np.zeros_like(v0), e, math.inf
        q = np.where(ramping, self.ramp, 0.0)
        e = np.where(ramping, 0.0, (self.u - v0) / self.tau) if self.tau > 0 else np.zeros_like(v0)
        pending = self.ramp_end[ramping]
        return v0, q, e, float(pending.min())

    def displacement(self, s: float) -> np.ndarray:
        """Distance each contact travels over the offsets ``[0, s]`` from ``a``: the exact
        integral of ``speeds``, m, shape (n,).

        ``start x + ramp x^2 / 2`` over the ramp (``x = min(s, ramp_end)``), then
        ``u y + (after - u) tau (1 - exp(-y / tau))`` over the remaining ``y = s - x``
        (``after y`` when ``tau = 0``).
        """
        on_ramp = np.minimum(s, self.ramp_end)
        rest = s - on_ramp
        distance = self.start * on_ramp + 0.5 * self.ramp * on_ramp * on_ramp
        if self.tau > 0:
            return distance + lag_travel(self.u, self.after, rest, self.tau)
        return distance + self.after * rest


def implicit_step(motors: Motors, speeds: np.ndarray, command: np.ndarray, h: float) -> np.ndarray:
    """One backward-Euler step of :func:`motor_rate` over ``h`` seconds, solved exactly.

    ``v+ = v + clip(w - v, -r h, r h)`` with ``w = (v + (h/tau) u) / (1 + h/tau)`` (``w = u``
    without a lag): the unique solution of ``v+ = v + h clip((u - v+)/tau, -r, r)``, the
    scalar equations being monotone.

    Parameters
    ----------
    motors : Motors
    speeds, command : ndarray of shape (n,), m/s
    h : float, s

    Returns
    -------
    ndarray of shape (n,), m/s
    """
    if motors.lag > 0:
        ratio = h / motors.lag
        target = (speeds + ratio * command) / (1.0 + ratio)
    else:
        target = command
    step = h * motors.rate_limit
    return speeds + np.clip(target - speeds, -step, step)


def reach(tau: float, rate: float, v: np.ndarray, limit: float, s: np.ndarray) -> np.ndarray:
    """Fastest motion of each contact from ``v`` towards ``limit`` after ``s`` seconds: (T, n).

    Under :func:`motor_rate` with any command between the speed limits no contact gets
    farther than this (comparison principle for the scalar motor ODE).

    Parameters
    ----------
    tau, rate : float
        Lag (s, 0 = none) and rate limit (m/s^2, inf = none).
    v : ndarray of shape (n,), m/s
    limit : float, m/s
    s : array_like of shape (T,), s
    """
    s = np.asarray(s, dtype=float)[:, None]
    direction = np.sign(limit - v)
    gap = np.abs(limit - v)
    if tau <= 0 and not math.isfinite(rate):
        return np.broadcast_to(np.full_like(v, limit), (s.shape[0], v.size)).copy()
    if tau <= 0:
        return v + direction * np.minimum(gap, rate * s)
    if not math.isfinite(rate):
        return lag_response(limit, v, s, tau)          # (v - limit = -direction gap exactly)
    linear = np.maximum(gap - rate * tau, 0.0) / rate    # saturated rate until gap = r tau
    near = np.minimum(gap, rate * tau)
    moved = np.where(s <= linear, rate * s, gap - near * lag_decay(s - linear, tau))
    return v + direction * moved
