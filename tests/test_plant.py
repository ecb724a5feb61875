"""Tests of toolkit.model: validation, signals and the force helpers shared by every method."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from toolkit.model import ContactSet
from toolkit.errors import ParameterError, ParameterTypeError
from toolkit.model import STRIBECK_PEAK, Motors, PiecewiseConstant, Plant, compliant_breakpoints


# -- PiecewiseConstant ----------------------------------------------------------------------
def test_piecewise_scalar_values_and_right_continuity():
    u = PiecewiseConstant([1.0, 2.0], [0.0, 3.0, -1.0])
    assert u(0.5) == 0.0 and u(1.0) == 3.0 and u(1.999) == 3.0 and u(2.0) == -1.0
    np.testing.assert_array_equal(u(np.array([-5.0, 1.0, 7.0])), [0.0, 3.0, -1.0])
    assert u.width is None


def test_piecewise_vector_and_breakpoints():
    u = PiecewiseConstant([0.5, 1.5, 2.5], [[0, 0], [1, 2], [3, 4], [5, 6]])
    assert u.width == 2
    np.testing.assert_array_equal(u(1.5), [3.0, 4.0])
    np.testing.assert_array_equal(u.breakpoints_in(0.5, 2.5), [1.5, 2.5])   # (t0, t1]
    np.testing.assert_array_equal(u.breakpoints_in(0.0, 0.4), [])
    assert u.next_switch(0.5) == 1.5 and u.next_switch(3.0) == float("inf")


def test_piecewise_constant_without_switches():
    u = PiecewiseConstant([], [2.5])
    assert u(-1e9) == 2.5 and u(1e9) == 2.5


@pytest.mark.parametrize("times, values, error, name, rule", [
    ([1.0, 1.0], [0, 1, 2], ParameterError, "times", "be strictly increasing. Got [1.0, 1.0] instead."),
    ([2.0, 1.0, 3.0], [0, 1, 2, 3], ParameterError, "times", "be strictly increasing. Got [2.0, 1.0, 3.0] instead."),
    ([1.0, np.inf], [0, 1, 2], ParameterError, "times", "be finite (no NaN or inf). Got inf instead."),
    ([1.0], [0, 1, 2], ParameterError, "values",
     "have one more row than 'times' (2). Got 'an array of shape (3,)' instead."),
    ([1.0], [[0, 1], [2, 3], [4, 5]], ParameterError, "values",
     "have one more row than 'times' (2). Got 'an array of shape (3, 2)' instead."),
    ([1.0], [[[0.0]], [[1.0]]], ParameterError, "values",
     "be 2-dimensional. Got 'an array of shape (2, 1, 1)' instead."),
    ([1.0], [0, np.nan], ParameterError, "values", "be finite (no NaN or inf). Got nan instead."),
    ([1.0], "ab", ParameterTypeError, "values", "be an array of numbers. Got 'ab' instead."),
    # Ragged rows: refused by the toolkit's template, not by numpy's conversion error.
    ([1.0], [[0, 1], [2]], ParameterError, "values",
     "be a rectangular array (nested sequences of equal lengths). Got [[0, 1], [2]] instead."),
    ([1.0], [0.5, [1, 2]], ParameterError, "values",
     "be a rectangular array (nested sequences of equal lengths). Got [0.5, [1, 2]] instead."),
    ([[1.0], 2.0], [0, 1, 2], ParameterError, "times",
     "be a rectangular array (nested sequences of equal lengths). Got [[1.0], 2.0] instead."),
])
def test_piecewise_refuses_bad_input(times, values, error, name, rule):
    """Each refusal names the parameter, the owner, the rule and the value, whole (mutants:
    any of the four changed or dropped, the row count ``k + 1`` off by one)."""
    message = f"The '{name}' parameter of PiecewiseConstant must {rule}"
    with pytest.raises(error, match="^" + re.escape(message) + "$"):
        PiecewiseConstant(times, values)


def test_sample_count_and_times_on_a_rounded_duration():
    """``floor(T f) + 1`` samples, a product within 1e-9 below a whole number counted as it:
    0.29 s at 100 Hz (0.29 * 100 = 28.999999999999996) is 30 samples, 10 s at 50 Hz is 501,
    0.2899999 s at 100 Hz (relative 3e-7 below) is 29; the instants are ``k / f`` exactly.
    Mutants killed: ``+ 1`` off by one, ``1 + 1e-9`` to ``1 - 1e-9`` or ``2 + 1e-9``,
    ``rate`` divided instead of multiplied, ``k / f`` to ``k f``."""
    from toolkit.model import sample_count, sample_times

    assert 0.29 * 100 < 29.0
    assert (sample_count(0.29, 100.0), sample_count(10.0, 50.0), sample_count(0.2899999, 100.0)) == (30, 501, 29)
    assert sample_count(0.0, 50.0) == 1
    np.testing.assert_array_equal(sample_times(0.29, 100.0), np.arange(30) / 100.0)
    np.testing.assert_array_equal(sample_times(0.1, 50.0), [0.0, 0.02, 0.04, 0.06, 0.08, 0.1])


def test_piecewise_arrays_are_read_only():
    u = PiecewiseConstant([1.0], [0.0, 1.0])
    with pytest.raises(ValueError):
        u.values[0] = 5.0


# -- Motors ---------------------------------------------------------------------------------
@pytest.mark.parametrize("kwargs", [
    {"lag": -0.1}, {"rate_limit": 0.0}, {"compliance": -1.0},
    {"speed_limits": (1.0, -1.0)}, {"speed_limits": (np.inf, np.inf)}, {"lag": np.nan},
])
def test_motors_refuse_bad_values(kwargs):
    with pytest.raises(ParameterError):
        Motors(**kwargs)


def test_motors_refuse_bad_types():
    with pytest.raises(ParameterTypeError):
        Motors(speed_limits=0.3)
    with pytest.raises(ParameterTypeError):
        Motors(lag="fast")


def test_motors_dynamic_flag():
    assert not Motors().dynamic and not Motors(compliance=0.1).dynamic
    assert Motors(lag=0.03).dynamic and Motors(rate_limit=10.0).dynamic


# -- Plant validation -----------------------------------------------------------------------
def test_plant_refuses_bad_input():
    cs = ContactSet([0.0, 1.0])
    with pytest.raises(ParameterTypeError):
        Plant([0.0, 1.0], 1.0)
    with pytest.raises(ParameterError):
        Plant(cs, 0.0)
    with pytest.raises(ParameterError):
        Plant(cs, 1.0, damping=-1.0)
    with pytest.raises(ParameterTypeError):
        Plant(cs, 1.0, motors="ideal")
    with pytest.raises(ParameterError, match="one column per contact"):
        Plant(cs, 1.0, commands=PiecewiseConstant([1.0], [[0, 1, 2], [0, 1, 2]]))
    with pytest.raises(ParameterError, match="scalar signal"):
        Plant(cs, 1.0, external_force=PiecewiseConstant([1.0], [[0, 1], [0, 1]]))
    with pytest.raises(ParameterTypeError):
        Plant(cs, 1.0, commands=[[0, 1]])


def test_command_clipping_and_schedule():
    cs = ContactSet([-0.5, 0.1, 0.5])
    plant = Plant(cs, 1.0, motors=Motors(speed_limits=(-0.35, 0.35)),
                  commands=PiecewiseConstant([1.0], [[-0.5, 0.1, 0.5], [0.2, 0.9, -0.9]]))
    np.testing.assert_array_equal(plant.command(0.0), [-0.35, 0.1, 0.35])
    np.testing.assert_array_equal(plant.command(1.0), [0.2, 0.35, -0.35])
    np.testing.assert_array_equal(plant.final_command(), [0.2, 0.35, -0.35])
    np.testing.assert_array_equal(plant.initial_speeds(), [-0.35, 0.1, 0.35])
    np.testing.assert_array_equal(Plant(cs, 1.0).command(3.0), cs.speeds)


def test_switching_times_union():
    cs = ContactSet([0.0, 1.0])
    plant = Plant(cs, 1.0, external_force=PiecewiseConstant([0.5, 2.0], [0, 1, 0]),
                  commands=PiecewiseConstant([1.0, 2.0], [[0, 1]] * 3))
    np.testing.assert_array_equal(plant.switching_times(), [0.5, 1.0, 2.0])
    assert plant.external(0.7) == 1.0 and Plant(cs, 1.0, external_force=2).external(9.0) == 2.0


# -- motor_rate -----------------------------------------------------------------------------
def test_motor_rate_lag_rate_limit_and_ideal():
    cs = ContactSet([1.0, -1.0, 0.0])
    v = np.array([0.0, 0.0, 0.0])
    # Ideal motors: speeds are the commands, no dynamics.
    np.testing.assert_array_equal(Plant(cs, 1.0).motor_rate(0.0, v), [0, 0, 0])
    # Lag tau = 0.5: (u - v)/tau exactly (binary fractions, so exact).
    lagged = Plant(cs, 1.0, motors=Motors(lag=0.5))
    np.testing.assert_array_equal(lagged.motor_rate(0.0, v), [2.0, -2.0, 0.0])
    # Lag with a rate limit: clipped to +-1.5.
    both = Plant(cs, 1.0, motors=Motors(lag=0.5, rate_limit=1.5))
    np.testing.assert_array_equal(both.motor_rate(0.0, v), [1.5, -1.5, 0.0])
    # Pure rate limit: ramps at the limit toward the command, 0 once there.
    ramp = Plant(cs, 1.0, motors=Motors(rate_limit=3.0))
    np.testing.assert_array_equal(ramp.motor_rate(0.0, v), [3.0, -3.0, 0.0])


@pytest.mark.parametrize("lag", [1e-3, 7.5e-3, 0.5, 20.0])
def test_lag_memory_and_settling_time_are_the_motor_law_solved(lag):
    # The share of the start speed left is unsaturated_response's slope in v0 (the law is
    # affine in v0: the difference of two responses, exact to rounding, rtol 1e-12 for the
    # difference's cancellation); its integral is the response's area against a trapezoid
    # rule on 20001 points (error h^2/12 max|v''| s: rtol 1e-8 at these grids).
    from toolkit.model import lag_memory, lag_settling_time, unsaturated_response

    s = np.linspace(0.0, 5.0 * lag, 20001)
    start, command = np.array([0.3]), np.array([-0.2])
    response = unsaturated_response(start, command, s[:, None], lag, np.inf)[:, 0]
    shares = np.array([lag_memory(t, lag)[0] for t in s])
    np.testing.assert_allclose(shares * (start[0] - command[0]) + command[0], response, rtol=1e-12, atol=1e-15)
    area = np.concatenate(([0.0], np.cumsum(0.5 * (shares[1:] + shares[:-1]) * np.diff(s))))
    np.testing.assert_allclose([lag_memory(t, lag)[1] for t in s[::1000]], area[::1000], rtol=1e-8, atol=1e-15 * lag)
    # Settling: the remaining travel gap * (the share's integral from s to inf) = travel.
    gap, travel = 0.5, 1e-3 * lag
    t = lag_settling_time(gap, lag, travel)
    np.testing.assert_allclose(gap * (lag - lag_memory(t, lag)[1]), travel, rtol=1e-12)
    assert lag_settling_time(gap, lag, 2.0 * gap * lag) == 0.0    # already closer than that


# -- contact forces -------------------------------------------------------------------------
def test_contact_forces_sign_with_tie_convention():
    cs = ContactSet([-1.0, 0.0, 2.0], [0.5, 1.0, 2.0])
    plant = Plant(cs, 1.0)
    np.testing.assert_array_equal(plant.contact_forces(0.0, cs.speeds), [-0.5, 0.0, 2.0])
    # Identity: the summed Coulomb forces equal ContactSet.force (same sign(0) = 0 convention).
    for V in (-2.0, -1.0, -0.3, 0.0, 1.0, 2.0, 3.0):
        assert np.sum(plant.contact_forces(V, cs.speeds)) == pytest.approx(
            float(cs.force(V)), rel=0, abs=1e-15)   # exact sums of binary fractions


def test_contact_forces_smoothed_laws():
    cs = ContactSet([0.0, 1.0], [1.0, 2.0])
    plant = Plant(cs, 1.0)
    eps = 1e-2
    V = 0.995
    expected = np.array([1.0 * np.tanh(-V / eps), 2.0 * np.tanh((1 - V) / eps)])
    np.testing.assert_allclose(plant.contact_forces(V, cs.speeds, friction="tanh", epsilon=eps),
                               expected, rtol=1e-15, atol=0)   # same formula, rounding only
    stribeck = plant.contact_forces(V, cs.speeds, friction="stribeck", epsilon=eps)
    # Far from the tie the hump has decayed (exp(-(0.995/0.03)^2) ~ 1e-478): Coulomb level.
    assert stribeck[0] == pytest.approx(-1.0, rel=1e-15, abs=0)
    # Near the tie the hump is above tanh, below the peak ratio.
    assert abs(expected[1]) < abs(stribeck[1]) < STRIBECK_PEAK * 2.0
    with pytest.raises(ParameterError):
        plant.contact_forces(V, cs.speeds, friction="tanh", epsilon=0.0)
    with pytest.raises(ParameterError, match="Did you mean 'tanh'"):
        plant.contact_forces(V, cs.speeds, friction="tahn", epsilon=eps)


def test_contact_forces_compliance_is_saturated_linear():
    cs = ContactSet([0.0, 1.0, 3.0], [1.0, 2.0, 0.0])
    plant = Plant(cs, 1.0, motors=Motors(compliance=0.25))
    # V = -0.25: contact 0 has slip 0.25 = k f -> 1 * clip(1) = 1; contact 1 slip 1.25 > k f
    # = 0.5 saturates at 2; the lifted contact (f = 0) gives 0.
    np.testing.assert_array_equal(plant.contact_forces(-0.25, cs.speeds), [1.0, 2.0, 0.0])
    # V = 0.75: contact 0 slip -0.75 saturates at -1; contact 1 slip 0.25 -> 2 * 0.25/0.5 = 1.
    np.testing.assert_array_equal(plant.contact_forces(0.75, cs.speeds), [-1.0, 1.0, 0.0])


def test_net_force_adds_external_and_drag():
    cs = ContactSet([1.0, 2.0])
    plant = Plant(cs, 1.0, damping=0.5, external_force=PiecewiseConstant([1.0], [0.0, 4.0]))
    assert plant.net_force(0.0, 0.0, cs.speeds) == 2.0
    assert plant.net_force(1.0, 1.5, cs.speeds) == 0.0 + 4.0 - 0.75


# -- equilibrium ----------------------------------------------------------------------------
def test_equilibrium_uses_final_command():
    cs = ContactSet([0.0, 1.0, 2.0])
    plant = Plant(cs, 1.0, commands=PiecewiseConstant([1.0], [[0, 1, 2], [5, 6, 7]]))
    assert plant.equilibrium() == (6.0, 6.0)
    assert Plant(ContactSet([0, 1, 2, 3]), 1.0).equilibrium() == (1.0, 2.0)


def test_compliant_equilibrium_closed_forms():
    # Odd, well separated: the median contact balances, point at the median.
    assert Plant(ContactSet([0, 1, 2]), 1.0, motors=Motors(compliance=0.1)).equilibrium() == \
        pytest.approx((1.0, 1.0), rel=0, abs=1e-15)
    # Even: zero band shrinks by k f at each side: [1 + 0.1, 2 - 0.1].
    lo, hi = Plant(ContactSet([0, 1, 2, 3]), 1.0, motors=Motors(compliance=0.1)).equilibrium()
    assert (lo, hi) == pytest.approx((1.1, 1.9), rel=1e-14, abs=0)   # rounding of v +- k f
    # Two contacts at 0 and 1 with f = (1, 3), k = 1: lines 1 - V ... solve
    # clip(-V/1) * 1 + 3 clip((1 - V)/3): for V in [0, 1]: -V + (1 - V) = 0 -> V = 1/2.
    lo, hi = Plant(ContactSet([0, 1], [1, 3]), 1.0, motors=Motors(compliance=1.0)).equilibrium()
    assert lo == hi == pytest.approx(0.5, rel=1e-15, abs=0)


@settings(deadline=None, max_examples=40)
@given(st.lists(st.floats(-1, 1), min_size=1, max_size=9),
       st.floats(1e-3, 1.0))
def test_compliant_equilibrium_is_a_zero_of_the_force(speeds, k):
    cs = ContactSet(speeds)
    plant = Plant(cs, 1.0, motors=Motors(compliance=k))
    lo, hi = plant.equilibrium()
    for V in (lo, hi):
        # Zero to the rounding of a sum of n slopes of size 1/k over spans <= 2 + 2 k n.
        assert abs(np.sum(plant.contact_forces(V, cs.speeds))) <= 1e-12 * cs.n * (1 + 1 / k)


def test_plant_refuses_rates_that_overflow():
    # (F_tot + max|F_ext|) / m = (1 + 1e300) / 1e-300 = 1e600 > 1.8e308: not a double.
    with pytest.raises(ParameterError, match="'mass' parameter of Plant"):
        Plant(ContactSet([0.1]), mass=1e-300, external_force=1e300)
    with pytest.raises(ParameterError, match="'mass' parameter of Plant"):
        Plant(ContactSet([0.1]), mass=1e-300,
              external_force=PiecewiseConstant([1.0], [0.0, -1e300]))
    # c / m = 1e10 / 1e-300 = 1e310 overflows.
    with pytest.raises(ParameterError, match="'damping' parameter of Plant"):
        Plant(ContactSet([0.1]), mass=1e-300, damping=1e10)
    # Just inside: (1 + 1e300) / 1e-8 = 1e308 and 1e8 / 1e-300 = 1e308 are finite.
    Plant(ContactSet([0.1]), mass=1e-8, external_force=1e300)
    Plant(ContactSet([0.1]), mass=1e-300, damping=1e8)
    # 1 / lag must be finite: 1 / 5e-324 (the smallest subnormal) overflows, 1 / 1e-300 not.
    with pytest.raises(ParameterError, match="'lag' parameter of Motors"):
        Motors(lag=5e-324)
    assert Motors(lag=1e-300).lag == 1e-300


def test_plant_refuses_compliance_below_the_speeds_rounding():
    # k f = 1e-17 N (m/s)/N is below 4 eps max|v| = 4 * 2.2e-16 * 0.7 = 6.2e-16 m/s: the
    # linear band is lost in the rounding of the speeds (it used to give ZENO at 0.7 in the
    # exact method and an IndexError in equilibrium()).
    with pytest.raises(ParameterError, match="compliance=0"):
        Plant(ContactSet([0.3, 0.5, 0.7]), 1.0, motors=Motors(compliance=1e-17))
    # Commands count too: their largest |v| sets the rounding.
    with pytest.raises(ParameterError, match="'motors' parameter of Plant"):
        Plant(ContactSet([0.0, 0.0]), 1.0, motors=Motors(compliance=1e-16),
              commands=PiecewiseConstant([1.0], [[0.0, 0.0], [7.0, 7.0]]))
    # 1 / (k f) must be finite even when every speed is 0: 1 / 1e-310 overflows.
    with pytest.raises(ParameterError, match="'motors' parameter of Plant"):
        Plant(ContactSet([0.0, 0.0]), 1.0, motors=Motors(compliance=1e-310))
    # Just above the rounding, the equilibrium is the closed form: the median 0.5 (odd N).
    plant = Plant(ContactSet([0.3, 0.5, 0.7]), 1.0, motors=Motors(compliance=1e-15))
    assert plant.equilibrium() == pytest.approx((0.5, 0.5), rel=0, abs=4e-15)   # +- k f


@settings(deadline=None, max_examples=40)
@given(st.lists(st.floats(-1, 1), min_size=1, max_size=9), st.floats(1e-3, 1.0))
def test_compliant_breakpoints_are_the_force_law(speeds, k):
    # One implementation serves Plant.equilibrium and the exact method's landscape; check it
    # against the second method, the direct sum of the saturated linear contact forces.
    cs = ContactSet(speeds, np.linspace(0.5, 1.5, len(speeds)))
    plant = Plant(cs, 1.0, motors=Motors(compliance=k))
    x, at_x, first, slope, total = compliant_breakpoints(cs.speeds, cs.forces, k)
    assert np.all(np.diff(x) > 0) and total == pytest.approx(cs.total_force, rel=1e-15)
    direct = np.array([np.sum(plant.contact_forces(V, cs.speeds)) for V in x])
    # Rounding of a running sum of n slopes (<= 1/k each) over spans <= 2 + 2 k n.
    np.testing.assert_allclose(at_x, direct, rtol=0, atol=1e-12 * cs.n * (1 + 1 / k))
    # Each limit belongs to a contact: x = v_first +- k f_first up to rounding of v +- k f.
    gap = np.abs(np.abs(x - cs.speeds[first]) - k * cs.forces[first])
    assert np.all(gap <= 4e-16 * (1 + np.abs(x)))
    # Slopes are running sums of up to 2n increments of size 1/k: a flat stretch may come out
    # as a few rounding errors, at most 4 n eps (n / k), instead of exactly 0.
    assert slope[0] == slope[-1] == 0.0
    assert np.all(slope <= 4 * cs.n * np.finfo(float).eps * cs.n / k)


# -- the laws at their defining points, at several scales, and on both back ends ---------------
#: Force scales of the law tests (powers of two: exact), and unequal magnitudes.
SCALES = [2.0 ** -20, 1.0, 2.0 ** 20]
EPS = np.finfo(float).eps


@pytest.mark.parametrize("scale", SCALES)
@pytest.mark.parametrize("epsilon", [2.0 ** -10, 0.05])
def test_stribeck_law_at_its_defining_points(scale, epsilon):
    """The Stribeck law over the tanh law is ``1 + (P - 1) exp(-(s / (S eps))^2)`` with
    ``P = 1.5`` and ``S = 3`` (the documented constants): ``P`` as the slip tends to 0 (at
    ``s = 1e-6 eps`` the hump is ``exp(-1e-12 / 9)``), ``1 + (P - 1)/e`` at ``s = S eps``, 1 far away;
    rtol a few eps (one tanh, one exp; tanh cancels in the ratio). Unequal magnitudes at
    several scales. Mutants killed: the peak ``P - 1`` to ``P`` or ``P + 1``, ``S eps`` to
    ``S / eps`` or ``eps``, the square dropped, the hump's sign."""
    from toolkit.model.friction import STRIBECK_SPEED, contact_forces

    assert (STRIBECK_PEAK, STRIBECK_SPEED) == (1.5, 3.0)
    f = np.array([1.0, 3.0, 0.5]) * scale
    for slip, ratio in ((1e-6 * epsilon, 1.0 + 0.5 * np.exp(-1e-12 / 9)), (3.0 * epsilon, 1.0 + 0.5 / np.e),
                        (-3.0 * epsilon, 1.0 + 0.5 / np.e), (40.0 * epsilon, 1.0)):
        s = np.full(3, slip)
        stribeck = contact_forces(s, f, law="stribeck", epsilon=epsilon)
        tanh = contact_forces(s, f, law="tanh", epsilon=epsilon)
        np.testing.assert_allclose(tanh, f * np.tanh(slip / epsilon), rtol=2 * EPS, atol=0.0)
        np.testing.assert_allclose(stribeck / tanh, ratio, rtol=8 * EPS, atol=0.0)


