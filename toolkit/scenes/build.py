"""Build toolkit objects from a parsed scene: the one place scene specs become objects.

:mod:`toolkit.scenes.spec` reads a TOML file into frozen spec dataclasses and checks the *form* of
every value (known keys, types, finite numbers, rules between sections, and the rules of
keys no constructor takes, such as ``motors.speed_limit`` or ``contacts.random``).
:func:`build_scene` then builds the objects those specs declare, once:

==========================  ===============================================================
``[contacts]``              :class:`~toolkit.model.ContactSet` (speeds within the motor
                            limits, or clipped to them with ``[motors] clip = true``)
``[motors]``                :class:`~toolkit.model.Motors`
``[body]`` (+ motors,       :class:`~toolkit.model.Plant`, its external force and commands
``simulation.commands``)    as :class:`~toolkit.model.PiecewiseConstant` signals
``[sensors]``               :class:`~toolkit.model.Encoder` per declared encoder
``[target]``                the allocation target (:class:`~toolkit.ForceCurve`, ...)
``[schedule]``              the schedule target (:class:`~toolkit.Braking` or
                            :class:`~toolkit.SpeedTrajectory`)
``simulation.options``      the options of :func:`toolkit.simulate`; a ``budget`` table
                            becomes a :class:`~toolkit.simulation.Budget`
``[estimation]``            :class:`EstimationObjects`: the noisy :class:`~toolkit.model.
                            sensors.Sensors`, the estimator's :class:`~toolkit.estimation.
                            EstimatorModel`, the estimators, the brake scenario's plant
``[control]``               :class:`ControlObjects`: the controller (bound once here to
                            check it), the sensors and estimator it reads, the step budget
==========================  ===============================================================

A rate is refused (under ``sensors.rate`` or ``control.rate``) when it is not > 0, when the
run it samples would take more than :data:`MAX_RUN_SAMPLES` samples, or when its period is
below what the simulation clock resolves at the end of the run.

Contact speeds and ``simulation.commands`` beyond the motors' speed limits are refused
(a :class:`~toolkit.errors.SceneError` naming the key, the limit and the value) unless the
scene sets ``[motors] clip = true``; then they are clipped and every clip is recorded in
:attr:`SceneObjects.clipped` (the study reports them as shortfalls).

Each value's rules live in the constructor that takes it (the motor lag in
:class:`~toolkit.model.Motors`, the mass in :class:`~toolkit.model.Plant`, ...). A
constructor's :class:`~toolkit.errors.ParameterError` becomes a
:class:`~toolkit.errors.SceneError` that keeps the constructor's rule and value and names
the scene key::

    In [motors]: The 'lag' parameter of Motors must be >= 0. Got -0.1 instead.
    (scene key 'motors.lag')
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass, field, fields, replace
from typing import TYPE_CHECKING, Any

import numpy as np

from .._validation import check_option, suggestion
from ..allocation import METHODS, EquilibriumSpeed, ForceCurve, FrictionFraction, Viscosity
from ..errors import ParameterError, ParameterTypeError, SceneError
from ..model import ContactSet, Encoder, Motors, PiecewiseConstant, Plant, unequal_loads
from ..model.sensors import Sensors
from ..schedule import Braking, SpeedTrajectory
from ..simulation import Budget

if TYPE_CHECKING:                      # scene.py imports this module: types only, no cycle
    from .spec import Scene, ScheduleSpec

__all__ = ["Clip", "SceneObjects", "EstimationObjects", "ControlObjects", "build_scene", "scene_plant",
           "schedule_target", "MAX_RUN_SAMPLES"]

#: Most samples an estimation record or a closed loop may take (its arrays grow with them).
MAX_RUN_SAMPLES = 10_000_000

#: The parameter name in the single error template (:func:`toolkit.errors.parameter_message`).
_PARAMETER = re.compile(r"The '(?P<name>[^']+)' parameter of ")


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


@dataclass(frozen=True, eq=False)
class SceneObjects:
    """The toolkit objects a scene declares, built and validated once by :func:`build_scene`.

    Attributes
    ----------
    contacts : ContactSet
        Declared contact speeds (m/s) and friction magnitudes (N), shape (n,).
    motors : Motors or None
        ``[motors]``; None for ideal motors.
    plant : Plant or None
        ``[body]`` on the declared contacts with the motors, the external force (N) and the
        ``[simulation]`` commands (m/s); None without ``[body]``.
    encoders : dict of str to Encoder
        ``"wheel"`` and ``"central"``, those ``[sensors]`` declares (empty without it).
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
        ``[estimation]``.
    control : ControlObjects or None
        ``[control]``.
    sweep : experiment or None
        ``[sweep]`` (:mod:`toolkit.experiments`); in a sweep scene the only object
        (``contacts`` is then None).
    """

    contacts: ContactSet | None
    motors: Motors | None = None
    plant: Plant | None = None
    encoders: dict[str, Encoder] = field(default_factory=dict)
    target: Any = None
    schedule_target: Braking | SpeedTrajectory | None = None
    simulation_options: dict[str, Any] = field(default_factory=dict)
    clipped: tuple[Clip, ...] = ()
    estimation: EstimationObjects | None = None
    control: ControlObjects | None = None
    sweep: Any = None

    def plant_on(self, contacts: ContactSet | None = None) -> Plant:
        """The scene's plant, on other contacts (e.g. allocated ones) when given.

        Raises
        ------
        SceneError
            The scene has no ``[body]`` (the moving inertia).
        """
        if self.plant is None:
            raise SceneError("This stage needs a [body] section (the moving inertia).")
        if contacts is None or contacts is self.contacts:
            return self.plant
        return replace(self.plant, contacts=contacts)


@contextmanager
def _scene_keys(section: str, keys: Mapping[str, str | tuple[str, ...]]) -> Iterator[None]:
    """Turn a constructor's parameter error into a SceneError naming the scene key.

    ``keys`` maps the constructor's parameter names to the scene key (or keys) that set
    them; the message keeps the constructor's rule and value (one template everywhere) and
    adds the key.
    """
    try:
        yield
    except SceneError:
        raise
    except (ParameterError, ParameterTypeError) as error:
        message = str(error)
        match = _PARAMETER.match(message)
        found = keys.get(match["name"], ()) if match else ()
        names = (found,) if isinstance(found, str) else found
        where = names[0].split(".")[0] if names else section
        suffix = (f" (scene keys {' and '.join(map(repr, names))})" if len(names) > 1
                  else f" (scene key {names[0]!r})" if names else "")
        raise SceneError(f"In [{where}]: {message}{suffix}") from None


def _same_keys(section: str, names: tuple[str, ...]) -> dict[str, str]:
    return {name: f"{section}.{name}" for name in names}


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
            return ForceCurve(p["speeds"], p["forces"], p.get("weights"))
        if spec.kind == "viscosity":
            return Viscosity(p["slope"], p["center"], p["band"])
        if spec.kind == "friction_fraction":
            return FrictionFraction(p["fraction"], p["band"])
        return EquilibriumSpeed(p["speed"], p.get("margin", 0))


def schedule_target(spec: ScheduleSpec | None) -> Braking | SpeedTrajectory | None:
    """The schedule target a ``[schedule]`` section declares (None without one)."""
    if spec is None:
        return None
    with _scene_keys("schedule", _same_keys("schedule", tuple(spec.params))):
        if spec.kind == "braking":
            return Braking(spec.params["speed"], spec.params.get("duration"))
        return SpeedTrajectory(spec.params["times"], spec.params["speeds"])


def build_scene(scene: Scene) -> SceneObjects:
    """Build every object ``scene`` declares (use ``scene.objects``: built once and kept).

    Parameters
    ----------
    scene : Scene
        A parsed scene (:func:`toolkit.load_scene`).

    Returns
    -------
    SceneObjects

    Raises
    ------
    SceneError
        A constructor refused a value; the message names the scene key, the rule and the
        value received.
    """
    if scene.sweep is not None:
        return SceneObjects(contacts=None, sweep=_sweep(scene))
    clips: list[Clip] = []
    contacts = _contacts(scene, clips)
    motors = _motors(scene)
    plant = _plant(scene, contacts, motors, clips)
    return SceneObjects(contacts=contacts, motors=motors, plant=plant,
                        encoders=_encoders(scene), target=_target(scene),
                        schedule_target=schedule_target(scene.schedule),
                        simulation_options=_simulation_options(scene), clipped=tuple(clips),
                        estimation=_estimation(scene, plant), control=_control(scene, plant))


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


def scene_plant(scene: Scene, contacts: ContactSet | None = None) -> Plant:
    """The :class:`~toolkit.model.Plant` a scene declares (needs ``[body]``), optionally on
    other contacts."""
    return scene.objects.plant_on(contacts)


# -- estimation and control ------------------------------------------------------------------

@dataclass(frozen=True, eq=False)
class EstimationObjects:
    """What ``[estimation]`` declares, built once.

    Attributes
    ----------
    sensors : Sensors
        The scene's encoders with the section's noise (missed counts, read noise, jitter).
    model : EstimatorModel
        What the model-based estimators know: the declared forces (N), the mass (kg), the
        sensors, the motor lag (s), the drag (N s/m) and ``friction_spread``.
    estimators : dict of str to Estimator
        One per ``methods`` entry, in order (each run resets its estimator).
    plant : Plant or None
        The brake scenario's plant (true friction: the declared forces with the drawn
        spread) and its commands; None for ``scenario = "simulation"``.
    duration : float, s
        Length of the record (brake scenario); the simulation's ``t_end`` otherwise.
    """

    sensors: Sensors
    model: Any
    estimators: dict[str, Any]
    plant: Plant | None
    duration: float


@dataclass(frozen=True, eq=False)
class ControlObjects:
    """What ``[control]`` declares, built once.

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
    """

    controller: Any
    sensors: Sensors | None
    estimator: Any
    rate: float
    budget: Budget | None


def _check_rate(rate: float, duration: float, key: str, what: str) -> None:
    """A sample rate the run can honour: a resolvable period and at most MAX_RUN_SAMPLES samples."""
    samples = math.floor(duration * rate + 1e-9) + 1
    if samples > MAX_RUN_SAMPLES:
        raise SceneError(f"The {key!r} value in the scene must give at most {MAX_RUN_SAMPLES} samples "
                         f"over the {what} of {duration:g} s. Got {rate:g} Hz ({samples} samples) instead.")
    if not duration + 1.0 / rate > duration:
        raise SceneError(f"The {key!r} value in the scene must give a period the simulation clock "
                         f"resolves at t = {duration:g} s. Got {rate:g} Hz instead.")


def _noisy_sensors(scene: Scene, section: str, spec: Any) -> Sensors:
    noise = {key: getattr(spec, key) for key in ("missed_count_prob", "count_noise", "jitter")}
    with _scene_keys(section, _same_keys(section, tuple(noise))):
        return Sensors.from_spec(scene.sensors, scene.contacts.n, **noise)


def _model(plant: Plant, sensors: Sensors, friction_spread: float = 0.0) -> Any:
    from ..estimation import EstimatorModel

    motors = plant.motors
    with _scene_keys("estimation", {"friction_uncertainty": "estimation.friction_spread"}):
        return EstimatorModel(plant.contacts.forces, plant.mass, sensors,
                              motor_lag=motors.lag if motors is not None else 0.0,
                              damping=plant.damping, friction_uncertainty=friction_spread,
                              speed_limits=motors.speed_limits if motors is not None else (-math.inf, math.inf))


def _estimator(name: str, model: Any, section: str, covariance: Any = None) -> Any:
    """The estimator ``name`` on ``model`` (``initial_covariance`` for the filters)."""
    from ..estimation import (CentralDifference, KalmanEstimator, RTSSmoother, UnscentedEstimator,
                             WheelDifference)

    if name == "central_difference":
        return CentralDifference(model.sensors)
    if name == "wheel_difference":
        return WheelDifference(model.sensors, model.forces)
    make = {"kalman": KalmanEstimator, "rts": RTSSmoother, "ukf": UnscentedEstimator}[name]
    with _scene_keys(section, {"initial_covariance": f"{section}.initial_covariance"}):
        return make(model, initial_covariance=covariance)


def _estimation(scene: Scene, plant: Plant | None) -> EstimationObjects | None:
    spec = scene.estimation
    if spec is None:
        return None
    assert plant is not None and scene.sensors is not None      # scene.py requires [body], [sensors]
    sensors = _noisy_sensors(scene, "estimation", spec)
    model = _model(plant, sensors, spec.friction_spread)
    covariance = None if spec.initial_covariance is None else np.array(spec.initial_covariance)
    estimators = {name: _estimator(name, model, "estimation", covariance) for name in spec.methods}
    scenario_plant = None
    if spec.scenario == "brake":
        duration = spec.record_duration
        if spec.brake_time > duration:
            raise SceneError(f"The 'estimation.brake_time' value in the scene must be <= "
                             f"estimation.duration ({duration:g} s). Got {spec.brake_time:g} instead.")
        n = plant.n
        offsets = np.linspace(-spec.spread, spec.spread, n)
        cruise, brake = spec.cruise + offsets, spec.brake + offsets
        low, high = scene.motors.speed_limits if scene.motors is not None else (-math.inf, math.inf)
        for key, centre in (("estimation.cruise", spec.cruise), ("estimation.brake", spec.brake)):
            if centre - spec.spread < low or centre + spec.spread > high:
                raise SceneError(f"The {key!r} value in the scene must keep {key.split('.')[1]} +- "
                                 f"estimation.spread ({spec.spread:g} m/s) within the motors' speed limits "
                                 f"[{low:g}, {high:g}] m/s. Got {centre:g} m/s instead.")
        rng = np.random.default_rng([spec.seed, 1])      # the sensors draw from default_rng(seed)
        forces = unequal_loads(plant.contacts.forces, spec.friction_spread, n, rng)
        commands = PiecewiseConstant([spec.brake_time], [cruise, brake])
        scenario_plant = replace(plant, contacts=ContactSet(cruise, forces), commands=commands,
                                 external_force=0.0)
    else:
        duration = scene.simulation.t_end                      # type: ignore[union-attr]
    _check_rate(sensors.rate, duration, "sensors.rate", "estimation record")
    return EstimationObjects(sensors, model, estimators, scenario_plant, duration)


def _control(scene: Scene, plant: Plant | None) -> ControlObjects | None:
    spec = scene.control
    if spec is None:
        return None
    assert plant is not None                                   # scene.py requires [body]
    from .. import controllers

    p = spec.params
    with _scene_keys("control", _same_keys("control", tuple(p))):
        if spec.controller == "viscosity":
            controller = controllers.VirtualViscosity(p["slope"], p.get("reference", 0.0), p.get("band"))
        elif spec.controller == "speed_hold":
            controller = controllers.SpeedHold(p["reference"], p["slope"], p.get("kp", 0.5), p.get("ki", 5.0))
        elif spec.controller == "friction_brake":
            controller = controllers.FrictionBrake(p["fraction"], p.get("start", 0.0), p.get("hold"))
        else:
            controller = None
    reads = spec.sensors if spec.sensors is not None else scene.sensors is not None
    sensors = estimator = None
    if reads:
        sensors = _noisy_sensors(scene, "control", spec)
        estimator = _estimator(spec.estimator or "kalman", _model(plant, sensors), "control")
        rate, key = sensors.rate, "sensors.rate"
    else:
        rate, key = (50.0 if spec.rate is None else spec.rate), "control.rate"
        if not rate > 0:
            raise _fail_value(key, "be > 0", rate)
    _check_rate(rate, spec.duration, key, "closed loop")
    if controller is not None:
        # Bind once to check the controller on this plant (e.g. finite speed limits).
        with _scene_keys("control", {"plant": "motors.speed_limit"}):
            controller.bind(plant, 1.0 / rate)
    budget = None
    if spec.budget is not None:
        with _scene_keys("control", _same_keys("control.budget", tuple(spec.budget))):
            budget = Budget(**spec.budget)
    return ControlObjects(controller, sensors, estimator, rate, budget)


def _fail_value(key: str, rule: str, value: Any) -> SceneError:
    return SceneError(f"The {key!r} value in the scene must {rule}. Got {value!r} instead.")
