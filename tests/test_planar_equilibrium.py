"""The planar equilibrium: closed forms, the exact 1-D reduction, certificates, cross-checks."""

from __future__ import annotations

import time
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



# -- the pieces, in closed form ------------------------------------------------------------------
from toolkit.planar import equilibrium as _eqmod                       # noqa: E402
from toolkit.planar.equilibrium import _canonical, speed_scale, twist_problem   # noqa: E402

SCALES = [2.0 ** -20, 1.0, 2.0 ** 20]


def test_canonical_directions():
    """Components at most ``4 eps`` are snapped to 0 (``5 eps`` is kept), the first non-zero
    component made positive, and no negative zero is returned."""
    assert np.array_equal(_canonical(np.array([1.0, 4 * EPS])), [1.0, 0.0])
    assert _canonical(np.array([1.0, 5 * EPS]))[1] == 5 * EPS
    for e, expect in (([-1.0, 0.0], [1.0, 0.0]), ([0.0, -1.0], [0.0, 1.0]), ([-0.6, 0.8], [0.6, -0.8]),
                      ([0.0, 2.0], [0.0, 1.0]), ([0.0, 0.5], [0.0, 1.0]), ([0.0, -0.5], [0.0, 1.0]),
                      ([-4 * EPS, -1.0], [0.0, 1.0])):
        got = _canonical(np.array(e))
        assert np.array_equal(got, expect) and not np.any(np.signbit(got) & (got == 0)), e


@pytest.mark.parametrize("scale", SCALES)
def test_speed_scale_is_the_weighted_mean_deviation(scale):
    """Weights 3 and 1 at 0 and 4 (times the scale): the weighted mean is 1, the deviations 1
    and 3, the scale ``(3 * 1 + 1 * 3) / 4 = 1.5`` (exact; equal weights would give 2). Forces
    at any scale leave it unchanged. Equal velocities: ``1e-9 max |v_i|``; all at rest: 1."""
    for fscale in SCALES:
        c = PlanarContactSet([[0.0, 0.0], [1.0, 0.0]], np.array([[0.0, 0.0], [4.0, 0.0]]) * scale,
                             np.array([3.0, 1.0]) * fscale)
        assert speed_scale(c) == 1.5 * scale
    same = PlanarContactSet([[0.0, 0.0], [1.0, 0.0]], np.array([[2.0, -3.0]] * 2) * scale, [3.0, 1.0])
    assert speed_scale(same) == 1e-9 * 3.0 * scale
    assert speed_scale(PlanarContactSet([[0.0, 0.0], [1.0, 0.0]], [[0.0, 0.0]] * 2, [3.0, 1.0])) == 1.0


def test_twist_problem_in_closed_form():
    """Unknowns ``((Vc - shift) / S, omega L / S)``: ``c_i = D_i^T (v_i - shift) / S``,
    ``B_i = D_i^T [[1, 0, -r_y / L], [0, 1, r_x / L]]`` with ``r = r_i - centre``, weights
    ``f_i / F_tot``; a lifted contact is left out (dyadic numbers: exact)."""
    M = np.array([[[4.0, 2.0], [2.0, 2.0]], [[1.0, 0.0], [0.0, 9.0]], [[1.0, 0.0], [0.0, 1.0]]])
    pos = np.array([[1.0, 2.0], [-1.0, 0.5], [3.0, 3.0]])
    vel = np.array([[0.5, 1.0], [2.0, -1.0], [7.0, 7.0]])
    c = PlanarContactSet(pos, vel, [3.0, 1.0, 0.0], M)
    centre, S, L, shift = np.array([0.5, 1.0]), 2.0, 4.0, np.array([0.25, 0.5])
    prob, active = twist_problem(c, False, centre, S, L, shift)
    assert active.tolist() == [0, 1]
    Dt = np.swapaxes(c.limit_factors[:2], 1, 2)
    r = (pos[:2] - centre) / L
    A = np.zeros((2, 2, 3))
    A[:, 0, 0] = A[:, 1, 1] = 1.0
    A[:, 0, 2], A[:, 1, 2] = -r[:, 1], r[:, 0]
    assert np.array_equal(prob.f, [0.75, 0.25])
    assert np.array_equal(prob.c, np.einsum("nij,nj->ni", Dt, (vel[:2] - shift) / S))
    assert np.array_equal(prob.B, Dt @ A) and np.array_equal(prob.b, np.zeros(3)) and prob.Q is None
    # Translation only: two unknowns; isotropic: D = I; no shift.
    iso = PlanarContactSet(pos, vel, [3.0, 1.0, 0.5])
    prob, active = twist_problem(iso, True, centre, S, L)
    assert active.tolist() == [0, 1, 2] and prob.B.shape == (3, 2, 2)
    assert np.array_equal(prob.c, vel / S) and np.array_equal(prob.B, np.broadcast_to(np.eye(2), (3, 2, 2)))


