"""Tests of the exact event-driven method and of the simulation API (dispatch, result types).

Every expected number comes from a closed form computed independently in the test. Unless
said otherwise the tolerance is ``rtol = 1e-12``: the issue's target for the exact method;
the closed forms involve a handful of operations, so rounding is ~1e-15.
"""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import integrate, optimize, special

from toolkit.model import ContactSet
from toolkit.errors import ParameterError, ParameterTypeError
from toolkit.model import Motors, PiecewiseConstant, Plant
from toolkit.simulation import (METHODS, Budget, Event, SimulationResult, SimulationStatus,
                                simulate)
from toolkit.simulation._exact import (_LANDSCAPES, _CoulombLandscape, _EventFunctions,
                                       _first_root, _reach_time, _scalar_expm1_ratio)

RTOL = 1e-12      # the precision target for the exact method


def _times(result: SimulationResult, kind: str) -> list[float]:
    return [e.time for e in result.events if e.kind == kind]


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(20260121)


# -- API ------------------------------------------------------------------------------------
def test_methods_table_and_option_refusal():
    assert METHODS == ("exact", "rk45", "lsoda", "radau", "bdf", "moreau", "casadi")
    plant = Plant(ContactSet([0.0, 1.0, 2.0]), 1.0)
    with pytest.raises(ParameterError, match="Did you mean 'exact'"):
        simulate(plant, 1.0, method="exakt")
    with pytest.raises(ParameterError, match="takes no options"):
        simulate(plant, 1.0, rtol=1e-3)
    with pytest.raises(ParameterError, match="Did you mean 'rtol'"):
        simulate(plant, 1.0, method="rk45", rtoll=1e-3)
    with pytest.raises(ParameterError):
        simulate(plant, 0.0)
    with pytest.raises(ParameterError):
        simulate(plant, 1.0, t_eval=[0.5, 0.2])
    with pytest.raises(ParameterError):
        simulate(plant, 1.0, t_eval=[0.5, 2.0])
    with pytest.raises(ParameterTypeError):
        simulate("plant", 1.0)
    with pytest.raises(ParameterTypeError):
        simulate(plant, 1.0, budget=5)


def test_budget_event_and_result_validation():
    with pytest.raises(ParameterError):
        Budget(wall_time=0.0)
    with pytest.raises(ParameterError):
        Budget(max_steps=0)
    with pytest.raises(ParameterError, match="Did you mean 'cross'"):
        Event(0.0, "crss", 1, 0.0)
    with pytest.raises(ParameterError):
        SimulationResult("x", "", [0.0, 1.0], [0.0], np.zeros((2, 1)), [0.0, 0.0], (),
                         SimulationStatus.SUCCESS, "", 0, 0, 0, 0.0)
    result = SimulationResult("x", "", [0.0, 1.0], [0.0, 2.0], np.zeros((2, 1)), [2.0, 2.0],
                              (), SimulationStatus.SUCCESS, "", 0, 0, 1, 0.0)
    # No dense output: linear interpolation between samples (exact for this line).
    np.testing.assert_allclose(result.speed_at([0.25, 0.5]), [0.5, 1.0], rtol=0, atol=0)
    assert result.success and not result.V.flags.writeable
    assert SimulationStatus.ZENO.value.startswith("stopped") and SimulationStatus.SUCCESS.value.startswith("finished")


def test_t_eval_gives_exactly_those_times():
    plant = Plant(ContactSet([1.0, 2.0, 3.0]), 2.0)
    times = np.array([0.0, 0.3, 0.7, 1.0])
    result = simulate(plant, 1.0, t_eval=times)
    np.testing.assert_array_equal(result.t, times)
    # Below every contact: F = F_tot = 3 N, V = 1.5 t until V = 1 at t = 2/3 (checked: the
    # samples before that time, and the force m V' = 3 N there).
    np.testing.assert_allclose(result.V[:2], 1.5 * times[:2], rtol=RTOL, atol=0)
    np.testing.assert_allclose(result.force[:2], [3.0, 3.0], rtol=RTOL, atol=0)
    assert result.contact_speeds.shape == (4, 3)


# -- closed forms, ideal motors -----------------------------------------------------------------
def test_constant_deceleration():
    # All contacts below V: F = -F_tot, V(t) = v0 - F_tot t / m until the first contact speed.
    speeds, forces, mass, v0 = [0.0, 0.5, 1.0], [1.0, 2.0, 3.0], 2.0, 2.0
    plant = Plant(ContactSet(speeds, forces), mass)
    result = simulate(plant, 1.0, v0=v0)
    t_hit = (v0 - 1.0) * mass / 6.0
    times = np.linspace(0.0, t_hit, 7)
    np.testing.assert_allclose(result.speed_at(times), v0 - 6.0 * times / mass, rtol=RTOL, atol=0)
    first = result.events[0]
    assert first.contact == 2 and first.time == pytest.approx(t_hit, rel=RTOL, abs=0)
    # At V = 1: others push -3 N, stiction W = 3 N: |G| <= W, the body sticks (tie rule).
    assert first.kind == "stick" and result.V[-1] == 1.0


def _startup_time(speeds: np.ndarray, forces: np.ndarray, mass: float, v0: float,
                  stop: float) -> float:
    """Sum of segment times m * dv / F over the plateaus from v0 up to `stop` (>= v0)."""
    levels = np.unique(speeds)
    points = np.concatenate(([v0], levels[(levels > v0) & (levels < stop)], [stop]))
    total = 0.0
    for lo, hi in zip(points[:-1], points[1:]):
        middle = 0.5 * (lo + hi)
        force = np.sum(forces * np.sign(speeds - middle))
        total += mass * (hi - lo) / force
    return total


def test_startup_from_rest_to_the_median_odd(rng):
    speeds = rng.uniform(0.05, 0.35, 11)
    forces = np.ones(11)
    plant = Plant(ContactSet(speeds, forces), 0.7)
    result = simulate(plant, 5.0)
    median = float(np.median(speeds))
    arrival = _startup_time(speeds, forces, 0.7, 0.0, median)
    assert result.V[-1] == median                                 # exactly the median speed
    stick = _times(result, "stick")
    assert len(stick) == 1 and stick[0] == pytest.approx(arrival, rel=RTOL, abs=0)
    assert len(_times(result, "cross")) == 5                      # five speeds below it


def test_even_n_stops_at_the_band_edge_reached_first(rng):
    speeds = rng.uniform(0.05, 0.35, 10)
    s = np.sort(speeds)
    plant = Plant(ContactSet(speeds), 1.0)
    up = simulate(plant, 5.0)                   # from rest, below: lower edge v_(5)
    down = simulate(plant, 5.0, v0=0.5)         # from above: upper edge v_(6)
    assert up.V[-1] == s[4] and down.V[-1] == s[5]
    assert up.V[-1] != np.median(speeds)
    arrival = _startup_time(speeds, np.ones(10), 1.0, 0.0, s[4])
    assert _times(up, "stick")[0] == pytest.approx(arrival, rel=RTOL, abs=0)
    # Started inside the zero-force band with no drag: the body coasts at constant speed.
    inside = simulate(plant, 5.0, v0=0.5 * (s[4] + s[5]))
    assert inside.V[-1] == 0.5 * (s[4] + s[5]) and inside.n_events == 0


