"""Build toolkit objects from a parsed scene: the one place scene specs become objects.

:func:`build_scene` checks every value and every rule between sections, then builds fresh
objects (a study builds them once per run: estimators and controllers carry state).

The bounds of values no constructor takes are declared with their keys
(:mod:`toolkit.scenes.spec`); every other value is checked by the constructor that takes it,
and a constructor's :class:`~toolkit.errors.ParameterError` becomes a
:class:`~toolkit.errors.SceneError` that keeps the rule and value and names the scene key::

    In [motors]: The 'lag' parameter of Motors must be >= 0. Got -0.1 instead.
    (scene key 'motors.lag')
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass, field, fields, replace
from typing import Any

import numpy as np

from ..errors import check_option, suggestion
from ..allocation import METHODS, EquilibriumSpeed, ForceCurve, FrictionFraction, Viscosity
from ..errors import ParameterError, ParameterTypeError, SceneError
from ..model import ContactSet, Encoder, Motors, PiecewiseConstant, Plant, sample_count, unequal_loads
from ..model.sensors import Sensors
from ..schedule import Braking, SpeedTrajectory
from ..simulation import Budget
from .keys import bounded_values
from .limits import BYTES_PER_NUMBER, MAX_OUTPUT_BYTES, MAX_RUN_SAMPLES, scene_value_error
from .spec import IDEAL_LOOP_RATE, LOOP_ESTIMATOR, NOISE_KEYS, SECTIONS, Scene, ScheduleSpec

__all__ = ["Clip", "SceneObjects", "EstimationObjects", "ControlObjects", "build_scene", "schedule_target",
           "output_numbers", "sweep_scene_error", "planar_scene_error", "check_record_outputs"]

_fail = scene_value_error


@dataclass(frozen=True)
class Clip:
    """Speeds a scene asked for beyond its motors' limits, clipped (``[motors] clip = true``).

    Attributes
    ----------
    key : str
        The scene key that set them (``"contacts.speeds"``, ``"simulation.commands"``, ...).
    value : float, m/s
        The requested speed farthest beyond the limits.
    limit : float, m/s
        The limit it was clipped to.
    count : int
        How many speeds were clipped.
    """

    key: str
    value: float
    limit: float
    count: int

    @property
    def excess(self) -> float:
        """``|value - limit|``, m/s."""
        return abs(self.value - self.limit)


@dataclass(frozen=True, eq=False)
class EstimationObjects:
    """What ``[estimation]`` declares.

    Attributes
    ----------
    sensors : Sensors
        The scene's encoders with the section's noise (missed counts, read noise, jitter).
    model : EstimatorModel
        What the model-based estimators know: the declared forces (N), the mass (kg), the
        sensors, the motor lag (s), the drag (N s/m) and ``friction_spread``.
    estimators : dict of str to Estimator
        One per ``methods`` entry, in order.
    truth : WorldTruth
        How the simulated world departs from the scene (``[estimation.truth]``; the
        estimators are not told).
    prior : ModelPrior
        What the estimators are told beyond the scene (``[estimation.model]``).
    plant : Plant
        The plant the record is simulated on: the brake scenario's (true friction: the
        declared forces with the drawn spread, and its commands), or the scene's own for
        ``scenario = "simulation"``.
    duration : float, s
        Length of the record.
    v0 : float, m/s
        The speed the record starts from (rest, or ``simulation.v0``).
    """

    sensors: Sensors
    model: Any
    estimators: dict[str, Any]
    plant: Plant
    duration: float
    v0: float
    truth: Any = None
    prior: Any = None


@dataclass(frozen=True, eq=False)
class ControlObjects:
    """What ``[control]`` declares.

    Attributes
    ----------
    controller : Controller or None
        None for ``"open_loop"`` (the study builds it from the designed schedule).
    sensors : Sensors or None
        The encoders read in the loop (None: the ideal loop on the true speed).
    estimator : Estimator or None
        What turns the counts into the estimate (with sensors).
    rate : float, Hz
    budget : Budget or None
        Guards of each plant step.
    truth : WorldTruth
        How the loop's world departs from the scene (``[control.truth]``).
    """

    controller: Any
    sensors: Sensors | None
    estimator: Any
    rate: float
    budget: Budget | None
    truth: Any = None


@dataclass(frozen=True, eq=False)
class SceneObjects:
    """The toolkit objects a scene declares, built by :func:`build_scene`.

    Attributes
    ----------
    scene : Scene
        The parsed scene they were built from.
    contacts : ContactSet or None
        Declared contact speeds (m/s) and friction magnitudes (N), shape (n,); None in a
        sweep scene.
    motors : Motors or None
        ``[motors]``; None for ideal motors.
    plant : Plant or None
        ``[body]`` on the declared contacts with the motors, the external force (N) and the
        ``[simulation]`` commands (m/s); None without ``[body]``.
    encoders : dict of str to Encoder
        ``"wheel"`` and ``"central"``, those ``[sensors]`` declares (empty without it).
    sensors : Sensors or None
        Both encoders, noise-free (None unless ``[sensors]`` declares both).
    target : ForceCurve, Viscosity, FrictionFraction, EquilibriumSpeed or None
        The allocation target of ``[target]``.
    schedule_target : Braking, SpeedTrajectory or None
        The schedule target of ``[schedule]``.
    simulation_options : dict
        ``[simulation] options`` as :func:`toolkit.simulate` takes them (``budget`` a
        :class:`~toolkit.simulation.Budget`); empty without ``[simulation]``.
    clipped : tuple of Clip
        Speeds clipped to the motor limits (``[motors] clip = true``); empty otherwise.
    estimation : EstimationObjects or None
    control : ControlObjects or None
    sweep : experiment or None
        ``[sweep]`` (:mod:`toolkit.experiments`).
    planar : toolkit.planar.scene.PlanarSceneObjects or None
        ``[planar]`` (:mod:`toolkit.planar`, imported only for a planar scene).
    """

    scene: Scene
    contacts: ContactSet | None
    motors: Motors | None = None
    plant: Plant | None = None
    encoders: dict[str, Encoder] = field(default_factory=dict)
    sensors: Sensors | None = None
    target: Any = None
    schedule_target: Braking | SpeedTrajectory | None = None
    simulation_options: dict[str, Any] = field(default_factory=dict)
    clipped: tuple[Clip, ...] = ()
    estimation: EstimationObjects | None = None
    control: ControlObjects | None = None
    sweep: Any = None
    planar: Any = None

    def plant_on(self, contacts: ContactSet | None = None) -> Plant:
        """The scene's plant, on other contacts (e.g. allocated ones) when given.

        Raises
        ------
        SceneError
            The scene has no ``[body]`` (the moving inertia).
        """
        if self.plant is None:
            raise SceneError(f"The scene {self.scene.name!r} has no [body] section (the moving "
                             "inertia) that this stage needs.")
        if contacts is None or contacts is self.contacts:
            return self.plant
        return replace(self.plant, contacts=contacts)

    def apparatus(self) -> Any:
        """The scene's plant and encoders as the paper's predictions' apparatus
        (:class:`toolkit.predictions.Apparatus`).

        Raises
        ------
        SceneError
            The scene has no ``[body]``, or breaks the apparatus's rules, named by the scene key
            that sets what it breaks (``contacts.forces``: one equal magnitude;
            ``motors.speed_limit``: finite symmetric limits).
        """
        from ..predictions import Apparatus

        keys = {"plant.contacts.forces": "contacts.forces", "plant.motors.speed_limits": "motors.speed_limit"}
        with _scene_keys("contacts", keys):
            return Apparatus(self.plant_on(None), self.sensors)


def sweep_scene_error(scene: Scene, command: str) -> SceneError:
    """The one refusal of a sweep scene by a command that needs contacts of its own."""
    return SceneError(f"The scene {scene.name!r} is a sweep scene: its runs draw their own contacts "
                      f"and it declares no [contacts], so '{command}' has nothing to work on. Run it "
                      "with 'active-contacts sweep'.")


def planar_scene_error(scene: Scene, command: str) -> SceneError:
    """The one refusal of a planar scene by a command of the 1-D toolkit."""
    return SceneError(f"The scene {scene.name!r} is a planar scene: it declares a body on planar "
                      f"contacts in [planar] and no [contacts], so '{command}' has nothing to work on. "
                      "Run it with 'active-contacts run'.")


def build_scene(scene: Scene) -> SceneObjects:
    """Check every value of ``scene`` and build the objects it declares (fresh ones each call).

    Parameters
    ----------
    scene : Scene
        A parsed scene (:func:`toolkit.load_scene`).

    Returns
    -------
    SceneObjects
        What each section becomes:

        ==========================  ===============================================================
        ``[contacts]``              :class:`~toolkit.model.ContactSet` (speeds within the motor
                                    limits, or clipped to them with ``[motors] clip = true``)
        ``[motors]``                :class:`~toolkit.model.Motors`
        ``[body]`` (+ motors,       :class:`~toolkit.model.Plant`, its external force and commands
        ``simulation.commands``)    as :class:`~toolkit.model.PiecewiseConstant` signals
        ``[sensors]``               :class:`~toolkit.model.Encoder` per declared encoder, and the
                                    :class:`~toolkit.model.Sensors` when both are declared
        ``[target]``                the allocation target (:class:`~toolkit.ForceCurve`, ...)
        ``[schedule]``              the schedule target (:class:`~toolkit.Braking` or
                                    :class:`~toolkit.SpeedTrajectory`)
        ``simulation.options``      the options of :func:`toolkit.simulate`; a ``budget`` table
                                    becomes a :class:`~toolkit.simulation.Budget`
        ``[estimation]``            :class:`EstimationObjects`
        ``[control]``               :class:`ControlObjects`
        ``[sweep]``                 the experiment (:mod:`toolkit.experiments`)
        ==========================  ===============================================================

    Raises
    ------
    SceneError
        A value out of its bounds, a rule between sections broken, or a constructor that
        refused a value; the message names the scene key, the rule and the value received.
    """
    if not isinstance(scene, Scene):
        raise SceneError(f"build_scene takes a Scene (from load_scene). Got {type(scene).__name__} instead.")
    _check_limits(scene)
    if scene.sweep is not None:
        return SceneObjects(scene=scene, contacts=None, sweep=_sweep(scene))
    if scene.planar is not None:
        return SceneObjects(scene=scene, contacts=None, planar=_planar(scene))
    _check_across(scene)
    clips: list[Clip] = []
    contacts = _contacts(scene, clips)
    motors = _motors(scene)
    plant = _plant(scene, contacts, motors, clips)
    encoders = _encoders(scene)
    sensors = (Sensors(encoders["central"], encoders["wheel"], contacts.n)
               if {"central", "wheel"} <= set(encoders) else None)
    objects = SceneObjects(scene=scene, contacts=contacts, motors=motors, plant=plant, encoders=encoders,
                           sensors=sensors, target=_target(scene), schedule_target=schedule_target(scene.schedule),
                           simulation_options=_simulation_options(scene), clipped=tuple(clips))
    estimation = _estimation(scene, objects)
    control = _control(scene, objects)
    _check_output_size(scene, estimation, control)
    return replace(objects, estimation=estimation, control=control)


# -- bounds and rules between sections ---------------------------------------------------------

def _check_limits(scene: Scene) -> None:
    for section in SECTIONS:
        spec = getattr(scene, section)
        for where, limit, value in bounded_values(section, spec) if spec is not None else ():
            if not limit.holds(value):
                raise _fail(where, limit.broken(value), value)
    contacts = scene.contacts
    if contacts is not None and contacts.random is not None and contacts.random["high"] < contacts.random["low"]:
        raise _fail("contacts.random.high", f"be >= low ({contacts.random['low']:g})", contacts.random["high"])


def _check_across(scene: Scene) -> None:
    """Rules that tie one section to another (the body a stage needs, contact counts, sensors)."""
    for stage in ("simulation", "schedule", "estimation", "control"):
        if getattr(scene, stage) is not None and scene.body is None:
            raise SceneError(f"A [{stage}] section needs a [body] section (the moving inertia).")
    n = scene.contacts.n
    target = scene.target
    if target is not None:
        for key in ("fixed", "failed", "liftable"):
            for index in getattr(target, key):
                if index >= n:
                    raise _fail(f"target.{key}", f"hold contact indices below n = {n}", list(getattr(target, key)))
        motors = scene.motors
        if target.dt is not None and (motors is None or not math.isfinite(motors.rate_limit)):
            raise SceneError("'target.dt' limits each contact's change to rate_limit * dt: "
                             "it needs [motors] rate_limit (m/s^2).")
    _check_sensing(scene)
    simulation = scene.simulation
    if simulation is not None and simulation.commands is not None:
        for i, row in enumerate(simulation.commands["values"]):
            if len(row) != n:
                raise _fail(f"simulation.commands.values[{i}]", f"hold one speed per contact ({n})", list(row))


def _missing_encoders(sensors: Any) -> list[str]:
    """The ``[sensors]`` keys an estimator needs that the section does not declare."""
    if sensors is None:
        return ["[sensors]"]
    return [f"sensors.{key}" for key in ("central_counts_per_rev", "wheel_counts_per_rev")
            if getattr(sensors, key) is None]


def _check_names(scene: Scene) -> None:
    """The simulation method and the estimators a scene names exist
    (:data:`toolkit.simulation.METHODS`, :data:`toolkit.estimation.ESTIMATOR_NAMES`; a loop
    reads any estimator but the smoother, which needs the future)."""
    from ..estimation import ESTIMATOR_NAMES
    from ..simulation import METHODS as SIMULATION_METHODS

    named = [(f"estimation.methods[{i}]", name, ESTIMATOR_NAMES)
             for i, name in enumerate(scene.estimation.methods if scene.estimation is not None else ())]
    if scene.simulation is not None:
        named.append(("simulation.method", scene.simulation.method, SIMULATION_METHODS))
    if scene.control is not None and scene.control.estimator is not None:
        loop = tuple(name for name in ESTIMATOR_NAMES if name != "rts")
        named.append(("control.estimator", scene.control.estimator, loop))
    for where, name, choices in named:
        if name not in choices:
            raise SceneError(f"The {where!r} value in the scene must be one of {list(choices)}. "
                             f"Got {name!r} instead.{suggestion(name, choices)}")


def _check_sensing(scene: Scene) -> None:
    """An estimator or a controller on the sensors it needs; options that need sensors."""
    _check_names(scene)
    sensors, estimation = scene.sensors, scene.estimation
    if estimation is not None:
        missing = _missing_encoders(sensors)
        if missing:
            raise SceneError(f"The [estimation] section reads both encoders (central and wheels): it "
                             f"needs {' and '.join(missing)}.")
        if estimation.scenario == "simulation":
            simulation = scene.simulation
            if simulation is None or simulation.method != "exact":
                raise SceneError("'estimation.scenario' = 'simulation' records the scene's [simulation] "
                                 "run: it needs a [simulation] section with method = 'exact' (the "
                                 "encoders count the exact dense output).")
            if estimation.duration is not None:
                raise SceneError("'estimation.duration' belongs to scenario = 'brake'; scenario = "
                                 "'simulation' records [simulation] t_end.")
    control = scene.control
    if control is None:
        return
    if control.controller == "open_loop" and scene.schedule is None:
        raise SceneError("'control.controller' = 'open_loop' replays the scene's designed schedule: it "
                         "needs a [schedule] section.")
    motors = scene.motors
    if control.cross_check and motors is not None and (math.isfinite(motors.rate_limit) or motors.compliance > 0):
        raise _fail("control.cross_check", "be false when the motors have a rate_limit or compliance "
                    "(the smoothed model it checks against has a first-order lag only)", control.cross_check)
    truth = control.truth or {}
    reads = control.sensors if control.sensors is not None else sensors is not None
    if reads:
        missing = _missing_encoders(sensors)
        if missing:
            raise SceneError(f"The [control] loop reads the encoders through an estimator "
                             f"(control.sensors = true): it needs {' and '.join(missing)} (or set "
                             f"control.sensors = false for the ideal loop on the true speed).")
        if control.rate is not None and control.rate != sensors.rate:
            raise _fail("control.rate", f"equal sensors.rate ({sensors.rate:g} Hz) when the loop reads "
                        "the sensors, or be left out", control.rate)
    else:
        if control.estimator is not None:
            raise _fail("control.estimator", "be left out of an ideal loop (control.sensors = false "
                        "or no [sensors]): the controller sees the true speed", control.estimator)
        for key in NOISE_KEYS:
            if getattr(control, key) != 0.0:
                raise _fail(f"control.{key}", "be left out of an ideal loop (no sensors read)",
                            getattr(control, key))
        if control.model:
            raise _fail("control.model", "be left out of an ideal loop (no estimator is told anything)",
                        control.model)
        for key in ("read_noise", "missed_count_prob", "jitter"):
            if truth.get(key, 0.0) != 0.0:
                raise _fail(f"control.truth.{key}", "be left out of an ideal loop (no sensors read)", truth[key])


def output_numbers(scene: Scene, estimation: EstimationObjects | None = None,
                   control: ControlObjects | None = None) -> int:
    """How many numbers the series of a run's JSON output hold (the force-speed curve, the
    estimation record's truth and estimates, the closed loop's signals), known before any
    work: what :data:`~toolkit.scenes.limits.MAX_OUTPUT_BYTES` bounds."""
    return sum(numbers for numbers, _ in _output_parts(scene, estimation, control))


def _output_parts(scene: Scene, estimation: EstimationObjects | None,
                  control: ControlObjects | None) -> list[tuple[int, str]]:
    """The numbers of each series of the outputs, with what would make it smaller."""
    n = scene.contacts.n if scene.contacts is not None else 0
    points = scene.report.curve_points if scene.report is not None else 801
    parts = [(2 * points, "sample the curve at fewer points (report.curve_points)"),
             (3 * n, f"declare fewer contacts (the scene has {n})")]
    if estimation is not None:
        samples = sample_count(estimation.duration, estimation.sensors.rate)
        parts.append((estimation_numbers(samples, estimation),
                      "shorten the estimation record or lower its rate (estimation.duration, sensors.rate)"))
    if control is not None:
        parts.append((sample_count(scene.control.duration, control.rate) * (4 + n),
                      "shorten the closed loop or lower its rate (control.duration)"))
    return parts


def estimation_numbers(samples: int, estimation: EstimationObjects) -> int:
    """Numbers of an estimation record's series in the outputs: per sample its time, the
    truth and one estimate per estimator."""
    return samples * (2 + len(estimation.estimators))


def check_record_outputs(samples: int, estimation: EstimationObjects, source: str) -> None:
    """Refuse, before any work, a recorded file (``source``) of ``samples`` rows whose
    estimates would pass :data:`~toolkit.scenes.limits.MAX_OUTPUT_BYTES`."""
    size = estimation_numbers(samples, estimation) * BYTES_PER_NUMBER
    if size > MAX_OUTPUT_BYTES:
        most = MAX_OUTPUT_BYTES // (BYTES_PER_NUMBER * estimation_numbers(1, estimation))
        raise SceneError(
            f"The record file {source!r} has {samples} samples; their estimates would take about "
            f"{size / 2**20:.0f} MiB of estimate.json, and outputs are limited to {MAX_OUTPUT_BYTES >> 20} MiB: "
            f"at most {most} samples with {len(estimation.estimators)} estimators (split the record, or "
            "name fewer estimation.methods).")


def _check_output_size(scene: Scene, estimation: EstimationObjects | None,
                       control: ControlObjects | None) -> None:
    parts = _output_parts(scene, estimation, control)
    numbers = sum(count for count, _ in parts)
    size = numbers * BYTES_PER_NUMBER
    if size > MAX_OUTPUT_BYTES:
        advice = max(parts)[1]          # the largest series
        raise SceneError(
            f"The scene {scene.name!r} asks for outputs of about {size / 2**20:.0f} MiB ({numbers} numbers "
            f"in its series: the curve, the contacts, the estimation record, the closed loop); outputs are "
            f"limited to {MAX_OUTPUT_BYTES >> 20} MiB: {advice}.")


# -- constructor errors named by scene key -------------------------------------------------------

@contextmanager
def _scene_keys(section: str, keys: Mapping[str, str | tuple[str, ...]]) -> Iterator[None]:
    """Turn a constructor's parameter error into a SceneError naming the scene key.

    ``keys`` maps the constructor's parameter names to the scene key (or keys) that set them;
    the message keeps the constructor's rule and value (one template everywhere) and adds
    the key.
    """
    try:
        yield
    except SceneError:
        raise
    except (ParameterError, ParameterTypeError) as error:
        found = keys.get(error.parameter, ()) if error.parameter is not None else ()
        names = (found,) if isinstance(found, str) else found
        where = names[0].split(".")[0] if names else section
        suffix = (f" (scene keys {' and '.join(map(repr, names))})" if len(names) > 1
                  else f" (scene key {names[0]!r})" if names else "")
        raise SceneError(f"In [{where}]: {error}{suffix}") from None


def _same_keys(section: str, names: tuple[str, ...]) -> dict[str, str]:
    return {name: f"{section}.{name}" for name in names}


# -- objects -------------------------------------------------------------------------------------

def _within_limits(key: str, speeds: np.ndarray, motors: Any) -> tuple[np.ndarray, Clip | None]:
    """``speeds`` checked against ``[motors]``'s limits: refused, or clipped with ``clip = true``."""
    if motors is None:
        return speeds, None
    low, high = motors.speed_limits
    beyond = (speeds < low) | (speeds > high)
    if not beyond.any():
        return speeds, None
    excess = np.where(speeds > high, speeds - high, low - speeds)
    worst = np.unravel_index(int(np.argmax(excess)), speeds.shape)
    value = float(speeds[worst])
    limit = high if value > high else low
    if not motors.clip:
        index = ", ".join(map(str, worst))
        raise SceneError(
            f"The {key!r} value in the scene must lie within the motors' speed limits "
            f"[{low:g}, {high:g}] m/s (or set [motors] clip = true to clip it). Got {value:g} m/s "
            f"(entry [{index}], beyond the limit {limit:g} m/s) instead.")
    return np.clip(speeds, low, high), Clip(key, value, limit, int(beyond.sum()))


