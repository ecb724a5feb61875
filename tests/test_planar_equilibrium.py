"""The planar equilibrium: closed forms, the exact 1-D reduction, certificates, cross-checks."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import toolkit as tk
from toolkit.errors import ParameterError, ParameterTypeError
from toolkit.planar import EquilibriumStatus, PlanarContactSet, geometric_median, weiszfeld
from toolkit.planar.equilibrium import solve_equilibrium

EPS = float(np.finfo(float).eps)


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(9182736)


def _legs(rng, n, aniso=False, scale=1.0):
    anisotropy = np.c_[rng.uniform(0, np.pi, n), rng.uniform(0.2, 5.0, n)] if aniso else None
    return PlanarContactSet(rng.normal(size=(n, 2)) * scale, rng.normal(size=(n, 2)) * scale,
                            rng.uniform(0.1, 3.0, n), anisotropy)


def _check_certificate(eq, contacts, tol_rel=1e-8):
    """The certificate's forces lie in their limit sets and balance; the gap is certified."""
    assert eq.status in (EquilibriumStatus.OPTIMAL, EquilibriumStatus.SEGMENT), eq.message
    assert eq.gap <= tol_rel * contacts.total_force * eq.speed_scale
    F = eq.contact_forces
    if contacts.isotropic:
        q = np.hypot(F[:, 0], F[:, 1])
    else:
        z = np.linalg.solve(contacts.limit_factors, F[:, :, None])[:, :, 0]
        q = np.hypot(z[:, 0], z[:, 1])
    assert np.all(q <= contacts.forces * (1 + 1e-12))
    # Balance to rounding: sums of n forces of size F_tot / n.
    tol = 64 * contacts.n * EPS * contacts.total_force
    np.testing.assert_allclose(F.sum(axis=0), 0.0, rtol=0, atol=tol)
    if not eq.translation_only:
        r = contacts.positions
        np.testing.assert_allclose(np.sum(r[:, 0] * F[:, 1] - r[:, 1] * F[:, 0]), 0.0, rtol=0,
                                   atol=tol * max(contacts.arm, 1.0))


# -- closed forms -------------------------------------------------------------------------------
def test_symmetric_sets_have_their_centre_as_median():
    for k in (3, 4, 5, 6, 12):
        angles = 2 * np.pi * np.arange(k) / k + 0.3
        points = 2.5 * np.c_[np.cos(angles), np.sin(angles)] + np.array([0.7, -0.2])
        eq = geometric_median(points)
        # Rounding of the polygon's coordinates (a few eps of 2.5): atol 1e-14.
        np.testing.assert_allclose(eq.velocity, [0.7, -0.2], rtol=0, atol=1e-14)
        assert eq.unique and eq.gap <= 1e-14 * eq.total_force * eq.speed_scale


def test_a_vertex_of_angle_above_120_degrees_is_the_median_exactly():
    points = np.array([[0.0, 0.0], [1.0, 0.05], [-1.0, 0.05]])      # angle at 0 is ~174 deg
    eq = geometric_median(points)
    assert eq.status is EquilibriumStatus.OPTIMAL
    assert np.array_equal(eq.velocity, [0.0, 0.0]) and eq.stuck[0]
    # A dominant weight (>= the sum of the others) holds the median at its point.
    eq = geometric_median(np.array([[0.3, 0.2], [1.0, 0.0], [0.0, 1.0], [-1.0, -1.0]]), [3.0, 1.0, 1.0, 1.0])
    assert np.array_equal(eq.velocity, [0.3, 0.2])


def test_fermat_point_of_a_triangle():
    # Equal weights, all angles below 120 deg: each side subtends 120 deg at the Fermat point.
    points = np.array([[0.0, 0.0], [4.0, 0.0], [1.0, 3.0]])
    eq = geometric_median(points)
    u = points - eq.velocity
    u /= np.hypot(u[:, 0], u[:, 1])[:, None]
    cosines = [u[0] @ u[1], u[1] @ u[2], u[2] @ u[0]]
    np.testing.assert_allclose(cosines, -0.5, rtol=0, atol=1e-13)


