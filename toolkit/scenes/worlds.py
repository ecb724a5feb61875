"""Random estimation worlds (:class:`toolkit.analysis.robustness.RandomWorld`) as scenes: the
declared plant and encoders, the commands under ``[simulation]``, and ``[estimation]`` with the
departures under ``[estimation.truth]``."""

from __future__ import annotations

from dataclasses import fields

from ..analysis.robustness import WORLD_METHODS, RandomWorld
from ..model.carousel import CAROUSEL
from ..model.truth import WorldTruth
from .spec import BodySpec, ContactsSpec, EstimationSpec, MotorsSpec, Scene, SensorsSpec, SimulationSpec

__all__ = ["world_scene"]


def world_scene(world: RandomWorld) -> Scene:
    """The world as a :class:`~toolkit.scenes.spec.Scene`: the declared plant and encoders,
    its commands under ``[simulation]``, and ``[estimation]`` (``scenario = "simulation"``,
    the seed, :data:`~toolkit.analysis.robustness.WORLD_METHODS`) with the departures under
    ``[estimation.truth]`` (write it with :func:`~toolkit.scenes.spec.dumps_scene`)."""
    v_max = CAROUSEL.speed_limit
    truth = {item.name: getattr(world.truth, item.name) for item in fields(WorldTruth)
             if getattr(world.truth, item.name) not in (None, 0.0)}
    sensors = world.sensors()
    return Scene(
        name=f"random-{world.label.replace('/', '-')}", description=world.describe(),
        contacts=ContactsSpec(speeds=world.commands[0], forces=world.forces), body=BodySpec(mass=world.mass),
        motors=MotorsSpec(speed_limits=(-v_max, v_max), speed_limit=v_max, lag=world.lag),
        sensors=SensorsSpec(rate=world.rate, wheel_counts_per_rev=sensors.wheel.counts_per_rev,
                            wheel_radius=sensors.wheel.radius, wheel_backlash=sensors.wheel.backlash,
                            central_counts_per_rev=sensors.central.counts_per_rev,
                            contact_radius=sensors.central.radius),
        simulation=SimulationSpec(t_end=world.duration, v0=world.v0,
                                  commands={"times": world.times, "values": world.commands}),
        estimation=EstimationSpec(methods=WORLD_METHODS, scenario="simulation", seed=world.seed, truth=truth))
