"""Closed forms of the ideal model's predictions, checked against the exact simulator."""

from __future__ import annotations

import math

import numpy as np
import pytest

from toolkit import ContactSet, ParameterError, Plant, simulate
from toolkit.predictions.theory import (ONE_MINUS_INV_E, least_squares_correction, resting_speed,
                                        staircase_correction, startup_correction, time_constant,
                                        transition_time, travel_time, uniform_staircase,
                                        viscosity_correction)

# The exact simulator and travel_time both sum closed-form segments: they agree to rounding
# (a few ulp per segment, <= 20 segments here): rtol 1e-12.
RTOL_EXACT = 1e-12


@pytest.mark.parametrize("n, center, spacing", [(10, 0.15, 0.03), (11, 0.12, 0.02), (7, -0.1, 0.05)])
def test_travel_time_equals_the_exact_simulation(n, center, spacing):
    contacts = uniform_staircase(n, center, spacing, 0.2)
    mass = 1.3
    stop = resting_speed(contacts, 0.0)
    target = ONE_MINUS_INV_E * stop
    run = simulate(Plant(contacts, mass), 3.0)
    # The body's speed is piecewise linear in time: read the crossing time off its events.
    t, V = run.t, run.V
    k = int(np.flatnonzero(np.sign(target) * (V - target) >= 0)[0])
    crossing = t[k - 1] + (target - V[k - 1]) * (t[k] - t[k - 1]) / (V[k] - V[k - 1])
    assert travel_time(contacts, mass, 0.0, target) == pytest.approx(crossing, rel=RTOL_EXACT)
    assert time_constant(contacts, mass, 0.0) == pytest.approx(crossing, rel=RTOL_EXACT)


def test_travel_time_is_infinite_where_the_body_stops_first():
    contacts = ContactSet([-0.35] * 5 + [0.35] * 5)            # zero-force band
    assert travel_time(contacts, 1.0, 0.0, 0.1) == math.inf
    assert travel_time(contacts, 1.0, 0.2, 0.2) == 0.0


def test_resting_speed_is_the_near_edge_of_the_band():
    contacts = ContactSet([-0.35] * 5 + [0.35] * 5)
    assert resting_speed(contacts, 0.1) == 0.1                  # inside the band: coasts
    assert resting_speed(contacts, -0.5) == -0.35
    assert resting_speed(contacts, 0.9) == 0.35


def test_uniform_staircase_has_the_commanded_slope():
    f, s = 0.2, 0.04
    contacts = uniform_staircase(9, 0.1, s, f)
    # Between neighbouring contacts the force drops by 2 f: slope 2 f / s on average.
    mids = contacts.speeds[:-1] + s / 2
    np.testing.assert_allclose(np.diff(contacts.force(mids)), -2 * f, rtol=0, atol=1e-15)


@pytest.mark.parametrize("u0", [20.5, 40.5, 80.5])
def test_correction_tends_to_one_deep_inside_the_spread(u0):
    # Odd n, start at mid-step u0 steps below the centre: the staircase force is the linear
    # law at each step's middle, so C is a midpoint rule for integral du/u = 1, whose error
    # is (1/24) sum h^3 f''/1 = (1/12) integral du/u^3 + O(u^-4) = (e^2 - 1)/(24 u0^2) + ...
    # (the 63.2 % point falls inside a step: one partial step adds at most 1/u1 = e/u0).
    n, s, f, m = 2 * int(u0) + 41, 0.01, 0.1, 2.0
    contacts = uniform_staircase(n, u0 * s, s, f)
    C = viscosity_correction(contacts, m, 0.0, 2 * f / s)
    assert abs(C - 1.0) <= (math.e ** 2 - 1) / (24 * u0 ** 2) + math.e / u0 ** 2


def test_correction_of_even_n_is_below_one():
    # Even n stops at the near edge of the zero band, half a step short of the centre,
    # while the plateaus push as the linear law about the centre: faster than exponential.
    contacts = uniform_staircase(10, 0.13, 0.04, 0.2)
    assert viscosity_correction(contacts, 1.0, 0.0, 2 * 0.2 / 0.04) < 1.0


@pytest.mark.parametrize("j", [1, 2, 3, 4, 5])
def test_transition_time_matches_the_exact_braking_run(j):
    v, f, m = 0.35, 0.2, 1.0
    contacts = ContactSet([v] * (5 - j) + [-v] * (5 + j), [f] * 10)
    run = simulate(Plant(contacts, m), 10.0, v0=v)
    arrival = run.t[np.flatnonzero(run.V <= -v)[0]]
    assert transition_time(m, v, 10 * f, j / 5) == pytest.approx(arrival, rel=RTOL_EXACT)
    assert transition_time(m, v, 10 * f, 0.0) == math.inf


