"""Run the stages a scene declares (numerics only: no files, no plots).

``run_study(scene)`` always computes the force-speed curve; it adds the encoder summary
when the scene has ``[sensors]``, the allocation when it has ``[target]`` and the
simulation when it has ``[simulation]``. A stage that is not declared is not run, and the
packages only it needs are not imported. When a scene has both a target and a simulation,
the simulation runs on the allocated contact speeds: the design is checked by simulating it.
A ``[schedule]`` is designed and then simulated exactly under its own commands.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from .model import ContactSet
from .scene import Scene

__all__ = ["CurveSamples", "StudyResult", "force_curve", "run_study", "scene_plant",
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
    allocation: Any = None
    schedule: Any = None
    schedule_check: Any = None
    simulation: Any = None

    @property
    def stages(self) -> tuple[str, ...]:
        """The stages that ran."""
        return self.scene.stages


def _sensors(scene: Scene) -> dict[str, dict[str, float]]:
    from .model import Encoder

    spec = scene.sensors
    out: dict[str, dict[str, float]] = {}
    if spec.wheel_counts_per_rev is not None:
        out["wheel"] = Encoder(spec.wheel_counts_per_rev, spec.wheel_radius, spec.rate,
                               spec.wheel_backlash).summary()
    if spec.central_counts_per_rev is not None:
        out["central"] = Encoder(spec.central_counts_per_rev, spec.contact_radius, spec.rate).summary()
    return out


def _motors(scene: Scene):
    from .model import Motors

    spec = scene.motors
    if spec is None:
        return None
    return Motors(lag=spec.lag, rate_limit=spec.rate_limit, speed_limits=spec.speed_limits,
                  compliance=spec.compliance)


def _signal(value: Any):
    from .model import PiecewiseConstant

    if isinstance(value, dict):
        return PiecewiseConstant(np.asarray(value["times"]), np.asarray(value["values"], dtype=float))
    return value


def scene_plant(scene: Scene, contacts: ContactSet | None = None):
    """The :class:`~toolkit.Plant` a scene declares (needs ``[body]``), optionally on other contacts."""
    from .errors import SceneError
    from .model import Plant

    if scene.body is None:
        raise SceneError("This stage needs a [body] section (the moving inertia).")
    commands = None
    if scene.simulation is not None and scene.simulation.commands is not None:
        commands = _signal(scene.simulation.commands)
    return Plant(contacts if contacts is not None else scene.contact_set(), scene.body.moving_mass,
                 damping=scene.body.damping, external_force=_signal(scene.body.external_force),
                 motors=_motors(scene), commands=commands)


def allocate_scene(scene: Scene, contacts: ContactSet | None = None):
    """Solve a scene's ``[target]`` under its ``[motors]`` limits and compliance; see :func:`toolkit.allocate`."""
    from .allocation import allocate

    spec = scene.target
    motors = scene.motors
    limits = motors.speed_limits if motors is not None else None
    rate = motors.rate_limit if motors is not None and spec.dt is not None else None
    return allocate(scene.target.build(), contacts if contacts is not None else scene.contact_set(),
                    speed_limits=limits, rate_limit=rate, dt=spec.dt, fixed=list(spec.fixed),
                    failed=list(spec.failed), liftable=list(spec.liftable), method=spec.method,
                    strict=spec.strict, time_limit=spec.time_limit,
                    compliance=motors.compliance if motors is not None else 0.0)


def design_scene_schedule(scene: Scene, contacts: ContactSet | None = None):
    """Design the scene's ``[schedule]`` and verify it with the exact simulator.

    Returns
    -------
    (ScheduleResult, SimulationResult)
        The design, and the exact nonsmooth simulation of the plant under its commands.
    """
    from dataclasses import replace

    from .schedule import design_schedule
    from .simulation import simulate

    spec = scene.schedule
    plant = scene_plant(scene, contacts)
    result = design_schedule(plant, spec.build(), v0=spec.v0, horizon=spec.horizon,
                             period=spec.period, epsilon=spec.epsilon, time_limit=spec.time_limit)
    check = simulate(replace(plant, commands=result.as_commands()), float(result.times[-1]),
                     v0=spec.v0, t_eval=result.times)
    return result, check


def _simulation(scene: Scene, contacts: ContactSet):
    from .simulation import simulate

    spec = scene.simulation
    return simulate(scene_plant(scene, contacts), spec.t_end, v0=spec.v0, method=spec.method, **spec.options)


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
    contacts = scene.contact_set()
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
