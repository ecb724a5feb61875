"""Reference scenarios: the estimation acceptance run, the paper's carousel started from rest,
then braked.

The paper's carousel (:data:`toolkit.model.carousel.CAROUSEL`, as in the shipped ``carousel``
design): ten equal wheels of 1 N each, the moving inertia ``m`` = 5 kg (``F_tot / m = 2
m/s^2``), motor lag 7.5 ms, the paper's encoders at 50 Hz. The contacts are commanded to a spread around ``cruise`` from rest, and at
``brake_time`` to a braking set spread around ``brake``; the run is simulated exactly and
recorded through the sensor law.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import as_int
from ..model import ContactSet, Motors, PiecewiseConstant, Plant
from ..model.carousel import CAROUSEL
from ..model.sensors import EncoderRecord, Sensors, record_simulation
from ..estimation import EstimatorModel

__all__ = ["BrakeScenario", "carousel_brake_scenario"]


@dataclass(frozen=True, eq=False)
class BrakeScenario:
    """A simulated startup-then-brake run and what an estimator may know about it.

    Attributes
    ----------
    plant : Plant
    result : SimulationResult
        The exact run.
    record : EncoderRecord
        Its encoder record (with the truth, for scoring).
    sensors : Sensors
    model : EstimatorModel
        The estimator's knowledge: nominal forces, mass, encoders, motor lag.
    """

    plant: Plant
    result: object
    record: EncoderRecord
    sensors: Sensors
    model: EstimatorModel


def carousel_brake_scenario(*, seed: int = 0, t_end: float = 10.0, brake_time: float = 5.0,
                            cruise: float = 0.2, brake: float = -0.1, spread: float = 0.05,
                            lag: float = 0.0075, grid_phase: int | None = None,
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
        Motor lag.
    grid_phase : int, optional
        Seeds uniform draws of where the body and the contacts start on their encoders'
        count grids (within one count: ``record_simulation``'s ``central_position`` and
        ``contact_positions``); ``None``: every grid starts on a count edge.
    **noise
        ``missed_count_prob``, ``count_noise``, ``jitter`` of :class:`Sensors`.
    """
    from ..simulation import simulate

    n = CAROUSEL.n_wheels
    forces = np.full(n, CAROUSEL.wheel_force)
    mass = CAROUSEL.moving_mass
    offsets = np.linspace(-spread, spread, n)
    commands = PiecewiseConstant([brake_time], [cruise + offsets, brake + offsets])
    v_max = CAROUSEL.speed_limit
    plant = Plant(ContactSet(cruise + offsets, forces), mass,
                  motors=Motors(lag=lag, speed_limits=(-v_max, v_max)), commands=commands)
    result = simulate(plant, t_end)
    sensors = CAROUSEL.sensors(n, **noise)
    positions: dict = {}
    if grid_phase is not None:
        draw = np.random.default_rng(as_int(grid_phase, "grid_phase", "carousel_brake_scenario", low=0))
        positions = {"central_position": draw.uniform(0.0, sensors.central.distance_per_count),
                     "contact_positions": draw.uniform(0.0, sensors.wheel.distance_per_count, n)}
    record = record_simulation(result, plant, sensors, rng=np.random.default_rng(seed), **positions)
    # The plant's friction is exactly the scene's (equal forces): no friction spread to model.
    model = EstimatorModel(forces, mass, sensors, motor_lag=lag, friction_uncertainty=0.0,
                           speed_limits=(-v_max, v_max))
    return BrakeScenario(plant, result, record, sensors, model)
