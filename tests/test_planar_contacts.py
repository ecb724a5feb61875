"""Planar contact sets: the wrench against the 1-D set, identities, frames, vectorization."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import toolkit as tk
from toolkit.errors import ParameterError, ParameterTypeError
from toolkit.planar import PlanarContactSet, wrench_batch

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


def test_resistance_is_the_jacobian_and_infinite_at_a_stick(rng):
    contacts = _random_set(rng, 12)
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