@pytest.mark.parametrize("law, options", [("sign", {}), ("tanh", {"epsilon": 0.01}),
                                          ("stribeck", {"epsilon": 0.01}), ("sign", {"compliance": 0.25})])
def test_contact_forces_are_one_law_on_numpy_and_casadi(law, options):
    """The same law evaluated by numpy and built symbolically by casadi (then evaluated)
    agree to rounding (a few eps of the forces) for slips on both sides of every kink, with
    unequal magnitudes and a lifted contact. Mutants killed: any operation of
    :class:`toolkit.model._xp.ArrayOps` swapped on one back end (built anew here, not the
    cached instance)."""
    import casadi

    from toolkit.model._xp import ArrayOps
    from toolkit.model.friction import contact_forces

    f = np.array([1.0, 3.0, 0.5, 0.0, 2.0])
    for slip in (np.array([-0.5, -0.01, 0.0, 0.2, 0.003]), np.array([0.6, 0.02, -0.004, -1.0, 0.5])):
        numeric = contact_forces(slip, f, law=law, **options)
        s = casadi.SX.sym("s", f.size)
        built = contact_forces(s, f, law=law, xp=casadi, **options)
        symbolic = np.array(casadi.Function("phi", [s], [built])(slip)).ravel()
        np.testing.assert_allclose(symbolic, numeric, rtol=4 * EPS, atol=4 * EPS)
    for module in (np, casadi):
        o = ArrayOps(module)
        assert o.module is module and o.symbolic is (module is casadi)
        x, y = np.array([-2.0, 0.5, 3.0]), np.array([1.0, -1.0, 4.0])
        for name, expected in (("tanh", np.tanh(x)), ("exp", np.exp(x)), ("sign", np.sign(x))):
            np.testing.assert_allclose(np.array(casadi.DM(getattr(o, name)(o.const(x)))).ravel(), expected,
                                       rtol=2 * EPS, atol=0.0)
        for name, expected in (("fmin", np.minimum(x, y)), ("fmax", np.maximum(x, y))):
            np.testing.assert_array_equal(np.array(casadi.DM(getattr(o, name)(o.const(x), o.const(y)))).ravel(),
                                          expected)
        assert float(o.sum(o.const(x))) == 1.5
        np.testing.assert_array_equal(np.array(casadi.DM(o.concat(7.0, o.const(x)))).ravel(), [7.0, *x])


