"""Estimators: closed forms, identities, one method against another, and the acceptance numbers.

Tolerances say where they come from. The acceptance scenario is the carousel's 10 s
startup-then-brake run, simulated exactly and recorded through the sensor law.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from toolkit import ParameterError, ParameterTypeError
from toolkit.estimation import (CentralDifference, EstimatorModel, NominalKalman, RTSSmoother,
                                UnscentedEstimator, WheelDifference,
                                chi2_band, steady_state_gain)
from toolkit.model import ContactSet, Plant
from toolkit.model.carousel import CAROUSEL
from toolkit.model.sensors import Sensors, record_simulation
from toolkit.analysis.scenarios import carousel_brake_scenario
from toolkit.simulation import simulate


@pytest.fixture(scope="module")
def scenario():
    return carousel_brake_scenario(seed=0)


def _constant_speed_record(V: float = 0.1234, t_end: float = 4.0):
    # Every contact at V and the body released at V: it stays stuck at V exactly.
    plant = Plant(ContactSet(np.full(10, V)), 5.0)
    result = simulate(plant, t_end, v0=V)
    sensors = CAROUSEL.sensors()
    return record_simulation(result, plant, sensors), EstimatorModel(np.ones(10), 5.0, sensors)


def test_chi2_band_matches_the_normal_approximation():
    # Mean of K chi2(n)/K: mean n, std sqrt(2 n / K); the band is about n +- 1.96 sqrt(2n/K).
    lo, hi = chi2_band(500, 2)
    assert lo == pytest.approx(2 - 1.96 * np.sqrt(4 / 500), abs=0.01)    # skew of chi2: 1e-2
    assert hi == pytest.approx(2 + 1.96 * np.sqrt(4 / 500), abs=0.01)


def test_kalman_on_a_constant_speed_body_beats_one_count_per_run():
    record, model = _constant_speed_record()
    result = NominalKalman(model).run(record, speed=0.12, speed_std=0.01)
    fd = CentralDifference(model.sensors).run(record, speed=0.12)
    q_rate = model.sensors.central.speed_step
    # Finite differences err by up to one count per period (sawtooth, test_sensors); the
    # filter averages the record: after 1 s its error is below a tenth of a count step
    # (the acceptance ratio), after 3 s below a hundredth (measured 1.6e-6 m/s).
    assert np.max(np.abs(fd.speed[1:] - 0.1234)) < q_rate
    assert np.max(np.abs(result.speed[record.times >= 1.0] - 0.1234)) < 0.1 * q_rate
    assert np.max(np.abs(result.speed[record.times >= 3.0] - 0.1234)) < 0.01 * q_rate


def test_run_and_step_give_the_same_estimates(scenario):
    record, model = scenario.record, scenario.model
    offline = NominalKalman(model).run(record, speed_std=1e-4)
    loop = NominalKalman(model)
    loop.reset(speed_std=1e-4)
    stepped = np.array([loop.step(record.sample(k)) for k in range(record.n_samples)])
    # Same per-sample code; the contact-speed windows see the same counts: rounding only.
    np.testing.assert_allclose(stepped[:, 0], offline.speed, rtol=0, atol=1e-12)
    np.testing.assert_allclose(stepped[:, 1], offline.variance, rtol=1e-9, atol=0)


def test_steady_state_gain_equals_dlqe():
    control = pytest.importorskip("control")
    _, model = _constant_speed_record()
    h, q = model.sensors.period, model.sensors.central.distance_per_count
    sigma_a = 0.05
    gain, prior = steady_state_gain(model, sigma_a)
    A = np.array([[1.0, h], [0.0, 1.0]])
    G = np.array([[0.5 * h * h], [h]])
    C = np.array([[1.0, 0.0]])
    L, P, _ = control.dlqe(A, G, C, np.array([[sigma_a**2]]), np.array([[q * q / 12]]))
    # dlqe's predictor gain is L = A K with K the filter gain on the steady prior P; both
    # solve the same discrete Riccati equation: agreement to the iteration's tolerance.
    np.testing.assert_allclose(prior, P, rtol=1e-9, atol=0)
    np.testing.assert_allclose(A @ gain, L, rtol=1e-9, atol=0)


def _brake_window(record):
    # The first 0.3 s after the brake command (5 s): the motors sweep five contacts through
    # the body's speed within the first period (six crossings within 1.6 ms), then the body
    # decelerates freely and arrives on the braking set.
    return (record.times >= 5.0) & (record.times < 5.3)


def test_filter_follows_the_brake_exactly(scenario):
    # The known input is the plant's exact flow (crossings at their exact times), so the
    # only error through the deceleration is the one the filter carried into the brake
    # (the cruise's, measured 3.2 um/s at 5.00 s) plus the crossings' sensitivity to the
    # contact estimates (their std ~30 um/s times 1 - s_i, the saltation factors): measured
    # <= 3.0 um/s on the samples 5.02 .. 5.12 s. Bound: 10 um/s, a third of one wheel
    # window's std (the former eight-sub-interval average erred by 156-171 um/s there).
    record = scenario.record
    kf = NominalKalman(scenario.model).run(record, speed_std=1e-4)
    window = (record.times > 5.01) & (record.times < 5.13)
    assert window.sum() == 6
    assert np.max(np.abs(kf.speed[window] - record.truth_speed[window])) < 10e-6


def test_smoother_is_no_worse_than_the_filter_in_each_phase(scenario):
    # The smoother conditions on every sample, the filter on the past only: on a model
    # that holds, the smoother is no worse in any phase of the run (startup, cruise, brake
    # window, braked). Measured over the record 0.0151 vs 0.0220 mm/s.
    record = scenario.record
    kf = NominalKalman(scenario.model).run(record, speed_std=1e-4)
    rts = RTSSmoother(scenario.model).run(record, speed_std=1e-4)
    t = record.times
    for lo, hi in ((0.0, 1.0), (1.0, 5.0), (5.0, 5.3), (5.3, 10.1)):
        keep = (t >= lo) & (t < hi)
        err_kf, err_rts = (kf.speed - record.truth_speed)[keep], (rts.speed - record.truth_speed)[keep]
        assert np.sqrt(np.mean(err_rts**2)) <= np.sqrt(np.mean(err_kf**2)), (lo, hi)
    assert rts.rms_error <= kf.rms_error


def test_the_smoother_is_refused_where_the_filter_left_its_model_and_never_worse():
    # Where the default's monitor trips (20 % unequal wheels the scene does not know, drag 1 N
    # s/m: the nominal model the smoother would run backwards is refuted), the smoother is
    # refused and its result is the filter's, to the bit; where the model holds (the
    # acceptance record), it smooths the filter's pass and is no worse than the default
    # filter overall (identity and the smoother's optimality for the affine model).
    from toolkit.estimation import KalmanEstimator
    from toolkit.model.truth import WorldTruth

    for seed in (0, 1):
        sc = carousel_brake_scenario(seed=seed, t_end=4.0, brake_time=2.0, grid_phase=seed,
                                     truth=WorldTruth(friction_spread=0.2, drag=1.0))
        kf = KalmanEstimator(sc.model).run(sc.record, speed_std=1e-4)
        rts = RTSSmoother(sc.model)
        smoothed = rts.run(sc.record, speed_std=1e-4)
        assert rts.refused is not None and rts.tripped == rts.refused
        assert smoothed.method == "rts"
        np.testing.assert_array_equal(smoothed.speed, kf.speed)
        assert smoothed.rms_error <= kf.rms_error
    sc = carousel_brake_scenario(seed=0)
    kf = KalmanEstimator(sc.model).run(sc.record, speed_std=1e-4)
    rts = RTSSmoother(sc.model)
    smoothed = rts.run(sc.record, speed_std=1e-4)
    assert rts.refused is None and smoothed.rms_error <= kf.rms_error


def test_acceptance_kalman_beats_finite_differences_tenfold(scenario):
    record, model = scenario.record, scenario.model
    fd = CentralDifference(model.sensors).run(record)
    kf = NominalKalman(model).run(record, speed_std=1e-4)
    assert kf.rms_error <= fd.rms_error / 10


def test_acceptance_kalman_near_the_smoother(scenario):
    # the filter's RMS within 1.5x of the RTS smoother's on the same record.
    # Measured 0.0220 vs 0.0151 mm/s (1.46x) with the exact holds (0.0226 vs 0.0160, 1.41x,
    # with the white model throughout; 0.049 vs 0.030, 1.66x, before the wheel windows'
    # least-squares lines).
    record, model = scenario.record, scenario.model
    kf = NominalKalman(model).run(record, speed_std=1e-4)
    rts = RTSSmoother(model).run(record, speed_std=1e-4)
    assert kf.rms_error <= 1.5 * rts.rms_error


@pytest.mark.xfail(strict=True, reason="short: measured KF NEES mean 1.77 below its band "
                   "[1.83, 2.18] on the acceptance record (1.64 in the first second, 2.44 cruising, "
                   "1.56 around the brake, 1.22 braked). The band is that of 500 independent "
                   "errors; a hold's errors are one line's, the same for hundreds of samples, so "
                   "one record's mean spreads far wider (10-90 % 1.4-2.8 over 40 grid phases) while "
                   "the filter is consistent over phases (test_kalman_is_consistent_over_grid_phases)")
def test_acceptance_kalman_consistent(scenario):
    record, model = scenario.record, scenario.model
    kf = NominalKalman(model).run(record, speed_std=1e-4)
    assert kf.nees_band[0] <= kf.nees_mean <= kf.nees_band[1]


def test_the_model_clips_commands_as_the_motors_do():
    # A record may log commands beyond the motors' limits (what a controller sent; the
    # motors clipped them, Motors.clip). The filter's model clips them the same way: run on
    # the raw log it equals the run on the clipped one (identity, offline and stepped); told
    # no limits it predicts contacts the motors never reached and errs far more (cruise
    # commands 0.28 .. 0.38 m/s against 0.35: with the white measurement model throughout,
    # where the input decides most, measured 0.0103 vs 0.0275 mm/s RMS, 2.7x; the exact
    # holds read the held speed off the counts and narrow the gap to 1.6x, 0.0127 vs 0.0199).
    sc = carousel_brake_scenario(seed=0, cruise=0.33, spread=0.05)
    raw = np.array(sc.record.commands)
    raw[sc.record.times < 5.0] = 0.33 + np.linspace(-0.05, 0.05, 10)
    assert raw.max() > 0.35 >= sc.record.commands.max()
    logged = dataclasses.replace(sc.record, commands=raw)
    np.testing.assert_array_equal(sc.model.clip(raw), sc.record.commands)
    clipped = NominalKalman(sc.model).run(sc.record, speed_std=1e-4)
    from_raw = NominalKalman(sc.model).run(logged, speed_std=1e-4)
    np.testing.assert_array_equal(from_raw.speed, clipped.speed)
    loop = NominalKalman(sc.model)
    loop.reset(speed_std=1e-4, contact_speeds=sc.record.initial_commands)
    stepped = np.array([loop.step(logged.sample(k))[0] for k in range(logged.n_samples)])
    np.testing.assert_allclose(stepped, clipped.speed, rtol=0, atol=1e-12)
    white = NominalKalman(sc.model, exact_holds=False).run(sc.record, speed_std=1e-4)
    free = NominalKalman(dataclasses.replace(sc.model, speed_limits=(-np.inf, np.inf)),
                           exact_holds=False).run(logged, speed_std=1e-4)
    assert white.rms_error <= free.rms_error / 2


@pytest.mark.parametrize("bad", [-1, 1.5, "a", True])
def test_bad_grid_phases_are_refused(bad):
    with pytest.raises((ParameterError, ParameterTypeError), match="grid_phase"):
        carousel_brake_scenario(grid_phase=bad, t_end=1.0)


def test_kalman_is_consistent_over_grid_phases():
    # Bar-Shalom's Monte Carlo test: over N independent runs (random phases of the encoders'
    # count grids, the one thing a record does not tell), the mean NEES at each sample is
    # chi-square(2N) / N for a consistent filter, inside its 95 % band at 95 % of the
    # samples. Measured with the exact holds: 98 %, 96 %, 98 % of samples and time averages
    # 1.89, 2.24, 1.97 for phases 0-29, 30-59, 60-89 (white measurement model throughout:
    # 35 %, 10 %, 17 % and 1.62, 0.79, 0.94). Asserted: at least 90 % (the binomial spread of
    # 500 correlated samples is a few %), time average within 2 +- 0.4 (its spread over the
    # three sets is 0.15).
    N = 30
    table = np.array([NominalKalman(sc.model).run(sc.record, speed_std=1e-4).nees
                      for sc in (carousel_brake_scenario(seed=0, grid_phase=p) for p in range(N))])
    ensemble = table[:, 1:].mean(axis=0)
    lo, hi = chi2_band(N, 2)
    assert np.mean((ensemble >= lo) & (ensemble <= hi)) >= 0.9
    assert abs(ensemble.mean() - 2.0) <= 0.4


def test_exact_holds_only_with_ideal_encoders_and_steady_motors(scenario):
    model = scenario.model
    assert NominalKalman(model).exact_holds
    assert not NominalKalman(model, exact_holds=False).exact_holds
    assert not UnscentedEstimator(model).exact_holds
    assert not NominalKalman(dataclasses.replace(model, contact_drift=1e-4)).exact_holds
    assert not NominalKalman(dataclasses.replace(model, friction_uncertainty=0.05)).exact_holds
    for noise in ({"count_noise": 0.3}, {"jitter": 1e-4}, {"missed_count_prob": 0.01}):
        sensors = dataclasses.replace(model.sensors, **noise)
        assert not NominalKalman(dataclasses.replace(model, sensors=sensors)).exact_holds
    with pytest.raises(ParameterTypeError, match="exact_holds"):
        NominalKalman(model, exact_holds=1)
    with pytest.raises(ParameterTypeError, match=r"'consider' parameter of NominalKalman must be a ModelPrior "
                       r"or None.*Got 0\.3"):
        NominalKalman(model, consider=0.3)


def test_a_reading_off_the_line_ends_the_hold(scenario):
    # The record "slips" two counts at 3 s (a reading no line through the earlier ones
    # gives): the hold fails there, the state restarts from the reading and the one-period
    # difference (two counts a period off: 20 mm/s, its std 4.2 mm/s), and the Gaussian
    # steps take over until the body next reaches the set (the brake); measured: back within
    # 0.034 mm/s after 0.5 s, every error within 4.8 of its std, holds again from 5.22 s.
    record = scenario.record
    counts = record.central_counts.copy()
    k = int(np.searchsorted(record.times, 3.0))
    counts[k:] += 2
    slipped = dataclasses.replace(record, central_counts=counts)
    loop = NominalKalman(scenario.model)
    loop.reset(speed_std=1e-4, contact_speeds=record.initial_commands)
    held, speed, std = [], [], []
    for j in range(record.n_samples):
        v, var = loop.step(slipped.sample(j))
        speed.append(v)
        std.append(np.sqrt(var))
        held.append(loop.holding)
    held, t = np.array(held), record.times
    err = np.array(speed) - record.truth_speed
    assert held[k - 20:k].all() and not held[k:250].any()
    # The restart's covariance: the reading errs by e_k, the one-period difference by
    # (e_k - e_k-1) / h, both uniform of variance q^2 / 12 (identity).
    replay = NominalKalman(scenario.model)
    replay.reset(speed_std=1e-4, contact_speeds=record.initial_commands)
    for j in range(k + 1):
        replay.step(slipped.sample(j))
    q, h = scenario.sensors.central.distance_per_count, scenario.sensors.period
    np.testing.assert_allclose(replay.kf.P, (q * q / 12) * np.array([[1, 1 / h], [1 / h, 2 / h**2]]),
                               rtol=1e-12)
    assert held[(t > 5.3)].all()
    assert np.all(np.isfinite(err)) and np.max(np.abs(err[1:]) / np.array(std)[1:]) < 5.0
    assert np.max(np.abs(err[(t > 3.5) & (t < 5.0)])) < 0.1e-3


def test_no_hold_on_a_body_that_met_a_settling_contact():
    # A tight staircase (VirtualViscosity 3000 N s/m, 0.67 mm/s between contacts) entered
    # from above while the motors still settle: the body meets the rising edge contact and
    # stops 5 um/s short of it, coasting inside the zero-force band. It never rode a
    # contact, so no hold may start: the filter equals the white-model filter there
    # (identity), consistent (NEES 0.16 after 1.5 s, where a hold on the edge contact gave
    # 375 before the arrival had to follow the lines' start).
    from toolkit import Motors, Sensors, VirtualViscosity, simulate_closed_loop
    plant = Plant(ContactSet([0.0] * 10, [1.0] * 10), 5.0, motors=Motors(lag=0.0075, speed_limits=(-0.35, 0.35)))
    sensors = CAROUSEL.sensors(10)
    run = simulate_closed_loop(plant, VirtualViscosity(3000.0, 0.15), 4.0, sensors=sensors, v0=0.3)
    model = EstimatorModel(plant.contacts.forces, 5.0, sensors, motor_lag=0.0075, speed_limits=(-0.35, 0.35))
    exact = NominalKalman(model).run(run.record, speed=0.3)
    white = NominalKalman(model, exact_holds=False).run(run.record, speed=0.3)
    np.testing.assert_array_equal(exact.speed, white.speed)
    assert np.nanmean(exact.nees[run.record.times > 1.5]) < 2.0


def test_no_hold_while_an_outside_force_ramps():
    # The ForceDrive rig ramps its force every sample over contacts inside the body's range:
    # the body may creep between contacts, so every new force hands it to the flow, which
    # must see it reach the set again under that force. Here none does: the filter equals the
    # white-model filter (identity; a review found holds restarting every sample before, NEES
    # 2.7e4 in the second second).
    from toolkit import ForceDrive, Motors, Sensors, simulate_closed_loop
    plant = Plant(ContactSet([0.0] * 10, [1.0] * 10), 5.0, motors=Motors(lag=0.0075, speed_limits=(-0.35, 0.35)))
    sensors = CAROUSEL.sensors(10)
    run = simulate_closed_loop(plant, ForceDrive(np.linspace(-0.3, 0.3, 10), 0.0, 0.2, 2.0), 4.0,
                               sensors=sensors, seed=1)
    model = EstimatorModel(plant.contacts.forces, 5.0, sensors, motor_lag=0.0075, speed_limits=(-0.35, 0.35))
    exact = NominalKalman(model).run(run.record)
    white = NominalKalman(model, exact_holds=False).run(run.record)
    np.testing.assert_array_equal(exact.speed, white.speed)


def test_holds_after_a_slow_reversal_wait_for_the_gearbox_play():
    # Braking to -10.6 mm/s: the wheels take up their 0.8 mm of play 75 ms after turning
    # (the encoders see no motion before), beyond the four lags of `settle`. The wheels'
    # lines start after it, and the held filter is consistent after the brake: NEES 2.3 /
    # 2.5 / 2.9 over 5.5-6 / 6-8 / 8-10 s (white model: 2031 / 1104 / 782, its wheel windows
    # spanning the play). Asserted below 5 in each (a consistent filter's mean is 2).
    sc = carousel_brake_scenario(seed=0, grid_phase=2, brake=-0.0106)
    r = NominalKalman(sc.model).run(sc.record, speed_std=1e-4)
    t = sc.record.times
    for a, b in ((5.5, 6.0), (6.0, 8.0), (8.0, 10.01)):
        assert np.mean(r.nees[(t >= a) & (t < b)]) < 5.0, (a, b)


def test_a_reused_wheel_buffer_gives_the_offline_estimates(scenario):
    # A driver that refills one wheel-count array in place: the filter copies what it keeps,
    # so stepping equals the offline run (identity to rounding).
    from toolkit.model.sensors import EncoderSample
    record = scenario.record
    offline = NominalKalman(scenario.model).run(record, speed_std=1e-4)
    loop = NominalKalman(scenario.model)
    loop.reset(speed_std=1e-4, contact_speeds=record.initial_commands)
    buffer = np.zeros(record.wheel_counts.shape[1], dtype=np.int64)
    speeds = []
    for k in range(record.n_samples):
        buffer[:] = record.wheel_counts[k]
        speeds.append(loop.step(EncoderSample(float(record.times[k]), int(record.central_counts[k]),
                                              buffer, record.commands[k]))[0])
    np.testing.assert_allclose(speeds, offline.speed, rtol=0, atol=1e-12)


def test_wheel_polygons_stay_small_with_a_long_lag():
    # Lag 20 ms, 10 s: every wheel's polygon keeps a few vertices (a run of one line's
    # counts allows a quadrilateral; measured 3-4) and none empties or overflows.
    from toolkit.estimation._hold import CAPACITY
    sc = carousel_brake_scenario(seed=0, grid_phase=1, lag=0.02)
    loop = NominalKalman(sc.model)
    loop.reset(speed_std=1e-4, contact_speeds=sc.record.initial_commands)
    worst = 0
    for k in range(sc.record.n_samples):
        loop.step(sc.record.sample(k))
        if loop._lines.active:
            assert (loop._lines.counts >= 3).all()
            worst = max(worst, int(loop._lines.counts.max()))
    assert 3 <= worst <= 8 < CAPACITY


def test_unscented_filter_is_consistent_over_grid_phases():
    # The UKF's sigma points take the exact flow, and a stuck step's collapse onto the
    # contact's estimated speed carries that estimate's variance: its NEES mean per record
    # lies in the 95 % band of a consistent filter (chi-square, 2 x 500 degrees of freedom)
    # for the median of 6 random grid phases (measured 2.11-2.21 over 12 phases, median
    # 2.14).
    means = [UnscentedEstimator(sc.model).run(sc.record, speed_std=1e-4).nees_mean
             for sc in (carousel_brake_scenario(seed=0, grid_phase=p) for p in range(6))]
    lo, hi = chi2_band(500, 2)
    assert lo <= float(np.median(means)) <= hi


def test_unscented_filter_tracks_the_run(scenario):
    fd = CentralDifference(scenario.model.sensors).run(scenario.record)
    ukf = UnscentedEstimator(scenario.model).run(scenario.record, speed_std=1e-4)
    assert ukf.rms_error <= fd.rms_error / 5


def test_wheel_baseline_settles_on_the_weighted_median(scenario):
    wheel = WheelDifference(scenario.sensors, scenario.model.forces).run(scenario.record)
    steady = (scenario.record.times > 2.0) & (scenario.record.times < 5.0)
    # Settled body = weighted median of the contacts (the lower band edge, reached first);
    # the baseline takes the band's midpoint: off by half the spacing 0.1/9/2 = 5.6 mm/s,
    # plus a wheel count step (3.9 mm/s).
    err = np.abs(wheel.speed[steady] - scenario.record.truth_speed[steady])
    assert np.max(err) <= 0.1 / 9 / 2 + 2 * scenario.sensors.wheel.speed_step


@pytest.mark.parametrize("bad", [np.array([[1.0, 2.0], [0.0, 1.0]]), np.array([[1.0, 0.0], [0.0, -1.0]]),
                                 np.array([[np.nan, 0.0], [0.0, 1.0]])])
def test_bad_covariances_are_refused(bad):
    _, model = _constant_speed_record(t_end=0.1)
    with pytest.raises(ParameterError, match="^The 'initial_covariance' parameter of NominalKalman must"):
        NominalKalman(model, initial_covariance=bad)


@pytest.mark.parametrize("kwargs, name", [({"mass": 0.0}, "mass"), ({"mass": float("inf")}, "mass"),
                                          ({"forces": [1.0, -1.0]}, "forces"),
                                          ({"friction_uncertainty": -0.1}, "friction_uncertainty")])
def test_bad_models_name_the_parameter(kwargs, name):
    args = {"forces": [1.0, 1.0], "mass": 1.0, "sensors": CAROUSEL.sensors(n_wheels=2), **kwargs}
    with pytest.raises(ParameterError, match=f"^The '{name}' parameter of EstimatorModel must"):
        EstimatorModel(**args)


def test_importing_the_toolkit_does_not_load_filterpy():
    import subprocess
    import sys
    code = "import toolkit, toolkit.estimation, sys; print('filterpy' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


@pytest.mark.parametrize("make", [lambda sc: CentralDifference(sc.sensors),
                                  lambda sc: WheelDifference(sc.sensors, sc.model.forces),
                                  lambda sc: NominalKalman(sc.model),
                                  lambda sc: UnscentedEstimator(sc.model)],
                         ids=["central_difference", "wheel_difference", "kalman", "unscented"])
def test_observe_then_commanded_equals_run(scenario, make):
    record = scenario.record
    K = 120 if "Unscented" in type(make(scenario)).__name__ else record.n_samples
    est = make(scenario)
    offline = est.run(record, speed_std=1e-4)
    est.reset(speed_std=1e-4)
    out = []
    for k in range(K):
        sample = record.sample(k)
        # The estimate at the sample time must not depend on the command sent then.
        out.append(est.observe(dataclasses.replace(sample, command=np.full_like(sample.command, np.nan))))
        est.commanded(sample.command)
    out = np.array(out)
    # Same per-sample code on the same numbers: rounding only.
    np.testing.assert_allclose(out[:, 0], offline.speed[:K], rtol=0, atol=1e-12)
    np.testing.assert_allclose(out[:, 1], offline.variance[:K], rtol=1e-9, atol=1e-15)


def test_contact_speed_tracker_equals_the_vectorized_estimates():
    # The loop's row-by-row tracker and the offline vectorized function: the same formulas
    # on the same counts, so equal to rounding (1e-12 m/s). A record whose commands change
    # at row 0 (from initial_commands), at isolated rows and at consecutive rows.
    from toolkit.estimation import ContactSpeedTracker, contact_speed_estimates

    sc = carousel_brake_scenario(seed=3, t_end=3.0, brake_time=1.5)
    rec = sc.record
    model = sc.model
    commands = np.array(rec.commands)
    commands[40:44] += np.linspace(0.001, 0.004, 4)[:, None]      # four changes in a row
    initial = commands[0] - 0.05                                   # a transient from row 0
    speeds, var, steady = contact_speed_estimates(rec.wheel_counts, commands, rec.times, model,
                                                  initial=initial)
    track = model.period_track(speeds, commands, steady)
    bounds = model.bounds(track)
    tracker = ContactSpeedTracker(model, initial)
    for k in range(rec.n_samples):
        s_k, v_k, st_k, track_k = tracker.push(float(rec.times[k]), rec.wheel_counts[k], commands[k])
        np.testing.assert_allclose(s_k, speeds[k], rtol=0, atol=1e-12)
        np.testing.assert_allclose(v_k, var[k], rtol=1e-12, atol=0)
        assert st_k == steady[k]
        np.testing.assert_allclose(track_k, track[k], rtol=0, atol=1e-12)
        np.testing.assert_allclose(model.bounds_row(track_k), bounds[k], rtol=0, atol=1e-12)
    assert not steady[:model.settle].any() and steady[model.settle:40].all()


def _three_contacts(speeds, lag=0.0):
    sensors = CAROUSEL.sensors(n_wheels=len(speeds))
    model = EstimatorModel(np.ones(len(speeds)), 1.0, sensors, motor_lag=lag)
    speeds = np.asarray(speeds, dtype=float)
    return model, np.stack((speeds, speeds))


def test_increment_crossing_a_contact_closed_form():
    # m = 1 kg, f = 1 N: contacts at 0.03, 0.3, 0.4 (equilibrium at 0.3), body at 0 with
    # steady contacts. a = 3 m/s^2 until 0.03 (t = 0.01 s), then 1 m/s^2 for the rest of
    # the 0.02 s period: dV = 0.03 + 0.01 = 0.04, dx = 1.5e-4 + 3.5e-4 = 5e-4 m.
    # Linearization: the crossing's saltation factor (a+ - 0) / (a- - 0) = 1/3, so dV+/dV =
    # 1/3 and dX+/dV = 0.01 + 0.01 / 3. A contact-speed error d moves the crossing by
    # d / 3 s and V after it by (1 - 1/3) d, which then holds for the remaining 0.01 s:
    # gains (0.01 (2/3), 2/3) times the contact std 1e-3.
    model, track = _three_contacts([0.03, 0.3, 0.4])
    dx, dV, Q, slopes, arrival, on_set = model.increment(0.0, track, 1e-3, 1e-3, True)
    # Exact crossing-by-crossing motion: rounding only (1e-15 of the speeds).
    assert dV == pytest.approx(0.04, rel=0, abs=1e-15)
    assert dx == pytest.approx(5e-4, rel=0, abs=1e-17)
    assert slopes == pytest.approx((0.01 + 0.01 / 3, 1 / 3), rel=1e-12)
    g = np.array([0.01 * 2 / 3, 2 / 3])
    np.testing.assert_allclose(Q, 1e-6 * np.outer(g, g), rtol=1e-12, atol=0)
    assert arrival is None and not on_set


def test_increment_arrival_on_the_equilibrium_set():
    # Contacts at 0.03 and 0.3 (zero band [0.03, 0.3]), body at 0: a = 2 m/s^2 until it
    # reaches 0.03 at t = 0.015 s, then it coasts there: dV = 0.03, dx = 2.25e-4 + 1.5e-4 m.
    # After the stick V+ is the contact's speed whatever V was: dV+/dV = 0, dX+/dV = 0.015;
    # it errs by the contact estimate (std 2e-3), the position by (h - 0.015) times that.
    model, track = _three_contacts([0.03, 0.3])
    dx, dV, Q, slopes, arrival, on_set = model.increment(0.0, track, 2e-3, 1e-3, True)
    assert dV == pytest.approx(0.03, rel=0, abs=1e-15)
    assert dx == pytest.approx(3.75e-4, rel=0, abs=1e-17)
    assert slopes == pytest.approx((0.015, 0.0), rel=1e-12, abs=1e-15)
    np.testing.assert_allclose(Q, 4e-6 * np.outer([0.005, 1.0], [0.005, 1.0]), rtol=1e-9, atol=0)
    assert arrival == pytest.approx(4e-6, rel=1e-15) and on_set
    # On the set: stuck, no motion, and no noise (a settled motor holds its speed).
    dx, dV, Q, slopes, arrival, on_set = model.increment(0.03, track, 2e-3, 1e-3, True)
    assert (dx, dV, slopes, arrival, on_set) == (0.0, 0.0, None, None, True)
    assert not Q.any()
    # With contact_drift the stuck body's speed wanders as the contact does: the white-noise
    # acceleration model's drift^2 [[h^3/3, h^2/2], [h^2/2, h]].
    drifting = dataclasses.replace(model, contact_drift=1e-3)
    h = 0.02
    np.testing.assert_allclose(drifting.increment(0.03, track, 2e-3, 1e-3, True)[2],
                               1e-6 * np.array([[h**3 / 3, h * h / 2], [h * h / 2, h]]), rtol=1e-15, atol=0)


def test_linearization_equals_finite_differences_of_the_flow():
    # Second method: central differences of the exact flow (advance) in V and in each
    # contact speed, on random scenes with held and lagging contacts, drag and an outside
    # force. The flow is smooth away from events moving in or out of the period: a step of
    # 1e-7 m/s gives the slopes to ~1e-8 relative (truncation ~ step^2, rounding ~ 1e-16 /
    # 1e-7); tolerance 1e-4 relative (1e-6 absolute) for slopes, 1e-3 for the noise, whose
    # entries are products of two differences.
    rng = np.random.default_rng(1)
    n = 10
    sensors = CAROUSEL.sensors(n_wheels=n)
    checked = 0
    for trial in range(240):
        lag = (0.0, 0.0075)[trial % 2]
        damping = (0.0, 0.0, 1.0)[trial % 3]
        model = EstimatorModel(rng.uniform(0.5, 1.5, n), 5.0, sensors, motor_lag=lag, damping=damping)
        target = rng.uniform(-0.3, 0.3, n)
        start = target.copy() if trial % 4 < 2 or lag == 0.0 else rng.uniform(-0.3, 0.3, n)
        track = np.stack((start, target))
        force = rng.uniform(-3.0, 3.0) if trial % 5 == 0 else 0.0
        V = rng.uniform(-0.3, 0.3)
        response = np.empty(2)
        dx, dV, Q, slopes, _, _ = model._linearized(V, track, force, model.period(V, track, force), 1e-4,
                                                    response)
        if slopes is None:
            continue
        d = 1e-7

        def end(v, tr=track, F=force):
            s = model.flow(v, tr, F)
            return np.array([s.body_displacement, s.state.V])

        np.testing.assert_allclose(slopes, (end(V + d) - end(V - d)) / (2 * d), rtol=1e-4, atol=1e-6)
        # The response to an outside force (force_gains), by differences of 1e-7 F_tot: the
        # flow is piecewise linear in it without drag (rounding ~ 1e-16 0.006 m / 1e-6 N);
        # atol far below its scales, h^2 / 2m = 4e-5 m/N and h / m = 4e-3 s/kg.
        dF = 1e-7 * float(model.forces.sum())
        np.testing.assert_allclose(response, (end(V, F=force + dF) - end(V, F=force - dF)) / (2 * dF),
                                   rtol=1e-4, atol=1e-10)
        held = np.array_equal(start, target)
        gains = []
        for i in range(n):
            e = np.zeros(n)
            e[i] = d
            # An error of the estimated start speed (the command is known): held contacts
            # keep it, lagging ones carry it along the motor law.
            plus = np.stack((start + e, target + e if held else target))
            minus = np.stack((start - e, target - e if held else target))
            gains.append((end(V, plus) - end(V, minus)) / (2 * d))
        G = np.array(gains)
        np.testing.assert_allclose(Q, 1e-8 * G.T @ G, rtol=1e-3, atol=1e-14)
        checked += 1
    assert checked > 100


def test_filter_after_an_arrival_forgets_the_old_speed_error():
    # An arrival step has the transition [[1, 0.015], [0, 0]]: the prior speed variance is
    # the contact estimate's, whatever P_VV was before (exact: 0 * P_VV + Q_VV).
    model, track = _three_contacts([0.03, 0.3])
    kf = NominalKalman(model)
    kf.reset(speed=0.0, speed_std=0.01)
    kf._advance(0.0, 1e-8, None, 0.0, True)
    bounds = model.bounds_row(track)
    kf._advance(3.75e-4, 1e-8, track, 4e-6, True, bounds)
    np.testing.assert_allclose(kf.last_F, [[1.0, 0.015], [0.0, 0.0]], rtol=1e-12, atol=1e-15)
    assert kf.kf.P_prior[1, 1] == pytest.approx(4e-6, rel=1e-12)
    # F x + u is the flow at the estimate: (0 + 3.75e-4, 0.03).
    assert kf.last_input == pytest.approx((3.75e-4, 0.03), rel=0, abs=1e-15)


def test_between_contacts_shortcut_is_the_flow_where_it_applies():
    # Unequal magnitudes (an adaptive filter's model), held contacts, bodies scattered near
    # the contact speeds at two scales (m = 1 and 20 kg, f ~ 0.3 and 3 N): where the
    # shortcut answers (the body falls short of the next contact in its direction), the
    # exact flow (second method) has no event and the same increments to rounding (1e-15
    # of the speeds), slopes, noise and force gains; where the flow has an event it
    # declines. Both answers occur.
    rng = np.random.default_rng(3)
    answered = declined = 0
    for scale, mass in ((0.3, 1.0), (3.0, 20.0)):
        n = 7
        sensors = CAROUSEL.sensors(n_wheels=n)
        model = EstimatorModel(scale * rng.uniform(0.5, 1.5, n), mass, sensors)
        for _ in range(150):
            speeds = np.sort(rng.uniform(-0.2, 0.2, n))
            track = np.stack((speeds, speeds))
            V = float(rng.choice(speeds)) + float(rng.choice([-1.0, 1.0])) * 10.0 ** rng.uniform(-7, -2)
            force = float(rng.uniform(-1.0, 1.0)) * scale if rng.random() < 0.3 else 0.0
            quiet = model._quiet_between(V, speeds, force)
            step = model.flow(V, track, force)
            if quiet is None:
                declined += 1
                continue
            answered += 1
            assert not step.events and step.state.stuck is None
            assert quiet == pytest.approx(step.state.V - V, rel=1e-12, abs=1e-15)
            g1, g2 = np.zeros((2, n + 1)), np.zeros((2, n + 1))
            a = model.increment(V, track, 1e-4, 1e-4, True, None, force, g1)
            period = model.period(V, track, force)
            b = model._linearized(V, track, force, period, 1e-4)
            model.force_gains(V, track, force, g2, b, period)
            assert a[1] == pytest.approx(b[1], rel=1e-12, abs=1e-15)
            assert a[0] == pytest.approx(b[0], rel=1e-9, abs=1e-17)
            assert a[3] is None and b[3] is None and a[4] is None and not a[5]
            np.testing.assert_array_equal(a[2], b[2])
            np.testing.assert_array_equal(g1, g2)
    assert answered > 50 and declined > 50


def test_between_contacts_shortcut_leaves_speeds_beyond_the_limits_to_the_flow():
    # A motor at its limit whose estimate overshoots it (0.3501 against 0.35 m/s): the flow
    # clips that contact to the limit, the shortcut would not; it declines and the increment
    # is the flow's (a review measured -0.0060000 against the flow's -0.0060435 m/s).
    sensors = CAROUSEL.sensors(n_wheels=3)
    model = EstimatorModel(np.array([1.0, 0.5, 0.8]), 1.0, sensors, speed_limits=(-0.35, 0.35))
    speeds = np.array([0.3501, 0.1, -0.1])
    track = np.stack((speeds, speeds))
    V = 0.35005
    assert model._quiet_between(V, speeds, 0.0) is None
    step = model.flow(V, track, 0.0)
    assert model.increment(V, track, 1e-4, 1e-4, True)[1] == pytest.approx(step.state.V - V, rel=1e-12)
    inside = np.array([0.3499, 0.1, -0.1])          # (inside: answered, net force -0.3 N at 0.2 m/s)
    assert model._quiet_between(0.2, inside, 0.0) == pytest.approx(-0.3 * sensors.period, rel=1e-12)


def test_increment_carries_a_body_on_a_slowly_moving_set():
    # Two 1 N contacts on m = 1 kg behind a 7.5 ms lag, commands moved by +1 mm/s (a motor
    # transient: not steady): the zero band [0.1, 0.2] moves up by 1 mm/s (1 - exp(-h /
    # tau)). A body on its lower edge follows contact 0 (stiction: 2 f h / m = 40 mm/s per
    # period would be needed to leave it): dV and dx are the motor law's own (exact
    # flow: second method, to rounding). Inside the band it coasts (no motion).
    model, _ = _three_contacts([0.1, 0.2], lag=0.0075)
    track = np.array([[0.1, 0.2], [0.101, 0.201]])
    dx, dV, Q, slopes, arrival, on_set = model.increment(0.1, track, 1e-4, 1e-4, False)
    step = model.flow(0.1, track)
    h, tau = 0.02, 0.0075
    assert dV == pytest.approx(0.001 * -np.expm1(-h / tau), rel=1e-12)
    assert dV == pytest.approx(step.state.V - 0.1, rel=1e-9)
    assert dx == pytest.approx(step.body_displacement - 0.1 * h, rel=1e-9)
    assert slopes is None and arrival is None and on_set
    assert model.increment(0.15, track, 1e-4, 1e-4, False)[:2] == (0.0, 0.0)
    # Given the precomputed bounds (the filter's path) the same rule.
    assert model.increment(0.1, track, 1e-4, 1e-4, False, model.bounds_row(track))[:2] == (dx, dV)
    # A body a little off the edge contact sticks on it within the period: not the shortcut
    # but the flow (dV+/dV = 0), below and above the band.
    for V in (0.099, 0.2002, 0.1015):
        out = model.increment(V, track, 1e-4, 1e-4, False)
        step = model.flow(V, track)
        assert out[1] == pytest.approx(step.state.V - V, rel=1e-12, abs=1e-15)
        assert out[0] == pytest.approx(step.body_displacement - V * h, rel=1e-9, abs=1e-15)
    # Moved by 60 mm/s (more than 40 mm/s in a period) the body is not carried: the flow.
    far = np.array([[0.1, 0.2], [0.16, 0.26]])
    out = model.increment(0.1, far, 1e-4, 1e-4, False)
    assert out[1] == pytest.approx(model.flow(0.1, far).state.V - 0.1, rel=1e-12)


def test_filter_fuses_the_edge_when_a_held_body_leaves_the_set():
    # The filter held the body on the set (a stuck step), then a measurement update moves
    # the estimate below the lower edge by less than 2 sigma (sigma^2 = P_VV + var_v): the
    # body has not left (steady contacts), so the step keeps V with the ordinary transition
    # and no noise, and fuses the edge estimate as a measurement of V after the encoder's
    # update. Second method: the Kalman equations written out.
    model, track = _three_contacts([0.03, 0.3])
    h, var_v = 0.02, 4e-6
    kf = NominalKalman(model)
    kf.reset(speed=0.03, speed_std=1e-4)
    kf._advance(0.0, 1e-8, None, 0.0, True)
    bounds = model.bounds_row(track)
    kf._advance(0.03 * h, 1e-8, track, var_v, True, bounds)            # stuck on the edge
    x0, P0 = kf.kf.x.copy(), kf.kf.P.copy()
    kf.kf.x[1, 0] = 0.03 - 0.003                                          # 0.75 sigma below
    x0[1, 0] = 0.027
    z, R = 2 * 0.03 * h, 1e-8
    kf._advance(z, R, track, var_v, True, bounds)
    np.testing.assert_array_equal(kf.last_F, [[1.0, h], [0.0, 1.0]])
    assert not kf.last_Q.any()
    F = np.array([[1.0, h], [0.0, 1.0]])
    x, P = F @ x0, F @ P0 @ F.T
    for H, zz, RR in ((np.array([[1.0, 0.0]]), z, R), (np.array([[0.0, 1.0]]), 0.03, var_v)):
        S = H @ P @ H.T + RR
        K = P @ H.T / S
        x = x + K * (zz - H @ x)
        P = (np.eye(2) - K @ H) @ P @ (np.eye(2) - K @ H).T + K * RR @ K.T
    # Two 2x2 updates in double precision: rounding, 1e-12 relative.
    np.testing.assert_allclose(kf.kf.x, x, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(kf.kf.P, P, rtol=1e-9, atol=1e-18)
    # Farther than 2 sigma it is off the set: the exact flow brings it back (an arrival).
    kf.kf.x[1, 0] = 0.03 - 0.01                  # reached within 5 ms at 2 m/s^2
    kf._advance(3 * 0.03 * h, R, track, var_v, True, bounds)
    assert kf.last_F[1, 1] == 0.0


def _kalman_by_hand(x, P, Q, updates, h=0.02):
    F = np.array([[1.0, h], [0.0, 1.0]])
    x, P = F @ x, F @ P @ F.T + Q
    for H, z, R in updates:
        H = np.array([H], dtype=float)
        S = H @ P @ H.T + R
        K = P @ H.T / S
        x = x + K * (z - H @ x)
        P = (np.eye(2) - K @ H) @ P @ (np.eye(2) - K @ H).T + K * R @ K.T
    return x, P


def test_filter_fuses_the_information_gained_on_an_edge():
    # A body held on the lower edge (0.03) whose estimate an update moved just below it is
    # on that edge: the first held step fuses the edge's contact estimate (variance 4e-6) as
    # a measurement of V; when the wheel window has grown (variance 1e-6) only the
    # information increment is fused, variance 1 / (1 / 1e-6 - 1 / 4e-6). Second method:
    # the Kalman equations.
    model, track = _three_contacts([0.03, 0.3])
    bounds = model.bounds_row(track)
    kf = NominalKalman(model)
    kf.reset(speed=0.03, speed_std=1e-4)
    kf._advance(0.0, 1e-8, None, 0.0, True)
    h, R = 0.02, 1e-8
    kf._advance(0.03 * h, R, track, 4e-6, True, bounds)                  # on the set
    assert kf.last_input == (0.0, 0.0)
    kf.kf.x[1, 0] = 0.0299
    for k, (var_v, fused) in enumerate(((4e-6, 4e-6), (1e-6, 1.0 / (1.0 / 1e-6 - 1.0 / 4e-6))), start=2):
        x0, P0 = kf.kf.x.copy(), kf.kf.P.copy()
        z = k * 0.0299 * h
        kf._advance(z, R, track, var_v, True, bounds)
        assert kf.last_input == (0.0, 0.0)                                # held: no input
        x, P = _kalman_by_hand(x0, P0, kf.last_Q, [((1.0, 0.0), z, R), ((0.0, 1.0), 0.03, fused)])
        # Two 2x2 updates in double precision: rounding, 1e-12 relative.
        np.testing.assert_allclose(kf.kf.x, x, rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(kf.kf.P, P, rtol=1e-9, atol=1e-18)
        kf.kf.x[1, 0] = min(kf.kf.x[1, 0], 0.0299)            # still below the edge
    # No new information (the same window variance): no fusion, the encoder's update only.
    x0, P0 = kf.kf.x.copy(), kf.kf.P.copy()
    kf._advance(4 * 0.0299 * h, R, track, 1e-6, True, bounds)
    x, P = _kalman_by_hand(x0, P0, kf.last_Q, [((1.0, 0.0), 4 * 0.0299 * h, R)])
    np.testing.assert_allclose(kf.kf.x, x, rtol=1e-12, atol=1e-15)


# -- the outside force (a rig's) as a known input ---------------------------------------------
def test_increment_with_an_outside_force_closed_form():
    # m = 1 kg, f = 1 N, contacts at 0.3, 0.4, 0.5 held, body at 0, outside force 0.5 N: no
    # contact speed within reach, so the acceleration is F_tot + F = 3.5 m/s^2 all period:
    # dV = 3.5 h = 0.07 m/s, dx = dV h / 2 = 7e-4 m. The shortcut (increment: every contact
    # out of reach) and the exact flow (second method) agree with it to rounding (1e-15 of
    # the speeds); the outside force, known exactly, adds no variance (equal friction: none).
    model, track = _three_contacts([0.3, 0.4, 0.5])
    bounds = model.bounds_row(track, 0.5)
    for out in (model.increment(0.0, track, 1e-3, 1e-3, True, bounds, 0.5),
                model._linearized(0.0, track, 0.5, model.period(0.0, track, 0.5), 1e-3)):
        dx, dV, Q, slopes, arrival, on_set = out
        assert dV == pytest.approx(0.07, rel=0, abs=1e-15)
        assert dx == pytest.approx(7e-4, rel=0, abs=1e-17)
        assert not Q.any() and slopes is None and arrival is None and not on_set
    # A force against the contacts: F = -5 N, a = 3 - 5 = -2 m/s^2: dV = -0.04 m/s.
    for out in (model.increment(0.0, track, 1e-3, 1e-3, True, force=-5.0),
                model._linearized(0.0, track, -5.0, model.period(0.0, track, -5.0), 1e-3)):
        assert out[1] == pytest.approx(-0.04, rel=0, abs=1e-15)
        assert out[0] == pytest.approx(-4e-4, rel=0, abs=1e-17)


@pytest.mark.parametrize("force, expected", [(0.0, (0.2, 0.3)), (1.0, (0.3, 0.3)), (2.0, (0.3, 0.4)),
                                             (-1.0, (0.2, 0.2)), (4.0, (0.4, np.inf)),
                                             (5.0, (np.inf, np.inf)), (-4.5, (-np.inf, -np.inf))])
def test_outside_force_moves_the_equilibrium_set(force, expected):
    # Four 1 N contacts at 0.1 .. 0.4: {V : -F in F_c(V)} is where the force-weighted CDF
    # crosses (F_tot + F) / (2 F_tot): F = 0 the median band [0.2, 0.3]; F = 1 N stuck at
    # 0.3; F = 2 N the zero band [0.3, 0.4]; F = F_tot the half-line above 0.4; |F| > F_tot
    # none (+-inf: the body accelerates throughout). Exact (the speeds themselves).
    model, track = _three_contacts([0.1, 0.2, 0.3, 0.4])
    row = model.bounds_row(track, force)
    assert tuple(row[2:4]) == expected and tuple(row[4:6]) == expected
    vectorized = model.bounds(np.stack([track, track]), [force, 0.0])
    np.testing.assert_array_equal(vectorized[0], row)
    np.testing.assert_array_equal(vectorized[1], model.bounds_row(track))
    if np.all(np.isfinite(expected)):
        # Second method: the force as one more contact out of reach, ContactSet's own median.
        far = ContactSet([0.1, 0.2, 0.3, 0.4, np.copysign(100.0, force)], [1, 1, 1, 1, abs(force)])
        assert far.equilibrium() == pytest.approx(expected, rel=0, abs=0)


def test_increment_sticks_where_the_outside_force_balances():
    # Contacts 0.1 .. 0.4 (1 N, m = 1 kg), F = 1 N: the body at 0.3 is stuck (on the set);
    # at 0.35 the net force is 1 - 3 + 1 = -1 N: dV = -0.02 m/s over the period, short of
    # 0.3 (no arrival); from 0.36 with F = 3 N (a = +1 m/s^2) it reaches 0.4, where the
    # force 3 - 4 + [-1, 1] holds it, after 0.04 s > h: dV = +0.02 m/s.
    model, track = _three_contacts([0.1, 0.2, 0.3, 0.4])
    dx, dV, _, _, arrival, on_set = model.increment(0.3, track, 1e-4, 1e-4, True, force=1.0)
    assert (dx, dV, arrival, on_set) == (0.0, 0.0, None, True)
    dx, dV, _, _, arrival, on_set = model.increment(0.35, track, 1e-4, 1e-4, True, force=1.0)
    assert dV == pytest.approx(-0.02, rel=0, abs=1e-15) and arrival is None and not on_set
    dx, dV, _, _, arrival, on_set = model.increment(0.36, track, 1e-4, 1e-4, True, force=3.0)
    assert dV == pytest.approx(0.02, rel=0, abs=1e-15) and arrival is None
    dx, dV, _, _, arrival, on_set = model.increment(0.395, track, 1e-4, 1e-4, True, force=3.0)
    assert dV == pytest.approx(0.005, rel=0, abs=1e-15) and on_set    # arrived at 0.4


@pytest.fixture(scope="module")
def rig_run():
    # The friction-fraction rig (j = 1 of the paper's experiment, f = 0.2 N, m = 1 kg): six
    # contacts at -0.35, four at +0.35, a PI force drives the body from 0.28 to -0.28 m/s.
    from toolkit import Motors, simulate_closed_loop
    from toolkit.controllers import ForceDrive

    speeds = np.array([-0.35] * 6 + [0.35] * 4)
    plant = Plant(ContactSet(speeds, [0.2] * 10), 1.0, motors=Motors(lag=0.0075, speed_limits=(-0.35, 0.35)))
    sensors = CAROUSEL.sensors(10)
    run = simulate_closed_loop(plant, ForceDrive(speeds, 0.28, -0.28, 3.0), 3.0, v0=0.28,
                               sensors=sensors, seed=3)
    return run, EstimatorModel(plant.contacts.forces, 1.0, sensors, motor_lag=0.0075)


def test_filter_with_the_rig_force_tracks_the_rig_driven_body(rig_run):
    # The rig's force is in the record (simulate_closed_loop fills it); the filter run over
    # the record equals the one stepped in the loop (rounding, 1e-12 m/s). With the force
    # as known input the filter beats the central difference tenfold (measured 0.32 vs 4.5
    # mm/s); told only the contact force (the record without it) it misses the rig's
    # ~0.4 N push and its error grows past the difference's (measured 140 mm/s).
    run, model = rig_run
    assert run.record.force is not None
    np.testing.assert_array_equal(run.record.force, run.force)
    offline = NominalKalman(model).run(run.record, speed=0.28)
    np.testing.assert_allclose(offline.speed, run.estimate, rtol=0, atol=1e-12)
    fd = CentralDifference(model.sensors).run(run.record, speed=0.28)
    assert offline.rms_error <= fd.rms_error / 10
    blind = NominalKalman(model).run(dataclasses.replace(run.record, force=None), speed=0.28)
    assert blind.rms_error > fd.rms_error
    # The unscented variant takes the force the same way (the exact flow of each sigma
    # point has it as its external force): measured 0.35 mm/s.
    ukf = UnscentedEstimator(model).run(run.record, speed=0.28)
    assert ukf.rms_error <= fd.rms_error / 5


def test_commanded_force_is_checked(rig_run):
    _, model = rig_run
    est = NominalKalman(model)
    est.observe(rig_run[0].record.sample(0))
    with pytest.raises(ParameterError, match="'force' parameter of NominalKalman.commanded must be finite"):
        est.commanded(np.zeros(10), float("nan"))


def test_wheel_window_is_the_least_squares_line():
    # A wheel at constant speed: the contact speed of a window of m readings is the
    # least-squares slope through them (second method: numpy.polyfit, to rounding 1e-12
    # m/s), with variance (q^2 / 12) / sum (t - tbar)^2 = q^2 / (h^2 m (m^2 - 1)) for equal
    # spacing (closed form, rtol 1e-12); two readings give the plain difference and its
    # q^2 / (6 h^2).
    from toolkit.estimation import contact_speed_estimates

    sensors = CAROUSEL.sensors(n_wheels=2)
    model = EstimatorModel(np.ones(2), 1.0, sensors)
    q, h = sensors.wheel.distance_per_count, sensors.period
    times = np.arange(40) * h
    v = np.array([0.1234, -0.0567])
    counts = np.floor((0.3e-4 + times[:, None] * v) / q).astype(np.int64)
    commands = np.broadcast_to(v, counts.shape)
    speeds, var, steady = contact_speed_estimates(counts, commands, times, model)
    assert steady.all()
    for j in (1, 2, 7, 25, 39):
        start = max(0, j - model.max_window)
        m = j - start + 1
        for i in range(2):
            slope = np.polyfit(times[start:j + 1], counts[start:j + 1, i] * q, 1)[0]
            assert speeds[j, i] == pytest.approx(slope, rel=0, abs=1e-12)
        assert var[j] == pytest.approx(q * q / (h * h * m * (m * m - 1)), rel=1e-12)
    assert speeds[1, 0] == pytest.approx((counts[1, 0] - counts[0, 0]) * q / h, rel=0, abs=1e-15)
    assert var[1] == pytest.approx(q * q / (6 * h * h), rel=1e-12)



def test_wheel_lines_wait_for_the_play_after_a_reversal():
    # After a command that turns a motor, its line is exact once it has travelled the
    # gearbox play from where it turned (and the lag law's remaining travel is under
    # TRANSIENT counts): the start time equals a brute-force scan of the motor law
    # (MotorPiece speeds on a 1 us grid, trapezoid sums of the travel since the turn;
    # tolerance 2 us, the grid plus the sum's error). A slow turn (-5 mm/s: the play takes
    # ~0.16 s) makes the play decide, not the transient (75 ms).
    from toolkit.estimation._hold import TRANSIENT, WheelLines
    from toolkit.model.motors import MotorPiece
    model = carousel_brake_scenario(seed=0, t_end=1.0).model
    lag, play, q = model.motor_lag, model.sensors.wheel.backlash, model.sensors.wheel.distance_per_count
    lines = WheelLines(model)
    start = np.full(model.n, 0.2)
    target = np.linspace(-0.005, 0.05, model.n)          # two turn, the others do not
    lines._change = (1.0, start, target)
    ready = lines._start_time() - 1.0
    piece = MotorPiece.build(0.0, start, target, lag, np.inf)
    s = np.arange(0.0, 0.5, 1e-6)
    v = piece.speeds(s)
    played = 0.0
    for i in np.flatnonzero(target < 0):
        turn = np.argmax(v[:, i] <= 0.0)
        travel = np.concatenate(([0.0], np.cumsum(0.5 * (v[turn + 1:, i] + v[turn:-1, i]) * 1e-6)))
        played = max(played, s[turn + np.argmax(np.abs(travel) >= play)])
    settled = lag * np.log(np.abs(start - target).max() * lag / (TRANSIENT * q))
    assert played > settled
    assert ready == pytest.approx(played, abs=2e-6)


def test_without_a_lag_the_wheel_lines_wait_for_the_play_too():
    # Ideal motors turn at once and run at their command: the play takes play / |u| after
    # the change (closed form); the window's reversal is judged from the speeds held before
    # the change (a lag-free track already starts at the target). In the brake scene braking
    # to -10.6 mm/s the held samples stay consistent (largest NEES measured 4.6; 2348 when
    # the window did not wait) and holds begin after the slowest turning wheel's play.
    from toolkit.estimation._hold import WheelLines
    model = dataclasses.replace(carousel_brake_scenario(seed=0, t_end=1.0).model, motor_lag=0.0)
    lines = WheelLines(model)
    start, target = np.full(model.n, 0.2), np.linspace(-0.005, 0.05, model.n)
    lines._change = (1.0, start, target)
    slowest = np.abs(target[target < 0]).min()
    assert lines._start_time() == pytest.approx(1.0 + model.sensors.wheel.backlash / slowest, rel=1e-12)
    sc = carousel_brake_scenario(seed=0, lag=0.0, brake=-0.0106)
    loop = NominalKalman(sc.model)
    loop.reset(speed_std=1e-4, contact_speeds=sc.record.initial_commands)
    held = []
    for k in range(sc.record.n_samples):
        loop.step(sc.record.sample(k))
        held.append(loop.holding)
    held, t = np.array(held), sc.record.times
    turning = sc.record.commands[-1][sc.record.commands[-1] < 0]
    first = t[np.flatnonzero(held & (t > 5.0))[0]]
    assert first >= 5.0 + sc.sensors.wheel.backlash / np.abs(turning).min()
    nees = NominalKalman(sc.model).run(sc.record, speed_std=1e-4).nees
    assert np.max(nees[held & (t > 5.0)]) < 10.0


def test_compiled_kalman_step_equals_the_filterpy_reference(monkeypatch):
    # Second method: the same record through the nominal filter with its hot step done by
    # filterpy's predict() and update(z) (the reference the kernel core.kalman_step replaced).
    # The record: 10 s of the speed-hold loop (commands move at every sample, so most steps
    # are the hot Gaussian step, not holds). Per step the two differ by rounding (the
    # kernel's test); the filter is stable, so over the record the estimates agree to 1e-12
    # m/s and the variances to 1e-12 relative (measured: speeds identical, variances 2e-15).
    from filterpy.kalman import KalmanFilter

    import toolkit.estimation.nominal as kalman_module
    from toolkit import _compiled
    from toolkit.controllers import SpeedHold
    from toolkit.estimation import KalmanEstimator
    from toolkit.loop.closed_loop import simulate_closed_loop

    plant = Plant(ContactSet([0.0] * 10, [1.0] * 10), 5.0, motors=CAROUSEL.motors())
    sensors = CAROUSEL.sensors(10)
    model = EstimatorModel(plant.contacts.forces, plant.mass, sensors, motor_lag=CAROUSEL.motor_lag,
                           speed_limits=plant.motors.speed_limits)
    record = simulate_closed_loop(plant, SpeedHold(0.2, 50.0), 10.0, sensors=sensors,
                                  estimator=KalmanEstimator(model), seed=1).record
    compiled = NominalKalman(model).run(record, speed_std=1e-4)
    calls = [0]

    def reference_step(x, P, F, Q, R, z, x_out, P_out, prior):
        calls[0] += 1
        kf = KalmanFilter(dim_x=2, dim_z=1)
        kf.x, kf.P, kf.F, kf.Q = x.copy(), P.copy(), F, Q
        kf.H, kf.R = np.array([[1.0, 0.0]]), np.array([[R]])
        kf.predict()
        prior[:] = (kf.x[0, 0], kf.x[1, 0], kf.P[0, 0])
        kf.update(z)
        x_out[:], P_out[:] = kf.x, kf.P
        return kf.y.item() ** 2 * kf.SI.item()

    class Reference:
        def __init__(self, *args):
            self.args = args

        def __getattr__(self, name):
            return reference_step if name == "kalman_step" else getattr(_compiled.kernels(*self.args), name)

    monkeypatch.setattr(kalman_module, "kernels", Reference)
    reference = NominalKalman(model).run(record, speed_std=1e-4)
    assert calls[0] > 0.7 * record.n_samples           # the hot step, not the holds (measured 408/501)
    np.testing.assert_allclose(compiled.speed, reference.speed, rtol=0, atol=1e-12)
    np.testing.assert_allclose(compiled.variance, reference.variance, rtol=1e-12, atol=0)
