"""The design stages of a study, each on a scene or on the objects built from it: the
force-speed curve, allocation, the schedule and the simulation, with the shortfalls each can
report (those known before any work are ``request_shortfalls``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ..allocation import (AllocationResult, AllocationStatus, EquilibriumSpeed, FrictionFraction,
                         allocate, build_problem)
from ..errors import ParameterError
from ..model import ContactSet
from .build import SceneObjects, build_scene
from .spec import Scene
from ..schedule import Braking, ScheduleResult, ScheduleStatus, design_schedule
from ..shortfall import Shortfall
from ..simulation import SimulationResult, SimulationStatus, simulate


@dataclass(frozen=True)
class CurveStep:
    """One step of a Coulomb staircase: the force just below and just above a contact speed.

    Attributes
    ----------
    speed : float, m/s
    force_below, force_above : float, N
        ``F(speed-)`` and ``F(speed+)`` (``force_below >= force_above``).
    """

    speed: float
    force_below: float
    force_above: float

    def to_dict(self) -> dict[str, float]:
        """``{speed, force_below, force_above}``."""
        return {"speed": self.speed, "force_below": self.force_below, "force_above": self.force_above}


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
    steps : tuple of CurveStep
        Every distinct contact speed, ascending, with the exact force just below and just
        above it: the whole staircase (between two steps ``F`` is constant).
    """

    speeds: np.ndarray
    force: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    equilibrium: tuple[float, float]
    total_force: float
    steps: tuple[CurveStep, ...] = ()

    def to_dict(self) -> dict[str, Any]:
        """JSON-able form: ``speeds``, ``force``, ``equilibrium`` as ``[lo, hi]``,
        ``total_force`` and ``steps`` (a list of ``{speed, force_below, force_above}``)."""
        return {"speeds": self.speeds.tolist(), "force": self.force.tolist(),
                "equilibrium": list(self.equilibrium), "total_force": self.total_force,
                "steps": [step.to_dict() for step in self.steps]}


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
    distinct = np.unique(contacts.speeds)
    below, above = contacts.force_bounds(distinct)[::-1]       # F(v-) = upper, F(v+) = lower
    steps = tuple(CurveStep(float(v), float(b), float(a)) for v, b, a in zip(distinct, below, above))
    return CurveSamples(grid, contacts.force(grid), lower, upper, contacts.equilibrium(),
                        contacts.total_force, steps)


def _built(scene: Scene | SceneObjects) -> SceneObjects:
    """The objects of a scene: given, or built now."""
    return scene if isinstance(scene, SceneObjects) else build_scene(scene)


def _spec(scene: Scene | SceneObjects) -> Scene:
    """The parsed scene, given or behind its objects (nothing is built)."""
    return scene.scene if isinstance(scene, SceneObjects) else scene


def allocate_scene(scene: Scene | SceneObjects, contacts: ContactSet | None = None, *,
                   strict: bool = False) -> AllocationResult:
    """Solve a scene's ``[target]`` under its ``[motors]`` limits and compliance; see :func:`toolkit.allocate`.

    Parameters
    ----------
    scene : Scene or SceneObjects
        Needs ``[target]``.
    contacts : ContactSet, optional
        Start from these contacts instead of the declared ones.
    strict : bool
        Refuse a target that needs projection or lies beyond the contacts' reach
        (:class:`~toolkit.errors.ParameterError`), as ``[target] strict = true`` does.
    """
    objects = _built(scene)
    motors = objects.motors
    return allocate(objects.target, contacts if contacts is not None else objects.contacts,
                    method=objects.scene.target.method,
                    compliance=motors.compliance if motors is not None else 0.0,
                    **_allocation_arguments(objects, strict))


def _allocation_arguments(objects: SceneObjects, strict: bool = False) -> dict[str, Any]:
    spec, motors = objects.scene.target, objects.motors
    limits = motors.speed_limits if motors is not None else None
    rate = motors.rate_limit if motors is not None and spec.dt is not None else None
    return dict(speed_limits=limits, rate_limit=rate, dt=spec.dt, fixed=list(spec.fixed),
                failed=list(spec.failed), liftable=list(spec.liftable),
                strict=spec.strict or strict, time_limit=spec.time_limit)


