"""Planar contact sets: the wrench against the 1-D set, identities, frames, vectorization."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import toolkit as tk
from toolkit.errors import ParameterError, ParameterTypeError
from toolkit.planar import PlanarContactSet, geometric_median, wrench_batch

EPS = float(np.finfo(float).eps)


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(20260422)


def _random_set(rng, n, scale=1.0, aniso=False):
    anisotropy = np.c_[rng.uniform(0, np.pi, n), rng.uniform(0.2, 5.0, n)] if aniso else None
    return PlanarContactSet(rng.normal(size=(n, 2)) * scale, rng.normal(size=(n, 2)) * scale,
                            rng.uniform(0.1, 3.0, n) * scale, anisotropy)


@pytest.mark.parametrize("scale", [1e-3, 1.0, 1e3])
@pytest.mark.parametrize("n", [1, 2, 7, 10, 101])
def test_line_wrench_is_the_1d_force(rng, n, scale):
    # Contacts on the x axis moving along it: the planar force is ContactSet.force, the force
    # bounds at a tie are ContactSet.force_bounds, and the torque about the axis is zero.
    speeds = np.round(rng.uniform(-0.35, 0.35, n) * scale, 3)
    forces = rng.uniform(0.1, 2.0, n) * scale
    line = tk.ContactSet(speeds, forces)
    planar = PlanarContactSet.on_line(line, positions=rng.normal(size=n))
    V = np.concatenate((speeds, np.linspace(-0.5, 0.5, 41) * scale, [-10 * scale, 10 * scale]))
    force, torque = planar.wrench(np.c_[V, np.zeros_like(V)], np.zeros_like(V))
    # Both sums round differently (index order against prefix sums of sorted levels) and
    # both snap below their tie tolerance: they differ by at most 4 (n + 1) eps F_tot.
    tol = planar.tie_tolerance
    np.testing.assert_allclose(force[:, 0], line.force(V), rtol=0, atol=tol)
    assert np.all(force[:, 1] == 0.0) and np.all(torque == 0.0)
    for v in speeds[:3]:
        lo, hi = planar.wrench_set([v, 0.0], 0.0).bounds([1.0, 0.0, 0.0])
        lo1, hi1 = line.force_bounds(v)
        np.testing.assert_allclose([lo, hi], [lo1, hi1], rtol=0, atol=tol)


def test_line_wrench_is_bitwise_the_1d_force_with_dyadic_loads():
    # Loads that add up exactly (dyadic): no rounding anywhere, the two agree bit for bit,
    # the zero-force band of five against five included.
    speeds = np.array([-0.35] * 5 + [0.35] * 5 + [0.125, -0.25, 0.0])
    forces = np.array([1.0] * 10 + [0.5, 0.25, 2.0])
    line = tk.ContactSet(speeds, forces)
    planar = PlanarContactSet.on_line(line, positions=np.arange(13.0))
    V = np.linspace(-0.5, 0.5, 201)
    force, _ = planar.wrench(np.c_[V, np.zeros_like(V)], 0.0)
    assert np.array_equal(force[:, 0], line.force(V))


def test_identities_on_random_sets(rng):
    for aniso in (False, True):
        contacts = _random_set(rng, 40, aniso=aniso)
        V = rng.normal(size=(500, 2))
        w = rng.normal(size=500)
        force, torque = contacts.wrench(V, w)
        phi = contacts.dissipation(V, w)
        s = contacts.slips(V, w)
        # |F| <= sum f_i s_max(D_i) (each force inside its ellipse), and for isotropic sets <= F_tot.
        smax = 1.0 if not aniso else np.linalg.svd(contacts.limit_factors, compute_uv=False)[:, 0]
        assert np.all(np.hypot(force[:, 0], force[:, 1]) <= np.sum(contacts.forces * smax) * (1 + 1e-12))
        assert np.all(phi >= 0)
        # Power balance: F . V + tau omega = sum F_i . v_i - Phi (the contacts' forces do the
        # work sum F_i . (v_i - s_i)); rounding of sums of 40 terms of order 10: atol 1e-11.
        per = _contact_forces(contacts, s)
        lhs = np.sum(force * V, axis=1) + torque * w
        rhs = np.einsum("mni,ni->m", per, contacts.velocities) - phi
        np.testing.assert_allclose(lhs, rhs, rtol=0, atol=1e-11)


def _contact_forces(contacts, s):
    if contacts.isotropic:
        z, D = s, None
    else:
        D = contacts.limit_factors
        z = np.einsum("nji,mnj->mni", D, s)
    u = z / np.hypot(z[..., 0], z[..., 1])[..., None]
    F = u if D is None else np.einsum("nij,mnj->mni", D, u)
    return F * contacts.forces[:, None]


def test_wrench_is_minus_the_gradient_of_the_dissipation(rng):
    # Central differences of Phi at twists away from any stick: truncation O(h^2 |Phi'''|)
    # with h = 1e-6 and slips of order 1 is below 1e-9; rounding eps |Phi| / h ~ 1e-9: atol 1e-7.
    for aniso in (False, True):
        contacts = _random_set(rng, 25, aniso=aniso)
        for _ in range(20):
            x = rng.normal(size=3)
            force, torque = contacts.wrench(x[:2], x[2])
            h = 1e-6
            grad = []
            for k in range(3):
                e = np.zeros(3)
                e[k] = h
                grad.append((contacts.dissipation((x + e)[:2], (x + e)[2])
                             - contacts.dissipation((x - e)[:2], (x - e)[2])) / (2 * h))
            np.testing.assert_allclose([force[0], force[1], torque], -np.array(grad), rtol=0, atol=1e-7)


@pytest.mark.parametrize("aniso", [False, True])
def test_resistance_is_the_jacobian_and_infinite_at_a_stick(rng, aniso):
    contacts = _random_set(rng, 12, aniso=aniso)
    x = rng.normal(size=3)
    R = contacts.resistance(x[:2], x[2])
    h = 1e-6
    J = np.empty((3, 3))
    for k in range(3):
        e = np.zeros(3)
        e[k] = h
        fp, tp = contacts.wrench((x + e)[:2], (x + e)[2])
        fm, tm = contacts.wrench((x - e)[:2], (x - e)[2])
        J[:, k] = -(np.r_[fp, tp] - np.r_[fm, tm]) / (2 * h)
    # Central differences of a smooth map: truncation ~h^2 / |s|^3 ~ 1e-10; atol 1e-6.
    np.testing.assert_allclose(R, J, rtol=0, atol=1e-6)
    np.testing.assert_allclose(R, R.T, rtol=0, atol=1e-12)
    assert np.linalg.eigvalsh(R)[0] >= -1e-12
    assert np.all(np.isinf(contacts.resistance(contacts.velocities[0], 0.0)))    # contact 0 sticks
    assert np.array_equal(contacts.resistance(x[:2]), contacts.resistance(x[:2], 0.0))     # omega 0 by default
    assert contacts.resistance(rng.normal(size=(5, 2)), rng.normal(size=5)).shape == (5, 3, 3)


def test_anisotropy_forms_agree_and_ratio_one_is_isotropic(rng):
    n = 9
    pos, vel, f = rng.normal(size=(n, 2)), rng.normal(size=(n, 2)), rng.uniform(0.5, 2, n)
    angle, ratio = rng.uniform(0, np.pi, n), rng.uniform(0.3, 4, n)
    c, s = np.cos(angle), np.sin(angle)
    R = np.stack((np.stack((c, -s), -1), np.stack((s, c), -1)), 1)
    M = R @ (np.eye(2) * np.array([1.0, 1.0])[:, None] * np.stack((np.ones(n), ratio ** 2), -1)[:, None, :]) @ np.swapaxes(R, 1, 2)
    a = PlanarContactSet(pos, vel, f, np.c_[angle, ratio])
    b = PlanarContactSet(pos, vel, f, M)
    iso = PlanarContactSet(pos, vel, f)
    one = PlanarContactSet(pos, vel, f, np.c_[angle, np.ones(n)])
    V, w = rng.normal(size=(50, 2)), rng.normal(size=50)
    for x, y in ((a, b), (iso, one)):
        for p, q in zip(x.wrench(V, w), y.wrench(V, w)):
            np.testing.assert_allclose(p, q, rtol=1e-12, atol=1e-12)
    # Each sliding contact's force lies on its ellipse: F^T M^-1 F = f^2.
    s_ = a.slips(V[0], w[0])
    F = _contact_forces(a, s_[None])[0]
    q = np.einsum("ni,nij,nj->n", F, np.linalg.inv(M), F)
    np.testing.assert_allclose(q, f ** 2, rtol=1e-12)


def test_rotating_the_frame_rotates_the_wrench(rng):
    contacts = _random_set(rng, 15, aniso=True)
    V, w = rng.normal(size=(20, 2)), rng.normal(size=20)
    angle = 0.7
    rot = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
    turned = contacts.transformed(angle=angle)
    f0, t0 = contacts.wrench(V, w)
    f1, t1 = turned.wrench(V @ rot.T, w)
    np.testing.assert_allclose(f1, f0 @ rot.T, rtol=0, atol=1e-12)
    np.testing.assert_allclose(t1, t0, rtol=0, atol=1e-12)
    # Moving the reference point to p: V' = V + omega J p, torque' = torque - p x F.
    p = np.array([0.3, -1.2])
    moved = contacts.transformed(shift=p)
    Vp = V + w[:, None] * np.array([-p[1], p[0]])
    f2, t2 = moved.wrench(Vp, w)
    np.testing.assert_allclose(f2, f0, rtol=0, atol=1e-12)
    np.testing.assert_allclose(t2, t0 - (p[0] * f0[:, 1] - p[1] * f0[:, 0]), rtol=0, atol=1e-12)


def test_vectorized_shapes_and_batches(rng):
    contacts = _random_set(rng, 6)
    V = rng.normal(size=(3, 4, 2))
    w = rng.normal(size=(3, 4))
    force, torque = contacts.wrench(V, w)
    assert force.shape == (3, 4, 2) and torque.shape == (3, 4)
    f00, t00 = contacts.wrench(V[1, 2], w[1, 2])
    assert np.array_equal(force[1, 2], f00) and torque[1, 2] == t00
    f_b, t_b = contacts.wrench(V, 0.5)           # omega broadcast
    assert f_b.shape == (3, 4, 2)
    sets = [_random_set(rng, 5) for _ in range(4)]
    Vs, ws = rng.normal(size=(4, 7, 2)), rng.normal(size=(4, 7))
    F, T = wrench_batch([s.positions for s in sets], [s.velocities for s in sets],
                        [s.forces for s in sets], Vs, ws)
    for k, s in enumerate(sets):
        fk, tk_ = s.wrench(Vs[k], ws[k])
        assert np.array_equal(F[k], fk) and np.array_equal(T[k], tk_)


def test_stuck_contacts_and_the_wrench_set(rng):
    pos = np.array([[1.0, 0.0], [-1.0, 0.0], [0.0, 2.0]])
    vel = np.array([[0.0, 0.0], [0.0, 0.0], [1.0, 0.0]])
    contacts = PlanarContactSet(pos, vel, [1.0, 2.0, 0.5])
    ws = contacts.wrench_set([0.0, 0.0], 0.0)
    assert list(ws.stuck) == [0, 1]
    # Centre: only contact 2 slides, pushing +x with 0.5 N at (0, 2): torque -1.
    np.testing.assert_array_equal(ws.force, [0.5, 0.0])
    assert ws.torque == -1.0
    # Support in +x: 0.5 + 1 + 2; torque support: -1 + 1*|J r_0| + 2*|J r_1| = -1 + 1 + 2.
    assert ws.support([1.0, 0.0, 0.0]) == 3.5
    assert ws.support([0.0, 0.0, 1.0]) == 2.0
    assert ws.bounds([0.0, 1.0, 0.0]) == (-3.0, 3.0)


@settings(max_examples=60, deadline=None)
@given(n=st.integers(1, 12), seed=st.integers(0, 2**32 - 1), scale=st.sampled_from([1e-2, 1.0, 1e2]))
def test_force_never_exceeds_the_total(n, seed, scale):
    rng = np.random.default_rng(seed)
    contacts = _random_set(rng, n, scale)
    V = rng.normal(size=(30, 2)) * scale
    w = rng.normal(size=30)
    force, _ = contacts.wrench(V, w)
    assert np.all(np.hypot(force[:, 0], force[:, 1]) <= contacts.total_force * (1 + 1e-12))


def test_bad_input_is_refused_with_the_rule():
    with pytest.raises(ParameterError, match="'positions' parameter of PlanarContactSet must be 2-dimensional"):
        PlanarContactSet([1.0, 2.0], [[0.0, 0.0]])
    with pytest.raises(ParameterError, match="'forces' parameter of PlanarContactSet must be >= 0"):
        PlanarContactSet([[0, 0]], [[0, 0]], [-1.0])
    with pytest.raises(ParameterError, match="positive sum"):
        PlanarContactSet([[0, 0]], [[0, 0]], [0.0])
    with pytest.raises(ParameterError, match="'anisotropy' parameter of PlanarContactSet must have a positive ratio"):
        PlanarContactSet([[0, 0]], [[0, 0]], [1.0], [[0.0, -1.0]])
    with pytest.raises(ParameterError, match="positive definite"):
        PlanarContactSet([[0, 0]], [[0, 0]], [1.0], [[[1.0, 0.0], [0.0, -1.0]]])
    with pytest.raises(ParameterError, match="'V' parameter of PlanarContactSet.wrench must have a last axis"):
        PlanarContactSet([[0, 0]], [[0, 0]]).wrench(1.0)
    with pytest.raises(ParameterTypeError):
        PlanarContactSet([[0, 0]], [[0, 0]]).wrench("fast")
    # Each twist part is named for its own fault.
    with pytest.raises(ParameterError, match="'omega' parameter of PlanarContactSet.wrench must be finite"):
        PlanarContactSet([[0, 0]], [[0, 0]]).wrench([0.0, 0.0], float("nan"))
    with pytest.raises(ParameterError, match="'V' parameter of PlanarContactSet.wrench must be finite"):
        PlanarContactSet([[0, 0]], [[0, 0]]).wrench([float("inf"), 0.0], 0.0)
    with pytest.raises(ParameterTypeError, match="'omega' parameter"):
        PlanarContactSet([[0, 0]], [[0, 0]]).wrench([0.0, 0.0], "spin")


# -- refusals, each named in full ---------------------------------------------------------------
_C3 = PlanarContactSet([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]], [[0.1, 0.0], [0.0, 0.2], [-0.1, 0.1]])
_Z2 = [[0.0, 0.0], [0.0, 0.0]]
_BAD_SHAPE = "The 'V' parameter of wrench_batch must have a first axis of length S = 2 (as 'omega'). Got "


@pytest.mark.parametrize(("call", "error", "message"), [
    (lambda: PlanarContactSet([[0.0, 0.0, 1.0]], [[0.0, 0.0]]), ParameterError,
     "The 'positions' parameter of PlanarContactSet must have shape (n, 2) (one planar vector per contact). "
     "Got 'an array of shape (1, 3)' instead."),
    (lambda: PlanarContactSet([[0.0, 0.0], [1.0, 0.0]], [[0.0, 0.0]]), ParameterError,
     "The 'velocities' parameter of PlanarContactSet must have shape (2, 2) (one planar vector per contact). "
     "Got 'an array of shape (1, 2)' instead."),
    (lambda: PlanarContactSet([[0, 0]], [[0, 0]], [1.0], "round"), ParameterTypeError,
     "The 'anisotropy' parameter of PlanarContactSet must be None or an array of numbers. Got 'round' instead."),
    # A string is refused as such, even one that numpy would read as a number.
    (lambda: PlanarContactSet([[0, 0]], [[0, 0]], [1.0], "2.0"), ParameterTypeError,
     "The 'anisotropy' parameter of PlanarContactSet must be None or an array of numbers. Got '2.0' instead."),
    (lambda: PlanarContactSet([[0, 0]], [[0, 0]], [1.0], [[0.0, np.nan]]), ParameterError,
     "The 'anisotropy' parameter of PlanarContactSet must be finite. Got [[0.0, nan]] instead."),
    # The first non-positive ratio is named (0.0, not the -2.0 after it).
    (lambda: PlanarContactSet([[0, 0], [1, 0], [2, 0]], [[0, 0]] * 3, None, [[0.0, 1.0], [0.0, 0.0], [0.0, -2.0]]),
     ParameterError, "The 'anisotropy' parameter of PlanarContactSet must have a positive ratio (second column) "
     "for every contact. Got 0.0 instead."),
    (lambda: PlanarContactSet([[0, 0]], [[0, 0]], [1.0], [[[1.0, 0.5], [0.4, 1.0]]]), ParameterError,
     "The 'anisotropy' parameter of PlanarContactSet must hold symmetric 2 x 2 matrices. "
     "Got 'a non-symmetric matrix' instead."),
    # An eigenvalue exactly 0 is refused (the smaller of 0 and 1).
    (lambda: PlanarContactSet([[0, 0]], [[0, 0]], [1.0], [[[1.0, 0.0], [0.0, 0.0]]]), ParameterError,
     "The 'anisotropy' parameter of PlanarContactSet must hold positive definite 2 x 2 matrices. "
     "Got 'a matrix with an eigenvalue <= 0' instead."),
    (lambda: PlanarContactSet([[0, 0]], [[0, 0]], [1.0], [[0.0, 0.0]]), ParameterError,
     "The 'anisotropy' parameter of PlanarContactSet must have a positive ratio (second column) for every "
     "contact. Got 0.0 instead."),
    (lambda: PlanarContactSet([[0, 0]], [[0, 0]], [1.0], [["axis", "ratio"]]), ParameterTypeError,
     "The 'anisotropy' parameter of PlanarContactSet must be None or an array of numbers. "
     "Got [['axis', 'ratio']] instead."),
    # Asymmetric by 1e-9 (relative and absolute): above the 1e-12 allowed.
    (lambda: PlanarContactSet([[0, 0]], [[0, 0]], [1.0], [[[4.0, 2.0], [2.0 + 2e-9, 2.0]]]), ParameterError,
     "The 'anisotropy' parameter of PlanarContactSet must hold symmetric 2 x 2 matrices. "
     "Got 'a non-symmetric matrix' instead."),
    (lambda: PlanarContactSet([[0, 0]], [[0, 0]], "heavy"), ParameterTypeError,
     "The 'forces' parameter of PlanarContactSet must be an array of numbers. Got 'heavy' instead."),
    (lambda: PlanarContactSet([[0, 0], [1, 0]], _Z2, None, [[0.0, 1.0, 2.0]]), ParameterError,
     "The 'anisotropy' parameter of PlanarContactSet must have shape (2, 2) (angle, ratio) or (2, 2, 2) "
     "(matrices). Got 'an array of shape (1, 3)' instead."),
    (lambda: PlanarContactSet([[0, 0], [1, 0]], _Z2, [1.0, 2.0, 3.0]), ParameterError,
     "The 'forces' parameter of PlanarContactSet must have one magnitude per contact (2). "
     "Got 'an array of length 3' instead."),
    (lambda: PlanarContactSet([[0, 0], [1, 0]], _Z2, [1e308, 1e308]), ParameterError,
     "The 'forces' parameter of PlanarContactSet must have a finite sum (F_tot overflows). Got 'max 1e+308' instead."),
    (lambda: PlanarContactSet([[0, 0], [1, 0]], _Z2, [0.0, 0.0]), ParameterError,
     "The 'forces' parameter of PlanarContactSet must have a positive sum (some contact must touch). "
     "Got [0.0, 0.0] instead."),
    (lambda: PlanarContactSet([[0, 0]] * 8, [[0, 0]] * 8, [0.0] * 8), ParameterError,
     "The 'forces' parameter of PlanarContactSet must have a positive sum (some contact must touch). "
     f"Got {[0.0] * 8} instead."),
    (lambda: PlanarContactSet([[0, 0]] * 9, [[0, 0]] * 9, [0.0] * 9), ParameterError,
     "The 'forces' parameter of PlanarContactSet must have a positive sum (some contact must touch). "
     "Got 'all zeros' instead."),
    (lambda: _C3.wrench(None), ParameterTypeError,
     "The 'V' parameter of PlanarContactSet.wrench must be real numbers (m/s). Got None instead."),
    (lambda: _C3.wrench(b"fast"), ParameterTypeError,
     "The 'V' parameter of PlanarContactSet.wrench must be real numbers (m/s). Got b'fast' instead."),
    (lambda: _C3.wrench([1j, 0.0]), ParameterTypeError,
     "The 'V' parameter of PlanarContactSet.wrench must be real numbers (m/s). Got [1j, 0.0] instead."),
    (lambda: _C3.wrench(np.array([1j, 0.0])), ParameterTypeError,
     "The 'V' parameter of PlanarContactSet.wrench must be real numbers (m/s). Got array([0.+1.j, 0.+0.j]) instead."),
    (lambda: _C3.wrench(np.zeros((3, 4, 2)), np.zeros(5)), ParameterError,
     "The 'omega' parameter of PlanarContactSet.wrench must broadcast against V's batch shape (3, 4). "
     "Got 'an array of shape (5,)' instead."),
    (lambda: _C3.wrench([[0.0, 1.0], [2.0]]), ParameterTypeError,
     "The 'V' parameter of PlanarContactSet.wrench must be real numbers (m/s). Got [[0.0, 1.0], [2.0]] instead."),
    (lambda: _C3.slips([0.0, 1.0], [[0.0], [1.0, 2.0]]), ParameterTypeError,
     "The 'omega' parameter of PlanarContactSet.slips must be real numbers (rad/s). "
     "Got [[0.0], [1.0, 2.0]] instead."),
    (lambda: _C3.dissipation([np.inf, 0.0]), ParameterError,
     "The 'V' parameter of PlanarContactSet.dissipation must be finite. Got 'a NaN or inf entry' instead."),
    (lambda: _C3.wrench(1.0), ParameterError,
     "The 'V' parameter of PlanarContactSet.wrench must have a last axis of length 2 (vx, vy). "
     "Got 'an array of shape ()' instead."),
    (lambda: _C3.wrench([1.0, 2.0, 3.0]), ParameterError,
     "The 'V' parameter of PlanarContactSet.wrench must have a last axis of length 2 (vx, vy). "
     "Got 'an array of shape (3,)' instead."),
    (lambda: _C3.wrench(np.zeros((3, 2)), np.zeros(4)), ParameterError,
     "The 'omega' parameter of PlanarContactSet.wrench must broadcast against V's batch shape (3,). "
     "Got 'an array of shape (4,)' instead."),
    (lambda: _C3.resistance(np.zeros((3, 2)), np.zeros(4)), ParameterError,
     "The 'omega' parameter of PlanarContactSet.resistance must broadcast against V's batch shape (3,). "
     "Got 'an array of shape (4,)' instead."),
    (lambda: PlanarContactSet.from_friction([[0, 0], [1, 0], [2, 0]], [[0, 0]] * 3, [0.5, 0.5], 1.0), ParameterError,
     "The 'mu' parameter of PlanarContactSet.from_friction must be a scalar or have one entry per contact (3). "
     "Got 'an array of length 2' instead."),
    (lambda: PlanarContactSet.from_friction([[0, 0], [1, 0], [2, 0]], [[0, 0]] * 3, 0.5, [1.0, 2.0]), ParameterError,
     "The 'normal_loads' parameter of PlanarContactSet.from_friction must be a scalar or have one entry per "
     "contact (3). Got 'an array of length 2' instead."),
    (lambda: PlanarContactSet.from_friction([[0, 0]], [[0, 0]], "high", 1.0), ParameterTypeError,
     "The 'mu' parameter of PlanarContactSet.from_friction must be an array of numbers. Got 'high' instead."),
    (lambda: PlanarContactSet.from_friction([[0, 0]], [[0, 0]], 0.5, [np.nan]), ParameterError,
     "The 'normal_loads' parameter of PlanarContactSet.from_friction must be finite (no NaN or inf). Got nan "
     "instead."),
    (lambda: PlanarContactSet.from_friction([[0, 0]], [[0, 0]], -0.5, 1.0), ParameterError,
     "The 'mu' parameter of PlanarContactSet.from_friction must be >= 0. Got -0.5 instead."),
    (lambda: PlanarContactSet.from_friction([[0, 0]], [[0, 0]], 0.5, -1.0), ParameterError,
     "The 'normal_loads' parameter of PlanarContactSet.from_friction must be >= 0. Got -1.0 instead."),
    (lambda: PlanarContactSet.from_friction([[0, 0, 0]], [[0, 0]], 0.5, 1.0), ParameterError,
     "The 'positions' parameter of PlanarContactSet.from_friction must have shape (n, 2) (one planar vector per "
     "contact). Got 'an array of shape (1, 3)' instead."),
    (lambda: PlanarContactSet.on_line("line"), ParameterTypeError,
     "The 'contacts' parameter of PlanarContactSet.on_line must be a ContactSet. Got 'line' instead."),
    (lambda: PlanarContactSet.on_line(tk.ContactSet([0.1, 0.2]), direction=(0.0, 0.0)), ParameterError,
     "The 'direction' parameter of PlanarContactSet.on_line must be a non-zero 2-vector. Got [0.0, 0.0] instead."),
    (lambda: PlanarContactSet.on_line(tk.ContactSet([0.1, 0.2]), direction=(1.0, 0.0, 0.0)), ParameterError,
     "The 'direction' parameter of PlanarContactSet.on_line must be a non-zero 2-vector. Got [1.0, 0.0, 0.0] instead."),
    (lambda: PlanarContactSet.on_line(tk.ContactSet([0.1, 0.2]), direction=[np.nan, 1.0]), ParameterError,
     "The 'direction' parameter of PlanarContactSet.on_line must be finite (no NaN or inf). Got nan instead."),
    (lambda: PlanarContactSet.on_line(tk.ContactSet([0.1, 0.2]), origin=(1.0, 0.0, 0.0)), ParameterError,
     "The 'origin' parameter of PlanarContactSet.on_line must be a 2-vector. Got [1.0, 0.0, 0.0] instead."),
    (lambda: PlanarContactSet.on_line(tk.ContactSet([0.1, 0.2]), origin=[np.inf, 0.0]), ParameterError,
     "The 'origin' parameter of PlanarContactSet.on_line must be finite (no NaN or inf). Got inf instead."),
    (lambda: PlanarContactSet.on_line(tk.ContactSet([0.1, 0.2]), positions=[1.0, 2.0, 3.0]), ParameterError,
     "The 'positions' parameter of PlanarContactSet.on_line must have one coordinate per contact (2). "
     "Got 'an array of length 3' instead."),
    (lambda: PlanarContactSet.on_line(tk.ContactSet([0.1, 0.2]), positions=[1.0, np.nan]), ParameterError,
     "The 'positions' parameter of PlanarContactSet.on_line must be finite (no NaN or inf). Got nan instead."),
    (lambda: _C3.with_velocities([[0.0, 0.0]] * 2), ParameterError,
     "The 'velocities' parameter of PlanarContactSet.with_velocities must have shape (3, 2) (one planar vector "
     "per contact). Got 'an array of shape (2, 2)' instead."),
    (lambda: _C3.subset([]), ParameterError,
     "The 'index' parameter of PlanarContactSet.subset must select contacts with a positive total force. "
     "Got [] instead."),
    (lambda: _C3.subset([False, False, False]), ParameterError,
     "The 'index' parameter of PlanarContactSet.subset must select contacts with a positive total force. "
     "Got [] instead."),
    (lambda: _C3.with_forces([0.0, 1.0, 0.0]).subset([0, 2]), ParameterError,
     "The 'index' parameter of PlanarContactSet.subset must select contacts with a positive total force. "
     "Got [0, 2] instead."),
    (lambda: _C3.transformed(shift=(1.0, 2.0, 3.0)), ParameterError,
     "The 'shift' parameter of PlanarContactSet.transformed must be a 2-vector. Got [1.0, 2.0, 3.0] instead."),
    (lambda: _C3.transformed(angle="left"), ParameterTypeError,
     "The 'angle' parameter of PlanarContactSet.transformed must be a real number. Got 'left' instead."),
    (lambda: _C3.transformed(shift=[0.0, np.inf]), ParameterError,
     "The 'shift' parameter of PlanarContactSet.transformed must be finite (no NaN or inf). Got inf instead."),
    (lambda: _C3.wrench_set([0.0, 0.0]).support([1.0, 0.0]), ParameterError,
     "The 'direction' parameter of WrenchSet.support must have a last axis of length 3. Got 'shape (2,)' instead."),
    (lambda: _C3.wrench_set([0.0, 0.0]).support(1.0), ParameterError,
     "The 'direction' parameter of WrenchSet.support must have a last axis of length 3. Got 'shape ()' instead."),
    (lambda: _C3.wrench_set("still"), ParameterTypeError,
     "The 'V' parameter of PlanarContactSet.wrench_set must be real numbers (m/s). Got 'still' instead."),
    (lambda: _C3.wrench_set(np.zeros((2, 2))), ParameterError,
     "The 'V' parameter of PlanarContactSet.wrench_set must be one velocity of shape (2,). "
     "Got 'an array of shape (2, 2)' instead."),
    (lambda: _C3.wrench_set([0.0, 0.0], [1.0, 2.0]), ParameterError,
     "The 'V' parameter of PlanarContactSet.wrench_set must be one velocity of shape (2,). "
     "Got 'an array of shape (2, 2)' instead."),
    (lambda: geometric_median([0.0, 1.0]), ParameterError,
     "The 'points' parameter of geometric_median must be 2-dimensional. Got 'an array of shape (2,)' instead."),
    (lambda: geometric_median([[0.0, 1.0, 2.0]]), ParameterError,
     "The 'points' parameter of geometric_median must have shape (n, 2) (one planar vector per contact). "
     "Got 'an array of shape (1, 3)' instead."),
    (lambda: wrench_batch(np.zeros((2, 3, 2)), np.zeros((2, 3, 2)), np.ones((2, 3)), "fast", np.zeros(2)),
     ParameterError, _BAD_SHAPE + "'shapes () and (2,)' instead."),
    (lambda: wrench_batch(np.zeros((3, 2)), np.zeros((3, 2)), np.ones(3), np.zeros(2), 0.0), ParameterError,
     "The 'positions' parameter of wrench_batch must have shape (S, n, 2). Got 'an array of shape (3, 2)' instead."),
    (lambda: wrench_batch(np.zeros((2, 3, 2)), np.zeros((2, 3, 2)), np.ones((2, 3)), np.zeros((3, 2)), np.zeros(2)),
     ParameterError, _BAD_SHAPE + "'shapes (3, 2) and (2,)' instead."),
    (lambda: wrench_batch(np.zeros((2, 3, 2)), np.zeros((2, 3, 2)), np.ones((2, 3)), np.zeros((2, 2)), np.zeros(3)),
     ParameterError, _BAD_SHAPE + "'shapes (2, 2) and (3,)' instead."),
])
def test_every_refusal_of_the_contacts_in_full(call, error, message):
    """Each refusal matched whole: parameter, owner, rule and value (mutants: any of them
    changed, dropped or replaced by None; a comparison loosened so that the value is let through
    or another value named)."""
    with pytest.raises(error) as info:
        call()
    assert str(info.value) == message


# -- thresholds bracketed, at several scales ----------------------------------------------------
SCALES = [2.0 ** -20, 1.0, 2.0 ** 20]


@pytest.mark.parametrize("scale", SCALES)
def test_ties_snap_at_the_tolerance_and_not_above(scale):
    """Two contacts at (0, 4) pushing +x and -x with ``(1 +- d/2) scale`` and a lifted one at
    the origin: ``n = 3`` and ``F_tot = 2 scale``, so the tie tolerance is ``32 eps scale =
    2**-47 scale`` and the net force ``d scale`` and torque ``-4 d scale`` are exact sums.
    ``d = 2**-47`` is at the tolerance (force) and at the tolerance times the arm 4 (torque):
    both are exactly 0; ``d = 2**-46`` is above both: reported. Mutants killed: ``<`` for
    ``<=``, the arm divided or dropped, the snapped value other than 0."""
    positions = [[0.0, 4.0], [0.0, 4.0], [0.0, 0.0]]
    velocities = [[1.0, 0.0], [-1.0, 0.0], [0.0, 0.0]]
    for d, snapped in ((2.0 ** -47, True), (2.0 ** -46, False)):
        contacts = PlanarContactSet(positions, velocities, np.array([1 + d / 2, 1 - d / 2, 0.0]) * scale)
        assert contacts.tie_tolerance == 2.0 ** -47 * scale and contacts.arm == 4.0
        force, torque = contacts.wrench([0.0, 0.0], 0.0)
        if snapped:
            assert np.array_equal(force, [0.0, 0.0]) and torque == 0.0
        else:
            assert np.array_equal(force, [d * scale, 0.0]) and torque == -4 * d * scale


@pytest.mark.parametrize("scale", SCALES)
def test_resistance_counts_a_slip_at_rounding_as_a_stick(scale):
    """A slip of at most ``64 eps`` times the size of the velocities it comes from (the
    contact's own ``|v_i|``, the twist's ``|V|`` and ``|omega| |r_i|``) is a stick. Contact 0
    at (0, 1) moves at ``(1, 0) scale``, the body at ``(2, k eps) scale`` turning at
    ``omega = scale``: the slip is ``(0, -k eps) scale`` exactly, the size ``(1 + 2 + 1) scale``,
    the bound ``256 eps scale``: ``k = 256`` sticks (inf), ``k = 257`` slides (finite). The
    other contacts are farther and faster (so the sizes are per contact), and the second twist
    of the batch is larger (so they are per twist). Mutants killed: the factor 64, ``<`` for
    ``<=``, a term's sign, a maximum over every contact or every twist."""
    positions = [[0.0, 1.0], [3.0, 0.0], [0.0, -4.0]]
    velocities = np.array([[1.0, 0.0], [-5.0, 0.0], [0.0, -6.0]]) * scale
    contacts = PlanarContactSet(positions, velocities, [1.0, 2.0, 0.5])
    for k, stuck in ((256, True), (257, False)):
        V = np.array([[2.0, k * EPS], [16.0, 0.0]]) * scale
        R = contacts.resistance(V, [scale, scale])
        assert np.all(np.isinf(R[0])) == stuck and np.all(np.isfinite(R[0])) == (not stuck)
        assert np.all(np.isfinite(R[1]))
    # A lifted contact (f = 0), with zero slip or sliding, adds nothing: the resistance is the
    # other two contacts' (exactly).
    for v in ([2.0, 0.0], [0.0, 3.0]):
        lifted = PlanarContactSet(positions, np.r_[[v], velocities[1:] / scale] * scale, [0.0, 2.0, 0.5])
        R = lifted.resistance(np.array([2.0, 0.0]) * scale, scale)
        assert np.all(np.isfinite(R))
        assert np.array_equal(R, lifted.subset([1, 2]).resistance(np.array([2.0, 0.0]) * scale, scale))


