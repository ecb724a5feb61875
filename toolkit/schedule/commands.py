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

_OWNER = "design_schedule"


@dataclass(frozen=True)
class _Motor:
    """The motor model as the optimizer sees it: exact inside the rate-limit-free regime."""

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

    def decay(self) -> float:
        return math.exp(-self.period / self.tau) if self.tau > 0 else 0.0

    def speeds(self, start: np.ndarray, u: np.ndarray, s: np.ndarray) -> np.ndarray:
        """Contact speeds at offsets ``s`` (T,) into a period: shape (T, n)."""
        s = np.asarray(s, dtype=float)[:, None]
        if self.tau > 0:
            return u + (start - u) * np.exp(-s / self.tau)
        if math.isfinite(self.rate):
            return start + np.clip(u - start, -self.rate * s, self.rate * s)
        return np.broadcast_to(u, (s.shape[0], u.size)).copy()

    def symbolic(self, ca: Any, start: Any, u: Any, s: Any) -> Any:
        if self.tau > 0:
            return u + (start - u) * ca.exp(-s / self.tau)
        if math.isfinite(self.rate):
            return start + ca.fmin(ca.fmax(u - start, -self.rate * s), self.rate * s)
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
    decay = motor.decay()
    out = np.empty_like(U)
    v = start.copy()
    speeds = [v.copy()]
    for k in range(K):
        u = start.copy() if (k == 0 and pin_first) else _clip_commands(U[k], v, lo, hi,
                                                                          motor.max_step)
        out[k] = u
        v = u if not motor.dynamic or (motor.tau == 0) else u + (v - u) * decay
        speeds.append(v.copy())
    return out, np.array(speeds)