@pytest.mark.parametrize("fscale", SCALES)
def test_the_result_reports_in_physical_units(rng, fscale):
    """Unequal forces at ``2**-20``, 1 and ``2**20``: the twist does not move (the problem is
    scaled by F_tot, exactly), while the gap, the tolerance ``tol F_tot S``, the residuals, the
    dissipation and the contact forces scale with the force (rtol 1e-12: the solver's
    iterations see the same scaled numbers). The dissipation is Phi at the returned twist."""
    base = _legs(rng, 7)
    ref = base.equilibrium(method="newton")
    c = base.with_forces(base.forces * fscale)
    for method in ("newton", "auto"):
        eq = c.equilibrium(method=method, tol=1e-9)
        assert eq.method == "newton" and eq.status is EquilibriumStatus.OPTIMAL and eq.certified
        assert eq.total_force == c.total_force and eq.speed_scale == speed_scale(c)
        assert eq.tolerance == 1e-9 * c.total_force * eq.speed_scale
        assert eq.relative_gap == eq.gap / (eq.total_force * eq.speed_scale)
        assert eq.dissipation == float(c.dissipation(eq.velocity, eq.omega))
        assert np.array_equal(eq.twist, [eq.velocity[0], eq.velocity[1], eq.omega])
        np.testing.assert_allclose(eq.twist, ref.twist, rtol=0, atol=1e-12)
        np.testing.assert_allclose(eq.contact_forces, ref.contact_forces * fscale, rtol=0, atol=1e-12 * fscale)
        np.testing.assert_allclose(eq.dissipation, ref.dissipation * fscale, rtol=1e-12)
        assert eq.residual_force <= 1e-12 * c.total_force and eq.residual_torque <= 1e-12 * c.total_force
        assert eq.wall_time > 0 and eq.iterations > 0 and not eq.translation_only and eq.segment is None
        assert eq.message == ""
        for array in (eq.velocity, eq.contact_forces, eq.stuck):
            assert not array.flags.writeable


def test_a_lifted_contact_gets_no_force_and_is_not_stuck():
    """A lifted contact (f = 0) at the equilibrium's own velocity: left out of the problem,
    its certificate force 0 and it is not stuck; the others' equilibrium as without it."""
    pos = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 2.0], [1.0, 1.0]])
    vel = np.array([[0.5, 0.0], [4.0, 1.0], [1.0, -3.0], [0.5, 0.0]])
    c = PlanarContactSet(pos, vel, [3.0, 1.0, 2.0, 0.0])
    eq = c.equilibrium(method="newton")
    ref = c.subset([0, 1, 2]).equilibrium(method="newton")
    assert np.array_equal(eq.contact_forces[3], [0.0, 0.0]) and not eq.stuck[3]
    np.testing.assert_allclose(eq.twist, ref.twist, rtol=0, atol=1e-13)
    np.testing.assert_allclose(eq.contact_forces[:3], ref.contact_forces, rtol=0, atol=1e-13)
    assert eq.stuck[:3].tolist() == ref.stuck.tolist() == [True, False, False]


