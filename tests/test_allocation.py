"""Tests of allocate(), the exact error evaluation, the quantile construction, projections
and refusals (toolkit/allocation/__init__.py, _problem.py, _evaluate.py, _quantile.py)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from toolkit import ContactSet
from toolkit.allocation import (
    AllocationStatus,
    EquilibriumSpeed,
    ForceCurve,
    FrictionFraction,
    Viscosity,
    allocate,
)
from toolkit.allocation._evaluate import evaluate_errors, failure_margin
from toolkit.errors import ParameterError, ParameterTypeError

V_MAX = 0.35          # docs/physics.md section 5: |v_i| <= 0.35 m/s


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(20250114)


# -- exact error evaluation ---------------------------------------------------------------------
def _dense_errors(curve: ForceCurve, contacts: ContactSet, m: int) -> tuple[float, float, float]:
    """Second method: sample on a fine grid that avoids contact speeds."""
    lo, hi = curve.band
    grid = np.linspace(lo, hi, m)
    grid = grid[~np.isin(grid, contacts.speeds)]
    diff = np.abs(curve.value_left(grid) - contacts.force(grid))
    return float(diff.max()), float(np.trapezoid(diff, grid)), (hi - lo) / (m - 1)


def test_evaluation_matches_dense_sampling(rng: np.random.Generator) -> None:
    for _ in range(5):
        n = 7
        contacts = ContactSet(rng.uniform(-0.4, 0.4, n), rng.uniform(0.5, 2.0, n))
        xs = np.sort(rng.uniform(-0.35, 0.35, 5))
        curve = ForceCurve(xs, np.sort(rng.uniform(-8, 8, 5))[::-1])
        sup, l1 = evaluate_errors(curve, contacts)
        d_sup, d_l1, h = _dense_errors(curve, contacts, 400_001)
        slope = float(np.max(np.abs(np.diff(curve.forces) / np.diff(xs))))
        # Sampling misses the sup by at most slope * h; the trapezoid rule errs by at most
        # (one jump of 2 F_tot + slope h) * h per contact and per target kink.
        assert d_sup <= sup + 1e-12
        assert sup - d_sup <= slope * h + 1e-12
        assert abs(l1 - d_l1) <= (n + 5) * (2 * contacts.total_force + slope * h) * h


def test_evaluation_uses_the_stiction_interval_at_contact_speeds() -> None:
    # Five at -0.35 and five at +0.35 against a zero target on the closed band [-0.35, 0.35]:
    # inside the band the force is exactly 0; at the ends the interval contains 0.
    contacts = ContactSet([-V_MAX] * 5 + [V_MAX] * 5)
    sup, l1 = evaluate_errors(ForceCurve([-V_MAX, V_MAX], [0.0, 0.0]), contacts)
    assert sup == 0.0 and l1 == 0.0
    # A single-speed band at a contact speed: the target 3 N lies in [-10, 10].
    assert evaluate_errors(ForceCurve([0.1, 0.1], [3.0, 3.0]), ContactSet([0.1] * 10))[0] == 0.0


def test_weighted_l1_is_the_quadrature_at_the_samples() -> None:
    contacts = ContactSet([0.0, 0.2], [1.0, 1.0])
    curve = ForceCurve([-0.1, 0.1, 0.3], [1.0, 1.0, 1.0], weights=[0.5, 1.0, 2.0])
    # Achieved: +2 at -0.1, 0 at 0.1, -2 at 0.3 -> |diff| = 1, 1, 3.
    _, l1 = evaluate_errors(curve, contacts)
    assert l1 == pytest.approx(0.5 * 1 + 1.0 * 1 + 2.0 * 3, rel=1e-15, abs=0)


# -- quantile construction: closed forms ----------------------------------------------------------
@pytest.mark.parametrize("n", [1, 2, 3, 10, 11, 100, 1000])
def test_quantile_error_is_f_tot_over_n_on_a_full_range_target(n: int) -> None:
    total = 2.0 * n
    target = Viscosity(slope=total / V_MAX, center=0.0, band=V_MAX)   # spans [-F_tot, F_tot]
    result = allocate(target, ContactSet(np.zeros(n), np.full(n, 2.0)))
    assert result.method == "quantile"
    assert result.status is AllocationStatus.OPTIMAL
    # Closed form F_tot / N (docs/physics.md section 8); rtol: a few roundings of the quantiles.
    assert result.error_sup == pytest.approx(total / n, rel=1e-12, abs=0)
    assert result.bound == pytest.approx(total / n, rel=1e-15, abs=0)
    assert abs(result.gap) < 1e-12
    # The paper's viscosity configuration: uniformly spaced speeds, spacing 2 v_max / N.
    # Each speed is the quantile x0 + share (x1 - x0) on [-v_max, v_max], a few roundings
    # (<= 8 eps relative of 2 v_max) from exact; a spacing carries two of them.
    np.testing.assert_allclose(np.diff(np.sort(result.speeds)), 2 * V_MAX / n,
                               rtol=0, atol=2 * 8 * np.finfo(float).eps * 2 * V_MAX)


@settings(deadline=None, max_examples=40)
@given(n=st.integers(1, 40), fraction=st.floats(-1.0, 1.0))
def test_quantile_meets_the_grid_distance_bound_on_constant_targets(n: int, fraction: float
                                                                  ) -> None:
    # Constant target c: the best staircase is the nearest achievable level F (1 - 2k/n),
    # error (2 F / n) * dist(n (1 + fraction) / 2, Z).
    result = allocate(FrictionFraction(fraction, V_MAX), ContactSet(np.zeros(n)),
                      speed_limits=(-V_MAX, V_MAX))
    g = n * (1 + fraction) / 2
    expected = 2.0 * n / n * abs(g - np.round(g))
    assert result.error_sup == pytest.approx(expected, rel=1e-12, abs=1e-12)
    assert abs(result.gap) < 1e-12


def _random_curve(seed: int, n: int) -> ForceCurve:
    rng = np.random.default_rng(seed)
    xs = np.sort(rng.uniform(-0.3, 0.3, 4))
    return ForceCurve(xs, np.sort(rng.uniform(-n, n, 4))[::-1])


def _rounding_allowance(curve: ForceCurve) -> float:
    """Error (N) that rounding the quantile speeds can add: each speed is a few roundings
    (8 eps relative) of numbers of magnitude <= 0.3 m/s, and the target moves by its
    steepest slope per unit of speed (the random curves can be very steep)."""
    slope = float(np.max(np.abs(np.diff(curve.forces) / np.diff(curve.speeds))))
    return 8 * np.finfo(float).eps * 0.3 * slope


@settings(deadline=None, max_examples=12)
@given(seed=st.integers(0, 10**6), n=st.integers(1, 3))
def test_quantile_is_optimal_on_random_curves_against_brute_force(seed: int, n: int) -> None:
    # Second method: the brute-force optimum (enumeration of every ordered grouping, bisection
    # to 2 F_tot / 2^40 < 1e-11 N). The quantile's bound is a valid lower bound on it and its
    # error attains it.
    from test_allocation_milp import brute_force

    curve = _random_curve(seed, n)
    result = allocate(curve, ContactSet(np.zeros(n)))
    assert result.method == "quantile"
    inf = np.full(n, np.inf)
    optimum = brute_force(curve, np.ones(n), -inf, inf, np.zeros(n, bool))
    assert result.bound <= optimum + 1e-9
    assert result.error_sup == pytest.approx(optimum, rel=0,
                                             abs=1e-9 + _rounding_allowance(curve))


@pytest.mark.parametrize("seed, n", [(1, 5), (2, 6), (3, 7), (4, 8)])
def test_quantile_is_optimal_on_random_curves_against_the_milp(seed: int, n: int) -> None:
    # Second method for larger n: the MILP (HiGHS closes to 1e-9 F_tot; its bound is lowered
    # by 1e-8 F_tot). Its error can be no lower than the quantile's optimum, its bound no
    # higher, and the two optima agree to the MILP's tolerance.
    curve = _random_curve(seed, n)
    contacts = ContactSet(np.zeros(n))
    quant = allocate(curve, contacts, speed_limits=(-V_MAX, V_MAX))
    milp = allocate(curve, contacts, speed_limits=(-V_MAX, V_MAX), method="milp")
    tol = 1e-7 * n + _rounding_allowance(curve)
    assert quant.method == "quantile" and milp.method == "milp"
    assert milp.bound <= quant.error_sup + tol
    assert quant.bound <= milp.error_sup + tol
    assert quant.error_sup == pytest.approx(milp.error_sup, rel=0, abs=tol)
    assert quant.gap <= 1e-12 * n + _rounding_allowance(curve)  # gap < 1e-12


def test_motor_limits_clip_the_quantile_range_and_the_bound() -> None:
    n, slope = 10, 10.0 / V_MAX
    contacts = ContactSet(np.zeros(n))
    # Band [-0.35, 0.35] but contacts limited to [-0.2, 0.35]: on [-0.35, -0.2) the force is
    # forced to +F_tot while the target is below it; worst at V -> -0.2: F_tot - T(-0.2).
    result = allocate(Viscosity(slope, 0.0, V_MAX), contacts, speed_limits=(-0.2, V_MAX))
    forced = 10.0 - slope * 0.2
    assert result.bound == pytest.approx(max(forced, 10.0 / n), rel=1e-14, abs=0)
    assert result.error_sup == pytest.approx(result.bound, rel=1e-12, abs=0)
    assert np.all(result.speeds >= -0.2)
    # Box entirely below the band: every contact below, F = -F_tot on the band.
    below = allocate(ForceCurve([0.5, 1.0], [2.0, -1.0]), contacts, speed_limits=(-V_MAX, V_MAX))
    assert below.error_sup == pytest.approx(2.0 + 10.0, rel=1e-15, abs=0)
    assert below.gap == 0.0


def test_quantile_agrees_with_the_milp_on_equal_magnitudes() -> None:
    # Second method: the mixed-integer program on the same equal-magnitude problem.
    target = ForceCurve([-0.3, -0.1, 0.2, 0.3], [5.0, 4.0, -3.0, -5.5])
    contacts = ContactSet(np.zeros(6))
    quant = allocate(target, contacts, method="quantile")
    milp = allocate(target, contacts, method="milp")
    # HiGHS closes to 1e-9 F_tot and its bound is lowered by 1e-8 F_tot (F_tot = 6 N):
    # both within 1e-7 N of the closed form.
    assert milp.error_sup == pytest.approx(quant.error_sup, rel=0, abs=1e-7)
    assert milp.bound == pytest.approx(quant.bound, rel=0, abs=1e-7)


def test_quantile_viscosity_error_at_two_sizes() -> None:
    # The quantile method's error on a viscosity over N equal contacts is one contact's force
    # (the staircase's step), at N = 10 and 1e5 (its speed: python -m toolkit.bench allocate).
    for n in (10, 100_000):
        contacts = ContactSet(np.zeros(n))
        target = Viscosity(n / V_MAX, 0.0, V_MAX)
        result = allocate(target, contacts, method="quantile")
        assert result.error_sup == pytest.approx(1.0, rel=1e-9, abs=0)


# -- the paper's configurations ----------------------------------------------------------------
@pytest.mark.parametrize("k", range(6))
def test_friction_fraction_gives_the_papers_split(k: int) -> None:
    result = allocate(FrictionFraction(k / 5, V_MAX), ContactSet(np.zeros(10)),
                      speed_limits=(-V_MAX, V_MAX))
    speeds = np.sort(result.speeds)
    np.testing.assert_array_equal(speeds, [-V_MAX] * (5 + k) + [V_MAX] * (5 - k))
    assert result.error_sup == 0.0 and result.bound == 0.0


@pytest.mark.parametrize("k", range(1, 6))
def test_friction_fraction_braking_time_by_simulation(k: int) -> None:
    simulation = pytest.importorskip("toolkit.simulation")
    from toolkit.model import Plant

    mass, f = 1.0, 0.2                        # F_tot = 2 N, F_tot / m = 2 m/s^2 (docs/physics.md section 6)
    result = allocate(FrictionFraction(k / 5, V_MAX), ContactSet(np.zeros(10), np.full(10, f)),
                      speed_limits=(-V_MAX, V_MAX))
    run = simulation.simulate(Plant(result.contacts, mass), 2.0, v0=V_MAX)
    sticks = [e for e in run.events if e.kind == "stick"]
    expected = mass * 2 * V_MAX / (2.0 * k / 5)          # dT = m 2 v_max / (F_tot mu/mu0)
    assert sticks and sticks[0].speed == pytest.approx(-V_MAX, abs=1e-12)
    assert sticks[0].time == pytest.approx(expected, rel=1e-12, abs=0)   # exact simulator


def test_viscosity_allocation_decays_like_the_staircase_by_simulation() -> None:
    simulation = pytest.importorskip("toolkit.simulation")
    from toolkit.model import Plant

    n, mass = 10, 0.5
    result = allocate(Viscosity(10.0 / V_MAX, 0.0, V_MAX), ContactSet(np.zeros(n)))
    levels = np.sort(result.speeds)
    run = simulation.simulate(Plant(result.contacts, mass), 1.0, v0=0.3)
    # Closed form: from 0.3 down to the zero-force band edge levels[5] the body crosses
    # plateaus of constant force; time = sum m * width / |F| on each.
    edges = np.concatenate(([0.3], levels[levels < 0.3][::-1]))
    edges = edges[edges >= levels[n // 2]]
    mids = 0.5 * (edges[:-1] + edges[1:])
    expected = float(np.sum(mass * -np.diff(edges) / -result.contacts.force(mids)))
    sticks = [e for e in run.events if e.kind == "stick"]
    assert sticks[0].speed == pytest.approx(levels[n // 2], abs=1e-12)
    assert sticks[0].time == pytest.approx(expected, rel=1e-12, abs=0)


def test_equilibrium_speed_survives_margin_failures_by_simulation() -> None:
    simulation = pytest.importorskip("toolkit.simulation")
    from toolkit.model import Plant

    result = allocate(EquilibriumSpeed(0.1, margin=4), ContactSet(np.zeros(10)),
                      speed_limits=(-V_MAX, V_MAX))
    assert result.status is AllocationStatus.OPTIMAL
    assert failure_margin(result.contacts, 0.1) >= 4
    broken = result.speeds.copy()
    broken[:4] = V_MAX                       # four contacts fail at the top speed
    for v0 in (-0.3, 0.3):
        run = simulation.simulate(Plant(ContactSet(broken), 1.0), 2.0, v0=v0)
        assert float(run.V[-1]) == pytest.approx(0.1, abs=1e-12)
    # Margin 6 > N/2 cannot be met by 10 equal contacts.
    too_many = allocate(EquilibriumSpeed(0.1, margin=6), ContactSet(np.zeros(10)),
                        speed_limits=(-V_MAX, V_MAX))
    assert too_many.status is AllocationStatus.INFEASIBLE


# -- projections ---------------------------------------------------------------------------------
def test_increasing_target_is_projected_by_isotonic_regression() -> None:
    result = allocate(ForceCurve([0.0, 1.0], [-1.0, 1.0]), ContactSet(np.zeros(4)))
    proj = result.projection
    assert result.status is AllocationStatus.PROJECTED and "increasing" in proj.reasons
    # Equal trapezoid weights: the pooled mean 0; distances: sup 1, integral of |1 - 2V| = 1/2.
    np.testing.assert_allclose(proj.curve.forces, [0.0, 0.0], rtol=0, atol=1e-15)
    assert proj.distance_sup == pytest.approx(1.0, rel=1e-15, abs=0)
    assert proj.distance_l1 == pytest.approx(0.5, rel=1e-15, abs=0)


def test_forces_beyond_f_tot_are_clipped_with_exact_kinks() -> None:
    total = 10.0
    result = allocate(Viscosity(2 * total / V_MAX, 0.0, V_MAX), ContactSet(np.zeros(10)))
    proj = result.projection
    assert "forces beyond +-F_tot" in proj.reasons
    np.testing.assert_allclose(proj.curve.speeds, [-V_MAX, -V_MAX / 2, V_MAX / 2, V_MAX],
                               rtol=1e-14, atol=1e-16)
    np.testing.assert_allclose(proj.curve.forces, [total, total, -total, -total], rtol=0, atol=0)
    # Excess is a triangle of height F_tot and base v_max/2 at each end.
    assert proj.distance_sup == pytest.approx(total, rel=1e-14, abs=0)
    assert proj.distance_l1 == pytest.approx(2 * 0.5 * total * V_MAX / 2, rel=1e-13, abs=0)


def test_non_finite_values_are_dropped_or_clipped() -> None:
    target = ForceCurve([-0.3, 0.0, 0.1, 0.3], [np.inf, np.nan, 0.0, -2.0])
    result = allocate(target, ContactSet(np.zeros(4)))
    proj = result.projection
    assert "non-finite values" in proj.reasons
    np.testing.assert_array_equal(proj.curve.speeds, [-0.3, 0.1, 0.3])
    np.testing.assert_array_equal(proj.curve.forces, [4.0, 0.0, -2.0])
    assert proj.distance_sup == np.inf
    assert json.dumps(result.to_dict())            # inf reported as a string, JSON-able
    with pytest.raises(ParameterError, match="at least one finite"):
        allocate(ForceCurve([0.0, 1.0], [np.nan, np.nan]), ContactSet(np.zeros(4)))


def test_equilibrium_speed_beyond_limits_is_moved_to_the_nearest_limit() -> None:
    result = allocate(EquilibriumSpeed(0.5), ContactSet(np.zeros(4)), speed_limits=(-V_MAX, V_MAX))
    assert result.projection is not None
    assert "equilibrium speed beyond the limits" in result.projection.reasons
    np.testing.assert_array_equal(result.speeds, [V_MAX] * 4)
    assert result.projection.distance_l1 == pytest.approx(2 * 4 * 0.15, rel=1e-14, abs=0)


# -- refusals ------------------------------------------------------------------------------------
@pytest.mark.parametrize("target, limits, word", [
    (ForceCurve([0.0, 1.0], [-1.0, 1.0]), None, "non-increasing"),
    (Viscosity(100.0, 0.0, V_MAX), None, "within"),
    (ForceCurve([0.0, 1.0], [np.inf, 0.0]), None, "finite"),
    (Viscosity(1.0, 0.0, 0.5), (-V_MAX, V_MAX), "reach"),
    (EquilibriumSpeed(0.5), (-V_MAX, V_MAX), "reach"),
])
def test_strict_refuses_unrealizable_targets(target, limits, word) -> None:
    with pytest.raises(ParameterError, match=word) as info:
        allocate(target, ContactSet(np.zeros(4)), speed_limits=limits, strict=True)
    assert "parameter of allocate must" in str(info.value) and "strict=True" in str(info.value)


@pytest.mark.parametrize("kwargs, error, word", [
    ({"method": "quantil"}, ParameterError, "Did you mean 'quantile'"),
    ({"speed_limits": (0.3, -0.3)}, ParameterError, "lo <= hi"),
    ({"speed_limits": 0.3}, ParameterTypeError, "pair"),
    ({"speed_limits": ([0.1] * 3, 0.3)}, ParameterError, "one entry per contact"),
    ({"rate_limit": 1.0}, ParameterError, "dt"),
    ({"rate_limit": -1.0, "dt": 0.1}, ParameterError, ">= 0"),
    ({"rate_limit": 1.0, "dt": 0.0}, ParameterError, "dt"),
    ({"fixed": [True, False]}, ParameterError, "shape"),
    ({"failed": [7]}, ParameterError, "indices"),
    # Non-integral and out-of-range indices are refused, not truncated (1.5 is not 1).
    ({"fixed": [1.5]}, ParameterError, "'fixed' parameter of allocate must hold integral"),
    ({"liftable": [0.999]}, ParameterError, "'liftable' parameter .* integral"),
    ({"failed": [-1]}, ParameterError, "'failed' parameter .* indices in \\[0, 3\\]"),
    ({"fixed": [np.nan]}, ParameterError, "integral"),
    ({"fixed": ["a"]}, ParameterTypeError, "fixed"),
    ({"strict": "yes"}, ParameterTypeError, "strict"),
    ({"time_limit": -1.0}, ParameterError, "time_limit"),
])
def test_bad_arguments_are_refused(kwargs, error, word) -> None:
    with pytest.raises(error, match=word):
        allocate(FrictionFraction(0.2, V_MAX), ContactSet(np.zeros(4)), **kwargs)


def test_bad_target_contacts_and_method_combinations_are_refused() -> None:
    with pytest.raises(ParameterTypeError, match="target"):
        allocate(0.3, ContactSet(np.zeros(4)))
    with pytest.raises(ParameterTypeError, match="contacts"):
        allocate(FrictionFraction(0.2, V_MAX), [0.0, 0.0])
    with pytest.raises(ParameterError, match="equal"):
        allocate(FrictionFraction(0.2, V_MAX), ContactSet(np.zeros(3), [1.0, 2.0, 3.0]),
                 method="quantile")


def test_strict_rate_limit_refusal_and_lenient_note() -> None:
    contacts = ContactSet([1.0, 0.0, 0.0, 0.0])       # contact 0 far above the limits
    with pytest.raises(ParameterError, match="rate_limit"):
        allocate(FrictionFraction(0.0, 0.2), contacts, speed_limits=(-V_MAX, V_MAX),
                 rate_limit=1.0, dt=0.1, strict=True)
    result = allocate(FrictionFraction(0.0, 0.2), contacts, speed_limits=(-V_MAX, V_MAX),
                      rate_limit=1.0, dt=0.1)
    assert result.speeds[0] == pytest.approx(0.9, rel=1e-15, abs=0)   # as near as it gets
    assert "cannot reach" in result.message


def test_result_to_dict_is_json_with_the_cli_keys() -> None:
    result = allocate(FrictionFraction(0.4, V_MAX), ContactSet(np.zeros(10)),
                      speed_limits=(-V_MAX, V_MAX))
    # allow_nan=False: strict JSON (no NaN/Infinity tokens), also for the MILP's extra stats.
    data = json.loads(json.dumps(result.to_dict(), allow_nan=False))
    milp = allocate(FrictionFraction(0.4, V_MAX), ContactSet(np.zeros(3), [1.0, 2.0, 3.0]),
                    speed_limits=(-V_MAX, (V_MAX, V_MAX, 0.3)), method="milp")
    assert json.loads(json.dumps(milp.to_dict(), allow_nan=False))["method"] == "milp"
    for key in ("speeds", "error_sup", "error_l1", "bound", "gap", "method", "status",
                "wall_time"):
        assert key in data
    assert data["status"] == "OPTIMAL" and data["method"] == "quantile"
    with pytest.raises(ValueError):
        result.speeds[0] = 0.0


def test_allocate_forwards_compliance_to_the_casadi_method():
    # The public verb reaches the compliant model: same closed form as the direct call
    # (abutting ramps of width 2 k f give slope 1/k; see test_allocation_smooth).
    from toolkit import ContactSet, Viscosity, allocate

    k, f = 0.1, 0.2
    result = allocate(Viscosity(1.0 / k, 0.0, 0.1), ContactSet(np.zeros(5), np.full(5, f)),
                      speed_limits=(-0.35, 0.35), compliance=k)
    assert result.method == "casadi"
    np.testing.assert_allclose(np.sort(result.speeds), [-0.08, -0.04, 0.0, 0.04, 0.08], rtol=0, atol=1e-7)


def test_compliance_with_a_coulomb_method_is_refused():
    from toolkit import ContactSet, ParameterError, Viscosity, allocate

    with pytest.raises(ParameterError, match="'method' parameter of allocate must be 'casadi'"):
        allocate(Viscosity(10.0, 0.0, 0.1), ContactSet(np.zeros(5)), method="quantile", compliance=0.1)
    with pytest.raises(ParameterError, match="'compliance' parameter of allocate must be >= 0"):
        allocate(Viscosity(10.0, 0.0, 0.1), ContactSet(np.zeros(5)), compliance=-1.0)


@pytest.mark.parametrize("scale", [2.0 ** -20, 1.0, 2.0 ** 20])
@pytest.mark.parametrize("n", [3, 8])
def test_quantile_allocation_scales_with_the_forces_exactly(scale: float, n: int) -> None:
    """Forces and target at ``2**-20``, 1 and ``2**20`` of the unit: the quantile speeds are
    the same to the bit (every level and share scales by a power of two), the error and the
    bound scale exactly, and the speeds are the ``(i - 1/2)/n`` quantiles of the linear target,
    ``V_max (2 (i - 1/2)/n - 1)`` (a few roundings of ``V_max``: rtol 8 eps). Mutants killed:
    the quantile's ``- 1/2`` to ``+ 1/2``, the total force dropped from the levels."""
    from toolkit.allocation._quantile import quantile_speeds

    def run(s: float):
        total = 2.0 * n * s
        return allocate(Viscosity(slope=total / V_MAX, center=0.0, band=V_MAX),
                        ContactSet(np.zeros(n), np.full(n, 2.0 * s)))

    result, reference = run(scale), run(1.0)
    assert result.method == "quantile"
    np.testing.assert_array_equal(result.speeds, reference.speeds)
    assert result.bound == reference.bound * scale and result.error_sup == reference.error_sup * scale
    expected = V_MAX * (2.0 * (np.arange(1, n + 1) - 0.5) / n - 1.0)
    np.testing.assert_allclose(np.sort(result.speeds), expected, rtol=0, atol=8 * np.finfo(float).eps * V_MAX)
    curve = ForceCurve([-V_MAX, V_MAX], [2.0 * n * scale, -2.0 * n * scale])
    np.testing.assert_allclose(quantile_speeds(curve, n, 2.0 * n * scale), expected, rtol=0,
                               atol=8 * np.finfo(float).eps * V_MAX)
