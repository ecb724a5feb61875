"""Reference integrators (scipy, Moreau-Jean, casadi): closed forms, budgets, cross-checks."""

from __future__ import annotations

import time

import numpy as np
import pytest

from toolkit.contacts import ContactSet
from toolkit.errors import ParameterError
from toolkit.plant import Motors, PiecewiseConstant, Plant
from toolkit.simulation import Budget, Status, simulate
from toolkit.simulation._moreau import _compliant_step, _staircase, moreau_step_staircase
from toolkit.simulation._reference import Meter

SCIPY = ("rk45", "lsoda", "radau", "bdf")


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(20250117)


def _random_plant(rng: np.random.Generator, n: int = 11) -> Plant:
    return Plant(ContactSet(rng.uniform(-0.35, 0.35, n), np.full(n, 2.0 / n)), mass=1.0)


# -- closed forms -------------------------------------------------------------------------------
@pytest.mark.parametrize("method", [*SCIPY, "moreau", "casadi"])
def test_constant_deceleration(method: str) -> None:
    # One contact at -1 m/s (f = 2 N), body from 0.5 m/s, m = 1 kg: V = 0.5 - 2 t while V > -1.
    # Slip >= 0.5 m/s >> epsilon = 1e-3, so tanh(slip/eps) == 1 in floating point: the smoothed
    # model is the same constant force. A constant right-hand side is integrated exactly by
    # every method (RK stages and implicit Euler are exact on linear solutions): atol = a few ulps.
    plant = Plant(ContactSet([-1.0], [2.0]), mass=1.0)
    t_eval = np.linspace(0.0, 0.5, 11)
    options = {"friction": "tanh", "epsilon": 1e-3} if method == "casadi" else {}
    if method == "moreau":
        options = {"step": 0.01}
    result = simulate(plant, 0.5, v0=0.5, method=method, t_eval=t_eval, **options)
    assert result.status is Status.SUCCESS
    np.testing.assert_array_equal(result.t, t_eval)
    np.testing.assert_allclose(result.V, 0.5 - 2.0 * t_eval, rtol=0, atol=1e-14)
    # Moreau's force is m (W - V) / h: rounding of V (~1e-16 m/s) over h = 0.01 s -> atol 1e-12 N.
    np.testing.assert_allclose(result.force, -2.0, rtol=0, atol=1e-12)


@pytest.mark.parametrize("method", [*SCIPY, "casadi"])
def test_exponential_approach_with_drag(method: str) -> None:
    # One contact far above (v = 10, f = 1 N) and drag c = 2 N s/m, m = 0.5 kg:
    # V = f/c + (v0 - f/c) exp(-c t / m). rtol = 1e-10: the global error of these adaptive
    # solvers on a decaying linear ODE stays within ~100 rtol of the solution scale (0.5 m/s);
    # atol = 1e-8 covers it.
    plant = Plant(ContactSet([10.0], [1.0]), mass=0.5, damping=2.0)
    t_eval = np.linspace(0.0, 3.0, 31)
    result = simulate(plant, 3.0, v0=-0.2, method=method, t_eval=t_eval, friction="tanh",
                      epsilon=1e-3, rtol=1e-10, atol=1e-12)
    expected = 0.5 + (-0.2 - 0.5) * np.exp(-4.0 * t_eval)
    assert result.success
    np.testing.assert_allclose(result.V, expected, rtol=0, atol=1e-8)


def test_moreau_is_implicit_euler_on_drag() -> None:
    # Identity: implicit Euler on m V' = f - c V gives V_k = V_inf + (v0 - V_inf) (1 + c h/m)^-k.
    # Agreement to rounding (atol 1e-14 on values of order 1).
    plant = Plant(ContactSet([10.0], [1.0]), mass=0.5, damping=2.0)
    h = 0.01
    result = simulate(plant, 1.0, v0=-0.2, method="moreau", step=h)
    k = np.arange(result.t.size)
    np.testing.assert_allclose(result.t, k * h, rtol=0, atol=1e-14)
    np.testing.assert_allclose(result.V, 0.5 - 0.7 * (1.0 + 4.0 * h) ** -k, rtol=0, atol=1e-14)


