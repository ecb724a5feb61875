"""The world as it departs from the nominal scene (toolkit.model.truth) and the brake scenario
built from it: draws reproducible from the seed, the estimators' model never the truth."""

from __future__ import annotations

import math

import numpy as np
import pytest

from toolkit import ParameterError, ParameterTypeError
from toolkit.analysis.scenarios import carousel_brake_scenario
from toolkit.model.carousel import CAROUSEL
from toolkit.model import ContactSet, Motors, Plant
from toolkit.model.sensors import Sensors
from toolkit.model.truth import ModelPrior, WorldTruth, realize


def _nominal() -> tuple[Plant, Sensors]:
    plant = Plant(ContactSet(np.linspace(0.1, 0.2, 10), np.full(10, 1.0)), 5.0,
                  motors=Motors(lag=0.0075, speed_limits=(-0.35, 0.35)))
    return plant, CAROUSEL.sensors()


@pytest.mark.parametrize("name, value", [("friction_spread", -0.1), ("drag", -1.0), ("lag", -0.01),
                                         ("contact_drift", float("nan")), ("read_noise", -0.5),
                                         ("missed_count_prob", 1.5), ("jitter", float("inf"))])
def test_bad_truths_name_the_parameter(name, value):
    with pytest.raises(ParameterError, match=f"^The '{name}' parameter of WorldTruth must"):
        WorldTruth(**{name: value})


@pytest.mark.parametrize("name, value", [("friction_spread", "a"), ("drag", True)])
def test_truths_of_the_wrong_type_name_the_parameter(name, value):
    with pytest.raises(ParameterTypeError, match=f"^The '{name}' parameter of WorldTruth must"):
        WorldTruth(**{name: value})


def test_a_nominal_truth_changes_nothing():
    plant, sensors = _nominal()
    world = realize(plant, sensors, WorldTruth(), seed=3)
    assert WorldTruth().is_nominal and WorldTruth().describe() == "nominal"
    np.testing.assert_array_equal(world.plant.contacts.forces, plant.contacts.forces)
    assert world.plant.damping == plant.damping and world.plant.motors == plant.motors
    assert world.sensors == sensors and world.wander(50) is None


def test_the_true_plant_takes_the_drawn_friction_the_drag_and_the_lag():
    plant, sensors = _nominal()
    truth = WorldTruth(friction_spread=0.2, drag=2.0, lag=0.02, read_noise=0.5, missed_count_prob=1e-3,
                       jitter=5e-4)
    a, b = realize(plant, sensors, truth, seed=7), realize(plant, sensors, truth, seed=7)
    # The same seed draws the same wheels (identity); another seed others.
    np.testing.assert_array_equal(a.plant.contacts.forces, b.plant.contacts.forces)
    other = realize(plant, sensors, truth, seed=8).plant.contacts.forces
    assert not np.array_equal(other, a.plant.contacts.forces)
    # Speeds kept, forces positive, the drag and lag replaced, the encoders noisy as told.
    np.testing.assert_array_equal(a.plant.contacts.speeds, plant.contacts.speeds)
    assert np.all(a.plant.contacts.forces > 0)
    assert a.plant.damping == 2.0 and a.plant.motors.lag == 0.02
    assert a.plant.motors.speed_limits == plant.motors.speed_limits
    assert (a.sensors.count_noise, a.sensors.missed_count_prob, a.sensors.jitter) == (0.5, 1e-3, 5e-4)


def test_the_friction_spread_is_a_mean_keeping_lognormal():
    # Over 4000 wheels drawn at 20 %: sample mean within 4 standard errors of the nominal
    # (0.2 / sqrt(4000) = 0.32 %), relative std within 5 % of 0.2 (its standard error for
    # a lognormal of this spread is about 1.2 %).
    plant = Plant(ContactSet(np.zeros(4000), np.ones(4000)), 1.0)
    forces = WorldTruth(friction_spread=0.2).plant(plant, seed=1).contacts.forces
    assert abs(forces.mean() - 1.0) < 4 * 0.2 / math.sqrt(4000)
    assert forces.std() / forces.mean() == pytest.approx(0.2, rel=0.05)


def test_the_wander_is_a_random_walk_of_the_drift_intensity():
    # Increments of one period h are N(0, drift^2 h): over 200 x 10 increments their std is
    # within 5 % of drift sqrt(h) (standard error 1.6 %); row 0 is the command itself.
    drift, h = 1e-3, 0.02
    walk = WorldTruth(contact_drift=drift).wander(201, 10, h, seed=4)
    assert walk.shape == (201, 10) and np.all(walk[0] == 0.0)
    assert np.std(np.diff(walk, axis=0)) == pytest.approx(drift * math.sqrt(h), rel=0.05)
    np.testing.assert_array_equal(walk, WorldTruth(contact_drift=drift).wander(201, 10, h, seed=4))