def design_scene_schedule(scene: Scene | SceneObjects, contacts: ContactSet | None = None
                          ) -> tuple[ScheduleResult, SimulationResult]:
    """Design the scene's ``[schedule]`` and verify it with the exact simulator.

    Parameters
    ----------
    scene : Scene or SceneObjects
        Needs ``[schedule]`` and ``[body]``.
    contacts : ContactSet, optional
        Design on these contacts (e.g. allocated ones) instead of the declared ones.

    Returns
    -------
    (ScheduleResult, SimulationResult)
        The design, and the exact nonsmooth simulation of the plant under its commands.
    """
    objects = _built(scene)
    spec = objects.scene.schedule
    plant = objects.plant_on(contacts)
    result = design_schedule(plant, objects.schedule_target, v0=spec.v0, horizon=spec.horizon,
                             period=spec.period, epsilon=spec.epsilon, time_limit=spec.time_limit)
    check = simulate(replace(plant, commands=result.as_commands()), float(result.times[-1]),
                     v0=spec.v0, t_eval=result.times)
    return result, check


def _simulation(objects: SceneObjects, contacts: ContactSet, fraction: float = 1.0) -> SimulationResult:
    """The scene's ``[simulation]`` (over ``fraction`` of its horizon: the warm-up run)."""
    spec = objects.scene.simulation
    return simulate(objects.plant_on(contacts), fraction * spec.t_end, v0=spec.v0,
                    method=spec.method, **objects.simulation_options)


# -- shortfalls ----------------------------------------------------------------------------------

def _limits(objects: SceneObjects) -> tuple[float, float]:
    motors = objects.motors
    return motors.speed_limits if motors is not None else (-math.inf, math.inf)


def _beyond(values: Any, limits: tuple[float, float]) -> tuple[float, float] | None:
    """The value farthest beyond ``limits`` and the limit it passes, or None."""
    values = np.atleast_1d(np.asarray(values, dtype=float))
    low, high = limits
    excess = np.maximum(values - high, low - values)
    i = int(np.argmax(excess))
    if excess[i] <= 0:
        return None
    return float(values[i]), high if values[i] > high else low


def _allocation_refusal(objects: SceneObjects, contacts: ContactSet) -> str | None:
    """Why ``allocate(..., strict=True)`` would refuse the scene's target (None if it would not).

    Only builds the problem (no solve): the realizability rules are checked there.
    """
    try:
        build_problem(objects.target, contacts, **_allocation_arguments(objects, strict=True))
    except ParameterError as error:
        return str(error)
    return None


def request_shortfalls(scene: Scene | SceneObjects) -> list[Shortfall]:
    """The shortfalls a scene's request implies before any work: clipped speeds (stage
    ``"scene"``), a target that needs projection or lies beyond reach (``"allocation"``),
    a schedule target beyond the speed limits (``"schedule"``). Amounts that only a solve
    gives are NaN here."""
    objects = _built(scene)
    found = [Shortfall("scene", f"{clip.count} speed(s) in {clip.key!r} beyond the motors' speed limit "
                       f"clipped: {clip.value:g} m/s to {clip.limit:g} m/s (excess {clip.excess:.3g} m/s)",
                       clip.excess, "m/s") for clip in objects.clipped]
    if objects.target is not None:
        refusal = _allocation_refusal(objects, objects.contacts)
        if refusal is not None:
            found.append(Shortfall("allocation", f"the target is not realizable: {refusal}",
                                   math.nan, "N"))
    target = objects.schedule_target
    if target is not None:
        values = target.speed if isinstance(target, Braking) else target.speeds
        beyond = _beyond(values, _limits(objects))
        if beyond is not None:
            found.append(Shortfall("schedule", f"unreachable: the target speed {beyond[0]:g} m/s exceeds "
                                   f"the speed limit {beyond[1]:g} m/s", abs(beyond[0] - beyond[1]),
                                   "m/s"))
    return found