def test_bad_inputs_name_the_parameter():
    with pytest.raises(ParameterError, match="'mass' parameter of travel_time"):
        travel_time(ContactSet([0.0]), -1.0, 0.0, 1.0)
    with pytest.raises(ParameterError, match="'fraction' parameter of transition_time"):
        transition_time(1.0, 0.35, 2.0, -0.1)
    with pytest.raises(ParameterError, match="'spacing' parameter of uniform_staircase"):
        uniform_staircase(3, 0.0, 0.0, 1.0)


# -- the closed-form correction of n equal steps --------------------------------------------
@pytest.mark.parametrize("n", [1, 2, 3, 4, 9, 10, 11, 30])
def test_staircase_correction_equals_the_travel_time_route(n):
    # Two methods: the closed form over plateaus, and the exact travel time on a ContactSet
    # (any spacing, magnitude and mass, since C depends on n and x0 only). Sums of <= n
    # plateau terms: rounding ~1e-15 each, rtol 1e-12.
    starts = np.array([-30.0, -(n + 1) / 2.0, -(n - 1) / 2.0 - 0.3, -2.2, -1.7, -0.9, -0.6, -0.2,
                       0.35, 0.8, 2.6, (n - 1) / 2.0 + 0.5, 12.0])
    spacing, center, f, m = 0.037, -0.11, 0.3, 2.5
    contacts = uniform_staircase(n, center, spacing, f)
    closed = staircase_correction(n, starts)
    for x0, C in zip(starts, closed):
        exact = viscosity_correction(contacts, m, center + x0 * spacing, 2 * f / spacing)
        if math.isnan(exact):
            assert math.isnan(C)
        else:
            assert C == pytest.approx(exact, rel=RTOL_EXACT)


def test_staircase_correction_where_the_motion_is_linear():
    # One contact (odd): the force is f all the way to the stop at 0, so the 63.2 % time is
    # (1 - 1/e)|x0| s m / f and C = 2 (1 - 1/e)|x0|. Two contacts from below both (even): force
    # 2 f up to the near band edge -1/2: C = 2 (1 - 1/e)(|x0| - 1/2) / 2. Exact up to rounding.
    assert staircase_correction(1, -0.3) == pytest.approx(2 * ONE_MINUS_INV_E * 0.3, rel=1e-15)
    assert staircase_correction(1, 4.0) == pytest.approx(2 * ONE_MINUS_INV_E * 4.0, rel=1e-15)
    assert staircase_correction(2, -2.0) == pytest.approx(ONE_MINUS_INV_E * 1.5, rel=1e-15)
    # At rest already: no startup to measure.
    assert math.isnan(staircase_correction(3, 0.0))
    assert math.isnan(staircase_correction(10, 0.5))


@pytest.mark.parametrize("n, u0", [(60, 20.5), (100, 40.0), (100, 40.5), (200, 80.5)])
def test_even_correction_tends_to_its_closed_limit(n, u0):
    # Even n stops at the band edge -1/2, so the linear law sampled at the plateau midpoints
    # gives C -> integral from u* to u0 of du/u with u* = u0/e + (1 - 1/e)/2, i.e.
    # 1 - ln(1 + (e - 1)/(2 u0)); the midpoint-rule error is bounded as for odd n (above):
    # (e^2 - 1)/(24 u0^2) + e/u0^2.
    limit = 1.0 - math.log(1.0 + (math.e - 1.0) / (2.0 * u0))
    C = staircase_correction(n, -u0)
    assert abs(C - limit) <= (math.e ** 2 - 1) / (24 * u0 ** 2) + math.e / u0 ** 2
    assert C == pytest.approx(staircase_correction(n, u0), rel=0, abs=0)   # symmetric


def test_staircase_correction_refuses_bad_input():
    with pytest.raises(ParameterError, match="'n' parameter of staircase_correction"):
        staircase_correction(0, -1.0)
    with pytest.raises(ParameterError, match="'start' parameter of staircase_correction"):
        staircase_correction(10, math.nan)


# -- the least-squares correction: a fit of the exact ideal trajectory ----------------------------
def _staircase_path(n: int, x0: float, t: np.ndarray) -> np.ndarray:
    """The ideal startup of n equal contacts (spacing, mass, slope 1) from x0 < 0, built from
    its plateaus by hand (dx/dt = (n - 2 j) / 2 with j contacts below), not by the simulator."""
    p = np.arange(1, n + 1) - (n + 1) / 2.0
    stop = -(0.0 if n % 2 else 0.5)
    xs, ts = [x0], [0.0]
    while xs[-1] < stop:
        j = int(np.sum(p <= xs[-1]))
        nxt = min([q for q in p if q > xs[-1]] + [stop])
        ts.append(ts[-1] + (nxt - xs[-1]) / ((n - 2 * j) / 2.0))
        xs.append(nxt)
    return np.interp(t, ts, xs)


@pytest.mark.parametrize("n, x0, window", [(10, -4.3, 6.0), (20, -9.0, 6.0), (7, -2.6, 5.0), (1, -0.8, 4.0),
                                           (100, -49.2, 8.0)])
