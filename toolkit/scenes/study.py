"""Run the stages a scene declares (numerics only: no files, no plots, no building).

:func:`run_study` computes the force-speed curve and each declared stage (encoders, allocation,
simulation, schedule, estimation, closed loop) on the objects
:func:`~toolkit.scenes.build.build_scene` makes once per run; a stage not declared is not run
and the packages only it needs are not imported. With a target and a simulation, the
simulation runs on the allocated speeds; a schedule is designed, then simulated exactly. Each
way a finished study misses its request is a :class:`Shortfall` (listed on :func:`run_study`);
those known before any work are :func:`request_shortfalls`, refused with ``strict=True``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from .._compiled import compile_seconds, warm
from ..allocation import (AllocationResult, AllocationStatus, EquilibriumSpeed, FrictionFraction,
                         allocate, build_problem)
from ..errors import ParameterError, SceneError
from ..model import ContactSet, Plant, sample_count
from .build import SceneObjects, build_scene
from .spec import ReportSpec, Scene
from ..schedule import Braking, ScheduleResult, ScheduleStatus, design_schedule
from ..analysis.scenarios import grid_positions, record_world
from ..model.truth import realize
from ..shortfall import Shortfall
from ..simulation import SimulationResult, SimulationStatus, simulate

__all__ = ["CurveSamples", "CurveStep", "Shortfall", "StudyResult", "force_curve", "run_study",
           "allocate_scene", "design_scene_schedule", "request_shortfalls", "allocation_shortfalls",
           "schedule_shortfalls", "simulation_shortfalls", "EstimationStudy", "ControlStudy",
           "estimate_scene", "estimate_record", "control_scene", "control_world", "estimation_shortfalls",
           "control_shortfalls", "sweep_scene", "sweep_shortfalls", "planar_scene",
           "planar_precision", "check_sweep_table"]


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


@dataclass(frozen=True)
class StudyResult:
    """What :func:`run_study` computed; ``None`` for stages the scene does not declare.

    ``contacts`` are those the study ran on (the allocated ones when the scene has a
    ``[target]``) and ``plant`` the scene's plant on them (None without ``[body]``).
    """

    scene: Scene
    contacts: ContactSet
    curve: CurveSamples
    sensors: dict[str, dict[str, float]] | None = None
    allocation: AllocationResult | None = None
    schedule: ScheduleResult | None = None
    schedule_check: SimulationResult | None = None
    simulation: SimulationResult | None = None
    shortfalls: tuple[Shortfall, ...] = ()
    estimation: EstimationStudy | None = None
    control: ControlStudy | None = None
    plant: Plant | None = None
    #: Seconds spent compiling kernels during the study (numba's compile events: 0 when every
    #: kernel came from the cache); in no ``wall_time`` of the result.
    compile_time: float = 0.0

    @property
    def stages(self) -> tuple[str, ...]:
        """The stages that ran."""
        return self.scene.stages

    @property
    def met(self) -> bool:
        """True when the study met every request (no shortfall)."""
        return not self.shortfalls


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


# -- estimation and the closed loop -------------------------------------------------------------

@dataclass(frozen=True, eq=False)
class EstimationStudy:
    """Every estimator of ``[estimation]`` over one simulated encoder record.

    Attributes
    ----------
    record : EncoderRecord
        The counts, commands and, when simulated, the truth (body speed and position,
        contact speeds).
    results : tuple of EstimationResult
        One per method, in the scene's order, scored against the truth when there is one.
    simulation : SimulationResult or None
        The exact run that was recorded (None for a recorded file).
    plant : Plant or None
        The plant simulated: the true world's (None for a recorded file).
    compile_time : float, s
        The one-time cost paid before the estimators were timed (the kernels compiled and
        each estimator run once over the record, untimed: the policy of
        :mod:`toolkit._compiled`); in no estimator's ``wall_time``.
    monitors : tuple of (str or None)
        Per result, the consistency monitor's verdict (``"consistent"``, or when and why the
        estimator left its nominal model); None for estimators without a monitor.
    """

    record: Any
    results: tuple[Any, ...]
    simulation: SimulationResult | None
    plant: Any
    compile_time: float = 0.0
    monitors: tuple[str | None, ...] = ()

    @property
    def duration(self) -> float:
        """The record's length, s."""
        return self.record.duration

    def rows(self) -> list[dict[str, Any]]:
        """Per estimator: ``name``, ``rms``, ``max_error`` (m/s), ``rms_phases`` (m/s per
        phase: startup, cruise, brake, braked), ``nees_mean`` (None without a covariance or
        the truth), its 95 % ``nees_band``, ``nees_in_band`` (the share of samples whose NEES
        lies in the 95 % chi-square(2) interval), ``nees_over_100`` (the share above 100:
        gross overconfidence) and ``nees_max``, ``nis_mean``, ``monitor`` (the consistency
        monitor's verdict), ``missed_count_prob`` and ``missed_count_std`` (the encoders'
        missed-count rate the position was reported under, told or identified; None where an
        estimator does not use it), ``wall_time`` (s) and ``real_time_ratio``."""
        monitors = self.monitors or (None,) * len(self.results)
        return [{"name": r.method, "rms": r.rms_error, "max_error": r.max_error,
                 "rms_phases": None if r.rms_phases is None else dict(r.rms_phases),
                 "nees_mean": r.nees_mean, "nees_band": r.nees_band, "nees_in_band": r.nees_in_band,
                 "nees_over_100": r.nees_over_100, "nees_max": r.nees_max,
                 "nis_mean": r.nis_mean, "monitor": monitor, "missed_count_prob": r.missed_count_prob,
                 "missed_count_std": r.missed_count_std, "wall_time": r.wall_time,
                 "real_time_ratio": r.real_time_ratio} for r, monitor in zip(self.results, monitors)]


