"""Planar simulation: the sliding-spinning disc, the exact 1-D reduction, Moreau-Jean steps."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import toolkit as tk
from toolkit.errors import ParameterError
from toolkit.planar import (DiscRegion, PlanarContactSet, PlanarPlant, RingRegion, simulate_planar,
                            terminal_ratio)

ROOT = Path(tk.__file__).resolve().parents[1]
G = 9.81


def _disc_plant(R=0.1, m=1.0, mu=0.3, resolution=12, kind="disc"):
    region = DiscRegion(R, mu * m * G) if kind == "disc" else RingRegion(R, mu * m * G)
    inertia = 0.5 * m * R * R if kind == "disc" else m * R * R
    return PlanarPlant(region, m, inertia, resolution=resolution)


# -- the sliding, spinning disc ----------------------------------------------------------------
def test_pure_slide_and_pure_spin_stop_at_their_closed_form_times():
    R, mu = 0.1, 0.3
    plant = _disc_plant(R, mu=mu)
    slide = tk.simulate(plant, 2.0, v0=[1.2, 0.0])
    np.testing.assert_allclose(slide.stop_time, 1.2 / (mu * G), rtol=1e-15)
    spin = tk.simulate(plant, 2.0, omega0=20.0)
    # A uniform disc spinning in place: torque (2/3) mu m g R, I = m R^2 / 2: t = 3 R w0 / (4 mu g).
    np.testing.assert_allclose(spin.stop_time, 3 * R * 20.0 / (4 * mu * G), rtol=1e-15)
    ring = tk.simulate(_disc_plant(R, mu=mu, kind="ring"), 2.0, omega0=20.0)
    np.testing.assert_allclose(ring.stop_time, R * 20.0 / (mu * G), rtol=1e-15)


@pytest.mark.parametrize("start", [(1.0, 2.0), (1.0, 30.0), (0.2, 80.0)])
def test_disc_stops_sliding_and_spinning_together_at_the_terminal_ratio(start):
    v0, w0 = start
    plant = _disc_plant()
    run = tk.simulate(plant, 5.0, v0=[v0, 0.0], omega0=w0)
    assert run.stop_time is not None and run.stop_time < 5.0
    ratio = run.terminal_ratio
    # The reduced ODE's ratio converges to the fixed point of F = 2 eps T (Brent, 1e-15).
    np.testing.assert_allclose(ratio, terminal_ratio(), rtol=0, atol=1e-10)
    t = np.linspace(0, run.stop_time * (1 - 1e-9), 200)
    dense = simulate_planar(plant, 5.0, v0=[v0, 0.0], omega0=w0, t_eval=t)
    speed, rim = dense.speed, np.abs(dense.omega) * 0.1
    assert np.all(speed > 0) and np.all(rim > 0)            # neither stops before the other
    eps = speed / rim
    # eps moves monotonically towards eps* (docs/planar.md section 4).
    assert np.all(np.diff(np.abs(eps - terminal_ratio())) <= 1e-12)
    # The motion is a straight line along the initial velocity (no lateral force).
    assert np.all(dense.position[:, 1] == 0.0)


def test_moreau_converges_to_the_exact_disc():
    plant = _disc_plant(resolution=24)
    t = np.linspace(0, 0.4, 41)
    exact = tk.simulate(plant, 1.0, v0=[1.0, 0.0], omega0=10.0, t_eval=t)
    errors = []
    for h in (4e-3, 2e-3, 1e-3):
        run = tk.simulate(plant, 1.0, v0=[1.0, 0.0], omega0=10.0, t_eval=t, method="moreau", step=h)
        errors.append(max(np.max(np.abs(run.speed - exact.speed)), 0.1 * np.max(np.abs(run.omega - exact.omega))))
        assert run.solve_error < 1e-6
    # First order in h once above the quadrature error (24 rings: ~2e-4 relative).
    assert errors[0] > errors[1] > errors[2]
    assert errors[-1] < 5e-3


def test_moreau_dissipates_energy_and_stops():
    plant = _disc_plant(resolution=8)
    run = tk.simulate(plant, 2.0, v0=[0.8, 0.3], omega0=-15.0, method="moreau", step=2e-3)
    energy = 0.5 * plant.mass * run.speed ** 2 + 0.5 * plant.inertia * run.omega ** 2
    assert np.all(np.diff(energy) <= 1e-15)
    assert run.stop_time is not None and np.all(run.velocity[-1] == 0) and run.omega[-1] == 0


# -- the exact 1-D reduction ---------------------------------------------------------------------
@pytest.mark.parametrize("n", [3, 4, 10, 11])
def test_line_plant_is_the_1d_simulation_exactly(n):
    rng = np.random.default_rng(n)
    for scale in (1e-2, 1.0, 1e2):
        speeds = rng.uniform(-0.35, 0.35, n) * scale
        forces = rng.uniform(0.2, 2.0, n)
        if n == 10:
            speeds = np.array([-0.35] * 5 + [0.35] * 5) * scale     # the zero-force band
        line = tk.ContactSet(speeds, forces)
        positions = rng.normal(size=n)
        planar = PlanarContactSet.on_line(line, positions=positions)      # on the x axis: through the centre of mass
        plant = PlanarPlant(planar, 2.0, 0.7, external_force=(0.1 * scale, 0.0))
        v0 = 0.2 * scale
        run = tk.simulate(plant, 3.0, v0=[v0, 0.0])
        ref = tk.simulate(tk.Plant(line, 2.0, external_force=0.1 * scale), 3.0, v0=v0)
        assert np.array_equal(run.t, ref.t) and np.array_equal(run.velocity[:, 0], ref.V)
        assert np.all(run.velocity[:, 1] == 0) and np.all(run.omega == 0)
        # The planar Moreau-Jean step solves the same implicit step as the 1-D one: both exact,
        # the planar one to its certified gap (about 1e-15 of the speeds here).
        mo = tk.simulate(plant, 3.0, v0=[v0, 0.0], method="moreau", step=1e-2)
        mo1 = tk.simulate(tk.Plant(line, 2.0, external_force=0.1 * scale), 3.0, v0=v0, method="moreau", step=1e-2)
        np.testing.assert_allclose(mo.velocity[:, 0], mo1.V, rtol=0, atol=1e-12 * scale)


def test_zero_force_band_coasts_in_moreau_and_creeps_when_smoothed():
    line = tk.ContactSet([-0.35] * 5 + [0.35] * 5)
    plant = PlanarPlant(PlanarContactSet.on_line(line, positions=np.linspace(-1, 1, 10)), 1.0, 1.0)
    mo = tk.simulate(plant, 1.0, v0=[0.2, 0.0], method="moreau", step=1e-2)
    assert np.all(mo.velocity[:, 0] == 0.2)
    sm = tk.simulate(plant, 1.0, v0=[0.2, 0.0], method="smooth", epsilon=0.05, solver="Radau")
    assert abs(sm.velocity[-1, 0] - 0.2) > 1e-3       # the regularized law drifts to the middle


def test_planar_options_and_refusals():
    plant = PlanarPlant(PlanarContactSet([[1, 0], [0, 1], [-1, -1]], [[0.1, 0], [0, 0.2], [0, 0]]), 1.0, 1.0)
    with pytest.raises(ParameterError, match="closed form"):
        tk.simulate(plant, 1.0)
    with pytest.raises(ParameterError, match="options"):
        tk.simulate(plant, 1.0, method="moreau", epsilon=1.0)
    with pytest.raises(ParameterError, match="'v0' parameter of simulate must be a 2-vector"):
        tk.simulate(plant, 1.0, v0=[1.0, 2.0, 3.0], method="moreau")
    run = tk.simulate(plant, 1.0, method="moreau", step=0.01)
    assert run.success and run.t.size == 101


def test_one_dimensional_use_never_imports_the_planar_package():
    code = ("import sys, toolkit as tk\n"
            "r = tk.simulate(tk.Plant(tk.ContactSet([-0.2, 0.1, 0.3]), 1.0), 1.0)\n"
            "r2 = tk.simulate(tk.Plant(tk.ContactSet([-0.2, 0.1, 0.3]), 1.0), 1.0, method='moreau')\n"
            "import json; print(json.dumps([m for m in sys.modules if m.startswith('toolkit.planar')]))\n")
    env = {k: v for k, v in os.environ.items()}
    env["PYTHONPATH"] = str(ROOT)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env,
                         check=True, cwd=ROOT)
    assert json.loads(out.stdout.strip().splitlines()[-1]) == []


def test_disc_shape_series_continues_the_closed_forms_and_has_their_limits():
    # For k = |W| / (R |omega|) >= 2 the shape functions are the closed forms' series in 1/k^2
    # (40 terms, error < 1e-24 at k = 2): at k = 2 and 3 the closed forms lose at most k^4 eps
    # (about 2e-14) to cancellation, hence atol 5e-14 there; far out F -> 1 and k T -> 1/4
    # (the fast-sliding disc), to rounding.
    from toolkit.planar.regions import _disc_shape

    e = 2.0 * (1 - 1e-15)
    below, above = _disc_shape(np.array([e, 2.0, 3.0 - 1e-13, 3.0]))
    assert abs(below[0] - below[1]) <= 5e-14 and abs(above[0] - above[1]) <= 5e-14
    assert abs(below[2] - below[3]) <= 5e-14 and abs(above[2] - above[3]) <= 5e-14
    F, T = _disc_shape(np.array([1e4, 1e8]))
    np.testing.assert_allclose(F, 1.0, rtol=0, atol=1e-8)        # 1 - F ~ (1/8) / k^2
    np.testing.assert_allclose(T * np.array([1e4, 1e8]), 0.25, rtol=1e-8)


def test_a_fast_puck_and_a_tiny_step_end_within_their_budgets():
    # A puck at 100 m/s took 260 s before the series (the closed forms' noise at k = 88 held
    # DOP853 at rtol 1e-13); now it stops at t_end, still sliding: its speed fell by the
    # kinetic deceleration mu g F with F = 1 to 1e-4 at this k, so atol 2e-3 m/s over 1.5 s.
    plant = PlanarPlant(DiscRegion(0.038, 0.2 * 0.17 * 9.81), 0.17, 0.17 * 0.038 ** 2 / 2)
    fast = simulate_planar(plant, 1.5, v0=[100.0, 0.0], omega0=30.0)
    assert fast.success and fast.stop_time is None and fast.terminal_ratio is None
    assert abs(np.hypot(*fast.velocity[-1]) - (100.0 - 0.2 * 9.81 * 1.5)) <= 2e-3
    # A step of 1e-12 s over 1.5 s (1.5e12 steps) builds only the budget's grid and stops there.
    tiny = simulate_planar(plant, 1.5, v0=[2.0, 0.0], omega0=30.0, method="moreau", step=1e-12,
                           budget=tk.Budget(max_steps=200))
    assert not tiny.success and tiny.t[-1] <= 200 * 1e-12 * (1 + 1e-9)
    with pytest.raises(ParameterError, match="'v0'"):
        simulate_planar(plant, 1.5, v0=[1e300, 0.0], omega0=30.0)