def _signal(value: float | Mapping[str, Any], key: str) -> float | PiecewiseConstant:
    """A constant, or a :class:`PiecewiseConstant` from a parsed ``{times, values}`` table."""
    if not isinstance(value, Mapping):
        return value
    with _scene_keys(key.split(".")[0], _same_keys(key, ("times", "values"))):
        return PiecewiseConstant(np.asarray(value["times"]), np.asarray(value["values"], dtype=float))


def _contacts(scene: Scene, clips: list[Clip]) -> ContactSet:
    spec = scene.contacts
    if spec.random is not None:
        rng = np.random.default_rng(spec.random["seed"])
        speeds = rng.uniform(spec.random["low"], spec.random["high"], spec.random["n"])
    else:
        speeds = np.asarray(spec.speeds)
    key = "contacts.random" if spec.random is not None else "contacts.speeds"
    speeds, clip = _within_limits(key, speeds, scene.motors)
    clips.extend([clip] if clip is not None else [])
    with _scene_keys("contacts", _same_keys("contacts", ("speeds", "forces", "mu", "normal_loads"))):
        if spec.mu is not None:
            return ContactSet.from_friction(speeds, spec.mu, spec.normal_loads)
        forces = spec.forces
        if isinstance(forces, float):
            forces = np.full(speeds.shape, forces)
        return ContactSet(speeds, forces)