# -- constructors, properties and variants ------------------------------------------------------
def test_from_friction_multiplies_and_broadcasts():
    """``f_i = mu_i N_i``, a scalar broadcast to every contact (dyadic: exact); anisotropy
    passed through."""
    pos, vel = [[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]], [[0.0, 0.0]] * 3
    c = PlanarContactSet.from_friction(pos, vel, [0.5, 0.25, 2.0], 4.0)
    assert np.array_equal(c.forces, [2.0, 1.0, 8.0]) and c.total_force == 11.0 and c.isotropic
    c = PlanarContactSet.from_friction(pos, vel, 0.5, [4.0, 2.0, 6.0], anisotropy=[[0.0, 2.0]] * 3)
    assert np.array_equal(c.forces, [2.0, 1.0, 3.0]) and not c.isotropic
    np.testing.assert_array_equal(c.limits, np.broadcast_to(np.diag([1.0, 4.0]), (3, 2, 2)))


def test_on_line_places_the_contacts_on_the_line():
    """Positions ``origin + s_i e``, velocities ``u_i e`` with ``e`` the unit direction (here
    (-3, -4) / 5), magnitudes kept; the rounding of 0.6 and 0.8: atol 4 eps."""
    line = tk.ContactSet([0.25, -0.5, 0.125], [1.0, 2.0, 0.5])
    s = np.array([1.0, -2.0, 0.0])
    c = PlanarContactSet.on_line(line, positions=s, direction=(-3.0, -4.0), origin=(1.0, 2.0))
    e = np.array([-0.6, -0.8])
    np.testing.assert_allclose(c.positions, np.array([1.0, 2.0]) + s[:, None] * e, rtol=0, atol=4 * EPS * 4)
    np.testing.assert_allclose(c.velocities, line.speeds[:, None] * e, rtol=0, atol=4 * EPS)
    assert np.array_equal(c.forces, line.forces)
    # Default: every contact at the origin.
    c0 = PlanarContactSet.on_line(line, origin=(1.0, 2.0))
    assert np.array_equal(c0.positions, [[1.0, 2.0]] * 3)


