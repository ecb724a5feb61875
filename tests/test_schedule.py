"""Tests of toolkit.schedule: closed-form braking times, designed schedules verified by the
exact simulator, limits, and the firmware export."""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import solve_ivp
from scipy.optimize import brentq
from scipy.special import lambertw

from toolkit.model import ContactSet
from toolkit.errors import ParameterError, ParameterTypeError
from toolkit.model import Motors, PiecewiseConstant, Plant
from toolkit.schedule.construct import implicit_step, tracking_lower_bound
from toolkit.schedule import (Braking, ScheduleResult, ScheduleStatus, SpeedTrajectory,
                              braking_time, design_schedule, deviation_bound)
from toolkit.simulation import simulate

VMAX = 0.35                      # docs/physics.md section 5
TAU = 0.01                       # motors settle in ~30 ms = 3 tau
PERIOD = 0.02                    # 50 Hz
MOTORS = Motors(lag=TAU, speed_limits=(-VMAX, VMAX))


def carousel(speeds, forces=None, motors=MOTORS, mass=1.0) -> Plant:
    forces = np.full(len(speeds), 0.2) if forces is None else forces   # F_tot / m = 2 m/s^2
    return Plant(ContactSet(speeds, forces), mass=mass, motors=motors)


def exact_run(plant: Plant, result: ScheduleResult, v0: float, times):
    return simulate(dataclasses.replace(plant, commands=result.as_commands()),
                    float(result.times[-1]), v0=v0, t_eval=times)


def check_limits(result: ScheduleResult, plant: Plant) -> None:
    lo, hi = plant.motors.speed_limits
    # Commands are projected onto the limits after the solver: exactly inside.
    assert np.all(result.speeds >= lo) and np.all(result.speeds <= hi)
    # The motor model of the schedule is the closed-form lag (second method: the recursion).
    decay = math.exp(-PERIOD / TAU)
    recursion = result.speeds[:-1] + (result.contact_speeds[:-1] - result.speeds[:-1]) * decay
    np.testing.assert_allclose(result.contact_speeds[1:], recursion, rtol=0, atol=1e-12)
    if math.isfinite(plant.motors.rate_limit):
        gap = np.abs(result.speeds[:-1] - result.contact_speeds[:-1])
        assert np.all(gap <= plant.motors.rate_limit * TAU * (1 + 1e-9))


# -- closed forms -----------------------------------------------------------------------------
def test_braking_time_ideal_motors_is_m_dv_over_ftot():
    plant = carousel([0.3] * 10, motors=Motors(speed_limits=(-VMAX, VMAX)))
    # dT = m (V0 - Vt) / F_tot = 1 * 0.3 / 2 (docs/physics.md section 6).
    assert braking_time(plant, 0.3, 0.0) == pytest.approx(0.15, rel=1e-15, abs=0)
    # Mirrored: speeding up from -0.3 to 0 with contacts at +v_max takes as long.
    assert braking_time(carousel([-0.3] * 10, motors=plant.motors), -0.3, 0.0) == \
        pytest.approx(0.15, rel=1e-15, abs=0)


def test_braking_time_lag_lost_time_is_the_crossing_time():
    # Friction fraction 0 (five at +v_max, five at -v_max): the body coasts at 0.2 until the
    # upper five decay past it, at t* = tau ln(2 v_max / (0.2 + v_max)) after the switch.
    plant = carousel([VMAX] * 5 + [-VMAX] * 5)
    t_star = TAU * math.log(2 * VMAX / (0.2 + VMAX))
    expected = PERIOD + t_star + 0.2 / 2.0
    assert braking_time(plant, 0.2, 0.0, hold=PERIOD) == pytest.approx(expected, rel=1e-14,
                                                                       abs=0)
    # Second method: the exact simulator under the bang-bang commands.
    bang = PiecewiseConstant([PERIOD], [[VMAX] * 5 + [-VMAX] * 5, [-VMAX] * 10])
    sim = simulate(dataclasses.replace(plant, commands=bang), 0.3, v0=0.2)
    hit = brentq(lambda t: float(sim.speed_at(np.array([t]))[0]), 0.05, 0.3, xtol=1e-15)
    assert hit == pytest.approx(expected, rel=1e-9, abs=0)     # event root finding


