"""Closed loop: the sample-rate driver against one exact simulation and closed forms."""

from __future__ import annotations

import numpy as np
import pytest

from toolkit import ContactSet, Motors, ParameterError, PiecewiseConstant, Plant, simulate
from toolkit.loop.closed_loop import simulate_closed_loop
from toolkit.model.carousel import CAROUSEL
from toolkit.controllers import ForceDrive, FrictionBrake, OpenLoop, SpeedHold, VirtualViscosity
from toolkit.predictions.theory import transition_time

F, M, VMAX = 0.2, 1.0, 0.35
SCHEDULE = PiecewiseConstant([0.5, 1.0], np.array([[0.1] * 10, [-0.2] * 5 + [0.3] * 5, [0.05] * 10]))


@pytest.mark.parametrize("motors", [Motors(lag=0.0075), Motors(lag=0.0075, rate_limit=5.0), None],
                         ids=["lag", "lag+rate", "ideal"])
def test_open_loop_equals_one_exact_simulation(motors):
    # The loop steps the same exact engine one held command at a time, so it reproduces one
    # simulate() run of the schedule to rounding: 1e-12 of the speed scale (0.35 m/s).
    plant = Plant(ContactSet([0.1] * 10, [F] * 10), M, motors=motors)
    run = simulate_closed_loop(plant, OpenLoop(SCHEDULE), 2.0)
    reference = simulate(Plant(plant.contacts, M, motors=motors, commands=SCHEDULE), 2.0, t_eval=run.times)
    np.testing.assert_allclose(run.speed, reference.V, rtol=0, atol=1e-12 * VMAX)
    assert run.times.size == 101 and run.record is None
    np.testing.assert_array_equal(run.estimate, run.speed)          # ideal loop: the truth


@pytest.mark.parametrize("j", [1, 2, 3, 5])
def test_friction_brake_arrives_at_the_predicted_time(j):
    # Ideal sensors: the body leaves +v_max at t = 0 (the commands switch there; the motors
    # reverse with a 7.5 ms lag) and sticks at -v_max after dT = m 2 v_max / (F_tot j/5).
    # Read at 50 Hz, arrival is seen at the first sample after it: within one period plus
    # the motors' reversal delay (a lag of 7.5 ms delays the force by less than 2 lags).
    plant = Plant(ContactSet([VMAX] * 10, [F] * 10), M,
                  motors=Motors(lag=0.0075, speed_limits=(-VMAX, VMAX)))
    run = simulate_closed_loop(plant, FrictionBrake(j / 5), 6.0, v0=VMAX)
    arrival = run.times[np.flatnonzero(run.speed <= -VMAX + 1e-12)[0]]
    predicted = transition_time(M, VMAX, 10 * F, j / 5)
    assert predicted <= arrival <= predicted + 0.02 + 2 * 0.0075


def test_virtual_viscosity_settles_on_the_staircase_median():
    plant = Plant(ContactSet([0.0] * 10, [F] * 10), M, motors=Motors(lag=0.0075, speed_limits=(-VMAX, VMAX)))
    control = VirtualViscosity(10.0, 0.1)
    run = simulate_closed_loop(plant, control, 3.0)
    lo, hi = ContactSet(control.speeds(plant), [F] * 10).equilibrium()
    # From rest the body stops at the near edge of the zero band (exact engine: to rounding).
    assert run.speed[-1] == pytest.approx(lo, abs=1e-12)


def test_bad_loops_are_refused():
    plant = Plant(ContactSet([0.0] * 3), M)
    with pytest.raises(ParameterError, match="'estimator' parameter of simulate_closed_loop"):
        simulate_closed_loop(plant, VirtualViscosity(1.0), 1.0, estimator=object())
    with pytest.raises(ParameterError, match="'rate' parameter of simulate_closed_loop"):
        simulate_closed_loop(plant, VirtualViscosity(1.0), 1.0, rate=0.0)
    with pytest.raises(ParameterError, match="'rate' parameter of simulate_closed_loop"):
        simulate_closed_loop(plant, VirtualViscosity(1.0), 1e6, rate=1e3)
    with pytest.raises(ParameterError, match="'t_end' parameter of simulate_closed_loop"):
        simulate_closed_loop(plant, VirtualViscosity(1.0), float("nan"))


