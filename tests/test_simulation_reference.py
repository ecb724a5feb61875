"""Reference integrators (scipy, Moreau-Jean, casadi): closed forms, budgets, cross-checks."""

from __future__ import annotations


import numpy as np
import pytest
import scipy.integrate
from scipy.optimize import brentq

from toolkit.model import ContactSet
from toolkit.errors import ParameterError
from toolkit.model import Motors, PiecewiseConstant, Plant
from toolkit.analysis.precision import rational_trajectory
from toolkit.simulation import Budget, SimulationStatus, simulate
from toolkit.simulation._moreau import _compliant_step, _staircase, moreau_step_staircase
from toolkit.simulation._reference import BudgetExceeded, Meter
from toolkit.simulation._scipy import _solver_call

SCIPY = ("rk45", "lsoda", "radau", "bdf")
EPS = np.finfo(float).eps
#: Global error of a tolerance-controlled solver on a stable ODE, in units of its local
#: tolerance ``rtol |V| + atol``: the accumulated local errors stay within this factor (measured
#: <= 5 on the closed-form cases of this file). Used for every bound on an adaptive solver.
GLOBAL_ERROR_FACTOR = 100.0


def _solver_error(rtol: float, atol: float, scale: float) -> float:
    """Bound on an adaptive solver's global error (m/s) on solutions of size ``scale``."""
    return GLOBAL_ERROR_FACTOR * (rtol * scale + atol)


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
    # every method (RK stages and implicit Euler are exact on linear solutions), up to rounding:
    # one rounding (<= eps, since |V| <= 0.5 and the increments are < 1) per accepted step, plus
    # 5 for the dense-output polynomial at each requested time (degree <= 5, one per coefficient).
    plant = Plant(ContactSet([-1.0], [2.0]), mass=1.0)
    t_eval = np.linspace(0.0, 0.5, 11)
    options = {"friction": "tanh", "epsilon": 1e-3} if method == "casadi" else {}
    if method == "moreau":
        options = {"step": 0.01}
    result = simulate(plant, 0.5, v0=0.5, method=method, t_eval=t_eval, **options)
    assert result.status is SimulationStatus.SUCCESS
    np.testing.assert_array_equal(result.t, t_eval)
    np.testing.assert_allclose(result.V, 0.5 - 2.0 * t_eval, rtol=0,
                               atol=(result.n_steps + 5) * EPS)
    # Moreau's force is m (W - V) / h, with W = (m V / h + F) / (m / h): W carries <= 3 roundings
    # of |V| + h |F| / m = 0.52 m/s and W - V one more, divided by h = 0.01 s (m = 1 kg).
    # The other methods evaluate F at V: exactly -2 N (tanh saturates), inside this bound.
    np.testing.assert_allclose(result.force, -2.0, rtol=0, atol=4 * EPS * (0.5 + 0.01 * 2.0) / 0.01)


@pytest.mark.parametrize("method", [*SCIPY, "casadi"])
def test_exponential_approach_with_drag(method: str) -> None:
    # One contact far above (v = 10, f = 1 N) and drag c = 2 N s/m, m = 0.5 kg:
    # V = f/c + (v0 - f/c) exp(-c t / m). The slip is >= 9.3 m/s >> eps, so tanh == 1 exactly
    # (no smoothing error); the solvers' global error at rtol 1e-10, atol 1e-12 on |V| <= 0.5.
    plant = Plant(ContactSet([10.0], [1.0]), mass=0.5, damping=2.0)
    t_eval = np.linspace(0.0, 3.0, 31)
    result = simulate(plant, 3.0, v0=-0.2, method=method, t_eval=t_eval, friction="tanh",
                      epsilon=1e-3, rtol=1e-10, atol=1e-12)
    expected = 0.5 + (-0.2 - 0.5) * np.exp(-4.0 * t_eval)
    assert result.success
    np.testing.assert_allclose(result.V, expected, rtol=0, atol=_solver_error(1e-10, 1e-12, 0.5))


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
    # Halving h halves the error at t = 1 s (first order). Implicit Euler on V' = -lam (V - V_inf)
    # gives (1 + lam h)^(-t/h) = exp(-lam t) (1 + A h + B h^2 + ...) with A = lam^2 t / 2 and
    # B = lam^4 t^2 / 8 - lam^3 t / 3, so e(h) / e(h/2) = 2 + (B / A) h + O(h^2); lam = c/m = 4,
    # t = 1: B / A = 4/3. The O(h^2) rest is O(lam h) = 0.4 % of the h term at h = 1e-3:
    # atol = 10 % of the smallest h term.
    plant = Plant(ContactSet([10.0], [1.0]), mass=0.5, damping=2.0)
    exact = 0.5 - 0.7 * np.exp(-4.0)
    steps = np.array([1e-3, 5e-4, 2.5e-4, 1.25e-4])
    errors = np.array([abs(simulate(plant, 1.0, v0=-0.2, method="moreau", step=h).V[-1] - exact)
                       for h in steps])
    ratios = errors[:-1] / errors[1:]
    leading = 4.0 / 3.0 * steps[:-1]
    np.testing.assert_allclose(ratios, 2.0 + leading, rtol=0, atol=0.1 * leading.min())


