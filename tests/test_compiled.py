"""Tests of the compiled kernels (toolkit/_compiled): one source, compiled or run as Python.

``make test`` runs this module twice: compiled (the tests' default, see conftest.py) and once
more under ``NUMBA_DISABLE_JIT=1``, where numba hands back the very same functions
uncompiled. Every test asserts numbers from a closed form, an identity or a second method;
``test_python_source_gives_the_compiled_numbers`` compares the two runs of the source.
"""

from __future__ import annotations

import json
import math
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import toolkit
from toolkit import _compiled
from toolkit._compiled import core
from toolkit.model import ContactSet, MotorPiece, Motors, PiecewiseConstant, Plant, motor_rate
from toolkit.simulation import (ExactState, SimulationStatus, advance, simulate,
                                simulate_batch, _stepper)

EPS = float(np.finfo(float).eps)
ROOT = Path(toolkit.__file__).resolve().parents[1]
JIT = os.environ.get("NUMBA_DISABLE_JIT", "0") in ("", "0")


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(20251123)


def _clean_env(**extra: str) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items()
           if k not in ("ACTIVE_CONTACTS_COMPILE", "NUMBA_DISABLE_JIT", "NUMBA_CACHE_DIR")}
    env["PYTHONPATH"] = str(ROOT)
    env.update(extra)
    return env


def test_kernels_are_compiled_unless_disabled():
    # The tests' default is eager compilation (conftest.py); NUMBA_DISABLE_JIT=1 hands back
    # the Python functions themselves (numba's own switch), the same source.
    module = _compiled.load("core")
    assert (module is core) == JIT
    assert "core" in _compiled.loaded()
    assert hasattr(core.ideal_piece, "py_func") == JIT


# -- the check of requested times -------------------------------------------------------------
def _numpy_ordered_within(times: np.ndarray, t_end: float) -> bool:
    """The NumPy rule simulate() applies before the kernels are compiled."""
    return bool(bool((times[1:] >= times[:-1]).all()) and times[0] >= 0 and times[-1] <= t_end)


def test_ordered_within_is_the_numpy_rule(rng):
    # Second method: the NumPy expression, on sorted grids, ties, one time, and every kind of
    # defect (a step back, NaN, +-inf, out of [0, t_end]) at the start, middle and end.
    grid = np.sort(rng.uniform(0.0, 5.0, 1003))
    cases = [grid, np.array([0.0]), np.array([5.0]), np.array([-0.0, 0.0, 5.0]),
             np.repeat(grid[::100], 3), np.linspace(0.0, 5.0, 1004)]
    for position in (0, 1, 500, 1002):
        for bad in (np.nan, np.inf, -np.inf, -1e-300, 5.0 + 1e-12, grid[position] - 1e-9):
            times = grid.copy()
            times[position] = bad
            cases.append(times)
    cases.append(grid[::-1].copy())
    for times in cases:
        for writeable in (True, False):            # two numba specializations
            times = times.copy()
            times.setflags(write=writeable)
            assert bool(core.ordered_within(times, 5.0)) == _numpy_ordered_within(times, 5.0)
    assert core.ordered_within(grid, 5.0) and not core.ordered_within(grid, 4.0)


def test_simulate_refuses_the_same_times_with_and_without_the_kernel(monkeypatch):
    # simulate() checks t_eval with the compiled kernel once the process has it, with NumPy
    # before: the same refusals and the same message either way.
    import toolkit.simulation as simulation

    plant = Plant(ContactSet([-0.2, 0.1, 0.3]), 1.0)
    bad = [[0.5, 0.2], [0.5, 2.0], [-0.1, 0.5], [0.0, np.nan, 0.5], [0.0, np.inf]]
    messages = []
    for kernel in (True, False):
        if not kernel:
            monkeypatch.setattr(simulation, "compiled", lambda name: None)
        found = []
        for times in bad:
            with pytest.raises(toolkit.errors.ParameterError) as info:
                simulate(plant, 1.0, t_eval=np.array(times))
            found.append(str(info.value))
        good = simulate(plant, 1.0, t_eval=np.array([0.0, 0.0, 0.5, 1.0]))
        np.testing.assert_array_equal(good.t, [0.0, 0.0, 0.5, 1.0])
        messages.append(found)
    assert messages[0] == messages[1]


# -- the Coulomb force ---------------------------------------------------------------------------
@pytest.mark.parametrize("n, m", [(1, 5), (7, 1), (40, 3000), pytest.param(2000, 50_000, marks=pytest.mark.slow)])
def test_coulomb_force_is_the_definition(rng, n, m):
    # Second method: the definition sum_i f_i sign(v_i - V) as an n x m broadcast. Speeds on
    # a grid of 1/64 m/s and forces in halves make every sum exact in binary, so the two must
    # agree exactly; queries hit the contact speeds (ties: sign(0) = 0), lie between them,
    # outside them and at +-inf; some contacts share a speed, some are lifted (f = 0).
    speeds = rng.integers(-40, 40, n) / 64.0
    forces = rng.integers(0, 6, n) / 2.0
    forces[0] = 1.0
    V = np.concatenate((rng.integers(-50, 50, m) / 64.0, rng.integers(-50, 50, m) / 128.0,
                        [np.inf, -np.inf]))
    got = ContactSet(speeds, forces).force(V)
    with np.errstate(invalid="ignore"):
        expected = np.sign(speeds[:, None] - V[None, :]).T @ forces
    np.testing.assert_array_equal(got, expected)


def test_coulomb_force_keeps_the_shape_and_snaps_cancelling_sums():
    # Identity: 0.1 + 0.2 against 0.3 cancels to within the prefix sums' rounding, and the
    # force there is exactly 0 (ContactSet.tie_tolerance), not 5.6e-17.
    contacts = ContactSet([-1.0, -1.0, 1.0], [0.1, 0.2, 0.3])
    assert contacts.force(0.0).shape == ()
    assert float(contacts.force(0.0)) == 0.0
    assert contacts.force(np.zeros((2, 3))).shape == (2, 3)