def test_rigid_velocities_are_their_own_equilibrium(rng):
    # v_i = V + omega J r_i for every contact: every contact sticks at that twist, Phi = 0.
    r = rng.normal(size=(8, 2))
    V, w = np.array([0.4, -0.1]), 0.7
    contacts = PlanarContactSet(r, V + w * np.c_[-r[:, 1], r[:, 0]], rng.uniform(0.5, 2, 8))
    eq = contacts.equilibrium()
    np.testing.assert_allclose(eq.twist, [0.4, -0.1, 0.7], rtol=0, atol=1e-15)
    # Phi at rounding: slips of a few eps of |v| ~ 1, weighted by F_tot ~ 10.
    assert np.all(eq.stuck) and eq.dissipation <= 64 * EPS * contacts.total_force and eq.unique


@pytest.mark.parametrize("scale", [1e-3, 1.0, 1e3])
def test_contacts_all_at_one_point_are_known_not_to_fix_the_twist(scale):
    # Stuck contacts at one point r fix only V + omega J r: every twist (V - omega J r, omega)
    # sticks them all too (Phi = 0 along that line), so uniqueness is known false, not unknown.
    r = np.array([[0.3, -0.2]] * 3)
    v = np.array([[0.1, 0.05]] * 3) * scale
    contacts = PlanarContactSet(r, v, [1.0, 2.5, 0.7])
    eq = contacts.equilibrium()
    assert np.all(eq.stuck) and eq.unique is False
    # The point itself moves at the contacts' speed (atol: rounding of the twist, eps * scale).
    point = eq.velocity + eq.omega * np.array([-r[0, 1], r[0, 0]])
    np.testing.assert_allclose(point, v[0], rtol=0, atol=64 * EPS * scale)
    # Legs at distinct points that all stick fix it: unique (the earlier test's case).
    assert PlanarContactSet([[0.1, 0], [-0.1, 0], [0, 0.1]], [[0.0, 0.0]] * 3, [1.0, 1.0, 1.0]).equilibrium().unique


# -- the exact 1-D reduction --------------------------------------------------------------------
@pytest.mark.parametrize("scale", [1e-3, 1.0, 1e4])
@pytest.mark.parametrize("n", [1, 2, 3, 8, 11, 100])
def test_line_equilibrium_is_the_weighted_median(rng, n, scale):
    for equal in (True, False):
        speeds = rng.uniform(-0.35, 0.35, n) * scale
        forces = np.ones(n) if equal else rng.uniform(0.1, 3.0, n)
        line = tk.ContactSet(speeds, forces)
        lo, hi = line.equilibrium()
        planar = PlanarContactSet.on_line(line, positions=np.linspace(-1, 1, n) if n > 1 else None)
        for translation_only in (True, False):
            if n == 1 and not translation_only:
                continue                      # one point: the rotation is free (not 1-D)
            eq = planar.equilibrium(translation_only)
            if hi > lo:
                assert eq.status is EquilibriumStatus.SEGMENT and eq.unique is False
                assert eq.segment[0, 0] == lo and eq.segment[1, 0] == hi
                assert eq.velocity[0] == 0.5 * (lo + hi)
            else:
                assert eq.status is EquilibriumStatus.OPTIMAL and eq.velocity[0] == lo
            assert eq.velocity[1] == 0.0 and eq.omega == 0.0 and eq.gap <= 1e-15 * scale * n


def test_five_against_five_is_the_zero_force_band():
    line = tk.ContactSet([-0.35] * 5 + [0.35] * 5)
    eq = PlanarContactSet.on_line(line, positions=np.arange(10.0)).equilibrium()
    assert eq.status is EquilibriumStatus.SEGMENT
    np.testing.assert_array_equal(eq.segment, [[-0.35, 0.0], [0.35, 0.0]])
    np.testing.assert_array_equal(eq.velocity, [0.0, 0.0])


