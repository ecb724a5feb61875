"""Planar allocation: target twists realized, infeasibility certified, resistance targets."""

from __future__ import annotations

import numpy as np
import pytest

from toolkit.errors import ParameterError
from toolkit.planar import PlanarContactSet
from toolkit.planar.allocation import (PlanarAllocationStatus, allocate_resistance, allocate_twist,
                                       infeasibility_margin)

HIPS = np.array([[0.1, 0.06], [0.0, 0.06], [-0.1, 0.06], [0.1, -0.06], [0.0, -0.06], [-0.1, -0.06]])
LOADS = np.full(6, 9.81 * 0.5 / 6)


def _check_realized(result, vmax):
    assert result.status is PlanarAllocationStatus.REALIZED, result.message
    speed = np.hypot(result.velocities[:, 0], result.velocities[:, 1])
    assert np.all(speed <= vmax * (1 + 1e-12))
    # Measured on the achieved contacts by the certified equilibrium (not the allocator's word).
    assert result.error <= 1e-9 * 0.1 and result.equilibrium.certified


@pytest.mark.parametrize("target,vmax", [((0.1, 0.0, 0.0), 0.2), ((0.1, 0.0, 0.3), 0.13),
                                         ((0.05, 0.02, -0.4), 0.2)])
def test_targets_within_reach_stick_every_leg(target, vmax):
    r = allocate_twist(HIPS, LOADS, vmax, target)
    _check_realized(r, vmax)
    assert r.method == "stick" and not np.any(r.slipping) and r.dissipation <= 1e-15
    assert r.equilibrium.unique        # stuck legs at distinct points fix the twist


@pytest.mark.parametrize("target,vmax,slipping", [((0.1, 0.0, 0.3), 0.12, 2), ((0.1, 0.0, 0.3), 0.11, 3),
                                                  ((0.1, 0.0, 0.5), 0.13, 2)])
def test_targets_that_need_slipping_legs_are_realized(target, vmax, slipping):
    r = allocate_twist(HIPS, LOADS, vmax, target)
    _check_realized(r, vmax)
    assert int(np.sum(r.slipping)) == slipping and r.dissipation > 0
    # The realized contacts reproduce the target as their own equilibrium, independently.
    eq = PlanarContactSet(HIPS, r.velocities, LOADS).equilibrium()
    np.testing.assert_allclose(eq.twist, target, rtol=0, atol=1e-10)


@pytest.mark.parametrize("target,vmax", [((0.3, 0.0, 0.0), 0.2), ((0.1, 0.0, 0.8), 0.12),
                                         ((0.0, 0.0, 2.0), 0.1), ((0.1, 0.0, 0.5), 0.11)])
def test_unreachable_targets_come_with_a_checked_certificate(target, vmax):
    r = allocate_twist(HIPS, LOADS, vmax, target)
    assert r.status is PlanarAllocationStatus.INFEASIBLE and r.bound > 0 and r.error == np.inf
    # The certificate is checked from the exact support functions of the legs' force sets.
    assert infeasibility_margin(HIPS, LOADS, vmax, target, r.certificate) < 0
    # Second method: any allocation within the limits leaves y . w < 0 (sampled allocations).
    rng = np.random.default_rng(1)
    y = r.certificate
    for _ in range(200):
        ang = rng.uniform(0, 2 * np.pi, 6)
        rad = vmax * np.sqrt(rng.uniform(0, 1, 6))
        v = np.c_[rad * np.cos(ang), rad * np.sin(ang)]
        force, torque = PlanarContactSet(HIPS, v, LOADS).wrench(np.asarray(target[:2]), target[2])
        assert y[0] * force[0] + y[1] * force[1] + y[2] * torque < 0


def test_resistance_target_from_a_real_configuration_is_matched():
    # A target that is achievable: the equilibrium and resistance of legs that all slip.
    for seed in range(20):
        rng = np.random.default_rng(seed)
        v = rng.uniform(-0.1, 0.1, (6, 2)) + [0.1, 0.0]
        contacts = PlanarContactSet(HIPS, v, LOADS)
        eq = contacts.equilibrium()
        if not np.any(eq.stuck):
            break
    R = contacts.resistance(eq.velocity, eq.omega)
    r = allocate_resistance(HIPS, LOADS, 0.3, eq.twist, R, starts=4)
    assert r.status is PlanarAllocationStatus.REALIZED, r.message
    # Measured on the achieved contacts: resistance within 1e-6 (ipopt at 1e-12), target
    # twist within 1e-9 of its speed scale; the bound is 0 (not certified).
    assert r.error <= 1e-6 and r.bound == 0.0
    np.testing.assert_allclose(r.contacts.resistance(eq.velocity, eq.omega), R, rtol=0,
                               atol=1e-6 * np.linalg.norm(R))


def test_allocation_input_is_checked():
    with pytest.raises(ParameterError, match="'target' parameter of allocate_twist must be a twist"):
        allocate_twist(HIPS, LOADS, 0.1, (0.1, 0.0))
    with pytest.raises(ParameterError, match="'speed_limits' parameter of allocate_twist must be >= 0"):
        allocate_twist(HIPS, LOADS, -0.1, (0.1, 0.0, 0.0))
