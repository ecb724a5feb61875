"""The result of :func:`~toolkit.schedule.design_schedule`: the schedule, its prediction and
its certificate (:class:`ScheduleResult`), and what was achieved (:class:`ScheduleStatus`)."""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..model import PiecewiseConstant

__all__ = ["ScheduleStatus", "ScheduleResult"]


class ScheduleStatus(enum.Enum):
    """Outcome of :func:`~toolkit.schedule.design_schedule`; the value is the message shown
    to users.

    The status describes the returned schedule, not the internals of any solver (those are
    in ``ScheduleResult.solver_status`` and the message).
    """

    OPTIMAL = ("optimal: the exact model stays within 'prediction_bound' of the prediction "
               "(a proven bound over the whole run, confirmed by the exact simulation at the "
               "dense samples) and "
               "the schedule meets a proven optimality bound (tracking: its exact error at "
               "the dense samples is within 'tolerance' of 'lower_bound', which no schedule "
               "beats there; braking: it arrives within one period of the closed-form "
               "minimum time)")
    VERIFIED = ("verified: the exact model stays within 'prediction_bound' of the "
                "prediction (a proven bound over the whole run, confirmed by the exact "
                "simulation at the dense samples); not proven optimal (see 'lower_bound' and "
                "'gap')")
    UNVERIFIED = ("failed: the exact simulation of the schedule left the prediction bound "
                  "at a dense sample or did not finish; the schedule is returned for inspection but must not "
                  "be played (see 'message')")