def test_exponential_approach_with_drag():
    # Contacts far above: m V' = F_tot - c V, V = (F/c)(1 - exp(-c t / m)), F/c = 1.5 < 10.
    plant = Plant(ContactSet([10.0, 11.0, 12.0], [1.0, 1.0, 1.0]), 2.0, damping=2.0)
    result = simulate(plant, 3.0)
    times = np.linspace(0.0, 3.0, 13)
    expected = 1.5 * -np.expm1(-times)
    np.testing.assert_allclose(result.speed_at(times), expected, rtol=RTOL, atol=1e-300)
    assert result.n_events == 0


def test_exponential_segments_with_drag_reach_contact_speed():
    # From rest with drag below a contact at 1: time to reach 1 is -(m/c) log(1 - c/F).
    plant = Plant(ContactSet([1.0, 5.0, 6.0]), 1.0, damping=0.5)
    result = simulate(plant, 10.0)
    t_hit = -2.0 * math.log1p(-0.5 / 3.0)
    assert result.events[0].time == pytest.approx(t_hit, rel=RTOL, abs=0)
    assert result.events[0].kind == "cross"      # others +2 - c = 1.5 > W = 1: passes


def test_stick_and_release_under_piecewise_external_force():
    # Median contact at 0.2 (W = 1); others cancel. External force steps 0 -> 0.8 -> 1.6 N.
    speeds = [-0.3, 0.2, 0.9]
    ext = PiecewiseConstant([1.0, 2.0], [0.0, 0.8, 1.6])
    plant = Plant(ContactSet(speeds), 0.5, external_force=ext)
    result = simulate(plant, 2.2, v0=0.2)
    assert _times(result, "stick") == [0.0]
    assert _times(result, "release") == [2.0]          # |G| = 1.6 > W = 1 only from t = 2
    assert [e.kind for e in result.events if e.time == 2.0] == ["command", "release"]
    # After release: m V' = 1.6 - 1 (contact below) - 1 + 1 ... = F_ext + (+1 - 1 - 1) = 0.6.
    times = np.array([2.05, 2.1, 2.2])
    np.testing.assert_allclose(result.speed_at(times), 0.2 + 0.6 / 0.5 * (times - 2.0),
                               rtol=RTOL, atol=0)
    np.testing.assert_array_equal(result.speed_at([0.5, 1.5, 1.99]), [0.2, 0.2, 0.2])


def test_command_schedule_moves_the_median():
    plant = Plant(ContactSet([0.0, 0.1, 0.2]), 1.0,
                  commands=PiecewiseConstant([1.0], [[0.0, 0.1, 0.2], [0.3, 0.4, 0.5]]))
    result = simulate(plant, 3.0, v0=0.1)
    # After the switch all contacts are above: V' = 3 until V = 0.3 (t = 1 + 0.2/3), then
    # +1 net until 0.4 (0.1 more s); the median 0.4 holds.
    assert result.V[-1] == 0.4
    assert _times(result, "stick")[-1] == pytest.approx(1.0 + 0.2 / 3.0 + 0.1, rel=RTOL, abs=0)
    assert _times(result, "release") == [1.0]


@pytest.mark.parametrize("n", [1, 2, 3, 4, 5])
def test_braking_law(n):
    # docs/physics.md section 6: 5-n contacts at +v_max, 5+n at -v_max, from V = +v_max:
    # dT = m 2 v_max / (F_tot n / 5).
    v_max, mass, f = 0.35, 0.8, 0.2
    speeds = [v_max] * (5 - n) + [-v_max] * (5 + n)
    plant = Plant(ContactSet(speeds, [f] * 10), mass)
    result = simulate(plant, 10.0, v0=v_max)
    expected = mass * 2 * v_max / (10 * f * n / 5)
    assert _times(result, "stick")[-1] == pytest.approx(expected, rel=RTOL, abs=0)
    assert result.V[-1] == -v_max


def test_braking_law_n0_never_moves():
    plant = Plant(ContactSet([0.35] * 5 + [-0.35] * 5), 1.0)
    result = simulate(plant, 10.0, v0=0.35)
    assert result.V[-1] == 0.35 and _times(result, "stick") == [0.0]


def test_coincident_speeds_stick_as_one_group():
    # Three contacts at 0.1 (W = 3) and two above, one below: others push +2 - 1 = 1 <= 3.
    plant = Plant(ContactSet([0.1, 0.1, 0.1, 0.5, 0.6, -0.4]), 1.0)
    result = simulate(plant, 2.0, v0=-1.0)
    assert result.V[-1] == 0.1
    stick = [e for e in result.events if e.kind == "stick"]
    assert stick[0].contact == 0                         # lowest index of the group


def test_mirrored_sign_convention(rng):
    speeds = rng.normal(size=9)
    a = simulate(Plant(ContactSet(speeds), 1.3, damping=0.2), 4.0, v0=-0.4)
    b = simulate(Plant(ContactSet(-speeds), 1.3, damping=0.2), 4.0, v0=0.4)
    # Mirroring V -> -V maps the problem to itself; only rounding of sums differs.
    np.testing.assert_allclose(a.V, -b.V, rtol=RTOL, atol=1e-15)
    assert [e.kind for e in a.events] == [e.kind for e in b.events]


@settings(deadline=None, max_examples=30)
@given(st.lists(st.integers(-20, 20), min_size=1, max_size=12), st.integers(-30, 30))
def test_final_state_is_in_the_equilibrium_set(grid, start):
    # Without drag or external force the body ends in the weighted-median set (it gets
    # there in finite time: t_end is far beyond the worst travel time 2 * 60 / 1).
    cs = ContactSet(np.array(grid) / 10.0)
    result = simulate(Plant(cs, 1.0), 200.0, v0=start / 10.0)
    lo, hi = cs.equilibrium()
    assert lo <= result.V[-1] <= hi