def test_a_back_end_that_fails_gives_a_status_not_a_traceback(monkeypatch):
    """Any exception of a back end: status SOLVER_ERROR with its text, NaN twist and forces,
    an infinite gap, the tolerance still ``tol F_tot S`` and nothing stuck."""
    def broken(prob, tol):
        raise RuntimeError("no convergence")

    monkeypatch.setattr(_eqmod, "solve_fast", broken)
    monkeypatch.setattr(_eqmod, "solve_cvxpy", broken)
    c = PlanarContactSet([[0.0, 0.0], [1.0, 0.0], [0.0, 2.0]], [[0.5, 0.0], [4.0, 1.0], [1.0, -3.0]], [3.0, 1.0, 2.0])
    for method, translation_only in (("auto", False), ("cvxpy", True), ("newton", False)):
        started = time.perf_counter()
        eq = c.equilibrium(translation_only, method=method, tol=1e-8)
        assert 0 <= eq.wall_time <= time.perf_counter() - started
        assert eq.stuck.dtype == bool
        assert eq.status is EquilibriumStatus.SOLVER_ERROR and not eq.certified
        assert eq.status.value == "the numerical back end failed; see 'message'"
        assert eq.message == "no convergence" and eq.method == method and eq.iterations == 0
        assert np.all(np.isnan(eq.velocity)) and eq.velocity.shape == (2,) and np.isnan(eq.omega)
        assert eq.gap == np.inf and eq.tolerance == 1e-8 * c.total_force * speed_scale(c)
        assert eq.total_force == c.total_force and eq.speed_scale == speed_scale(c)
        assert np.isnan(eq.dissipation) and np.isnan(eq.residual_force) and np.isnan(eq.residual_torque)
        assert eq.contact_forces.shape == (3, 2) and np.all(np.isnan(eq.contact_forces))
        assert eq.stuck.tolist() == [False] * 3 and eq.segment is None and eq.unique is None
        assert eq.translation_only is translation_only and eq.wall_time >= 0


def test_auto_falls_back_to_cvxpy_when_newton_is_not_certified(monkeypatch):
    """``"auto"``: a Newton answer above the tolerance is replaced by the cone program's when
    that one's gap is smaller (here Newton's gap is forced to 1)."""
    real = _eqmod.solve_fast

    def uncertified(prob, tol):
        sol = real(prob, tol)
        return type(sol)(sol.x, sol.g, 1.0, sol.residual, sol.stuck, sol.iterations, sol.method)

    monkeypatch.setattr(_eqmod, "solve_fast", uncertified)
    c = PlanarContactSet([[0.0, 0.0], [1.0, 0.0], [0.0, 2.0]], [[0.5, 0.0], [4.0, 1.0], [1.0, -3.0]], [3.0, 1.0, 2.0])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert c.equilibrium(method="auto").method == "cvxpy"
        eq = c.equilibrium(method="newton")
    # Newton alone keeps its (forced) gap: not certified, INACCURATE, the gap in watts.
    assert eq.method == "newton" and eq.status is EquilibriumStatus.INACCURATE and not eq.certified
    assert eq.gap == 1.0 * c.total_force * eq.speed_scale


@pytest.mark.parametrize("scale", SCALES)
def test_translation_only_median_on_a_slanted_line(scale):
    """Velocities on the line through (1, 2) along (3, 4) with weights 1, 2, 0.5 (and a
    lifted contact off the line, which does not count): the 1-D weighted median is the
    velocity of the contact of weight 2, returned exactly (a data point), with the 1-D
    method's name and message; uneven weights 2, 2 give the segment between two contacts.
    Mutants killed: the lifted contact counted, the direction or the speeds lost."""
    e = np.array([0.6, 0.8])
    p = np.array([1.0, 2.0])
    vel = np.r_[p + np.array([-1.0, 2.0, 5.0])[:, None] * e, [[9.0, -9.0]]] * scale
    pos = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [2.0, 2.0]])
    eq = PlanarContactSet(pos, vel, [1.0, 2.0, 0.5, 0.0]).equilibrium(True)
    assert eq.status is EquilibriumStatus.OPTIMAL and eq.method == "median-1d" and eq.unique is True
    assert eq.message == "contacts and motion on one line: the 1-D weighted median"
    assert np.array_equal(eq.velocity, vel[1]) and eq.omega == 0.0 and eq.iterations == 0
    assert eq.stuck.tolist() == [False, True, False, False]
    seg = PlanarContactSet(pos, vel, [1.0, 2.0, 2.0, 1.0]).equilibrium(True)  # now the 4th counts: no line
    assert seg.method != "median-1d"
    seg = PlanarContactSet(pos[:3], vel[:3], [1.5, 1.0, 2.5]).equilibrium(True)
    assert seg.status is EquilibriumStatus.SEGMENT and seg.unique is False
    assert np.array_equal(seg.segment, vel[1:3]) and np.array_equal(seg.velocity, 0.5 * (vel[1] + vel[2]))