def test_properties_and_repr():
    """n, len, F_tot, the tie tolerance ``4 (n + 1) eps F_tot``, the arm ``max |r_i|`` (a 3-4-5
    triangle: exact) and the summary line."""
    c = PlanarContactSet([[3.0, 4.0], [-1.0, 0.0], [0.0, 2.0]], [[0.0, 0.0]] * 3, [1.0, 2.5, 0.5])
    assert c.n == 3 and len(c) == 3 and c.total_force == 4.0 and c.isotropic
    assert c.tie_tolerance == 4 * 4 * EPS * 4.0 and c.arm == 5.0
    assert repr(c) == "PlanarContactSet(n=3, total_force=4 N, isotropic, max |r| = 5 m)"
    a = PlanarContactSet([[0.0, 0.0]], [[0.0, 0.0]], [2.0], [[0.5, 3.0]])
    assert repr(a) == "PlanarContactSet(n=1, total_force=2 N, anisotropic, max |r| = 0 m)"
    assert c.limit_factors.shape == (0, 2, 2) and a.limit_factors.shape == (1, 2, 2)


def test_limit_matrices_and_their_factors():
    """From (angle, ratio): ``M = R diag(1, k^2) R^T`` (angle 0 and pi/2 up to the rounding of
    cos(pi/2), 1e-16: atol 1e-15). From matrices: ``M`` itself (symmetrized) and its Cholesky
    factor ``D`` with ``D D^T = M``, exact here (4 = 2^2, 2 = 2*1, 2 = 1 + 1)."""
    c = PlanarContactSet([[0.0, 0.0]] * 2, [[0.0, 0.0]] * 2, [1.0, 1.0], [[0.0, 3.0], [np.pi / 2, 0.5]])
    np.testing.assert_allclose(c.limits, [np.diag([1.0, 9.0]), np.diag([0.25, 1.0])], rtol=0, atol=1e-15)
    np.testing.assert_allclose(c.limit_factors @ np.swapaxes(c.limit_factors, 1, 2), c.limits, rtol=0, atol=1e-15)
    M = np.array([[[4.0, 2.0], [2.0, 2.0]], [[1.0, 0.0], [0.0, 9.0]]])
    a = PlanarContactSet([[1.0, 2.0], [-1.0, 0.5]], [[0.0, 0.0]] * 2, [1.5, 0.5], M)
    assert np.array_equal(a.limits, M)
    assert np.array_equal(a.limit_factors, [[[2.0, 0.0], [1.0, 1.0]], [[1.0, 0.0], [0.0, 3.0]]])
    assert not a.limits.flags.writeable and not a.limit_factors.flags.writeable
    # Symmetric to rtol 1e-12 is accepted (and symmetrized): the mean of the two off-diagonals.
    b = PlanarContactSet([[0.0, 0.0]], [[0.0, 0.0]], [1.0], [[[4.0, 2.0], [2.0 * (1 + 2.0 ** -45), 2.0]]])
    np.testing.assert_allclose(b.limits[0], [[4.0, 2.0 * (1 + 2.0 ** -46)]] * 1 + [[2.0 * (1 + 2.0 ** -46), 2.0]],
                               rtol=4 * EPS, atol=0)