def _loop_with_sensors():
    from toolkit import CentralDifference, Sensors

    plant = Plant(ContactSet([0.0] * 10, [F] * 10), M, motors=Motors(lag=0.0075, speed_limits=(-VMAX, VMAX)))
    sensors = CAROUSEL.sensors(10)
    run = simulate_closed_loop(plant, VirtualViscosity(10.0, 0.15), 4.0, sensors=sensors, seed=1)
    ideal = simulate_closed_loop(plant, VirtualViscosity(10.0, 0.15), 4.0)
    baseline = CentralDifference(sensors).run(run.record)
    return run, ideal, baseline


def test_sensors_and_filter_in_the_loop():
    # VirtualViscosity does not read the estimate, so the true trajectory must equal the
    # ideal loop's bit for bit (identity); the Kalman filter stepped in the loop must beat the
    # central finite difference on the same record (the second method).
    run, ideal, baseline = _loop_with_sensors()
    np.testing.assert_array_equal(run.speed, ideal.speed)
    assert np.sqrt(np.mean(run.estimation_error ** 2)) < baseline.rms_error
    assert run.record is not None and run.record.n_samples == run.times.size


def test_filter_in_the_loop_is_ten_times_better_than_differencing():
    # in the loop from rest (the motors start at 0 and the first command starts a
    # transient, recorded as the record's initial_commands) the stepped filter's RMS error
    # is at most a tenth of the central finite difference's on the same record (measured
    # 0.245 vs 4.77 mm/s, 19.5x; 0.375, 12.7x before the input was the exact flow).
    run, _, baseline = _loop_with_sensors()
    assert np.sqrt(np.mean(run.estimation_error ** 2)) <= baseline.rms_error / 10


@pytest.mark.parametrize("controller", [VirtualViscosity(10.0, 0.15), SpeedHold(0.12, 10.0),
                                        ForceDrive(np.linspace(-0.3, 0.3, 10), 0.0, 0.2, 2.0)],
                         ids=["viscosity", "speed_hold", "rig"])
def test_stepped_filter_equals_the_offline_filter_on_the_loop_record(controller):
    # The loop steps the filter sample by sample (ContactSpeedTracker, one row at a time);
    # run() over the loop's record uses the vectorized contact-speed estimates. Same
    # formulas on the same numbers: equal to rounding (1e-12 m/s on speeds of 0.1 m/s).
    # SpeedHold changes the commands at every sample (a motor transient each period) and
    # VirtualViscosity once, at row 0 (from the motors at rest). The rig (ForceDrive) pushes
    # with an outside force that changes at every sample: the record holds it (force) and
    # run() reads it as the loop's commanded(command, force) did.
    from toolkit import KalmanEstimator, Sensors
    from toolkit.estimation import EstimatorModel

    plant = Plant(ContactSet([0.0] * 10, [F] * 10), M, motors=Motors(lag=0.0075, speed_limits=(-VMAX, VMAX)))
    sensors = CAROUSEL.sensors(10)
    run = simulate_closed_loop(plant, controller, 3.0, sensors=sensors, seed=2)
    np.testing.assert_array_equal(run.record.initial_commands, np.zeros(10))
    model = EstimatorModel(plant.contacts.forces, M, sensors, motor_lag=0.0075)
    offline = KalmanEstimator(model).run(run.record)
    np.testing.assert_allclose(run.estimate, offline.speed, rtol=0, atol=1e-12)
    np.testing.assert_allclose(run.variance, offline.variance, rtol=1e-9, atol=1e-18)