def test_motor_law_per_contact_with_some_saturated():
    """The motor law acts per contact: with lag 0.5 s and rate limit 1.5 m/s^2, gaps
    ``u - v`` of (1, -1, 0.25, -0.5, 0) m/s pull at (2, -2, 0.5, -1, 0) and are clipped to
    (1.5, -1.5, 0.5, -1, 0) (dyadic: exact). ``unsaturated_response`` after ``s``: with a lag,
    ``u + (v0 - u) exp(-s/tau)`` (``v0`` at 0, a share 1/e left at ``tau``); with only the rate
    limit, ``v0 + clip(u - v0, -r s, r s)`` per contact; ideal, ``u``. Mutants killed: the
    ramp's upper bound ``r s`` to ``r``, the lag's clip to ``min(pull, pull)``."""
    from toolkit.model import motor_rate, unsaturated_response

    u = np.array([1.0, -1.0, 0.25, -0.5, 0.125])
    v = np.array([0.0, 0.0, 0.0, 0.0, 0.125])
    np.testing.assert_array_equal(motor_rate(Motors(lag=0.5, rate_limit=1.5), u, v), [1.5, -1.5, 0.5, -1.0, 0.0])
    np.testing.assert_array_equal(motor_rate(Motors(lag=0.25), u, v), [4.0, -4.0, 1.0, -2.0, 0.0])
    np.testing.assert_array_equal(motor_rate(Motors(rate_limit=3.0), u, v), [3.0, -3.0, 3.0, -3.0, 0.0])
    np.testing.assert_array_equal(motor_rate(None, u, v), np.zeros(5))
    tau = 0.25
    np.testing.assert_array_equal(unsaturated_response(v, u, 0.0, tau, np.inf), v)
    np.testing.assert_allclose(unsaturated_response(v, u, tau, tau, np.inf), u + (v - u) / np.e,
                               rtol=4 * np.finfo(float).eps, atol=1e-300)
    # Rate limit 2 m/s^2 for 0.25 s: at most 0.5 m/s of travel each way.
    np.testing.assert_array_equal(unsaturated_response(v, u, 0.25, 0.0, 2.0), [0.5, -0.5, 0.25, -0.5, 0.125])
    np.testing.assert_array_equal(unsaturated_response(v, u, 0.25, 0.0, np.inf), u)