def _motors(scene: Scene) -> Motors | None:
    spec = scene.motors
    if spec is None:
        return None
    with _scene_keys("motors", _same_keys("motors", ("lag", "rate_limit", "speed_limits", "compliance",
                                                         "backlash"))):
        return Motors(lag=spec.lag, rate_limit=spec.rate_limit, speed_limits=spec.speed_limits,
                      compliance=spec.compliance, backlash=spec.backlash)


def _plant(scene: Scene, contacts: ContactSet, motors: Motors | None, clips: list[Clip]) -> Plant | None:
    body = scene.body
    if body is None:
        return None
    commands = None
    if scene.simulation is not None and scene.simulation.commands is not None:
        table = scene.simulation.commands
        values, clip = _within_limits("simulation.commands", np.asarray(table["values"], dtype=float),
                                      scene.motors)
        clips.extend([clip] if clip is not None else [])
        commands = _signal({"times": table["times"], "values": values}, "simulation.commands")
    keys = {"mass": "body.mass" if body.mass is not None else ("body.inertia", "body.contact_radius"),
            "damping": "body.damping", "external_force": "body.external_force",
            "motors": ("motors.compliance", "motors.lag"), "commands": "simulation.commands"}
    external_force = _signal(body.external_force, "body.external_force")
    with _scene_keys("body", keys):
        return Plant(contacts, body.moving_mass, damping=body.damping,
                     external_force=external_force, motors=motors, commands=commands)