def test_filter_under_speed_hold_is_ten_times_better_than_differencing():
    # SpeedHold moves the commands at every sample (its PI law on the estimate): every
    # period is a motor transient, and the body coasts in the zero band that the commands
    # carry along. Scored after the first second (the filter starts from the loop's default
    # prior, 50 mm/s, which its first samples forget): measured 0.30 mm/s against 4.9 mm/s
    # (16x) on this 6 s run.
    from toolkit import CentralDifference, Sensors

    plant = Plant(ContactSet([0.0] * 10, [1.0] * 10), 5.0, motors=Motors(lag=0.0075, speed_limits=(-VMAX, VMAX)))
    sensors = CAROUSEL.sensors(10)
    run = simulate_closed_loop(plant, SpeedHold(0.2, 50.0), 6.0, sensors=sensors, seed=1)
    baseline = CentralDifference(sensors).run(run.record)
    late = run.times >= 1.0
    fd = np.sqrt(np.mean((baseline.speed - run.speed)[late] ** 2))
    assert np.sqrt(np.mean(run.estimation_error[late] ** 2)) <= fd / 10


def test_loop_bench_runs_and_restores_the_loop(capsys):
    # The benchmark runs the loop both ways (the compiled loop and, as its baseline, the
    # Python loop) and times the estimator by wrapping its methods: afterwards the loop is
    # back to compiled and the estimator has its own methods; both ways gave the same
    # trajectory (the bench prints it).
    import toolkit.loop.closed_loop as closed_loop
    from toolkit.bench import loop

    loop.main(["--seconds", "1", "--repeat", "1"])
    assert closed_loop._COMPILED is True
    out = capsys.readouterr().out
    assert out.count("same trajectory and estimates: True") == 2
    assert out.count("same trajectory: True") == 2
    for stage in ("estimator (observe + commanded)", "the Python loop (baseline", "one kernel call"):
        assert out.count(stage) == 2


# -- the compiled loop (toolkit.simulation.SampledRun) against the Python loop ---------------------
CAROUSEL_PLANT = Plant(ContactSet([0.0] * 10, [1.0] * 10), 5.0,
                       motors=Motors(lag=0.0075, speed_limits=(-VMAX, VMAX)))


def _both(*args, **kwargs):
    """The loop compiled (the default) and in Python around advance (the second method)."""
    import toolkit.loop.closed_loop as closed_loop

    compiled = simulate_closed_loop(*args, **kwargs)
    closed_loop._COMPILED = False
    try:
        python = simulate_closed_loop(*args, **kwargs)
    finally:
        closed_loop._COMPILED = True
    return compiled, python


@pytest.mark.parametrize("case", ["speed_hold+kalman", "viscosity+kalman", "viscosity", "speed_hold",
                                  "open_loop+sensors", "carry", "carry+kalman", "brake",
                                  "ideal_motors", "ideal_motors+kalman", "rate_limit"])
def test_compiled_loop_is_the_python_loop(case):
    # The kernel runs the same engines (advance's), the sensor law's compiled form and the
    # laws' compiled forms (or calls a Python law / estimator per sample): every recorded
    # array equals the Python loop's bit for bit (atol 0), counts included.
    from toolkit.predictions.apparatus import CarryThen

    sensors = CAROUSEL.sensors(10)
    plant, controller, kwargs = CAROUSEL_PLANT, VirtualViscosity(50.0, 0.15), {}
    if case.startswith("speed_hold"):
        controller = SpeedHold(0.2, 50.0)
    elif case == "open_loop+sensors":
        controller = OpenLoop(PiecewiseConstant([0.5, 1.2], np.array([[0.1] * 10, [0.3] * 10, [-0.2] * 10])
                                                + np.linspace(-0.02, 0.02, 10)))
    elif case.startswith("carry"):
        controller = CarryThen(VirtualViscosity(30.0, 0.0), 0.1, 0.12)
    elif case == "brake":
        controller = FrictionBrake(0.4, 0.5, 0.05)                # no compiled form: Python law
    elif case.startswith("ideal_motors"):
        plant = Plant(plant.contacts, 5.0, motors=Motors(speed_limits=(-VMAX, VMAX)))
    elif case == "rate_limit":
        plant = Plant(plant.contacts, 5.0, damping=0.3,
                      motors=Motors(lag=0.0075, rate_limit=3.0, speed_limits=(-VMAX, VMAX)))
    if "kalman" in case or case == "open_loop+sensors":
        kwargs["sensors"] = sensors
    compiled, python = _both(plant, controller, 2.0, v0=0.1, seed=1, **kwargs)
    assert compiled.status is python.status
    for name in ("times", "speed", "estimate", "variance", "commands", "force", "contact_speeds",
                 "position"):
        np.testing.assert_array_equal(getattr(compiled, name), getattr(python, name), err_msg=name)
    if "sensors" in kwargs:
        np.testing.assert_array_equal(compiled.record.central_counts, python.record.central_counts)
        np.testing.assert_array_equal(compiled.record.wheel_counts, python.record.wheel_counts)