_CS = ContactSet([0.0, 1.0])


@pytest.mark.parametrize(("call", "error", "message"), [
    (lambda: Motors(lag=-0.1), ParameterError,
     "The 'lag' parameter of Motors must be >= 0. Got -0.1 instead."),
    (lambda: Motors(rate_limit=0.0), ParameterError,
     "The 'rate_limit' parameter of Motors must be > 0. Got 0.0 instead."),
    (lambda: Motors(compliance=-1.0), ParameterError,
     "The 'compliance' parameter of Motors must be >= 0. Got -1.0 instead."),
    (lambda: Motors(speed_limits=(1.0, -1.0)), ParameterError,
     "The 'speed_limits' parameter of Motors must satisfy low <= high with low < inf and high > "
     '-inf. Got (1.0, -1.0) instead.'),
    (lambda: Motors(speed_limits=(np.inf, np.inf)), ParameterError,
     "The 'speed_limits' parameter of Motors must satisfy low <= high with low < inf and high > "
     '-inf. Got (inf, inf) instead.'),
    (lambda: Motors(lag=np.nan), ParameterError,
     "The 'lag' parameter of Motors must be finite. Got nan instead."),
    (lambda: Motors(speed_limits=0.3), ParameterTypeError,
     "The 'speed_limits' parameter of Motors must be a pair (low, high) of speeds. Got 0.3 instead."),
    (lambda: Motors(lag='fast'), ParameterTypeError,
     "The 'lag' parameter of Motors must be a real number. Got 'fast' instead."),
    (lambda: Motors(backlash=-1.0), ParameterError,
     "The 'backlash' parameter of Motors must be >= 0. Got -1.0 instead."),
    (lambda: Plant('x', 1.0), ParameterTypeError,
     "The 'contacts' parameter of Plant must be a ContactSet. Got 'x' instead."),
    (lambda: Plant(_CS, 0.0), ParameterError,
     "The 'mass' parameter of Plant must be > 0. Got 0.0 instead."),
    (lambda: Plant(_CS, 1.0, damping=-1.0), ParameterError,
     "The 'damping' parameter of Plant must be >= 0. Got -1.0 instead."),
    (lambda: Plant(_CS, 1.0, motors='m'), ParameterTypeError,
     "The 'motors' parameter of Plant must be a Motors instance or None. Got 'm' instead."),
    (lambda: Plant(_CS, 1.0, commands=PiecewiseConstant([], [[0.0, 0.0, 0.0]])), ParameterError,
     "The 'commands' parameter of Plant must have values of shape (k + 1, 2) (one column per "
     "contact). Got 'values of shape (1, 3)' instead."),
    (lambda: Plant(_CS, 1.0, commands=[0.0, 0.0]), ParameterTypeError,
     "The 'commands' parameter of Plant must be a PiecewiseConstant or None. Got [0.0, 0.0] instead."),
    (lambda: Plant(_CS, 1.0, external_force=PiecewiseConstant([], [[0.0, 0.0]])), ParameterError,
     "The 'external_force' parameter of Plant must be a scalar signal (values of shape (k + 1,)). "
     "Got 'values of shape (1, 2)' instead."),
])
def test_every_refusal_of_the_motors_and_the_plant_in_full(call, error, message):
    """Each refusal matched whole: parameter, owner, rule and value (mutants: any of them changed,
    dropped or replaced by None)."""
    with pytest.raises(error) as info:
        call()
    assert str(info.value) == message



@pytest.mark.parametrize("scale", SCALES)
def test_compliant_zero_band_of_cancelling_loads_at_every_scale(scale):
    """Compliant contacts at 0, 0.5 and 2 m/s with loads 0.1, 0.2 and 0.3 (times the scale)
    and ``k = 0.5 / scale``: between the second's upper and the third's lower saturation limit
    the force is ``-0.1 - 0.2 + 0.3``, zero but for rounding (about 5.6e-17 scale), which the
    tolerance ``4 (K + 1) eps F_tot`` snaps: the zero set is that band, its ends ``v_i +- k
    f_i`` exactly, at every scale (the products ``k f_i`` do not depend on it). Mutants killed:
    the tolerance without ``F_tot`` (at 2**20; the unit-scale tests let it through), the slope
    above every limit."""
    from toolkit.model.friction import compliant_breakpoints, compliant_zero_set

    speeds = np.array([0.0, 0.5, 2.0])
    forces = np.array([0.1, 0.2, 0.3]) * scale
    k = 0.5 / scale
    assert compliant_zero_set(speeds, forces, k) == (0.5 + 0.5 * 0.2, 2.0 - 0.5 * 0.3)
    x, at_x, first, slope, total = compliant_breakpoints(speeds, forces, k)
    np.testing.assert_array_equal(x, [-0.05, 0.05, 0.5 - 0.1, 0.5 + 0.1, 2.0 - 0.15, 2.0 + 0.15])
    np.testing.assert_array_equal(first, [0, 0, 1, 1, 2, 2])
    np.testing.assert_array_equal(slope * k, [0.0, -1.0, 0.0, -1.0, 0.0, -1.0, 0.0])
    assert total == pytest.approx(0.6 * scale, rel=2 * EPS, abs=0.0)
    np.testing.assert_allclose(at_x, np.array([0.6, 0.4, 0.4, 0.0, 0.0, -0.6]) * scale, rtol=1e-15, atol=0.0)


@pytest.mark.parametrize("options, message", [
    ({"law": "tanh", "epsilon": 0.0}, "The 'epsilon' parameter of contact_forces must be > 0. Got 0.0 instead."),
    ({"law": "stribeck"}, "The 'epsilon' parameter of contact_forces must be > 0. Got 0.0 instead."),
    ({"law": "stribeck", "epsilon": -1.0}, "The 'epsilon' parameter of contact_forces must be > 0. Got -1.0 instead."),
    ({"law": "tahn", "epsilon": 0.1}, "The 'friction' parameter of contact_forces must be one of ['sign', 'tanh', "
                                      "'stribeck']. Got 'tahn' instead. Did you mean 'tanh'?"),
    ({"law": "tahn", "owner": "Plant.contact_forces"}, "The 'friction' parameter of Plant.contact_forces must be one "
                                                       "of ['sign', 'tanh', 'stribeck']. Got 'tahn' instead. Did you "
                                                       "mean 'tanh'?"),
])
def test_friction_law_refusals_in_full(options, message):
    """The smoothing width and the law's name refused whole, under the caller's name
    (mutants: the parameter, the owner, the bound 0 or its openness changed)."""
    from toolkit.model.friction import contact_forces

    with pytest.raises(ParameterError) as info:
        contact_forces(np.array([0.1, -0.2]), np.array([1.0, 2.0]), **options)
    assert str(info.value) == message


def test_array_ops_are_made_once_per_back_end(monkeypatch):
    """``ops`` returns the one numpy instance for numpy (or None) and makes one instance per
    other module, kept (from an empty cache here: the suite's earlier calls would hide a
    cache that never fills). numpy's ``sum`` adds along the last axis only. Mutants killed:
    the numpy test inverted, the cache's key or its fill, the module passed on, ``axis=-1``
    dropped."""
    import casadi

    from toolkit.model import _xp

    monkeypatch.setattr(_xp, "_CACHE", {})
    first, again = _xp.ops(casadi), _xp.ops(casadi)
    assert first is again and first.module is casadi and first.symbolic
    assert _xp.ops(np) is _xp.ops(None) is _xp.ops() and not _xp.ops(np).symbolic
    np.testing.assert_array_equal(_xp.ArrayOps(np).sum(np.arange(6.0).reshape(2, 3)), [3.0, 12.0])


