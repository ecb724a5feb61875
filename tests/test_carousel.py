"""The reference carousel (toolkit.model.carousel): its motors and encoders as the hardware
states them, and the startup scene at several masses."""

from __future__ import annotations

import re

import numpy as np
import pytest

from toolkit import ParameterError
from toolkit.model.carousel import CAROUSEL, CAROUSEL_ACCELERATION, CAROUSEL_SPEED_LIMIT, carousel_startup_plant
from toolkit.model.parameters import PARAMETERS


def test_motors_and_encoders_are_the_hardwares():
    """Every figure passed on as stated (mutants: an argument dropped or swapped, the lower
    speed limit's sign, the wheel count's default)."""
    motors = CAROUSEL.motors()
    assert motors.lag == PARAMETERS["motor_lag"].value
    assert motors.speed_limits == (-0.35, 0.35)
    sensors = CAROUSEL.sensors()
    central, wheel = sensors.central, sensors.wheel
    assert (central.counts_per_rev, central.radius, central.rate, central.backlash) == (8192.0, 0.266, 50.0, 0.0)
    assert (wheel.counts_per_rev, wheel.radius, wheel.rate) == (3591.84, 0.045, 50.0)
    assert wheel.backlash == PARAMETERS["wheel_backlash"].value
    assert sensors.n_wheels == 10 and CAROUSEL.sensors(4).n_wheels == 4
    noisy = CAROUSEL.sensors(3, count_noise=0.5, missed_count_prob=1e-3)
    assert (noisy.n_wheels, noisy.count_noise, noisy.missed_count_prob) == (3, 0.5, 1e-3)
    # 0.353780 kg m^2 over (0.266 m)^2: 5.000 kg to the stated digits.
    assert CAROUSEL.moving_mass == pytest.approx(5.0, rel=1e-4, abs=0.0)


@pytest.mark.parametrize("mass", [2.0 ** -20, 1.0, 5.0, 2.0 ** 20])
def test_startup_plant_scales_its_forces_with_the_mass(mass):
    """Equal loads with ``F_tot / m = 2`` m/s^2 at every mass (n = 7 sums of equal terms: a
    few eps), the same speeds for the same seed, uniform within the speed limits; by default
    seed 0, 11 contacts, 1 kg (mutants: the mass dropped from the forces, a default changed)."""
    plant = carousel_startup_plant(3, n=7, mass=mass)
    reference = carousel_startup_plant(3, n=7)
    f = plant.contacts.forces
    assert plant.mass == mass and f.size == 7 and np.all(f == f[0])
    np.testing.assert_allclose(plant.contacts.total_force / mass, CAROUSEL_ACCELERATION, rtol=8 * np.finfo(float).eps,
                               atol=0.0)
    assert CAROUSEL_ACCELERATION == 2.0
    np.testing.assert_array_equal(plant.contacts.speeds, reference.contacts.speeds)
    np.testing.assert_array_equal(plant.contacts.speeds,
                                  np.random.default_rng(3).uniform(-CAROUSEL_SPEED_LIMIT, CAROUSEL_SPEED_LIMIT, 7))
    assert not np.array_equal(plant.contacts.speeds, carousel_startup_plant(4, n=7).contacts.speeds)
    default = carousel_startup_plant()
    assert default.contacts.n == 11 and default.mass == 1.0
    np.testing.assert_array_equal(default.contacts.speeds,
                                  np.random.default_rng(0).uniform(-CAROUSEL_SPEED_LIMIT, CAROUSEL_SPEED_LIMIT, 11))


@pytest.mark.parametrize("kwargs, rule", [({"seed": -1}, "'seed' parameter of carousel_startup_plant must be >= 0. "
                                                         "Got -1 instead."),
                                          ({"n": 0}, "'n' parameter of carousel_startup_plant must be >= 1. Got 0 instead."),
                                          ({"mass": 0.0}, "'mass' parameter of carousel_startup_plant must be > 0. "
                                                          "Got 0.0 instead.")])
def test_startup_plant_refuses_with_the_parameter(kwargs, rule):
    with pytest.raises(ParameterError, match="^The " + re.escape(rule) + "$"):
        carousel_startup_plant(**kwargs)
