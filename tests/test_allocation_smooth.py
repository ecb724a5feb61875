"""Tests of toolkit.allocation._smooth: compliant contacts and continuous patches (casadi)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import stats

from toolkit.allocation import FrictionFraction, Viscosity, allocate
from toolkit.allocation._problem import AllocationStatus, build_problem
from toolkit.allocation._smooth import (allocate_smooth, compliant_force, patch_force,
                                        piecewise_linear_errors)
from toolkit.allocation.targets import ForceCurve
from toolkit.model import ContactDistribution, ContactSet
from toolkit.errors import ParameterError
from toolkit.model import Motors, Plant


def test_compliant_contacts_reproduce_a_viscosity_slope_exactly():
    # Five contacts of 0.2 N, compliance k = 0.1 (m/s)/N: each is a ramp of slope 1/k and
    # width 2 k f = 0.04 m/s; abutting ramps at spacing 0.04 give exactly slope 1/k = 10 N s/m.
    k, f = 0.1, 0.2
    problem = build_problem(Viscosity(1.0 / k, 0.0, 0.1), ContactSet(np.zeros(5), np.full(5, f)),
                            speed_limits=(-0.35, 0.35))
    result = allocate_smooth(problem, compliance=k)
    # Soft-clip corner width 1e-6 in the last stage: positions within a few 1e-8 m/s.
    np.testing.assert_allclose(np.sort(result.speeds), [-0.08, -0.04, 0.0, 0.04, 0.08],
                               rtol=0, atol=1e-7)
    assert result.error_sup <= 1e-6 * problem.total_force   # exact evaluation, not the solver
    V = np.array([-0.05, 0.05])
    slope = np.diff(compliant_force(V, result.speeds, np.full(5, f), k)) / np.diff(V)
    assert slope[0] == pytest.approx(-1.0 / k, rel=1e-5, abs=0)
    # Second method: the plant's compliant zero set (the equilibrium) is the centre.
    plant = Plant(ContactSet(result.speeds, np.full(5, f)), mass=1.0,
                  motors=Motors(compliance=k))
    lo, hi = plant.equilibrium()
    assert lo == pytest.approx(0.0, abs=1e-7) and hi == pytest.approx(0.0, abs=1e-7)
    assert result.method == "casadi" and result.extra["model"] == "compliant"


def test_uniform_patch_matches_a_viscosity_in_closed_form():
    # Uniform patch on [a, b]: slope 2 F_tot / (b - a), zero at (a + b) / 2.
    total, slope, center = 1.0, 5.0, 0.05
    result = allocate(Viscosity(slope, center, 0.1),
                      ContactDistribution(stats.uniform(-1.0, 2.0), total))
    half = total / slope
    np.testing.assert_allclose(result.speeds, [center - half, center + half], rtol=0, atol=1e-6)
    assert result.error_sup <= 1e-6 * total
    # The achieved distribution is the reported patch (second evaluation: scipy's cdf).
    V = np.linspace(-0.05, 0.15, 7)
    np.testing.assert_allclose(result.contacts.force(V), -slope * (V - center),
                               rtol=0, atol=1e-5)
    assert result.status in (AllocationStatus.OPTIMAL, AllocationStatus.FEASIBLE_WITH_GAP)


def test_patch_friction_fraction_uses_the_whole_band():
    # A constant force -0.5 F_tot over (-0.1, 0.1) is not a uniform patch's law: the error is
    # positive and uncertified (bound 0, gap = error).
    result = allocate(FrictionFraction(0.5, 0.1), ContactDistribution(stats.uniform(-1, 2), 1.0))
    assert result.error_sup > 0
    assert result.bound == 0.0 and result.gap == result.error_sup
    assert "no certified lower bound" in result.message


@settings(deadline=None, max_examples=25)
@given(st.integers(min_value=0, max_value=10_000))
def test_piecewise_linear_errors_match_dense_sampling(seed):
    rng = np.random.default_rng(seed)
    n, k = 4, 0.05
    speeds, forces = rng.uniform(-0.3, 0.3, n), rng.uniform(0.1, 1.0, n)
    grid = np.sort(rng.uniform(-0.3, 0.3, 5))
    curve = ForceCurve(grid, np.sort(rng.uniform(-2.0, 2.0, 5))[::-1])
    sup, l1 = piecewise_linear_errors(
        curve, lambda V: compliant_force(V, speeds, forces, k),
        np.concatenate((speeds - k * forces, speeds + k * forces)))
    dense = np.linspace(grid[0], grid[-1], 200_001)
    diff = np.abs(compliant_force(dense, speeds, forces, k) - curve.value_right(dense))
    # Both sides are Lipschitz with constant L <= 1/k + max target slope; sampling at
    # spacing h misses at most L h / 2 of the sup and L h * width of the L1.
    lipschitz = 1.0 / k * n + np.max(np.abs(np.diff(curve.forces) / np.maximum(
        np.diff(curve.speeds), 1e-300)))
    h = dense[1] - dense[0]
    assert diff.max() <= sup + 1e-12
    assert sup <= diff.max() + lipschitz * h
    trapezoid = float(np.sum(0.5 * (diff[1:] + diff[:-1]) * h))
    assert l1 == pytest.approx(trapezoid, rel=0, abs=lipschitz * h * (grid[-1] - grid[0]) + 1e-12)


def test_patch_force_closed_form():
    np.testing.assert_allclose(patch_force([-1.0, 0.0, 0.5, 2.0], 0.0, 1.0, 3.0),
                               [3.0, 3.0, 0.0, -3.0], rtol=0, atol=1e-15)


def test_refusals():
    problem = build_problem(Viscosity(1.0, 0.0, 0.1), ContactSet(np.zeros(3)))
    with pytest.raises(ParameterError, match="quantile"):
        allocate_smooth(problem)                  # Coulomb contacts: not this method
    with pytest.raises(ParameterError, match="compliance"):
        allocate_smooth(problem, compliance=-1.0)


def test_compliant_result_is_self_consistent_with_the_plant_law():
    # The reviewer's case: ten unit contacts, compliance 0.01 (m/s)/N. The result records
    # the compliance, and its contacts driven by motors of that compliance (second method:
    # the plant's per-contact law, summed) reproduce error_sup; their Coulomb staircase
    # does not (it is another law).
    from toolkit.allocation import evaluate_errors      # public: the message points to it

    k, v_max = 0.01, 0.35
    target = Viscosity(10 / v_max, 0.0, v_max)
    result = allocate(target, ContactSet(np.zeros(10)), compliance=k,
                      speed_limits=(-v_max, v_max))
    assert result.compliance == k and result.extra["compliance"] == k
    assert "compliance k = 0.01" in result.message
    plant = Plant(result.contacts, mass=1.0, motors=Motors(compliance=k))
    # Samples: a dense grid plus every kink of the compliant law (v_i +- k f_i) and the band
    # ends; the difference is linear between kinks, so its max over these samples is the
    # sup, to rounding (1e-12 N: sums of ten O(1) terms).
    kinks = np.concatenate((result.speeds - k, result.speeds + k))
    V = np.unique(np.concatenate((np.linspace(-v_max, v_max, 2001),
                                  kinks[np.abs(kinks) <= v_max])))
    achieved = np.array([plant.contact_forces(float(v), result.speeds).sum() for v in V])
    sampled = float(np.max(np.abs(achieved - result.curve.value_right(V))))
    assert sampled == pytest.approx(result.error_sup, rel=0, abs=1e-12)
    # The evaluation helper accepts the compliance and agrees; the Coulomb reading differs.
    sup, _ = evaluate_errors(result.curve, result.contacts, compliance=k)
    assert sup == pytest.approx(result.error_sup, rel=0, abs=1e-12)
    coulomb, _ = evaluate_errors(result.curve, result.contacts)
    assert coulomb > result.error_sup + 0.1          # 1.036 vs 0.750 N on this case


def test_patch_respects_scalar_speed_limits_and_reports_the_forced_bound():
    # A standard normal patch, target slope 10 N s/m on [-0.35, 0.35], F_tot = 10 N, limits
    # +-0.1 m/s. Closed form: for V < -0.1 every contact is above V, F = +10 N, against
    # T(-0.1) = 1 N: the forced error is 9 N, a certified bound. The patch [-0.1, 0.1] has
    # slope 2 F_tot / 0.2 = 100 N s/m, within 9 N of the target on [-0.1, 0.1] too, so the
    # optimum is 9 N.
    result = allocate(Viscosity(10.0, 0.0, 0.35), ContactDistribution(stats.norm(), 10.0),
                      speed_limits=(-0.1, 0.1))
    assert -0.1 <= result.speeds[0] < result.speeds[1] <= 0.1
    assert result.bound == pytest.approx(9.0, rel=1e-15, abs=0)   # two roundings of 10 * 0.1
    # Second method: the achieved patch's force (scipy's cdf) sampled on the band.
    V = np.linspace(-0.35, 0.35, 7001)
    sampled = np.max(np.abs(result.contacts.force(V) - (-10.0 * V)))
    # The patch is at most 100 N s/m steep: sampling at h = 1e-4 misses <= 100 h / 2.
    assert sampled <= result.error_sup + 1e-12
    assert result.error_sup <= sampled + 100 * 1e-4 / 2
    assert result.error_sup >= result.bound
    assert result.status is AllocationStatus.OPTIMAL


@pytest.mark.parametrize("kwargs, word", [
    ({"speed_limits": ([-0.1, -0.2], 0.1)}, "pair of scalars"),
    ({"rate_limit": 1.0, "dt": 0.1}, "rate_limit"),
    ({"fixed": [0]}, "fixed"),
    ({"liftable": [0]}, "liftable"),
])
def test_patch_refuses_per_contact_arguments(kwargs, word):
    with pytest.raises(ParameterError, match=word):
        allocate(Viscosity(10.0, 0.0, 0.35), ContactDistribution(stats.norm(), 10.0), **kwargs)