@pytest.mark.parametrize("scale", SCALES)
@pytest.mark.parametrize("excess, band", [(9, True), (11, False)])
def test_compliant_tie_tolerance_brackets_the_net_force(scale, excess, band):
    """Compliant contacts at 0 and 1 m/s with loads 1 and ``1 + d`` (times the scale), ``k =
    0.25 / scale``: between the saturation limits the force is ``d`` exactly (dyadic), against
    the tolerance ``4 (K + 1) eps F_tot = 40 eps`` (``K = 4``), i.e. ``10 * 2**-50``. ``d = 9 *
    2**-50`` is a tie (the zero band between the limits 0.25 and ``1 - k (1 + d)``), ``11 *
    2**-50`` is not (a single point). A lifted contact (load 0) adds no limit. Mutants killed:
    the factor 4 to 5, ``K + 1`` to ``K - 1`` or ``K + 2``, the lifted contact counted."""
    from toolkit.model.friction import compliant_breakpoints, compliant_zero_set

    d = excess * 2.0 ** -50
    speeds = np.array([0.0, 1.0, 0.5])
    forces = np.array([1.0, 1.0 + d, 0.0]) * scale
    k = 0.25 / scale
    lo, hi = compliant_zero_set(speeds, forces, k)
    upper = 1.0 - 0.25 * (1.0 + d)
    if band:
        assert (lo, hi) == (0.25, upper)
    else:
        assert lo == hi and upper <= lo <= upper + 2 * 0.25 * (1.0 + d)
    x, at_x, first, _, _ = compliant_breakpoints(speeds, forces, k)
    assert x.size == 4 and list(first) == [0, 0, 1, 1]
    assert at_x[1] == (0.0 if band else d * scale)


# -- the motor law solved: MotorPiece, reach, implicit_step, clip on casadi -----------------
def _lag_ode(motors, start, command, s_end):
    """Second method: motor_rate integrated by an adaptive Runge-Kutta (rtol 1e-12)."""
    from scipy.integrate import solve_ivp

    from toolkit.model import motor_rate

    sol = solve_ivp(lambda t, v: motor_rate(motors, command, v), (0.0, s_end), start, method="DOP853",
                    rtol=1e-12, atol=1e-14, dense_output=True, max_step=motors.lag / 8 if motors.lag else np.inf)
    return sol.sol


@pytest.mark.parametrize("scale", [2.0 ** -20, 1.0, 2.0 ** 20])
def test_motor_piece_ramps_then_settles_per_contact(scale):
    """Lag 1/4 s and rate limit 2 m/s^2 (r tau = 1/2 m/s), unequal gaps u - v0 of (1.5, -1,
    1/4, 1/2) m/s (times ``scale``, with the rate: every number scales by a power of two,
    exactly): the first two ramp for (|gap| - r tau) / r = 1/2 and 1/4 s and end at u -+ r tau;
    the third is inside the lag's reach; the fourth sits exactly on it (no ramp: ``>``, not
    ``>=``). Exact at the ramp's end (dyadic), the lag's closed form after it (4 eps), and
    the law integrated by Runge-Kutta (1e-9: its tolerance) in between; the displacement is
    the quadrature of the speeds (1e-12 relative: Gauss-Kronrod on smooth pieces)."""
    from scipy.integrate import quad

    from toolkit.model import MotorPiece

    tau, r = 0.25, 2.0 * scale
    v0 = np.array([0.0, 0.5, -0.25, 0.125]) * scale
    u = v0 + np.array([1.5, -1.0, 0.25, 0.5]) * scale
    piece = MotorPiece.build(0.5, v0, u, tau, r)
    np.testing.assert_array_equal(piece.ramp, np.array([2.0, -2.0, 0.0, 0.0]) * scale)
    np.testing.assert_array_equal(piece.ramp_end, [0.5, 0.25, 0.0, 0.0])
    np.testing.assert_array_equal(piece.after, np.array([1.0, 0.0, -0.25, 0.125]) * scale)
    assert piece.a == 0.5
    ramps = piece.speeds(np.array([0.125, 0.25, 0.5]))
    np.testing.assert_array_equal(ramps[:, 0], np.array([0.25, 0.5, 1.0]) * scale)
    np.testing.assert_array_equal(ramps[:2, 1], np.array([0.25, 0.0]) * scale)
    s = np.array([0.0, 0.0625, 0.3, 0.5, 0.75, 1.5])
    expect = np.where(s[:, None] < piece.ramp_end, v0 + piece.ramp * s[:, None],
                      u + (piece.after - u) * np.exp(-(s[:, None] - piece.ramp_end) / tau))
    np.testing.assert_allclose(piece.speeds(s), expect, rtol=4 * np.finfo(float).eps, atol=0)
    ode = _lag_ode(Motors(lag=tau, rate_limit=r), v0, u, 1.5)
    np.testing.assert_allclose(piece.speeds(s), ode(s).T, rtol=0, atol=1e-9 * scale)
    for t in s:
        np.testing.assert_array_equal(piece.speeds_at(float(t)), piece.speeds(np.array([t]))[0])
        for i in range(4):
            area = quad(lambda x: piece.speeds(np.array([x]))[0, i], 0.0, t, points=[0.25, 0.5], epsabs=0,
                        epsrel=1e-13)[0] if t > 0 else 0.0
            assert piece.displacement(float(t))[i] == pytest.approx(area, rel=1e-12, abs=1e-15 * scale)
    # Coefficients: v(s + x) = v0 + q x + e ..., the next phase change the first ramp end ahead.
    v, q, e, nxt = piece.coefficients(0.125)
    np.testing.assert_array_equal(q, [2.0 * scale, -2.0 * scale, 0.0, 0.0])
    np.testing.assert_array_equal(e, [0.0, 0.0, *((u - v)[2:] / tau)])
    assert nxt == 0.25
    v, q, e, nxt = piece.coefficients(0.375)
    np.testing.assert_array_equal(q, [2.0 * scale, 0.0, 0.0, 0.0])
    assert nxt == 0.5 and e[0] == 0.0 and e[1] == (u[1] - v[1]) / tau
    v, q, e, nxt = piece.coefficients(0.75)
    np.testing.assert_array_equal(q, np.zeros(4))
    np.testing.assert_array_equal(e, (u - v) / tau)
    assert nxt == math.inf


def test_motor_piece_without_lag_ramps_and_holds_and_without_rate_limit_decays():
    from toolkit.model import MotorPiece

    v0, u = np.array([0.0, 0.5]), np.array([1.0, -0.25])
    ramp = MotorPiece.build(0.0, v0, u, 0.0, 4.0)      # ramps of 1/4 and 3/16 s at 4 m/s^2
    np.testing.assert_array_equal(ramp.ramp_end, [0.25, 0.1875])
    np.testing.assert_array_equal(ramp.after, u)
    np.testing.assert_array_equal(ramp.speeds(np.array([0.125, 0.1875, 1.0])), [[0.5, 0.0], [0.75, -0.25], u])
    np.testing.assert_array_equal(ramp.speeds_at(1.0), u)
    # Displacement: v0 x + 4 x^2 / 2 on the ramp, then u times the rest (dyadic: exact).
    np.testing.assert_array_equal(ramp.displacement(1.0), [0.125 + 0.75, 0.5 * 0.1875 - 2 * 0.1875 ** 2 - 0.25 * 0.8125])
    v, q, e, nxt = ramp.coefficients(0.5)
    np.testing.assert_array_equal(e, [0.0, 0.0])
    assert nxt == math.inf and not q.any()
    v, q, e, nxt = ramp.coefficients(0.0)
    np.testing.assert_array_equal(q, [4.0, -4.0])
    np.testing.assert_array_equal(e, [0.0, 0.0])
    assert nxt == 0.1875
    tau = 0.125
    lag = MotorPiece.build(0.0, v0, u, tau, math.inf)
    assert not lag.ramp.any() and not lag.ramp_end.any()
    np.testing.assert_array_equal(lag.after, v0)
    np.testing.assert_allclose(lag.speeds(np.array([tau])), [u + (v0 - u) / np.e], rtol=4 * np.finfo(float).eps)
    # u s + (v0 - u) tau (1 - e^-s/tau) at s = tau (4 eps of the terms).
    np.testing.assert_allclose(lag.displacement(tau), u * tau + (v0 - u) * tau * (1 - 1 / np.e),
                               rtol=8 * np.finfo(float).eps)


@pytest.mark.parametrize("tau, rate", [(0.0, math.inf), (0.0, 2.0), (0.25, math.inf), (0.25, 2.0)])
def test_reach_bounds_every_command_and_is_met_by_the_limit(tau, rate):
    """``reach`` is the motor law driven at the limit: equal to the law's own solution with the
    limit as the command (MotorPiece: 4 eps; Runge-Kutta: its 1e-9) from unequal starts below
    it, and no other command between the limits gets farther (checked on two)."""
    from toolkit.model import MotorPiece
    from toolkit.model.motors import reach

    v = np.array([-0.5, 0.0, 0.25, 0.625])
    limit = 0.75
    s = np.array([0.0, 0.0625, 0.125, 0.3, 0.5, 1.0])
    got = reach(tau, rate, v, limit, s)
    def law(command):                                  # ideal motors jump to the command
        if tau == 0 and rate == math.inf:
            return np.full((s.size, 4), command)
        return MotorPiece.build(0.0, v, np.full(4, command), tau, rate).speeds(s)

    np.testing.assert_allclose(got, law(limit), rtol=4 * np.finfo(float).eps, atol=1e-16)
    if tau > 0:
        ode = _lag_ode(Motors(lag=tau, rate_limit=rate), v, np.full(4, limit), 1.0)
        np.testing.assert_allclose(got, ode(s).T, rtol=0, atol=1e-9)
    for other in (0.5, -0.75):
        slower = law(other)
        assert np.all(got >= slower - 1e-15)
    if tau == 0 and rate == 2.0:
        np.testing.assert_array_equal(got[2], [-0.25, 0.25, 0.5, 0.75])     # 2 x 1/8 = 1/4 up, to the limit


