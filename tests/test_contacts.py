"""Tests of the contact model against closed forms, identities and brute force.

Tolerances: the model computes every force from prefix sums of at most N magnitudes, so
its rounding error is below N * eps * F_tot; ``atol=1e-12`` (in newtons, for F_tot of
order 1-100 N and N <= 60) is several orders above that and far below any physical step.
"""

from __future__ import annotations

import os

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import stats

from toolkit import ContactDistribution, ContactSet, ParameterError, ParameterTypeError
from toolkit.model.contacts import unequal_loads, weighted_median

SPEED = st.floats(-1.0, 1.0, allow_nan=False).map(lambda v: round(v, 3))
MAGNITUDE = st.floats(0.01, 10.0, allow_nan=False)


@st.composite
def contact_sets(draw, min_size=1, max_size=25, equal=False):
    n = draw(st.integers(min_size, max_size))
    speeds = draw(st.lists(SPEED, min_size=n, max_size=n))
    forces = None if equal else draw(st.lists(MAGNITUDE, min_size=n, max_size=n))
    return ContactSet(speeds, forces)


def brute_force(cs: ContactSet, V: np.ndarray) -> np.ndarray:
    """The N x M definition ``sum f_i sign(v_i - V)``: the second method."""
    return np.sum(cs.forces[:, None] * np.sign(cs.speeds[:, None] - V[None, :]), axis=0)


def probes(cs: ContactSet) -> np.ndarray:
    """Every contact speed, the midpoints between them, and points beyond both ends."""
    levels = np.unique(cs.speeds)
    mids = 0.5 * (levels[1:] + levels[:-1])
    return np.concatenate((levels, mids, [levels[0] - 1.0, levels[-1] + 1.0]))


@settings(max_examples=200, deadline=None)
@given(contact_sets())
def test_force_matches_brute_force(cs):
    V = probes(cs)
    np.testing.assert_allclose(cs.force(V), brute_force(cs, V), rtol=0, atol=1e-12)


@settings(max_examples=200, deadline=None)
@given(contact_sets())
def test_force_is_nonincreasing_and_spans_total(cs):
    V = np.sort(np.concatenate((probes(cs), np.linspace(-2, 2, 101))))
    F = cs.force(V)
    assert np.all(np.diff(F) <= 0.0)
    np.testing.assert_allclose(cs.force([-np.inf, -5.0]), cs.total_force, rtol=1e-15, atol=0)
    np.testing.assert_allclose(cs.force([5.0, np.inf]), -cs.total_force, rtol=1e-15, atol=0)


@settings(max_examples=200, deadline=None)
@given(contact_sets())
def test_zero_in_bounds_exactly_on_equilibrium_set(cs):
    lo, hi = cs.equilibrium()
    V = np.unique(np.concatenate((probes(cs), np.linspace(lo, hi, 7))))
    lower, upper = cs.force_bounds(V)
    contains_zero = (lower <= 0.0) & (0.0 <= upper)
    in_set = (V >= lo) & (V <= hi)
    np.testing.assert_array_equal(contains_zero, in_set)


@settings(max_examples=100, deadline=None)
@given(contact_sets(), st.randoms(use_true_random=False))
def test_invariant_under_permutation(cs, rng):
    order = list(range(cs.n))
    rng.shuffle(order)
    shuffled = ContactSet(cs.speeds[order], cs.forces[order])
    V = probes(cs)
    assert shuffled.equilibrium() == cs.equilibrium()
    np.testing.assert_allclose(shuffled.force(V), cs.force(V), rtol=0, atol=1e-12)


@settings(max_examples=100, deadline=None)
@given(contact_sets(), st.floats(1e-3, 1e3))
def test_scaling_magnitudes_keeps_equilibrium(cs, scale):
    assert ContactSet(cs.speeds, cs.forces * scale).equilibrium() == cs.equilibrium()


