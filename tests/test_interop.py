"""python-control interop: the interconnection of plant, estimator and controller blocks
simulated by python-control against the toolkit's own closed loop (a second method)."""

from __future__ import annotations

import math
import subprocess
import sys

import numpy as np
import pytest

control = pytest.importorskip("control")

from toolkit import ContactSet, Motors, Plant, simulate_closed_loop  # noqa: E402
from toolkit.controllers import (FrictionBrake, ForceDrive, OpenLoop, SpeedHold,  # noqa: E402
                                 VirtualViscosity)
from toolkit.errors import ParameterError, SolverError  # noqa: E402
from toolkit.estimation import (CentralDifference, EstimatorModel, KalmanEstimator,  # noqa: E402
                                WheelDifference)
from toolkit.loop.interop import (closed_loop_system, controller_system, plant_system,  # noqa: E402
                             viscous_system)
from toolkit.model import PiecewiseConstant  # noqa: E402
from toolkit.model.carousel import CAROUSEL  # noqa: E402
from toolkit.model.sensors import Sensors  # noqa: E402

V_MAX = 0.35
PLANT = Plant(ContactSet(np.linspace(-0.1, 0.3, 10), [1.0] * 10), mass=5.0,
              motors=Motors(lag=0.0075, speed_limits=(-V_MAX, V_MAX)))
#: Identical arithmetic: both paths run the same advance(), measure(), filter step and law
#: in the same order, so the numbers agree bit for bit (observed difference 0); 1e-12 m/s
#: only leaves room for a platform's fused multiply-add in one path and not the other.
ATOL = 1e-12


def _controllers() -> dict[str, object]:
    schedule = PiecewiseConstant([1.0], [np.full(10, 0.3), np.full(10, -0.2)])
    return {"viscosity": VirtualViscosity(40.0, 0.1), "speed_hold": SpeedHold(0.15, 40.0),
            "brake": FrictionBrake(0.4, start=0.5, hold=0.02), "open_loop": OpenLoop(schedule),
            "drive": ForceDrive(np.linspace(-0.1, 0.3, 10), -0.05, 0.25, 2.0)}


def _compare(loop, reference, t_end: float) -> None:
    response = control.input_output_response(loop.system, loop.times(t_end), 0, loop.initial_state)
    y = response.outputs
    n = PLANT.n
    np.testing.assert_array_equal(response.time, reference.times)
    np.testing.assert_allclose(y[0], reference.speed, rtol=0, atol=ATOL)
    np.testing.assert_allclose(y[1], reference.estimate, rtol=0, atol=ATOL)
    np.testing.assert_allclose(y[2:2 + n].T, reference.commands, rtol=0, atol=ATOL)
    np.testing.assert_allclose(y[2 + n], reference.force, rtol=0, atol=ATOL)
    if reference.record is not None:
        np.testing.assert_allclose(y[3 + n], reference.variance, rtol=0, atol=ATOL ** 2)


@pytest.mark.parametrize("name", list(_controllers()))
def test_ideal_loop_matches_simulate_closed_loop(name):
    controller = _controllers()[name]
    reference = simulate_closed_loop(PLANT, controller, 2.0, v0=0.05)
    assert reference.status.name == "SUCCESS"
    _compare(closed_loop_system(PLANT, controller, v0=0.05), reference, 2.0)


@pytest.mark.parametrize("name", ["viscosity", pytest.param("speed_hold", marks=pytest.mark.slow), "brake", "drive"])
def test_loop_with_sensors_and_kalman_filter_matches(name):
    # "drive": the rig's force reaches the filter as a known input (the estimator block's
    # force input, connected to the controller's force output).
    controller = _controllers()[name]
    sensors = CAROUSEL.sensors(10)
    model = EstimatorModel(PLANT.contacts.forces, PLANT.mass, sensors, motor_lag=0.0075)
    reference = simulate_closed_loop(PLANT, controller, 2.0, sensors=sensors,
                                     estimator=KalmanEstimator(model), v0=0.1)
    loop = closed_loop_system(PLANT, controller, sensors=sensors, estimator=KalmanEstimator(model),
                              v0=0.1)
    _compare(loop, reference, 2.0)
    # Run twice: the blocks restart from their initial states (same numbers again).
    _compare(loop, reference, 2.0)


