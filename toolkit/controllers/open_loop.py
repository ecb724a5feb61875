"""Open loop: replay a contact-speed schedule, whatever the estimate says."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import ParameterError, ParameterTypeError, parameter_message
from ..model import PiecewiseConstant, Plant
from ..simulation import SampledLaw
from .base import Action, StatelessLaw

__all__ = ["OpenLoop"]


@dataclass(frozen=True, eq=False)
class OpenLoop:
    """Send a precomputed schedule.

    Parameters
    ----------
    schedule : PiecewiseConstant (vector of width n) or ScheduleResult
        Commanded contact speeds over time, m/s; a
        :class:`~toolkit.schedule.ScheduleResult` (from
        :func:`~toolkit.schedule.design_schedule`) is replayed row ``k`` on
        ``[times[k], times[k+1])``.
    """

    schedule: Any

    def __post_init__(self) -> None:
        schedule = self.schedule
        if not isinstance(schedule, PiecewiseConstant):
            times, speeds = getattr(schedule, "times", None), getattr(schedule, "speeds", None)
            if times is None or speeds is None:
                raise ParameterTypeError(parameter_message(
                    "schedule", "OpenLoop", "be a PiecewiseConstant or a ScheduleResult", schedule))
            schedule = PiecewiseConstant(np.asarray(times)[1:], np.asarray(speeds))
        if schedule.width is None:
            raise ParameterError(parameter_message(
                "schedule", "OpenLoop", "be a vector signal (one column per contact)",
                f"values of shape {schedule.values.shape}"))
        object.__setattr__(self, "schedule", schedule)

    def bind(self, plant: Plant, period: float) -> _OpenLoopLaw:
        if self.schedule.width != plant.n:
            raise ParameterError(parameter_message(
                "schedule", "OpenLoop", f"have one column per contact ({plant.n})",
                f"{self.schedule.width} columns"))
        return _OpenLoopLaw(self.schedule)


class _OpenLoopLaw(StatelessLaw):
    def __init__(self, schedule: PiecewiseConstant) -> None:
        self.schedule = schedule

    def output(self, t: float, z: np.ndarray, estimate: float) -> Action:
        return Action(self.schedule(t))

    def sampled(self) -> SampledLaw:
        """The schedule's table (rows between its switching times)."""
        return SampledLaw(self.schedule.values, self.schedule.times)