def test_braking_time_lambert_w_while_the_body_accelerates():
    # Seven contacts above, three below: the body accelerates at 0.8 m/s^2 while the seven
    # decay towards -v_max; the crossing solves A e^{-x} = c + b x (Lambert W, branch 0).
    plant = carousel([VMAX] * 7 + [-VMAX] * 3)
    A, c, b = 2 * VMAX, 0.1 + VMAX, 0.8 * TAU
    x = float(np.real(lambertw(A / b * math.exp(c / b)))) - c / b
    t_star = TAU * x
    V_star = 0.1 + 0.8 * t_star
    expected = t_star + V_star / 2.0
    assert braking_time(plant, 0.1, 0.0) == pytest.approx(expected, rel=1e-12, abs=0)


def test_braking_time_refuses_uncovered_cases():
    plant = carousel([0.3] * 10)
    with pytest.raises(ParameterError, match="target_speed"):
        braking_time(plant, 0.3, -0.34)           # within F_tot tau / m of the command
    with pytest.raises(ParameterError, match="equilibrium"):
        braking_time(plant, 0.1, 0.0, hold=0.02)  # body not at the median of the contacts
    with pytest.raises(ParameterTypeError):
        braking_time("plant", 0.3, 0.0)


def test_deviation_bound_is_delta_when_the_smoothing_is_saturated():
    # Contacts far from the body: tanh = +-1 to rounding, so the defect vanishes and the
    # bound is the smallest delta tried (0.5 eps).
    t = np.linspace(0.0, 1.0, 11)
    v = np.tile([1.0, -1.0, -1.0], (11, 1))
    bound, pointwise = deviation_bound(t, np.zeros(11), v, [1.0, 1.0, 1.0], 1.0, 1e-3)
    assert bound == pytest.approx(0.5e-3, rel=1e-12, abs=0)
    np.testing.assert_allclose(pointwise, 0.5e-3, rtol=1e-12, atol=0)
    # The predictor's integration allowance widens the enclosure (still saturated) and
    # adds to the bound: identity.
    bound, _ = deviation_bound(t, np.zeros(11), v, [1.0, 1.0, 1.0], 1.0, 1e-3, allowance=1e-6)
    assert bound == pytest.approx(0.5e-3 + 1e-6, rel=1e-12, abs=0)


DELTAS = (0.5, 1.0, 1.5, 2.0, 3.0, 4.0, 6.0, 8.0, 12.0, 16.0, 24.0, 32.0)   # schedule._DELTAS


def test_deviation_bound_never_misses_a_crossing_between_samples():
    # One contact (f = 1 N, m = 1 kg) sweeps v = 1 - 2t past a body held at V = 0. The
    # defect for a given delta vanishes for |v| <= delta and is 1 - tanh(|v|/eps) beyond, so
    # int d_delta dt = eps ln(1 + exp(-2 delta/eps)) (closed form, dv/dt = -2 m/s^2), and the
    # smallest bound over the deltas is min(delta + that).
    eps = 1e-3
    closed = min(r * eps + eps * math.log1p(math.exp(-2 * r)) for r in DELTAS)
    # Samples at v = 1, 1/3, -1/3, -1 never see the contact near the body: a quadrature on
    # them would return 0.5 eps (regression: the trapezoid rule did), below the truth.
    t = np.linspace(0.0, 1.0, 4)
    coarse, _ = deviation_bound(t, np.zeros(4), (1 - 2 * t)[:, None], [1.0], 1.0, eps)
    assert coarse >= closed
    # Dense samples: the interval extension exceeds the integral only on intervals holding
    # a jump of the sign pattern (two, of height <= 2 f/m) or through the variation of the
    # tanh term (total <= 4 f/m): at most 8 h above the closed form.
    t = np.linspace(0.0, 1.0, 100001)
    dense, _ = deviation_bound(t, np.zeros(t.size), (1 - 2 * t)[:, None], [1.0], 1.0, eps)
    assert closed <= dense <= closed + 8 * (t[1] - t[0])