def estimate_scene(scene: Scene | SceneObjects, simulation: SimulationResult | None = None
                   ) -> EstimationStudy:
    """Simulate, record and estimate as the scene's ``[estimation]`` declares.

    Parameters
    ----------
    scene : Scene or SceneObjects
        Needs ``[estimation]`` (and so ``[sensors]`` and ``[body]``).
    simulation : SimulationResult, optional
        For ``scenario = "simulation"``: the scene's ``[simulation]`` run when already
        computed (the study passes its own); otherwise it is run here.

    Returns
    -------
    EstimationStudy
        One result per method and, when the scene has ``[estimation.truth]``, last, the
        default told that true world (:func:`~toolkit.estimation.truth_told`, named
        ``truth_told``: the reference of what is achievable).

    Notes
    -----
    The encoders' count grids start where ``[estimation] seed`` puts them
    (:func:`~toolkit.analysis.scenarios.grid_positions`): each seed is another phase of the
    quantization, so a nominal scene too gives other records for other seeds.
    """
    from ..estimation import truth_told
    from ..model.sensors import record_simulation

    built = _built(scene)
    spec, objects = built.scene.estimation, built.estimation
    if spec is None or objects is None:
        raise SceneError(f"The scene {built.scene.name!r} has no [estimation] section.")
    plant, told = objects.plant, None
    grid = grid_positions(objects.sensors, spec.seed)     # the seed's phase of the count grids
    if spec.scenario == "simulation" and objects.truth.is_nominal:      # the scene's own run
        run = simulation if simulation is not None else _simulation(built, built.contacts)
        record = record_simulation(run, plant, objects.sensors, rng=np.random.default_rng(spec.seed), **grid)
    else:     # the true world ([estimation.truth]; the scene itself when it says nothing)
        world = realize(plant, objects.sensors, objects.truth, spec.seed)
        run, record = record_world(world, objects.duration, seed=spec.seed, v0=objects.v0, **grid)
        plant = world.plant
        if spec.truth is not None:        # the default told this world: the reference
            told = truth_told(world, initial_covariance=None if spec.initial_covariance is None
                              else np.array(spec.initial_covariance))
    return _run_estimators(objects, spec, record, run, plant, told)