def test_moreau_first_order_convergence() -> None:
    # Halving h halves the error at t = 1 s (first order). The leading error term is
    # C h (1 + O(c h / m)); with c/m = 4 and h <= 1e-3 the ratio is 2 within 4 c h / m <= 0.02.
    plant = Plant(ContactSet([10.0], [1.0]), mass=0.5, damping=2.0)
    exact = 0.5 - 0.7 * np.exp(-4.0)
    errors = [abs(simulate(plant, 1.0, v0=-0.2, method="moreau", step=h).V[-1] - exact)
              for h in (1e-3, 5e-4, 2.5e-4, 1.25e-4)]
    ratios = np.array(errors[:-1]) / np.array(errors[1:])
    np.testing.assert_allclose(ratios, 2.0, rtol=0, atol=0.02)


def test_moreau_first_order_on_startup_events() -> None:
    # Startup through several contact speeds: the error of each crossing time is below one
    # step, so the max |V error| against the rational exact solution is <= h * F_tot / m
    # (the speed change over one step) for every h.
    from toolkit.precision import rational_trajectory

    plant = Plant(ContactSet([-0.3, -0.1, 0.05, 0.2, 0.3], np.full(5, 0.4)), mass=1.0)
    for h in (1e-2, 1e-3, 1e-4):
        result = simulate(plant, 2.0, v0=-0.35, method="moreau", step=h)
        truth = rational_trajectory(plant, -0.35, result.t)
        assert np.max(np.abs(result.V - truth)) <= h * 2.0 * (1 + 1e-9)
        assert result.V[-1] == 0.05                      # sticks exactly at the median


# -- exactness of the Moreau step ---------------------------------------------------------------
def test_moreau_stays_exactly_at_equilibrium(rng: np.random.Generator) -> None:
    plant = _random_plant(rng)
    median = float(np.median(plant.contacts.speeds))
    result = simulate(plant, 5.0, v0=median, method="moreau", step=1e-2)
    assert np.all(result.V == median)                    # no chattering, not even by one ulp


def test_moreau_does_not_creep_in_zero_band() -> None:
    plant = Plant(ContactSet([-0.35] * 5 + [0.35] * 5), mass=1.0)
    result = simulate(plant, 10.0, v0=0.2, method="moreau", step=1e-2)
    assert np.all(result.V == 0.2)
    assert np.all(result.force == 0.0)


def test_moreau_step_solves_the_inclusion(rng: np.random.Generator) -> None:
    # For random staircases and right-hand sides, W satisfies a W - b in [F_lo(W), F_hi(W)]
    # (ContactSet.force_bounds), up to rounding of a W - b (atol 1e-12 on forces of order 1).
    for _ in range(200):
        n = int(rng.integers(1, 8))
        cs = ContactSet(np.round(rng.uniform(-1, 1, n), 2), rng.uniform(0.1, 1.0, n))
        stair = cs.staircase()
        a, b = float(rng.uniform(0.5, 50.0)), float(rng.uniform(-30, 30))
        W, stuck = moreau_step_staircase(stair.levels, stair.plateaus, a, b)
        lo, hi = cs.force_bounds(W)
        assert lo - 1e-12 <= a * W - b <= hi + 1e-12
        assert stuck == bool(np.any(stair.levels == W))


def test_moving_staircase_matches_contact_set(rng: np.random.Generator) -> None:
    # The per-step staircase of moving contacts equals ContactSet.staircase (second method):
    # same levels bit for bit; plateaus are sums of <= 8 terms of order 1 -> atol 1e-14 N.
    for _ in range(300):
        n = int(rng.integers(1, 9))
        speeds = np.round(rng.uniform(-1, 1, n), 1)           # rounding makes ties common
        forces = np.where(rng.random(n) < 0.2, 0.0, rng.uniform(0.1, 1.0, n))
        if forces.sum() == 0:
            continue
        stair = ContactSet(speeds, forces).staircase()
        levels, plateaus = _staircase(speeds, forces)
        np.testing.assert_array_equal(levels, stair.levels)
        np.testing.assert_allclose(plateaus, stair.plateaus, rtol=0, atol=1e-14)