# -- certificates and cross-checks ---------------------------------------------------------------
@pytest.mark.parametrize("aniso", [False, True])
@pytest.mark.parametrize("n", [3, 4, 6, 20, 300])
def test_twist_equilibrium_is_certified(rng, n, aniso):
    for _ in range(5):
        contacts = _legs(rng, n, aniso)
        for translation_only in (False, True):
            eq = contacts.equilibrium(translation_only)
            _check_certificate(eq, contacts)
            # The returned twist is where the wrench set contains zero: the residual is at
            # the rounding of the sums (checked against F_tot).
            assert eq.residual_force <= 1e-9 * contacts.total_force


@pytest.mark.parametrize("aniso", [False, True])
def test_fast_solver_agrees_with_cvxpy(rng, aniso):
    for n in (5, 50, 1000):
        contacts = _legs(rng, n, aniso)
        for translation_only in (True, False):
            fast = contacts.equilibrium(translation_only, method="newton")
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")          # Clarabel at 1e-13: "inaccurate"
                ref = contacts.equilibrium(translation_only, method="cvxpy")
            scale = contacts.total_force * fast.speed_scale
            # Objective values: both certified; they agree within the larger gap (<= 1e-9).
            assert abs(fast.dissipation - ref.dissipation) <= max(fast.gap, ref.gap) + 1e-12 * scale
            assert ref.gap <= 1e-9 * scale
            # Positions: cvxpy's own accuracy is about 1e-7 of the speed scale at Clarabel's
            # tightest tolerances (docs/planar.md section 2); the fast solver's is at rounding.
            np.testing.assert_allclose(fast.twist, ref.twist, rtol=0, atol=1e-5 * fast.speed_scale)


def test_fast_median_agrees_with_weiszfeld_to_1e_10(rng):
    for n in (3, 10, 200, 2000):
        points = rng.normal(size=(n, 2))
        weights = rng.uniform(0.2, 2.0, n)
        fast = geometric_median(points, weights, method="newton")
        slow, iterations = weiszfeld(points, weights, tol=1e-15)
        # Weiszfeld converges linearly; at a 1e-15 step its error is below 1e-12 here.
        np.testing.assert_allclose(fast.velocity, slow, rtol=0, atol=1e-10 * fast.speed_scale)


def test_invariances(rng):
    contacts = _legs(rng, 9)
    eq = contacts.equilibrium()
    # Scaling every magnitude does not move it.
    scaled = contacts.with_forces(contacts.forces * 7.5)
    np.testing.assert_allclose(scaled.equilibrium().twist, eq.twist, rtol=0, atol=1e-12)
    # A common velocity u added to every contact adds u to V (Galilean).
    u = np.array([0.25, -1.5])
    moved = contacts.with_velocities(contacts.velocities + u)
    np.testing.assert_allclose(moved.equilibrium().twist, eq.twist + [*u, 0.0], rtol=0, atol=1e-12)
    # Another reference point p: V' = V + omega J p, same omega.
    p = np.array([1.0, 2.0])
    shifted = contacts.transformed(shift=p).equilibrium()
    expect = eq.velocity + eq.omega * np.array([-p[1], p[0]])
    np.testing.assert_allclose(shifted.twist, [*expect, eq.omega], rtol=0, atol=1e-12)


@settings(max_examples=40, deadline=None)
@given(n=st.integers(2, 9), seed=st.integers(0, 2**32 - 1), aniso=st.booleans())
def test_random_small_sets_are_certified(n, seed, aniso):
    rng = np.random.default_rng(seed)
    contacts = _legs(rng, n, aniso)
    for translation_only in (True, False):
        eq = contacts.equilibrium(translation_only)
        _check_certificate(eq, contacts)


def test_bad_requests_are_refused(rng):
    contacts = _legs(rng, 4)
    with pytest.raises(ParameterError, match="'method' parameter of PlanarContactSet.equilibrium must be 'weiszfeld' only with translation_only=True"):
        contacts.equilibrium(method="weiszfeld")
    with pytest.raises(ParameterError, match="Did you mean 'cvxpy'"):
        contacts.equilibrium(method="cvxpi")
    with pytest.raises(ParameterError, match="'tol'"):
        contacts.equilibrium(tol=0.0)