@pytest.mark.parametrize("scale", SCALES)
def test_collinear_velocities_bracketed(scale):
    """A velocity ``k eps`` (times the scale) off the line of the others, all of order 1:
    ``k = 16`` is on it (``16 eps`` of the largest speed), ``k = 17`` is not."""
    for k, on in ((16, True), (17, False)):
        vel = np.array([[0.0, 0.0], [1.0, 0.0], [0.5, k * EPS]]) * scale
        eq = PlanarContactSet(np.zeros((3, 2)), vel, [1.0, 1.5, 1.0]).equilibrium(True)
        assert (eq.method == "median-1d") is on
    # Two velocities 16 eps apart (of the largest coordinate) count as one point: the line is
    # the x axis, on which both have speed 0, and the first is returned; 17 eps apart they are
    # two points on the y axis, and the weighted median is the heavier second.
    for k, first in ((16, True), (17, False)):
        pair = np.array([[0.0, 1.0 - k * EPS], [0.0, 1.0]]) * scale
        eq = PlanarContactSet(np.zeros((2, 2)), pair, [1.0, 2.0]).equilibrium(True)
        assert eq.method == "median-1d" and np.array_equal(eq.velocity, pair[0 if first else 1])
    # Every velocity the same: a line through them all, the median that velocity exactly.
    same = PlanarContactSet(np.zeros((3, 2)), np.array([[1.0, 2.0]] * 3) * scale, [1.0, 1.5, 1.0]).equilibrium(True)
    assert same.method == "median-1d" and np.array_equal(same.velocity, np.array([1.0, 2.0]) * scale)
    # Anisotropic with the x axis an axis of every ellipse: still the 1-D median.
    same = PlanarContactSet(np.zeros((3, 2)), np.array([[1.0, 2.0]] * 3) * scale, [1.0, 1.5, 1.0],
                            [[0.0, 2.0]] * 3).equilibrium(True)
    assert same.method == "median-1d" and np.array_equal(same.velocity, np.array([1.0, 2.0]) * scale)


def test_collinear_velocities_at_a_tiny_scale():
    """Velocities of order 2**-40 on the line along (3, 4): still found on it (the direction
    is normalized before round-off components are snapped)."""
    e = np.array([0.6, 0.8])
    vel = np.outer([-1.0, 2.0, 5.0], e) * 2.0 ** -40
    eq = PlanarContactSet(np.zeros((3, 2)), vel, [1.0, 2.0, 0.5]).equilibrium(True)
    assert eq.method == "median-1d" and np.array_equal(eq.velocity, vel[1])


def test_weiszfeld_stops_at_its_tolerance_and_its_iteration_limit():
    """A triangle (no data point is the median): the iteration count is ``max_iter`` when it
    stops there, and a looser ``tol`` stops earlier; the step at ``tol`` moves less than
    ``tol`` times the spread (4, the x extent). Every run starts at the weighted mean."""
    points = np.array([[0.0, 0.0], [4.0, 0.0], [1.0, 3.0]])
    w = np.array([1.0, 2.0, 1.5])
    y1, it1 = weiszfeld(points, w, max_iter=1)
    assert it1 == 1
    mean = w @ points / w.sum()
    d = np.hypot(*(points - mean).T)
    np.testing.assert_allclose(y1, (w / d) @ points / np.sum(w / d), rtol=4 * EPS)    # one Weiszfeld step
    _, it3 = weiszfeld(points, w, max_iter=3)
    assert it3 == 3
    y_loose, it_loose = weiszfeld(points, w, tol=1e-4)
    y_tight, it_tight = weiszfeld(points, w, tol=1e-14)
    assert it_loose < it_tight < 100_000
    ref = geometric_median(points, w).velocity
    # Linear convergence: the error after a step below 1e-4 * 4 is of that order (factor 10).
    assert np.max(np.abs(y_loose - ref)) <= 4e-3 and np.max(np.abs(y_tight - ref)) <= 1e-12
    # Equal weights by default; every point equal: spread 1, the point itself.
    assert np.array_equal(weiszfeld(points)[0], weiszfeld(points, np.ones(3))[0])
    assert np.array_equal(weiszfeld([[2.0, 3.0]] * 3)[0], [2.0, 3.0])