@pytest.mark.parametrize("n", [5, 70])      # 10 kinks (all evaluated) / 140 (binary search)
def test_compliant_step_solves_the_equation(n: int, rng: np.random.Generator) -> None:
    # Second method: scipy's brentq on a W - b - F(W) (strictly increasing, continuous).
    from scipy.optimize import brentq

    plant = Plant(ContactSet(rng.uniform(-0.3, 0.3, n), rng.uniform(0.1, 1.0, n)), mass=1.0,
                  motors=Motors(compliance=0.02))
    speeds = plant.contacts.speeds
    for _ in range(20):
        a, b = float(rng.uniform(1.0, 100.0)), float(rng.uniform(-40.0, 40.0))
        W = _compliant_step(plant, speeds, a, b, Meter(Budget()))
        g = lambda x: a * x - b - float(np.sum(plant.contact_forces(x, speeds)))  # noqa: E731
        expected = brentq(g, -1e3, 1e3, xtol=1e-15, rtol=4 * np.finfo(float).eps)
        assert W == pytest.approx(expected, rel=1e-12, abs=1e-13)   # both exact to rounding


def test_moreau_with_compliance_matches_smooth_solver() -> None:
    # A compliant motor makes the force Lipschitz (saturated linear): Radau at rtol 1e-10 is a
    # second method. Moreau is first order: error <= h * max|dV/dt| * (a few) = 1e-4 * 2 * 5.
    plant = Plant(ContactSet([-0.3, 0.0, 0.25], np.full(3, 2.0 / 3)), mass=1.0,
                  motors=Motors(compliance=0.05))
    t_eval = np.linspace(0.0, 2.0, 41)
    moreau = simulate(plant, 2.0, v0=0.3, method="moreau", step=1e-4, t_eval=t_eval)
    radau = simulate(plant, 2.0, v0=0.3, method="radau", t_eval=t_eval, rtol=1e-10, atol=1e-13)
    np.testing.assert_allclose(moreau.V, radau.V, rtol=0, atol=1e-3)
    assert radau.V[-1] == pytest.approx(plant.equilibrium()[0], abs=1e-6)


def test_moreau_motor_lag_matches_smooth_solver() -> None:
    # Lagged motors (tau = 30 ms) switching their commands at t = 0.5 s. The tanh model at
    # eps = 1e-6 differs from Coulomb by ~eps; Moreau at h = 1e-4 by O(h * max|dV/dt|)
    # (dV/dt <= F_tot/m = 2 plus the stuck body following the motors, <= 0.5/0.03 ~ 17 m/s^2):
    # atol = 2e-3.
    commands = PiecewiseConstant([0.5], [[0.1, 0.2, -0.3], [-0.2, 0.3, 0.1]])
    plant = Plant(ContactSet([0.1, 0.2, -0.3], np.full(3, 2.0 / 3)), mass=1.0,
                  motors=Motors(lag=0.03), commands=commands)
    t_eval = np.linspace(0.0, 1.5, 31)
    moreau = simulate(plant, 1.5, method="moreau", step=1e-4, t_eval=t_eval)
    radau = simulate(plant, 1.5, method="radau", friction="tanh", epsilon=1e-6, rtol=1e-9,
                     atol=1e-12, t_eval=t_eval)
    assert moreau.success and radau.success
    np.testing.assert_allclose(moreau.V, radau.V, rtol=0, atol=2e-3)
    np.testing.assert_allclose(moreau.contact_speeds, radau.contact_speeds, rtol=0, atol=2e-3)