def test_bucket_index_handles_clustered_levels(rng):
    # Levels bunched in one bucket (1e5 contacts within 1e-9 m/s, one far away) make the
    # bucket search a binary search inside one bucket: the same numbers as the definition.
    speeds = np.concatenate((1e-9 * rng.random(999), [5.0]))
    forces = np.ones(1000)
    V = np.concatenate((1e-9 * rng.random(2000), [0.0, 1e-9, 2.5, 5.0, 6.0]))
    expected = np.sign(speeds[:, None] - V[None, :]).T @ forces
    np.testing.assert_array_equal(ContactSet(speeds, forces).force(V), expected)


# -- the event loop, dense output and batch ----------------------------------------------------
def test_single_contact_startup_is_the_closed_form():
    # Closed form: one contact at v = 0.3 with f = 2 N on m = 4 kg from rest accelerates at
    # f/m = 0.5 m/s^2, reaches v at t = 0.6 s and sticks; with drag c = 1 N s/m it approaches
    # the balance V* = f/c = 2 m/s (> v, so it still reaches v) along
    # V(t) = V* (1 - exp(-c t/m)), t_hit = -m/c log(1 - v/V*). rtol 4 eps: a few roundings.
    result = simulate(Plant(ContactSet([0.3], [2.0]), 4.0), 1.0,
                      t_eval=np.array([0.0, 0.2, 0.6, 1.0]))
    np.testing.assert_allclose(result.V, [0.0, 0.1, 0.3, 0.3], rtol=4 * EPS, atol=0)
    np.testing.assert_allclose(result.force, [2.0, 2.0, 0.0, 0.0], rtol=4 * EPS, atol=0)
    assert [(e.kind, e.contact) for e in result.events] == [("stick", 0)]
    assert result.events[0].time == pytest.approx(0.6, rel=4 * EPS, abs=0)
    drag = simulate(Plant(ContactSet([0.3], [2.0]), 4.0, damping=1.0), 2.0,
                    t_eval=np.array([0.1, 0.4]))
    np.testing.assert_allclose(drag.V, 2.0 * -np.expm1(-np.array([0.1, 0.4]) / 4.0),
                               rtol=8 * EPS, atol=0)
    assert drag.events[0].time == pytest.approx(-4.0 * np.log1p(-0.15), rel=8 * EPS, abs=0)


def test_batch_gains_external_force_drag_and_masses_per_scene(rng):
    # Second method: each scene through simulate() of its own Plant (mass, drag, external
    # force, start speed): the same kernel, so the same numbers; 1e-12 is the bound.
    scenes, n = 300, 7
    speeds = rng.uniform(-0.35, 0.35, (scenes, n))
    forces = rng.uniform(0.0, 0.15, (scenes, n))
    forces[:, 0] = 0.1
    speeds[:, 1] = speeds[:, 2]                             # coincident contacts
    mass = rng.uniform(0.2, 2.0, scenes)
    damping = rng.choice([0.0, 0.3], scenes)
    external = rng.uniform(-0.2, 0.2, scenes)
    v0 = rng.uniform(-0.5, 0.5, scenes)
    batch = simulate_batch(speeds, forces, mass, 3.0, v0=v0, damping=damping,
                           external=external)
    assert batch.success
    for s in range(scenes):
        single = simulate(Plant(ContactSet(speeds[s], forces[s]), mass[s], damping=damping[s],
                                external_force=external[s]), 3.0, v0=v0[s])
        assert batch.final_speeds[s] == pytest.approx(single.V[-1], rel=1e-12, abs=1e-300)
        assert batch.n_events[s] == single.n_events
        assert batch.stuck[s] == (single.events[-1].kind == "stick"
                                  if single.events else False)


def test_batch_external_force_closed_form():
    # Closed form: F_ext = 0.5 N beside one contact at 0.1 m/s with f = 1 N pushes the body
    # (m = 1 kg) from rest at 1.5 m/s^2 up to the contact, where |G| = 0.5 <= W = 1: it sticks
    # at 0.1; with F_ext = 1.5 N > W it passes and moves on at 0.5 m/s^2: at t = 1,
    # V = 0.1 + 0.5 (1 - 0.1/2.5) = 0.58.
    batch = simulate_batch([[0.1], [0.1]], None, 1.0, 1.0, external=[0.5, 1.5])
    np.testing.assert_allclose(batch.final_speeds, [0.1, 0.58], rtol=4 * EPS, atol=0)
    assert batch.stuck.tolist() == [True, False]


def test_dense_output_is_the_closed_form_at_any_times():
    # Closed form of a piecewise schedule (speed steps at 1 s): V rises at 1 m/s^2 to 0.5
    # (t = 0.5), sticks, then after the switch to 1.5 rises again from t = 1 to 1.5 at t = 2.
    plant = Plant(ContactSet([0.5]), 1.0, commands=PiecewiseConstant([1.0], [[0.5], [1.5]]))
    result = simulate(plant, 3.0)
    times = np.array([2.5, 0.25, 1.5, 0.75, 3.0, 1.0])       # any order
    np.testing.assert_allclose(result.speed_at(times), [1.5, 0.25, 1.0, 0.5, 1.5, 0.5],
                               rtol=4 * EPS, atol=0)


def test_quiet_certificate_agrees_with_the_engine(rng):
    # Second method: every 20 ms step through the certified no-event kernel and through the
    # full engine (the shortcut off); rtol 1e-12: the two evaluate the same closed forms.
    plant = Plant(ContactSet(rng.uniform(-0.3, 0.3, 6)), 0.5,
                  motors=Motors(lag=0.01, speed_limits=(-0.35, 0.35)))
    commands = np.clip(rng.uniform(-0.3, 0.3, 6) + np.cumsum(rng.normal(0, 0.01, (100, 6)),
                                                             axis=0), -0.35, 0.35)
    fast = slow = ExactState(0.0, 0.0, commands[0])
    quiet = 0
    for k in range(100):
        step = advance(plant, fast, commands[k], 0.02 * (k + 1))
        quiet += step.shortcut
        _stepper._QUIET = False
        try:
            reference = advance(plant, slow, commands[k], 0.02 * (k + 1))
        finally:
            _stepper._QUIET = True
        assert step.state.V == pytest.approx(reference.state.V, rel=1e-12, abs=1e-15)
        np.testing.assert_allclose(step.contact_displacements, reference.contact_displacements,
                                   rtol=1e-12, atol=1e-15)
        assert step.body_displacement == pytest.approx(reference.body_displacement,
                                                       rel=1e-12, abs=1e-15)
        fast, slow = step.state, reference.state
    assert quiet > 50                                      # the shortcut was exercised


