"""Gaits: schedules, the force-twist map through a cycle, net motion, the averaged model."""

from __future__ import annotations

import numpy as np
import pytest

from toolkit.errors import ParameterError
from toolkit.planar import PlanarContactSet
from toolkit.planar.gaits import (Gait, averaged_model, compare_averaged, dynamic_cycles,
                                  force_twist_map, quasi_static_cycle, se2_step, serpenoid,
                                  tripod_gait)


def test_schedule_interpolates_linearly_and_wraps():
    pos = np.array([[[0.0, 0.0], [1.0, 0.0]], [[0.2, 0.0], [1.0, 0.4]]])
    vel = np.array([[[0.1, 0.0], [0.0, 0.0]], [[0.3, 0.0], [0.0, 0.2]]])
    load = np.array([[1.0, 0.0], [3.0, 2.0]])
    gait = Gait(2.0, [0.0, 1.0], pos, vel, load)
    c = gait.contacts_at(0.25)
    np.testing.assert_allclose(c.positions, [[0.05, 0.0], [1.0, 0.1]], rtol=0, atol=1e-15)
    np.testing.assert_allclose(c.forces, [1.5, 0.5], rtol=0, atol=1e-15)
    # From the last sample back to the first one over the wrap (t = 1.5: halfway).
    np.testing.assert_allclose(gait.contacts_at(1.5).forces, [2.0, 1.0], rtol=0, atol=1e-15)
    np.testing.assert_allclose(gait.contacts_at(3.5).forces, [2.0, 1.0], rtol=0, atol=1e-15)


def test_tripod_loads_touch_down_and_lift_off_at_zero_and_carry_the_weight():
    gait = tripod_gait(duty=0.6, mu=0.5, weight=9.81, samples=240)
    total = gait.loads.sum(axis=1)
    np.testing.assert_allclose(total, 0.5 * 9.81, rtol=1e-13)
    for leg in range(6):
        f = gait.loads[:, leg]
        on = f > 0
        # Stance is 60 % of the period; the load rises from 0 and returns to 0.
        assert abs(on.mean() - 0.6) <= 2 / 240
        edges = np.flatnonzero(np.diff(on.astype(int)))
        for e in edges:
            assert min(f[e], f[(e + 1) % 240]) < 0.05 * f.max()


def test_straight_tripod_walks_at_its_sweep_speed_with_and_without_averaging():
    # Equal sweeps: at every instant the stance legs are rigidly consistent with (u, 0, 0),
    # so the body moves u per second exactly; the averaged model agrees exactly.
    gait = tripod_gait(speed=0.12, period=1.5)
    cmp = compare_averaged(gait, samples=96)
    np.testing.assert_allclose(cmp.cycle.displacement, [0.18, 0.0], rtol=0, atol=1e-14)
    np.testing.assert_allclose(cmp.averaged.displacement, [0.18, 0.0], rtol=0, atol=1e-14)
    assert cmp.error <= 1e-14


def test_turning_tripod_quasi_static_against_averaged():
    gait = tripod_gait(turn=0.3, load_shift=0.25, samples=240)
    coarse = quasi_static_cycle(gait, 120)
    fine = quasi_static_cycle(gait, 240)
    # The Richardson estimate of the 120-sample result bounds its distance to the 240 one
    # within a factor 4 (second-order midpoint rule; the equilibrium is only Lipschitz at
    # touchdown and lift-off).
    assert np.hypot(*(coarse.displacement - fine.displacement)) <= 4 * coarse.error + 1e-12
    assert fine.max_gap <= 1e-8 * 9.81
    cmp = compare_averaged(gait, fine, samples=240)
    # The averaged (resistive-force) model turns several times more than the cycle does:
    # its error is far above the cycle's own error estimate.
    assert cmp.rotation_error > 10 * fine.rotation_error
    assert cmp.error > 100 * fine.error


def test_force_twist_map_shapes_and_the_averaged_wrench():
    gait = tripod_gait(turn=0.2, samples=64)
    V = np.array([[0.1, 0.0], [0.05, 0.01]])
    w = np.array([0.0, 0.2])
    F, T = force_twist_map(gait, gait.times, V, w)
    assert F.shape == (64, 2, 2) and T.shape == (64, 2)
    avg = averaged_model(gait, samples=64)
    # The averaged set's wrench is the mean over the samples of the instantaneous wrench.
    fa, ta = avg.contacts.wrench(V, w)
    np.testing.assert_allclose(fa, F.mean(axis=0), rtol=0, atol=1e-13)
    np.testing.assert_allclose(ta, T.mean(axis=0), rtol=0, atol=1e-13)
    assert avg.equilibrium.certified


def test_dynamic_cycles_approach_the_quasi_static_motion_for_a_light_body():
    gait = tripod_gait(turn=0.3, load_shift=0.25, samples=120)
    qs = quasi_static_cycle(gait, 120)
    dyn = dynamic_cycles(gait, 0.01, 1e-5, cycles=2, steps_per_cycle=240)
    # A 10 g body (its friction acceleration ~500 m/s^2) tracks the equilibrium within a
    # few steps: the cycle's motion agrees within the two error estimates plus 2 %.
    assert np.hypot(*(dyn.displacement - qs.displacement)) <= dyn.error + qs.error + 0.02 * np.hypot(*qs.displacement)


def test_snake_moves_head_first_and_isotropic_friction_does_not_propel():
    snake = serpenoid(elements=30, samples=48, ratio=3.0)
    cycle = quasi_static_cycle(snake, 48)
    assert cycle.displacement[0] < -0.05          # towards the head (-x), several cm per cycle
    assert abs(cycle.displacement[1]) < 1e-10 and abs(cycle.rotation) < 1e-10
    iso = quasi_static_cycle(serpenoid(elements=30, samples=48, ratio=1.0), 48)
    # Isotropic Coulomb friction: an undulation in place (no net thrust) to the quadrature error.
    assert abs(iso.displacement[0]) < 1e-3 * abs(cycle.displacement[0]) + 2 * iso.error


def test_se2_step_closed_form():
    # A quarter turn at unit speed: radius 1/omega, displacement (r, r).
    w = np.pi / 2
    np.testing.assert_allclose(se2_step(np.array([1.0, 0.0]), w, 1.0), [1 / w, 1 / w, w], rtol=1e-15)
    np.testing.assert_allclose(se2_step(np.array([0.3, -0.2]), 0.0, 2.0), [0.6, -0.4, 0.0], rtol=1e-15)


def test_gait_input_is_checked():
    with pytest.raises(ParameterError, match="'times' parameter of Gait must increase within"):
        Gait(1.0, [0.0, 1.0], np.zeros((2, 1, 2)), np.zeros((2, 1, 2)), np.ones((2, 1)))
    with pytest.raises(ParameterError, match="'loads' parameter of Gait"):
        Gait(1.0, [0.0, 0.5], np.zeros((2, 1, 2)), np.zeros((2, 1, 2)), np.array([[1.0], [0.0]]))
    with pytest.raises(ParameterError, match="'duty' parameter of tripod_gait"):
        tripod_gait(duty=0.4)
