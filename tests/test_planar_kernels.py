"""The planar kernels (toolkit/_compiled/planar.py) against NumPy and as plain Python.

``make test`` runs this module a second time under ``NUMBA_DISABLE_JIT=1`` (the same source
as Python): every number here comes from a formula written independently in NumPy.
"""

from __future__ import annotations

import numpy as np
import pytest

from toolkit._compiled import load
from toolkit.planar import PlanarContactSet
from toolkit.planar._socp import NormSum, solve_fast

EPS = float(np.finfo(float).eps)


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(77)


def _numpy_wrench(c: PlanarContactSet, V: np.ndarray, w: np.ndarray):
    s = c.slips(V, w)
    if c.isotropic:
        z = s
        u = z / np.hypot(z[..., 0], z[..., 1])[..., None]
        F = u
    else:
        D = c.limit_factors
        z = np.einsum("nji,mnj->mni", D, s)
        u = z / np.hypot(z[..., 0], z[..., 1])[..., None]
        F = np.einsum("nij,mnj->mni", D, u)
    F = F * c.forces[:, None]
    r = c.positions
    return F.sum(axis=1), np.sum(r[:, 0] * F[..., 1] - r[:, 1] * F[..., 0], axis=1), \
        np.sum(c.forces * np.hypot(z[..., 0], z[..., 1]), axis=1)


@pytest.mark.parametrize("aniso", [False, True])
def test_wrench_and_dissipation_kernels_match_numpy(rng, aniso):
    n = 40
    anisotropy = np.c_[rng.uniform(0, 3, n), rng.uniform(0.3, 4, n)] if aniso else None
    c = PlanarContactSet(rng.normal(size=(n, 2)), rng.normal(size=(n, 2)), rng.uniform(0.1, 2, n), anisotropy)
    V, w = rng.normal(size=(60, 2)), rng.normal(size=60)
    kernels = load("planar")
    force, torque = np.empty((60, 2)), np.empty(60)
    kernels.wrench(c.positions, c.velocities, c.forces, c.limit_factors, V, w, force, torque)
    phi = np.empty(60)
    kernels.dissipation(c.positions, c.velocities, c.forces, c.limit_factors, V, w, phi)
    f_ref, t_ref, p_ref = _numpy_wrench(c, V, w)
    # Sums of 40 terms of order 1 in another order: a few hundred eps.
    np.testing.assert_allclose(force, f_ref, rtol=0, atol=1e-13)
    np.testing.assert_allclose(torque, t_ref, rtol=0, atol=1e-13)
    np.testing.assert_allclose(phi, p_ref, rtol=1e-14, atol=0)


def test_newton_terms_match_finite_differences(rng):
    n, d = 25, 3
    c, B, f = rng.normal(size=(n, 2)), rng.normal(size=(n, 2, d)), rng.uniform(0.1, 1, n)
    Q, b = np.diag([2.0, 1.0, 0.5]), rng.normal(size=d)
    kernels = load("planar")
    for mu in (0.0, 1e-2):
        x = rng.normal(size=d)
        grad, hess = np.zeros(d), np.zeros((d, d))
        value = kernels.terms(c, B, f, Q, b, x, mu, 1e-300, grad, hess)
        assert abs(value - kernels.value(c, B, f, Q, b, x, mu)) <= 1e-14 * abs(value)
        h = 1e-6
        for k in range(d):
            e = np.zeros(d)
            e[k] = h
            fd = (kernels.value(c, B, f, Q, b, x + e, mu) - kernels.value(c, B, f, Q, b, x - e, mu)) / (2 * h)
            gp, gm, hp = np.zeros(d), np.zeros(d), np.zeros((d, d))
            kernels.terms(c, B, f, Q, b, x + e, mu, 1e-300, gp, hp)
            kernels.terms(c, B, f, Q, b, x - e, mu, 1e-300, gm, hp)
            # Central differences, truncation ~h^2 |P'''| ~ 1e-11, rounding eps |P| / h ~ 1e-9.
            assert abs(fd - grad[k]) <= 1e-7
            np.testing.assert_allclose((gp - gm) / (2 * h), hess[:, k], rtol=0, atol=1e-5)


def test_solve_small_and_a_certified_solve(rng):
    kernels = load("planar")
    A = np.array([[4.0, 1.0, 0.5], [1.0, 3.0, 0.2], [0.5, 0.2, 2.0]])
    r = np.array([1.0, -2.0, 0.5])
    out = np.zeros(3)
    assert kernels.solve_small(A, r, out)
    np.testing.assert_allclose(A @ out, r, rtol=0, atol=1e-15)
    assert not kernels.solve_small(np.zeros((2, 2)), np.ones(2), np.zeros(2))
    # An indefinite matrix from rounding: the lost pivot takes the shift, no exception.
    assert kernels.solve_small(np.array([[1.0, 1.0], [1.0, 1.0 - 1e-12]]), np.ones(2), np.zeros(2))
    n = 200
    prob = NormSum(rng.normal(size=(n, 2)), np.tile(np.eye(2), (n, 1, 1)), np.full(n, 1.0 / n), None, np.zeros(2))
    sol = solve_fast(prob, 1e-10)
    assert sol.gap <= 1e-12 and np.max(np.abs(sol.residual)) <= 1e-13