def test_buffers_grow_and_budgets_stop_inside_the_kernel():
    # 2001 contacts crossed one by one from below: 2000 crossings and a stick, far more rows
    # than the first buffers hold (they double while the kernel pauses); a budget of 100
    # rounds stops the same run with MAX_STEPS and keeps its partial, exact trajectory.
    n = 2001
    contacts = ContactSet(np.linspace(-1.0, 1.0, n), np.full(n, 1.0 / n))
    whole = simulate(Plant(contacts, 1.0), 20.0, v0=-1.5)
    assert whole.success and whole.n_events == (n - 1) // 2 + 1
    from toolkit.simulation import Budget
    cut = simulate(Plant(contacts, 1.0), 20.0, v0=-1.5, budget=Budget(max_steps=100))
    assert cut.status is SimulationStatus.MAX_STEPS
    assert cut.n_events == 100
    np.testing.assert_array_equal(cut.t[:50], whole.t[:50])


# -- the event roots of the dynamic-motor engine ----------------------------------------------
def _first_root(alpha, beta, gamma, delta, lam, mu, D=0.0, horizon=1.5):
    """core.first_root on float arrays (through load: under NUMBA_DISABLE_JIT the source runs
    as Python inside np.errstate, as the engine calls it)."""
    as_array = [np.atleast_1d(np.asarray(c, dtype=float)) for c in (alpha, beta, gamma, delta)]
    s, i = _compiled.load("core").first_root(*as_array, lam, mu, D, horizon)
    return float(s), int(i)


@pytest.mark.parametrize("mu", [1.0, 10.0, 133.3, 1e3, 1e100, 1e300])
def test_first_root_of_an_exponential_crossing_a_line_is_the_lambert_w_closed_form(mu):
    # A body braking at 1 m/s^2 (no drag) 0.7 m/s above a contact whose motor decelerates
    # with rate mu: g(s) = 0.7 - s - 0.5 mu expm1_ratio(mu, s) = A - s + B exp(-mu s) with
    # A = 0.2, B = 0.5. Closed form: s = A + W(B mu exp(-mu A)) / mu (Lambert W, principal
    # branch; its argument underflows to 0 from mu = 1e3 on: then s = A). Function 0 never
    # changes sign. rtol 8 eps: Newton's stopping rule (a step <= 4 eps relative) plus the
    # rounding of g near its root and of the closed form (two terms of one sign, no
    # cancellation); atol 0.
    from scipy.special import lambertw

    A, B = 0.7 - 0.5, 0.5
    argument = B * mu * math.exp(-mu * A) if mu * A < 700 else 0.0
    expected = A + float(lambertw(argument).real) / mu
    s, i = _first_root([0.3, 0.7], [0.0, -1.0], [0.0, 0.0], [0.0, -0.5 * mu], 0.0, mu)
    assert i == 1
    assert s == pytest.approx(expected, rel=8 * EPS, abs=0)


@pytest.mark.parametrize("mu", [1.0, 133.3, 1e6])
def test_first_root_with_drag_and_motor_terms_matches_brentq(rng, mu):
    # g decreasing (beta, gamma, delta < 0: g' < 0) from g(0) > 0 with a root inside the
    # horizon: two exponential terms (drag lam = 20 /s and the motor's mu), so the kernel
    # polishes with Brent's method after bracketing. Second method: scipy's brentq on the
    # whole horizon with the same tolerances (xtol the smallest subnormal, rtol 4 eps). rtol
    # 8 eps: each result lies within brentq's 4 eps of the true root; atol: g is evaluated
    # with a rounding error of a few eps times the size of its terms, which fixes its root
    # only to that error over |g'| (8 eps sum|terms| / |g'| at the root).
    from scipy.optimize import brentq

    lam, found = 20.0, 0
    for _ in range(40):
        alpha = rng.uniform(0.01, 0.5)
        beta, gamma, delta = -rng.uniform(0.0, 1.0), -rng.uniform(0.1, 1.0), -rng.uniform(0.1, 1.0) * mu
        g = lambda s: (alpha + beta * s + gamma * -math.expm1(-lam * s) / lam      # noqa: E731
                       + delta * -math.expm1(-mu * s) / mu)
        if g(1.5) >= 0:
            continue
        found += 1
        expected = brentq(g, 0.0, 1.5, xtol=math.ulp(0.0), rtol=4 * EPS, maxiter=500)
        s, i = _first_root(alpha, beta, gamma, delta, lam, mu)
        terms = (abs(alpha) + abs(beta * s) + abs(gamma * -math.expm1(-lam * s) / lam)
                 + abs(delta * -math.expm1(-mu * s) / mu))
        slope = abs(beta + gamma * math.exp(-lam * s) + delta * math.exp(-mu * s))
        assert i == 0
        assert s == pytest.approx(expected, rel=8 * EPS, abs=8 * EPS * terms / slope)
    assert found > 10


def test_first_root_prefilter_is_the_search_over_every_function(rng):
    # Identity: with more than core.SMALL functions the kernel searches only those whose
    # bound |g(0)| / sup|g'| falls inside a growing window; the answer must be the earliest
    # root over all of them (core.first_root_all over every row). The same function wins;
    # its root is polished on a bracket cut at the window instead of the horizon: rtol 8 eps
    # (both within a few ulp of the root), atol 0.
    module = _compiled.load("core")
    bits = np.zeros(2)
    for n, lam, mu in [(65, 0.0, 133.3), (300, 20.0, 133.3), (2000, 3.0, 1e4), (500, 0.0, 0.0)]:
        alpha = rng.uniform(-0.3, 0.3, n)
        beta = rng.normal(0.0, 1.0, n)
        gamma = rng.normal(0.0, 1.0, n) if lam > 0 else np.zeros(n)
        delta = rng.normal(0.0, 1.0, n) * max(mu, 1.0)
        for horizon in (1e-3, 0.05, 1.5):
            s, i = module.first_root(alpha, beta, gamma, delta, lam, mu, 0.0, horizon)
            s_all, i_all = module.first_root_all(alpha, beta, gamma, delta, lam, mu, 0.0,
                                                 horizon, np.arange(n), bits,
                                                 bits.view(np.int64))
            assert i == i_all
            assert s == pytest.approx(s_all, rel=8 * EPS, abs=0)
    assert i >= 0                                      # (the widest horizon found a root)