def test_weiszfeld_method_of_the_solver():
    points = np.array([[0.0, 0.0], [4.0, 0.0], [1.0, 3.0], [-1.0, 2.0]])
    w = np.array([1.0, 2.0, 1.5, 0.5])
    eq = geometric_median(points, w, method="weiszfeld")
    assert eq.method == "weiszfeld" and eq.iterations > 1 and eq.status is EquilibriumStatus.OPTIMAL
    # Run to a step of 1e-15 of the spread: more steps than to 1e-14 (linear convergence, a few
    # steps per decade; the scaled data are the points moved and scaled, the same iteration).
    assert eq.iterations > weiszfeld(points, w, tol=1e-14)[1]
    # Integer points and weights: the same median.
    assert np.array_equal(weiszfeld(points.astype(int), [2, 4, 3, 1])[0], weiszfeld(points, 2 * w)[0])
    ref = geometric_median(points, w, method="newton")
    np.testing.assert_allclose(eq.velocity, ref.velocity, rtol=0, atol=1e-12)


def test_statuses_say_what_they_mean():
    """Each status's value is the message a user reads, whole."""
    assert [s.value for s in EquilibriumStatus] == [
        "certified: the duality gap is within the tolerance",
        "certified: the contacts and the motion lie on one line and the equilibria form a segment (a "
        "zero-force band, exactly as in the 1-D toolkit); 'velocity' is its midpoint, 'segment' its two ends",
        "not certified: the duality gap is above the tolerance; 'gap' bounds how far the dissipation at the "
        "returned twist may be above the optimum",
        "the numerical back end failed; see 'message'"]


def test_uniqueness_is_established_only_when_it_holds():
    """Sliding contacts all on the line through the stuck one make the dissipation flat across
    that line only at second order (its Hessian singular): uniqueness is not established by the
    general solvers (None), though the 1-D reduction knows it (True). Off a line, the Hessian is
    definite: True."""
    line = np.array([[0.0, 0.0], [1.0, 0.0], [3.0, 0.0]])
    assert geometric_median(line, [1.0, 2.0, 1.5]).unique is True
    for method in ("newton", "cvxpy"):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            eq = geometric_median(line, [1.0, 2.0, 1.5], method=method)
        assert eq.unique is None and np.array_equal(eq.velocity, [1.0, 0.0]), method
    eq = geometric_median(np.array([[0.0, 0.0], [1.0, 0.0], [3.0, 1.0], [0.0, 2.0]]), [1.0, 1.0, 1.5, 1.0],
                          method="newton")
    assert eq.unique is True and not np.any(eq.stuck)


@pytest.mark.parametrize("fscale", SCALES)
def test_result_converts_a_scaled_solution_to_physical_units(fscale):
    """A scaled solution ``x = (0.5, -0.25, 2)`` with ``S = 2``, ``L = 4``, shift ``(1, 1)`` and
    centre ``(1, 2)`` (dyadic: exact): ``omega = x_2 S / L = 1``, ``Vc = x S + shift = (2, 0.5)``
    and ``V = Vc - omega J centre = (2 + 2, 0.5 - 1)``. The gap ``gap F S``, the residuals
    ``|res_xy| F`` and ``|res_w| F L``, the forces ``D g F`` of the active contacts (0 for the
    lifted one), the status from the gap against ``tol F S`` bracketed at equality. Forces at
    2**-20, 1 and 2**20 (exact). Translation only, a stuck contact's own velocity is returned."""
    from toolkit.planar._socp import Solution

    M = np.array([[[4.0, 2.0], [2.0, 2.0]], [[1.0, 0.0], [0.0, 4.0]], [[1.0, 0.0], [0.0, 1.0]]])
    c = PlanarContactSet([[0.0, 0.0], [3.0, 1.0], [1.0, 1.0]], [[0.5, 1.0], [2.0, -1.0], [7.0, 7.0]],
                         np.array([3.0, 0.0, 1.0]) * fscale, M)
    F = c.total_force
    centre, S, L, shift, tol = np.array([1.0, 2.0]), 2.0, 4.0, np.array([1.0, 1.0]), 2.0 ** -10
    prob, active = twist_problem(c, False, centre, S, L, shift)
    assert active.tolist() == [0, 2]
    g = np.array([[0.25, 0.5], [-0.25, -0.5]])
    for gap, status in ((tol, EquilibriumStatus.OPTIMAL), (tol * (1 + 2 * EPS), EquilibriumStatus.INACCURATE)):
        sol = Solution(np.array([0.5, -0.25, 2.0]), g, gap, np.array([3.0, 4.0, -2.0]), np.array([False, False]), 7,
                       "fake")
        started = time.perf_counter() - 1.0
        eq = _eqmod._result(c, False, prob, active, sol, centre, S, L, tol, started, "note", shift=shift)
        assert 1.0 <= eq.wall_time <= time.perf_counter() - started
        assert eq.omega == 1.0 and np.array_equal(eq.velocity, [4.0, -0.5]) and eq.status is status
        assert eq.gap == gap * F * S and eq.tolerance == tol * F * S
        assert eq.residual_force == 5.0 * F and eq.residual_torque == 2.0 * F * L
        D = c.limit_factors
        assert np.array_equal(eq.contact_forces, [D[0] @ g[0] * F, [0.0, 0.0], D[2] @ g[1] * F])
        assert eq.stuck.tolist() == [False, False, False] and eq.iterations == 7 and eq.method == "fake"
        assert eq.message == "note" and eq.total_force == F and eq.speed_scale == S and eq.segment is None
        assert not eq.translation_only and eq.stuck.dtype == bool
    prob, active = twist_problem(c, True, centre, S, L, shift)
    sol = Solution(np.array([0.5, -0.25]), g, 0.0, np.array([3.0, 4.0]), np.array([False, True]), 1, "fake")
    eq = _eqmod._result(c, True, prob, active, sol, centre, S, L, tol, 0.0, "", shift=shift)
    assert np.array_equal(eq.velocity, [7.0, 7.0]) and eq.omega == 0.0 and eq.residual_torque == 0.0
    assert eq.stuck.tolist() == [False, False, True] and eq.translation_only