def estimate_record(scene: Scene | SceneObjects, record: Any) -> EstimationStudy:
    """Run the scene's ``[estimation]`` estimators over a recorded file's ``record`` (no truth:
    estimates, NIS and the monitor's verdict; no simulation).

    Parameters
    ----------
    scene : Scene or SceneObjects
        Needs ``[estimation]`` (the estimators, the model and the prior).
    record : EncoderRecord
        From :func:`toolkit.model.record_io.read_record_csv`; its channels must match the
        scene's contacts.
    """
    built = _built(scene)
    spec, objects = built.scene.estimation, built.estimation
    if spec is None or objects is None:
        raise SceneError(f"The scene {built.scene.name!r} has no [estimation] section.")
    if record.wheel_counts.shape[1] != built.contacts.n:
        raise SceneError(f"The record has {record.wheel_counts.shape[1]} wheel channels; the scene "
                         f"{built.scene.name!r} has {built.contacts.n} contacts.")
    return _run_estimators(objects, spec, record, None, None)


def _run_estimators(objects: Any, spec: Any, record: Any, run: SimulationResult | None,
                    plant: Any, told: Any = None) -> EstimationStudy:
    """Every estimator over ``record``, each timed on compiled code (warmed first, untimed),
    then ``told`` (the default told the true world) when there is one."""
    compile_time = warm(None, "core", "lines")     # every wall time below: compiled code
    results, monitors = [], []
    for estimator in [*objects.estimators.values(), *([] if told is None else [told])]:
        compile_time += warm(lambda: estimator.warm_up(record))
        results.append(estimator.run(record, speed=objects.v0, speed_std=spec.speed_std))
        monitors.append(_verdict(estimator))
    return EstimationStudy(record, tuple(results), run, plant, compile_time, tuple(monitors))


def _verdict(estimator: Any) -> str | None:
    """What an estimator's consistency monitor concluded over its last run (None: no monitor)."""
    if not hasattr(estimator, "tripped"):
        return None
    if estimator.tripped is None:
        return "consistent: the nominal model held throughout"
    time_, reason = estimator.tripped
    return f"left the nominal model at t = {time_:.3f} s ({reason})"


def estimation_shortfalls(scene: Scene | SceneObjects, study: EstimationStudy) -> list[Shortfall]:
    """A recorded run that stopped before its end (the time not recorded, s)."""
    run = study.simulation
    if run is None or run.status is SimulationStatus.SUCCESS:        # a recorded file, or a full run
        return []
    spec = _spec(scene)
    duration = spec.estimation.record_duration if spec.estimation.scenario == "brake" else spec.simulation.t_end
    reached = float(run.t_final)
    return [Shortfall("estimation", f"the recorded simulation {run.status.value} at t = {reached:.6g} s "
                      f"of {duration:g} s ({duration - reached:.6g} s not recorded)", duration - reached, "s")]


@dataclass(frozen=True, eq=False)
class ControlStudy:
    """The closed loop of ``[control]``.

    Attributes
    ----------
    loop : ClosedLoopResult
    controller : str
        The scene's ``control.controller``.
    estimator : str or None
        The estimator's name (None: the ideal loop on the true speed).
    cross_check : CrossCheck or None
        The loop's plant against its smoothed model in python-control, width by width
        (:func:`toolkit.loop.cross_check.cross_check`; None when not asked for, or the loop
        stopped early).
    compile_time : float, s
        The one-time cost paid before the loop was timed (the kernels compiled and the loop
        run once, untimed: the policy of :mod:`toolkit._compiled`); not in the loop's
        ``wall_time``.
    """

    loop: Any
    controller: str
    estimator: str | None
    cross_check: Any = None
    compile_time: float = 0.0

    def to_dict(self) -> dict[str, Any]:
        """JSON-able: settings, status, final speed, estimation error, wall time, the series."""
        loop = self.loop
        error = loop.estimate - loop.speed
        return {"controller": self.controller, "estimator": self.estimator,
                "status": loop.status, "message": loop.message, "samples": int(loop.times.size),
                "final_speed": float(loop.speed[-1]), "wall_time": loop.wall_time,
                "compile_time": self.compile_time, "estimate_rms_error": float(np.sqrt(np.mean(error ** 2))),
                "estimate_max_error": float(np.max(np.abs(error))),
                "cross_check": None if self.cross_check is None else self.cross_check.to_dict(),
                "times": loop.times, "speed": loop.speed, "estimate": loop.estimate,
                "force": loop.force, "commands": loop.commands}


