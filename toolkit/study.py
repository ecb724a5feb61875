"""Run the stages a scene declares (numerics only: no files, no plots, no building).

``run_study(scene)`` always computes the force-speed curve; it adds the encoder summary
when the scene has ``[sensors]``, the allocation when it has ``[target]`` and the
simulation when it has ``[simulation]``. A stage that is not declared is not run, and the
packages only it needs are not imported. When a scene has both a target and a simulation,
the simulation runs on the allocated contact speeds: the design is checked by simulating it.
A ``[schedule]`` is designed and then simulated exactly under its own commands.

Every object a stage needs (contacts, motors, plant, encoders, targets) comes from
``scene.objects`` (:mod:`toolkit.scene_build`), built once when the scene was loaded.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from .allocation import AllocationResult, allocate
from .model import ContactSet
from .scene import Scene
from .schedule import ScheduleResult, design_schedule
from .simulation import SimulationResult, simulate

__all__ = ["CurveSamples", "StudyResult", "force_curve", "run_study",
           "allocate_scene", "design_scene_schedule"]


@dataclass(frozen=True)
class CurveSamples:
    """Samples of a contact set's force-speed curve.

    Attributes
    ----------
    speeds : ndarray of shape (M,), m/s
        Body speeds, ascending; every contact speed is included so the steps are exact.
    force : ndarray of shape (M,), N
        ``F(V)``; at a contact speed the midpoint of the set-valued force.
    lower, upper : ndarray of shape (M,), N
        The set-valued force interval at each speed.
    equilibrium : tuple of float, m/s
        The weighted-median set ``(lo, hi)``.
    total_force : float, N
    """

    speeds: np.ndarray
    force: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    equilibrium: tuple[float, float]
    total_force: float

    def to_dict(self) -> dict[str, Any]:
        """JSON-able form: ``speeds``, ``force``, ``equilibrium`` as ``[lo, hi]``, ``total_force``."""
        return {"speeds": self.speeds.tolist(), "force": self.force.tolist(),
                "equilibrium": list(self.equilibrium), "total_force": self.total_force}


def force_curve(contacts: ContactSet, points: int = 801, *, margin: float | None = None) -> CurveSamples:
    """Sample ``F(V)`` over the contact speeds widened by ``margin`` on both sides.

    Parameters
    ----------
    contacts : ContactSet
    points : int
        Evenly spaced samples (the contact speeds are added to them), >= 2.
    margin : float, m/s, optional
        Widening beyond the slowest and fastest contact; default 15 % of the spread
        (0.1 m/s when every contact has one speed).
    """
    lo, hi = float(contacts.speeds.min()), float(contacts.speeds.max())
    if margin is None:
        margin = 0.15 * (hi - lo) if hi > lo else 0.1
    grid = np.union1d(np.linspace(lo - margin, hi + margin, points), contacts.speeds)
    lower, upper = contacts.force_bounds(grid)
    return CurveSamples(grid, contacts.force(grid), lower, upper, contacts.equilibrium(), contacts.total_force)


@dataclass(frozen=True)
class StudyResult:
    """What :func:`run_study` computed; ``None`` for stages the scene does not declare."""

    scene: Scene
    contacts: ContactSet
    curve: CurveSamples
    sensors: dict[str, dict[str, float]] | None = None
    allocation: AllocationResult | None = None
    schedule: ScheduleResult | None = None
    schedule_check: SimulationResult | None = None
    simulation: SimulationResult | None = None

    @property
    def stages(self) -> tuple[str, ...]:
        """The stages that ran."""
        return self.scene.stages


def _sensors(scene: Scene) -> dict[str, dict[str, float]]:
    return {name: encoder.summary() for name, encoder in scene.objects.encoders.items()}


def allocate_scene(scene: Scene, contacts: ContactSet | None = None) -> AllocationResult:
    """Solve a scene's ``[target]`` under its ``[motors]`` limits and compliance; see :func:`toolkit.allocate`.

    Parameters
    ----------
    scene : Scene
        Needs ``[target]``.
    contacts : ContactSet, optional
        Start from these contacts instead of the declared ones.
    """
    spec, motors = scene.target, scene.objects.motors
    limits = motors.speed_limits if motors is not None else None
    rate = motors.rate_limit if motors is not None and spec.dt is not None else None
    return allocate(scene.objects.target, contacts if contacts is not None else scene.objects.contacts,
                    speed_limits=limits, rate_limit=rate, dt=spec.dt, fixed=list(spec.fixed),
                    failed=list(spec.failed), liftable=list(spec.liftable), method=spec.method,
                    strict=spec.strict, time_limit=spec.time_limit,
                    compliance=motors.compliance if motors is not None else 0.0)


def design_scene_schedule(scene: Scene, contacts: ContactSet | None = None
                          ) -> tuple[ScheduleResult, SimulationResult]:
    """Design the scene's ``[schedule]`` and verify it with the exact simulator.

    Parameters
    ----------
    scene : Scene
        Needs ``[schedule]`` and ``[body]``.
    contacts : ContactSet, optional
        Design on these contacts (e.g. allocated ones) instead of the declared ones.

    Returns
    -------
    (ScheduleResult, SimulationResult)
        The design, and the exact nonsmooth simulation of the plant under its commands.
    """
    spec = scene.schedule
    plant = scene.objects.plant_on(contacts)
    result = design_schedule(plant, scene.objects.schedule_target, v0=spec.v0, horizon=spec.horizon,
                             period=spec.period, epsilon=spec.epsilon, time_limit=spec.time_limit)
    check = simulate(replace(plant, commands=result.as_commands()), float(result.times[-1]),
                     v0=spec.v0, t_eval=result.times)
    return result, check


def _simulation(scene: Scene, contacts: ContactSet) -> SimulationResult:
    spec = scene.simulation
    return simulate(scene.objects.plant_on(contacts), spec.t_end, v0=spec.v0, method=spec.method,
                    **spec.options)


def run_study(scene: Scene) -> StudyResult:
    """Run every stage the scene declares and return their results.

    Parameters
    ----------
    scene : Scene
        From :func:`toolkit.load_scene`.

    Returns
    -------
    StudyResult
    """
    contacts = scene.objects.contacts
    points = scene.report.curve_points if scene.report is not None else 801
    sensors = _sensors(scene) if scene.sensors is not None else None
    allocation = None
    if scene.target is not None:
        allocation = allocate_scene(scene, contacts)
        contacts = allocation.contacts
    schedule = check = None
    if scene.schedule is not None:
        schedule, check = design_scene_schedule(scene, contacts)
    simulation = _simulation(scene, contacts) if scene.simulation is not None else None
    return StudyResult(scene, contacts, force_curve(contacts, points), sensors, allocation,
                       schedule, check, simulation)