def test_large_n_from_below_reaches_the_median(rng):
    # Unit magnitudes keep every plateau force an exact integer; the arrival time is the
    # sum of m dv / F over 5e4 segments, summed exactly here with math.fsum (the simulator
    # sums its segment times with compensation).
    n = 100_001
    speeds = rng.uniform(-1.0, 1.0, n)
    mass = float(n)
    plant = Plant(ContactSet(speeds), mass)
    result = simulate(plant, 20.0, v0=-1.5)
    median = float(np.median(speeds))
    assert result.success and result.V[-1] == median
    assert len(_times(result, "cross")) == n // 2 and result.n_events == n // 2 + 1
    s = np.concatenate(([-1.5], np.sort(speeds)[: n // 2 + 1]))
    below = np.arange(n // 2 + 1)                      # contacts below each segment
    arrival = math.fsum(mass * np.diff(s) / (n - 2.0 * below))
    assert _times(result, "stick")[0] == pytest.approx(arrival, rel=RTOL, abs=0)


# -- compliance -------------------------------------------------------------------------------
def test_compliance_steady_state_and_trajectory():
    # k = 2: every slip stays within k f = 2, all contacts linear: m V' = sum (v - V)/k + E - cV
    # -> V(t) = V_inf (1 - exp(-b t / m)), b = 3/k + c, V_inf = (sum v / k + E) / b.
    plant = Plant(ContactSet([0.0, 1.0, 2.0]), 1.0, damping=0.2, external_force=0.3,
                  motors=Motors(compliance=2.0))
    result = simulate(plant, 40.0)
    b, v_inf = 1.5 + 0.2, (3.0 / 2.0 + 0.3) / 1.7
    times = np.linspace(0.0, 40.0, 9)
    np.testing.assert_allclose(result.speed_at(times), -v_inf * np.expm1(-b * times),
                               rtol=RTOL, atol=1e-300)


def test_compliance_saturation_events():
    # k = 0.1: contact 0 leaves the linear band at V = 0.1 (slip -k f) after an exponential
    # segment m V' = 2 - V / k: V = 0.2 (1 - exp(-10 t)) reaches 0.1 at t = ln(2) / 10.
    plant = Plant(ContactSet([0.0, 1.0, 2.0]), 1.0, motors=Motors(compliance=0.1))
    result = simulate(plant, 5.0)
    first = result.events[0]
    assert first.kind == "saturation" and first.contact == 0
    assert first.time == pytest.approx(math.log(2.0) / 10.0, rel=RTOL, abs=0)
    assert result.V[-1] == pytest.approx(plant.equilibrium()[0], rel=RTOL, abs=0)


# -- dynamic motors -------------------------------------------------------------------------
def test_crossing_with_first_order_lag_matches_lambert_w():
    # Body from rest, contact A at 10 (f = 1) and contact B (f = 0.5) commanded 5 -> -5 at
    # t_s = 0.5 with lag tau: before the crossing V = a t (a = 1.5), v_B = -5 + 10 e^{-(t-t_s)/tau}.
    # a t + 5 = 10 e^{-(t - t_s)/tau} -> t = tau W(10 e^{(t_s + 5/a)/tau} / (a tau)) - 5/a.
    tau, t_s, a = 0.2, 0.5, 1.5
    plant = Plant(ContactSet([10.0, 5.0], [1.0, 0.5]), 1.0, motors=Motors(lag=tau),
                  commands=PiecewiseConstant([t_s], [[10.0, 5.0], [10.0, -5.0]]))
    result = simulate(plant, 2.0)
    arg = 10.0 * math.exp((t_s + 5.0 / a) / tau) / (a * tau)
    expected = tau * float(np.real(special.lambertw(arg))) - 5.0 / a
    # Cross-check the Lambert-W closed form with brentq on the same equation.
    check = optimize.brentq(lambda t: a * t + 5 - 10 * math.exp(-(t - t_s) / tau), t_s, 2.0,
                            xtol=1e-15, rtol=4 * np.finfo(float).eps)
    assert expected == pytest.approx(check, rel=1e-13, abs=0)
    cross = [e for e in result.events if e.kind == "cross"]
    assert len(cross) == 1 and cross[0].contact == 1
    assert cross[0].time == pytest.approx(expected, rel=RTOL, abs=0)
    # After the crossing the net force is 1 - 0.5 = 0.5 N.
    later = np.array([1.5, 2.0])
    np.testing.assert_allclose(result.speed_at(later), a * expected + 0.5 * (later - expected),
                               rtol=RTOL, atol=0)


def test_crossing_with_rate_limit_ramp():
    # Contact B ramps 5 -> -5 at r = 4 m/s^2 from t_s = 0.5: crossing a t = 5 - r (t - t_s).
    r, t_s, a = 4.0, 0.5, 1.5
    plant = Plant(ContactSet([10.0, 5.0], [1.0, 0.5]), 1.0, motors=Motors(rate_limit=r),
                  commands=PiecewiseConstant([t_s], [[10.0, 5.0], [10.0, -5.0]]))
    result = simulate(plant, 4.0)
    cross = _times(result, "cross")
    assert cross == [pytest.approx((5.0 + r * t_s) / (a + r), rel=RTOL, abs=0)]
    np.testing.assert_allclose(result.contact_speeds[-1], [10.0, -5.0], rtol=0, atol=0)


def test_stuck_body_follows_a_lagging_contact():
    # The median contact moves 0 -> 0.1 with tau = 0.5; the outer contacts (f = 5) are far:
    # G = 0 and m |dv/dt| <= 0.2 < W = 1: the body follows v(t) = 0.1 (1 - e^{-(t-1)/tau}).
    plant = Plant(ContactSet([-1.0, 0.0, 1.0], [5.0, 1.0, 5.0]), 1.0, motors=Motors(lag=0.5),
                  commands=PiecewiseConstant([1.0], [[-1.0, 0.0, 1.0], [-1.0, 0.1, 1.0]]))
    result = simulate(plant, 3.0)
    times = np.linspace(1.0, 3.0, 9)
    np.testing.assert_allclose(result.speed_at(times), -0.1 * np.expm1(-(times - 1.0) / 0.5),
                               rtol=RTOL, atol=1e-300)
    assert _times(result, "release") == []


def test_stuck_body_released_when_the_contact_accelerates_too_fast():
    # Same scene, mass 10: at the switch m dv/dt = 10 * 0.2 = 2 > W = 1: release at t = 1;
    # then m V' = +1 (the contact above), V = 0.1 x with x = t - 1, while the contact moves
    # as v = 0.1 (1 - e^{-2x}). They meet again where x = 1 - e^{-2x}, i.e.
    # x = 1 + W0(-2 e^{-2}) / 2 (Lambert W); there m dv/dt = 2 e^{-2x} < 1 = W: it sticks.
    plant = Plant(ContactSet([-1.0, 0.0, 1.0], [5.0, 1.0, 5.0]), 10.0, motors=Motors(lag=0.5),
                  commands=PiecewiseConstant([1.0], [[-1.0, 0.0, 1.0], [-1.0, 0.1, 1.0]]))
    result = simulate(plant, 3.0)
    assert _times(result, "release") == [1.0]
    meet = 1.0 + float(np.real(special.lambertw(-2.0 * math.exp(-2.0)))) / 2.0
    assert _times(result, "stick")[-1] == pytest.approx(1.0 + meet, rel=RTOL, abs=0)
    later = np.array([1.2, 1.5, 1.0 + meet])
    np.testing.assert_allclose(result.speed_at(later), 0.1 * (later - 1.0), rtol=RTOL, atol=0)
    after = np.array([2.9, 3.0])
    np.testing.assert_allclose(result.speed_at(after), -0.1 * np.expm1(-2.0 * (after - 1.0)),
                               rtol=RTOL, atol=0)


def test_dynamic_engine_equals_ideal_engine_when_motors_are_settled(rng):
    # A schedule whose only switch comes after t_end sends the plant through the dynamic
    # engine, but its lagging motors never move: both engines solve one problem.
    speeds = rng.uniform(-0.35, 0.35, 9)
    ideal = simulate(Plant(ContactSet(speeds), 0.6, damping=0.1), 3.0, v0=-0.5)
    lagged = simulate(Plant(ContactSet(speeds), 0.6, damping=0.1, motors=Motors(lag=0.03),
                            commands=PiecewiseConstant([100.0], [speeds, speeds])),
                      3.0, v0=-0.5)
    assert [e.kind for e in ideal.events] == [e.kind for e in lagged.events]
    np.testing.assert_allclose([e.time for e in lagged.events], [e.time for e in ideal.events],
                               rtol=RTOL, atol=0)
    assert lagged.V[-1] == pytest.approx(ideal.V[-1], rel=RTOL, abs=0)


def test_compliant_lagging_motors_against_a_tight_ode_solver():
    # Compliance makes the model Lipschitz: a tight LSODA run on (V, v_1..v_n) is a second
    # method. Its tolerance (rtol 1e-11) bounds the comparison, so compare at 1e-8.
    speeds = np.array([-0.3, 0.1, 0.25, 0.4])
    forces = np.array([1.0, 0.7, 1.2, 0.5])
    new = np.array([0.2, -0.1, 0.3, 0.05])
    motors = Motors(lag=0.05, compliance=0.08)
    plant = Plant(ContactSet(speeds, forces), 0.3, damping=0.1, motors=motors,
                  commands=PiecewiseConstant([0.4], [speeds, new]))
    times = np.linspace(0.0, 1.5, 31)
    exact = simulate(plant, 1.5, t_eval=times, v0=0.5)

    def rhs(t, y):
        V, v = y[0], y[1:]
        return np.concatenate(([plant.net_force(t, V, v) / plant.mass], plant.motor_rate(t, v)))

    ref = np.empty_like(times)
    state = np.concatenate(([0.5], speeds))
    for k, (lo, hi) in enumerate(((0.0, 0.4), (0.4, 1.5))):
        part = times[(times >= lo) & (times <= hi)] if k else times[times < 0.4]
        sol = integrate.solve_ivp(rhs, (lo, hi), state, method="LSODA", rtol=1e-11, atol=1e-13,
                                  t_eval=np.append(part, hi) if k == 0 else part, dense_output=True)
        ref[(times >= lo) & (times <= hi) if k else times < 0.4] = sol.sol(part)[0]
        state = sol.sol(hi)
    np.testing.assert_allclose(exact.V, ref, rtol=0, atol=1e-8)
    assert any(e.kind == "saturation" for e in exact.events)


# -- budgets ----------------------------------------------------------------------------------
def test_zeno_guard_returns_zeno_status():
    # 20 000 command switches within 2 ms: ~1e7 events per second > max_event_rate = 1e6.
    times = np.linspace(1e-3, 3e-3, 20_000)
    rows = np.where((np.arange(20_001) % 2)[:, None] == 0, [[0.0, 1.0, 2.0]], [[0.0, -1.0, 2.0]])
    plant = Plant(ContactSet([0.0, 1.0, 2.0]), 1.0, commands=PiecewiseConstant(times, rows))
    result = simulate(plant, 1.0, budget=Budget(max_event_rate=1e6))
    assert result.status is SimulationStatus.ZENO and not result.success
    assert "Zeno" in result.message and result.t_final < 3e-3
    assert np.isnan(result.speed_at(0.5))              # nothing is claimed past the stop


def test_step_and_wall_time_budgets():
    speeds = np.linspace(-1.0, 1.0, 2001)
    plant = Plant(ContactSet(speeds), 1.0)
    steps = simulate(plant, 100.0, v0=-2.0, budget=Budget(max_steps=50))
    assert steps.status is SimulationStatus.MAX_STEPS and steps.n_steps <= 51
    wall = simulate(plant, 100.0, v0=-2.0, budget=Budget(wall_time=1e-9))
    assert wall.status is SimulationStatus.WALL_TIME
    assert np.all(np.isfinite(wall.V))


# -- second method and robustness -----------------------------------------------------------
def test_moreau_converges_to_the_exact_solution_with_dynamic_motors():
    # Moreau-Jean is first order: shrinking its step 10x must shrink its distance to the
    # exact trajectory about 10x (we ask for 5x). A wrong exact solution would make the
    # distance stall at the size of the mistake instead.
    rng = np.random.default_rng(11)
    speeds, forces = rng.uniform(-0.35, 0.35, 5), rng.uniform(0.1, 1.0, 5)
    commands = PiecewiseConstant([0.3, 0.6], [speeds, rng.uniform(-0.35, 0.35, 5),
                                              rng.uniform(-0.35, 0.35, 5)])
    plant = Plant(ContactSet(speeds, forces), 0.5, motors=Motors(lag=0.03, rate_limit=3.0),
                  commands=commands)
    times = np.linspace(0.0, 1.0, 41)
    exact = simulate(plant, 1.0, v0=0.2, t_eval=times)
    kinds = {e.kind for e in exact.events}
    assert {"cross", "stick", "release", "command"} <= kinds
    errors = [np.max(np.abs(simulate(plant, 1.0, v0=0.2, t_eval=times, method="moreau",
                                     step=h).V - exact.V)) for h in (1e-3, 1e-4)]
    assert errors[1] < errors[0] / 5 and errors[1] < 2e-4


def test_speed_limits_clip_commands():
    limits = (-0.3, 0.3)
    commands = PiecewiseConstant([0.2], [[0.0, 0.1, 0.2], [0.5, 0.6, 0.7]])
    for motors in (Motors(speed_limits=limits), Motors(lag=0.02, speed_limits=limits)):
        plant = Plant(ContactSet([0.0, 0.1, 0.2]), 1.0, motors=motors, commands=commands)
        result = simulate(plant, 3.0, v0=0.1)
        # Every command above 0.3 is clipped to 0.3: the body ends at the limit exactly.
        assert result.V[-1] == pytest.approx(0.3, rel=RTOL, abs=0)
        assert np.max(result.contact_speeds) <= 0.3


@settings(deadline=None, max_examples=12)
@given(st.integers(0, 10**6))
def test_random_dynamic_scenes_finish_finite(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 7))
    speeds = rng.uniform(-0.35, 0.35, n)
    motors = Motors(lag=float(rng.choice([0.0, 0.03])), rate_limit=float(rng.choice([2.0, 50.0])),
                    compliance=float(rng.choice([0.0, 0.05])))
    commands = PiecewiseConstant(np.sort(rng.uniform(0.0, 1.0, 2)),
                                 rng.uniform(-0.35, 0.35, (3, n)))
    plant = Plant(ContactSet(speeds, rng.uniform(0.1, 1.0, n)), float(rng.uniform(0.1, 2.0)),
                  damping=float(rng.choice([0.0, 0.5])), motors=motors, commands=commands)
    result = simulate(plant, 2.0, v0=float(rng.uniform(-0.5, 0.5)), budget=Budget(wall_time=20))
    assert result.success and np.all(np.isfinite(result.V)) and result.n_events < 200
    # The dense output agrees with the samples it produced: the same closed forms, evaluated
    # scalar (samples) or vectorized (dense), so they may differ by a few ulp of their terms
    # (whose size is that of the speeds: a V near 0 is a cancellation, hence the atol).
    scale = max(float(np.max(np.abs(result.V))), float(np.max(np.abs(result.contact_speeds))))
    np.testing.assert_allclose(result.speed_at(result.t), result.V, rtol=1e-15,
                               atol=4 * np.finfo(float).eps * scale)


def test_repeated_runs_reuse_the_plant_cache_without_changing_results():
    plant = Plant(ContactSet([0.3, -0.2, 0.1, 0.25, -0.05]), 0.4, damping=0.05)
    first = simulate(plant, 2.0)
    assert _LANDSCAPES.get(plant)                        # the sorted landscape is kept
    second = simulate(plant, 2.0)
    np.testing.assert_array_equal(first.V, second.V)
    assert first.events == second.events
    other = Plant(ContactSet([0.3, -0.2, 0.1]), 0.4)
    assert not _LANDSCAPES.get(other)                    # each plant has its own cache


def test_coincident_moving_contacts_act_as_one():
    # Identity: two contacts with the same schedule move identically, so they are one contact
    # with the summed magnitude; the two plants must give the same trajectory bit for bit.
    motors = Motors(lag=0.05, rate_limit=2.0)
    split = Plant(ContactSet([-0.3, 0.1, 0.1, 0.3], [1.0, 0.5, 0.5, 1.0]), 0.3, motors=motors,
                  commands=PiecewiseConstant([0.2, 0.6], [[-0.3, 0.1, 0.1, 0.3],
                                                          [-0.3, 0.25, 0.25, 0.3],
                                                          [-0.3, -0.2, -0.2, 0.3]]))
    merged = Plant(ContactSet([-0.3, 0.1, 0.3], [1.0, 1.0, 1.0]), 0.3, motors=motors,
                   commands=PiecewiseConstant([0.2, 0.6], [[-0.3, 0.1, 0.3], [-0.3, 0.25, 0.3],
                                                           [-0.3, -0.2, 0.3]]))
    times = np.linspace(0.0, 1.5, 31)
    a = simulate(split, 1.5, t_eval=times, v0=0.05)
    b = simulate(merged, 1.5, t_eval=times, v0=0.05)
    np.testing.assert_array_equal(a.V, b.V)
    assert [e.kind for e in a.events] == [e.kind for e in b.events]


def test_contacts_a_few_ulp_apart_are_simulated():
    # Regression (F1): lag-compensated commands from design_schedule (seed 46965, 4 contacts,
    # lag 0.01) bring contacts within a few ulp of each other; the crossing bracket (found
    # with np.expm1) then held no sign change for the scalar polish (math.expm1) and _brent
    # raised ValueError. Second method: the same run on commands rounded to 1e-9 m/s (exactly
    # tied). Identity used for the tolerance: V' = (1/m) sum f_i sign(v_i - V) is monotone in
    # (v - V), so two runs whose contact speeds differ by at most d stay within d of each
    # other; a first-order lag is an average of its commands, so d <= max |command shift|.
    rng = np.random.default_rng(46965)
    speeds, forces = rng.uniform(-0.3, 0.3, 4), rng.uniform(0.1, 0.5, 4)
    head = [[0.08090092114379605, 0.12980428791116305, -0.11386425712043502,
             0.27726807981134954],
            [0.03359828423628308, 0.025944044547332464, 0.35, 0.00286335944818803],
            [0.060386661353120874, 0.060386661353120874, 0.021691931560304814,
             0.06038666135312089]]
    tail = [0.0835016711215131, 0.10038666135312088, 0.12286486408818263, 0.14250443788420314,
            0.15166154833501488, 0.17, -0.35, 0.17104062313054505, 0.0917666197287446,
            0.04307656111839125, -0.019391058564980062, -0.07939105856498002,
            -0.07939105856498002]
    values = np.vstack((head, np.repeat(np.array(tail)[:, None], 4, axis=1)))
    times = 0.02 * np.arange(1, 16)
    motors = Motors(lag=0.01, speed_limits=(-0.35, 0.35))
    plant = Plant(ContactSet(speeds, forces), 1.0, motors=motors,
                  commands=PiecewiseConstant(times, values))
    rounded = Plant(ContactSet(speeds, forces), 1.0, motors=motors,
                    commands=PiecewiseConstant(times, np.round(values, 9)))
    grid = np.linspace(0.0, 0.3, 3001)
    result = simulate(plant, 0.3, t_eval=grid)
    second = simulate(rounded, 0.3, t_eval=grid)
    assert result.status is SimulationStatus.SUCCESS and second.status is SimulationStatus.SUCCESS
    assert all(math.isfinite(e.time) for e in result.events)
    shift = float(np.max(np.abs(values - np.round(values, 9))))
    # atol: the shift bound plus rounding of the two closed forms (|V| <= 0.35, ~1e-15).
    np.testing.assert_allclose(result.V, second.V, rtol=0, atol=shift + 1e-14)


def test_to_dict_is_json_able():
    result = simulate(Plant(ContactSet([-1.0, 0.5, 2.0]), 1.0), 2.0)
    summary = json.loads(json.dumps(result.to_dict(samples=True)))
    assert summary["status"] == "SUCCESS" and summary["V_final"] == 0.5
    assert summary["events"] == [{"time": 0.5, "kind": "stick", "contact": 1, "speed": 0.5}]
    assert summary["t"] == result.t.tolist()


# -- fast paths: the result built without re-validation, the landscape read from ContactSet ----
def _revalidated(result: SimulationResult) -> SimulationResult:
    """The same fields through the public, validating constructor."""
    return SimulationResult(**{f.name: getattr(result, f.name)
                               for f in dataclasses.fields(SimulationResult)})


@pytest.mark.parametrize("case", ["ideal", "t_eval", "commands", "dynamic", "compliant"])
def test_result_built_by_the_fast_path_passes_validation_unchanged(case):
    speeds = [-0.3, 0.1, 0.25, -0.05, 0.3]
    kwargs: dict = {}
    if case == "commands":
        kwargs["commands"] = PiecewiseConstant([0.5], [speeds, [0.2, -0.1, 0.0, 0.3, -0.3]])
    if case == "dynamic":
        kwargs.update(motors=Motors(lag=0.05, rate_limit=3.0),
                      commands=PiecewiseConstant([0.4], [speeds, [0.2, -0.1, 0.0, 0.3, -0.3]]))
    if case == "compliant":
        kwargs["motors"] = Motors(compliance=0.02)
    plant = Plant(ContactSet(speeds), 0.7, damping=0.1, **kwargs)
    t_eval = np.linspace(0.0, 1.5, 7) if case == "t_eval" else None
    result = simulate(plant, 1.5, t_eval=t_eval)
    again = _revalidated(result)
    for name in ("t", "V", "force", "contact_speeds"):
        array = getattr(result, name)
        assert not array.flags.writeable
        np.testing.assert_array_equal(array, getattr(again, name))
    if case in ("ideal", "compliant", "t_eval"):       # a zero-stride table: locked for good
        with pytest.raises(ValueError, match="WRITEABLE"):
            result.contact_speeds.setflags(write=True)
    assert result.events == again.events and result.n_events == len(result.events) > 0
    for event in result.events:
        assert type(event.time) is float and type(event.speed) is float
        assert event.contact is None or type(event.contact) is int
        assert Event(event.time, event.kind, event.contact, event.speed) == event


@pytest.mark.parametrize("case", ["t_eval", "none", "commands", "dynamic", "stopped"])
def test_lazy_fields_are_computed_on_first_access_and_survive_copies(case):
    # The fast path leaves events, contact speeds and the dense output to be built on first
    # access. Closed forms: with speeds [-1, 0.5, 2] (f = 1 N each), m = 1 kg, from rest, the
    # body feels +1 N up to 0.5 m/s and sticks there at t = 0.5 s; contact speeds are the
    # commands. Pickle and deepcopy carry every field (identities).
    import copy
    import pickle

    speeds = [-1.0, 0.5, 2.0]
    kwargs: dict = {}
    if case == "commands":
        kwargs["commands"] = PiecewiseConstant([1.0], [speeds, [-1.0, 0.25, 2.0]])
    if case == "dynamic":
        kwargs.update(motors=Motors(lag=0.05),
                      commands=PiecewiseConstant([1.0], [speeds, [-1.0, 0.25, 2.0]]))
    plant = Plant(ContactSet(speeds), 1.0, **kwargs)
    times = np.linspace(0.0, 0.8, 9) if case in ("t_eval", "stopped") else None
    budget = Budget(max_steps=1) if case == "stopped" else None
    result = simulate(plant, 0.8 if case in ("t_eval", "stopped") else 2.0, t_eval=times,
                      budget=budget)
    assert {"events", "contact_speeds", "dense"}.isdisjoint(vars(result))
    if case != "stopped":
        assert (result.events[0].kind, result.events[0].contact) == ("stick", 1)
        assert result.events[0].time == pytest.approx(0.5, rel=RTOL, abs=0)
        assert result.events[0].speed == pytest.approx(0.5, rel=RTOL, abs=0)
    assert len(result.events) == result.n_events
    if case == "dynamic":        # the motor lag's closed form after the switch at 1 s
        expected = np.tile(speeds, (result.t.size, 1))
        late = result.t > 1.0
        expected[late, 1] = 0.25 + 0.25 * np.exp(-(result.t[late] - 1.0) / 0.05)
        # rtol: a few roundings of exp and of the closed form (~1e-15)
        np.testing.assert_allclose(result.contact_speeds, expected, rtol=RTOL, atol=0)
    else:
        expected = np.array([plant.command(t) for t in result.t])
        np.testing.assert_array_equal(result.contact_speeds, expected)
    np.testing.assert_array_equal(result.speed_at(result.t), result.V)
    assert "_source" not in vars(result)       # every lazy field built: the record let go
    fresh = simulate(plant, result.dense.t_end, t_eval=times, budget=budget)
    for twin in (pickle.loads(pickle.dumps(fresh)), copy.deepcopy(fresh)):
        for f in dataclasses.fields(SimulationResult):
            if f.name in ("dense", "wall_time"):
                continue
            mine, other = getattr(result, f.name), getattr(twin, f.name)
            if isinstance(mine, np.ndarray):
                np.testing.assert_array_equal(mine, other)
            else:
                assert mine == other, f.name
        np.testing.assert_array_equal(twin.speed_at(result.t), result.V)
    with pytest.raises(AttributeError, match="no_such_field"):
        result.no_such_field


def test_caller_t_eval_array_is_not_frozen_by_the_result():
    times = np.linspace(0.0, 1.0, 5)
    result = simulate(Plant(ContactSet([-0.2, 0.1, 0.3]), 1.0), 1.0, t_eval=times)
    assert times.flags.writeable and not result.t.flags.writeable
    np.testing.assert_array_equal(result.t, times)


@pytest.mark.parametrize("n_far", [0, 100])        # few contacts: a scan; many: one sort
def test_events_name_the_lowest_touching_contact(n_far):
    # Contact 0 is lifted (f = 0) at the speed where the body sticks; contacts 2 and 3 touch
    # there. Far contacts (at +-10 m/s, balanced) only add the same force above and below.
    far = [10.0, -10.0] * (n_far // 2)
    speeds = [0.5, 1.0, 0.5, 0.5, 2.0, -0.5] + far
    forces = [0.0, 1.0, 1.0, 1.0, 1.0, 1.0] + [1.0] * n_far
    plant = Plant(ContactSet(speeds, forces), 2.0)
    result = simulate(plant, 3.0)
    # From rest: F = (4 - 1) N above 0 up to 0.5, where W = 2 N holds against G = 2 - 1 = 1 N.
    assert [(e.kind, e.contact) for e in result.events] == [("stick", 2)]
    assert result.events[0].time == pytest.approx(0.5 * 2.0 / 3.0, rel=RTOL, abs=0)
    # Passing downward through 0.5 from above 1.0: crossings name contacts 1 and then 2.
    down = simulate(Plant(ContactSet(speeds, forces), 2.0, external_force=-5.0), 3.0, v0=1.5)
    assert [(e.kind, e.contact) for e in down.events][:2] == [("cross", 1), ("cross", 2)]


@settings(deadline=None, max_examples=25)
@given(st.lists(st.tuples(st.sampled_from([-0.3, -0.1, 0.0, 0.2, 0.4]),
                          st.sampled_from([0.0, 0.5, 1.0, 2.0])), min_size=1, max_size=9)
       .filter(lambda pairs: any(f > 0 for _, f in pairs)))
def test_coulomb_landscape_is_the_contact_set_staircase(pairs):
    # Identity: the engine's landscape reads the ContactSet's own prefix sums, so its plateau
    # forces are ContactSet.force between the levels, bit for bit, and its stiction is the
    # half-width of ContactSet.force_bounds at each level (magnitudes are halves and integers,
    # so every sum is exact in binary; 1e-15 only allows for the ulp of a different order).
    contacts = ContactSet([v for v, _ in pairs], [f for _, f in pairs])
    land = _CoulombLandscape(contacts)
    levels = contacts.staircase().levels
    assert land.xs == levels.tolist()
    probes = np.concatenate(([levels[0] - 1.0], 0.5 * (levels[:-1] + levels[1:]),
                             [levels[-1] + 1.0]))
    for j, V in enumerate(probes):
        assert land.force(j, float(V)) == (float(contacts.force(V)), 0.0)
    for k, level in enumerate(levels):
        W, G = land.stiction(k)
        lower, upper = contacts.force_bounds(level)
        assert W == pytest.approx(0.5 * (upper - lower), rel=1e-15, abs=1e-15)
        assert G == pytest.approx(contacts.force(level), rel=1e-15, abs=1e-15)
        touching = [i for i, (v, f) in enumerate(pairs) if v == level and f > 0]
        assert land.contact(k) == touching[0]


# -- non-finite physics ------------------------------------------------------------------------
def test_overflow_over_the_horizon_is_failed_not_success():
    # Finite rates (1e300 m/s^2) can still overflow over a long run: V(1e10 s) = 1e310 is not
    # a double. The run must say FAILED, never SUCCESS with V = inf.
    plant = Plant(ContactSet([0.1]), mass=1.0, external_force=1e300)
    result = simulate(plant, 1e10)
    assert result.status is SimulationStatus.FAILED
    assert result.message.startswith(SimulationStatus.FAILED.value)
    assert "floating-point range" in result.message
    assert np.all(np.isfinite(result.V)) and np.all(np.isfinite(result.t))   # the finite part
    # Kept: the segments that start finite; before the crossing at 1e-301 s, V = 1e300 t.
    dense = result.speed_at(np.array([1e-302, 1e5]))
    assert dense[0] == pytest.approx(0.01, rel=RTOL, abs=0) and np.isnan(dense[1])
    # The same plant over 1 s stays finite: V(1) = 1e300 exactly (constant acceleration,
    # the contact force 1 N is rounding next to 1e300).
    short = simulate(plant, 1.0)
    assert short.status is SimulationStatus.SUCCESS
    assert short.V[-1] == pytest.approx(1e300, rel=RTOL, abs=0)


def test_reach_time_of_non_finite_targets_and_rates_is_never():
    inf = math.inf
    assert _reach_time(0.0, inf, 0.0, 0.1) == inf          # infinite rate
    assert _reach_time(0.0, 1.0, 0.0, inf) == inf          # infinite target
    assert _reach_time(0.0, 1.0, 2.0, -inf) == inf
    assert _reach_time(inf, 1.0, 0.0, 0.1) == inf          # an overflowed V: never, not NaN
    # Closed forms: linear V = r0 s reaches 1 at s = 1 / 2; V = 1 - exp(-s) reaches 1/2 at ln 2.
    assert _reach_time(0.0, 2.0, 0.0, 1.0) == 0.5
    assert _reach_time(0.0, 1.0, 1.0, 0.5) == pytest.approx(math.log(2.0), rel=1e-15, abs=0)


# -- dense output: per-segment evaluation of sorted times ------------------------------------
def _random_scene(rng: np.random.Generator, kind: int) -> Plant:
    n = int(rng.integers(1, 9))
    contacts = ContactSet(rng.uniform(-0.4, 0.4, n), rng.uniform(0.1, 1.0, n))
    switches = np.sort(rng.uniform(0.1, 1.8, 3))
    commands = PiecewiseConstant(switches, rng.uniform(-0.4, 0.4, (4, n)))
    external = PiecewiseConstant(switches[:1], rng.uniform(-0.5, 0.5, 2))
    motors = [None, Motors(lag=0.05), Motors(rate_limit=3.0), Motors(compliance=0.05),
              Motors(lag=0.03, rate_limit=2.0, compliance=0.02)][kind % 5]
    return Plant(contacts, float(rng.uniform(0.2, 2.0)), damping=float(rng.choice([0.0, 0.7])),
                 external_force=external, motors=motors,
                 commands=None if kind % 7 == 6 else commands)


def test_sorted_dense_output_equals_the_gathered_path(rng):
    # Second method: the per-time gather of segment rows (the path kept for unsorted times)
    # against the per-segment slices for sorted times, and against the straight-line gather
    # of runs whose segments are all lines. Same operations in the same order, so equal bit
    # for bit (array_equal; a dropped zero term may only turn -0.0 into 0.0).
    linear_runs = 0
    for kind in range(35):
        plant = _random_scene(rng, kind)
        budget = Budget(max_steps=5) if kind % 11 == 10 else Budget()   # a stopped run: NaN
        base = simulate(plant, 2.0, v0=float(rng.uniform(-0.5, 0.5)), budget=budget)
        events = [e.time for e in base.events]
        times = np.union1d(np.union1d(base.t, events), np.linspace(0.0, 2.0, 257))
        dense = base.dense
        V, dV = dense.sorted_values(times)
        np.testing.assert_array_equal(V, dense.gathered_values(times))
        np.testing.assert_array_equal(dV, dense.gathered_derivative(times))
        shuffled = rng.permutation(times)                    # unsorted: the gathered path
        np.testing.assert_array_equal(dense(shuffled), dense.gathered_values(shuffled))
        # Non-finite times (dense() does not refuse them) propagate as in the general form.
        odd = np.array([np.nan, np.inf, -np.inf, 1e10])
        np.testing.assert_array_equal(dense(odd), dense.gathered_values(odd))
        np.testing.assert_array_equal(dense.derivative(odd), dense.gathered_derivative(odd))
        lines = dense.linear_values(shuffled)
        # The engine's claim that its segments are lines holds on the stored rows (it may
        # also hold without the claim, e.g. a damped body stuck all along).
        assert not dense.linear or (not np.any(dense.table[:, [2, 4, 5, 6]]) and dense.mu == 0)
        if lines is not None:
            linear_runs += 1
            np.testing.assert_array_equal(lines[0], dense.gathered_values(shuffled))
            np.testing.assert_array_equal(lines[1], dense.gathered_derivative(shuffled))
        # simulate with t_eval (sorted) gives the same samples and force m dV/dt.
        run = simulate(plant, 2.0, v0=float(base.V[0]),
                       t_eval=times, budget=budget)
        np.testing.assert_array_equal(run.V, V)
        force = plant.mass * dV
        force[np.isnan(V)] = np.nan
        np.testing.assert_array_equal(run.force, force)
    assert linear_runs >= 3                                  # the straight-line path was tested


def test_speed_at_refuses_times_outside_the_simulated_span():
    # V = 1 t (F_ext / m = 1 N / 1 kg, no contact force above v = -1): closed form inside.
    plant = Plant(ContactSet([-1.0]), 1.0, external_force=2.0)
    result = simulate(plant, 2.0, t_eval=[0.0, 0.5, 1.0])
    # The exact dense output knows its horizon t_end = 2 s, beyond the last sample 1 s.
    np.testing.assert_allclose(result.speed_at([0.0, 1.5, 2.0]), [0.0, 1.5, 2.0],
                               rtol=RTOL, atol=0)
    for outside in (-1e-9, 2.0 + 1e-9, [0.5, 3.0]):
        with pytest.raises(ParameterError, match="simulated span"):
            result.speed_at(outside)
    # Without a dense output: the samples' span [t[0], t_final], linear interpolation inside.
    plain = SimulationResult("x", "y", [0.5, 1.0], [1.0, 2.0], np.zeros((2, 1)), [0.0, 0.0],
                             (), SimulationStatus.SUCCESS, "ok", 0, 0, 1, 0.0)
    assert plain.speed_at(0.75) == pytest.approx(1.5, rel=1e-15, abs=0)
    with pytest.raises(ParameterError, match=r"\[0.5, 1\] s"):
        plain.speed_at(0.25)


@pytest.mark.parametrize("motors, t_end", [
    (Motors(lag=1e-300), 2.0), (Motors(lag=1e-300, rate_limit=1.0), 2.0),
    (Motors(lag=0.1), 1e300), (Motors(lag=0.1, rate_limit=2.0), 1e300),
    (Motors(rate_limit=1e300), 2.0), (Motors(lag=1e-300, compliance=0.1), 2.0),
])
@pytest.mark.parametrize("damping", [0.0, 0.5])
def test_extreme_motor_scales_run_without_warnings(motors, t_end, damping):
    # Regression (F11): lag 1e-300 and horizons of 1e300 s overflowed masked or sign-only
    # products (warnings, errors under this suite's filterwarnings). Coulomb: both command
    # sets have the median 0.2 m/s (equal forces) and 0 lies in F(0.2) - 0.2 c = [-1, 1] -
    # 0.1 c, so the body ends at V = 0.2 exactly. Compliant: second method, the same plant
    # with instantaneous motors (lag 0: the ideal-motor engine); a 1e-300 s lag changes
    # nothing a double can hold, so rtol 1e-12 (the target). Regression: the
    # saturation events of the 1e-300 s transient were once placed near 1e-175 s (bisection
    # by halving widths from the 1.5 s horizon), leaving a saturated contact linear for good.
    commands = PiecewiseConstant([0.5], [[0.0, 0.2, 0.4], [0.3, -0.1, 0.2]])
    plant = Plant(ContactSet([0.0, 0.2, 0.4]), 1.0, damping=damping, motors=motors,
                  commands=commands)
    result = simulate(plant, t_end)
    assert result.status is SimulationStatus.SUCCESS
    assert np.all(np.isfinite(result.V)) and np.all(np.isfinite(result.t))
    expected = 0.2
    if motors.compliance > 0:
        ideal = Plant(ContactSet([0.0, 0.2, 0.4]), 1.0, damping=damping,
                      motors=Motors(compliance=motors.compliance), commands=commands)
        expected = float(simulate(ideal, t_end).V[-1])
    assert result.V[-1] == pytest.approx(expected, rel=1e-12, abs=0)


def _compliant_schedule_plant(seed: int, lag: float, compliance: float, damping: float) -> Plant:
    rng = np.random.default_rng(seed)
    commands = rng.uniform(-0.3, 0.3, (4, 6))
    forces = rng.uniform(0.2, 1.0, 6)
    schedule = PiecewiseConstant(np.sort(rng.uniform(0.1, 1.4, 3)), commands)
    return Plant(ContactSet(commands[0], forces), 0.5, damping=damping,
                 motors=Motors(lag=lag, compliance=compliance), commands=schedule)


@pytest.mark.parametrize("lag", [1e-30, 1e-100, 1e-200, 1e-300, 1e-305])
@pytest.mark.parametrize("compliance, damping", [(0.05, 0.0), (0.3, 0.4)])
def test_compliant_lag_tends_to_instantaneous_motors(lag, compliance, damping):
    # Regression: below lag ~ 1e-200 s the saturation events of the motors' transient were
    # placed far from their roots (the bisection only resolved ~1e-24 s of a 1.5 s bracket),
    # so runs ended off by a few percent or stalled on chatter. Second method: the same plant
    # with instantaneous motors (lag 0: the ideal-motor engine). A lag tau moves V by about
    # tau F_tot / m <= 1e-29 m/s, below rounding, so what is left is the two engines'
    # rounding over ~10-30 closed-form segments: rtol 1e-12 (the target; measured
    # <= 1e-14 for every lag and seed here), atol 1e-15 m/s for samples that pass near V = 0.
    # 1e-305 s is near the smallest lag Plant accepts for these scales (see the next test).
    times = np.linspace(0.0, 1.5, 16)
    for seed in (6, 7, 9, 10):
        runs = [simulate(_compliant_schedule_plant(seed, tau, compliance, damping), 1.5,
                         t_eval=times) for tau in (lag, 0.0)]
        assert all(run.status is SimulationStatus.SUCCESS for run in runs)
        np.testing.assert_allclose(runs[0].V, runs[1].V, rtol=1e-12, atol=1e-15)


def test_compliant_lag_too_small_for_doubles_is_refused():
    # 16 n 2 max|v| / (tau k) = 16 * 6 * 0.6 / (1e-307 * 0.05) ~ 1e310 overflows: these runs
    # once ended FAILED with NaN (inf - inf in the event functions); now Plant refuses them.
    with pytest.raises(ParameterError, match=r"motors.*lag tau with 16 n 2 max\|v\| / \(tau k\)"):
        _compliant_schedule_plant(6, 1e-307, 0.05, 0.0)
    _compliant_schedule_plant(6, 1e-307, 0.0, 0.0)   # without compliance nothing sums to it


@pytest.mark.parametrize("mu", [1.0, 1e3, 1e10, 1e100, 1e300])
@pytest.mark.parametrize("gamma", [0.0, 0.027])
def test_event_roots_are_located_at_every_motor_rate(mu, gamma):
    # g(s) = 0.1 + gamma expm1_ratio(20, s) - 0.2 mu expm1_ratio(mu, s): a saturation event
    # function with a body term (rate lam = 20 /s) and a motor term (rate mu = 1 / lag); its
    # root lies near ln 2 / mu, down to 7e-301 s, inside a 1.5 s horizon. Regression: with
    # mu = 1e300 the inflection overflowed and bisection by widths stopped near 1e-24 s.
    # References: gamma = 0, the closed form expm1_ratio(mu, s) = 1 / (2 mu), s = ln 2 / mu;
    # gamma > 0, a second method, brentq on the rescaled time x = mu s (a bracket [0, 50] on the root's scale).
    # rtol 16 eps: the root finder's "a few ulp" (brentq's rtol 4 eps) plus the rounding of g
    # near its root (|g| rounds at ~eps 0.1 where |g'| s ~ 0.1: a few eps of s).
    eps = float(np.finfo(float).eps)
    lam, delta = 20.0, -0.2 * mu
    fns = _EventFunctions(np.array([0.3, 0.1]), np.zeros(2), np.array([0.0, gamma]),
               np.array([0.0, delta]), lam, mu)      # function 0 never changes sign
    s, i = _first_root(fns, 1.5)
    if gamma == 0.0:
        expected = math.log(2.0) / mu
    else:
        def scaled(x: float) -> float:
            return 0.1 + gamma * _scalar_expm1_ratio(lam, x / mu) + (delta / mu) * -math.expm1(-x)

        expected = optimize.brentq(scaled, 0.0, 50.0, xtol=1e-300, rtol=4 * eps) / mu
        # The inflection is where the two terms of g'' balance (computed without overflow).
        infl = float(fns.inflection()[1])
        assert 0.0 < infl < 1.5
        # Both sides are ~ -0.6 after cancelling terms up to mu infl ~ 1400: 4 * 1400 eps.
        assert (math.log(gamma * lam) - lam * infl
                == pytest.approx(math.log(-delta) + math.log(mu) - mu * infl,
                                 rel=0, abs=4 * 1400 * eps))
    assert i == 1
    assert s == pytest.approx(expected, rel=16 * eps, abs=0)
