"""What a filter takes as known, in its covariance: toolkit.estimation.consider."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from toolkit.estimation.consider import Consider, OtherContact, prior_moments
from toolkit.model.friction import contact_forces


@pytest.mark.parametrize("scale", [2.0 ** -20, 1.0, 2.0 ** 20])
@pytest.mark.parametrize("k, margin, direction", [(2, 0.5, 1.0), (3, -0.3, 1.0), (2, 0.2, -1.0)])
def test_the_chance_of_sliding_on_is_the_friction_laws_over_the_force_errors(scale, k, margin, direction):
    # Unequal magnitudes, drag and an outside force that leaves contact k a stick margin of
    # `margin` standard deviations of the force errors, all scaled together (forces and mass
    # by `scale`: the same accelerations). Over 200 000 draws of the force errors (Gaussian,
    # of second moments m2), the share of draws where the friction law no longer holds the
    # body on contact k (|G| > f_k (1 + e_k)) is the prior probability Phi(-margin) (a
    # binomial share errs by sqrt(p (1 - p) / N) <= 0.0011: the line is 4 of those), and the
    # mean and variance of the excess force over those draws, per unit mass, are the
    # alternative's acceleration and its variance, towards the next contact speed on the side
    # the net force pushes (`direction`) (the truncated normal's; lines 1 % and 3 %,
    # about 4 standard errors). |G| lies more than 6 sigma from 0: the law is linear in the
    # errors there.
    speeds = np.array([-0.3, -0.1, 0.05, 0.2, 0.45])
    forces = np.array([1.0, 2.5, 3.0, 1.5, 0.7]) * scale
    mass, damping = 2.0 * scale, 0.4 * scale
    m2 = np.array([4e-4, 1e-4, 9e-4, 2.5e-4, 1e-3, 1e-3 * scale * scale])
    v = speeds[k]
    sigma = math.sqrt(float(np.sum(forces ** 2 * m2[:-1])) + v * v * m2[-1])
    G_in = float(np.delete(contact_forces(speeds - v, forces), k).sum()) - damping * v
    outside = direction * (forces[k] - margin * sigma) - G_in    # (|G| = f_k - margin sigma)
    other = OtherContact(forces, mass, damping, m2)
    p = other.start(0.0, 0.0, speeds, k, outside)
    assert p == pytest.approx(0.5 * math.erfc(margin / math.sqrt(2.0)), rel=1e-12)
    rng = np.random.default_rng(7)
    N = 200_000
    e = rng.standard_normal((N, m2.size)) * np.sqrt(m2)
    drawn = forces * (1.0 + e[:, :-1])
    G = (np.delete(contact_forces(speeds - v, 1.0) * drawn, k, axis=1).sum(axis=1) + outside
         - (damping + e[:, -1]) * v)
    assert forces[k] - margin * sigma > 6.0 * sigma
    excess = np.abs(G) - drawn[:, k]
    slid = excess > 0.0
    assert abs(slid.mean() - p) <= 4.0 * math.sqrt(p * (1.0 - p) / N), (slid.mean(), p)
    t0, X0, v_k, sign, d, a, var_a = other._motion
    assert sign == direction and v_k == v
    assert a == pytest.approx(excess[slid].mean() / mass, rel=0.01)
    assert var_a == pytest.approx(excess[slid].var() / mass ** 2, rel=0.03)
    assert d == (speeds[k + 1] - v if direction > 0 else v - speeds[k - 1])


def test_the_counts_decide_between_the_contact_and_the_next():
    # A body stuck on contact 1 whose margin is nil (a tie: p = 1/2). Readings that follow the
    # contact drive the alternative's probability to 0 (below floating point: the alternative
    # is dropped while the body stays, and nothing is added however the readings go on);
    # readings that follow the alternative's motion drive it to 1, and the covariance added is
    # then the alternative's offset from the estimate (u u^T + C with p = 1).
    speeds = np.array([0.0, 0.1, 0.2, 0.3])
    forces = np.ones(4)
    m2 = np.array([0.09, 0.09, 0.09, 0.09, 0.0])
    h, S = 0.01, 1e-10
    for follows_alternative in (False, True):
        other = OtherContact(forces, 1.0, 0.0, m2)
        X = 0.0
        for j in range(80):
            t = j * h
            if j == 0:
                z = x_pred = X
            else:
                X_alt, V_alt, _ = other._alternative(t)
                x_pred = 0.1 * t
                z = X_alt if follows_alternative else x_pred
            other.step(t, h, 1, speeds, 0.0, x_pred, 0.1, z, x_pred, S)
        p = 1.0 / (1.0 + math.exp(-other._logit)) if other._logit < 700 else 1.0
        if follows_alternative:
            assert p > 1.0 - 1e-9 and other.weighed is True
            X_alt, V_alt, C = other._alternative(t)
            u = np.array([X_alt - x_pred, V_alt - 0.1])
            np.testing.assert_allclose(other.covariance, np.outer(u, u) + C, rtol=1e-12)
        else:
            assert other._logit == -math.inf and other.weighed is False
            np.testing.assert_array_equal(other.covariance, np.zeros((2, 2)))
            X_alt = other._motion_at(0.9)[0]                 # (readings on the alternative now)
            other.step(0.9, h, 1, speeds, 0.0, 0.09, 0.1, X_alt, 0.09, S)
            assert other._logit == -math.inf and other.weighed is False
            np.testing.assert_array_equal(other.covariance, np.zeros((2, 2)))


def test_the_sensitivity_steps_as_the_linear_filters_error():
    # S+ = (I - K H)(F S + G) for a position update (H = [1, 0]) and (I - K [0, 1]) S for a
    # speed update, and the covariance S diag(m2) S^T, against the matrices written out, over
    # steps with unequal second moments and gains (rounding: S to 1e-14 relative; the
    # covariance's off-diagonal sums terms of both signs, to 1e-14 of its largest entry).
    rng = np.random.default_rng(3)
    m2 = np.array([0.09, 0.01, 0.25, 4.0])
    consider = Consider(m2)
    S = np.zeros((2, 4))
    for _ in range(5):
        F = np.array([[1.0, 0.02], [0.0, rng.uniform(0.0, 1.0)]])
        G = rng.standard_normal((2, 4)) * 1e-3
        K = rng.uniform(0.0, 1.0, 2)
        consider.step(F, G, (K[0], K[1]))
        S = (np.eye(2) - np.outer(K, [1.0, 0.0])) @ (F @ S + G)
        np.testing.assert_allclose(consider.S, S, rtol=1e-14, atol=1e-18)
        cov = S @ np.diag(m2) @ S.T
        np.testing.assert_allclose(consider.covariance, cov, rtol=1e-14, atol=1e-14 * np.abs(cov).max())
    K = np.array([0.1, 0.6])
    consider.measured_speed(K)
    S = (np.eye(2) - np.outer(K, [0.0, 1.0])) @ S
    cov = S @ np.diag(m2) @ S.T
    np.testing.assert_allclose(consider.covariance, cov, rtol=1e-14, atol=1e-14 * np.abs(cov).max())
    consider.step(np.eye(2), None, (0.0, 0.0))              # (no response: F S alone)
    np.testing.assert_allclose(consider.S, S, rtol=1e-14)
    consider.reset()
    np.testing.assert_array_equal(consider.S, np.zeros((2, 4)))
    np.testing.assert_array_equal(consider.covariance, np.zeros((2, 2)))


def test_the_priors_moments_about_the_model():
    # Each magnitude's relative error: mean 0, variance spread^2; the drag's error about the
    # model's drag: a told range as a Gaussian of its midpoint and half-width, by default the
    # nominal drag with std DEFAULT_DRAG.
    from toolkit.analysis.scenarios import carousel_brake_scenario
    from toolkit.model.truth import DEFAULT_DRAG, ModelPrior

    model = dataclasses.replace(carousel_brake_scenario(t_end=0.2, brake_time=0.1).model, damping=0.7)
    n = model.n
    mean, var = prior_moments(model, ModelPrior(friction_spread=0.3))
    np.testing.assert_array_equal(mean, np.zeros(n + 1))
    np.testing.assert_array_equal(var, np.r_[np.full(n, 0.09), DEFAULT_DRAG ** 2])
    mean, var = prior_moments(model, ModelPrior(friction_spread=0.1, drag_range=(0.5, 1.7)))
    assert mean[n] == pytest.approx(0.4, rel=1e-15) and var[n] == pytest.approx(0.36, rel=1e-15)
    assert np.all(var[:n] == 0.1 ** 2) and not mean[:n].any()


def test_the_alternatives_motion_and_its_slopes_in_the_acceleration():
    # The alternative accelerates at a from v_k towards the next contact speed d away and
    # sticks there: X = X0 + v tau + s a tau^2 / 2 until tau = d / a, then X0 + v tau + s (d
    # tau - d^2 / (2 a)), V = v + s min(a tau, d). Its covariance is var_a g g^T with g the
    # slopes of (X, V) in a: against central differences of the mean (step 1e-6 a:
    # truncation and rounding below 1e-7 relative; the line 1e-6).
    # Two contacts share the held speed: the next speed beyond is 0.25, d = 0.15.
    speeds = np.array([0.0, 0.1, 0.1, 0.25, 0.3])
    other = OtherContact(np.array([1.0, 1.0, 0.4, 1.2, 0.9]), 1.5, 0.0,
                         np.array([0.04, 0.09, 0.01, 0.02, 0.05, 0.0]))
    p = other.start(1.0, 2.0, speeds, 1, 0.0)
    t0, X0, v, sign, d, a, var_a = other._motion
    assert 0.0 < p < 1.0 and (t0, X0, v) == (1.0, 2.0, 0.1) and sign == 1.0 and d == pytest.approx(0.15, rel=1e-14)
    for tau in (0.3 * d / a, 0.999 * d / a, 1.001 * d / a, 3.0 * d / a):
        X, V, C = other._alternative(t0 + tau)
        reach = d / a
        expect_X = X0 + v * tau + (0.5 * a * tau * tau if tau < reach else d * tau - d * d / (2.0 * a))
        assert X == pytest.approx(expect_X, rel=1e-14) and V == pytest.approx(v + min(a * tau, d), rel=1e-14)
        slopes = []
        for delta in (1e-6 * a, -1e-6 * a):
            other._motion = (t0, X0, v, sign, d, a + delta, var_a)
            slopes.append(np.array(other._alternative(t0 + tau)[:2]))
        other._motion = (t0, X0, v, sign, d, a, var_a)
        g = (slopes[0] - slopes[1]) / (2e-6 * a)
        np.testing.assert_allclose(C, var_a * np.outer(g, g), rtol=1e-6, atol=1e-18)


def test_each_count_weighs_the_two_hypotheses_by_bayes_rule():
    # Two samples after the body is found on contact 1 with an intermediate prior: the
    # alternative's probability is Bayes' rule over the readings' Gaussian likelihoods (the
    # filter's prediction with variance S, the alternative's mean with S + C_XX), computed
    # here with scipy.stats.norm; the covariance added is p (u u^T + C).
    from scipy.stats import norm

    speeds = np.array([0.0, 0.1, 0.25])
    m2 = np.array([0.09, 0.09, 0.09, 0.0])
    forces = np.array([1.0, 1.0, 1.0])
    outside = -0.8                                    # (margin 0.2 N: an intermediate prior)
    other = OtherContact(forces, 1.0, 0.0, m2)
    h, S, X, V = 0.01, 4e-10, 1.0, 0.1
    other.step(0.0, h, 1, speeds, outside, X, V, 1.0, 1.0, S)
    probe = OtherContact(forces, 1.0, 0.0, m2)
    p = probe.start(-h, X - 0.1 * h, speeds, 1, outside)
    assert 0.05 < p < 0.95
    X_alt, V_alt, C = other._alternative(0.0)
    u = np.array([X_alt - X, V_alt - V])
    np.testing.assert_allclose(other.covariance, p * (np.outer(u, u) + C), rtol=1e-12)
    for j, shift in ((1, 2e-5), (2, -1e-5)):
        t = j * h
        X, x_pred = 1.0 + 0.1 * t, 1.0 + 0.1 * t
        X_alt, V_alt, C = other._alternative(t)
        z = x_pred + shift
        alt, nominal = p * norm.pdf(z, X_alt, math.sqrt(S + C[0, 0])), (1.0 - p) * norm.pdf(z, x_pred, math.sqrt(S))
        p = alt / (alt + nominal)
        other.step(t, h, 1, speeds, outside, X, V, z, x_pred, S)
        u = np.array([X_alt - X, V_alt - V])
        np.testing.assert_allclose(other.covariance, p * (np.outer(u, u) + C), rtol=1e-9)
    assert other.weighed is True
    other.step(3 * h, h, None, speeds, outside, X, V, z, x_pred, S)     # (off the contact: none)
    assert other.k is None and other.weighed is False
    np.testing.assert_array_equal(other.covariance, np.zeros((2, 2)))


def test_certain_forces_add_nothing_and_a_certain_slide_adds_all():
    # Force errors of second moment 0: no alternative (probability 0, nothing added). A
    # margin of -40 sigma (an outside force far beyond the contact's friction): the body
    # slides on for certain (p = 1 in floating point), and the alternative's whole offset and
    # covariance are added. With no contact speed beyond (the outermost contact, pushed
    # outwards), it slides on without end: still accelerating long after.
    speeds, forces = np.array([0.0, 0.1, 0.25]), np.array([1.0, 1.0, 1.0])
    certain = OtherContact(forces, 1.0, 0.0, np.zeros(4))
    assert certain.start(0.0, 0.0, speeds, 1, 0.0) == 0.0 and certain._motion is None
    for t in (0.0, 0.01):                           # (found on the contact, then held there)
        certain.step(t, 0.01, 1, speeds, 0.0, 0.1 * t, 0.1, 0.1 * t, 0.1 * t, 1e-10)
        np.testing.assert_array_equal(certain.covariance, np.zeros((2, 2)))
        assert certain.weighed is False
    m2 = np.array([0.01, 0.01, 0.01, 0.0])
    sigma = math.sqrt(0.03)
    other = OtherContact(forces, 1.0, 0.0, m2)
    push = 1.0 + 40.0 * sigma                       # (G = 0 + push: margin 1 - push = -40 sigma)
    other.step(0.0, 0.01, 1, speeds, push, 0.0, 0.1, 0.0, 0.0, 1e-10)
    X_alt, V_alt, C = other._alternative(0.0)
    np.testing.assert_allclose(other.covariance, np.outer([X_alt, V_alt - 0.1], [X_alt, V_alt - 0.1]) + C,
                               rtol=1e-12)
    outer = OtherContact(forces, 1.0, 0.0, m2)
    outer.start(0.0, 0.0, speeds, 2, 3.0)             # (G = -2 + 3: outwards)
    t0, X0, v, sign, d, a, var_a = outer._motion
    assert sign == 1.0 and d == math.inf
    assert outer._alternative(100.0)[1] == pytest.approx(0.25 + 100.0 * a, rel=1e-14)