def smoothed_run(plant: Plant, result: ScheduleResult, v0: float):
    """Second method for the prediction: scipy's Radau on the tanh-smoothed law, period by
    period on the closed-form lag paths (no external force or drag in these plants)."""
    f, m, eps = plant.contacts.forces, plant.mass, result.epsilon
    pieces, V = [], v0
    for k in range(result.times.size - 1):
        start, u, t0 = result.contact_speeds[k], result.speeds[k], result.times[k]

        def rhs(t, y, start=start, u=u, t0=t0):
            v = u + (start - u) * np.exp(-(t - t0) / TAU)
            return [float(np.tanh((v - y[0]) / eps) @ f) / m]

        sol = solve_ivp(rhs, (t0, result.times[k + 1]), [V], method="Radau", rtol=1e-11,
                        atol=1e-14, dense_output=True)
        pieces.append(sol.sol)
        V = float(sol.y[0, -1])
    return lambda t: np.array([float(pieces[min(int(x // PERIOD), len(pieces) - 1)](x)[0])
                               for x in t])


@pytest.mark.parametrize("name", ["braking", "sinusoid"])
def test_exact_model_stays_within_the_bound_over_the_whole_run(name, request):
    # The bound is claimed on the whole run, not at the samples: check the exact solution
    # (closed-form dense output, on a fine grid and at every event time) against a second
    # integration of the smoothed law (scipy Radau, rtol 1e-11: its error is below 1e-9 m/s,
    # the allowance added to the bound).
    fixture = request.getfixturevalue(name)
    plant, result = fixture[0], fixture[-1]
    v0 = 0.3 if name == "braking" else 0.0
    sim = exact_run(plant, result, v0, result.times)
    events = np.array([e.time for e in sim.events])
    grid = np.unique(np.concatenate((np.linspace(0.0, result.times[-1], 6001), events)))
    smooth = smoothed_run(plant, result, v0)(grid)
    assert np.max(np.abs(sim.speed_at(grid) - smooth)) <= result.prediction_bound + 1e-9
    # And the smoothed law agrees with the designer's prediction at the period starts.
    np.testing.assert_allclose(smooth[np.searchsorted(grid, result.times)], result.body_speed,
                               rtol=0, atol=1e-8)   # both integrators at rtol <= 1e-10


# -- designed schedules, verified by the exact simulator -----------------------------------
@pytest.fixture(scope="module")
def braking():
    plant = carousel([0.3] * 10)
    return plant, design_schedule(plant, Braking(0.0), v0=0.3)


def test_fast_braking_reaches_the_closed_form_minimum_time(braking):
    plant, result = braking
    check_limits(result, plant)
    # Motors start settled on the current commands; the first new command acts at PERIOD.
    T = braking_time(plant, 0.3, 0.0, hold=PERIOD)
    assert T == pytest.approx(PERIOD + 0.15, rel=1e-14, abs=0)   # contacts drop past the body
    assert result.minimum_time == pytest.approx(T, rel=1e-14, abs=0)
    fine = np.linspace(0.0, result.times[-1], 4001)
    sim = exact_run(plant, result, 0.3, fine)
    bound = result.prediction_bound
    assert bound < 5 * result.epsilon                 # the certificate is not vacuous
    predicted = np.interp(fine, result.times, result.body_speed)
    grid = exact_run(plant, result, 0.3, result.times)
    assert np.max(np.abs(grid.V - result.body_speed)) <= bound
    # Contact speeds: the simulator's motor model equals the schedule's (closed forms).
    np.testing.assert_allclose(grid.contact_speeds, result.contact_speeds, rtol=0, atol=1e-12)
    # First time the exact body is within 2 bounds of the goal: no schedule can get there
    # before T - 2 bound m / F_tot (comparison principle); the design gets there within
    # one controller period of the minimum.
    hit = fine[np.argmax(sim.V <= 2 * bound)]
    assert T - 2 * bound / 2.0 - 1e-12 <= hit <= T + PERIOD
    # ... and stays there: the exact body ends within the bound of the goal.
    assert abs(sim.V[-1]) <= 2 * bound
    assert np.all(np.abs(predicted[-10:]) <= bound)


def test_braking_within_a_duration_follows_the_constant_deceleration():
    plant = carousel([0.3] * 10)
    # mu/mu0 = 0.5: dT = m (V0 - Vt) / (F_tot mu/mu0) = 0.3 s (docs/physics.md section 6).
    result = design_schedule(plant, Braking(0.0, duration=0.3), v0=0.3)
    check_limits(result, plant)
    grid = exact_run(plant, result, 0.3, result.times)
    assert np.max(np.abs(grid.V - result.body_speed)) <= result.prediction_bound
    # The ramp needs half the friction; the contacts can follow it to within the lag of one
    # period: the predicted error stays below the speed change of one period at 1 m/s^2
    # plus the certificate.
    assert np.max(np.abs(grid.V - result.reference)) <= 1.0 * PERIOD + \
        result.tracking_error + result.prediction_bound
    assert result.tracking_error <= 1.0 * PERIOD


@pytest.fixture(scope="module")
def sinusoid():
    plant = carousel(np.zeros(10))
    t = np.linspace(0.0, 0.6, 61)
    reference = SpeedTrajectory(t, 0.1 * np.sin(2 * np.pi * t))
    return plant, reference, design_schedule(plant, reference, v0=0.0)


def test_tracking_a_sinusoid_is_verified_by_the_exact_simulator(sinusoid):
    plant, reference, result = sinusoid
    check_limits(result, plant)
    fine = np.linspace(0.0, result.times[-1], 1201)
    sim = exact_run(plant, result, 0.0, fine)
    grid = exact_run(plant, result, 0.0, result.times)
    assert np.max(np.abs(grid.V - result.body_speed)) <= result.prediction_bound
    # Triangle inequality: exact tracking error <= predicted error + certificate.
    assert np.max(np.abs(sim.V - reference(fine))) <= result.tracking_error + \
        result.prediction_bound
    # The first period is pinned (motors settled at rest): the reference moves by
    # 0.1 * 2 pi * PERIOD meanwhile; afterwards the error stays below that.
    assert result.tracking_error <= 0.1 * 2 * np.pi * PERIOD * (1 + 1e-6)


def test_steady_tracking_puts_the_weighted_median_at_the_target():
    rng = np.random.default_rng(3)
    start = rng.uniform(-0.3, 0.3, 9)
    plant = carousel(start)
    target = 0.05
    result = design_schedule(plant, SpeedTrajectory([0.0, 0.3], [target, target]), v0=target)
    check_limits(result, plant)
    lo, hi = ContactSet(result.speeds[-1], plant.contacts.forces).equilibrium()
    # In the smoothed model the body balances a contact within a few eps of it; the exact
    # median of the final commands lies within the certificate of the target.
    distance = max(lo - target, target - hi, 0.0)
    assert distance <= result.prediction_bound + 3 * result.epsilon
    grid = exact_run(plant, result, target, result.times)
    assert np.max(np.abs(grid.V - result.body_speed)) <= result.prediction_bound


def test_rate_limit_is_respected():
    motors = Motors(lag=TAU, rate_limit=20.0, speed_limits=(-VMAX, VMAX))
    plant = carousel([0.3] * 10, motors=motors)
    result = design_schedule(plant, Braking(0.1), v0=0.3)
    check_limits(result, plant)                 # |u - v| <= r tau: the rate never clips
    grid = exact_run(plant, result, 0.3, result.times)
    assert np.max(np.abs(grid.V - result.body_speed)) <= result.prediction_bound


# -- export -------------------------------------------------------------------------------
def test_export_rows_dict_and_commands(braking):
    plant, result = braking
    header, rows = result.to_rows()
    assert header == ["time_s"] + [f"speed_{i}_mps" for i in range(10)]
    assert len(rows) == result.times.size
    np.testing.assert_array_equal(np.array(rows)[:, 1:], result.speeds)
    np.testing.assert_array_equal(np.array(rows)[:, 0], result.times)
    data = json.loads(json.dumps(result.to_dict()))
    assert data["status"] == result.status.name and data["period"] == PERIOD
    np.testing.assert_array_equal(data["speeds"], result.speeds)
    commands = result.as_commands()
    for k, t in enumerate(result.times):
        np.testing.assert_array_equal(commands(t + 0.5 * PERIOD), result.speeds[k])
    assert not result.speeds.flags.writeable


# -- refusals -----------------------------------------------------------------------------
def test_refusals():
    plant = carousel([0.0] * 3)
    with pytest.raises(ParameterTypeError):
        design_schedule(plant, 0.3)
    with pytest.raises(ParameterError, match="speed_limits"):
        design_schedule(carousel([0.0] * 3, motors=None), Braking(0.0), v0=0.3)
    with pytest.raises(ParameterError, match="compliance"):
        design_schedule(carousel([0.0] * 3, motors=Motors(compliance=0.1,
                                                          speed_limits=(-1, 1))), Braking(0.0))
    with pytest.raises(ParameterError, match="speed limits"):
        design_schedule(plant, Braking(0.5), v0=0.3)
    with pytest.raises(ParameterError, match="increasing"):
        SpeedTrajectory([0.0, 0.0], [0.1, 0.2])
    with pytest.raises(ParameterError, match="duration"):
        Braking(0.0, duration=-1.0)


# -- the constructive design: closed forms and certificates --------------------------------
IDEAL = Motors(speed_limits=(-VMAX, VMAX))
A_MAX = 2.0                      # F_tot / m of carousel(): 10 x 0.2 N on 1 kg


def test_ideal_motors_stick_to_a_feasible_reference_exactly():
    # Hold, ramp at exactly the largest acceleration F_tot / m (every contact above the
    # body), hold: feasible everywhere, so the body can ride the reference exactly: sticking
    # (Filippov) on the holds, the full force on the ramp.
    plant = carousel([0.1] * 10, motors=IDEAL)
    reference = SpeedTrajectory([0.0, 0.1, 0.2, 0.4], [0.1, 0.1, 0.1 + A_MAX * 0.1,
                                                       0.1 + A_MAX * 0.1])
    result = design_schedule(plant, reference, v0=0.1)
    fine = np.linspace(0.0, result.times[-1], 2001)
    sim = exact_run(plant, result, 0.1, fine)
    # Exact event-driven closed forms: equal to the reference up to rounding.
    np.testing.assert_allclose(sim.V, reference(fine), rtol=0, atol=1e-12)
    assert result.status is ScheduleStatus.OPTIMAL
    # The certified lower bound is 0 up to the funnel's conservative step (A_MAX h, h =
    # period / 32) and the schedule meets it.
    assert 0.0 <= result.lower_bound <= A_MAX * PERIOD / 32
    assert result.exact_tracking_error == pytest.approx(0.0, abs=1e-12)


def test_lagged_contacts_carry_the_body_while_sticking_holds(sinusoid):
    # With a lag the contacts follow exponentials; wherever every contact has the same speed
    # p(t) and |m p'(t)| <= F_tot (docs/physics.md section 4, c = F_ext = 0) the body sticks to
    # them: the exact simulation equals the closed-form path p to rounding.
    plant, _, result = sinusoid
    checked = 0
    for k in range(1, result.times.size - 1):
        v_k, u_k = result.contact_speeds[k], result.speeds[k]
        common = np.ptp(v_k) == 0 and np.ptp(u_k) == 0
        if not common:
            continue
        start = exact_run(plant, result, 0.0, result.times[:k + 1]).V[-1]
        rate = abs(u_k[0] - v_k[0]) / TAU                  # largest |p'| in the period: at s = 0
        if start != v_k[0] or plant.mass * rate > plant.contacts.total_force:
            continue
        s = np.linspace(0.0, PERIOD, 17)
        path = u_k[0] + (v_k[0] - u_k[0]) * np.exp(-s / TAU)
        samples = np.concatenate((result.times[:k + 1], result.times[k] + s[1:]))
        sim = exact_run(plant, result, 0.0, samples)
        np.testing.assert_allclose(sim.V[k:], path, rtol=0, atol=1e-12)
        checked += 1
    assert checked >= (result.times.size - 1) // 2         # most periods are sticking periods


def test_braking_is_certified_optimal_by_the_closed_form_minimum_time(braking):
    plant, result = braking
    assert result.status is ScheduleStatus.OPTIMAL and result.success
    assert result.method == "constructive" and result.solver_status == "not run"
    T = braking_time(plant, 0.3, 0.0, hold=PERIOD)
    # Arrival (exact simulation within the bound of the goal) no later than one period after
    # the closed-form minimum time, and no earlier than the comparison principle allows.
    assert T - result.prediction_bound / A_MAX - 1e-12 <= result.arrival_time <= T + PERIOD
    assert result.exact_deviation <= result.prediction_bound


def test_unequal_magnitudes_infeasible_ramp_saturates_at_the_closed_form_error():
    # The reference climbs at 1.5 times the largest acceleration A for 0.1 s, then holds.
    # From V(0) = V_ref(0) no schedule is above V_ref(0) + A t, so the error at the end of
    # the ramp is at least (1.5 A - A) 0.1; pushing every contact up meets it exactly, then
    # the body catches the hold at A and sticks there. Unequal magnitudes: only F_tot counts.
    forces = np.array([0.05, 0.1, 0.15, 0.2, 0.25, 0.25])          # F_tot = 1 N
    plant = Plant(ContactSet(np.zeros(6), forces), mass=0.5, motors=IDEAL)   # A = 2 m/s^2
    level = 1.5 * A_MAX * 0.1
    reference = SpeedTrajectory([0.0, 0.1, 0.4], [0.0, level, level])
    result = design_schedule(plant, reference, v0=0.0)
    closed_form = (1.5 * A_MAX - A_MAX) * 0.1
    fine = np.linspace(0.0, result.times[-1], 4001)
    sim = exact_run(plant, result, 0.0, fine)
    # Second method: the exact simulation against the closed-form optimum.
    assert np.max(np.abs(sim.V - reference(fine))) == pytest.approx(closed_form, rel=1e-12, abs=0)
    caught = 0.1 + closed_form / A_MAX                  # then it rides the hold exactly
    np.testing.assert_allclose(sim.V[fine >= caught], level, rtol=0, atol=1e-12)
    assert result.exact_tracking_error == pytest.approx(closed_form, rel=1e-12, abs=0)
    # The funnel bound is valid (<= the optimum) and tight up to its conservative step.
    assert closed_form - 2 * A_MAX * PERIOD / 32 <= result.lower_bound <= closed_form + 1e-12
    assert result.status is ScheduleStatus.OPTIMAL


@settings(deadline=None, max_examples=8)
@given(seed=st.integers(0, 2**32 - 1))
def test_lower_bound_holds_for_arbitrary_schedules(seed):
    # Validity of the certificate: no schedule within the limits, however chosen, tracks
    # better than the lower bound (second method: exact simulation of random commands).
    rng = np.random.default_rng(seed)
    plant = carousel(rng.uniform(-0.3, 0.3, 4), forces=rng.uniform(0.1, 0.5, 4))
    reference = SpeedTrajectory([0.0, 0.2, 0.3], [0.0, 0.2, -0.1])
    result = design_schedule(plant, reference, v0=0.0)
    K = result.times.size - 1
    table = np.vstack((plant.contacts.speeds, rng.uniform(-VMAX, VMAX, (K, 4))))
    random_plant = dataclasses.replace(plant, commands=PiecewiseConstant(result.times[1:], table))
    fine = np.linspace(0.0, result.times[-1], 801)
    sim = simulate(random_plant, float(result.times[-1]), v0=0.0, t_eval=fine)
    # The bound is over the design's samples; the max over 801 samples of the error differs
    # from the max over any other samples by at most (A + max |V_ref'|) spacing / 2, with
    # A <= F_tot / m <= 2 m/s^2 and |V_ref'| <= 3 m/s^2: below 3 A_MAX spacing.
    spacing = result.times[-1] / 800
    assert np.max(np.abs(sim.V - reference(fine))) >= result.lower_bound - 3 * A_MAX * spacing
    assert result.exact_tracking_error >= result.lower_bound - 1e-12


def test_implicit_step_solves_the_inclusion_exactly():
    rng = np.random.default_rng(7)
    for _ in range(50):
        n = int(rng.integers(1, 8))
        v = np.round(rng.uniform(-1, 1, (3, n)), 1)         # ties on purpose
        f = rng.uniform(0.1, 1.0, n)
        V = rng.uniform(-1, 1, 3)
        m, c, ext, h = 0.7, 0.3, float(rng.uniform(-0.5, 0.5)), 1e-2
        W = implicit_step(V, v, f, m, c, ext, h)
        for row in range(3):
            lower, upper = ContactSet(v[row], f).force_bounds(W[row])
            lhs = m * (W[row] - V[row]) / h + c * W[row] - ext
            # Identity of the backward-Euler step: lhs in [F_lo(W), F_hi(W)] (rounding).
            assert float(lower) - 1e-9 <= lhs <= float(upper) + 1e-9


def test_refinement_runs_bounded_and_keeps_a_verified_schedule():
    plant = carousel(np.zeros(4), forces=np.full(4, 0.5))
    t = np.linspace(0.0, 0.2, 21)
    reference = SpeedTrajectory(t, 0.1 * np.sin(2 * np.pi * 2.5 * t))
    base = design_schedule(plant, reference, v0=0.0)
    refined = design_schedule(plant, reference, v0=0.0, refine=True, max_iter=15)
    assert refined.solver_status != "not run" and 0 < refined.iterations <= 15
    assert refined.success and refined.exact_deviation <= refined.prediction_bound
    # Kept only if it lowers the objective; the certificate still holds either way.
    assert refined.objective <= base.objective
    assert refined.exact_tracking_error >= refined.lower_bound - 1e-12
    np.testing.assert_allclose(refined.lower_bound, base.lower_bound, rtol=0, atol=1e-12)


def test_holding_against_drag_and_a_force_step_is_exact():
    # Contacts at the held speed R carry the body there while |F_ext - c R| <= F_tot
    # (Filippov sticking, docs/physics.md section 4): 1.2 N - 2 N s/m x 0.1 m/s = 1 N <= 2 N.
    push = PiecewiseConstant([0.13], [0.0, 1.2])                    # N, a step mid-period
    plant = Plant(ContactSet(np.full(10, 0.1), np.full(10, 0.2)), mass=1.0, damping=2.0,
                  external_force=push, motors=MOTORS)
    reference = SpeedTrajectory([0.0, 0.3], [0.1, 0.1])
    result = design_schedule(plant, reference, v0=0.1)
    fine = np.linspace(0.0, result.times[-1], 1001)
    sim = exact_run(plant, result, 0.1, fine)
    np.testing.assert_allclose(sim.V, 0.1, rtol=0, atol=1e-12)    # rounding of the closed forms
    assert result.status is ScheduleStatus.OPTIMAL and result.lower_bound == 0.0
    np.testing.assert_array_equal(result.speeds, 0.1)                # nothing to change


def test_refusals_of_the_design_options():
    plant = carousel([0.0] * 3)
    with pytest.raises(ParameterTypeError, match="refine"):
        design_schedule(plant, Braking(0.0), refine="yes")
    with pytest.raises(ParameterError, match="tolerance"):
        design_schedule(plant, Braking(0.0), tolerance=-1.0)


def test_contacts_moving_together_are_verified():
    # Lag-compensated commands bring contacts to one speed up to a few ulp; a schedule with
    # such near-ties is still simulated exactly and verified (regression: the exact
    # simulator once raised on it: toolkit.simulation._exact._brent's sign check).
    rng = np.random.default_rng(46965)
    plant = carousel(rng.uniform(-0.3, 0.3, 4), forces=rng.uniform(0.1, 0.5, 4))
    reference = SpeedTrajectory([0.0, 0.2, 0.3], [0.0, 0.2, -0.1])
    result = design_schedule(plant, reference, v0=0.0)
    assert result.success
    check_limits(result, plant)
    grid = exact_run(plant, result, 0.0, result.times)
    assert np.max(np.abs(grid.V - result.body_speed)) <= result.prediction_bound
    assert result.exact_tracking_error >= result.lower_bound


def test_a_prediction_that_does_not_verify_is_redone_closer_to_the_exact_law(monkeypatch):
    import toolkit.schedule.verify as schedule

    calls = []
    honest = schedule.deviation_bound

    def first_too_small(*args, **kwargs):              # the first certificate misses a defect
        bound, pointwise = honest(*args, **kwargs)
        calls.append(bound)
        return (bound * 1e-6, pointwise) if len(calls) == 1 else (bound, pointwise)

    monkeypatch.setattr(schedule, "deviation_bound", first_too_small)
    plant = carousel([0.3] * 10)
    result = design_schedule(plant, Braking(0.0), v0=0.3, epsilon=1e-3)
    assert len(calls) == 2 and result.success
    assert result.epsilon == pytest.approx(1e-3 / 4, rel=1e-15, abs=0)   # _RETRY = 4
    grid = exact_run(plant, result, 0.3, result.times)
    assert np.max(np.abs(grid.V - result.body_speed)) <= result.prediction_bound


def test_the_exact_body_speed_is_the_exact_simulation_at_the_period_starts(braking):
    plant, result = braking
    grid = exact_run(plant, result, 0.3, result.times)
    # Same simulator, same commands, same times: equal up to the dense evaluation's rounding.
    np.testing.assert_allclose(result.exact_body_speed, grid.V, rtol=0, atol=1e-12)
    assert json.loads(json.dumps(result.to_dict()))["exact_body_speed"] == \
        result.exact_body_speed.tolist()


@settings(deadline=None, max_examples=5)
@given(seed=st.integers(0, 2**32 - 1))
def test_lower_bound_holds_with_drag_and_m_per_s_swings(seed):
    # Regression (speed cap of the funnel): with drag the funnel's in-step slope must cover
    # |V| up to max |reference| + the tube width, which m/s swings put far above the speed
    # limits plus 1. Second method: exact simulations of random feasible schedules and of
    # one following the reference, all with the first period pinned at rest (so the body
    # is at V_free = 0 at t_free = PERIOD: no force acts on it) and evaluated at exactly the
    # bound's samples, where no schedule can beat it.
    rng = np.random.default_rng(seed)
    limit = 3.0
    forces = rng.uniform(0.2, 0.8, 4)
    damping = float(rng.uniform(0.5, 2.0))
    plant = Plant(ContactSet(np.zeros(4), forces), mass=1.0, damping=damping,
                  motors=Motors(lag=TAU, speed_limits=(-limit, limit)))
    swing = float(rng.uniform(1.5, 2.9))
    reference = SpeedTrajectory([0.0, 1.0, 2.0], [0.0, swing, -swing])
    K = 100
    times = np.arange(K + 1) * PERIOD
    t = np.linspace(PERIOD, K * PERIOD, 16 * (K - 1) + 1)
    forced = float(reference(PERIOD))          # V = 0 on [0, PERIOD], the reference rises
    bound = tracking_lower_bound(
        forces=forces, mass=1.0, damping=damping, external=plant.external, tau=TAU,
        rate=math.inf, lo=-limit, hi=limit, t=t, reference=reference(t), t_free=PERIOD,
        V_free=0.0, v_free=np.zeros(4), forced=forced)
    follow = np.tile(np.clip(reference(times[1:]), -limit, limit)[:, None], (1, 4))
    tables = [follow] + [rng.uniform(-limit, limit, (K, 4)) for _ in range(3)]
    for rows in tables:
        table = PiecewiseConstant(times[1:], np.vstack((np.zeros(4), rows)))
        sim = simulate(dataclasses.replace(plant, commands=table), K * PERIOD, v0=0.0,
                       t_eval=np.concatenate(([0.0], t)))
        assert sim.V[1] == 0.0                  # the forced part: at rest, exactly
        assert np.max(np.abs(sim.V - reference(sim.t))) >= bound


def test_huge_horizons_are_refused_before_allocating():
    plant = carousel([0.0] * 3)
    with pytest.raises(ParameterError, match="'horizon'.*100000 controller periods.*'period'"):
        design_schedule(plant, Braking(0.0), horizon=1e6)            # 5e7 periods
    with pytest.raises(ParameterError, match="'target'.*'times\\[-1\\]'.*'period'"):
        design_schedule(plant, SpeedTrajectory([0.0, 1e12], [0.0, 0.1]))
    with pytest.raises(ParameterError, match="'target'.*'duration'.*'period'"):
        design_schedule(plant, Braking(0.0, duration=1e5))
    # Just above the cap (100100 periods) is refused too; the check precedes any work.
    with pytest.raises(ParameterError, match="controller periods"):
        design_schedule(plant, Braking(0.0), horizon=100_000 * PERIOD * 1.001)


def test_a_schedule_whose_exact_check_a_budget_stopped_is_a_shortfall_never_a_pass():
    # The design verifies the brake schedule (status VERIFIED or OPTIMAL); its exact check
    # stopped by a wall-clock guard (1e-9 s: it fires at the first look at the clock) leaves
    # the schedule unchecked: a shortfall, whatever the design said.
    from dataclasses import replace

    from toolkit.scenes.build import build_scene
    from toolkit.scenes.designs import load_design
    from toolkit.scenes.study import design_scene_schedule, schedule_shortfalls
    from toolkit.simulation import Budget, SimulationStatus

    objects = build_scene(load_design("brake_schedule"))
    result, check = design_scene_schedule(objects)
    assert check.success and result.success
    assert schedule_shortfalls(objects, result, check) == []
    plant = replace(objects.plant_on(None), commands=result.as_commands())
    stopped = simulate(plant, float(result.times[-1]), v0=objects.scene.schedule.v0, t_eval=result.times,
                       budget=Budget(wall_time=1e-9))
    assert stopped.status is SimulationStatus.WALL_TIME
    found = schedule_shortfalls(objects, result, stopped)
    assert [s.stage for s in found] == ["schedule"] and found[0].what.startswith("unchecked"), found