# -- the dynamic-motor engine: the motor law's one compiled form ---------------------------------
@pytest.mark.parametrize("lag, rate", [(0.0075, math.inf), (0.0075, 5.0), (0.0, 3.0),
                                       (0.03, 40.0)])
def test_compiled_motor_piece_is_the_motor_law(rng, lag, rate):
    # The motor law is written in toolkit/model/motors.py (motor_rate, solved by MotorPiece);
    # the engine's kernels hold its one compiled form (core.motor_build, motor_speed,
    # motor_coefficients, motor_displacement). Both on one grid of offsets (through the ramp
    # phases and the approach): speeds and displacements agree to rtol 4 eps (the same
    # operations; NumPy's exp and libm's may differ in the last bit), atol 4 eps times the
    # speed (displacement) scale; the rates of the closed form at each offset are the law's
    # motor_rate at the speeds there (rtol 4 eps: the same division, clipped at the rate
    # limit where rounding puts a settling motor a hair past it).
    module = _compiled.load("core")
    n = 9
    motors = Motors(lag=lag, rate_limit=rate)
    start = rng.uniform(-0.35, 0.35, n)
    u = rng.uniform(-0.35, 0.35, n)
    u[0] = start[0]                                    # a motor already there
    piece = MotorPiece.build(0.0, start, u, lag, rate)
    table = np.empty((5, n))
    module.motor_build(start, u, lag, rate, table)
    for row, values in zip(table, (piece.start, piece.u, piece.ramp, piece.ramp_end,
                                   piece.after)):
        np.testing.assert_array_equal(row, values)
    grid = np.concatenate(([0.0], np.geomspace(1e-5, 0.5, 60), piece.ramp_end))
    v, q, e = np.empty(n), np.empty(n), np.empty(n)
    out = np.empty(n)
    speed_scale, distance_scale = 0.35, 0.35 * 0.5
    for s in grid:
        expected_v, expected_q, expected_e, expected_end = piece.coefficients(float(s))
        phase_end = module.motor_coefficients(table, lag, float(s), v, q, e)
        np.testing.assert_allclose(v, expected_v, rtol=4 * EPS, atol=4 * EPS * speed_scale)
        np.testing.assert_allclose(v, piece.speeds(np.array([s]))[0], rtol=4 * EPS,
                                   atol=4 * EPS * speed_scale)
        np.testing.assert_array_equal(q, expected_q)
        np.testing.assert_allclose(e, expected_e, rtol=4 * EPS, atol=4 * EPS * speed_scale / max(lag, 1e-3))
        assert phase_end == expected_end
        np.testing.assert_allclose(q + e, motor_rate(motors, u, v), rtol=4 * EPS,
                                   atol=4 * EPS * speed_scale / max(lag, 1e-3))
        module.motor_displacement(table, lag, float(s), out)
        np.testing.assert_allclose(out, piece.displacement(float(s)), rtol=4 * EPS,
                                   atol=4 * EPS * distance_scale)


@pytest.mark.parametrize("lag, play, n", [(0.0075, 2e-4, 10), (0.03, 1e-3, 3), (0.002, 5e-5, 25)])
def test_play_take_up_time_is_the_bisection_on_the_motor_law(rng, lag, play, n):
    # core.play_take_up_time (the holds' wait for the gearbox play after a reversal) against a
    # second method: the same bracket and bisection in Python on MotorPiece.displacement (the
    # motor law as written). They agree to atol 1e-12 s: the bisection ends on an interval of
    # bracket / 2^50 (< 1e-15 s here) and the two displacements differ by at most 4 eps
    # (test above), which moves the root by 4 eps * 0.2 m / (0.01 m/s) < 1e-13 s. Checked on the
    # law itself too: at the time found every motor has travelled the play since it turned
    # (to 4 eps of the distances), 1 us earlier one has not.
    module = _compiled.load("core")
    v0 = rng.uniform(0.01, 0.35, n) * rng.choice([-1.0, 1.0], n)
    u = -np.sign(v0) * rng.uniform(0.01, 0.35, n)         # every motor reverses
    turn = lag * np.log((u - v0) / u)
    step = play / float(np.abs(u).min()) + lag
    found = module.play_take_up_time(v0, u, lag, turn, play, step)
    piece = MotorPiece.build(0.0, v0, u, lag, math.inf)
    at_turn = np.array([piece.displacement(float(s))[i] for i, s in enumerate(turn)])

    def taken_up(s):
        return bool(np.all((s >= turn) & (np.abs(piece.displacement(s) - at_turn) >= play)))

    lo = float(turn.max())
    hi = lo + step
    while not taken_up(hi):
        hi += step
    for _ in range(50):
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if taken_up(mid) else (mid, hi)
    assert found == pytest.approx(hi, rel=0.0, abs=1e-12)
    travelled = np.abs(piece.displacement(found) - at_turn)
    assert np.all(found >= turn) and np.all(travelled >= play * (1 - 4 * EPS))
    assert not taken_up(found - 1e-6)


def test_pairwise_sum_is_numpys_sum(rng):
    # The engine's sums are NumPy's own doubles (np.add.reduce on a contiguous float64 array:
    # blocks of 8 partial sums, halved above 128 terms): compared exactly, at every length
    # up to 300 and a few long ones, with terms spread over ten decades (where the order of
    # additions changes the rounding).
    module = _compiled.load("core")
    for n in [*range(0, 300), 1000, 4099, 70001]:
        values = rng.standard_normal(n) * 10.0 ** rng.uniform(-5, 5, n)
        assert module.pairwise_sum(values, 0, n) == float(np.add.reduce(values)), n
    values = rng.standard_normal(500)
    assert module.pairwise_sum(values, 100, 250) == float(np.add.reduce(values[100:350]))


