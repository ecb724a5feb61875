"""Controllers: the speeds they command, checked against closed forms of the allocation."""

from __future__ import annotations

import numpy as np
import pytest

from toolkit import ContactSet, Motors, ParameterError, PiecewiseConstant, Plant
from toolkit.controllers import ForceDrive, FrictionBrake, OpenLoop, SpeedHold, VirtualViscosity

F, N, VMAX = 0.2, 10, 0.35


@pytest.fixture
def plant():
    return Plant(ContactSet([0.0] * N, [F] * N), 1.0,
                 motors=Motors(lag=0.0075, speed_limits=(-VMAX, VMAX)))


def test_virtual_viscosity_is_a_uniform_staircase_of_spacing_2f_over_k(plant):
    k = 10.0
    speeds = np.sort(VirtualViscosity(k, 0.1).bind(plant, 0.02).output(0.0, np.zeros(0), 0.0).commands)
    # Quantiles of the linear law (docs/physics.md section 8): spacing 2 f / k, centred on 0.1.
    np.testing.assert_allclose(np.diff(speeds), 2 * F / k, rtol=1e-12)
    assert np.mean(speeds) == pytest.approx(0.1, abs=1e-15)


@pytest.mark.parametrize("j", [0, 1, 2, 3, 4, 5])
def test_friction_brake_splits_5_minus_j_and_5_plus_j(plant, j):
    law = FrictionBrake(j / 5, start=0.5).bind(plant, 0.02)
    z = law.initial_state()
    assert np.all(law.output(0.0, z, 0.0).commands == VMAX)
    braking = law.output(0.5, z, 0.0).commands
    assert np.sum(braking == VMAX) == 5 - j and np.sum(braking == -VMAX) == 5 + j


def test_friction_brake_holds_once_the_estimate_arrives(plant):
    law = FrictionBrake(0.4, start=0.0, hold=0.01).bind(plant, 0.02)
    z = law.update(0.1, law.initial_state(), 0.0)
    assert z[0] == 0.0
    z = law.update(0.2, z, -0.345)
    assert np.all(law.output(0.22, z, 0.1).commands == -VMAX)


def test_speed_hold_moves_the_centre_by_the_pi_law(plant):
    hold = SpeedHold(0.1, 10.0, kp=0.5, ki=5.0)
    law = hold.bind(plant, 0.02)
    z = law.update(0.0, law.initial_state(), 0.05)             # integral += 0.05 * 0.02
    assert z[0] == pytest.approx(0.001, rel=1e-15)
    commands = law.output(0.02, z, 0.05).commands
    centre = 0.1 + 0.5 * 0.05 + 5.0 * 0.001
    assert np.mean(commands) == pytest.approx(centre, rel=1e-12)


def test_open_loop_replays_a_schedule(plant):
    schedule = PiecewiseConstant([1.0], np.array([[0.1] * N, [0.2] * N]))
    law = OpenLoop(schedule).bind(plant, 0.02)
    assert np.all(law.output(0.5, law.initial_state(), 9.0).commands == 0.1)
    assert np.all(law.output(1.0, law.initial_state(), 9.0).commands == 0.2)


def test_force_drive_is_a_pi_law_on_the_ramp(plant):
    drive = ForceDrive(np.zeros(N), -0.3, 0.3, 6.0, bandwidth=20.0, ki=100.0)
    law = drive.bind(plant, 0.02)
    assert drive.reference(3.0) == pytest.approx(0.0, abs=1e-15)
    assert law.output(0.0, np.array([0.01]), -0.25).force == pytest.approx(
        1.0 * (20.0 * (-0.3 + 0.25) + 100.0 * 0.01), rel=1e-12)


def test_bad_controller_settings_are_refused(plant):
    with pytest.raises(ParameterError, match="'slope' parameter of VirtualViscosity"):
        VirtualViscosity(0.0)
    with pytest.raises(ParameterError, match="'fraction' parameter of FrictionBrake"):
        FrictionBrake(1.5)
    with pytest.raises(ParameterError, match="'plant' parameter of FrictionBrake"):
        FrictionBrake(0.4).bind(Plant(ContactSet([0.0] * N), 1.0), 0.02)
    with pytest.raises(ParameterError, match="'schedule' parameter of OpenLoop"):
        OpenLoop(PiecewiseConstant([], [[0.1] * 3])).bind(plant, 0.02)