@dataclass(frozen=True, eq=False)
class ScheduleResult:
    """A designed schedule, its predicted effect and a certificate.

    Attributes
    ----------
    times : ndarray of shape (K + 1,), s
        ``k * period``: row ``k`` of ``speeds`` is commanded on ``[times[k], times[k+1])``
        and the last row from ``times[K]`` on (it holds the final command).
    speeds : ndarray of shape (K + 1, n), m/s
        Commanded contact speeds, within the speed limits; with a lag or rate limit each
        command differs from the contact speed at the start of its period by at most
        ``r tau`` (``r * period`` without lag), so the motors never saturate their rate.
        With dynamic motors ``speeds[0]`` equals the plant's current commands (motors start
        settled there, see :class:`~toolkit.model.Plant`): new commands act from ``times[1]``.
    contact_speeds : ndarray of shape (K + 1, n), m/s
        Contact speeds of the motor model at ``times`` (closed form).
    body_speed : ndarray of shape (K + 1,), m/s
        Predicted body speed at ``times``: the smoothed model integrated at tight tolerance.
    reference : ndarray of shape (K + 1,), m/s
        Target body speed at ``times``.
    prediction_bound : float, m/s
        Every solution of the exact Coulomb model under these commands stays within this
        distance of the prediction on the whole of ``[0, times[-1]]``
        (:func:`~toolkit.schedule.verify.deviation_bound`: a rigorous bound of the defect
        integral plus an allowance for the predictor's integration error; exact up to
        floating-point rounding and CVODES honouring its local error tolerance).
    tracking_error : float, m/s
        ``max |body_speed - reference|`` over the prediction's dense samples (64 per period).
    objective : float
        The normalized objective evaluated on the prediction (not taken from the solver).
    arrival_time : float or None, s
        Braking: first dense sample time (64 per period) at which the exact simulation comes
        within ``prediction_bound`` of the target speed (None when it never does, or for
        tracking).
    minimum_time : float or None, s
        Braking: the closed-form minimum time of :func:`~toolkit.schedule.braking_time`
        when it applies.
    epsilon : float, m/s
        Smoothing width of the prediction's model: the requested ``epsilon``, or a quarter of
        it when the exact simulation left the first prediction's bound (a guard: the bound
        is proven, so only rounding, CVODES missing its tolerance or a simulator defect can
        trigger it).
    period : float, s
    model_mismatch : float, m/s
        ``max |V_design - body_speed|`` at ``times``: how far the designer's own model of
        the returned schedule (implicit steps of the exact law, or ipopt's smoothed RK4)
        lies from the prediction.
    iterations : int
        ipopt iterations (0 when the refinement did not run).
    solver_status : str
        ipopt's return status, ``"not run"`` when the constructive schedule was kept
        without refinement.
    status : ScheduleStatus
    message : str
    wall_time : float, s
        Time the design took, compiling kernels left out (the one-time cost is reported apart).
    method : str
        ``"constructive"`` or ``"constructive + ipopt"``: what produced the schedule.
    exact_tracking_error : float, m/s
        ``max |V_exact - reference|`` over the dense samples (64 per period), on the exact
        simulation.
    exact_deviation : float, m/s
        ``max |V_exact - V_pred|`` over the dense samples (64 per period) of the exact
        simulation (at most ``prediction_bound`` when verified; between the samples
        ``prediction_bound`` holds by proof).
    exact_body_speed : ndarray of shape (K + 1,), m/s
        The exact simulation's body speed at ``times`` (NaN when it did not finish): callers
        need not simulate the schedule again to check it.
    lower_bound : float or None, m/s
        Tracking: a lower bound on the sup tracking error at the dense samples (hence
        also over the whole run) of *every* schedule within the motor limits
        (``tracking_lower_bound`` on every fourth sample,
        the forced first period on all); None for braking as fast as possible.
    gap : float or None, m/s
        ``exact_tracking_error - lower_bound``.
    tolerance : float, m/s
        Gap below which a tracking schedule is reported OPTIMAL.
    """

    times: np.ndarray
    speeds: np.ndarray
    contact_speeds: np.ndarray
    body_speed: np.ndarray
    reference: np.ndarray
    prediction_bound: float
    tracking_error: float
    objective: float
    arrival_time: float | None
    minimum_time: float | None
    epsilon: float
    period: float
    model_mismatch: float
    iterations: int
    solver_status: str
    status: ScheduleStatus
    message: str
    wall_time: float
    method: str = "constructive"
    exact_tracking_error: float = math.nan
    exact_deviation: float = math.nan
    lower_bound: float | None = None
    gap: float | None = None
    tolerance: float = 0.0
    exact_body_speed: np.ndarray = field(default_factory=lambda: np.empty(0), repr=False)
    target: Any = field(default=None, repr=False)

    def __post_init__(self) -> None:
        for name in ("times", "speeds", "contact_speeds", "body_speed", "reference",
                     "exact_body_speed"):
            array = np.array(getattr(self, name), dtype=float)
            array.setflags(write=False)
            object.__setattr__(self, name, array)

    @property
    def n(self) -> int:
        """Number of contacts."""
        return int(self.speeds.shape[1])

    @property
    def success(self) -> bool:
        """True for OPTIMAL and VERIFIED: the exact simulation confirms the prediction."""
        return self.status in (ScheduleStatus.OPTIMAL, ScheduleStatus.VERIFIED)

    def as_commands(self) -> PiecewiseConstant:
        """The schedule as a :class:`~toolkit.model.PiecewiseConstant` for ``Plant(commands=...)``.

        Row ``k`` applies on ``[k period, (k + 1) period)`` (row 0 also before 0), the last
        row from ``K period`` on.
        """
        return PiecewiseConstant(self.times[1:], self.speeds)

    def to_rows(self) -> tuple[list[str], list[list[float]]]:
        """Header and rows for a CSV file firmware can play.

        Returns
        -------
        header : list of str
            ``["time_s", "speed_0_mps", ..., "speed_{n-1}_mps"]``.
        rows : list of list of float
            One row per period: start time (s), then the commanded speed of each contact
            (m/s), held until the next row's time (the last row: held from then on).
        """
        header = ["time_s"] + [f"speed_{i}_mps" for i in range(self.n)]
        rows = [[float(t), *map(float, row)] for t, row in zip(self.times, self.speeds)]
        return header, rows

    def to_dict(self) -> dict[str, Any]:
        """JSON-able summary with the table (``times``, ``speeds``) and the certificate."""
        def opt(value: float | None) -> float | None:
            return None if value is None else float(value)

        def finite(value: float) -> float | None:           # NaN/inf are not JSON
            return float(value) if math.isfinite(value) else None

        return {
            "period": float(self.period),
            "times": self.times.tolist(),
            "speeds": self.speeds.tolist(),
            "contact_speeds": self.contact_speeds.tolist(),
            "body_speed": self.body_speed.tolist(),
            "reference": self.reference.tolist(),
            "prediction_bound": float(self.prediction_bound),
            "tracking_error": float(self.tracking_error),
            "objective": float(self.objective),
            "arrival_time": opt(self.arrival_time),
            "minimum_time": opt(self.minimum_time),
            "epsilon": float(self.epsilon),
            "model_mismatch": float(self.model_mismatch),
            "iterations": int(self.iterations),
            "solver_status": self.solver_status,
            "status": self.status.name,
            "message": self.message,
            "wall_time": float(self.wall_time),
            "method": self.method,
            "exact_tracking_error": finite(self.exact_tracking_error),
            "exact_deviation": finite(self.exact_deviation),
            "exact_body_speed": [finite(x) for x in self.exact_body_speed],
            "lower_bound": opt(self.lower_bound),
            "gap": opt(self.gap),
            "tolerance": float(self.tolerance),
        }