def test_variants_keep_what_they_do_not_change(rng):
    """with_velocities, with_forces, subset and transformed keep the other arrays (the
    anisotropy included) and return read-only arrays."""
    c = _random_set(rng, 5, aniso=True)
    v = rng.normal(size=(5, 2))
    w = c.with_velocities(v)
    assert np.array_equal(w.velocities, v) and w.positions is c.positions and w.limits is c.limits
    assert w.limit_factors is c.limit_factors and w.total_force == c.total_force
    f = c.with_forces(np.arange(1.0, 6.0))
    assert f.total_force == 15.0 and np.array_equal(f.velocities, c.velocities)
    # The limit matrices factored again (Cholesky of D D^T): rounding, a few eps of |M| <= 25.
    np.testing.assert_allclose(f.limits, c.limits, rtol=0, atol=1e-14)
    assert c.with_forces(np.ones(5)).limits is not None and _random_set(rng, 3).with_forces([1, 2, 3]).isotropic
    sub = c.subset([3, 1])
    for name in ("positions", "velocities", "forces", "limits", "limit_factors"):
        got, whole = getattr(sub, name), getattr(c, name)
        assert np.array_equal(got, whole[[3, 1]]) and not got.flags.writeable, name
    assert sub.total_force == c.forces[3] + c.forces[1]
    # One contact, and a total force below 1 N: both are subsets.
    small = c.with_forces([0.25, 0.5, 1.0, 2.0, 3.0])
    assert small.subset([1]).total_force == 0.5 and small.subset([0, 1]).total_force == 0.75
    mask = np.array([True, False, True, False, False])
    assert np.array_equal(c.subset(mask).positions, c.positions[mask])
    iso = _random_set(rng, 4).subset([0, 2])
    assert iso.isotropic and iso.limit_factors.shape == (0, 2, 2) and not iso.forces.flags.writeable
    t = c.transformed(angle=0.3, shift=(1.0, -1.0))
    for name in ("positions", "velocities", "limits", "limit_factors"):
        assert not getattr(t, name).flags.writeable, name
    assert t.forces is c.forces and t.total_force == c.total_force
    # The limit matrices turn with the frame: R M R^T.
    rot = np.array([[np.cos(0.3), -np.sin(0.3)], [np.sin(0.3), np.cos(0.3)]])
    np.testing.assert_allclose(t.limits, rot @ c.limits @ rot.T, rtol=0, atol=1e-14)
    np.testing.assert_allclose(t.positions, (c.positions - [1.0, -1.0]) @ rot.T, rtol=0, atol=1e-14)
    assert _random_set(rng, 3).transformed(angle=1.0).isotropic