@settings(max_examples=200, deadline=None)
@given(contact_sets(equal=True))
def test_equal_magnitudes_give_median_or_band(cs):
    ordered = np.sort(cs.speeds)
    n = cs.n
    lo, hi = cs.equilibrium()
    if n % 2:
        assert lo == hi == np.median(cs.speeds)
    else:
        assert (lo, hi) == (ordered[n // 2 - 1], ordered[n // 2])


def test_five_against_five_is_an_exact_zero_band():
    cs = ContactSet([-0.35] * 5 + [0.35] * 5, np.full(10, 0.1))   # 0.1 is not a dyadic number
    assert cs.equilibrium() == (-0.35, 0.35)
    assert cs.zero_force_band() == (-0.35, 0.35)
    np.testing.assert_array_equal(cs.force(np.linspace(-0.34, 0.34, 11)), 0.0)


def test_decimal_loads_that_cancel_give_a_band():
    # 0.1 + 0.2 != 0.3 in binary floating point; the tie tolerance makes the band exact.
    cs = ContactSet([0.1, 0.2, 0.3], [0.1, 0.2, 0.3])
    assert cs.equilibrium() == (0.2, 0.3)


def test_tie_value_is_interval_midpoint():
    cs = ContactSet([0.0, 0.0, 1.0], [1.0, 2.0, 4.0])
    lower, upper = cs.force_bounds(0.0)
    assert (float(lower), float(upper)) == (1.0, 7.0)   # 4 from above, +-3 stiction
    assert float(cs.force(0.0)) == 4.0


def test_cdf_identity_away_from_ties():
    cs = ContactSet([0.3, -0.1, 0.2, 0.05], [1.0, 2.0, 0.5, 3.0])
    V = np.array([-1.0, 0.0, 0.1, 0.25, 1.0])
    np.testing.assert_allclose(cs.force(V), cs.total_force * (1 - 2 * cs.cdf(V)), rtol=0, atol=1e-12)


def test_uniform_spacing_has_average_viscosity():
    # Average slope 2 F_tot / (N s) over the staircase (docs/physics.md section 6).
    n, spacing = 10, 0.07
    cs = ContactSet(np.arange(n) * spacing, np.full(n, 0.3))
    stairs = cs.staircase()
    # N - 1 steps of 2 f between the first and the last level, N - 1 spacings apart.
    slope = (stairs.plateaus[1] - stairs.plateaus[-1]) / (stairs.levels[-1] - stairs.levels[0])
    np.testing.assert_allclose(slope, 2 * cs.total_force / (n * spacing), rtol=1e-12)


def test_lifted_contacts_do_not_count():
    cs = ContactSet([-1.0, 0.0, 5.0], [1.0, 1.0, 0.0])
    assert cs.equilibrium() == (-1.0, 0.0)
    assert cs.total_force == 2.0


def test_from_friction_multiplies():
    cs = ContactSet.from_friction([0.1, 0.2], mu=0.5, normal_loads=[2.0, 4.0])
    np.testing.assert_array_equal(cs.forces, [1.0, 2.0])


def test_large_sets_are_handled_without_a_matrix():
    rng = np.random.default_rng(7)
    cs = ContactSet(rng.uniform(-1, 1, 100_000))
    F = cs.force(rng.uniform(-1, 1, 200_000))
    assert F.shape == (200_000,)
    lo, hi = cs.equilibrium()
    ordered = np.sort(cs.speeds)
    assert (lo, hi) == (ordered[49_999], ordered[50_000])


@pytest.mark.parametrize(
    ("kwargs", "error", "fragment"),
    [
        ({"speeds": [0.1, np.nan]}, ParameterError, "'speeds' parameter of ContactSet must be finite"),
        ({"speeds": [0.1, np.inf]}, ParameterError, "must be finite"),
        ({"speeds": [0.1], "forces": [np.nan]}, ParameterError, "'forces'"),
        ({"speeds": [0.1, 0.2], "forces": [1.0, -0.2]}, ParameterError, "must be >= 0. Got -0.2"),
        ({"speeds": []}, ParameterError, "must not be empty"),
        ({"speeds": [0.1, 0.2], "forces": [1.0]}, ParameterError, "same length as 'speeds' (2)"),
        ({"speeds": [0.1, 0.2], "forces": [0.0, 0.0]}, ParameterError, "positive sum"),
        ({"speeds": "fast"}, ParameterTypeError, "array of numbers"),
        ({"speeds": [[0.1, 0.2]]}, ParameterError, "1-dimensional"),
        ({"speeds": ["a", "b"]}, ParameterTypeError, "array of numbers"),
    ],
)
def test_bad_input_is_refused_with_a_clear_message(kwargs, error, fragment):
    with pytest.raises(error) as info:
        ContactSet(**kwargs)
    assert fragment in str(info.value)


def test_errors_subclass_builtins():
    with pytest.raises(ValueError):
        ContactSet([0.1], [-1.0])
    with pytest.raises(TypeError):
        ContactSet(None)


def test_nan_query_is_refused():
    with pytest.raises(ParameterError, match="'V'"):
        ContactSet([0.0]).force([0.0, np.nan])


def test_arrays_are_read_only():
    cs = ContactSet([0.1, 0.2])
    with pytest.raises(ValueError):
        cs.speeds[0] = 1.0


# -- continuous distributions ------------------------------------------------------------

def test_uniform_patch_is_a_straight_line():
    # Uniform density on [a, b]: F(V) = F_tot (1 - 2 (V - a) / (b - a)); slope -2 F_tot / (b - a).
    a, b, total = -0.35, 0.35, 5.0
    patch = ContactDistribution(stats.uniform(a, b - a), total)
    V = np.linspace(a, b, 9)
    np.testing.assert_allclose(patch.force(V), total * (1 - 2 * (V - a) / (b - a)), rtol=0, atol=1e-13)
    np.testing.assert_allclose(patch.density(0.0), 1 / (b - a), rtol=1e-14)
    assert patch.equilibrium() == pytest.approx((0.0, 0.0), abs=1e-15)


def test_normal_patch_is_an_erf():
    # F(V) = -F_tot erf((V - mu) / (sigma sqrt 2)): a closed form independent of scipy's cdf.
    from math import erf, sqrt

    mu, sigma, total = 0.1, 0.2, 3.0
    patch = ContactDistribution(stats.norm(mu, sigma), total)
    V = np.array([-0.3, 0.0, 0.1, 0.25, 0.6])
    expected = [-total * erf((v - mu) / (sigma * sqrt(2))) for v in V]
    np.testing.assert_allclose(patch.force(V), expected, rtol=0, atol=1e-14)
    assert patch.equilibrium() == pytest.approx((mu, mu), abs=1e-14)


def test_histogram_patch_with_gap_has_median_interval():
    patch = ContactDistribution.from_histogram([0.0, 1.0, 2.0, 3.0], [1.0, 0.0, 1.0], 2.0)
    assert patch.equilibrium() == (1.0, 2.0)
    np.testing.assert_allclose(patch.force([0.5, 1.5, 2.5]), [1.0, 0.0, -1.0], rtol=0, atol=1e-14)


def test_histogram_median_inside_a_bin():
    # Weights 1, 2, 1 on unit bins: CDF(1.5) = 0.25 + 0.5 * 0.5 = 0.5.
    patch = ContactDistribution.from_histogram([0.0, 1.0, 2.0, 3.0], [1.0, 2.0, 1.0], 2.0)
    assert patch.equilibrium() == (1.5, 1.5)


def test_fine_histogram_matches_discrete_set():
    # A set of equal contacts and a histogram with one narrow bin around each: same force
    # away from the bins (identity of the two representations).
    speeds = np.array([-0.2, 0.0, 0.1, 0.3])
    width = 1e-6
    edges = np.sort(np.concatenate((speeds - width, speeds + width)))
    weights = np.zeros(edges.size - 1)
    weights[::2] = 1.0
    patch = ContactDistribution.from_histogram(edges, weights, 4.0)
    V = np.array([-0.5, -0.1, 0.05, 0.2, 0.5])
    np.testing.assert_allclose(patch.force(V), ContactSet(speeds).force(V), rtol=0, atol=1e-12)


@pytest.mark.parametrize(
    ("call", "error", "fragment"),
    [
        (lambda: ContactDistribution("uniform", 1.0), ParameterTypeError, "'distribution'"),
        (lambda: ContactDistribution(stats.uniform(0, 1), -1.0), ParameterError, "'total_force'"),
        (lambda: ContactDistribution.from_histogram([0, 1], [1, 2], 1.0), ParameterError, "'edges'"),
        (lambda: ContactDistribution.from_histogram([0, 1, 0.5], [1, 2], 1.0), ParameterError,
         "strictly increasing"),
        (lambda: ContactDistribution.from_histogram([0, 1, 2], [0, 0], 1.0), ParameterError,
         "positive sum"),
    ],
)
def test_distribution_bad_input(call, error, fragment):
    with pytest.raises(error) as info:
        call()
    assert fragment in str(info.value)


@pytest.mark.parametrize(
    ("call", "error", "fragment"),
    [
        (lambda: ContactSet([0.0, 1.0, 2.0], [1e308] * 3), ParameterError, "finite sum"),
        (lambda: ContactSet([True, False]), ParameterTypeError, "real numbers"),
        (lambda: ContactSet([0.0]).force("a"), ParameterTypeError, "'V' parameter of ContactSet.force"),
        (lambda: ContactSet([0.0]).force(1j), ParameterTypeError, "real numbers"),
        (lambda: ContactSet([0.0]).force(None), ParameterTypeError, "real numbers"),
        (lambda: ContactSet([0.0]).cdf([np.nan]), ParameterError, "'V' parameter of ContactSet.cdf"),
        (lambda: ContactSet([0.0]).force_bounds([np.nan]), ParameterError, "ContactSet.force_bounds"),
        (lambda: ContactDistribution(stats.poisson(3.0), 1.0), ParameterTypeError, "continuous"),
    ],
)
def test_more_bad_input(call, error, fragment):
    with pytest.raises(error) as info:
        call()
    assert fragment in str(info.value)


def test_with_speeds_equals_a_new_set_and_checks_the_speeds():
    # with_speeds skips re-checking the magnitudes: the staircase it builds must equal the
    # checked constructor's exactly (same operations on the same numbers).
    base = ContactSet([0.1, -0.2, 0.3, 0.3], [1.0, 0.0, 2.0, 0.5])
    moved = base.with_speeds([0.4, 0.1, -0.1, 0.4])
    fresh = ContactSet([0.4, 0.1, -0.1, 0.4], [1.0, 0.0, 2.0, 0.5])
    np.testing.assert_array_equal(moved._table, fresh._table)
    assert moved.equilibrium() == fresh.equilibrium() and moved.total_force == fresh.total_force
    with pytest.raises(ParameterError, match="speeds"):
        base.with_speeds([0.1, 0.2])
    with pytest.raises(ParameterError, match="speeds"):
        base.with_speeds([0.1, np.nan, 0.2, 0.3])


# -- the tie tolerance at several scales, and loads drawn per contact ---------------------------
#: Powers of two scale every force, prefix sum and tolerance exactly: each identity below holds
#: to the bit at every scale.
SCALES = [2.0 ** -20, 1.0, 2.0 ** 20]
_EPS = np.finfo(float).eps


@pytest.mark.parametrize("scale", SCALES)
def test_tie_tolerance_is_its_formula_at_every_scale(scale):
    """``4 (K + 1) eps F_tot`` with ``K`` the distinct speeds (five contacts, four speeds,
    unequal forces summing to 7 scale exactly; mutants: the factor 4 to 5, ``K + 1`` to
    ``K + 2``)."""
    cs = ContactSet([0.0, 1.0, 1.0, 2.0, 3.0], np.array([1.0, 0.5, 2.5, 1.0, 2.0]) * scale)
    assert cs.total_force == 7.0 * scale
    assert cs.tie_tolerance == 4.0 * 5 * _EPS * 7.0 * scale


@pytest.mark.parametrize("scale", SCALES)
@pytest.mark.parametrize("excess, expected", [(5, (0.0, 1.0)), (7, (1.0, 1.0))])
def test_tie_tolerance_brackets_the_net_force_at_every_scale(scale, excess, expected):
    """Two contacts at 0 and 1 m/s with forces 1 and ``1 + d``: between them the net force is
    ``d`` exactly (Sterbenz), against the tolerance ``12 eps F_tot ~ 6 * 2**-50`` (times the
    scale). ``d = 5 * 2**-50`` is a tie (the zero-force band (0, 1)); ``d = 7 * 2**-50`` is not
    (the point 1). Mutants killed: the factor 4 to 5, ``K + 1`` to ``K + 2``, the ``F_tot``
    factor dropped."""
    d = excess * 2.0 ** -50
    cs = ContactSet([0.0, 1.0], np.array([1.0, 1.0 + d]) * scale)
    assert cs.equilibrium() == expected
    assert float(cs.force(0.5)) == (0.0 if expected == (0.0, 1.0) else d * scale)


@pytest.mark.parametrize("scale", SCALES)
def test_decimal_loads_that_cancel_give_a_band_at_every_scale(scale):
    """0.1 + 0.2 != 0.3 in binary: the rounding (about 5.6e-17 scale) is a tie at every scale
    because the tolerance scales with F_tot (at 2**20 a tolerance without F_tot moves the
    equilibrium from the band (0.2, 0.3) to the point 0.2)."""
    cs = ContactSet([0.1, 0.2, 0.3], np.array([0.1, 0.2, 0.3]) * scale)
    assert cs.equilibrium() == (0.2, 0.3)
    np.testing.assert_array_equal(cs.force([0.25]), 0.0)


@pytest.mark.parametrize("scale", SCALES)
def test_unequal_loads_keep_each_contacts_own_mean_and_spread(scale):
    """The lognormal of :func:`unequal_loads` integrated exactly by 60-point Gauss-Hermite
    quadrature over the normals (one row of normals per node): each contact's mean is its own
    ``mean_i`` and its relative variance ``spread^2`` (the quadrature is exact to rounding for
    this smooth integrand: rtol 1e-12). Unequal means at several scales; mutants: the loads
    drawn around the mean of all contacts (``mean.mean()``), ``sigma^2 = ln(1 + spread)``."""
    from numpy.polynomial.hermite_e import hermegauss

    means = np.array([1.0, 3.0, 0.5, 8.0]) * scale
    spread = 0.3
    nodes, weights = hermegauss(60)
    weights = weights / np.sqrt(2.0 * np.pi)
    loads = unequal_loads(means, spread, means.size, normals=np.repeat(nodes[:, None], means.size, axis=1))
    assert loads.shape == (60, means.size)
    mean = weights @ loads
    np.testing.assert_allclose(mean, means, rtol=1e-12, atol=0.0)
    np.testing.assert_allclose(weights @ loads ** 2 - mean ** 2, (spread * means) ** 2, rtol=1e-11, atol=0.0)
    # At z = 0 each load is its own mean times exp(-sigma^2 / 2) = mean / sqrt(1 + spread^2).
    np.testing.assert_allclose(unequal_loads(means, spread, means.size, normals=np.zeros(means.size)),
                               means / np.sqrt(1.0 + spread ** 2), rtol=4 * _EPS, atol=0.0)
    np.testing.assert_array_equal(unequal_loads(means, 0.0, means.size), means)


@pytest.mark.parametrize(("call", "error", "message"), [
    (lambda: ContactSet([0.1, np.nan]), ParameterError,
     "The 'speeds' parameter of ContactSet must be finite (no NaN or inf). Got nan instead."),
    (lambda: ContactSet([0.1], [np.nan]), ParameterError,
     "The 'forces' parameter of ContactSet must be finite (no NaN or inf). Got nan instead."),
    (lambda: ContactSet([0.1, 0.2], [1.0, -0.2]), ParameterError,
     "The 'forces' parameter of ContactSet must be >= 0. Got -0.2 instead."),
    (lambda: ContactSet([]), ParameterError,
     "The 'speeds' parameter of ContactSet must not be empty. Got [] instead."),
    (lambda: ContactSet([0.1, 0.2], [1.0]), ParameterError,
     "The 'forces' parameter of ContactSet must have the same length as 'speeds' (2). Got 'an array "
     "of length 1' instead."),
    (lambda: ContactSet([0.1, 0.2], [0.0, 0.0]), ParameterError,
     "The 'forces' parameter of ContactSet must have a positive sum (some contact must touch). Got "
     '[0.0, 0.0] instead.'),
    (lambda: ContactSet([0.0, 1.0, 2.0], [1e308] * 3), ParameterError,
     "The 'forces' parameter of ContactSet must have a finite sum (F_tot overflows). Got 'max 1e+308' instead."),
    (lambda: ContactSet([0.0]).force(np.nan), ParameterError,
     "The 'V' parameter of ContactSet.force must not contain NaN. Got nan instead."),
    (lambda: ContactSet([0.0]).force('a'), ParameterTypeError,
     "The 'V' parameter of ContactSet.force must be real numbers (m/s). Got 'a' instead."),
    (lambda: ContactSet([0.0]).cdf([np.nan]), ParameterError,
     "The 'V' parameter of ContactSet.cdf must not contain NaN. Got [nan] instead."),
    (lambda: ContactSet.from_friction([0.1, 0.2], [0.5, 0.5, 0.5], 2.0), ParameterError,
     "The 'mu' parameter of ContactSet.from_friction must be a scalar or have the length of 'speeds' "
     "(2). Got 'an array of length 3' instead."),
    (lambda: ContactSet.from_friction([0.1, 0.2], 0.5, [1.0, 2.0, 3.0]), ParameterError,
     "The 'normal_loads' parameter of ContactSet.from_friction must be a scalar or have the length "
     "of 'speeds' (2). Got 'an array of length 3' instead."),
    (lambda: ContactSet([0.1, 0.2]).with_speeds([0.1]), ParameterError,
     "The 'speeds' parameter of ContactSet.with_speeds must have one speed per contact (2). Got 'an "
     "array of length 1' instead."),
    (lambda: ContactDistribution('uniform', 1.0), ParameterTypeError,
     "The 'distribution' parameter of ContactDistribution must be a frozen scipy.stats continuous "
     "distribution. Got 'uniform' instead."),
    (lambda: ContactDistribution.from_histogram([0, 1], [1, 2], 1.0), ParameterError,
     "The 'edges' parameter of ContactDistribution.from_histogram must have one more entry than "
     "'weights' (3). Got 'an array of length 2' instead."),
    (lambda: ContactDistribution.from_histogram([0, 1, 0.5], [1, 2], 1.0), ParameterError,
     "The 'edges' parameter of ContactDistribution.from_histogram must be strictly increasing. Got "
     '[0.0, 1.0, 0.5] instead.'),
    (lambda: ContactDistribution.from_histogram([0, 1, 2], [0, 0], 1.0), ParameterError,
     "The 'weights' parameter of ContactDistribution.from_histogram must have a positive sum. Got "
     '[0.0, 0.0] instead.'),
    (lambda: weighted_median(0.5, [1.0]), ParameterError,
     "The 'speeds' parameter of weighted_median must have at least one axis (..., n). Got 0.5 instead."),
    (lambda: weighted_median([0.1, np.nan], [1.0, 1.0]), ParameterError,
     "The 'speeds' parameter of weighted_median must hold no NaN. Got 'an array with NaN' instead."),
    (lambda: weighted_median([0.1, 0.2], [1.0]), ParameterError,
     "The 'forces' parameter of weighted_median must have one magnitude per contact (2). Got 'shape (1,)' instead."),
    (lambda: weighted_median([[0.1, 0.2]] * 3, [1.0, 1.0], outside=[1.0, 2.0]), ParameterError,
     "The 'outside' parameter of weighted_median must broadcast to the rows' shape (3,). Got (2,) instead."),
    (lambda: weighted_median([0.1, 0.2], [1.0, 1.0], outside=np.inf), ParameterError,
     "The 'outside' parameter of weighted_median must be finite. Got inf instead."),
    (lambda: unequal_loads(1.0, -0.1, 3), ParameterError,
     "The 'spread' parameter of unequal_loads must be >= 0. Got -0.1 instead."),
])
def test_every_refusal_of_the_contact_model_in_full(call, error, message):
    """Each refusal matched whole: the parameter, the owner, the rule and the value (mutants:
    any of the four changed, dropped or replaced by None, a length in a rule off by one)."""
    with pytest.raises(error) as info:
        call()
    assert str(info.value) == message


@pytest.mark.parametrize("scale", SCALES)
def test_weighted_median_weighs_each_contact_and_each_row(scale):
    """Rows of speeds sharing unequal weights: each row's ``(lo, hi)`` is its ContactSet's
    equilibrium (the second method), at every scale of the weights. Forces (1, 1, 1, 5) at
    0.1..0.4 m/s put the median at the heavy contact, (0.4, 0.4); weights dropped it would be
    the band (0.2, 0.3). An outside force is one more contact of magnitude ``|F|`` at
    ``sign(F) inf`` (a contact far beyond the speeds in the second method), per row; beyond
    ``F_tot`` the set is at ``+-inf``. Mutants killed: the weights dropped, the outside
    force's sign."""
    forces = np.array([1.0, 1.0, 1.0, 5.0]) * scale
    rows = np.array([[0.1, 0.2, 0.3, 0.4], [0.4, 0.3, 0.2, 0.1], [0.0, -1.0, 2.0, 0.5], [0.3, 0.3, 0.1, -0.2]])
    lo, hi = weighted_median(rows, forces)
    assert lo.shape == hi.shape == (4,)
    assert (lo[0], hi[0]) == (0.4, 0.4)
    for row, a, b in zip(rows, lo, hi):
        assert (a, b) == ContactSet(row, forces).equilibrium()
    for push in (3.0, -3.0, 7.5, -7.5):
        a, b = weighted_median(rows[0], forces, outside=push * scale)
        beyond = ContactSet(np.append(rows[0], np.sign(push) * 1e6), np.append(forces, abs(push) * scale))
        assert (float(a), float(b)) == beyond.equilibrium()
    assert weighted_median(rows[0], forces, outside=9.0 * scale) == (np.inf, np.inf)
    assert weighted_median(rows[0], forces, outside=-9.0 * scale) == (-np.inf, -np.inf)
    lo, hi = weighted_median(rows, forces, outside=np.array([0.0, 0.0, 3.0, -3.0]) * scale)
    for row, push, a, b in zip(rows, [0.0, 0.0, 3.0, -3.0], lo, hi):
        expected = ContactSet(np.append(row, np.sign(push) * 1e6), np.append(forces, abs(push) * scale)).equilibrium()
        assert (a, b) == expected


@pytest.mark.parametrize("scale", SCALES)
def test_from_friction_multiplies_per_contact_at_every_scale(scale):
    """``f_i = mu_i N_i`` per contact, with a scalar for either broadcast to every contact
    (powers of two: exact; mutant killed: ``mu N`` to ``mu + N``, which the other tests let
    through)."""
    speeds = [0.0, 0.1, 0.2]
    mu, loads = np.array([0.5, 0.25, 0.75]), np.array([2.0, 8.0, 4.0]) * scale
    np.testing.assert_array_equal(ContactSet.from_friction(speeds, mu, loads).forces, mu * loads)
    np.testing.assert_array_equal(ContactSet.from_friction(speeds, 0.5, loads).forces, 0.5 * loads)
    np.testing.assert_array_equal(ContactSet.from_friction(speeds, mu, 4.0 * scale).forces, mu * 4.0 * scale)
    np.testing.assert_array_equal(ContactSet.from_friction(speeds, mu, loads).speeds, speeds)


# -- the staircase from both builders, the refusals left, the patch and the loads ---------------
@pytest.mark.parametrize("scale", SCALES)
@pytest.mark.parametrize("small", [64, 0])
def test_staircase_is_its_closed_form_from_either_builder(monkeypatch, scale, small):
    """Speeds (0.5, -0.25, 0.5, 1, 2) with unequal magnitudes (1, 2, 0.5, 0.25, 0) x scale (the
    last lifted): levels (-0.25, 0.5, 1), steps (2, 1.5, 0.25), plateaus F_tot = 3.75 then
    -0.25, -3.25, -3.75, all x scale, exact (dyadic). The same from the compiled builder (sets
    up to 64 contacts) and from NumPy's (larger sets; forced here by a limit of 0)."""
    import toolkit.model.contacts as contacts

    monkeypatch.setattr(contacts, "_SMALL", small)
    cs = ContactSet([0.5, -0.25, 0.5, 1.0, 2.0], np.array([1.0, 2.0, 0.5, 0.25, 0.0]) * scale)
    stairs = cs.staircase()
    np.testing.assert_array_equal(stairs.levels, [-0.25, 0.5, 1.0])
    np.testing.assert_array_equal(stairs.steps, np.array([2.0, 1.5, 0.25]) * scale)
    np.testing.assert_array_equal(stairs.plateaus, np.array([3.75, -0.25, -3.25, -3.75]) * scale)
    assert cs.total_force == 3.75 * scale and (cs.n, len(cs)) == (5, 5)
    assert cs.tie_tolerance == 4 * 4 * np.finfo(float).eps * 3.75 * scale
    np.testing.assert_array_equal(cs.cdf([-1.0, -0.25, 0.0, 0.5, 1.0, np.inf]),
                                  [0.0, 2.0 / 3.75, 2.0 / 3.75, 3.5 / 3.75, 1.0, 1.0])
    np.testing.assert_array_equal(cs.force([-np.inf, -0.25, 0.0, 0.5, 0.75, 1.0, np.inf]),
                                  np.array([3.75, 1.75, -0.25, -1.75, -3.25, -3.5, -3.75]) * scale)
    lower, upper = cs.force_bounds([-0.25, 0.5, 2.0])
    np.testing.assert_array_equal(lower, np.array([-0.25, -3.25, -3.75]) * scale)
    np.testing.assert_array_equal(upper, np.array([3.75, -0.25, -3.75]) * scale)
    # The heavy contact at -0.25 (2 of 3.75) holds the median: 0 in [-0.25, 3.75] there.
    assert cs.equilibrium() == (-0.25, -0.25) and cs.zero_force_band() is None
    halves = ContactSet([0.0, 1.0, 3.0], np.array([1.0, 0.5, 0.5]) * scale)
    assert halves.equilibrium() == (0.0, 1.0) and halves.zero_force_band() == (0.0, 1.0)
    assert repr(cs) == f"ContactSet(n=5, total_force={3.75 * scale:.6g} N, speeds in [-0.25, 2] m/s)"


def test_the_numpy_builder_refuses_like_the_compiled_one(monkeypatch):
    import toolkit.model.contacts as contacts

    for small in (64, 0):
        monkeypatch.setattr(contacts, "_SMALL", small)
        with pytest.raises(ParameterError) as info:
            ContactSet([0.1, 0.2, 0.3], [0.0, 0.0, 0.0])
        assert str(info.value) == ("The 'forces' parameter of ContactSet must have a positive sum (some contact must "
                                   "touch). Got [0.0, 0.0, 0.0] instead.")
        with pytest.raises(ParameterError) as info:
            ContactSet(np.arange(9.0), np.zeros(9))
        assert str(info.value) == ("The 'forces' parameter of ContactSet must have a positive sum (some contact must "
                                   "touch). Got 'all zeros' instead.")
    with pytest.raises(ParameterError) as info:
        ContactSet([0.1, 0.2], [1e308, 1e308])
    assert str(info.value) == ("The 'forces' parameter of ContactSet must have a finite sum (F_tot overflows). "
                               "Got 'max 1e+308' instead.")
    assert ContactSet([0.1, 0.2], [1e308, 7e307]).total_force == 1.7e308


def test_a_large_set_has_the_staircase_of_its_levels():
    """A hundred contacts on 7 levels (NumPy's builder), unequal dyadic magnitudes: the steps
    are the magnitudes summed per level, the plateaus F_tot minus twice the prefix sums (exact),
    and the force the brute-force sum at every level and between them."""
    rng = np.random.default_rng(5)
    speeds = rng.choice([-0.5, -0.25, 0.0, 0.125, 0.25, 0.5, 1.0], 100)
    forces = rng.choice([0.0, 0.25, 0.5, 1.0, 2.0], 100)
    cs = ContactSet(speeds, forces)
    levels = np.unique(speeds[forces > 0])
    steps = np.array([forces[speeds == v].sum() for v in levels])
    stairs = cs.staircase()
    np.testing.assert_array_equal(stairs.levels, levels)
    np.testing.assert_array_equal(stairs.steps, steps)
    total = forces.sum()
    np.testing.assert_array_equal(stairs.plateaus, total - 2 * np.concatenate(([0.0], np.cumsum(steps))))
    V = probes(cs)
    np.testing.assert_array_equal(cs.force(V), brute_force(cs, V))
    assert cs.tie_tolerance == 4 * (levels.size + 1) * np.finfo(float).eps * total


@pytest.mark.parametrize("scale", SCALES)
def test_a_histogram_patch_is_its_closed_form(scale):
    """Bins [0, 1), [1, 2), [2, 4) with weights 1, 0, 3 (normalized 1/4, 0, 3/4) and F_tot =
    2 x scale: CDF 1/4 on the empty bin, so F = F_tot (1 - 2 CDF) = F_tot / 2 there; the
    median inside the last bin at 2 + (1/2 - 1/4) / (3/4) x 2 = 8/3 (a few ulp: one
    division); the density 1/4 per unit speed in the first bin, 3/8 in the last."""
    patch = ContactDistribution.from_histogram([0.0, 1.0, 2.0, 4.0], [1.0, 0.0, 3.0], 2.0 * scale)
    np.testing.assert_allclose(patch.cdf([0.0, 0.5, 1.5, 3.0, 5.0]), [0.0, 0.125, 0.25, 0.625, 1.0],
                               rtol=4 * np.finfo(float).eps, atol=1e-300)
    np.testing.assert_allclose(patch.force([1.5, 3.0]), np.array([1.0, -0.5]) * scale, rtol=8 * np.finfo(float).eps)
    lower, upper = patch.force_bounds([1.5, 3.0])
    np.testing.assert_array_equal(lower, upper)
    assert lower is not upper
    np.testing.assert_allclose(patch.density([0.5, 1.5, 3.0]), [0.25, 0.0, 0.375], rtol=4 * np.finfo(float).eps)
    lo, hi = patch.equilibrium()
    assert lo == hi == pytest.approx(8.0 / 3.0, rel=4 * np.finfo(float).eps)
    # Weights (1, 0, 1): the median is the empty bin [1, 2], exactly.
    assert ContactDistribution.from_histogram([0.0, 1.0, 2.0, 4.0], [1.0, 0.0, 1.0], scale).equilibrium() == (1.0, 2.0)
    assert ContactDistribution(stats.uniform(-0.5, 2.0), scale).equilibrium() == (0.5, 0.5)
    with pytest.raises(ParameterError) as info:
        ContactDistribution(stats.uniform(0, 1), 0.0)
    assert str(info.value) == "The 'total_force' parameter of ContactDistribution must be > 0. Got 0.0 instead."
    with pytest.raises(ParameterError) as info:
        ContactDistribution.from_histogram([0.0, 1.0], [-1.0], 1.0)
    assert str(info.value) == ("The 'weights' parameter of ContactDistribution.from_histogram must be >= 0. "
                               "Got -1.0 instead.")


@pytest.mark.parametrize("scale", SCALES)
def test_unequal_loads_from_given_normals_are_the_lognormal_formula(scale):
    """``f_i = mean_i exp(sigma z_i - sigma^2 / 2)``, ``sigma^2 = ln(1 + spread^2)``, with
    ``z`` given (rows of carousels) and each contact's own mean: 4 eps (one exp, one log);
    z = sigma / 2 gives each mean exactly (the exponent is 0); spread 0 is the mean,
    unchanged, a fresh array, and draws nothing."""
    means = np.array([1.0, 2.0, 0.5]) * scale
    spread = 0.75
    sigma = np.sqrt(np.log(1 + spread ** 2))
    z = np.array([[0.0, 1.0, -2.0], [0.5 * sigma, 0.5 * sigma, 0.5 * sigma]])
    loads = unequal_loads(means, spread, 3, normals=z)
    np.testing.assert_allclose(loads[0], means * np.exp(sigma * z[0] - sigma ** 2 / 2), rtol=4 * np.finfo(float).eps)
    np.testing.assert_array_equal(loads[1], means)
    rng = np.random.default_rng(3)
    same = unequal_loads(means, 0.0, 3, rng)
    np.testing.assert_array_equal(same, means)
    same[0] = -1.0
    assert rng.random() == np.random.default_rng(3).random()
    np.testing.assert_array_equal(unequal_loads(2.0 * scale, 0.0, 2), [2.0 * scale, 2.0 * scale])


def test_weighted_median_of_a_row_without_weight_is_its_slowest_speed():
    lo, hi = weighted_median([[0.3, -0.2, 0.1], [0.3, -0.2, 0.1]], [0.0, 0.0, 0.0], outside=[0.0, 0.0])
    np.testing.assert_array_equal(lo, [-0.2, -0.2])
    np.testing.assert_array_equal(hi, [-0.2, -0.2])


@pytest.mark.parametrize("call, error, message", [
    (lambda: ContactSet([0.0]).force(None), ParameterTypeError,
     "The 'V' parameter of ContactSet.force must be real numbers (m/s). Got None instead."),
    (lambda: ContactSet([0.0]).force([1 + 2j]), ParameterTypeError,
     "The 'V' parameter of ContactSet.force must be real numbers (m/s). Got [(1+2j)] instead."),
    (lambda: ContactSet([0.0]).force_bounds(b"x"), ParameterTypeError,
     "The 'V' parameter of ContactSet.force_bounds must be real numbers (m/s). Got b'x' instead."),
    (lambda: ContactSet([0.0]).force_bounds([[0.1], [0.2, 0.3]]), ParameterTypeError,
     "The 'V' parameter of ContactSet.force_bounds must be real numbers (m/s). Got [[0.1], [0.2, 0.3]] instead."),
    (lambda: ContactSet([0.0]).force(np.array([0.1, np.nan])), ParameterError,
     "The 'V' parameter of ContactSet.force must not contain NaN. Got array([0.1, nan]) instead."),
    (lambda: ContactSet([0.0]).cdf({"a": 1}), ParameterTypeError,
     "The 'V' parameter of ContactSet.cdf must be real numbers (m/s). Got {'a': 1} instead."),
    (lambda: ContactDistribution(stats.norm(0, 1), 1.0).cdf(np.nan), ParameterError,
     "The 'V' parameter of ContactDistribution.cdf must not contain NaN. Got nan instead."),
    (lambda: ContactDistribution(stats.norm(0, 1), 1.0).density("v"), ParameterTypeError,
     "The 'V' parameter of ContactDistribution.density must be real numbers (m/s). Got 'v' instead."),
    (lambda: ContactSet.from_friction([0.1, 0.2], [0.5, -0.5], 2.0), ParameterError,
     "The 'mu' parameter of ContactSet.from_friction must be >= 0. Got -0.5 instead."),
    (lambda: ContactSet.from_friction([0.1, 0.2], 0.5, [1.0, -2.0]), ParameterError,
     "The 'normal_loads' parameter of ContactSet.from_friction must be >= 0. Got -2.0 instead."),
    (lambda: ContactSet.from_friction([0.1, np.nan], 0.5, 1.0), ParameterError,
     "The 'speeds' parameter of ContactSet.from_friction must be finite (no NaN or inf). Got nan instead."),
    (lambda: ContactSet.from_friction([0.1], "a", 1.0), ParameterTypeError,
     "The 'mu' parameter of ContactSet.from_friction must be an array of numbers. Got 'a' instead."),
    (lambda: ContactSet.from_friction([0.1], 1.0, None), ParameterTypeError,
     "The 'normal_loads' parameter of ContactSet.from_friction must be an array of numbers. Got None instead."),
    (lambda: ContactSet([0.1, 0.2]).with_speeds([0.1, np.inf]), ParameterError,
     "The 'speeds' parameter of ContactSet.with_speeds must be finite (no NaN or inf). Got inf instead."),
    (lambda: ContactSet([0.1, 0.2], [1.0, np.inf]), ParameterError,
     "The 'forces' parameter of ContactSet must be finite (no NaN or inf). Got inf instead."),
    (lambda: ContactSet([0.1, 0.2], [1.0, -1.0]), ParameterError,
     "The 'forces' parameter of ContactSet must be >= 0. Got -1.0 instead."),
    (lambda: ContactSet([0.1, 0.2], [1.0, 1.0, 1.0]), ParameterError,
     "The 'forces' parameter of ContactSet must have the same length as 'speeds' (2). Got 'an array of length 3' "
     "instead."),
    (lambda: ContactSet(np.ones((2, 2))), ParameterError,
     "The 'speeds' parameter of ContactSet must be 1-dimensional. Got 'an array of shape (2, 2)' instead."),
    (lambda: ContactDistribution.from_histogram([0, np.nan], [1.0], 1.0), ParameterError,
     "The 'edges' parameter of ContactDistribution.from_histogram must be finite (no NaN or inf). Got nan instead."),
    (lambda: ContactDistribution.from_histogram([0, 1], [np.inf], 1.0), ParameterError,
     "The 'weights' parameter of ContactDistribution.from_histogram must be finite (no NaN or inf). Got inf "
     "instead."),
    (lambda: ContactDistribution.from_histogram([0, 1], [1.0], -1.0), ParameterError,
     "The 'total_force' parameter of ContactDistribution must be > 0. Got -1.0 instead."),
    (lambda: weighted_median([0.1, 0.2], [1.0, -1.0]), ParameterError,
     "The 'forces' parameter of weighted_median must be >= 0. Got -1.0 instead."),
    (lambda: weighted_median([0.1, 0.2], [1.0, np.nan]), ParameterError,
     "The 'forces' parameter of weighted_median must be finite (no NaN or inf). Got nan instead."),
    (lambda: unequal_loads(1.0, "wide", 3), ParameterTypeError,
     "The 'spread' parameter of unequal_loads must be a real number. Got 'wide' instead."),
])
def test_each_remaining_refusal_names_its_owner_in_full(call, error, message):
    with pytest.raises(error) as info:
        call()
    assert str(info.value) == message


def test_default_magnitudes_are_one_newton_each_and_read_only():
    cs = ContactSet([0.3, -0.1, 0.2])
    np.testing.assert_array_equal(cs.forces, [1.0, 1.0, 1.0])
    assert not cs.forces.flags.writeable and not cs.speeds.flags.writeable and cs.total_force == 3.0
    moved = cs.with_speeds([1.0, 2.0, 3.0])
    assert moved.forces is cs.forces and moved.equilibrium() == (2.0, 2.0)
    np.testing.assert_array_equal(cs.speeds, [0.3, -0.1, 0.2])


def test_both_builders_give_the_kernels_the_same_table(monkeypatch):
    """The staircase table the exact simulator's kernel reads (levels padded with +inf, the
    magnitude below and at-or-above each level) is the same array, bit for bit, from the
    compiled builder and from NumPy's (unequal magnitudes, ties, a lifted contact)."""
    import toolkit.model.contacts as contacts
    from toolkit import _compiled

    _compiled.load("core")                   # the compiled builder runs once the kernels are loaded
    assert contacts.compiled("core") is not None or os.environ.get("NUMBA_DISABLE_JIT") == "1"
    speeds, forces = [0.3, -0.1, 0.3, 0.2, -0.4, 0.2], [0.5, 2.0, 0.25, 1.0, 0.0, 0.75]
    compiled = ContactSet(speeds, forces)._table
    monkeypatch.setattr(contacts, "_SMALL", 0)
    numpy_built = ContactSet(speeds, forces)._table
    np.testing.assert_array_equal(numpy_built, compiled)
    assert numpy_built[0, -1] == np.inf and numpy_built.shape == (3, 4)


def test_the_patch_and_the_loads_keep_their_rules_and_types():
    """A histogram patch's median tie is bracketed at its tolerance ``4 (K + 1) eps`` (K = 2
    bins: 12 eps): a cumulative share 1/2 + 12 eps at the middle edge is a tie (the band ends
    there), 1/2 + 16 eps is not (the median falls just inside the first bin, 1 / (1 + 2^-47));
    a repeated edge is refused; integers are kept as floats."""
    eps = np.finfo(float).eps
    tie = ContactDistribution.from_histogram([0.0, 1.0, 2.0], [0.5 + 12 * eps, 0.5 - 12 * eps], 1.0)
    assert tie.equilibrium() == (1.0, 1.0)
    near = ContactDistribution.from_histogram([0.0, 1.0, 2.0], [0.5 + 16 * eps, 0.5 - 16 * eps], 1.0)
    lo, hi = near.equilibrium()
    assert lo == hi == 0.5 / (0.5 + 16 * eps) and lo < 1.0
    with pytest.raises(ParameterError) as info:
        ContactDistribution.from_histogram([0.0, 1.0, 1.0, 2.0], [1.0, 1.0, 1.0], 1.0)
    assert str(info.value) == ("The 'edges' parameter of ContactDistribution.from_histogram must be strictly "
                               "increasing. Got [0.0, 1.0, 1.0, 2.0] instead.")
    assert type(ContactDistribution(stats.uniform(0, 1), 2).total_force) is float
    loads = unequal_loads(2, 0.0, 3)
    assert loads.dtype == np.float64 and loads.tolist() == [2.0, 2.0, 2.0]
    with pytest.raises(ParameterError) as info:
        ContactSet(np.arange(8.0), np.zeros(8))
    assert str(info.value) == ("The 'forces' parameter of ContactSet must have a positive sum (some contact must "
                               "touch). Got [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0] instead.")


def test_weighted_median_of_a_grid_of_sets_with_bands():
    """Rows on a (2, 2) grid of sets of four equal magnitudes (even: a band between the 2nd
    and 3rd speeds), each with its own outside force: each cell is its ContactSet's
    equilibrium with the force as one more contact far beyond (the second method)."""
    speeds = np.array([[[0.1, 0.2, 0.3, 0.4], [0.4, -0.1, 0.0, 0.2]], [[1.0, 2.0, 3.0, 4.0], [0.5, 0.5, -0.5, 1.5]]])
    forces = np.ones(4)
    push = np.array([[0.0, 1.0], [-1.0, 0.0]])
    lo, hi = weighted_median(speeds, forces, outside=push)
    assert lo.shape == hi.shape == (2, 2)
    assert (lo[0, 0], hi[0, 0]) == (0.2, 0.3) and (lo[1, 1], hi[1, 1]) == (0.5, 0.5)
    for i in range(2):
        for j in range(2):
            p = push[i, j]
            expected = ContactSet(np.append(speeds[i, j], np.sign(p) * 1e6), np.append(forces, abs(p))).equilibrium() \
                if p else ContactSet(speeds[i, j], forces).equilibrium()
            assert (lo[i, j], hi[i, j]) == expected


def test_an_overflowing_total_is_refused_even_where_overflows_raise():
    with np.errstate(all="raise"):
        with pytest.raises(ParameterError, match="must have a finite sum"):
            ContactSet([0.1, 0.2], [1e308, 1e308])