def test_implicit_step_solves_the_backward_euler_equation():
    """``v+ = v + h clip((u - v+) / tau, -r, r)``: the step's result put back in the defining
    equation (2 eps: one division and one product), per contact with unequal gaps, some on the
    rate limit; without a lag, a ramp of at most ``r h`` to the command (dyadic: exact)."""
    from toolkit.model.motors import implicit_step

    v = np.array([0.0, 0.5, -0.25, 0.125])
    u = np.array([1.0, -0.5, -0.125, 0.125])
    h = 0.125
    for motors in (Motors(lag=0.375, rate_limit=2.0), Motors(lag=0.375), Motors(lag=0.125, rate_limit=1.0)):
        nxt = implicit_step(motors, v, u, h)
        pull = (u - nxt) / motors.lag
        np.testing.assert_allclose(nxt, v + h * np.clip(pull, -motors.rate_limit, motors.rate_limit),
                                   rtol=2 * np.finfo(float).eps, atol=1e-17)
    # Lag 1/8 = h: w = (v + u) / 2; rate 2: at most 1/4 per step (dyadic: exact).
    np.testing.assert_array_equal(implicit_step(Motors(lag=0.125, rate_limit=2.0), v, u, h),
                                  [0.25, 0.25, -0.1875, 0.125])
    np.testing.assert_array_equal(implicit_step(Motors(rate_limit=2.0), v, u, h), [0.25, 0.25, -0.125, 0.125])
    np.testing.assert_array_equal(implicit_step(Motors(), v, u, h), u)


def test_motor_clip_on_casadi_is_numpys_clip():
    import casadi

    x = np.array([-1.0, -0.25, 0.0, 0.5, 2.0])
    for limits in ((-0.5, 0.75), (-math.inf, 0.75), (-0.5, math.inf), (-math.inf, math.inf)):
        motors = Motors(speed_limits=limits)
        s = casadi.SX.sym("s", x.size)
        built = casadi.Function("f", [s], [motors.clip(s, casadi)])
        np.testing.assert_array_equal(np.array(built(x)).ravel(), np.clip(x, *limits))
        np.testing.assert_array_equal(motors.clip(x, None), np.clip(x, *limits))


def test_motor_rate_on_casadi_is_numpys():
    import casadi

    from toolkit.model import motor_rate

    u, v = np.array([1.0, -1.0, 0.25, 0.0]), np.array([0.0, 0.0, 0.0, 0.5])
    s = casadi.SX.sym("v", 4)
    for motors in (None, Motors(), Motors(lag=0.5), Motors(lag=0.5, rate_limit=1.5), Motors(rate_limit=3.0)):
        built = casadi.Function("f", [s], [casadi.vertcat(motor_rate(motors, u, s, casadi))])
        np.testing.assert_array_equal(np.array(built(v)).ravel(), motor_rate(motors, u, v))
    assert Motors(lag=0.5, speed_limits=(-1.0, 1.0)).speed_limits == (-1.0, 1.0)


def test_lag_settling_time_is_bracketed_at_the_travel():
    from toolkit.model import lag_settling_time

    # remaining gap tau = 0.5 x 0.25 = 1/8 m: equal to the travel is already settled (0), twice
    # the travel takes tau ln 2 (the remaining travel halves after tau ln 2).
    assert lag_settling_time(0.5, 0.25, 0.125) == 0.0
    assert lag_settling_time(0.5, 0.25, 0.0625) == pytest.approx(0.25 * math.log(2.0), rel=2 * np.finfo(float).eps)
    assert lag_settling_time(0.5, 0.25, 0.125 * (1 - 2 ** -40)) > 0.0


def test_motors_keep_floats_and_bracket_the_lag_and_limits():
    """Integers given are kept as Python floats (speed limits as a tuple of floats); the lag's
    rate 1 / lag must be finite: 1e-308 (rate 1e308) is taken, 5e-324 refused in full; equal
    speed limits are a valid (fixed) speed; each limit is named when it is not a number."""
    motors = Motors(lag=1, rate_limit=2, speed_limits=[-1, np.float32(1)], compliance=1, backlash=1)
    for name in ("lag", "rate_limit", "compliance", "backlash"):
        assert type(getattr(motors, name)) is float, name
    assert motors.speed_limits == (-1.0, 1.0) and type(motors.speed_limits) is tuple
    assert all(type(v) is float for v in motors.speed_limits)
    assert Motors(lag=1e-308).lag == 1e-308
    assert Motors(speed_limits=(0.5, 0.5)).speed_limits == (0.5, 0.5)
    for call, error, message in (
            (lambda: Motors(lag=5e-324), ParameterError,
             "The 'lag' parameter of Motors must be 0 or have a finite rate 1 / lag. Got 5e-324 instead."),
            (lambda: Motors(speed_limits=("a", 1.0)), ParameterTypeError,
             "The 'speed_limits' parameter of Motors must be a real number. Got 'a' instead."),
            (lambda: Motors(speed_limits=(-1.0, np.nan)), ParameterError,
             "The 'speed_limits' parameter of Motors must be finite. Got nan instead.")):
        with pytest.raises(error) as info:
            call()
        assert str(info.value) == message


def test_ideal_motor_rates_are_float_zeros_of_the_speeds_shape():
    """Ideal motors: zero rates, one per contact, as floats whatever the speeds were given as
    (a list, integers, NaN from a failed estimate: still no motion); the ideal response is the
    command from the first instant (s = 0 included)."""
    from toolkit.model import motor_rate, unsaturated_response

    for speeds in ([0.1, 0.2, 0.3], np.array([1, 2, 3]), np.array([np.nan, 0.0, 1.0])):
        for motors in (None, Motors(compliance=0.5)):
            rate = motor_rate(motors, np.zeros(3), speeds)
            assert rate.shape == (3,) and rate.dtype == np.float64
            np.testing.assert_array_equal(rate, np.zeros(3))
    u, v = np.array([0.5, -0.25]), np.array([0.0, 0.125])
    np.testing.assert_array_equal(unsaturated_response(v, u, 0.0, 0.0, math.inf), u)
    np.testing.assert_array_equal(unsaturated_response(v, u, np.array([[0.0], [0.5]]), 0.0, math.inf), [u, u])


def test_lag_memory_is_python_floats():
    from toolkit.model import lag_memory

    share, area = lag_memory(0.25, 0.25)
    assert type(share) is float and type(area) is float
    assert share == pytest.approx(math.exp(-1.0), rel=2 * EPS) and area == pytest.approx(0.25 * (1 - math.exp(-1)),
                                                                                         rel=4 * EPS)


def test_motor_piece_is_its_fields_at_their_defining_points():
    """A piece keeps its start time ``a`` whatever its motors; at the end of a ramp its speed is
    ``after`` exactly (the field's definition), also where ``start + ramp * ramp_end`` rounds
    elsewhere (starts and commands drawn until it does: found, asserted); with no ramp the
    coefficients are float zeros of the contacts' shape."""
    from toolkit.model import MotorPiece

    assert MotorPiece.build(0.75, np.zeros(2), np.ones(2), 0.25, math.inf).a == 0.75
    assert MotorPiece.build(0.75, np.zeros(2), np.ones(2), 0.0, 2.0).a == 0.75
    start, u = np.array([0.09587318112501803, 0.0]), np.array([-0.16114930036529077, 0.3])
    for tau in (0.0075, 0.0):
        piece = MotorPiece.build(0.0, start, u, tau, 5.0)
        end = piece.ramp_end[0]
        assert end > 0 and (start + piece.ramp * end)[0] != piece.after[0] or tau == 0.0
        assert piece.speeds(np.array([end]))[0, 0] == piece.after[0]
        assert piece.speeds_at(float(end))[0] == piece.after[0]
    v, q, e, nxt = MotorPiece.build(0.0, start, u, 0.25, math.inf).coefficients(0.5)
    assert q.shape == (2,) and q.dtype == np.float64 and not q.any() and nxt == math.inf