def _encoders(scene: Scene) -> dict[str, Encoder]:
    spec = scene.sensors
    encoders: dict[str, Encoder] = {}
    if spec is None:
        return encoders
    if spec.wheel_counts_per_rev is not None:
        with _scene_keys("sensors", {"counts_per_rev": "sensors.wheel_counts_per_rev",
                                     "radius": "sensors.wheel_radius", "rate": "sensors.rate",
                                     "backlash": "sensors.wheel_backlash"}):
            encoders["wheel"] = Encoder(spec.wheel_counts_per_rev, spec.wheel_radius, spec.rate,
                                        spec.wheel_backlash)
    if spec.central_counts_per_rev is not None:
        with _scene_keys("sensors", {"counts_per_rev": "sensors.central_counts_per_rev",
                                     "radius": "sensors.contact_radius", "rate": "sensors.rate"}):
            encoders["central"] = Encoder(spec.central_counts_per_rev, spec.contact_radius, spec.rate)
    return encoders


def _target(scene: Scene) -> Any:
    spec = scene.target
    if spec is None:
        return None
    p = spec.params
    with _scene_keys("target", _same_keys("target", (*p, "method"))):
        if spec.method is not None:
            check_option(spec.method, "method", "allocate", METHODS)
        if spec.kind == "force_curve":
            return ForceCurve(p["speeds"], p["forces"], spec.param("weights"))
        if spec.kind == "viscosity":
            return Viscosity(p["slope"], p["center"], p["band"])
        if spec.kind == "friction_fraction":
            return FrictionFraction(p["fraction"], p["band"])
        return EquilibriumSpeed(p["speed"], spec.param("margin"))


