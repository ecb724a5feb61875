"""Budgets on every path of ``simulate``: each method (1-D and planar) and each region type,
driven to its worst inputs under small step budgets, stops with a budget status within them;
the thin ring's shape functions near eps = 1 against a second quadrature."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from scipy.integrate import IntegrationWarning, quad

import toolkit as tk
from toolkit.planar import (CurveRegion, DiscRegion, PlanarContactSet, PlanarPlant, RingRegion,
                            terminal_ratio)
from toolkit.planar.regions import _ring_shape
from toolkit.simulation import METHODS, Budget, SimulationStatus

G = 9.81
STOPPED = (SimulationStatus.MAX_STEPS, SimulationStatus.ZENO)


# -- 1-D: every method ------------------------------------------------------------------------
def _chattering_plant() -> tk.Plant:
    """200 contacts of unequal magnitudes with motor lag, the body started beyond them all:
    the sign law chatters at the weighted median, the smoothed laws are stiff (slope
    f / epsilon), the exact engine meets an event at every crossing."""
    rng = np.random.default_rng(7)
    contacts = tk.ContactSet(np.linspace(-0.35, 0.35, 200), rng.uniform(0.1, 3.0, 200))
    return tk.Plant(contacts, mass=0.05, motors=tk.Motors(lag=0.01))


# method -> (options, counted units allowed by Budget(max_steps=K)); the exact engine counts
# rounds (two events each), the others evaluations or steps (docs of each method).
_ONE_D = {"exact": {}, "rk45": {"friction": "sign"}, "lsoda": {"friction": "sign"},
          "radau": {"friction": "tanh", "epsilon": 1e-9}, "bdf": {"friction": "stribeck", "epsilon": 1e-9},
          "moreau": {"step": 1e-9}, "casadi": {"friction": "tanh", "epsilon": 1e-9}}


def test_every_one_d_method_is_listed():
    assert set(_ONE_D) == set(METHODS)


@pytest.mark.parametrize("method", sorted(_ONE_D))
@pytest.mark.parametrize("max_steps", [3, 40])
def test_one_d_methods_stop_within_a_small_step_budget(method, max_steps):
    plant = _chattering_plant()
    run = tk.simulate(plant, 50.0, v0=2.0, method=method, budget=Budget(max_steps=max_steps),
                      **_ONE_D[method])
    assert run.status in STOPPED, run.message
    assert run.t_final < 50.0
    # Whatever a method counts (evaluations, steps, rounds), it stopped at the budget: the
    # counter it reports never exceeds it by more than the unit in progress.
    counted = {"exact": run.n_steps, "moreau": run.n_steps, "casadi": run.n_steps}.get(method, run.n_evaluations)
    assert counted <= max_steps + 1, run


# -- planar: every method and region ----------------------------------------------------------
def _region(kind: str):
    R, force = 0.038, 0.2 * 0.17 * G
    if kind == "disc":
        return DiscRegion(R, force)
    if kind == "annulus":
        return DiscRegion(R, force, inner_radius=0.9 * R)           # near-degenerate: a thin annulus
    if kind == "ring":
        return RingRegion(R, force)
    if kind == "curve":
        theta = np.linspace(0, 2 * np.pi, 9)
        return CurveRegion(np.c_[R * np.cos(theta), R * np.sin(theta)], force / (2 * np.pi * R))
    # 60 contacts on one line through the centre of mass (the 1-D exact reduction), unequal
    x = np.linspace(-R, R, 60)
    return PlanarContactSet(np.c_[x, 0 * x], np.c_[np.linspace(-0.3, 0.3, 60), 0 * x],
                            np.random.default_rng(3).uniform(0.1, 2.0, 60))


def _planar(kind: str) -> PlanarPlant:
    mass, R = 0.17, 0.038
    return PlanarPlant(_region(kind), mass, mass * R * R, resolution=8 if kind != "line" else None)


# The worst starts: a rim speed equal to the sliding speed (eps = 1 exactly, where the ring's
# K diverges), and for the line a start far from the median (many crossings).
_START = {"line": dict(v0=[2.0, 0.0])}
_RIM = dict(v0=[30.0 * 0.038, 0.0], omega0=30.0)
_PLANAR_CASES = ([("exact", kind) for kind in ("line", "disc", "annulus", "ring")]
                 + [("moreau", kind) for kind in ("line", "disc", "annulus", "ring", "curve")]
                 + [("smooth", kind) for kind in ("line", "disc", "annulus", "ring", "curve")])
_PLANAR_OPTIONS = {"exact": {}, "moreau": {"step": 1e-9}, "smooth": {"epsilon": 1e-12, "solver": "RK45"}}


def test_every_planar_method_is_covered():
    from toolkit.planar import PLANAR_METHODS

    assert {method for method, _ in _PLANAR_CASES} == set(PLANAR_METHODS)


@pytest.mark.parametrize("method, kind", _PLANAR_CASES)
def test_planar_methods_stop_within_a_small_step_budget(method, kind):
    plant = _planar(kind)
    budget = Budget(max_steps=12)
    run = tk.simulate(plant, 1.5, method=method, budget=budget, **_START.get(kind, _RIM),
                      **_PLANAR_OPTIONS[method])
    assert run.status in STOPPED, run.message
    assert run.t[-1] < 1.5
    # As in 1-D: at most the budget and the unit in progress (the exact engine's n_steps
    # counts the segment it stopped in).
    assert run.steps <= budget.max_steps + 1, run.message


def test_sliding_spinning_thin_ring_finishes_at_its_terminal_ratio():
    # The case that ran past 240 s: near eps = 1 the elliptic parameter rounded to 1.
    ring = PlanarPlant(RingRegion(radius=0.038, force=0.2 * 0.17 * G), mass=0.17,
                       inertia=0.17 * 0.038 ** 2)
    run = tk.simulate(ring, 1.5, v0=[2.0, 0.0], omega0=30.0)
    assert run.status is SimulationStatus.SUCCESS, run.message
    assert run.stop_time is not None and run.stop_time < 1.5
    # With I = m R^2 the terminal ratio solves F(eps) = eps T(eps): eps* = 1 exactly (F(1) =
    # T(1) = 2/pi); the reduced ODE stops at w = w0 e^-80 with its rtol 1e-13 on eps.
    np.testing.assert_allclose(run.terminal_ratio, 1.0, rtol=0, atol=1e-12)
    np.testing.assert_allclose(terminal_ratio("ring"), 1.0, rtol=0, atol=1e-15)
    # A second method: Moreau-Jean steps of h = 2 ms on 64 arcs stop within a few steps of it
    # (first order in h; the arcs' wrench error is far smaller).
    h = 2e-3
    stepped = tk.simulate(PlanarPlant(ring.contacts, ring.mass, ring.inertia, resolution=64), 1.5,
                          v0=[2.0, 0.0], omega0=30.0, method="moreau", step=h)
    assert abs(stepped.stop_time - run.stop_time) <= 3 * h


def _ring_by_quadrature(eps: float) -> tuple[float, float]:
    """F and T of the thin ring as averages over its angle (a second method): the slip at
    angle theta = pi/2 + phi is (eps - cos phi, -sin phi) in units of R omega; near eps = 1
    it nearly vanishes at phi = 0, over a width d = |1 - eps|, resolved by phi = d sinh(u)."""
    d = abs(1.0 - eps)

    def force(phi):
        return -(np.cos(phi) - eps) / np.hypot(np.sin(phi), np.cos(phi) - eps)

    def torque(phi):
        return (1 - eps * np.cos(phi)) / np.hypot(np.sin(phi), np.cos(phi) - eps)

    values = []
    for f in (force, torque):
        with warnings.catch_warnings():      # "roundoff error is detected": tolerances at rounding
            warnings.simplefilter("ignore", IntegrationWarning)
            integral = quad(lambda u: f(d * np.sinh(u)) * d * np.cosh(u), 0.0, np.arcsinh(np.pi / d),
                            epsabs=1e-16, epsrel=1e-15, limit=1000)[0]
        values.append(integral / np.pi)              # twice the half-circle, over 2 pi
    return values[0], values[1]


@pytest.mark.parametrize("gap", [1e-2, 1e-5, 1e-8, 3e-9, 1e-11, 1e-14])
@pytest.mark.parametrize("side", [-1.0, 1.0])
def test_ring_shape_functions_near_eps_one_against_quadrature(gap, side):
    eps = 1.0 + side * gap
    F, T = _ring_shape(np.array(eps))
    F_num, T_num = _ring_by_quadrature(eps)
    # Both to rounding: the closed form's terms are O(1) with K = O(ln(1/gap)) times gap, the
    # quadrature's requested 1e-15; observed differences stay below 4e-15.
    np.testing.assert_allclose([F, T], [F_num, T_num], rtol=0, atol=2e-14)


def test_ring_shape_functions_are_continuous_through_eps_one():
    # The doubles nearest 1 (1 -+ 1.1e-16, 2.2e-16) and 1 itself, where F = T = (2/pi) E(1) =
    # 2/pi; the (1 - eps) ln|1 - eps| term is 4e-15 there, the rest rounding.
    eps = np.array([1 - 2.0 ** -53, 1.0, 1 + 2.0 ** -52])
    F, T = _ring_shape(eps)
    np.testing.assert_allclose(F, 2 / np.pi, rtol=0, atol=1e-14)
    np.testing.assert_allclose(T, 2 / np.pi, rtol=0, atol=1e-14)
