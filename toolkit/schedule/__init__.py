"""Contact-speed schedules: time-varying commands that take the body along a target.

- :mod:`~toolkit.schedule.targets`: what the body should do (:class:`SpeedTrajectory`,
  :class:`Braking`);
- :mod:`~toolkit.schedule.result`: the designed schedule and its certificate
  (:class:`ScheduleResult`, :class:`ScheduleStatus`);
- :mod:`~toolkit.schedule.braking`: the minimum braking time in closed form
  (:func:`braking_time`);
- :mod:`~toolkit.schedule.commands`: the motor settings of a design, commands projected
  onto them;
- :mod:`~toolkit.schedule.construct`: the constructive schedule (closed-form candidates on
  the exact Coulomb law) and the lower bound on every schedule's tracking error;
- :mod:`~toolkit.schedule.verify`: prediction on the smoothed law, the proven bound to the
  exact model (:func:`deviation_bound`), the exact simulation as a second method;
- :mod:`~toolkit.schedule.design`: :func:`design_schedule`, the one verb over all of these.
"""

from __future__ import annotations

from .braking import braking_time
from .design import design_schedule
from .result import ScheduleResult, ScheduleStatus
from .targets import Braking, SpeedTrajectory
from .verify import deviation_bound

__all__ = ["SpeedTrajectory", "Braking", "ScheduleStatus", "ScheduleResult", "design_schedule",
           "braking_time", "deviation_bound"]
