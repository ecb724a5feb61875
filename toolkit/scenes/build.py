"""Build toolkit objects from a parsed scene: the one place scene specs become objects.

:func:`build_scene` checks every value and every rule between sections
(:mod:`~toolkit.scenes.rules`), then builds fresh objects (:mod:`~toolkit.scenes.objects`; a
study builds them once per run: estimators and controllers carry state, and
:mod:`~toolkit.scenes.build_loop` builds those).

The bounds of values no constructor takes are declared with their keys
(:mod:`toolkit.scenes.spec`); every other value is checked by the constructor that takes it,
and a constructor's :class:`~toolkit.errors.ParameterError` becomes a
:class:`~toolkit.errors.SceneError` that keeps the rule and value and names the scene key::

    In [motors]: The 'lag' parameter of Motors must be >= 0. Got -0.1 instead.
    (scene key 'motors.lag')
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import fields, replace
from typing import Any

import numpy as np

from ..errors import check_option, suggestion
from ..allocation import METHODS, EquilibriumSpeed, ForceCurve, FrictionFraction, Viscosity
from ..errors import SceneError
from ..model import ContactSet, Encoder, Motors, PiecewiseConstant, Plant, sample_count
from ..model.sensors import Sensors
from ..schedule import Braking, SpeedTrajectory
from ..simulation import Budget
from ._key_errors import _same_keys, _scene_keys
from .build_loop import _control, _estimation
from .limits import BYTES_PER_NUMBER, MAX_OUTPUT_BYTES, scene_value_error
from .objects import Clip, ControlObjects, EstimationObjects, SceneObjects
from .rules import _check_across, _check_limits
from .spec import Scene, ScheduleSpec

__all__ = ["Clip", "SceneObjects", "EstimationObjects", "ControlObjects", "build_scene", "schedule_target",
           "output_numbers", "sweep_scene_error", "planar_scene_error", "check_record_outputs"]

_fail = scene_value_error


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
        ``[estimation]``            ``EstimationObjects``
        ``[control]``               ``ControlObjects``
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