def schedule_target(spec: ScheduleSpec | None) -> Braking | SpeedTrajectory | None:
    """The schedule target a ``[schedule]`` section declares (None without one)."""
    if spec is None:
        return None
    with _scene_keys("schedule", _same_keys("schedule", tuple(spec.params))):
        if spec.kind == "braking":
            return Braking(spec.params["speed"], spec.param("duration"))
        return SpeedTrajectory(spec.params["times"], spec.params["speeds"])


def _sweep(scene: Scene) -> Any:
    """The ``[sweep]`` experiment, its parameters checked by its constructor."""
    from ..experiments import EXPERIMENTS

    spec = scene.sweep
    kind = EXPERIMENTS[spec.experiment]
    for name in spec.statistics:
        if name not in kind.STATISTICS:
            raise SceneError(f"The 'sweep.statistics' value in the scene must list statistics of "
                             f"{spec.experiment!r} ({', '.join(kind.STATISTICS)}). Got {name!r} instead."
                             f"{suggestion(name, kind.STATISTICS)}")
    with _scene_keys("sweep", _same_keys("sweep", tuple(spec.params))):
        return kind(**spec.params)


def _planar(scene: Scene) -> Any:
    """The ``[planar]`` plant (toolkit.planar imported here: a 1-D scene never loads it)."""
    from ..planar.scene import build_planar

    keys = {"mass": "planar.mass", "inertia": "planar.inertia", "radius": "planar.radius",
            "inner_radius": "planar.inner_radius", "force": ("planar.mu", "planar.mass", "planar.gravity"),
            "positions": "planar.positions", "velocities": "planar.velocities", "forces": "planar.forces",
            "resolution": "planar.resolution", "rings": "planar.resolution", "arcs": "planar.resolution",
            "v0": "planar.v0", "omega0": "planar.omega0", "method": "planar.method"}
    with _scene_keys("planar", keys):
        return build_planar(scene.planar)


