"""Estimators: closed forms, identities, one method against another, and the acceptance numbers.

Tolerances say where they come from. The acceptance scenario is the carousel's 10 s
startup-then-brake run (issue 9), simulated exactly and recorded through the sensor law.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from toolkit import ParameterError
from toolkit.estimation import (CentralDifference, EstimatorModel, KalmanEstimator, RTSSmoother,
                                UnscentedEstimator, WheelDifference,
                                chi2_band, steady_state_gain)
from toolkit.model import ContactSet, Plant
from toolkit.model.sensors import Sensors, record_simulation
from toolkit.scenarios import carousel_brake_scenario
from toolkit.simulation import simulate


@pytest.fixture(scope="module")
def scenario():
    return carousel_brake_scenario(seed=0)


def _constant_speed_record(V: float = 0.1234, t_end: float = 4.0):
    # Every contact at V and the body released at V: it stays stuck at V exactly.
    plant = Plant(ContactSet(np.full(10, V)), 5.0)
    result = simulate(plant, t_end, v0=V)
    sensors = Sensors.carousel()
    return record_simulation(result, plant, sensors), EstimatorModel(np.ones(10), 5.0, sensors)


def test_chi2_band_matches_the_normal_approximation():
    # Mean of K chi2(n)/K: mean n, std sqrt(2 n / K); the band is about n +- 1.96 sqrt(2n/K).
    lo, hi = chi2_band(500, 2)
    assert lo == pytest.approx(2 - 1.96 * np.sqrt(4 / 500), abs=0.01)    # skew of chi2: 1e-2
    assert hi == pytest.approx(2 + 1.96 * np.sqrt(4 / 500), abs=0.01)


def test_kalman_on_a_constant_speed_body_beats_one_count_per_run():
    record, model = _constant_speed_record()
    result = KalmanEstimator(model).run(record, speed=0.12, speed_std=0.01)
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
    offline = KalmanEstimator(model).run(record, speed_std=1e-4)
    loop = KalmanEstimator(model)
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
    # the body's speed within the first period, and the input's 8-sub-interval average
    # places each crossing at a sub-interval midpoint (up to 1.25 ms off): a shared input
    # error of about 0.15 mm/s for the 6 samples of the deceleration that neither the
    # filter's nor the smoother's covariance holds (NEES about 23 there).
    return (record.times >= 5.0) & (record.times < 5.3)


def test_smoother_is_no_worse_than_the_filter_where_the_model_holds(scenario):
    # The smoother conditions on every sample, the filter on the past only: outside the
    # brake window the smoother is better (measured 0.0135 vs 0.0211 mm/s).
    record = scenario.record
    kf = KalmanEstimator(scenario.model).run(record, speed_std=1e-4)
    rts = RTSSmoother(scenario.model).run(record, speed_std=1e-4)
    keep = ~_brake_window(record)
    err_kf, err_rts = (kf.speed - record.truth_speed)[keep], (rts.speed - record.truth_speed)[keep]
    assert np.sqrt(np.mean(err_rts**2)) <= np.sqrt(np.mean(err_kf**2))


@pytest.mark.xfail(strict=True, reason="the brake window's input error (see _brake_window): there the "
                   "smoother errs by 0.163 mm/s RMS against the filter's 0.113, over the record "
                   "0.0311 against 0.0286 mm/s (before the wheel windows' least-squares lines, "
                   "0.0297 against 0.0494: the smoother was already worse in that window, 0.151 "
                   "against 0.116)")
def test_smoother_is_no_worse_than_the_filter(scenario):
    kf = KalmanEstimator(scenario.model).run(scenario.record, speed_std=1e-4)
    rts = RTSSmoother(scenario.model).run(scenario.record, speed_std=1e-4)
    assert rts.rms_error <= kf.rms_error


def test_acceptance_kalman_beats_finite_differences_tenfold(scenario):
    record, model = scenario.record, scenario.model
    fd = CentralDifference(model.sensors).run(record)
    kf = KalmanEstimator(model).run(record, speed_std=1e-4)
    assert kf.rms_error <= fd.rms_error / 10


def test_acceptance_kalman_near_the_smoother(scenario):
    # Issue 9: the filter's RMS within 1.5x of the RTS smoother's on the same record.
    # Measured 0.0286 vs 0.0311 mm/s (0.92x) with the wheel windows' least-squares lines
    # (before: 0.049 vs 0.030, 1.66x). Outside the brake window, where the smoother is the
    # reference it should be, 0.0211 vs 0.0135 mm/s: 1.56x (before: 3.16x).
    record, model = scenario.record, scenario.model
    kf = KalmanEstimator(model).run(record, speed_std=1e-4)
    rts = RTSSmoother(model).run(record, speed_std=1e-4)
    assert kf.rms_error <= 1.5 * rts.rms_error


@pytest.mark.xfail(strict=True, reason="short (issue 9): measured KF NEES mean 1.14 below its band "
                   "[1.83, 2.18]: underconfident while the contacts hold (0.58 cruising, 0.14 "
                   "after the brake: the quantization sawtooth at constant speed is deterministic "
                   "and R = q^2/12 treats it as white; see kalman.py), 3.5 in the startup's first "
                   "0.3 s and 23 in the brake window (see _brake_window): the mean is a mix of "
                   "under- and overconfidence, not a tuning away from the band")
def test_acceptance_kalman_consistent(scenario):
    record, model = scenario.record, scenario.model
    kf = KalmanEstimator(model).run(record, speed_std=1e-4)
    assert kf.nees_band[0] <= kf.nees_mean <= kf.nees_band[1]


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
    with pytest.raises(ParameterError, match="^The 'initial_covariance' parameter of KalmanEstimator must"):
        KalmanEstimator(model, initial_covariance=bad)


@pytest.mark.parametrize("kwargs, name", [({"mass": 0.0}, "mass"), ({"mass": float("inf")}, "mass"),
                                          ({"forces": [1.0, -1.0]}, "forces"),
                                          ({"friction_uncertainty": -0.1}, "friction_uncertainty")])
def test_bad_models_name_the_parameter(kwargs, name):
    args = {"forces": [1.0, 1.0], "mass": 1.0, "sensors": Sensors.carousel(n_wheels=2), **kwargs}
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
                                  lambda sc: KalmanEstimator(sc.model),
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
    sub = model.substep_speeds(speeds, commands, steady)
    bounds = model.bounds(sub)
    tracker = ContactSpeedTracker(model, initial)
    for k in range(rec.n_samples):
        s_k, v_k, st_k, sub_k = tracker.push(float(rec.times[k]), rec.wheel_counts[k], commands[k])
        np.testing.assert_allclose(s_k, speeds[k], rtol=0, atol=1e-12)
        np.testing.assert_allclose(v_k, var[k], rtol=1e-12, atol=0)
        assert st_k == steady[k]
        np.testing.assert_allclose(sub_k, sub[k], rtol=0, atol=1e-12)
        np.testing.assert_allclose(model.bounds_row(sub_k), bounds[k], rtol=0, atol=1e-12)
    assert not steady[:model.settle].any() and steady[model.settle:40].all()


def _three_contacts(speeds, std=1e-3):
    sensors = Sensors.carousel(n_wheels=len(speeds))
    model = EstimatorModel(np.ones(len(speeds)), 1.0, sensors)
    sub = np.broadcast_to(np.asarray(speeds, dtype=float), (model.substeps, len(speeds)))
    return model, sub


def test_increment_crossing_a_contact_closed_form():
    # m = 1 kg, f = 1 N: contacts at 0.03, 0.3, 0.4 (equilibrium at 0.3), body at 0 with
    # steady contacts. a = 3 m/s^2 until 0.03 (t = 0.01 s), then 1 m/s^2 for the rest of
    # the 0.02 s period: dV = 0.03 + 0.01 = 0.04, dx = 1.5e-4 + 3.5e-4 = 5e-4 m.
    # Crossing variance: slip std sigma = sqrt(2) 1e-3 (speed and contact stds 1e-3), slip
    # rate r = dV / h = 2 m/s^2, so the crossing is timed to sigma / r and the mean force
    # errs by 2 f (sigma / r) / h; the contacts at 0.3 and 0.4 are far from [0, 0.04].
    model, sub = _three_contacts([0.03, 0.3, 0.4])
    dx, dV, var, arrival, on_set = model.increment(0.0, sub, 1e-3, 1e-3, True)
    sigma, h = np.sqrt(2) * 1e-3, 0.02
    # Exact crossing-by-crossing motion: rounding only (1e-15 of the speeds).
    assert dV == pytest.approx(0.04, rel=0, abs=1e-15)
    assert dx == pytest.approx(5e-4, rel=0, abs=1e-17)
    assert var == pytest.approx((2.0 * (sigma / 2.0) / h) ** 2, rel=1e-12)
    assert arrival is None and not on_set


def test_increment_arrival_on_the_equilibrium_set():
    # Contacts at 0.03 and 0.3 (zero band [0.03, 0.3]), body at 0: a = 2 m/s^2 until it
    # reaches 0.03 at t = 0.015 s, then it coasts there: dV = 0.03, dx = 2.25e-4 + 1.5e-4 m.
    # The arrival contact is not crossed (no crossing variance) and V+ errs by the contact
    # estimate: arrival variance contact_std^2.
    model, sub = _three_contacts([0.03, 0.3])
    dx, dV, var, arrival, on_set = model.increment(0.0, sub, 2e-3, 1e-3, True)
    assert dV == pytest.approx(0.03, rel=0, abs=1e-15)
    assert dx == pytest.approx(3.75e-4, rel=0, abs=1e-17)
    assert var == 0.0 and arrival == pytest.approx(4e-6, rel=1e-15) and on_set
    # Already within 2 sigma of the set: stuck, no motion, only the floor.
    dx, dV, var, arrival, on_set = model.increment(0.03 - 1e-3, sub, 2e-3, 1e-3, True)
    assert (dx, dV, arrival, on_set) == (0.0, 0.0, None, True)
    assert var == pytest.approx((1.0 / 0.02) ** 2 * 4e-6 / model.max_window, rel=1e-12)


def test_filter_after_an_arrival_forgets_the_old_speed_error():
    # An arrival step has the transition [[1, h], [0, 0]]: the prior speed variance is the
    # contact estimate's plus the step's force variance, whatever P_VV was before.
    model, sub = _three_contacts([0.03, 0.3])
    kf = KalmanEstimator(model)
    kf.reset(speed=0.0, speed_std=0.01)
    kf._advance(0.0, 1e-8, None, 0.0, True)
    bounds = model.bounds_row(sub)
    kf._advance(3.75e-4, 1e-8, sub, 4e-6, True, bounds)
    np.testing.assert_array_equal(kf.last_F, [[1.0, 0.02], [0.0, 0.0]])
    # Prior P_VV = 0 * P_VV + Q_VV = contact variance (no crossing variance): exact.
    assert kf.kf.P_prior[1, 1] == pytest.approx(4e-6, rel=1e-12)
    assert kf.last_input == pytest.approx((3.75e-4, 0.03), rel=0, abs=1e-15)


def test_increment_carries_a_body_on_a_slowly_moving_set():
    # Two 1 N contacts on m = 1 kg, commands moved by +1 mm/s (a motor transient: not
    # steady): the zero band [0.1, 0.2] ends at [0.101, 0.201]. A body on its lower edge is
    # carried along (stiction: the edge moves by 1 mm/s per period, less than the 2 f h / m
    # = 40 mm/s one stiction step gives): V+ = 0.101, dx = dV h / 2. Inside the band it
    # coasts. Moved by 60 mm/s (more than 40 mm/s) the rule does not apply.
    model, _ = _three_contacts([0.1, 0.2])
    start, end = np.array([0.1, 0.2]), np.array([0.101, 0.201])
    sub = start + (end - start) * np.linspace(0.0, 1.0, model.substeps)[:, None]
    dx, dV, var, arrival, on_set = model.increment(0.1, sub, 1e-4, 1e-4, False)
    assert dV == pytest.approx(0.001, rel=0, abs=1e-15) and dx == pytest.approx(0.001 * 0.01, rel=1e-12)
    assert arrival is None and on_set and var == pytest.approx((1.0 / 0.02) ** 2 * 1e-8 / model.max_window, rel=1e-12)
    assert model.increment(0.15, sub, 1e-4, 1e-4, False)[:2] == (0.0, 0.0)
    # quick_increment takes the same rule from the bounds.
    assert model.quick_increment(0.1, sub, 1e-4, 1e-4, False, model.bounds_row(sub))[:2] == (dx, dV)
    far = start + np.array([0.06, 0.06]) * np.linspace(0.0, 1.0, model.substeps)[:, None]
    assert model.increment(0.1, far, 1e-4, 1e-4, False)[1] != pytest.approx(0.06, abs=1e-3)


def test_filter_fuses_the_edge_when_a_held_body_leaves_the_set():
    # The filter held the body on the set (a stuck step), then the estimate lies below the
    # lower edge by more than 2 sigma: the body has not left (steady contacts), so the step
    # keeps V with the ordinary transition and fuses the edge estimate as a measurement of
    # V after the encoder's update. Second method: the Kalman equations written out.
    model, sub = _three_contacts([0.03, 0.3])
    h, var_v = 0.02, 4e-6
    kf = KalmanEstimator(model)
    kf.reset(speed=0.03, speed_std=1e-4)
    kf._advance(0.0, 1e-8, None, 0.0, True)
    bounds = model.bounds_row(sub)
    kf._advance(0.03 * h, 1e-8, sub, var_v, True, bounds)            # stuck at the edge
    x0, P0 = kf.kf.x.copy(), kf.kf.P.copy()
    kf.kf.x[1, 0] = 0.03 - 0.01                                          # far below the edge
    x0[1, 0] = 0.02
    z, R = 2 * 0.03 * h, 1e-8
    kf._advance(z, R, sub, var_v, True, bounds)
    np.testing.assert_array_equal(kf.last_F, [[1.0, h], [0.0, 1.0]])
    F = np.array([[1.0, h], [0.0, 1.0]])
    x, P = F @ x0, F @ P0 @ F.T + kf.last_Q
    for H, zz, RR in ((np.array([[1.0, 0.0]]), z, R), (np.array([[0.0, 1.0]]), 0.03, var_v)):
        S = H @ P @ H.T + RR
        K = P @ H.T / S
        x = x + K * (zz - H @ x)
        P = (np.eye(2) - K @ H) @ P @ (np.eye(2) - K @ H).T + K * RR @ K.T
    # Two 2x2 updates in double precision: rounding, 1e-12 relative.
    np.testing.assert_allclose(kf.kf.x, x, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(kf.kf.P, P, rtol=1e-9, atol=1e-18)


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
    # A body held within 2 sigma of the lower edge (0.03) from below is on that edge: the
    # first stuck step fuses the edge's contact estimate (variance 4e-6) as a measurement of
    # V; when the wheel window has grown (variance 1e-6) only the information increment is
    # fused, variance 1 / (1 / 1e-6 - 1 / 4e-6). Second method: the Kalman equations.
    model, sub = _three_contacts([0.03, 0.3])
    bounds = model.bounds_row(sub)
    kf = KalmanEstimator(model)
    kf.reset(speed=0.0299, speed_std=1e-4)
    kf._advance(0.0, 1e-8, None, 0.0, True)
    h, R = 0.02, 1e-8
    for k, (var_v, fused) in enumerate(((4e-6, 4e-6), (1e-6, 1.0 / (1.0 / 1e-6 - 1.0 / 4e-6))), start=1):
        x0, P0 = kf.kf.x.copy(), kf.kf.P.copy()
        z = k * 0.0299 * h
        kf._advance(z, R, sub, var_v, True, bounds)
        assert kf.last_input == (0.0, 0.0)                                # stuck: no input
        x, P = _kalman_by_hand(x0, P0, kf.last_Q, [((1.0, 0.0), z, R), ((0.0, 1.0), 0.03, fused)])
        # Two 2x2 updates in double precision: rounding, 1e-12 relative.
        np.testing.assert_allclose(kf.kf.x, x, rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(kf.kf.P, P, rtol=1e-9, atol=1e-18)
    # No new information (the same window variance): no fusion, the encoder's update only.
    x0, P0 = kf.kf.x.copy(), kf.kf.P.copy()
    kf._advance(3 * 0.0299 * h, R, sub, 1e-6, True, bounds)
    x, P = _kalman_by_hand(x0, P0, kf.last_Q, [((1.0, 0.0), 3 * 0.0299 * h, R)])
    np.testing.assert_allclose(kf.kf.x, x, rtol=1e-12, atol=1e-15)


# -- the outside force (a rig's) as a known input ---------------------------------------------
def test_increment_with_an_outside_force_closed_form():
    # m = 1 kg, f = 1 N, contacts at 0.3, 0.4, 0.5 held, body at 0, outside force 0.5 N: no
    # contact speed within reach, so the acceleration is F_tot + F = 3.5 m/s^2 all period:
    # dV = 3.5 h = 0.07 m/s, dx = dV h / 2 = 7e-4 m. The exact coast (increment) and the
    # shortcut (quick_increment) agree with it to rounding (1e-15 of the speeds); the
    # outside force, known exactly, adds no variance (equal friction: none at all).
    model, sub = _three_contacts([0.3, 0.4, 0.5])
    bounds = model.bounds_row(sub, 0.5)
    for out in (model.increment(0.0, sub, 1e-3, 1e-3, True, force=0.5),
                model.quick_increment(0.0, sub, 1e-3, 1e-3, True, bounds, 0.5)):
        dx, dV, var, arrival, on_set = out
        assert dV == pytest.approx(0.07, rel=0, abs=1e-15)
        assert dx == pytest.approx(7e-4, rel=0, abs=1e-17)
        assert var == 0.0 and arrival is None and not on_set
    # A force against the contacts: F = -5 N, a = 3 - 5 = -2 m/s^2: dV = -0.04 m/s.
    dx, dV, _, _, _ = model.increment(0.0, sub, 1e-3, 1e-3, True, force=-5.0)
    assert dV == pytest.approx(-0.04, rel=0, abs=1e-15)
    assert dx == pytest.approx(-4e-4, rel=0, abs=1e-17)
    # Drag path (the sub-interval average of the contact law) with c = 0 forced through
    # increment(steady=False): the same closed form.
    dx, dV, _, _, _ = model.increment(0.0, sub, 1e-3, 1e-3, False, force=0.5)
    assert dV == pytest.approx(0.07, rel=0, abs=1e-15)


@pytest.mark.parametrize("force, expected", [(0.0, (0.2, 0.3)), (1.0, (0.3, 0.3)), (2.0, (0.3, 0.4)),
                                             (-1.0, (0.2, 0.2)), (4.0, (0.4, np.inf)),
                                             (5.0, (np.inf, np.inf)), (-4.5, (-np.inf, -np.inf))])
def test_outside_force_moves_the_equilibrium_set(force, expected):
    # Four 1 N contacts at 0.1 .. 0.4: {V : -F in F_c(V)} is where the force-weighted CDF
    # crosses (F_tot + F) / (2 F_tot): F = 0 the median band [0.2, 0.3]; F = 1 N stuck at
    # 0.3; F = 2 N the zero band [0.3, 0.4]; F = F_tot the half-line above 0.4; |F| > F_tot
    # none (+-inf: the body accelerates throughout). Exact (the speeds themselves).
    model, sub = _three_contacts([0.1, 0.2, 0.3, 0.4])
    row = model.bounds_row(sub, force)
    assert tuple(row[2:4]) == expected and tuple(row[4:6]) == expected
    vectorized = model.bounds(np.stack([sub, sub]), [force, 0.0])
    np.testing.assert_array_equal(vectorized[0], row)
    np.testing.assert_array_equal(vectorized[1], model.bounds_row(sub))
    if np.all(np.isfinite(expected)):
        # Second method: the force as one more contact out of reach, ContactSet's own median.
        far = ContactSet([0.1, 0.2, 0.3, 0.4, np.copysign(100.0, force)], [1, 1, 1, 1, abs(force)])
        assert far.equilibrium() == pytest.approx(expected, rel=0, abs=0)


def test_increment_sticks_where_the_outside_force_balances():
    # Contacts 0.1 .. 0.4 (1 N, m = 1 kg), F = 1 N: the body at 0.3 is stuck (on the set);
    # at 0.35 the net force is 1 - 3 + 1 = -1 N: dV = -0.02 m/s over the period, short of
    # 0.3 (no arrival); from 0.36 with F = 3 N (a = +1 m/s^2) it reaches 0.4, where the
    # force 3 - 4 + [-1, 1] holds it, after 0.04 s > h: dV = +0.02 m/s.
    model, sub = _three_contacts([0.1, 0.2, 0.3, 0.4])
    dx, dV, _, arrival, on_set = model.increment(0.3, sub, 1e-4, 1e-4, True, force=1.0)
    assert (dx, dV, arrival, on_set) == (0.0, 0.0, None, True)
    dx, dV, _, arrival, on_set = model.increment(0.35, sub, 1e-4, 1e-4, True, force=1.0)
    assert dV == pytest.approx(-0.02, rel=0, abs=1e-15) and arrival is None and not on_set
    dx, dV, _, arrival, on_set = model.increment(0.36, sub, 1e-4, 1e-4, True, force=3.0)
    assert dV == pytest.approx(0.02, rel=0, abs=1e-15) and arrival is None
    dx, dV, _, arrival, on_set = model.increment(0.395, sub, 1e-4, 1e-4, True, force=3.0)
    assert dV == pytest.approx(0.005, rel=0, abs=1e-15) and on_set    # arrived at 0.4


@pytest.fixture(scope="module")
def rig_run():
    # The friction-fraction rig (j = 1 of the paper's experiment, f = 0.2 N, m = 1 kg): six
    # contacts at -0.35, four at +0.35, a PI force drives the body from 0.28 to -0.28 m/s.
    from toolkit import Motors, simulate_closed_loop
    from toolkit.controllers import ForceDrive

    speeds = np.array([-0.35] * 6 + [0.35] * 4)
    plant = Plant(ContactSet(speeds, [0.2] * 10), 1.0, motors=Motors(lag=0.0075, speed_limits=(-0.35, 0.35)))
    sensors = Sensors.carousel(10)
    run = simulate_closed_loop(plant, ForceDrive(speeds, 0.28, -0.28, 3.0), 3.0, v0=0.28,
                               sensors=sensors, seed=3)
    return run, EstimatorModel(plant.contacts.forces, 1.0, sensors, motor_lag=0.0075)


def test_filter_with_the_rig_force_tracks_the_rig_driven_body(rig_run):
    # The rig's force is in the record (simulate_closed_loop fills it); the filter run over
    # the record equals the one stepped in the loop (rounding, 1e-12 m/s). With the force
    # as known input the filter beats the central difference tenfold (measured 0.33 vs 4.5
    # mm/s); told only the contact force (the record without it) it misses the rig's
    # ~0.4 N push and its error grows past the difference's (measured 138 mm/s).
    run, model = rig_run
    assert run.record.force is not None
    np.testing.assert_array_equal(run.record.force, run.force)
    offline = KalmanEstimator(model).run(run.record, speed=0.28)
    np.testing.assert_allclose(offline.speed, run.estimate, rtol=0, atol=1e-12)
    fd = CentralDifference(model.sensors).run(run.record, speed=0.28)
    assert offline.rms_error <= fd.rms_error / 10
    blind = KalmanEstimator(model).run(dataclasses.replace(run.record, force=None), speed=0.28)
    assert blind.rms_error > fd.rms_error
    # The unscented variant takes the force the same way (as a contact out of reach in its
    # exact sigma-point propagation): measured 0.40 mm/s.
    ukf = UnscentedEstimator(model).run(run.record, speed=0.28)
    assert ukf.rms_error <= fd.rms_error / 5


def test_commanded_force_is_checked(rig_run):
    _, model = rig_run
    est = KalmanEstimator(model)
    est.observe(rig_run[0].record.sample(0))
    with pytest.raises(ParameterError, match="'force' parameter of KalmanEstimator.commanded must be finite"):
        est.commanded(np.zeros(10), float("nan"))


def test_wheel_window_is_the_least_squares_line():
    # A wheel at constant speed: the contact speed of a window of m readings is the
    # least-squares slope through them (second method: numpy.polyfit, to rounding 1e-12
    # m/s), with variance (q^2 / 12) / sum (t - tbar)^2 = q^2 / (h^2 m (m^2 - 1)) for equal
    # spacing (closed form, rtol 1e-12); two readings give the plain difference and its
    # q^2 / (6 h^2).
    from toolkit.estimation import contact_speed_estimates

    sensors = Sensors.carousel(n_wheels=2)
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