def test_the_scenario_model_is_the_nominal_scene_not_the_truth():
    truth = WorldTruth(friction_spread=0.2, drag=2.0, lag=0.02, contact_drift=1e-3)
    sc = carousel_brake_scenario(seed=2, t_end=2.0, brake_time=1.0, truth=truth,
                                 prior=ModelPrior(friction_spread=0.1))
    nominal = carousel_brake_scenario(seed=2, t_end=2.0, brake_time=1.0)
    # The estimators' model: the nominal forces, lag and drag; the record logs the commands
    # sent (not the wandering motors' speeds), the truth is another world.
    np.testing.assert_array_equal(sc.model.forces, nominal.model.forces)
    assert sc.model.motor_lag == 0.0075 and sc.model.damping == 0.0
    assert sc.prior.friction_spread == 0.1
    np.testing.assert_array_equal(sc.record.commands, nominal.record.commands)
    np.testing.assert_array_equal(sc.record.initial_commands, nominal.record.initial_commands)
    assert sc.plant.damping == 2.0 and sc.plant.motors.lag == 0.02
    assert not np.array_equal(sc.plant.contacts.forces, nominal.plant.contacts.forces)
    # The wander moved the true contact speeds off the commands once the motors settled
    # (after 0.5 s the lag's remainder is exp(-25) of the step: what is left is the wander).
    late = sc.record.times > 0.5
    off = np.abs(sc.record.truth_contact_speeds[late] - sc.record.commands[late])
    assert off.max() > 1e-4
    with pytest.raises(ParameterTypeError, match="'prior' parameter of carousel_brake_scenario"):
        carousel_brake_scenario(t_end=1.0, prior="broad")


@pytest.mark.parametrize("kwargs, name", [({"friction_spread": -1.0}, "friction_spread"),
                                          ({"drag_range": (2.0, 1.0)}, "drag_range"),
                                          ({"lag_range": (0.0, -0.1)}, "lag_range"),
                                          ({"contact_drift": -1e-3}, "contact_drift")])
def test_bad_priors_name_the_parameter(kwargs, name):
    with pytest.raises(ParameterError, match=f"^The '{name}' parameter of ModelPrior must"):
        ModelPrior(**kwargs)


def test_the_friction_spread_is_drawn_around_each_wheels_own_force():
    """Two groups of 2000 wheels, nominal 1 N and 4 N (unequal, interleaved): each group's
    sample mean is within 4 standard errors (0.2 / sqrt(2000) = 0.45 %) of its own nominal and
    its relative std within 6 % of 0.2 (standard error about 1.6 %). Mutant killed: the spread
    drawn around the mean of all wheels (2.5 N), which keeps the overall mean."""
    nominal = np.tile([1.0, 4.0], 2000)
    plant = Plant(ContactSet(np.zeros(nominal.size), nominal), 1.0)
    forces = WorldTruth(friction_spread=0.2).plant(plant, seed=5).contacts.forces
    for own in (1.0, 4.0):
        group = forces[nominal == own]
        assert abs(group.mean() / own - 1.0) < 4 * 0.2 / math.sqrt(group.size)
        assert group.std() / group.mean() == pytest.approx(0.2, rel=0.06)


_PLANT, _SENSORS = Plant(ContactSet([0.0, 0.1]), 1.0), CAROUSEL.sensors(2)