def _simulation_options(scene: Scene) -> dict[str, Any]:
    """``[simulation] options`` with a ``budget`` table turned into a :class:`Budget`."""
    if scene.simulation is None:
        return {}
    options = dict(scene.simulation.options)
    if isinstance(options.get("budget"), Mapping):
        table = options["budget"]
        keys = tuple(item.name for item in fields(Budget))
        unknown = [key for key in table if key not in keys]
        if unknown:
            raise SceneError(f"Unknown key {unknown[0]!r} in [simulation.options.budget]. "
                             f"Valid keys: {', '.join(keys)}.")
        with _scene_keys("simulation", _same_keys("simulation.options.budget", tuple(table))):
            options["budget"] = Budget(**table)
    return options


# -- estimation and control ----------------------------------------------------------------------

def _check_rate(rate: float, duration: float, keys: tuple[str, str], what: str) -> None:
    """A sample rate the run can honour: a resolvable period and at most MAX_RUN_SAMPLES samples.

    ``keys``: the rate's scene key and the duration's. Too many samples are the duration's
    fault (the rate is the hardware's, or the loop's; the length is what the run asks for).
    """
    rate_key, duration_key = keys
    samples = sample_count(duration, rate)
    if samples > MAX_RUN_SAMPLES:
        raise SceneError(f"The {duration_key!r} value in the scene must be at most "
                         f"{(MAX_RUN_SAMPLES - 1) / rate:g} s at {rate_key} = {rate:g} Hz (the {what} takes "
                         f"at most {MAX_RUN_SAMPLES} samples). Got {duration:g} s ({samples} samples) instead.")
    if not duration + 1.0 / rate > duration:
        raise SceneError(f"The {rate_key!r} value in the scene must give a period the simulation clock "
                         f"resolves at t = {duration:g} s ({duration_key}). Got {rate:g} Hz instead.")


