"""Continuous contact regions: closed forms, quadrature within its bound, terminal ratios."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import dblquad, quad

from toolkit.errors import ParameterError
from toolkit.planar import (CurveRegion, DiscRegion, Quadrature, RingRegion, disc_force_torque,
                            terminal_ratio)
from toolkit.planar.regions import _disc_shape, _ring_shape


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(424242)


def test_spinning_disc_torque_is_two_thirds_mu_n_r():
    for R, F, w in ((0.1, 3.0, 2.0), (2.0, 0.5, -7.0), (1e-3, 1e3, 0.1)):
        force, torque = disc_force_torque([0.0, 0.0], w, radius=R, force=F)
        np.testing.assert_array_equal(force, [0.0, 0.0])
        np.testing.assert_allclose(torque, -np.sign(w) * 2 / 3 * F * R, rtol=1e-15)
        # Annulus: (2/3) F (R^3 - r^3) / (R^2 - r^2); thin ring: F R.
        r = 0.4 * R
        _, t_ann = disc_force_torque([0.0, 0.0], w, radius=R, force=F, inner_radius=r)
        np.testing.assert_allclose(t_ann, -np.sign(w) * 2 / 3 * F * (R**3 - r**3) / (R**2 - r**2), rtol=1e-14)
        _, t_ring = RingRegion(R, F).force_torque([0.0, 0.0], w)
        np.testing.assert_allclose(t_ring, -np.sign(w) * F * R, rtol=1e-14)


def test_sliding_without_spin_is_plain_coulomb():
    for region in (DiscRegion(0.3, 2.0), RingRegion(0.3, 2.0), DiscRegion(0.3, 2.0, inner_radius=0.1)):
        force, torque = region.force_torque([0.6, -0.8], 0.0)
        np.testing.assert_allclose(force, [-1.2, 1.6], rtol=1e-15)
        assert torque == 0.0


@pytest.mark.parametrize("eps", [0.05, 0.3, 0.7, 0.999, 1.0, 1.001, 1.7, 6.0])
def test_disc_shape_functions_against_direct_integration(eps):
    # F(eps), T(eps) of the unit disc spinning at omega = 1 with its centre moving at eps:
    # direct double integrals of the unit slip direction (adaptive quadrature, 1e-12).
    c = np.array([0.0, eps])

    def unit(r, th):
        x, y = r * np.cos(th), r * np.sin(th)
        d = np.hypot(x - c[0], y - c[1])
        return x, y, d

    fx = dblquad(lambda r, th: -(unit(r, th)[1] - eps) / unit(r, th)[2] * r, 0, 2 * np.pi, 0, 1,
                 epsabs=1e-12, epsrel=1e-12)[0] / np.pi
    tq = dblquad(lambda r, th: (r * r - eps * unit(r, th)[1]) / unit(r, th)[2] * r, 0, 2 * np.pi, 0, 1,
                 epsabs=1e-12, epsrel=1e-12)[0] / np.pi
    F, T = _disc_shape(np.array(eps))
    # The integrand has a kink at the ICR inside the disc: adaptive quadrature to ~1e-10.
    np.testing.assert_allclose([F, T], [fx, tq], rtol=0, atol=1e-9)


@pytest.mark.parametrize("eps", [0.2, 1.0, 3.0])
def test_ring_shape_functions_against_direct_integration(eps):
    F_num = quad(lambda th: -(np.sin(th) - eps) / np.hypot(np.cos(th), np.sin(th) - eps),
                 0, 2 * np.pi, epsabs=1e-13, limit=200, points=[np.pi / 2] if eps == 1.0 else None)[0] / (2 * np.pi)
    T_num = quad(lambda th: (1 - eps * np.sin(th)) / np.hypot(np.cos(th), np.sin(th) - eps),
                 0, 2 * np.pi, epsabs=1e-13, limit=200, points=[np.pi / 2] if eps == 1.0 else None)[0] / (2 * np.pi)
    F, T = _ring_shape(np.array(eps))
    np.testing.assert_allclose([F, T], [F_num, T_num], rtol=0, atol=1e-10)


def _twists(rng, k, scale):
    return rng.normal(size=(k, 2)) * scale, rng.normal(size=k) * 3


@pytest.mark.parametrize("kind", ["disc", "annulus", "ring"])
def test_quadrature_error_is_within_its_bound_and_shrinks(rng, kind):
    region = {"disc": DiscRegion(0.4, 5.0, centre=(0.2, -0.1), velocity=(0.1, 0.0)),
              "annulus": DiscRegion(0.4, 5.0, centre=(-0.3, 0.0), inner_radius=0.25),
              "ring": RingRegion(0.4, 5.0, centre=(0.1, 0.3))}[kind]
    V, w = _twists(rng, 300, 0.5)
    exact_f, exact_t = region.force_torque(V, w)
    previous = np.inf
    for level in ((6, 12, 24) if kind != "ring" else (64, 256, 1024)):
        q = region.quadrature(level)
        r = q.wrench(V, w)
        err_f = np.hypot(*(r.force - exact_f).T)
        err_t = np.abs(r.torque - exact_t)
        # The bound is rigorous (docs/planar.md section 3); closed forms are at ~1e-15.
        assert np.all(err_f <= r.force_bound + 1e-12) and np.all(err_t <= r.torque_bound + 1e-12)
        worst = float(np.max(r.force_bound))
        assert worst < previous
        previous = worst


def test_curve_quadrature_within_its_bound(rng):
    # A snake-like curve with varying density, varying velocity and anisotropy: the reference
    # is the same quadrature refined 64 times, whose own bound is added to the tolerance.
    s = np.linspace(0, 1, 9)
    points = np.c_[s, 0.1 * np.sin(2 * np.pi * s)]
    curve = CurveRegion(points, density=2.0 + np.cos(3 * s), velocities=np.c_[0.2 * s, -0.1 * s ** 2],
                        ratio=3.0)
    V, w = _twists(rng, 100, 0.3)
    fine = curve.quadrature(curve.length / 12800).wrench(V, w)
    for cells in (50, 200, 800):
        r = curve.quadrature(curve.length / cells).wrench(V, w)
        assert np.all(np.hypot(*(r.force - fine.force).T) <= r.force_bound + fine.force_bound + 1e-12)
        assert np.all(np.abs(r.torque - fine.torque) <= r.torque_bound + fine.torque_bound + 1e-12)
    np.testing.assert_allclose(curve.quadrature().contacts.total_force, curve.total_force, rtol=1e-14)


def test_translation_of_a_uniform_curve_is_exact():
    # No rotation and a uniform velocity: every cell has the same slip, the bound is 0.
    curve = CurveRegion([[0, 0], [1, 0], [1, 1]], density=1.5)
    r = curve.quadrature(0.1).wrench([0.3, 0.4], 0.0)
    np.testing.assert_allclose(r.force, [-3.0 * 0.6, -3.0 * 0.8], rtol=1e-14)    # F_tot = 1.5 N/m x 2 m
    assert r.force_bound == 0.0


def test_concatenated_quadratures_add():
    a, b = DiscRegion(0.2, 1.0, centre=(0.5, 0)), RingRegion(0.1, 2.0, centre=(-0.5, 0))
    qa, qb = a.quadrature(8), b.quadrature(64)
    both = Quadrature.concatenate([qa, qb])
    r, ra, rb = both.wrench([0.1, 0.2], 1.5), qa.wrench([0.1, 0.2], 1.5), qb.wrench([0.1, 0.2], 1.5)
    np.testing.assert_allclose(r.force, ra.force + rb.force, rtol=1e-14)
    np.testing.assert_allclose(r.torque_bound, ra.torque_bound + rb.torque_bound, rtol=1e-14)


def test_terminal_ratios_match_the_literature():
    # Uniform disc: 0.653 (Farkas et al. 2003; Weidman & Malhotra 2005); thin ring: 1.0;
    # annuli between the two, increasing with the hole (Weidman & Malhotra).
    assert abs(terminal_ratio() - 0.653) < 5e-4
    np.testing.assert_allclose(terminal_ratio("ring"), 1.0, rtol=1e-12)
    ratios = [terminal_ratio(inner_ratio=e) for e in (0.0, 0.3, 0.6, 0.9)]
    assert np.all(np.diff(ratios) > 0) and 0.653 < ratios[-1] < 1.0


def test_terminal_ratio_from_the_quadrature_is_within_its_bound():
    # Second method: the root of F = 2 eps T with F and T from a 48-ring quadrature; the
    # quadrature's bounds on F and T at the root bound how far the root can move.
    from scipy.optimize import brentq

    q = DiscRegion(1.0, 1.0).quadrature(48)

    def balance(e):
        r = q.wrench([e, 0.0], 1.0)
        return -r.force[0] - 2 * e * (-r.torque)

    root = brentq(balance, 0.3, 0.9, xtol=1e-14)
    r = q.wrench([root, 0.0], 1.0)
    slack = float(r.force_bound + 2 * root * r.torque_bound)
    exact = terminal_ratio()
    d = 1e-6
    slope = abs((balance(exact + d) - balance(exact - d)) / (2 * d))
    assert abs(root - exact) <= slack / slope * 1.5


def test_region_input_is_checked():
    with pytest.raises(ParameterError, match="'inner_radius' parameter of DiscRegion must be < radius"):
        DiscRegion(0.1, 1.0, inner_radius=0.2)
    with pytest.raises(ParameterError, match="'density' parameter of CurveRegion"):
        CurveRegion([[0, 0], [1, 0]], density=[0.0, 0.0])
    with pytest.raises(ParameterError, match="'radius' parameter of RingRegion must be > 0"):
        RingRegion(0.0, 1.0)