def test_the_1d_median_is_a_touching_contact_velocity():
    """Velocities on the line y = 1 with weights 1, 2, 0.5: the median is (2, 1), the velocity of
    the contact of weight 2, exactly; a lifted contact listed first with the same speed along
    the line but off it, (2, 5), is never returned. The full twist of the same contacts on a
    line of positions: the median speed along the line, ``omega = 0``."""
    vel = np.array([[2.0, 5.0], [0.0, 1.0], [2.0, 1.0], [5.0, 1.0]])
    c = PlanarContactSet([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0], [3.0, 0.0]], vel, [0.0, 1.0, 2.0, 0.5])
    eq = c.equilibrium(True)
    assert eq.method == "median-1d" and np.array_equal(eq.velocity, [2.0, 1.0])
    line = PlanarContactSet([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0], [3.0, 0.0]], vel * [1.0, 0.0], [0.0, 1.0, 2.0, 0.5])
    eq = line.equilibrium()
    assert eq.method == "median-1d" and np.array_equal(eq.twist, [2.0, 0.0, 0.0]) and eq.unique is True
    seg = line.with_forces([0.0, 1.0, 0.5, 0.5]).equilibrium()
    assert seg.status is EquilibriumStatus.SEGMENT and np.array_equal(seg.segment, [[0.0, 0.0], [2.0, 0.0]])
    assert np.array_equal(seg.velocity, [1.0, 0.0]) and seg.omega == 0.0


@pytest.mark.parametrize("wscale", SCALES)
def test_weiszfeld_step_from_a_weighted_data_point_off_the_origin(wscale):
    """The five points of the test above moved by ``c = (1, 2)`` and weighted at ``2**-20``, 1
    and ``2**20``: the weights' scale cancels, the step moves with the points. Centre weight
    ``2.5 wscale`` (at least ``|R| = 2 wscale``): the centre ``c`` in one iteration; ``1.5
    wscale``: one step to ``c + (-3/26, 0)`` (rounding of the shifted sums: atol 8 eps).
    Mutants killed: the data-point branch taken only for a weight above 1, the step's
    ``(eta / r) y`` term with its sign changed (invisible at y = 0)."""
    c = np.array([1.0, 2.0])
    points = np.array([[0.0, 0.0], [3.0, 0.0], [-1.0, 0.0], [0.0, 2.0], [0.0, -2.0]]) + c
    others = np.array([1.0, 3.0, 1.0, 1.0])
    median, iterations = weiszfeld(points, np.r_[2.5, others] * wscale)
    assert iterations == 1 and np.array_equal(median, c)
    step, iterations = weiszfeld(points, np.r_[1.5, others] * wscale, max_iter=1)
    assert iterations == 1
    np.testing.assert_allclose(step, c + [-3.0 / 26.0, 0.0], rtol=0, atol=8 * EPS)