def _numpy_staircase(speeds: np.ndarray, forces: np.ndarray) -> tuple[np.ndarray, float]:
    """The staircase by NumPy's unique, bincount and cumsum (ContactSet's way without the
    kernel): rows levels + inf, below, above; and F_tot as np.sum of the steps."""
    active = forces > 0
    levels, inverse = np.unique(speeds[active], return_inverse=True)
    steps = np.bincount(inverse, weights=forces[active], minlength=levels.size)
    K = levels.size
    table = np.empty((3, K + 1))
    table[0, :K], table[0, K] = levels, np.inf
    table[1, 0] = 0.0
    np.cumsum(steps, out=table[1, 1:])
    table[2, :K], table[2, K] = np.cumsum(steps[::-1])[::-1], 0.0
    return table, float(np.sum(steps))


@pytest.mark.parametrize("n", [1, 3, 7, 8, 9, 10, 17, 64])
def test_contact_table_is_numpys_staircase(rng, n):
    # core.contact_table (what ContactSet builds once the kernels are machine code) against
    # NumPy's unique / bincount / cumsum / sum: exactly equal (the same doubles, the sign of
    # a zero level included), on ties, lifted contacts and magnitudes over six decades
    # (where the order of the additions shows in the last bit), below and above the 8 terms
    # where np.sum starts its partial sums.
    _compiled.load("core")                       # (ContactSet takes the kernel once compiled)
    for trial in range(200):
        if trial % 2:
            speeds = rng.choice([-0.2, -0.1, 0.0, 0.1, 0.3], n)
        else:
            speeds = rng.standard_normal(n)
        forces = 10.0 ** rng.uniform(-3, 3, n) * (rng.random(n) < 0.8)
        forces[rng.integers(n)] = 1.5
        land = np.empty((3, n + 1))
        K, total = core.contact_table(speeds.reshape(1, n), forces.reshape(1, n), np.empty(n, dtype=np.int64),
                                      land, np.empty(n + 1, dtype=np.int64))
        table, total_np = _numpy_staircase(speeds, forces)
        assert K == table.shape[1] - 1
        assert np.array_equal(land[1:, :K + 1], table[1:]) and np.array_equal(land[0, :K], table[0, :K])
        assert np.array_equal(np.signbit(land[0, :K]), np.signbit(table[0, :K]))
        assert total == total_np
        # ContactSet holds the same staircase whichever way built it.
        contacts = ContactSet(speeds, forces)
        assert np.array_equal(contacts._table, table) and contacts.total_force == total_np
    # Both signed zeros among the touching contacts: left to NumPy (whose sort may take the
    # level from either), and ContactSet still builds its staircase.
    speeds, forces = np.array([0.0, 0.2, -0.0]), np.array([1.0, 2.0, 3.0])
    K, _ = core.contact_table(speeds.reshape(1, 3), forces.reshape(1, 3), np.empty(3, dtype=np.int64),
                              np.empty((3, 4)), np.empty(4, dtype=np.int64))
    assert K == -1
    table, total_np = _numpy_staircase(speeds, forces)
    assert np.array_equal(ContactSet(speeds, forces)._table, table)


def test_filippov_acceleration_solves_the_inclusion(rng):
    # core.filippov returns the body's acceleration a among tied contacts moving at rates
    # `slopes`: 0 in G + sum_j w_j Sign(slope_j - a) - m a. Identity check: when the body
    # follows a level, the others' push minus m a lies within that level's stiction (plus the
    # tolerance given); otherwise a is no slope and the equation holds with a single value
    # (to rounding: atol 8 eps times the force scale).
    module = _compiled.load("core")
    tol = 1e-12
    followed = free = 0
    for _ in range(400):
        T = int(rng.integers(1, 7))
        slopes = rng.choice([-2.0, -0.5, 0.0, 0.5, 1.5], T) + (rng.random() < 0.3) * rng.normal(0, 1, T)
        weights = rng.uniform(0.1, 2.0, T)
        G, m = rng.normal(0.0, 3.0), rng.uniform(0.2, 3.0)
        scratch = np.empty((3, T))
        order = np.empty(T, dtype=np.int64)
        a, follows, level = module.filippov(G, slopes, weights, T, m, tol, order, scratch[0],
                                            scratch[1])
        scale = abs(G) + weights.sum() + m * abs(a)
        if follows:
            followed += 1
            assert a == level and np.any(slopes == level)
            here = slopes == level
            residual = G + np.sum(weights[~here] * np.sign(slopes[~here] - a)) - m * a
            assert abs(residual) <= weights[here].sum() + tol + 8 * EPS * scale
        else:
            free += 1
            assert not np.any(slopes == a)
            residual = G + np.sum(weights * np.sign(slopes - a)) - m * a
            assert abs(residual) <= 8 * EPS * scale
    assert followed > 50 and free > 50


# -- one source: compiled and as Python ----------------------------------------------------------
_SCENES = """
import json, numpy as np
from toolkit.model import ContactSet, Motors, PiecewiseConstant, Plant
from toolkit.simulation import ExactState, advance, simulate, simulate_batch
rng = np.random.default_rng(7)
out = {}
speeds = rng.uniform(-0.35, 0.35, 11)
cs = ContactSet(speeds, np.full(11, 2 / 11))
times = np.linspace(0.0, 5.0, 101)
plants = {
    "coulomb": Plant(cs, 1.0),
    "drag_external": Plant(cs, 1.0, damping=0.7, external_force=0.3),
    "compliant": Plant(cs, 1.0, motors=Motors(compliance=0.02)),
    "schedule": Plant(cs, 1.0, commands=PiecewiseConstant([1.0, 2.5],
                                                          [speeds, -speeds, speeds[::-1]])),
    # The dynamic-motor engine: lag and rate limit under a schedule, and compliant lagging
    # motors with drag (every kind of round: free, stuck, released, saturating).
    "lag_rate": Plant(cs, 1.0, damping=0.2, external_force=0.1,
                      motors=Motors(lag=0.0075, rate_limit=5.0, speed_limits=(-0.35, 0.35)),
                      commands=PiecewiseConstant([0.5, 1.0, 2.5],
                                                 [speeds, speeds[::-1], -speeds, speeds])),
    "compliant_lag": Plant(cs, 1.0, damping=0.3,
                           motors=Motors(lag=0.01, compliance=0.02),
                           commands=PiecewiseConstant([1.0, 2.5],
                                                      [speeds, -speeds, speeds[::-1]])),
}
for name, plant in plants.items():
    r = simulate(plant, 5.0, t_eval=times)
    out[name] = [*r.V.tolist(), *r.force.tolist(), *[e.time for e in r.events]]
out["force"] = cs.force(rng.uniform(-0.4, 0.4, 500)).tolist()
b = simulate_batch(rng.uniform(-0.35, 0.35, (50, 10)), rng.uniform(0.05, 0.15, (50, 10)),
                   rng.uniform(0.5, 1.5, 50), 5.0, damping=0.1, external=0.05)
out["batch"] = [*b.final_speeds.tolist(), *b.n_events.tolist()]
lagged = Plant(cs, 1.0, motors=Motors(lag=0.0075, speed_limits=(-0.35, 0.35)))
state = ExactState(0.0, 0.0, speeds)
walk = []
for k in range(60):
    step = advance(lagged, state, np.clip(speeds + 0.01 * np.sin(k + np.arange(11)), -0.35, 0.35),
                   0.02 * (k + 1))
    state = step.state
    walk += [state.V, step.body_displacement]
out["advance"] = walk
print(json.dumps(out))
"""