def control_scene(scene: Scene | SceneObjects, schedule: ScheduleResult | None = None) -> ControlStudy:
    """Run the scene's ``[control]`` closed loop (and its python-control cross check).

    Parameters
    ----------
    scene : Scene or SceneObjects
        Needs ``[control]``.
    schedule : ScheduleResult, optional
        For ``controller = "open_loop"``: the designed ``[schedule]`` (designed here when
        not given).
    """
    from ..loop.closed_loop import simulate_closed_loop

    built = _built(scene)
    spec, objects = built.scene.control, built.control
    if spec is None or objects is None:
        raise SceneError(f"The scene {built.scene.name!r} has no [control] section.")
    controller = objects.controller
    if controller is None:                                     # open loop: the designed schedule
        from ..controllers import OpenLoop

        if schedule is None:
            schedule, _ = design_scene_schedule(built)
        controller = OpenLoop(schedule)
    rate = None if objects.sensors is not None else objects.rate
    plant, sensors, wander = control_world(built, spec.duration)
    arguments = dict(sensors=sensors, estimator=objects.estimator, v0=spec.v0, seed=spec.seed,
                     budget=objects.budget)
    if wander is not None:
        arguments["wander"] = wander
    # The loop's wall time is of compiled code: the kernels loaded and the loop run once first,
    # untimed (toolkit._compiled.warm: a kernel compiles at its first call, wherever it comes).
    compile_time = warm(lambda: simulate_closed_loop(plant, controller, spec.duration, rate=rate,
                                                     **arguments), "core", "lines")
    loop = simulate_closed_loop(plant, controller, spec.duration, rate=rate, **arguments)
    check = None
    if spec.cross_check and loop.status is SimulationStatus.SUCCESS:
        from ..loop.cross_check import cross_check     # python-control: only for a cross check

        check = cross_check(plant, controller, spec.duration, rate=objects.rate, v0=spec.v0,
                            budget=objects.budget)
    name = getattr(objects.estimator, "name", None) if objects.sensors is not None else None
    return ControlStudy(loop, spec.controller, name, check, compile_time)


def control_world(scene: Scene | SceneObjects, duration: float | None = None) -> tuple[Any, Any, Any]:
    """The true world ``[control]``'s loop runs on (``[control.truth]``; the scene itself when it
    says nothing): its plant, its encoders (None for an ideal loop) and the motors' wander
    (ndarray of shape (k, n), m/s, one row per period of ``duration`` s, default
    ``control.duration``; None without wander), every draw from ``control.seed``. The loop's
    estimator knows the scene only."""
    built = _built(scene)
    spec, objects = built.scene.control, built.control
    if spec is None or objects is None:
        raise SceneError(f"The scene {built.scene.name!r} has no [control] section.")
    duration = spec.duration if duration is None else duration
    plant, truth, sensors = built.plant_on(None), objects.truth, objects.sensors
    if truth.is_nominal:
        return plant, sensors, None
    plant = truth.plant(plant, spec.seed)
    sensors = None if sensors is None else truth.sensors(sensors)
    return plant, sensors, truth.wander(sample_count(duration, objects.rate), plant.n, 1.0 / objects.rate, spec.seed)


def control_shortfalls(scene: Scene | SceneObjects, study: ControlStudy) -> list[Shortfall]:
    """A loop stopped before ``duration`` (time left, s); a cross check that does not converge
    (:attr:`toolkit.loop.cross_check.CrossCheck.converges`; its fitted order)."""
    found: list[Shortfall] = []
    loop, duration = study.loop, _spec(scene).control.duration
    if loop.status is not SimulationStatus.SUCCESS:
        reached = float(loop.times[-1]) if loop.times.size else 0.0
        found.append(Shortfall("control", f"the closed loop {loop.status.value} at t = {reached:.6g} s of "
                               f"duration = {duration:g} s ({duration - reached:.6g} s not run): "
                               f"{loop.message}", duration - reached, "s"))
    check = study.cross_check
    if check is not None and not check.converges:
        from ..loop.cross_check import ORDER_BAND

        found.append(Shortfall("control", f"the smoothed model's loop does not converge to the exact "
                               f"one: differences {', '.join(f'{d:.3g}' for d in check.differences)} m/s "
                               f"at widths {', '.join(f'{w:g}' for w in check.widths)} m/s, fitted "
                               f"order {check.order:.3g} (band {ORDER_BAND[0]:g} to {ORDER_BAND[1]:g}; "
                               f"{check.message})", check.order, "order"))
    return found