# -- external force schedule --------------------------------------------------------------------
@pytest.mark.parametrize("method", ["rk45", "radau", "moreau", "casadi"])
def test_piecewise_external_force(method: str) -> None:
    # Far contact (+100 m/s, f = 1 N): V' = 1 then, from t = 1 s, 1 - 3 = -2 (m = 1 kg).
    # Segments restart at the switch, so each piece is a constant force: exact to rounding.
    plant = Plant(ContactSet([100.0], [1.0]), mass=1.0,
                  external_force=PiecewiseConstant([1.0], [0.0, -3.0]))
    t_eval = np.linspace(0.0, 2.0, 9)
    options = {"step": 0.05} if method == "moreau" else {"friction": "tanh", "epsilon": 1e-3}
    result = simulate(plant, 2.0, method=method, t_eval=t_eval, **options)
    expected = np.where(t_eval < 1.0, t_eval, 1.0 - 2.0 * (t_eval - 1.0))
    np.testing.assert_allclose(result.V, expected, rtol=0, atol=1e-13)


# -- budgets ------------------------------------------------------------------------------------
def test_sign_rk45_returns_budget_status_instead_of_hanging(rng: np.random.Generator) -> None:
    # RK45 on sign() chatters around the median of 11 contacts: it must stop at its budget.
    plant = _random_plant(rng)
    start = time.perf_counter()
    result = simulate(plant, 5.0, method="rk45", friction="sign", budget=Budget(wall_time=0.5))
    elapsed = time.perf_counter() - start
    assert result.status in (Status.WALL_TIME, Status.MAX_STEPS)
    assert result.t_final < 5.0
    assert elapsed < 0.5 + 0.5                           # budget + one step + result assembly
    assert np.all(np.isfinite(result.V))
    assert result.message.startswith(result.status.value)


def test_step_budget_counts_evaluations(rng: np.random.Generator) -> None:
    plant = _random_plant(rng)
    result = simulate(plant, 5.0, method="lsoda", friction="sign", budget=Budget(max_steps=2000))
    assert result.status is Status.MAX_STEPS
    assert result.n_evaluations <= 2001                  # the refused call is counted, not run
    moreau = simulate(plant, 5.0, method="moreau", step=1e-3, budget=Budget(max_steps=100))
    assert moreau.status is Status.MAX_STEPS
    assert moreau.n_steps <= 101 and moreau.t_final == pytest.approx(0.1, abs=1e-12)


def test_casadi_step_budget(rng: np.random.Generator) -> None:
    plant = _random_plant(rng)
    result = simulate(plant, 5.0, method="casadi", epsilon=1e-8, budget=Budget(max_steps=3))
    assert result.status is Status.MAX_STEPS
    assert result.t.size == 1                            # casadi returns no partial trajectory


# -- casadi against the plant's own friction laws ----------------------------------------------
@pytest.mark.parametrize("friction", ["tanh", "stribeck"])
def test_casadi_right_hand_side_is_the_plant_law(friction: str, rng: np.random.Generator) -> None:
    import casadi as ca

    from toolkit.simulation._casadi import casadi_right_hand_side

    plant = Plant(ContactSet(rng.uniform(-1, 1, 6), rng.uniform(0.1, 1, 6)), mass=2.0,
                  damping=0.3)
    x, u, ode = casadi_right_hand_side(plant, friction, 1e-2)
    f = ca.Function("f", [x, u], [ode])
    for V in rng.uniform(-1.2, 1.2, 20):
        ext = float(rng.normal())
        value = float(f(V, np.concatenate((plant.contacts.speeds, [ext]))))
        expected = (plant.net_force(0.0, V, plant.contacts.speeds, friction=friction,
                                    epsilon=1e-2) + ext) / plant.mass
        assert value == pytest.approx(expected, rel=1e-13, abs=1e-13)   # same formula, rounding


