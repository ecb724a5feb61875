"""Reference scenarios: the estimation acceptance run, the paper's carousel started from rest,
then braked.

The paper's carousel (:data:`toolkit.model.carousel.CAROUSEL`, as in the shipped ``carousel``
design): ten equal wheels of 1 N each, the moving inertia ``m`` = 5 kg (``F_tot / m = 2
m/s^2``), motor lag 7.5 ms, the paper's encoders at 50 Hz. The contacts are commanded to a spread around ``cruise`` from rest, and at
``brake_time`` to a braking set spread around ``brake``; the run is simulated exactly and
recorded through the sensor law.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ..errors import ParameterTypeError, as_int, parameter_message
from ..model import ContactSet, Motors, PiecewiseConstant, Plant, sample_times
from ..model.carousel import CAROUSEL
from ..model.sensors import EncoderRecord, Sensors, record_simulation
from ..model.truth import GRID_STREAM, TrueWorld, WorldTruth, realize
from ..estimation import EstimatorModel, ModelPrior

__all__ = ["BrakeScenario", "carousel_brake_scenario", "record_world", "grid_positions"]


@dataclass(frozen=True, eq=False)
class BrakeScenario:
    """A simulated startup-then-brake run and what an estimator may know about it.

    Attributes
    ----------
    plant : Plant
        The true plant (the nominal one when the world is nominal), with the commands as
        sent (the motors' wander is in ``world``).
    result : SimulationResult
        The exact run of the true plant (its commands include the wander).
    record : EncoderRecord
        Its encoder record (with the truth, for scoring); its commands are those sent.
    sensors : Sensors
        The nominal encoders (what the estimators are told).
    model : EstimatorModel
        The estimator's knowledge: the nominal forces, mass, encoders, motor lag and drag.
    prior : ModelPrior
        What the adaptive estimator believes beyond the nominal scene.
    world : TrueWorld
        The true plant, encoders and wander (simulation and scores only).
    nominal : Plant
        The plant the scene declares.
    """

    plant: Plant
    result: object
    record: EncoderRecord
    sensors: Sensors
    model: EstimatorModel
    prior: ModelPrior = ModelPrior()
    world: TrueWorld | None = None
    nominal: Plant | None = None


def grid_positions(sensors: Sensors, rng: Any) -> dict[str, Any]:
    """Where the body and the contacts start on their encoders' count grids, uniform within one
    count: :func:`~toolkit.model.sensors.record_simulation`'s ``central_position`` (m) and
    ``contact_positions`` (m, shape (n,)).

    ``rng`` is a ``numpy.random.Generator``, or an integer seed whose grid stream
    (``default_rng([seed, GRID_STREAM])``, :data:`toolkit.model.truth.GRID_STREAM`) draws them:
    a scene's ``[estimation] seed``.
    """
    if not isinstance(rng, np.random.Generator):
        rng = np.random.default_rng([as_int(rng, "rng", "grid_positions", low=0), GRID_STREAM])
    return {"central_position": rng.uniform(0.0, sensors.central.distance_per_count),
            "contact_positions": rng.uniform(0.0, sensors.wheel.distance_per_count, sensors.n_wheels)}


def record_world(world: TrueWorld, t_end: float, *, seed: int, v0: float = 0.0,
                 **positions: Any) -> tuple[Any, EncoderRecord]:
    """Simulate a true world exactly from ``v0`` (m/s) over ``t_end`` (s) and record it
    through its encoders.

    The motors run towards the plant's commands (switched when sent, on or off the sample
    grid) plus the world's wander (one offset per sample,
    :meth:`~toolkit.model.truth.TrueWorld.wander`); the record logs the commands sent at
    the samples. ``seed`` seeds the encoders' own draws (``numpy.random.default_rng(seed)``);
    ``positions`` are :func:`~toolkit.model.sensors.record_simulation`'s
    ``central_position`` and ``contact_positions``.

    Returns
    -------
    (SimulationResult, EncoderRecord)
    """
    from ..simulation import simulate

    plant = world.plant
    stamps = sample_times(t_end, world.sensors.rate)
    wander = world.wander(stamps.size)

    def sent(times: np.ndarray) -> np.ndarray:
        if plant.commands is None:
            return np.tile(plant.contacts.speeds, (times.size, 1))
        return np.asarray([plant.commands(t) for t in times])

    simulated = plant
    if wander is not None:        # the command, switched when sent (on or off the samples), plus
        # the wander, switched at each sample
        breaks = stamps[1:]
        if plant.commands is not None:
            switches = plant.commands.times
            breaks = np.union1d(breaks, switches[(switches > 0.0) & (switches <= stamps[-1])])
        held = np.searchsorted(stamps, np.concatenate(([0.0], breaks)), side="right") - 1
        simulated = replace(plant, commands=PiecewiseConstant(
            breaks, sent(np.concatenate(([0.0], breaks))) + wander[held]))
    result = simulate(simulated, t_end, v0=v0)
    record = record_simulation(result, simulated, world.sensors, rng=np.random.default_rng(seed), **positions)
    if wander is not None:        # the commands sent, not the speeds the wandering motors ran at
        record = replace(record, commands=sent(record.times), initial_commands=plant.initial_speeds())
    return result, record


def carousel_brake_scenario(*, seed: int = 0, t_end: float = 10.0, brake_time: float = 5.0,
                            cruise: float = 0.2, brake: float = -0.1, spread: float = 0.05,
                            lag: float = 0.0075, grid_phase: int | None = None,
                            truth: WorldTruth | None = None, prior: ModelPrior | None = None,
                            **noise: float) -> BrakeScenario:
    """Build, simulate exactly and record the carousel's startup-then-brake run.

    Parameters
    ----------
    seed : int
        Seeds the ``numpy.random.Generator`` of the sensors (jitter, missed counts, noise).
    t_end, brake_time : float, s
    cruise, brake, spread : float, m/s
        Contacts at ``cruise + linspace(-spread, spread, 10)`` from rest, then at
        ``brake + linspace(-spread, spread, 10)`` from ``brake_time``.
    lag : float, s
        Motor lag (nominal).
    grid_phase : int, optional
        Seeds uniform draws of where the body and the contacts start on their encoders'
        count grids (within one count: ``record_simulation``'s ``central_position`` and
        ``contact_positions``); ``None``: every grid starts on a count edge.
    truth : WorldTruth, optional
        How the simulated world departs from the nominal scene (drawn from ``seed``:
        :func:`~toolkit.model.truth.realize`); default: not at all.
    prior : ModelPrior, optional
        The estimators' prior knowledge (default ``ModelPrior()``); the model is built from
        the nominal scene only, never from ``truth``.
    **noise
        ``missed_count_prob``, ``count_noise``, ``jitter`` of the nominal :class:`Sensors`
        (declared, so the estimators are told them).
    """
    owner = "carousel_brake_scenario"
    prior = ModelPrior() if prior is None else prior
    if not isinstance(prior, ModelPrior):
        raise ParameterTypeError(parameter_message("prior", owner, "be a ModelPrior or None", prior))
    n = CAROUSEL.n_wheels
    forces = np.full(n, CAROUSEL.wheel_force)
    mass = CAROUSEL.moving_mass
    offsets = np.linspace(-spread, spread, n)
    commands = PiecewiseConstant([brake_time], [cruise + offsets, brake + offsets])
    v_max = CAROUSEL.speed_limit
    nominal = Plant(ContactSet(cruise + offsets, forces), mass,
                    motors=Motors(lag=lag, speed_limits=(-v_max, v_max)), commands=commands)
    sensors = CAROUSEL.sensors(n, **noise)
    world = realize(nominal, sensors, truth, seed)
    plant = world.plant
    positions: dict = {}
    if grid_phase is not None:
        positions = grid_positions(sensors, np.random.default_rng(
            as_int(grid_phase, "grid_phase", "carousel_brake_scenario", low=0)))
    result, record = record_world(world, t_end, seed=seed, **positions)
    # The estimators know the nominal scene: its forces, lag and drag (none).
    model = EstimatorModel(forces, mass, sensors, motor_lag=lag, friction_uncertainty=0.0,
                           speed_limits=(-v_max, v_max))
    return BrakeScenario(plant, result, record, sensors, model, prior, world, nominal)