def run_study(scene: Scene | SceneObjects, *, strict: bool = False) -> StudyResult:
    """Build the scene's objects once and run every stage it declares.

    Parameters
    ----------
    scene : Scene or SceneObjects
        From :func:`toolkit.load_scene` (built here), or already built.
    strict : bool
        Refuse, before any work, a request that is known to fall short
        (:func:`request_shortfalls`) instead of running it and reporting the shortfall.

    Returns
    -------
    StudyResult
        With :attr:`StudyResult.shortfalls`: every way the result misses the request, one
        :class:`Shortfall` kind per way of missing:

        =============  =====================================================================  ======
        stage          what                                                                   unit
        =============  =====================================================================  ======
        scene          speeds beyond the motor limits clipped (``[motors] clip = true``)      m/s
        allocation     a target that is not realizable, projected (distance to it)            N
        allocation     a target the contacts cannot reach (best achievable error)             N
        allocation     no allocation (infeasible, time limit, solver error)                   N
        schedule       a target beyond the speed limits (best achievable error)               m/s
        schedule       an unverified schedule (exact run left the prediction bound)           m/s
        schedule       a braking target not reached (final distance to it)                    m/s
        simulation     a run stopped before ``t_end`` (budget, Zeno, failure; time left)      s
        estimation     the recorded run stopped before its end (time not recorded)            s
        control        the closed loop stopped before ``duration`` (budget; time left)        s
        control        python-control's simulation of the loop differs from the toolkit's     m/s
        =============  =====================================================================  ======

    Raises
    ------
    SceneError
        ``strict=True`` and the request falls short before any work.
    """
    compiled_before = compile_seconds()
    objects = _built(scene)
    scene = objects.scene
    if scene.sweep is not None:
        from .build import sweep_scene_error

        raise sweep_scene_error(scene, "run_study")
    if scene.planar is not None:
        from .build import planar_scene_error

        raise planar_scene_error(scene, "run_study")
    known = request_shortfalls(objects)
    if strict and known:
        raise SceneError(f"--strict: {known[0]}" + (f" (and {len(known) - 1} more)" if len(known) > 1 else ""))
    contacts = objects.contacts
    found = [s for s in known if s.stage == "scene"]
    points = (scene.report or ReportSpec()).curve_points
    sensors = ({name: encoder.summary() for name, encoder in objects.encoders.items()}
               if scene.sensors is not None else None)
    allocation = None
    if scene.target is not None:
        allocation = allocate_scene(objects, contacts)
        found += allocation_shortfalls(objects, allocation, contacts)
        contacts = allocation.contacts
    schedule = check = None
    if scene.schedule is not None:
        schedule, check = design_scene_schedule(objects, contacts)
        found += schedule_shortfalls(objects, schedule, check)
    simulation = None
    if scene.simulation is not None:
        if scene.simulation.method == "exact":       # its wall time: of compiled kernels
            warm(lambda: _simulation(objects, contacts, 1e-3), "core")
        simulation = _simulation(objects, contacts)
        found += simulation_shortfalls(scene, simulation)
    estimation = None
    if scene.estimation is not None:
        estimation = estimate_scene(objects, simulation)
        found += estimation_shortfalls(objects, estimation)
    loop = None
    if scene.control is not None:
        loop = control_scene(objects, schedule)
        found += control_shortfalls(objects, loop)
    plant = objects.plant_on(contacts) if objects.plant is not None else None
    return StudyResult(scene, contacts, force_curve(contacts, points), sensors, allocation,
                       schedule, check, simulation, tuple(found), estimation, loop, plant,
                       compile_seconds() - compiled_before)


# -- planar scenes ----------------------------------------------------------------------------------

def planar_scene(scene: Scene | SceneObjects) -> Any:
    """Run a planar scene's ``[planar]`` (:func:`toolkit.planar.scene.run_planar`): the
    simulation, the terminal ratio of a disc or ring, the equilibrium of legs, the optional
    work-precision rows. Returns a :class:`toolkit.planar.scene.PlanarStudyResult`.

    Raises
    ------
    SceneError
        The scene has no ``[planar]``.
    """
    from ..planar.scene import run_planar   # the planar package loads with a planar scene only

    return run_planar(_planar(scene))


