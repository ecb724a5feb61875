"""Commands under the motor model: the motor settings a schedule is designed for, and
commands projected onto them.

A command may differ from the current contact speed by at most ``r tau`` (``r dt`` without
lag), so the rate limit never clips and every contact speed inside a period is the closed
form of :func:`toolkit.model.motors.unsaturated_response`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import ParameterError, parameter_message
from ..model import Plant
from ..model.motors import unsaturated_response

_OWNER = "design_schedule"


@dataclass(frozen=True)
class _Motor:
    """The motor model as the designer sees it: exact inside the rate-limit-free regime.

    Contact speeds are :func:`toolkit.model.motors.unsaturated_response` (the motor law
    solved for a constant command): exact because commands stay within :attr:`max_step`.
    """

    tau: float                 # s, 0 = no lag
    rate: float                # m/s^2, inf = none
    period: float              # s

    @property
    def dynamic(self) -> bool:
        return self.tau > 0 or math.isfinite(self.rate)

    @property
    def max_step(self) -> float:
        """Largest ``|u_k - v_k|`` that keeps the motor out of rate saturation (inf = any)."""
        if not math.isfinite(self.rate):
            return math.inf
        return self.rate * (self.tau if self.tau > 0 else self.period)

    def speeds(self, start: np.ndarray, u: np.ndarray, s: np.ndarray) -> np.ndarray:
        """Contact speeds at offsets ``s`` (T,) into a period: shape (T, n), m/s."""
        s = np.asarray(s, dtype=float)[:, None]
        return unsaturated_response(start, u, s, self.tau, self.rate)

    def symbolic(self, ca: Any, start: Any, u: Any, s: Any) -> Any:
        """``speeds`` as a casadi expression (``ca`` the casadi module)."""
        return unsaturated_response(start, u, s, self.tau, self.rate, xp=ca)

    def period_end(self, start: Any, u: Any, xp: Any = np) -> Any:
        """Contact speeds at the end of a period whose commands ``u`` lie within
        :attr:`max_step` of ``start`` (m/s; numpy arrays, or casadi with ``xp=casadi``).

        With a lag, the closed form at ``s = period``; without one the command itself (a ramp
        of at most ``r period``, or a jump, ends on it within the period).
        """
        if self.tau > 0:
            return unsaturated_response(start, u, self.period, self.tau, self.rate, xp=xp)
        return u

    def kinks(self, start: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Offsets inside a period where a rate-limited ideal motor reaches its command."""
        if self.tau > 0 or not math.isfinite(self.rate):
            return np.empty(0)
        ends = np.abs(u - start) / self.rate
        return np.unique(ends[(ends > 0) & (ends < self.period)])


def _motor_of(plant: Plant, period: float) -> _Motor:
    motors = plant.motors
    if motors is None:
        return _Motor(0.0, math.inf, period)
    if motors.compliance > 0:
        raise ParameterError(parameter_message(
            "plant", _OWNER, "have stiff motors (Motors.compliance == 0): schedules use the "
            "Coulomb model", f"compliance {motors.compliance:g}"))
    return _Motor(motors.lag, motors.rate_limit, period)


def _clip_commands(u: np.ndarray, v: np.ndarray, lo: float, hi: float, step: float) -> np.ndarray:
    """Commands ``u`` clipped into the speed limits and, when finite, to ``|u - v| <= step``."""
    u = np.clip(u, lo, hi)
    if math.isfinite(step):
        u = np.clip(u, np.maximum(v - step, lo), np.minimum(v + step, hi))
    return u


def _project(U: np.ndarray, start: np.ndarray, motor: _Motor, lo: float, hi: float,
             pin_first: bool) -> tuple[np.ndarray, np.ndarray]:
    """Clip commands into the limits exactly (solver tolerances), forward through the motors."""
    K, n = U.shape
    out = np.empty_like(U)
    v = start.copy()
    speeds = [v.copy()]
    for k in range(K):
        u = start.copy() if (k == 0 and pin_first) else _clip_commands(U[k], v, lo, hi,
                                                                          motor.max_step)
        out[k] = u
        v = motor.period_end(v, u)
        speeds.append(v.copy())
    return out, np.array(speeds)
