"""The checks :func:`~toolkit.scenes.build.build_scene` makes before it builds anything:
every bounded value of every section, and the rules that tie one section to another (the body
a stage needs, contact indices, the sensors an estimator or a loop reads, the names of
methods and estimators).
"""

from __future__ import annotations

import math
from typing import Any

from ..errors import SceneError, suggestion
from .keys import bounded_values
from .limits import scene_value_error
from .spec import NOISE_KEYS, SECTIONS, Scene

_fail = scene_value_error


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