def test_slips_are_exact_with_dyadic_numbers():
    """``s_i = v_i - V - omega J r_i`` with ``J r = (-r_y, r_x)``: dyadic numbers, exact."""
    c = PlanarContactSet([[1.0, 2.0], [-0.5, 0.25]], [[0.5, -1.0], [2.0, 0.0]], [1.0, 3.0])
    s = c.slips([0.25, 0.5], 2.0)
    assert np.array_equal(s, [[0.5 - 0.25 + 2.0 * 2.0, -1.0 - 0.5 - 2.0 * 1.0],
                              [2.0 - 0.25 + 2.0 * 0.25, 0.0 - 0.5 + 2.0 * 0.5]])
    # Batches: (3, 2) twists give (3, n, 2).
    assert c.slips(np.zeros((3, 2)), np.ones(3)).shape == (3, 2, 2)


def test_dissipation_and_stuck_in_closed_form():
    """``Phi = sum f_i sqrt(s_i^T M_i s_i)``: slips (3, 4) and (0, 2) in ``M = diag(1, 4)``
    give 5 and 4 (isotropic) or sqrt(9 + 64) and 4 (anisotropic); a contact with zero slip is
    stuck only if it carries a force."""
    pos = [[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]]
    vel = [[3.0, 4.0], [0.0, 2.0], [0.0, 0.0]]
    c = PlanarContactSet(pos, vel, [2.0, 0.5, 1.0])
    assert c.dissipation([0.0, 0.0], 0.0) == 2.0 * 5.0 + 0.5 * 2.0
    a = PlanarContactSet(pos, vel, [2.0, 0.5, 1.0], [[[1.0, 0.0], [0.0, 4.0]]] * 3)
    np.testing.assert_allclose(a.dissipation([0.0, 0.0], 0.0), 2.0 * np.sqrt(73.0) + 0.5 * 4.0, rtol=2 * EPS)
    assert a.dissipation(np.zeros((4, 2)), np.zeros(4)).shape == (4,)
    assert c.stuck([0.0, 0.0]).tolist() == [False, False, True]
    assert c.with_forces([2.0, 0.5, 0.0]).stuck([0.0, 0.0]).tolist() == [False, False, False]
    assert c.stuck([3.0, 4.0]).tolist() == [True, False, False]