def _scenes(env: dict[str, str]) -> dict[str, list[float]]:
    done = subprocess.run([sys.executable, "-c", _SCENES], env=env, cwd=ROOT, check=True,
                          capture_output=True, text=True)
    return json.loads(done.stdout)


@pytest.mark.slow
def test_python_source_gives_the_compiled_numbers():
    # The rule: the kernels compiled and the same source as Python (NUMBA_DISABLE_JIT)
    # give the same numbers to 1e-12 relative (they run the same IEEE operations and libm
    # calls, so in practice they agree to the last bit); atol 1e-300 only for exact zeros.
    compiled = _scenes(_clean_env(ACTIVE_CONTACTS_COMPILE="eager"))
    python = _scenes(_clean_env(NUMBA_DISABLE_JIT="1"))
    assert compiled.keys() == python.keys()
    for name in compiled:
        np.testing.assert_allclose(python[name], compiled[name], rtol=1e-12, atol=1e-300,
                                   err_msg=name)


_ROOTS = """
import json, math
import numpy as np
from toolkit import _compiled
from toolkit.model import ContactSet, Motors, Plant
from toolkit.simulation import ExactState, advance
core = _compiled.load("core")
rng = np.random.default_rng(11)
out = []
# Every path of the root finder: one exponential (lam = 0) with Newton's polish, two with
# Brent's, resonance (lam = mu, D != 0), motor rates up to 1e300 (scale-free bisection), the
# prefilter of many functions.
for n, lam, mu, D in [(1, 0.0, 133.3, 0.0), (7, 20.0, 133.3, 0.0), (12, 20.0, 20.0, 0.7),
                      (5, 20.0, 1e300, 0.0), (40, 3.0, 1e10, 0.0), (300, 20.0, 133.3, 0.0)]:
    for horizon in (1e-3, 1.5):
        for _ in range(5):
            alpha = rng.uniform(-0.3, 0.3, n)
            beta = rng.normal(0.0, 1.0, n)
            gamma = rng.normal(0.0, 1.0, n)
            delta = rng.normal(0.0, 1.0, n) * min(mu, 1e3)
            s, i = core.first_root(alpha, beta, gamma, delta, lam, mu, D, horizon)
            out.append([float(s), int(i)])
# The lag transient of the stepper benchmark: six crossings within 1.6 ms.
off = np.linspace(-0.05, 0.05, 10)
plant = Plant(ContactSet(0.2 + off), 5.0, motors=Motors(lag=0.0075))
step = advance(plant, ExactState(5.0, 0.194444, 0.2 + off), -0.1 + off, 5.02)
out += [[e.time, -1 if e.contact is None else e.contact] for e in step.events]
print(json.dumps(out))
"""


@pytest.mark.slow
def test_python_root_finder_gives_the_compiled_roots():
    # The root finder compiled and its source as Python (NUMBA_DISABLE_JIT): the same
    # functions win and their roots agree to rtol 8 eps, the root finder's own precision (a
    # few ulp; they run the same IEEE operations and libm calls, so in practice every root
    # is the same double); atol 0. Cases with no root report (inf, -1) both ways.
    runs = []
    for env in (_clean_env(ACTIVE_CONTACTS_COMPILE="eager"), _clean_env(NUMBA_DISABLE_JIT="1")):
        done = subprocess.run([sys.executable, "-c", _ROOTS], env=env, cwd=ROOT, check=True,
                              capture_output=True, text=True)
        runs.append(np.array(json.loads(done.stdout.replace("Infinity", "1e999"))))
    compiled, python = runs
    np.testing.assert_array_equal(python[:, 1], compiled[:, 1])
    np.testing.assert_allclose(python[:, 0], compiled[:, 0], rtol=8 * EPS, atol=0)
    assert (compiled[:, 1] >= 0).sum() > 30 and (compiled[:, 1] < 0).any()


_LAZY = """
import json, sys
import numpy as np
import toolkit._compiled as C
from toolkit.model import ContactSet, Plant
from toolkit.simulation import simulate
plant = Plant(ContactSet([-0.2, 0.1, 0.3]), 1.0)
first = simulate(plant, 2.0, t_eval=np.linspace(0.0, 2.0, 50))
ContactSet([-0.2, 0.1, 0.3]).force(np.linspace(-1, 1, 100))
before = "numba" in sys.modules
while "core" not in C.loaded():              # keep working until compiling pays
    simulate(plant, 2.0, t_eval=np.linspace(0.0, 2.0, 5000))
after = "numba" in sys.modules
again = simulate(plant, 2.0, t_eval=np.linspace(0.0, 2.0, 50))
print(json.dumps([before, after, C._WORK[0] >= C.COMPILE_AFTER,
                  (first.V == again.V).all().item(), first.events == again.events]))
"""


@pytest.mark.skipif(not JIT, reason="numba is disabled: nothing is compiled")
def test_a_short_run_does_not_load_numba_and_a_long_one_compiles():
    # A process that simulates a little runs the kernels as Python (no numba import, no
    # compile); once its work reaches COMPILE_AFTER it compiles, and its numbers do not
    # change across the switch (the same source, the same operations: compared exactly).
    done = subprocess.run([sys.executable, "-c", _LAZY], env=_clean_env(), cwd=ROOT,
                          check=True, capture_output=True, text=True)
    assert json.loads(done.stdout) == [False, True, True, True, True]


