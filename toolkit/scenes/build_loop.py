"""What ``[estimation]`` and ``[control]`` build: the estimators on the scene's noisy
sensors with what they are told, the controller and its loop rate, each value checked by the
constructor that takes it and named by its scene key.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

import numpy as np

from ..errors import SceneError
from ..model import ContactSet, PiecewiseConstant, Plant, sample_count, unequal_loads
from ..model.sensors import Sensors
from ..simulation import Budget
from ._key_errors import _same_keys, _scene_keys
from .limits import MAX_RUN_SAMPLES, scene_value_error
from .objects import ControlObjects, EstimationObjects, SceneObjects
from .spec import IDEAL_LOOP_RATE, LOOP_ESTIMATOR, NOISE_KEYS, Scene

_fail = scene_value_error


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