def test_motor_piece_overflow_on_the_ramp_is_masked_silently():
    """With a tiny lag (1e-20 s) the settling branch evaluated on the ramp overflows (exp of
    5e19) and gives 0 * inf where ``after`` rounds onto the command; that branch is masked, and
    it raises nothing even where floating-point errors are made to raise."""
    from toolkit.model import MotorPiece

    piece = MotorPiece.build(0.0, np.array([0.0, 0.0]), np.array([1.0, -0.5]), 1e-20, 1.0)
    assert piece.after[0] == 1.0 and piece.ramp_end[0] > 0.5
    with np.errstate(all="raise"):
        np.testing.assert_array_equal(piece.speeds(np.array([0.25]))[0], [0.25, -0.25])
        np.testing.assert_array_equal(piece.speeds_at(0.25), [0.25, -0.25])


def test_reach_towards_a_limit_on_the_other_side_of_zero():
    """Towards a negative limit from positive and zero speeds (limit + v and limit - v differ in
    sign): every contact moves down, by r s on a pure ramp (dyadic: exact)."""
    from toolkit.model.motors import reach

    got = reach(0.0, 2.0, np.array([0.5, 0.0]), -0.25, np.array([0.125]))
    np.testing.assert_array_equal(got, [[0.25, -0.25]])


# -- the plant: its scale checks bracketed and refused in full, its right-hand side ---------
def test_plant_scale_refusals_in_full():
    """The overflow and rounding checks name the parameter, the rule with the numbers that
    broke it, and the value."""
    def message(call):
        with pytest.raises(ParameterError) as info:
            call()
        return str(info.value)

    assert message(lambda: Plant(ContactSet([0.1, 0.2], [1.0, 2.0]), mass=1e-300, external_force=1e300)) == (
        "The 'mass' parameter of Plant must keep the largest acceleration (F_tot + max|F_ext|) / m finite "
        "(F_tot = 3 N, max|F_ext| = 1e+300 N). Got 1e-300 instead.")
    assert message(lambda: Plant(ContactSet([0.1]), mass=1e-300, damping=1e10,
                                 external_force=PiecewiseConstant([1.0], [0.5, -2.0]))) == (
        "The 'damping' parameter of Plant must keep the drag rate c / m finite (m = 1e-300 kg). Got 10000000000.0 "
        "instead.")
    assert message(lambda: Plant(ContactSet([0.3, 0.7, 0.1], [1.0, 0.5, 0.0]), 1.0,
                                 motors=Motors(compliance=1e-17))) == (
        "The 'motors' parameter of Plant must have a compliance k with k f_i above the speeds' rounding "
        "4 eps max|v| = 6.22e-16 m/s and 1 / (k f_i) finite for every contact (smallest f_i = 0.5 N); use "
        "compliance=0 for a stiff motor. Got 1e-17 instead.")
    commands = PiecewiseConstant([1.0], [[0.5, -1.0], [0.25, 0.0]])
    assert message(lambda: Plant(ContactSet([0.5, -1.0]), 1.0, motors=Motors(compliance=2.0 ** -40,
                                                                             lag=2.0 ** -978),
                                 commands=commands)) == (
        "The 'motors' parameter of Plant must have a lag tau with 16 n 2 max|v| / (tau k) finite (n = 2, "
        "max|v| = 1 m/s, k = 9.09495e-13 (m/s)/N); use lag=0 for instantaneous motors. Got "
        f"{2.0 ** -978!r} instead.")


def test_plant_scale_checks_are_bracketed_at_their_edges():
    """Each bound from both sides, on powers of two (exact): the compliance floor ``4 eps
    max|v|`` with the speeds clipped to the limits (max|v| = 1/2 from commands of 1 and -3),
    ``k f`` at the floor refused and one ulp above taken, the smallest loaded contact's ``f``
    (the lifted one skipped); the lag's pull ``16 n 2 max|v| / (tau k)`` at 2^1024 refused
    and at 2^1023 taken; the acceleration and drag rates at the largest double taken."""
    eps = np.finfo(float).eps
    limits = (-0.5, 0.5)
    cs = ContactSet([1.0, -3.0, 0.0], [2.0, 0.5, 0.0])
    floor = 4 * eps * 0.5
    with pytest.raises(ParameterError, match="'motors' parameter of Plant must have a compliance"):
        Plant(cs, 1.0, motors=Motors(compliance=floor / 0.5, speed_limits=limits))
    taken = Plant(cs, 1.0, motors=Motors(compliance=np.nextafter(floor / 0.5, 1.0), speed_limits=limits))
    assert taken.compliance == np.nextafter(floor / 0.5, 1.0)
    # Commands set the scale: max |clip(commands)| = 1/4 halves the floor.
    commands = PiecewiseConstant([1.0], [[0.25, 0.0, 0.0], [0.125, -0.25, 0.0]])
    Plant(cs, 1.0, motors=Motors(compliance=np.nextafter(floor / 1.0, 1.0), speed_limits=limits), commands=commands)
    with pytest.raises(ParameterError, match="'motors' parameter of Plant must have a compliance"):
        Plant(cs, 1.0, motors=Motors(compliance=floor / 1.0, speed_limits=limits), commands=commands)
    two = ContactSet([0.5, -1.0])
    commands = PiecewiseConstant([1.0], [[0.5, -1.0], [0.25, 0.0]])
    # 16 * 2 * (2 * 1 / 2^-977) / 2^-40 = 2^1023: finite; 2^-978 gives 2^1024 = inf.
    plant = Plant(two, 1.0, motors=Motors(compliance=2.0 ** -40, lag=2.0 ** -977), commands=commands)
    assert plant.motors.lag == 2.0 ** -977
    with pytest.raises(ParameterError, match="'motors' parameter of Plant must have a lag"):
        Plant(two, 1.0, motors=Motors(compliance=2.0 ** -40, lag=2.0 ** -978), commands=commands)
    # Without commands (or without a lag) the pull is not checked.
    Plant(two, 1.0, motors=Motors(compliance=2.0 ** -40, lag=2.0 ** -978))
    big = np.finfo(float).max
    assert Plant(ContactSet([0.0], [big / 2]), 1.0, external_force=big / 2).mass == 1.0
    with pytest.raises(ParameterError, match="'mass' parameter of Plant"):
        Plant(ContactSet([0.0], [big / 2]), 1.0, external_force=PiecewiseConstant([1.0], [0.0, -big]))
    assert Plant(ContactSet([0.0]), 0.5, damping=big / 2).damping == big / 2
    with pytest.raises(ParameterError, match="'damping' parameter of Plant"):
        Plant(ContactSet([0.0]), 0.5, damping=big)


@pytest.mark.parametrize("scale", [2.0 ** -20, 1.0, 2.0 ** 20])
def test_plant_rhs_is_the_law_on_both_back_ends(scale):
    """``m dV/dt = sum f_i sign(v_i - V) + F_ext - c V`` and the motor law, on unequal loads and
    masses at three scales of force and mass (their ratio, the acceleration, unchanged: every
    value below is exact), with the plant's own command and outside force or those given; the
    same on casadi."""
    import casadi

    cs = ContactSet([0.5, -0.25, 0.125], np.array([1.0, 2.0, 0.5]) * scale)
    commands = PiecewiseConstant([1.0], [[0.5, -0.25, 0.125], [1.0, 0.75, -2.0]])
    lagging = Plant(cs, 2.0 * scale, damping=0.5 * scale, external_force=PiecewiseConstant([0.5], [0.0, 0.25 * scale]),
                    motors=Motors(lag=0.25, speed_limits=(-1.0, 0.5)), commands=commands)
    x = np.array([0.0, 0.5, 0.0, 0.125])
    # t = 0.75: F_ext = 0.25, forces (1, 0, 0.5) (the second ties: 0), drag 0 -> dV = 1.75 / 2;
    # commands (0.5, -0.25, 0.125) until 1 s: motor rates (0, -1, 0); after it, clipped to
    # (0.5, 0.5, -1): (0, 2, -4.5).
    np.testing.assert_array_equal(lagging.rhs(0.75, x), [0.875, 0.0, -1.0, 0.0])
    np.testing.assert_array_equal(lagging.motor_rate(1.5, x[1:]), [0.0, 2.0, -4.5])
    np.testing.assert_array_equal(lagging.motor_rate(0.5, x[1:]), [0.0, -1.0, 0.0])
    # Given command (clipped by the motors) and force: u = (1, 1, 1) -> (0.5, 0.5, 0.5).
    np.testing.assert_array_equal(lagging.rhs(0.75, x, [1.0, 1.0, 1.0], external=-1.5 * scale),
                                  [(1.5 - 1.5) / 2, 0.0, 2.0, 1.5])
    V = 0.25
    drag = lagging.rhs(0.25, np.array([V, 0.5, -0.25, 0.125]))
    np.testing.assert_array_equal(drag, [(1.0 - 2.0 - 0.5 - 0.5 * V) / 2, 0.0, 0.0, 0.0])
    assert lagging.net_force(0.25, V, [0.5, -0.25, 0.125]) == (1.0 - 2.0 - 0.5 - 0.5 * V) * scale
    # The smoothed law's width reaches the law: tanh(s / eps) at s = V - v of 1/2 and 1/4.
    eps = 0.5
    tanh = lagging.net_force(0.0, 0.0, [0.5, -0.25, 0.125], friction="tanh", epsilon=eps)
    assert tanh == pytest.approx(scale * (np.tanh(1.0) - 2 * np.tanh(0.5) + 0.5 * np.tanh(0.25)), rel=4 * EPS)
    assert lagging.rhs(0.0, [0.0, 0.5, -0.25, 0.125], friction="tanh", epsilon=eps)[0] == pytest.approx(
        tanh / (2.0 * scale), rel=4 * EPS)
    s = casadi.SX.sym("x", 4)
    built = casadi.Function("f", [s], [lagging.rhs(0.75, s, xp=casadi)])
    np.testing.assert_array_equal(np.array(built(x)).ravel(), [0.875, 0.0, -1.0, 0.0])
    ideal = Plant(cs, 2.0 * scale, commands=commands)
    np.testing.assert_array_equal(ideal.rhs(0.75, [0.0]), [-0.25])      # (1 - 2 + 0.5) / 2 at u(0.75)
    np.testing.assert_array_equal(ideal.rhs(1.5, [0.0]), [(1.0 + 2.0 - 0.5) / 2])
    np.testing.assert_array_equal(ideal.rhs(1.5, [0.0], [1.0, 1.0, 1.0]), [(1.0 + 2.0 + 0.5) / 2])
    np.testing.assert_array_equal(ideal.motor_rate(0.0, [0.1, 0.2, 0.3]), np.zeros(3))
    v = casadi.SX.sym("V", 1)
    built = casadi.Function("g", [v], [ideal.rhs(1.5, v, xp=casadi)])
    assert float(built(0.0)) == (1.0 + 2.0 - 0.5) / 2
    with pytest.raises(ParameterError, match=re.escape(
            "The 'epsilon' parameter of Plant.rhs must be > 0. Got 0.0 instead.")):
        ideal.rhs(0.0, [0.0], friction="tanh")
    with pytest.raises(ParameterError, match=re.escape(
            "The 'epsilon' parameter of Plant.contact_forces must be > 0. Got -1 instead.")):
        ideal.net_force(0.0, 0.0, [0, 1, 2], friction="tanh", epsilon=-1)