@pytest.mark.parametrize("scale", [2.0 ** -20, 1.0, 2.0 ** 20])
def test_weiszfeld_started_on_a_weighted_data_point(scale):
    """Four points around a fifth at the origin whose weighted mean (the start) is the origin.
    The weighted unit vectors of the others sum to ``R = (-2, 0)`` at every scale. With the centre's weight 2.5 >= |R| the origin is the median: returned
    exactly, in one iteration. With weight 1.5 < |R| Vardi and Zhang's first step is
    ``(1 - 1.5/2) T`` with ``T = (-6/13, 0)`` the Weiszfeld point of the others: ``(-3/26, 0)``
    to rounding (4 eps). Points at 2**-20, 1 and 2**20 (exact). Mutant killed: the points at
    ``y`` counted (``eta = at.sum()``) instead of weighed: it steps away from the median."""
    points = np.array([[0.0, 0.0], [3.0, 0.0], [-1.0, 0.0], [0.0, 2.0], [0.0, -2.0]]) * scale
    others = np.array([1.0, 3.0, 1.0, 1.0])
    median, iterations = weiszfeld(points, np.r_[2.5, others])
    assert iterations == 1 and np.array_equal(median, [0.0, 0.0])
    step, iterations = weiszfeld(points, np.r_[1.5, others], max_iter=1)
    assert iterations == 1
    np.testing.assert_allclose(step, np.array([-3.0 / 26.0, 0.0]) * scale, rtol=4 * np.finfo(float).eps, atol=0.0)


_TRIO = ([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]], [[0.1, 0.0], [0.0, 0.2], [-0.1, 0.1]])
_C = PlanarContactSet(*_TRIO)
_A = PlanarContactSet(*_TRIO, anisotropy=[[0.0, 0.5]] * 3)


@pytest.mark.parametrize(("call", "error", "message"), [
    (lambda: solve_equilibrium('x'), ParameterTypeError,
     "The 'contacts' parameter of PlanarContactSet.equilibrium must be a PlanarContactSet. Got 'x' instead."),
    (lambda: solve_equilibrium(_C, translation_only=1), ParameterTypeError,
     "The 'translation_only' parameter of PlanarContactSet.equilibrium must be a bool. Got 1 instead."),
    (lambda: solve_equilibrium(_C, method='newtn'), ParameterError,
     "The 'method' parameter of PlanarContactSet.equilibrium must be one of ['auto', 'newton', "
     "'cvxpy', 'weiszfeld']. Got 'newtn' instead. Did you mean 'newton'?"),
    (lambda: solve_equilibrium(_C, tol=0.0), ParameterError,
     "The 'tol' parameter of PlanarContactSet.equilibrium must be > 0. Got 0.0 instead."),
    (lambda: solve_equilibrium(_C, method='weiszfeld'), ParameterError,
     "The 'method' parameter of PlanarContactSet.equilibrium must be 'weiszfeld' only with "
     "translation_only=True (the geometric median). Got 'weiszfeld' instead."),
    (lambda: weiszfeld([[0.0, 0.0], [1.0, 1.0]], [1.0, 0.0]), ParameterError,
     "The 'points' parameter of weiszfeld must have shape (n, 2) with n positive weights. Got "
     "'shapes (2, 2) and (2,)' instead."),
    (lambda: weiszfeld([0.0, 1.0]), ParameterError,
     "The 'points' parameter of weiszfeld must have shape (n, 2) with n positive weights. Got "
     "'shapes (2,) and (2,)' instead."),
    (lambda: weiszfeld([[0.0, 0.0], [1.0, 1.0]], [1.0]), ParameterError,
     "The 'points' parameter of weiszfeld must have shape (n, 2) with n positive weights. Got "
     "'shapes (2, 2) and (1,)' instead."),
    (lambda: solve_equilibrium(_A, translation_only=True, method='weiszfeld'), ParameterError,
     "The 'method' parameter of PlanarContactSet.equilibrium must be 'weiszfeld' only for isotropic "
     "contacts. Got 'weiszfeld' instead."),
])
def test_every_refusal_of_the_equilibrium_in_full(call, error, message):
    """Each refusal matched whole: parameter, owner, rule and value (mutants: any of them changed,
    dropped or replaced by None, the isotropy and translation checks)."""
    with pytest.raises(error) as info:
        call()
    assert str(info.value) == message