def allocation_shortfalls(scene: Scene | SceneObjects, result: AllocationResult,
                          contacts: ContactSet | None = None) -> list[Shortfall]:
    """How an allocation of the scene's ``[target]`` missed it (an empty list when it did not).

    A projected target (its distance to the projection, N), a target the contacts cannot
    reach (the certified best achievable error, N), or no allocation at all (infeasible,
    time limit, solver error; the achieved error, N).
    """
    objects = _built(scene)
    found: list[Shortfall] = []
    target, projection = objects.target, result.projection
    if projection is not None:
        distance = float(projection.distance_sup)
        if isinstance(target, FrictionFraction):
            level = float(np.max(np.abs(projection.curve.forces))) / float(result.contacts.total_force)
            what = (f"friction fraction {target.fraction:g} is not realizable: projected to "
                    f"{math.copysign(level, target.fraction):.6g} (distance {distance:.3g} N)")
        elif isinstance(target, EquilibriumSpeed):
            xs, ys = projection.curve.speeds, projection.curve.forces
            what = (f"equilibrium speed {target.speed:g} m/s is beyond the contacts' reach: "
                    f"projected to {float(xs[np.argmax(ys <= 0)]):g} m/s (distance {distance:.3g} N)")
        else:
            what = (f"the {objects.scene.target.kind} target is not realizable ({', '.join(projection.reasons)}): "
                    f"projected (distance {distance:.3g} N)")
        found.append(Shortfall("allocation", what, distance, "N"))
    elif (refusal := _allocation_refusal(objects, contacts if contacts is not None
                                         else objects.contacts)) is not None:
        found.append(Shortfall("allocation", f"unreachable: best achievable error {result.bound:.3g} N "
                               f"({refusal})", float(result.bound), "N"))
    if result.status in (AllocationStatus.INFEASIBLE, AllocationStatus.TIME_LIMIT,
                         AllocationStatus.SOLVER_ERROR):
        found.append(Shortfall("allocation", f"{result.status.name.lower()}: {result.status.value} "
                               f"(sup error {result.error_sup:.3g} N, gap {result.gap:.3g} N)",
                               float(result.error_sup), "N"))
    return found


def schedule_shortfalls(scene: Scene | SceneObjects, result: ScheduleResult,
                        check: SimulationResult) -> list[Shortfall]:
    """How a designed schedule missed the scene's ``[schedule]`` (an empty list when it did not).

    A target beyond the speed limits (``"unreachable: best achievable error X m/s, because
    the target exceeds the speed limit Y m/s"``: the schedule's certified lower bound, or
    its exact error without one), an unverified schedule (its deviation beyond the
    prediction bound), a schedule whose exact check a budget stopped (never a pass: a budget is a
    guard, not a verdict) and a braking target not reached (the final distance to it).
    A VERIFIED schedule that is not proven optimal is a success.
    """
    objects = _built(scene)
    found: list[Shortfall] = []
    target = objects.schedule_target
    values = target.speed if isinstance(target, Braking) else target.speeds
    beyond = _beyond(values, _limits(objects))
    if beyond is not None:
        if isinstance(target, Braking):
            best = abs(beyond[0] - beyond[1])
        else:
            best = float(result.lower_bound if result.lower_bound is not None else result.exact_tracking_error)
        found.append(Shortfall("schedule", f"unreachable: best achievable error {best:.3g} m/s, because "
                               f"the target exceeds the speed limit {beyond[1]:g} m/s "
                               f"(target speed {beyond[0]:g} m/s)", best, "m/s"))
    if not check.success:             # a budget stopped the exact check: never a pass
        found.append(Shortfall("schedule", f"unchecked: the exact simulation of the schedule stopped "
                               f"({check.message}); the schedule must not be played", math.nan, ""))
    elif result.status is ScheduleStatus.UNVERIFIED:
        deviation = float(result.exact_deviation)
        excess = deviation - float(result.prediction_bound) if math.isfinite(deviation) else math.nan
        found.append(Shortfall("schedule", f"unverified: the exact simulation ({check.status.value}) left the "
                               f"prediction bound {result.prediction_bound:.3g} m/s "
                               f"(deviation {deviation:.3g} m/s); the schedule must not be played",
                               excess, "m/s"))
    elif isinstance(target, Braking) and beyond is None and result.arrival_time is None:
        final = float(result.exact_body_speed[-1]) if result.exact_body_speed.size else math.nan
        miss = abs(final - target.speed)
        found.append(Shortfall("schedule", f"not reached: the braking target {target.speed:g} m/s is "
                               f"{miss:.3g} m/s away at the end of the schedule", miss, "m/s"))
    return found


def simulation_shortfalls(scene: Scene | SceneObjects, result: SimulationResult) -> list[Shortfall]:
    """A simulation that stopped before ``t_end`` (the simulated time left, s)."""
    if result.status is SimulationStatus.SUCCESS:
        return []
    t_end, reached = _spec(scene).simulation.t_end, float(result.t[-1]) if len(result.t) else 0.0
    return [Shortfall("simulation", f"{result.status.value} at t = {reached:.6g} s of t_end = {t_end:g} s "
                      f"({t_end - reached:.6g} s not simulated)", t_end - reached, "s")]