def test_anisotropic_wrench_set_support_is_the_norm_in_the_limit_matrix():
    """The support of a stuck contact's ellipse in direction ``a`` is ``f sqrt(a^T M a)``
    (the dual norm); with a torque weight ``b`` the direction is ``a + b J r``. A second
    formula through ``M`` rather than ``D``; rounding of a few terms: rtol 1e-14. Mutants
    killed: ``D`` transposed, a component of ``a + b J r`` changed."""
    M = np.array([[[4.0, 2.0], [2.0, 2.0]], [[1.0, -0.5], [-0.5, 9.0]]])
    pos = np.array([[1.0, 2.0], [-1.5, 0.5]])
    c = PlanarContactSet(pos, [[0.0, 0.0], [0.0, 0.0]], [1.5, 0.5], M)
    ws = c.wrench_set([0.0, 0.0], 0.0)
    assert list(ws.stuck) == [0, 1] and np.array_equal(ws.dmat, c.limit_factors)
    for d in ([1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [0.3, -0.7, 1.1]):
        a = np.array(d[:2]) + d[2] * np.c_[-pos[:, 1], pos[:, 0]]
        expect = np.sum(c.forces * np.sqrt(np.einsum("ni,nij,nj->n", a, M, a)))
        np.testing.assert_allclose(ws.support(d), expect, rtol=1e-14)
        lo, hi = ws.bounds(d)
        np.testing.assert_allclose([lo, hi], [-expect, expect], rtol=1e-14)
    # Batched directions (..., 3) give (...).
    assert ws.support(np.ones((4, 3))).shape == (4,)
    # One contact sliding: the centre moves, the ellipse of the other remains.
    ws1 = c.with_velocities([[0.0, 0.0], [1.0, 0.0]]).wrench_set([0.0, 0.0], 0.0)
    assert list(ws1.stuck) == [0] and ws1.dmat.shape == (1, 2, 2)
    assert np.array_equal(ws1.positions, pos[:1]) and np.array_equal(ws1.forces, [1.5])


def test_wrench_batch_with_anisotropy(rng):
    sets = [_random_set(rng, 4, aniso=True) for _ in range(3)]
    aniso = np.array([s.limits for s in sets])
    Vs, ws = rng.normal(size=(3, 6, 2)), rng.normal(size=(3, 6))
    F, T = wrench_batch([s.positions for s in sets], [s.velocities for s in sets], [s.forces for s in sets],
                        Vs, ws, anisotropy=aniso)
    for k, s in enumerate(sets):
        fk, tk_ = s.wrench(Vs[k], ws[k])
        # The same matrices through a Cholesky factor computed again: rounding, atol 1e-13.
        np.testing.assert_allclose(F[k], fk, rtol=0, atol=1e-13)
        np.testing.assert_allclose(T[k], tk_, rtol=0, atol=1e-13)


# -- the reduction to the 1-D set ---------------------------------------------------------------
def test_line_reduction_of_a_slanted_line():
    """Contacts on the line through (1, 2) along -(3, 4) / 5: the direction is made canonical
    ((0.6, 0.8), first component positive), the origin is the foot of the perpendicular from
    0, ``p - (p . e) e = (-0.32, 0.24)``, the speeds are ``v_i . e`` (the signs flipped with
    ``e``), the magnitudes kept. Rounding of 0.6 and 0.8: atol 8 eps."""
    line = tk.ContactSet([0.25, -0.5, 0.125], [1.0, 2.0, 0.5])
    c = PlanarContactSet.on_line(line, positions=[1.0, -2.0, 0.0], direction=(-3.0, -4.0), origin=(1.0, 2.0))
    red = c.line_reduction()
    assert np.array_equal(red.direction, [0.6, 0.8])
    np.testing.assert_allclose(red.origin, [-0.32, 0.24], rtol=0, atol=8 * EPS)
    np.testing.assert_allclose(red.contacts.speeds, [-0.25, 0.5, -0.125], rtol=0, atol=8 * EPS)
    assert np.array_equal(red.contacts.forces, line.forces)


@pytest.mark.parametrize("scale", SCALES)
def test_line_reduction_tolerances_are_bracketed(scale):
    """A position or a velocity ``k eps`` (times the scale) off the x axis, with every other
    number of order 1: ``k = 16`` is on the line (``16 eps`` times the largest coordinate or
    speed), ``k = 17`` is not. A limit matrix with an off-diagonal ``k eps`` has the axis as an
    axis for ``k = 16`` (``16 eps max |M e|``), not for 17. Mutants killed: the factors 16,
    ``>=`` for ``>``, the scales dropped."""
    base_r = np.array([[0.0, 0.0], [1.0, 0.0], [0.5, 0.0]])
    base_v = np.array([[1.0, 0.0], [-0.5, 0.0], [0.25, 0.0]])
    f = [1.0, 2.0, 0.5]
    for k, on in ((16, True), (17, False)):
        off = np.array([[0.0, 0.0], [0.0, 0.0], [0.0, k * EPS]])
        for r, v in ((base_r + off, base_v), (base_r, base_v + off)):
            red = PlanarContactSet(r * scale, v * scale, f).line_reduction()
            assert (red is not None) is on
            if on:
                assert np.array_equal(red.direction, [1.0, 0.0]) and np.array_equal(red.origin, [0.0, 0.0])
                assert np.array_equal(red.contacts.speeds, base_v[:, 0] * scale)
        M = np.array([[[1.0, k * EPS], [k * EPS, 1.0]]] * 3)
        c = PlanarContactSet(base_r * scale, base_v * scale, f, M * 4.0)
        weights = c.line_weights(np.array([1.0, 0.0]))
        assert (weights is not None) is on and (c.line_reduction() is not None) is on
        if on:
            assert np.array_equal(weights, np.array(f) * 2.0)       # f |D^T e| = f sqrt(4)


def test_line_reduction_of_contacts_at_one_point():
    """Contacts all at one point lie on every line: the line is that of the velocities (here
    along -y, made canonical (0, 1)); all at rest, the x axis. Velocities that are not
    parallel: no reduction. A limit surface whose axes are not along the line: none either."""
    r = [[1.0, 1.0]] * 3
    c = PlanarContactSet(r, [[0.0, -2.0], [0.0, 1.0], [0.0, 0.5]], [1.0, 2.0, 0.5])
    red = c.line_reduction()
    assert np.array_equal(red.direction, [0.0, 1.0]) and np.array_equal(red.contacts.speeds, [-2.0, 1.0, 0.5])
    assert np.array_equal(red.origin, [1.0, 0.0])
    rest = PlanarContactSet(r, [[0.0, 0.0]] * 3, [1.0, 2.0, 0.5]).line_reduction()
    assert np.array_equal(rest.direction, [1.0, 0.0]) and np.array_equal(rest.origin, [0.0, 1.0])
    assert PlanarContactSet(r, [[0.0, -2.0], [1.0, 1.0], [0.0, 0.5]]).line_reduction() is None
    tilted = PlanarContactSet([[0.0, 0.0], [1.0, 0.0]], [[1.0, 0.0], [0.5, 0.0]], None,
                              [[[4.0, 2.0], [2.0, 2.0]]] * 2)
    assert tilted.line_weights(np.array([1.0, 0.0])) is None and tilted.line_reduction() is None
    # Along an axis of the ellipse: f |D^T e| with D = diag(1, 3): 1 along x, 3 along y.
    axes = PlanarContactSet([[0.0, 0.0], [0.0, 1.0]], [[0.0, 1.0], [0.0, 0.5]], [2.0, 0.5], [[0.0, 3.0]] * 2)
    red = axes.line_reduction()
    np.testing.assert_allclose(red.contacts.forces, [6.0, 1.5], rtol=2 * EPS)
    assert PlanarContactSet([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]], [[0.0, 0.0]] * 3).line_reduction() is None