def test_least_squares_correction_equals_a_second_fit(n, x0, window):
    # Second method: the trajectory built by hand from its plateaus on 20001 samples, fitted
    # by scipy's curve_fit (Levenberg-Marquardt) instead of the toolkit's grid-and-Brent on the
    # simulator's 1001 samples. The two sampled sums differ by the quadrature of a piecewise
    # linear path (measured < 1e-6 relative): rtol 1e-5.
    from scipy.optimize import curve_fit

    t = np.linspace(0.0, window, 20001)
    x = _staircase_path(n, x0, t)
    end = x[-1]
    (tau,), _ = curve_fit(lambda t, tau: end + (x0 - end) * np.exp(-t / tau), t, x, p0=[0.8],
                          xtol=1e-14, ftol=1e-14)
    C = least_squares_correction(n, x0, window)
    assert C == pytest.approx(tau, rel=1e-5)
    # Symmetric: the mirrored start's exact trajectory is the mirror image (rounding: 1e-12).
    assert least_squares_correction(n, -x0, window) == pytest.approx(C, rel=1e-12)


def test_least_squares_correction_barely_depends_on_the_window():
    # Holding both ends fixed makes the fit nearly blind to the settled samples after the stop
    # (their residual decays as exp(-2 t / tau)): a start in the lowest spacing of ten
    # contacts, windows of 1 and 3 time constants past the stop (2.08): 0.7820 and 0.7796,
    # within 0.5 % of each other (measured 0.3 %).
    a, b = least_squares_correction(10, np.array([-4.5, -4.5]), np.array([3.08, 5.08]))
    assert abs(a / b - 1) <= 5e-3
    # Deep inside a long staircase both definitions go to the viscous law (odd n: C -> 1);
    # the fit's error is of the order of the crossing's, (e^2 - 1) / (24 u0^2) + e / u0^2 at
    # u0 = 500: 1.1e-5; measured 1.8e-5: atol 1e-4.
    assert least_squares_correction(1001, -500.0, 12.0) == pytest.approx(1.0, rel=0, abs=1e-4)


def test_least_squares_differs_from_the_crossing_rule():
    # Ten contacts, starts in the lowest spacing (x0 = -4.5 .. -3.5), a window past the stop:
    # the fitted exponential is several percent faster than the 63.2 % crossing reads
    # (C 0.735-0.780 against 0.782-0.848), so k = 1 / C is 6-9 % higher.
    starts = np.array([-4.5, -4.0, -3.5])
    ls = startup_correction("least_squares", 10, starts, 5.0)
    cross = startup_correction("crossing_63", 10, starts)
    np.testing.assert_allclose(cross, staircase_correction(10, starts), rtol=0, atol=0)
    assert np.all((cross / ls - 1 >= 0.05) & (cross / ls - 1 <= 0.10)), cross / ls
    assert math.isnan(least_squares_correction(10, 0.3, 2.0))          # at rest in the band
    with pytest.raises(ParameterError, match="'window' parameter of startup_correction"):
        startup_correction("least_squares", 10, -4.0)
    with pytest.raises(ParameterError, match="'window' parameter of least_squares_correction"):
        least_squares_correction(10, -4.0, 0.0)
    with pytest.raises(ParameterError, match="'definition' parameter of startup_correction"):
        startup_correction("crossing", 10, -4.0)


def test_holding_the_final_value_is_what_makes_the_fit_window_blind():
    # docs/physics.md section 6 and the README quote, for a start at the lowest of ten contacts
    # (x0 = -4.5, stop after 2.083 time constants), one and three time constants of record after
    # the stop: C = 0.782 and 0.780 with both ends held (least_squares_correction), 0.930 and
    # 0.829 with the final value free (a second fit, scipy's curve_fit, on the trajectory built
    # by hand). Printed to three digits: atol 5e-4.
    from scipy.optimize import curve_fit

    stop = 2.083                        # s in units of m / k: the travel time to the band edge
    held, free = [], []
    for extra in (1.0, 3.0):
        window = stop + extra
        held.append(least_squares_correction(10, -4.5, window))
        t = np.linspace(0.0, window, 20001)
        x = _staircase_path(10, -4.5, t)
        (tau, _), _ = curve_fit(lambda t, tau, end: end + (-4.5 - end) * np.exp(-t / tau), t, x,
                                p0=[0.8, x[-1]], xtol=1e-14, ftol=1e-14)
        free.append(tau)
    assert stop == pytest.approx(travel_time(uniform_staircase(10, 0.0, 1.0, 0.5), 1.0, -4.5, -0.5), abs=5e-4)
    np.testing.assert_allclose(held, [0.782, 0.780], rtol=0, atol=5e-4)
    np.testing.assert_allclose(free, [0.930, 0.829], rtol=0, atol=5e-4)