def planar_precision(scene: Scene | SceneObjects) -> Any:
    """A planar scene's work-precision report (:func:`toolkit.planar.scene.scene_precision`:
    its ``[planar.precision]`` settings or the defaults), what ``active-contacts precision``
    runs on a planar scene. Returns a :class:`toolkit.planar.PlanarPrecisionReport`.

    Raises
    ------
    SceneError
        The scene has no ``[planar]``.
    """
    from ..planar.scene import scene_precision

    return scene_precision(_planar(scene))


def _planar(scene: Scene | SceneObjects) -> Any:
    objects = _built(scene)
    if objects.planar is None:
        raise SceneError(f"The scene {objects.scene.name!r} has no [planar] section to run.")
    return objects.planar


# -- sweeps -------------------------------------------------------------------------------------

def sweep_scene(scene: Scene | SceneObjects, *, runs: int | None = None, seed: int | None = None,
                scheduler: Any = None, workers: int | None = None, progress: bool = False) -> Any:
    """Run a sweep scene's ``[sweep]`` (:func:`toolkit.sweep`); ``runs`` and ``seed`` override
    the scene's.

    Returns
    -------
    SweepResult

    Raises
    ------
    SceneError
        The scene has no ``[sweep]``.
    """
    from ..sweeps import sweep   # pandas comes with the first sweep

    objects = _built(scene)
    spec = objects.scene.sweep
    if spec is None:
        raise SceneError(f"The scene {objects.scene.name!r} has no [sweep] section to run.")
    return sweep(objects.sweep, spec.runs if runs is None else runs,
                 seed=spec.seed if seed is None else seed, scheduler=scheduler, workers=workers,
                 chunk_size=spec.chunk_size, progress=progress)


#: Runs of the probe that measures a sweep table's bytes per run (:func:`check_sweep_table`).
TABLE_PROBE_RUNS = 16


def check_sweep_table(scene: Scene | SceneObjects, *, runs: int | None = None,
                      seed: int | None = None) -> int:
    """Refuse, before the sweep, a ``results.csv`` larger than
    :data:`~toolkit.scenes.limits.MAX_TABLE_BYTES`: its size is estimated from the bytes per
    run of the first :data:`TABLE_PROBE_RUNS` runs (the table's own CSV form; the run index
    counted at its full width). Returns the estimate (bytes).

    Raises
    ------
    SceneError
        The estimate exceeds the limit (the message gives the most runs that fit).
    """
    from ..sweeps import sweep
    from .limits import MAX_TABLE_BYTES

    objects = _built(scene)
    spec = objects.scene.sweep
    if spec is None:
        raise SceneError(f"The scene {objects.scene.name!r} has no [sweep] section to run.")
    total = spec.runs if runs is None else runs
    probe = min(total, TABLE_PROBE_RUNS)
    table = sweep(objects.sweep, probe, seed=spec.seed if seed is None else seed,
                  chunk_size=spec.chunk_size).table
    text = table.to_csv(index=False, float_format="%.17g")
    header = len(text.split("\n", 1)[0]) + 1
    per_run = (len(text) - header) / probe + len(str(total)) - len(str(probe))
    size = int(header + per_run * total)
    if size > MAX_TABLE_BYTES:
        fit = int((MAX_TABLE_BYTES - header) // per_run)
        raise SceneError(
            f"The sweep of {objects.scene.name!r} with {total} runs would write a results.csv of about "
            f"{size / 2**20:.0f} MiB ({per_run:.0f} bytes per run, measured on its first {probe} runs); "
            f"tables are limited to {MAX_TABLE_BYTES >> 20} MiB. Run at most about {fit} runs, or leave "
            "out --out for the summary alone.")
    return size


def sweep_shortfalls(result: Any) -> list[Shortfall]:
    """Runs that had not settled by the end of their observation time (median law, mean
    against median): their speeds are not steady speeds (the count of such runs)."""
    table = result.table
    if "settled" not in table:
        return []
    unsettled = int((~table["settled"]).sum())
    if not unsettled:
        return []
    return [Shortfall("sweep", f"{unsettled} of {result.runs} runs had not settled when observed "
                      "(their speeds are not steady)", float(unsettled), "runs")]