def test_compiled_sensor_law_is_the_sensor_reader():
    # The sensor law is written in toolkit/model/sensors.py (SensorReader.read: the play
    # operator, then floor of position over the count); its compiled form
    # (toolkit._compiled.core.sensor_read) on the same positions gives the same integer counts
    # and the same motor-side positions (exactly: the same operations), through reversals.
    from toolkit import _compiled
    from toolkit.model.sensors import SensorReader

    core = _compiled.load("core")
    rng = np.random.default_rng(3)
    sensors = CAROUSEL.sensors(10)
    start = rng.uniform(-0.3, 0.3, 10)
    state = sensors.initial_state(start)
    reader = SensorReader(sensors, state)
    play = np.array(state.motor, dtype=float)
    X, x = 0.0, np.zeros(10)
    wheel = np.empty(10, dtype=np.int64)
    for k in range(400):
        X += 0.004 * np.sin(k / 17.0)
        x = x + 0.003 * np.sin(k / 9.0 + np.arange(10))          # reversals through the play
        c, w = reader.read(X, x)
        central = core.sensor_read(X, x, play, 0.5 * sensors.backlash,
                                   sensors.central.distance_per_count,
                                   sensors.wheel.distance_per_count, wheel)
        assert central == c
        np.testing.assert_array_equal(wheel, w)
    np.testing.assert_array_equal(play, reader.state.motor)


def test_failed_step_in_the_compiled_loop_reports_as_the_python_loop():
    # A step budget the plant cannot meet stops the loop at the same sample with the same
    # status and message in both loops (the kernel's stop re-run through advance).
    from toolkit.simulation import Budget

    budget = Budget(max_steps=1)
    compiled, python = _both(CAROUSEL_PLANT, SpeedHold(0.2, 50.0), 1.0, budget=budget)
    assert compiled.status is python.status and compiled.status.name == "MAX_STEPS"
    assert compiled.message == python.message
    np.testing.assert_array_equal(compiled.speed, python.speed)


def test_sampled_batch_runs_each_loop_as_one():
    # Many loops of one plant on the true speed, in parallel: each run equals the single
    # compiled loop of its law (the same kernel; arrays equal bit for bit) whatever the
    # number of threads, and past its own length a run is NaN.
    from toolkit.simulation import SampledLaw, SampledRun, sampled_batch

    rng = np.random.default_rng(5)
    laws, lengths, starts = [], [], []
    for r in range(12):
        speeds = np.sort(rng.uniform(-0.3, 0.3, 10))
        laws.append(SampledLaw(speeds[None, :], carry=np.full(10, 0.1 * (r % 3)), switch=0.1 - 1e-11,
                               start=0.1, period=0.02))
        lengths.append(int(rng.integers(5, 60)))
        starts.append(np.full(10, 0.1 * (r % 3)))
    v0 = rng.uniform(-0.2, 0.2, 12)
    out = sampled_batch(CAROUSEL_PLANT, laws, lengths, 50.0, v0=v0, contact_speeds=np.array(starts))
    assert (out["codes"] == 0).all() and (out["reached"] == lengths).all()
    for r in range(12):
        plant = Plant(ContactSet(starts[r], CAROUSEL_PLANT.contacts.forces), 5.0, motors=CAROUSEL_PLANT.motors)
        run = SampledRun(plant, out["times"][:lengths[r]], v0=v0[r], law=laws[r])
        run.run_to(lengths[r])
        np.testing.assert_array_equal(out["speed"][r, :lengths[r]], run.speed)
        np.testing.assert_array_equal(out["commands"][r, :lengths[r]], run.commands)
        assert np.isnan(out["speed"][r, lengths[r]:]).all()