def test_omega_defaults_to_zero_and_frames_to_the_identity(rng):
    """Every evaluation without ``omega`` is the one at ``omega = 0``; ``on_line`` without a
    direction or an origin is the x axis through 0; ``transformed()`` is the same set."""
    c = _random_set(rng, 6, aniso=True)
    V = rng.normal(size=2)
    for name in ("slips", "wrench", "dissipation", "stuck", "resistance"):
        got, ref = getattr(c, name)(V), getattr(c, name)(V, 0.0)
        for a, b in zip(got if isinstance(got, tuple) else (got,), ref if isinstance(ref, tuple) else (ref,)):
            assert np.array_equal(a, b), name
    ws, ref = c.wrench_set(c.velocities[0]), c.wrench_set(c.velocities[0], 0.0)
    assert np.array_equal(ws.stuck, ref.stuck) and np.array_equal(ws.force, ref.force) and ws.torque == ref.torque
    line = tk.ContactSet([0.25, -0.5], [1.0, 2.0])
    c1 = PlanarContactSet.on_line(line, positions=[1.0, -2.0])
    assert np.array_equal(c1.positions, [[1.0, 0.0], [-2.0, 0.0]]) and np.array_equal(c1.velocities, [[0.25, 0.0], [-0.5, 0.0]])
    same = c.transformed()
    for name in ("positions", "velocities", "limits", "limit_factors"):
        assert np.array_equal(getattr(same, name), getattr(c, name)), name