def test_moreau_first_order_on_startup_events() -> None:
    # Startup through several contact speeds: the error of each crossing time is below one
    # step, so the max |V error| against the rational exact solution is <= h * F_tot / m
    # (the speed change over one step) for every h.
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
    # second method. The law is monotone, so implicit Euler is contractive: its global error is
    # at most the sum of its local errors, (h/2) * total variation of dV/dt <= (h/2) 2 F_tot/m
    # (dV/dt runs once from -F_tot/m to 0); plus Radau's own error on |V| <= 0.3.
    plant = Plant(ContactSet([-0.3, 0.0, 0.25], np.full(3, 2.0 / 3)), mass=1.0,
                  motors=Motors(compliance=0.05))
    t_eval = np.linspace(0.0, 2.0, 41)
    moreau = simulate(plant, 2.0, v0=0.3, method="moreau", step=1e-4, t_eval=t_eval)
    radau = simulate(plant, 2.0, v0=0.3, method="radau", t_eval=t_eval, rtol=1e-10, atol=1e-13)
    h, accel, radau_error = 1e-4, 2.0, _solver_error(1e-10, 1e-13, 0.3)
    np.testing.assert_allclose(moreau.V, radau.V, rtol=0, atol=h * accel + radau_error)
    # The body is inside the middle contact's linear zone (width k f = 0.033 m/s) by t ~ 0.4 s
    # (0.05 m/s at 2 N, then 0.25 m/s at 2/3 N), then decays with m k = 0.05 s for >= 1.5 s.
    settled = 0.05 * (2.0 / 3.0) * np.exp(-1.5 / 0.05)
    assert radau.V[-1] == pytest.approx(plant.equilibrium()[0], rel=0, abs=settled + radau_error)


def test_moreau_motor_lag_matches_smooth_solver() -> None:
    # Lagged motors (tau = 30 ms) switching their commands at t = 0.5 s by at most D = 0.4 m/s.
    # Implicit Euler on a lag: D ((1 + h/tau)^-k - exp(-k h/tau)) ~ D (k h^2 / 2 tau^2) e^(-kh/tau),
    # largest at k h = tau: D h / (2 e tau) (the motors are independent of V: their only error).
    # The body adds its sliding error (first order, <= h F_tot/m as in the compliant test) and
    # the tanh offset (<= 10 eps, the stability suite's factor); plus Radau's own error.
    commands = PiecewiseConstant([0.5], [[0.1, 0.2, -0.3], [-0.2, 0.3, 0.1]])
    plant = Plant(ContactSet([0.1, 0.2, -0.3], np.full(3, 2.0 / 3)), mass=1.0,
                  motors=Motors(lag=0.03), commands=commands)
    t_eval = np.linspace(0.0, 1.5, 31)
    moreau = simulate(plant, 1.5, method="moreau", step=1e-4, t_eval=t_eval)
    radau = simulate(plant, 1.5, method="radau", friction="tanh", epsilon=1e-6, rtol=1e-9,
                     atol=1e-12, t_eval=t_eval)
    assert moreau.success and radau.success
    h, tau, jump, eps = 1e-4, 0.03, 0.4, 1e-6
    radau_error = _solver_error(1e-9, 1e-12, 0.3)
    motor_error = jump * h / (2 * np.e * tau)
    np.testing.assert_allclose(moreau.contact_speeds, radau.contact_speeds, rtol=0,
                               atol=motor_error + radau_error)
    np.testing.assert_allclose(moreau.V, radau.V, rtol=0,
                               atol=motor_error + h * 2.0 + 10 * eps + radau_error)


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
    # RK45 on sign() chatters around the median of 11 contacts: it must stop at its step
    # budget (deterministic; the wall clock is only a guard that never decides here).
    plant = _random_plant(rng)
    result = simulate(plant, 5.0, method="rk45", friction="sign",
                      budget=Budget(wall_time=600.0, max_steps=20_000))
    assert result.status is SimulationStatus.MAX_STEPS, result.message
    assert result.t_final < 5.0
    assert np.all(np.isfinite(result.V))
    assert result.message.startswith(result.status.value)


def test_step_budget_counts_evaluations(rng: np.random.Generator) -> None:
    plant = _random_plant(rng)
    result = simulate(plant, 5.0, method="lsoda", friction="sign", budget=Budget(max_steps=2000))
    assert result.status is SimulationStatus.MAX_STEPS
    assert result.n_evaluations <= 2001                  # the refused call is counted, not run
    moreau = simulate(plant, 5.0, method="moreau", step=1e-3, budget=Budget(max_steps=100))
    assert moreau.status is SimulationStatus.MAX_STEPS
    assert moreau.n_steps <= 101 and moreau.t_final == pytest.approx(0.1, abs=1e-12)