@pytest.mark.skipif(not JIT, reason="numba is disabled: nothing is compiled")
def test_cli_commands_that_do_not_simulate_never_import_numba(tmp_path):
    # The CLI's curve command (no simulation) and a small run: no numba in the process.
    code = (
        "import runpy, sys\n"
        f"sys.argv = ['active-contacts', 'curve', {str(ROOT / 'designs' / 'carousel.toml')!r}]\n"
        "try:\n    runpy.run_module('toolkit.cli', run_name='__main__')\n"
        "except SystemExit:\n    pass\n"
        "print('numba' in sys.modules, file=sys.stderr)\n")
    done = subprocess.run([sys.executable, "-c", code], env=_clean_env(), cwd=tmp_path,
                          check=True, capture_output=True, text=True)
    assert done.stderr.strip().splitlines()[-1] == "False"


_CACHED = ("import toolkit._compiled as C\n"
           "kernel = C.load('core').expm1_ratio\n"
           "value = kernel(2.0, 0.5)\n"
           "print(value, sum(kernel.stats.cache_hits.values()))\n")


@pytest.mark.skipif(not JIT, reason="numba is disabled: nothing is compiled")
def test_numba_cache_dir_holds_the_cache_and_a_fresh_process_loads_it(tmp_path):
    # NUMBA_CACHE_DIR (the fallback for an install whose source directory is not writable):
    # the first process compiles and writes there, the second loads the machine code
    # (a cache hit, no compile) and computes the same number.
    env = _clean_env(ACTIVE_CONTACTS_COMPILE="eager", NUMBA_CACHE_DIR=str(tmp_path / "cache"))
    first = subprocess.run([sys.executable, "-c", _CACHED], env=env, cwd=tmp_path, check=True,
                           capture_output=True, text=True).stdout.split()
    assert list((tmp_path / "cache").rglob("*.nbi"))
    second = subprocess.run([sys.executable, "-c", _CACHED], env=env, cwd=tmp_path, check=True,
                            capture_output=True, text=True).stdout.split()
    # expm1_ratio(2, 0.5) = (1 - e^-1) / 2; rtol 2 eps: one expm1 and one division.
    assert float(first[0]) == pytest.approx(-np.expm1(-1.0) / 2.0, rel=2 * EPS, abs=0)
    assert (first[0], int(first[1])) == (second[0], 0) and int(second[1]) == 1


@pytest.mark.slow
@pytest.mark.skipif(not JIT, reason="numba is disabled: nothing is compiled")
@pytest.mark.skipif(hasattr(os, "geteuid") and os.geteuid() == 0,
                    reason="root writes into read-only directories: nothing to test")
def test_read_only_install_caches_in_the_user_cache_directory(tmp_path):
    # A copy of the package in a read-only directory (as a site-packages may be): numba cannot
    # write beside the source and falls back to the user-wide cache (here NUMBA_CACHE_DIR
    # unset and XDG_CACHE_HOME/HOME pointing into tmp_path); a second process loads from it.
    site = tmp_path / "site"
    shutil.copytree(ROOT / "toolkit", site / "toolkit",
                    ignore=shutil.ignore_patterns("__pycache__", "*.nbi", "*.nbc"))
    for path in sorted(site.rglob("*"), reverse=True):
        path.chmod(0o555 if path.is_dir() else 0o444)
    (site).chmod(0o555)
    home = tmp_path / "home"
    home.mkdir()
    env = _clean_env(ACTIVE_CONTACTS_COMPILE="eager", HOME=str(home),
                     XDG_CACHE_HOME=str(home / ".cache"), PYTHONPATH=str(site),
                     PYTHONDONTWRITEBYTECODE="1")
    code = ("import toolkit._compiled as C, toolkit\n"
            "assert toolkit.__file__.startswith(%r)\n"
            "print(C.load('core').expm1_ratio(2.0, 0.5))\n" % str(site))
    try:
        first = subprocess.run([sys.executable, "-c", code], env=env, cwd=tmp_path,
                               check=True, capture_output=True, text=True)
        cached = list((home / ".cache").rglob("*.nbi"))
        second = subprocess.run([sys.executable, "-c", code], env=env, cwd=tmp_path,
                                check=True, capture_output=True, text=True)
    finally:
        for path in [site, *site.rglob("*")]:
            path.chmod(0o755)
    # expm1_ratio(2, 0.5) = (1 - e^-1) / 2; rtol 2 eps: one expm1 and one division.
    assert float(first.stdout) == pytest.approx(-np.expm1(-1.0) / 2.0, rel=2 * EPS, abs=0)
    assert first.stdout == second.stdout
    assert cached, "no numba cache index written to the user cache directory"


# -- the one weighted median ---------------------------------------------------------------------
def _median_by_hand(speeds, forces, outside=0.0):
    """Second method: sort, add up the magnitudes in exact rational arithmetic, and read the
    first speed whose cumulative magnitude reaches half the total (lo) and the first that
    passes it (hi); the outside force is one more contact at sign(F) inf."""
    from fractions import Fraction

    pairs = [(float(v), Fraction(float(f))) for v, f in zip(speeds, forces) if f > 0]
    if outside != 0.0:
        pairs.append((math.copysign(math.inf, outside), Fraction(abs(float(outside)))))
    pairs.sort(key=lambda p: p[0])
    half = sum(f for _, f in pairs) / 2
    acc, lo = Fraction(0), None
    for v, f in pairs:
        acc += f
        if lo is None and acc >= half:
            lo = v
        if acc > half:
            return lo, v
    raise AssertionError("unreachable: the cumulative sum ends at the total")