def test_geometric_median_passes_its_settings():
    """The method and the tolerance reach the solver: the result names the method, and its
    tolerance is ``tol F_tot S``."""
    points = np.array([[0.0, 0.0], [4.0, 0.0], [1.0, 3.0], [-1.0, 2.0]])
    eq = geometric_median(points, [1.0, 2.0, 1.5, 0.5], method="weiszfeld", tol=1e-6)
    assert eq.method == "weiszfeld" and eq.tolerance == 1e-6 * 5.0 * eq.speed_scale
    assert eq.contact_forces.shape == (4, 2) and eq.translation_only


def test_line_reduction_edge_cases():
    """One contact: the line of its velocity. Contacts ``16 eps`` apart along x (exactly the
    tolerance, of the largest coordinate 1) count as one point, so the line is that of the
    velocities (along y), and the positions lie on it within the tolerance. Tiny positions or
    velocities (2**-40) still give a unit direction. Contacts at one point with the first at
    rest: the direction of the others. An ellipse with its axes along a slanted line: the
    line's magnitudes ``f |D^T e| = f``."""
    one = PlanarContactSet([[1.0, 2.0]], [[0.5, 0.0]]).line_reduction()
    assert np.array_equal(one.direction, [1.0, 0.0]) and np.array_equal(one.origin, [0.0, 2.0])
    near = PlanarContactSet([[1.0 - 16 * EPS, 0.0], [1.0, 0.0]], [[0.0, 1.0], [0.0, -2.0]]).line_reduction()
    assert np.array_equal(near.direction, [0.0, 1.0]) and np.array_equal(near.contacts.speeds, [1.0, -2.0])
    tiny = 2.0 ** -40
    red = PlanarContactSet([[0.0, 0.0], [tiny, 0.0]], [[1.0, 0.0], [2.0, 0.0]]).line_reduction()
    assert np.array_equal(red.direction, [1.0, 0.0])
    red = PlanarContactSet([[1.0, 1.0]] * 2, [[0.0, tiny], [0.0, -tiny]]).line_reduction()
    assert np.array_equal(red.direction, [0.0, 1.0]) and np.array_equal(red.contacts.speeds, [tiny, -tiny])
    red = PlanarContactSet([[1.0, 1.0]] * 3, [[0.0, 0.0], [0.0, -2.0], [0.0, 1.0]]).line_reduction()
    assert np.array_equal(red.direction, [0.0, 1.0]) and np.array_equal(red.contacts.speeds, [0.0, -2.0, 1.0])
    e, n = np.array([0.6, 0.8]), np.array([-0.8, 0.6])
    M = np.outer(e, e) + 9.0 * np.outer(n, n)
    c = PlanarContactSet(np.outer([0.0, 1.0, 2.0], e), np.outer([1.0, -0.5, 0.25], e), [1.0, 2.0, 0.5], [M] * 3)
    red = c.line_reduction()
    assert red is not None and np.array_equal(red.direction, e)
    # |D^T e|^2 = e^T M e = 1 up to the rounding of 0.6 and 0.8: rtol 8 eps.
    np.testing.assert_allclose(red.contacts.forces, [1.0, 2.0, 0.5], rtol=8 * EPS)


def test_rotation_sticks_a_contact_in_the_wrench_set():
    """At ``V = (0, 0)``, ``omega = 1`` the contact at (0, 1) moving at ``J r = (-1, 0)`` sticks
    and the others slide: the set's centre is their wrench at that twist."""
    c = PlanarContactSet([[0.0, 1.0], [1.0, 0.0], [2.0, 0.0]], [[-1.0, 0.0], [0.0, 0.0], [0.0, 3.0]], [1.0, 2.0, 0.5])
    assert c.stuck([0.0, 0.0], 1.0).tolist() == [True, False, False]
    ws = c.wrench_set([0.0, 0.0], 1.0)
    force, torque = c.wrench([0.0, 0.0], 1.0)
    assert list(ws.stuck) == [0] and np.array_equal(ws.force, force) and ws.torque == torque


def test_the_kernels_are_charged_the_work_of_each_call(monkeypatch):
    """Each evaluation tells the kernel loader its work, ``n`` times the twists (the loader
    compiles the kernels once enough work has been charged)."""
    from toolkit.planar import contacts as module

    real, calls = module.kernels, []

    def recording(name, work):
        calls.append((name, work))
        return real(name, work)

    monkeypatch.setattr(module, "kernels", recording)
    c = PlanarContactSet(np.zeros((3, 2)), np.eye(3, 2), [1.0, 2.0, 0.5])
    c.wrench(np.zeros((7, 2)), np.zeros(7))
    c.dissipation(np.zeros((5, 2)), np.zeros(5))
    assert calls == [("planar", 21), ("planar", 15)]


def test_numbers_of_other_types_are_read_as_floats():
    """Integers and fractions (anything ``float`` reads) give the same results as floats:
    twists, support directions and (angle, ratio) limits. Default magnitudes (1 N) are
    read-only. A sum of forces that overflows is refused without a numpy warning."""
    from fractions import Fraction

    c = PlanarContactSet([[0.0, 0.0], [1.0, 0.0], [0.0, 2.0]], [[1.0, 0.0], [0.0, 0.0], [0.0, 0.0]], None,
                         [[0, 2], [0, 1], [0, 3]])
    ref = PlanarContactSet(c.positions, c.velocities, None, [[0.0, 2.0], [0.0, 1.0], [0.0, 3.0]])
    assert np.array_equal(c.limits, ref.limits) and np.array_equal(c.forces, [1.0, 1.0, 1.0])
    assert not c.forces.flags.writeable
    for p, q in zip(c.wrench([Fraction(1, 2), Fraction(1, 4)], Fraction(1, 8)), c.wrench([0.5, 0.25], 0.125)):
        assert np.array_equal(p, q)
    ws = c.wrench_set([0.0, 0.0], 0.0)
    d = [Fraction(1, 2), Fraction(-1, 4), Fraction(1, 8)]
    assert ws.support(d) == ws.support([0.5, -0.25, 0.125])
    assert ws.bounds(d) == ws.bounds([0.5, -0.25, 0.125])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(ParameterError, match="must have a finite sum"):
            PlanarContactSet([[0, 0], [1, 0]], _Z2, [1e308, 1e308])


def test_support_of_a_set_with_a_centre_and_a_turned_ellipse():
    """The support adds the sliding contacts' wrench ``d . (F, tau)`` to the stuck ones'
    ellipses; in a turned frame the factors ``D`` are full matrices (not triangular), so each
    entry counts. Second formula through ``M`` (rtol 1e-14)."""
    M = np.array([[[4.0, 2.0], [2.0, 2.0]], [[1.0, -0.5], [-0.5, 9.0]]])
    c = PlanarContactSet([[1.0, 2.0], [-1.5, 0.5]], [[0.0, 0.0], [1.0, -2.0]], [1.5, 0.5], M).transformed(angle=0.7)
    ws = c.wrench_set([0.0, 0.0], 0.0)
    force, torque = c.wrench([0.0, 0.0], 0.0)
    assert list(ws.stuck) == [0] and force[0] != 0 and force[1] != 0 and torque != 0
    r = c.positions[0]
    for d in ([1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [0.3, -0.7, 1.1]):
        a = np.array(d[:2]) + d[2] * np.array([-r[1], r[0]])
        expect = d[0] * force[0] + d[1] * force[1] + d[2] * torque + 1.5 * np.sqrt(a @ c.limits[0] @ a)
        np.testing.assert_allclose(ws.support(d), expect, rtol=1e-14)