def _noisy_sensors(objects: SceneObjects, section: str, spec: Any) -> Sensors:
    noise = {key: getattr(spec, key) for key in NOISE_KEYS}
    with _scene_keys(section, _same_keys(section, tuple(noise))):
        return replace(objects.sensors, **noise)


def _model(plant: Plant, sensors: Sensors, friction_spread: float = 0.0) -> Any:
    from ..estimation import EstimatorModel

    motors = plant.motors
    with _scene_keys("estimation", {"friction_uncertainty": "estimation.friction_spread"}):
        return EstimatorModel(plant.contacts.forces, plant.mass, sensors,
                              motor_lag=motors.lag if motors is not None else 0.0,
                              damping=plant.damping, friction_uncertainty=friction_spread,
                              speed_limits=motors.speed_limits if motors is not None else (-math.inf, math.inf))


def _estimator(name: str, model: Any, section: str, prior: Any, covariance: Any = None) -> Any:
    """The estimator ``name`` (:func:`toolkit.estimation.build_estimator`) on the nominal
    ``model`` and the ``prior`` of ``[section.model]`` (``initial_covariance`` for the filters)."""
    from ..estimation import build_estimator

    with _scene_keys(section, {"initial_covariance": f"{section}.initial_covariance"}):
        return build_estimator(name, model, prior=prior, initial_covariance=covariance)


def _knowledge(section: str, spec: Any, sensors: Sensors | None) -> tuple[Any, Any]:
    """The ``truth`` (:class:`~toolkit.model.truth.WorldTruth`) and the ``model``
    (:class:`~toolkit.estimation.ModelPrior`) sub-tables of ``[section]``, each value checked
    by its constructor under its scene key (the true encoders too, against ``sensors``)."""
    from ..estimation import ModelPrior
    from ..model.truth import WorldTruth

    truth_table, model_table = spec.truth or {}, spec.model or {}
    keys = {**_same_keys(f"{section}.truth", tuple(truth_table)), "count_noise": f"{section}.truth.read_noise"}
    with _scene_keys(section, keys):
        truth = WorldTruth(**truth_table)
        if sensors is not None:
            truth.sensors(sensors)            # the true encoders (their jitter bound, ...)
    with _scene_keys(section, _same_keys(f"{section}.model", tuple(model_table))):
        prior = ModelPrior(**model_table)
    return truth, prior