@pytest.mark.parametrize("scale", [1e-3, 0.37, 1.0, 41.0, 1e3])
def test_weighted_median_is_the_sorted_cumulative_sum(rng, scale):
    # Unequal weights at several scales (N), speeds with shared values (rounded to 0.1 m/s),
    # lifted contacts (f = 0) and outside forces: the kernel equals the exact-arithmetic
    # median exactly (it picks speeds, so no tolerance), unless a plateau lies within the tie
    # tolerance 4 (K + 1) eps F_tot of zero, which random unequal weights never give.
    from toolkit.model import weighted_median

    for _ in range(60):
        n = int(rng.integers(1, 14))
        forces = scale * rng.uniform(0.05, 1.0, n)
        forces[rng.random(n) < 0.15] = 0.0
        forces[0] = max(forces[0], 0.05 * scale)
        speeds = np.round(rng.normal(0.0, 1.0, (4, n)), 1)
        outside = scale * rng.choice([0.0, 0.2, -0.45, 3.0 * n, -3.0 * n], 4)
        lo, hi = weighted_median(speeds, forces, outside)
        for r in range(4):
            assert (lo[r], hi[r]) == _median_by_hand(speeds[r], forces, outside[r])
            if outside[r] == 0.0:
                assert ContactSet(speeds[r], forces).equilibrium() == (lo[r], hi[r])


@pytest.mark.parametrize("scale", [1e-3, 1.0, 1e3])
def test_weighted_median_ties_are_zero_force_bands(scale):
    from toolkit.model import weighted_median

    # Closed forms. Even equal weights: the band [v_(N/2), v_(N/2+1)] of the sorted speeds.
    speeds = np.array([3.0, -1.0, 0.5, 2.0, -4.0, 1.0])
    lo, hi = weighted_median(speeds, np.full(6, scale))
    assert (lo, hi) == (0.5, 1.0)
    # Odd equal weights: the middle speed, a point.
    assert weighted_median(speeds[:5], np.full(5, scale)) == (0.5, 0.5)
    # 0.1 + 0.2 against 0.3 cancels to within the prefix sums' rounding (5.6e-17 relative):
    # the tie tolerance makes it a band, as ContactSet.equilibrium says.
    forces = scale * np.array([0.1, 0.2, 0.3])
    assert weighted_median([-1.0, -1.0, 1.0], forces) == (-1.0, 1.0)
    assert ContactSet([-1.0, -1.0, 1.0], forces).equilibrium() == (-1.0, 1.0)
    # The outside force as a contact at sign(F) inf: F = F_tot exactly balances the contacts
    # (a band up to +inf), more than F_tot drives the median to +-inf.
    one = np.array([[2.0, 5.0]])
    assert weighted_median(one, [scale, scale], 2.0 * scale) == ([5.0], [np.inf])
    assert weighted_median(one, [scale, scale], -2.5 * scale) == ([-np.inf], [-np.inf])
    # A force of the size of one contact moves the median by one contact: [5, 5] under +1.
    assert weighted_median(one, [scale, scale], 1.0 * scale) == ([5.0], [5.0])
    # No weight at all: the slowest speed twice.
    assert weighted_median([4.0, -2.0], [0.0, 0.0]) == (-2.0, -2.0)


def test_weighted_median_keeps_the_leading_axes_and_refuses_bad_input():
    from toolkit.errors import ParameterError
    from toolkit.model import weighted_median

    speeds = np.arange(24.0).reshape(2, 3, 4)
    lo, hi = weighted_median(speeds, [1.0, 1.0, 1.0, 2.0])
    assert lo.shape == hi.shape == (2, 3)
    np.testing.assert_array_equal(lo, speeds[..., 2])      # 1 + 1 + 1 >= 5 / 2 at the third
    np.testing.assert_array_equal(hi, speeds[..., 2])
    with pytest.raises(ParameterError, match="'forces'"):
        weighted_median(speeds, [1.0, -1.0, 1.0, 1.0])
    with pytest.raises(ParameterError, match="'forces'"):
        weighted_median(speeds, [1.0, 1.0])
    with pytest.raises(ParameterError, match="'speeds'"):
        weighted_median([np.nan, 1.0], [1.0, 1.0])
    with pytest.raises(ParameterError, match="'outside'"):
        weighted_median(speeds, np.ones(4), np.ones(5))


# -- the Kalman filter's step --------------------------------------------------------------------
@pytest.mark.parametrize("scale", [1e-6, 1e-3, 1.0, 1e2])
def test_kalman_step_is_filterpy_predict_then_update(rng, scale):
    # Second method: filterpy's KalmanFilter.predict() then update(z) (the reference the
    # estimator's hot path replaced). Same formulas, products summed in index order where
    # filterpy's BLAS may fuse them: equal to a few rounding errors of the largest entry
    # (atol 1e-13 of it: 2x2 products of ~10 operations, each 1.1e-16 relative; the Joseph
    # form's off-diagonal terms may cancel, hence absolute, not relative).
    from filterpy.kalman import KalmanFilter

    for _ in range(50):
        h = rng.uniform(1e-3, 0.1)
        F = np.array([[1.0, h], [0.0, 1.0]]) if rng.random() < 0.5 else rng.normal(size=(2, 2))
        L = rng.normal(size=(2, 2)) * scale
        P = L @ L.T + 1e-3 * scale**2 * np.eye(2)
        M = rng.normal(size=(2, 2)) * scale * rng.uniform(0.01, 1.0)
        Q = M @ M.T
        R = float(rng.uniform(0.01, 2.0) * scale**2)
        x = rng.normal(size=(2, 1)) * scale
        z = float(rng.normal() * scale)
        kf = KalmanFilter(dim_x=2, dim_z=1)
        kf.x, kf.P, kf.F, kf.Q = x.copy(), P.copy(), F, Q
        kf.H = np.array([[1.0, 0.0]])
        kf.R = np.array([[R]])
        kf.predict()
        prior_x, prior_P = kf.x.copy(), kf.P.copy()
        kf.update(z)
        x_out, P_out, prior = np.empty((2, 1)), np.empty((2, 2)), np.empty(3)
        nis = _compiled.load("core").kalman_step(x, P, F, Q, R, z, x_out, P_out, prior)
        big = max(np.abs(prior_P).max(), np.abs(kf.P).max())
        np.testing.assert_allclose(prior, [prior_x[0, 0], prior_x[1, 0], prior_P[0, 0]], rtol=0,
                                   atol=1e-13 * max(np.abs(prior_x).max(), big))
        np.testing.assert_allclose(x_out, kf.x, rtol=0, atol=1e-13 * np.abs(kf.x).max() + 1e-13 * scale)
        np.testing.assert_allclose(P_out, kf.P, rtol=0, atol=1e-13 * big)
        np.testing.assert_allclose(nis, kf.y.item() ** 2 * kf.SI.item(), rtol=1e-12)