def test_stribeck_agrees_between_casadi_and_scipy(rng: np.random.Generator) -> None:
    # Same smooth ODE, two integrators at tight tolerances: agreement within 1e-7 m/s
    # (both at rtol 1e-10 on a solution of scale 0.35 m/s).
    plant = _random_plant(rng, 7)
    t_eval = np.linspace(0.0, 2.0, 21)
    options = {"friction": "stribeck", "epsilon": 1e-2, "rtol": 1e-10, "atol": 1e-12}
    a = simulate(plant, 2.0, method="casadi", t_eval=t_eval, **options)
    b = simulate(plant, 2.0, method="radau", t_eval=t_eval, **options)
    np.testing.assert_allclose(a.V, b.V, rtol=0, atol=1e-7)


# -- options ------------------------------------------------------------------------------------
def test_bad_options_are_refused() -> None:
    plant = Plant(ContactSet([0.0, 1.0]), mass=1.0)
    with pytest.raises(ParameterError, match="Did you mean 'tanh'"):
        simulate(plant, 1.0, method="rk45", friction="tanhh")
    with pytest.raises(ParameterError, match="'epsilon' parameter"):
        simulate(plant, 1.0, method="radau", friction="tanh", epsilon=0.0)
    with pytest.raises(ParameterError, match="'friction' parameter"):
        simulate(plant, 1.0, method="casadi", friction="sign")
    with pytest.raises(ParameterError, match="'step' parameter"):
        simulate(plant, 1.0, method="moreau", step=-1e-3)
    with pytest.raises(ParameterError, match="Did you mean 'idas'"):
        simulate(plant, 1.0, method="casadi", integrator="ida")


# -- against the exact method -------------------------------------------------------------------
@pytest.mark.parametrize("method, options, atol", [
    # tanh at eps: the smoothed solution differs from Coulomb by O(eps) near each contact
    # speed (measured 0.4 eps); the solver's global error is <= ~100 rtol * 0.35 m/s.
    ("radau", {"friction": "tanh", "epsilon": 1e-8, "rtol": 1e-8, "atol": 1e-12}, 10 * 1e-8 + 3.5e-7),
    ("casadi", {"friction": "tanh", "epsilon": 1e-6, "rtol": 1e-10, "atol": 1e-12}, 10 * 1e-6 + 3.5e-9),
    # first order: below one step's speed change, h F_tot / m
    ("moreau", {"step": 1e-4}, 1e-4 * 2.0),
])
def test_reference_methods_agree_with_exact(method: str, options: dict, atol: float,
                                            rng: np.random.Generator) -> None:
    plant = _random_plant(rng)
    t_eval = np.linspace(0.0, 3.0, 301)
    exact = simulate(plant, 3.0, t_eval=t_eval)
    result = simulate(plant, 3.0, method=method, t_eval=t_eval, **options)
    assert result.success
    np.testing.assert_allclose(result.V, exact.V, rtol=0, atol=atol)


def test_motor_lag_reference_agrees_with_exact() -> None:
    # Lagged motors (tau = 30 ms) with a command switch: the stuck body follows its contact
    # through the tanh layer, offset by eps * atanh(m dv/dt / W) <= eps * atanh(0.9) ~ 1.5 eps;
    # Radau's global error at rtol 1e-9 is <= ~1e-7. atol = 1e-6 covers both (eps = 1e-7).
    commands = PiecewiseConstant([0.5], [[0.1, 0.2, -0.3], [-0.2, 0.3, 0.1]])
    plant = Plant(ContactSet([0.1, 0.2, -0.3], np.full(3, 2.0 / 3)), mass=1.0,
                  motors=Motors(lag=0.03), commands=commands)
    t_eval = np.linspace(0.0, 1.5, 151)
    exact = simulate(plant, 1.5, t_eval=t_eval)
    radau = simulate(plant, 1.5, method="radau", friction="tanh", epsilon=1e-7, rtol=1e-9,
                     atol=1e-12, t_eval=t_eval)
    np.testing.assert_allclose(radau.contact_speeds, exact.contact_speeds, rtol=0, atol=1e-8)
    np.testing.assert_allclose(radau.V, exact.V, rtol=0, atol=1e-6)