def test_weiszfeld_stops_relative_to_the_spread_of_each_axis():
    """Points 4 wide moved 1000 away from the origin: the stop (a step below ``tol`` times the
    largest extent along an axis, 4) is where it is near the origin, so both medians agree to
    the step's size (1e-10 * 4, and the linear rate: 1e-8). A stop scaled by the coordinates
    (about 2000) would stop 500 times earlier; one that divides by the spread instead would
    not be scale-free."""
    points = np.array([[0.0, 0.0], [4.0, 0.0], [1.0, 3.0], [-1.0, 2.0]])
    w = np.array([1.0, 2.0, 1.5, 0.5])
    shift = np.array([1000.0, -1000.0])
    near, _ = weiszfeld(points, w, tol=1e-10)
    far, _ = weiszfeld(points + shift, w, tol=1e-10)
    np.testing.assert_allclose(far - shift, near, rtol=0, atol=1e-8)
    # Scaled by 2**-20 and 2**20 (exact): the same iterates scaled, so the same count.
    count = weiszfeld(points, w, tol=1e-10)[1]
    for scale in (2.0 ** -20, 2.0 ** 20):
        scaled, iterations = weiszfeld(points * scale, w, tol=1e-10)
        assert iterations == count and np.array_equal(scaled, near * scale)


def test_full_twist_reduction_edges():
    """Positions 0.5 apart (less than 1) are distinct: the 1-D reduction applies. A velocity
    ``2 eps`` off the line (within its tolerance) still reduces, and the equilibrium at that
    contact's speed is returned on the line, ``(0.5, 0)`` exactly, not the velocity itself.
    One touching contact and a lifted one: the rotation is free, solved in general (not
    unique)."""
    c = PlanarContactSet([[0.0, 0.0], [0.25, 0.0], [0.5, 0.0]], [[0.5, 2 * EPS], [-0.25, 0.0], [0.125, 0.0]],
                         [2.0, 1.0, 0.5])
    eq = c.equilibrium()
    assert eq.method == "median-1d" and np.array_equal(eq.twist, [0.5, 0.0, 0.0])
    eq = c.with_forces([1.0, 2.0, 0.5]).equilibrium()
    assert eq.method == "median-1d" and np.array_equal(eq.twist, [-0.25, 0.0, 0.0])
    assert not np.signbit(eq.velocity[1])          # -0.25 * 0.0 is -0.0: made +0.0
    one = PlanarContactSet([[0.0, 0.0], [1.0, 0.0]], [[0.5, 0.0], [0.5, 0.0]], [1.0, 0.0]).equilibrium()
    assert one.method == "newton" and one.certified and one.unique is False
    # The contact is at the reference point: V is its velocity (rounding of the solve: 1e-15).
    np.testing.assert_allclose(one.velocity, [0.5, 0.0], rtol=0, atol=1e-15)


def test_default_tolerance_and_method():
    """Called directly, the solver certifies to ``1e-10 F_tot S`` and picks its method itself
    (here the 1-D reduction does not apply: Newton), as PlanarContactSet.equilibrium does."""
    c = PlanarContactSet([[0.0, 0.0], [1.0, 0.0], [0.0, 2.0]], [[0.5, 0.0], [4.0, 1.0], [1.0, -3.0]], [3.0, 1.0, 2.0])
    eq = solve_equilibrium(c)
    assert eq.tolerance == 1e-10 * c.total_force * eq.speed_scale and eq.method == "newton"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")          # (Clarabel at its tightest: "inaccurate")
        assert solve_equilibrium(c, method="cvxpy").method == "cvxpy"
    assert not eq.translation_only and np.array_equal(eq.twist, c.equilibrium().twist)


def test_uniqueness_threshold_on_a_nearly_collinear_set():
    """The median at the data point (1, 0) of weight 2, the two sliding contacts at (0, 0) and
    (3, d): their Hessian's eigenvalues are in the ratio of about ``d^2 / 10``. For ``d = 1e-6``
    (ratio ~1e-13) it is singular to the solver's ``1e-9``: uniqueness is not established
    (None); for ``d = 1e-3`` (ratio ~1e-7) it is (True)."""
    for d, unique in ((1e-6, None), (1e-3, True)):
        eq = geometric_median(np.array([[0.0, 0.0], [1.0, 0.0], [3.0, d]]), [1.0, 2.0, 1.5], method="newton")
        assert np.array_equal(eq.velocity, [1.0, 0.0]) and eq.stuck.tolist() == [False, True, False]
        assert eq.unique is unique