def test_casadi_step_budget(rng: np.random.Generator) -> None:
    plant = _random_plant(rng)
    result = simulate(plant, 5.0, method="casadi", epsilon=1e-8, budget=Budget(max_steps=3))
    assert result.status is SimulationStatus.MAX_STEPS
    assert result.t.size == 1                            # casadi returns no partial trajectory


# -- casadi against the plant's own friction laws ----------------------------------------------
@pytest.mark.parametrize("friction", ["tanh", "stribeck"])
def test_casadi_right_hand_side_is_the_plant_law(friction: str, rng: np.random.Generator) -> None:
    import casadi as ca          # (here: only the casadi tests load casadi)

    from toolkit.simulation._casadi import casadi_right_hand_side   # (imports casadi)

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
    # Same smooth ODE, two integrators at rtol 1e-10, atol 1e-12 on |V| <= 0.35: the sum of
    # their two global errors.
    plant = _random_plant(rng, 7)
    t_eval = np.linspace(0.0, 2.0, 21)
    options = {"friction": "stribeck", "epsilon": 1e-2, "rtol": 1e-10, "atol": 1e-12}
    a = simulate(plant, 2.0, method="casadi", t_eval=t_eval, **options)
    b = simulate(plant, 2.0, method="radau", t_eval=t_eval, **options)
    np.testing.assert_allclose(a.V, b.V, rtol=0, atol=2 * _solver_error(1e-10, 1e-12, 0.35))


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
    # speed (measured 0.4 eps; 10 eps allowed); plus the solver's global error on |V| <= 0.35.
    ("radau", {"friction": "tanh", "epsilon": 1e-8, "rtol": 1e-8, "atol": 1e-12},
     10 * 1e-8 + _solver_error(1e-8, 1e-12, 0.35)),
    ("casadi", {"friction": "tanh", "epsilon": 1e-6, "rtol": 1e-10, "atol": 1e-12},
     10 * 1e-6 + _solver_error(1e-10, 1e-12, 0.35)),
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


# -- numerical failures become a status ---------------------------------------------------------
@pytest.mark.parametrize("method, options", [
    *[(solver, {"friction": friction}) for solver in SCIPY for friction in ("sign", "tanh")],
    ("moreau", {"step": 1e-3}), ("casadi", {"friction": "tanh"}),
])
def test_overflowing_plant_fails_with_a_status(method: str, options: dict) -> None:
    # F_ext / m = 1e300 / 1e-8 = 1e308 m/s^2 is finite (Plant accepts it), but V(2 s) = 2e308
    # overflows a double (max ~1.8e308) during the run. Every method must stop with FAILED
    # (not raise, not run on until the wall-clock budget: LSODA used to).
    plant = Plant(ContactSet([0.1]), mass=1e-8, external_force=1e300)
    result = simulate(plant, 2.0, method=method, budget=Budget(wall_time=600.0, max_steps=100_000),
                      **options)
    if method == "lsoda":
        # LSODA shrinks its step until t + h == t and never reaches the overflow: it stalls,
        # and the step budget stops it with its own status (the wall clock is only a guard).
        assert result.status in (SimulationStatus.FAILED, SimulationStatus.MAX_STEPS), result.message
    else:
        assert result.status is SimulationStatus.FAILED, result.message
        assert result.message.startswith(result.status.value)
    assert np.all(np.isfinite(result.V))                  # only the finite part is returned


def test_plant_whose_acceleration_overflows_is_refused() -> None:
    # F_ext / m = 1e300 / 1e-300 = 1e600 m/s^2 is not a double: refused when built.
    with pytest.raises(ParameterError, match="'mass'"):
        Plant(ContactSet([0.1]), mass=1e-300, external_force=1e300)


@pytest.mark.parametrize("error", [ValueError("array must not contain infs or NaNs"),
                                   np.linalg.LinAlgError("Singular matrix"),
                                   ZeroDivisionError("float division by zero")])
def test_scipy_solver_errors_map_to_failed(error: Exception) -> None:
    def raising() -> None:
        raise error

    with pytest.raises(BudgetExceeded) as stop:
        _solver_call("radau", raising)
    assert stop.value.status is SimulationStatus.FAILED
    assert stop.value.detail == f"Radau: {error}"


def test_scipy_own_value_error_maps_to_failed() -> None:
    # A real scipy refusal (non-finite initial state) goes through the same mapping.
    with pytest.raises(BudgetExceeded, match="must be finite") as stop:
        _solver_call("bdf", scipy.integrate.BDF, lambda t, y: y, 0.0, np.array([np.nan]), 1.0)
    assert stop.value.status is SimulationStatus.FAILED