def test_plant_keeps_floats_and_reports_its_motors():
    """Integers given for the mass, the drag and a constant outside force are kept as Python
    floats; the plant reports its motors' compliance, play and dynamics (0, 0, none for ideal
    motors) and its number of contacts; commands are clipped to the motors' limits only."""
    plant = Plant(ContactSet([0.5, -0.75, 0.25]), 2, damping=1, external_force=3)
    for name in ("mass", "damping", "external_force"):
        assert type(getattr(plant, name)) is float, name
    assert (plant.n, plant.compliance, plant.backlash, plant.dynamic_motors) == (3, 0.0, 0.0, False)
    np.testing.assert_array_equal(plant.command(0.0), [0.5, -0.75, 0.25])
    np.testing.assert_array_equal(plant.final_command(), [0.5, -0.75, 0.25])
    assert plant.external(7.0) == 3.0 and type(plant.external(7.0)) is float
    driven = Plant(ContactSet([0.5, -0.75, 0.25]), 2.0, motors=Motors(compliance=0.5, backlash=0.001, lag=0.25,
                                                                      speed_limits=(-0.5, 0.375)))
    assert (driven.compliance, driven.backlash, driven.dynamic_motors) == (0.5, 0.001, True)
    np.testing.assert_array_equal(driven.command(0.0), [0.375, -0.5, 0.25])
    np.testing.assert_array_equal(driven.final_command(), [0.375, -0.5, 0.25])
    np.testing.assert_array_equal(driven.initial_speeds(), [0.375, -0.5, 0.25])
    ramp = Plant(ContactSet([0.5]), 1.0, motors=Motors(rate_limit=3.0))
    assert ramp.dynamic_motors and not Plant(ContactSet([0.5]), 1.0, motors=Motors(compliance=1.0)).dynamic_motors
    # A compliant plant's equilibrium is the zero of the saturated lines, at the final command:
    # contacts at 0 and 1 with f = (1, 3), k = 1 meet at 1/2 (closed form, test above).
    commands = PiecewiseConstant([1.0], [[5.0, 6.0], [0.0, 1.0]])
    lo, hi = Plant(ContactSet([0, 1], [1, 3]), 1.0, motors=Motors(compliance=1.0), commands=commands).equilibrium()
    assert lo == hi == pytest.approx(0.5, rel=1e-15, abs=0)


def test_plant_rhs_with_compliant_motors_is_the_saturated_linear_law():
    # k = 1/4, f = (1, 2): slips 0.125 and -1 give 1 x clip(0.125 / 0.25) = 0.5 and -2
    # (saturated); m = 2: dV/dt = -0.75; the same through net_force (dyadic: exact).
    plant = Plant(ContactSet([0.125, -1.0], [1.0, 2.0]), 2.0, motors=Motors(compliance=0.25))
    np.testing.assert_array_equal(plant.rhs(0.0, [0.0]), [-0.75])
    assert plant.net_force(0.0, 0.0, [0.125, -1.0]) == -1.5
    np.testing.assert_array_equal(plant.contact_forces(0.0, [0.125, -1.0]), [0.5, -2.0])


def test_plant_scale_checks_at_the_largest_doubles():
    """The lag's pull ``16 n 2 max|v| / (tau k)`` at 1.9 x 2^1023 (n = 2, max|v| = 1/2, k =
    2^-40) is finite and taken: 17/16 of it, or 3 for 2, or max|v| divided, overflow. ``1 /
    (k f)`` is finite for k f = 0.75 x 2^-1023 (taken; twice it is not) and for k = 2^-1020
    with f = 2^10 (k / f would not be). ``k f`` above the floor with f = 4 and k 1.5 floor /
    4 (k / f is below it). Under floating-point errors that raise, the checks still refuse
    with their own error (their overflows and divisions are expected)."""
    eps = np.finfo(float).eps
    commands = PiecewiseConstant([1.0], [[0.5, -0.5], [0.25, 0.0]])
    plant = Plant(ContactSet([0.5, -0.5]), 1.0, motors=Motors(compliance=2.0 ** -40, lag=2.0 ** -978 / 1.9),
                  commands=commands)
    assert plant.motors.lag == 2.0 ** -978 / 1.9
    assert Plant(ContactSet([0.0]), 1.0, motors=Motors(compliance=0.75 * 2.0 ** -1023)).compliance > 0
    assert Plant(ContactSet([0.0], [1024.0]), 1.0, motors=Motors(compliance=2.0 ** -1020)).compliance > 0
    floor = 4 * eps * 0.5
    assert Plant(ContactSet([0.5], [4.0]), 1.0, motors=Motors(compliance=1.5 * floor / 4)).compliance > 0
    with np.errstate(all="raise"):
        with pytest.raises(ParameterError, match="'motors' parameter of Plant must have a compliance"):
            Plant(ContactSet([0.0]), 1.0, motors=Motors(compliance=1e-320))
        with pytest.raises(ParameterError, match="'motors' parameter of Plant must have a lag"):
            Plant(ContactSet([0.5, -0.5]), 1.0, motors=Motors(compliance=2.0 ** -40, lag=2.0 ** -980),
                  commands=commands)


def test_plant_signals_defaults_and_shapes():
    """No commands and no outside signal: no switching times at all; the final command is the
    last row of three; ideal motor rates are float zeros of the speeds' shape; the smoothed
    laws need their width (no default); the ideal right-hand side is one-element."""
    cs = ContactSet([0.0, 1.0])
    assert Plant(cs, 1.0).switching_times().size == 0
    commands = PiecewiseConstant([1.0, 2.0], [[0.0, 1.0], [2.0, 3.0], [4.0, 5.0]])
    np.testing.assert_array_equal(Plant(cs, 1.0, commands=commands).final_command(), [4.0, 5.0])
    rate = Plant(cs, 1.0).motor_rate(0.0, [1, 2])
    assert rate.shape == (2,) and rate.dtype == np.float64 and not rate.any()
    plant = Plant(cs, 2.0)
    for call, owner in ((lambda: plant.contact_forces(0.5, [0.0, 1.0], friction="tanh"), "Plant.contact_forces"),
                        (lambda: plant.net_force(0.0, 0.5, [0.0, 1.0], friction="stribeck"), "Plant.contact_forces")):
        with pytest.raises(ParameterError) as info:
            call()
        assert str(info.value) == f"The 'epsilon' parameter of {owner} must be > 0. Got 0.0 instead."
    dV = plant.rhs(0.0, [0.5])
    assert dV.shape == (1,) and dV[0] == 0.0
    with pytest.raises(ParameterTypeError) as info:
        Plant(cs, 1.0, external_force="a")
    assert str(info.value) == "The 'external_force' parameter of Plant must be a real number. Got 'a' instead."
    with pytest.raises(ParameterError) as info:
        Plant(cs, 1.0, external_force=np.inf)
    assert str(info.value) == "The 'external_force' parameter of Plant must be finite. Got inf instead."