def _estimation(scene: Scene, objects: SceneObjects) -> EstimationObjects | None:
    spec = scene.estimation
    if spec is None:
        return None
    plant = objects.plant
    sensors = _noisy_sensors(objects, "estimation", spec)
    if spec.scenario == "brake":
        duration = spec.record_duration
        if spec.friction_spread > 0 and (spec.truth or {}).get("friction_spread", 0.0) > 0:
            raise _fail("estimation.truth.friction_spread", "be left out when estimation.friction_spread "
                        "draws the wheels (declared to the estimators); give one of the two",
                        spec.truth["friction_spread"])
        if spec.brake_time > duration:
            raise _fail("estimation.brake_time", f"be <= estimation.duration ({duration:g} s)", spec.brake_time)
        n = plant.n
        offsets = np.linspace(-spec.spread, spec.spread, n)
        cruise, brake = spec.cruise + offsets, spec.brake + offsets
        low, high = objects.motors.speed_limits if objects.motors is not None else (-math.inf, math.inf)
        for key, centre in (("estimation.cruise", spec.cruise), ("estimation.brake", spec.brake)):
            if centre - spec.spread < low or centre + spec.spread > high:
                raise _fail(key, f"keep {key.split('.')[1]} +- estimation.spread ({spec.spread:g} m/s) within "
                            f"the motors' speed limits [{low:g}, {high:g}] m/s", centre)
        rng = np.random.default_rng([spec.seed, 1])      # the sensors draw from default_rng(seed)
        forces = unequal_loads(plant.contacts.forces, spec.friction_spread, n, rng)
        commands = PiecewiseConstant([spec.brake_time], [cruise, brake])
        record_plant = replace(plant, contacts=ContactSet(cruise, forces), commands=commands, external_force=0.0)
        v0 = 0.0
    else:
        duration, record_plant, v0 = scene.simulation.t_end, plant, scene.simulation.v0
    duration_key = "simulation.t_end" if spec.scenario == "simulation" else "estimation.duration"
    _check_rate(sensors.rate, duration, ("sensors.rate", duration_key), "estimation record")
    model = _model(plant, sensors, spec.friction_spread)
    truth, prior = _knowledge("estimation", spec, sensors)
    covariance = None if spec.initial_covariance is None else np.array(spec.initial_covariance)
    estimators = {name: _estimator(name, model, "estimation", prior, covariance) for name in spec.methods}
    return EstimationObjects(sensors, model, estimators, record_plant, duration, v0, truth, prior)


def _control(scene: Scene, objects: SceneObjects) -> ControlObjects | None:
    spec = scene.control
    if spec is None:
        return None
    from .. import controllers

    plant = objects.plant
    p = spec.params
    with _scene_keys("control", _same_keys("control", tuple(p))):
        if spec.controller == "viscosity":
            controller = controllers.VirtualViscosity(p["slope"], spec.param("reference"), spec.param("band"))
        elif spec.controller == "speed_hold":
            controller = controllers.SpeedHold(p["reference"], p["slope"], spec.param("kp"), spec.param("ki"))
        elif spec.controller == "friction_brake":
            controller = controllers.FrictionBrake(p["fraction"], spec.param("start"), spec.param("hold"))
        else:
            controller = None
    reads = spec.sensors if spec.sensors is not None else scene.sensors is not None
    sensors = estimator = None
    if reads:
        sensors = _noisy_sensors(objects, "control", spec)
    truth, prior = _knowledge("control", spec, sensors)
    if reads:
        estimator = _estimator(spec.estimator or LOOP_ESTIMATOR, _model(plant, sensors), "control", prior)
        rate, key = sensors.rate, "sensors.rate"
    else:
        rate, key = (IDEAL_LOOP_RATE if spec.rate is None else spec.rate), "control.rate"
        if not rate > 0:
            raise _fail(key, "be > 0", rate)
    _check_rate(rate, spec.duration, (key, "control.duration"), "closed loop")
    if controller is not None:
        # Bind once to check the controller on this plant (e.g. finite speed limits).
        with _scene_keys("control", {"plant": "motors.speed_limit"}):
            controller.bind(plant, 1.0 / rate)
    budget = None
    if spec.budget is not None:
        with _scene_keys("control", _same_keys("control.budget", tuple(spec.budget))):
            budget = Budget(**spec.budget)
    return ControlObjects(controller, sensors, estimator, rate, budget, truth)