@pytest.mark.parametrize(("call", "error", "message"), [
    (lambda: WorldTruth(friction_spread=-0.1), ParameterError,
     "The 'friction_spread' parameter of WorldTruth must be >= 0. Got -0.1 instead."),
    (lambda: WorldTruth(drag=-1.0), ParameterError,
     "The 'drag' parameter of WorldTruth must be >= 0. Got -1.0 instead."),
    (lambda: WorldTruth(lag=-0.01), ParameterError,
     "The 'lag' parameter of WorldTruth must be >= 0. Got -0.01 instead."),
    (lambda: WorldTruth(contact_drift=float('nan')), ParameterError,
     "The 'contact_drift' parameter of WorldTruth must be finite. Got nan instead."),
    (lambda: WorldTruth(read_noise=-0.5), ParameterError,
     "The 'read_noise' parameter of WorldTruth must be >= 0. Got -0.5 instead."),
    (lambda: WorldTruth(missed_count_prob=1.5), ParameterError,
     "The 'missed_count_prob' parameter of WorldTruth must be <= 1. Got 1.5 instead."),
    (lambda: WorldTruth(jitter=float('inf')), ParameterError,
     "The 'jitter' parameter of WorldTruth must be finite. Got inf instead."),
    (lambda: WorldTruth().plant('x'), ParameterTypeError,
     "The 'nominal' parameter of WorldTruth.plant must be a Plant. Got 'x' instead."),
    (lambda: WorldTruth().sensors('x'), ParameterTypeError,
     "The 'nominal' parameter of WorldTruth.sensors must be a Sensors. Got 'x' instead."),
    (lambda: WorldTruth().plant(_PLANT, seed=-1), ParameterError,
     "The 'seed' parameter of WorldTruth.plant must be >= 0. Got -1 instead."),
    (lambda: WorldTruth(contact_drift=1e-3).wander(0, 2, 0.02), ParameterError,
     "The 'samples' parameter of WorldTruth.wander must be >= 1. Got 0 instead."),
    (lambda: WorldTruth(contact_drift=1e-3).wander(5, 0, 0.02), ParameterError,
     "The 'n' parameter of WorldTruth.wander must be >= 1. Got 0 instead."),
    (lambda: WorldTruth(contact_drift=1e-3).wander(5, 2, 0.0), ParameterError,
     "The 'period' parameter of WorldTruth.wander must be > 0. Got 0.0 instead."),
    (lambda: realize(_PLANT, _SENSORS, 'x'), ParameterTypeError,
     "The 'truth' parameter of realize must be a WorldTruth or None. Got 'x' instead."),
    (lambda: realize(_PLANT, 'x'), ParameterTypeError,
     "The 'sensors' parameter of realize must be a Sensors. Got 'x' instead."),
    (lambda: ModelPrior(drag_range=(2.0, 1.0)), ParameterError,
     "The 'drag_range' parameter of ModelPrior must satisfy low <= high. Got (2.0, 1.0) instead."),
    (lambda: ModelPrior(drag_range=3.0), ParameterTypeError,
     "The 'drag_range' parameter of ModelPrior must be a pair (low, high) or None. Got 3.0 instead."),
    (lambda: ModelPrior(lag_range=(0.0, 20.0)), ParameterError,
     "The 'lag_range' parameter of ModelPrior must be <= 10. Got 20.0 instead."),
    (lambda: ModelPrior(drag_range=(-1.0, 1.0)), ParameterError,
     "The 'drag_range' parameter of ModelPrior must be >= 0. Got -1.0 instead."),
    (lambda: ModelPrior(friction_spread=-0.1), ParameterError,
     "The 'friction_spread' parameter of ModelPrior must be >= 0. Got -0.1 instead."),
    (lambda: ModelPrior(missed_count_prob=2.0), ParameterError,
     "The 'missed_count_prob' parameter of ModelPrior must be <= 0.5. Got 2.0 instead."),
])
def test_every_refusal_of_the_truth_and_the_prior_in_full(call, error, message):
    """Each refusal matched whole: parameter, owner, rule and value (mutants: any of them changed,
    dropped or replaced by None, a bound changed)."""
    with pytest.raises(error) as info:
        call()
    assert str(info.value) == message



@pytest.mark.parametrize("kwargs, message", [
    ({"missed_count_mean": 0.0}, "The 'missed_count_mean' parameter of ModelPrior must be > 0. Got 0.0 instead."),
    ({"missed_count_mean": 0.02}, "The 'missed_count_mean' parameter of ModelPrior must be <= 0.01. Got 0.02 instead."),
    ({"friction_spread": 11.0}, "The 'friction_spread' parameter of ModelPrior must be <= 10. Got 11.0 instead."),
    ({"contact_drift": -1e-3}, "The 'contact_drift' parameter of ModelPrior must be >= 0. Got -0.001 instead."),
    ({"lag_range": (0.0, 11.0)}, "The 'lag_range' parameter of ModelPrior must be <= 10. Got 11.0 instead."),
    ({"drag_range": (1.0, "a")}, "The 'drag_range' parameter of ModelPrior must be a real number. Got 'a' instead."),
])
def test_prior_bounds_refused_whole(kwargs, message):
    """Each bound of the prior refused whole (mutants: a bound, its openness, the name)."""
    with pytest.raises((ParameterError, ParameterTypeError)) as info:
        ModelPrior(**kwargs)
    assert str(info.value) == message


def test_prior_keeps_what_it_is_told_as_floats():
    """Every field kept as told, converted to float, at its bounds' ends (mutants: a field set
    to None or under another name, a closed bound made open)."""
    prior = ModelPrior(friction_spread=10, drag_range=(0, 2), lag_range=(0.01, 10), contact_drift=0,
                       missed_count_prob=np.float64(0.5), missed_count_mean=np.float64(0.01))
    assert (prior.friction_spread, prior.drag_range, prior.lag_range) == (10.0, (0.0, 2.0), (0.01, 10.0))
    assert (prior.contact_drift, prior.missed_count_prob, prior.missed_count_mean) == (0.0, 0.5, 0.01)
    assert all(type(v) is float for v in (prior.friction_spread, prior.contact_drift, prior.missed_count_prob,
                                           prior.missed_count_mean, *prior.drag_range, *prior.lag_range))
    default = ModelPrior()
    assert (default.friction_spread, default.drag_range, default.lag_range) == (0.3, None, None)
    assert (default.contact_drift, default.missed_count_prob, default.missed_count_mean) == (None, 0.0, None)
