"""What a filter takes as known, in its covariance: toolkit.estimation.consider."""

from __future__ import annotations

import math

import numpy as np
import pytest

from toolkit.estimation.consider import OtherContact
from toolkit.model.friction import contact_forces


@pytest.mark.parametrize("scale", [2.0 ** -20, 1.0, 2.0 ** 20])
@pytest.mark.parametrize("k, margin", [(2, 0.5), (3, -0.3)])
def test_the_chance_of_sliding_on_is_the_friction_laws_over_the_force_errors(scale, k, margin):
    # Unequal magnitudes, drag and an outside force that leaves contact k a stick margin of
    # `margin` standard deviations of the force errors, all scaled together (forces and mass
    # by `scale`: the same accelerations). Over 200 000 draws of the force errors (Gaussian,
    # of second moments m2), the share of draws where the friction law no longer holds the
    # body on contact k (|G| > f_k (1 + e_k)) is the prior probability Phi(-margin) (a
    # binomial share errs by sqrt(p (1 - p) / N) <= 0.0011: the line is 4 of those), and the
    # mean and variance of the excess force over those draws, per unit mass, are the
    # alternative's acceleration and its variance (the truncated normal's; lines 1 % and 3 %,
    # about 4 standard errors). |G| lies more than 6 sigma from 0: the law is linear in the
    # errors there.
    speeds = np.array([-0.3, -0.1, 0.05, 0.2, 0.45])
    forces = np.array([1.0, 2.5, 3.0, 1.5, 0.7]) * scale
    mass, damping = 2.0 * scale, 0.4 * scale
    m2 = np.array([4e-4, 1e-4, 9e-4, 2.5e-4, 1e-3, 1e-3 * scale * scale])
    v = speeds[k]
    sigma = math.sqrt(float(np.sum(forces ** 2 * m2[:-1])) + v * v * m2[-1])
    G_in = float(np.delete(contact_forces(speeds - v, forces), k).sum()) - damping * v
    outside = (forces[k] - margin * sigma) - G_in           # (G = f_k - margin sigma > 0)
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
    assert sign == 1.0 and v_k == v
    assert a == pytest.approx(excess[slid].mean() / mass, rel=0.01)
    assert var_a == pytest.approx(excess[slid].var() / mass ** 2, rel=0.03)
    assert d == speeds[k + 1] - v


def test_the_counts_decide_between_the_contact_and_the_next():
    # A body stuck on contact 1 whose margin is nil (a tie: p = 1/2). Readings that follow the
    # contact drive the alternative's probability to 0 and the added covariance with it; readings
    # that follow the alternative's motion drive it to 1, and the covariance added is then the
    # alternative's offset from the estimate (u u^T + C with p = 1).
    speeds = np.array([0.0, 0.1, 0.2, 0.3])
    forces = np.ones(4)
    m2 = np.array([0.09, 0.09, 0.09, 0.09, 0.0])
    h, S = 0.01, 1e-10
    for follows_alternative in (False, True):
        other = OtherContact(forces, 1.0, 0.0, m2)
        X = 0.0
        for j in range(40):
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
            assert p > 1.0 - 1e-9
            X_alt, V_alt, C = other._alternative(t)
            u = np.array([X_alt - x_pred, V_alt - 0.1])
            np.testing.assert_allclose(other.covariance, np.outer(u, u) + C, rtol=1e-12)
        else:
            assert p < 1e-9 and np.all(np.abs(other.covariance) <= 1e-9 * 0.1 ** 2)