@pytest.mark.parametrize("make", [CentralDifference, lambda s: WheelDifference(s, PLANT.contacts.forces)],
                         ids=["central_difference", "wheel_difference"])
def test_noisy_sensors_and_baselines_match(make):
    # Missed counts and read noise draw from the seeded generator in the same order.
    sensors = CAROUSEL.sensors(10, missed_count_prob=0.05, count_noise=0.7)
    estimator = make(sensors)
    reference = simulate_closed_loop(PLANT, VirtualViscosity(40.0, 0.1), 1.0, sensors=sensors,
                                     estimator=estimator, v0=0.0, seed=7)
    loop = closed_loop_system(PLANT, VirtualViscosity(40.0, 0.1), sensors=sensors,
                              estimator=make(sensors), v0=0.0, seed=7)
    _compare(loop, reference, 1.0)


def test_blocks_have_named_signals_and_discrete_time():
    sensors = CAROUSEL.sensors(10)
    block = plant_system(PLANT, sensors=sensors)
    assert block.system.dt == pytest.approx(0.02, rel=0, abs=0)   # 1/50 exactly
    assert block.system.input_labels[-1] == "force"
    assert block.system.output_labels[:2] == ["speed", "central_count"]
    law = controller_system(SpeedHold(0.1, 40.0), PLANT)
    assert law.system.input_labels == ["estimate"] and law.system.nstates == 1


def test_bad_interop_input_is_refused():
    sensors = CAROUSEL.sensors(10)
    with pytest.raises(ParameterError, match="'sensors' parameter of plant_system must have jitter = 0"):
        plant_system(PLANT, sensors=CAROUSEL.sensors(10, jitter=1e-3))
    with pytest.raises(ParameterError, match="'estimator' parameter of closed_loop_system must be given"):
        closed_loop_system(PLANT, VirtualViscosity(40.0), sensors=sensors)
    with pytest.raises(ParameterError, match="'rate' parameter of plant_system must equal the sensors'"):
        plant_system(PLANT, sensors=sensors, rate=100.0)
    with pytest.raises(ParameterError, match="'rate' parameter of plant_system must be > 0. Got -1"):
        plant_system(PLANT, rate=-1.0)
    with pytest.raises(ParameterError, match="'slope' parameter of viscous_system must be finite. Got nan"):
        viscous_system(math.nan, 5.0)


def test_estimator_block_refuses_skipped_samples():
    sensors = CAROUSEL.sensors(10)
    model = EstimatorModel(PLANT.contacts.forces, PLANT.mass, sensors)
    loop = closed_loop_system(PLANT, VirtualViscosity(40.0), sensors=sensors, estimator=KalmanEstimator(model))
    x0 = loop.initial_state.copy()
    estimator_block = loop.blocks[1]
    start = loop.blocks[0].system.nstates
    x0[start] = 3.0                        # claims three samples observed before the start
    with pytest.raises(SolverError, match="one sample after the other"):
        control.input_output_response(loop.system, loop.times(0.1), 0, x0)
    assert estimator_block.system.nstates == 3


def test_viscous_system_step_is_the_closed_form():
    # m dV/dt = -k (V - V_ref): the ZOH-discretized step response is 1 - exp(-k t / m) at
    # the samples exactly; rtol 1e-12 is rounding of expm on a 1 x 1 matrix.
    k, m, rate = 40.0, 5.0, 50.0
    sys_d = viscous_system(k, m, rate=rate)
    t = np.arange(50) / rate
    response = control.step_response(sys_d, t)
    np.testing.assert_allclose(response.outputs, 1.0 - np.exp(-k * t / m), rtol=1e-12, atol=1e-15)
    pole = viscous_system(k, m, damping=2.0).poles()
    np.testing.assert_allclose(pole, [-(k + 2.0) / m], rtol=1e-15, atol=0)


def test_importing_the_interop_does_not_load_control():
    code = "import toolkit, toolkit.loop.interop, sys; print('control' in sys.modules)"
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert done.stdout.strip() == "False"
