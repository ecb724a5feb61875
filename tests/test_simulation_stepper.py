"""Tests of :func:`toolkit.simulation.advance`: stepping the exact engine sample by sample.

References: one exact ``simulate`` run of the same command schedule (the same engine, so
agreement to rounding, ``rtol = 1e-12`` with ``atol = 1e-12 * 0.35 m/s`` for speeds that
cross zero), a high-accuracy quadrature of the exact dense output for the displacements, and
the closed form of a first-order lag for the contacts.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from scipy import integrate

from toolkit import ContactSet, Motors, PiecewiseConstant, Plant
from toolkit.errors import ParameterError
from toolkit.model.carousel import CAROUSEL, carousel_startup_plant
from toolkit.simulation import ExactState, SimulationStatus, advance, simulate
from toolkit.simulation._exact import _motor_speeds

RTOL = 1e-12
ATOL = 1e-12 * 0.35         # 1e-12 relative to the carousel's speed scale, m/s
DT = 0.02                   # s, the carousel's 50 Hz sample period


def _schedule(rng: np.random.Generator, n: int, steps: int, hold: int) -> np.ndarray:
    """Commands of ``steps`` periods, each value held for ``hold`` periods: shape (steps, n)."""
    values = rng.uniform(-0.35, 0.35, (steps // hold + 1, n))
    return np.repeat(values, hold, axis=0)[:steps]


def _step_through(plant: Plant, commands: np.ndarray, external: float = 0.0):
    """Step ``plant`` through ``commands`` from rest, motors settled on the first command."""
    state = ExactState.initial(_scheduled(plant, commands))
    states, steps = [state], []
    for k, command in enumerate(commands):
        step = advance(plant, state, command, (k + 1) * DT, external=external)
        assert step.status is SimulationStatus.SUCCESS
        state = step.state
        states.append(state)
        steps.append(step)
    return states, steps


def _scheduled(plant: Plant, commands: np.ndarray, external: float = 0.0) -> Plant:
    times = DT * np.arange(1, commands.shape[0])
    return dataclasses.replace(plant, commands=PiecewiseConstant(times, commands),
                               external_force=external)


@pytest.mark.parametrize("case", ["lag", "lag+rate", "rate", "ideal", "drag+force"])
def test_stepping_equals_one_simulate_run(case: str) -> None:
    rng = np.random.default_rng(7)
    plant = dataclasses.replace(carousel_startup_plant(3), motors=CAROUSEL.motors())
    external = 0.0
    if case == "lag+rate":
        plant = dataclasses.replace(plant, motors=Motors(lag=0.0075, rate_limit=20.0,
                                                         speed_limits=(-0.35, 0.35)))
    elif case == "rate":
        plant = dataclasses.replace(plant, motors=Motors(rate_limit=20.0))
    elif case == "ideal":
        plant = dataclasses.replace(plant, motors=None)
    elif case == "drag+force":
        plant = dataclasses.replace(plant, damping=0.3)
        external = 0.1
    commands = _schedule(rng, plant.n, 100, hold=5)          # 2 s, a switch every 0.1 s
    states, _ = _step_through(plant, commands, external)
    times = np.array([s.t for s in states])
    reference = simulate(_scheduled(plant, commands, external), times[-1], t_eval=times)
    assert reference.success
    np.testing.assert_allclose([s.V for s in states], reference.V, rtol=RTOL, atol=ATOL)
    if plant.dynamic_motors:    # (ideal contacts jump at t1: simulate reports the new command)
        np.testing.assert_allclose(np.array([s.contact_speeds for s in states]),
                                   reference.contact_speeds, rtol=RTOL, atol=ATOL)


def test_constant_commands_from_rest_equal_one_run() -> None:
    plant = dataclasses.replace(carousel_startup_plant(0), motors=CAROUSEL.motors())
    commands = np.tile(plant.contacts.speeds, (150, 1))      # 3 s, motors settled throughout
    states, steps = _step_through(plant, commands)
    times = np.array([s.t for s in states])
    reference = simulate(plant, times[-1], t_eval=times)
    np.testing.assert_allclose([s.V for s in states], reference.V, rtol=RTOL, atol=ATOL)
    assert [e.kind for step in steps for e in step.events] == [
        e.kind for e in reference.events]


def test_displacements_equal_a_quadrature_of_the_exact_speed() -> None:
    # quad with every event and command time as a breakpoint integrates a smooth closed form
    # on each piece: epsabs 1e-15 m, epsrel 1e-13. Tolerance: 1e-12 relative to the distance
    # scale 0.35 m/s * DT plus that quadrature error.
    rng = np.random.default_rng(11)
    plant = dataclasses.replace(carousel_startup_plant(5), motors=CAROUSEL.motors(),
                                damping=0.2)
    commands = _schedule(rng, plant.n, 50, hold=3)
    states, steps = _step_through(plant, commands, external=-0.05)
    scheduled = _scheduled(plant, commands, -0.05)
    reference = simulate(scheduled, states[-1].t)
    kinks = np.array(sorted({e.time for e in reference.events}))
    for k, step in enumerate(steps):
        t0, t1 = states[k].t, states[k + 1].t
        inside = kinks[(kinks > t0) & (kinks < t1)]
        distance, error = integrate.quad(reference.speed_at, t0, t1,
                                         points=inside if inside.size else None,
                                         epsabs=1e-15, epsrel=1e-13, limit=200)
        assert step.body_displacement == pytest.approx(distance, rel=0,
                                                       abs=1e-12 * 0.35 * DT + 1e-15 + error)
        # The contacts: their exact tracks (smooth inside a step: a lag, no rate limit).
        tracks, errors = integrate.quad_vec(
            lambda t: _motor_speeds(scheduled, np.array([t]))[0], t0, t1, epsabs=1e-15,
            epsrel=1e-13)
        np.testing.assert_allclose(step.contact_displacements, tracks, rtol=0,
                                   atol=1e-12 * 0.35 * DT + 1e-15 + errors)


def test_unsettled_motor_displacement_is_the_lag_closed_form() -> None:
    # v = u + (v0 - u) exp(-t / tau), int_0^T v dt = u T + (v0 - u) tau (1 - exp(-T / tau)).
    tau = 0.0075
    plant = Plant(ContactSet([-0.2, 0.05, 0.3], [1.0, 1.0, 1.0]), mass=1.0,
                  motors=Motors(lag=tau))
    v0 = np.array([-0.3, 0.25, 0.0])
    u = np.array([0.1, -0.15, 0.3])
    state = ExactState(0.0, 0.12, v0)
    step = advance(plant, state, u, DT)
    decay = math.exp(-DT / tau)
    np.testing.assert_allclose(step.state.contact_speeds, u + (v0 - u) * decay,
                               rtol=RTOL, atol=1e-16)
    np.testing.assert_allclose(step.contact_displacements,
                               u * DT + (v0 - u) * tau * -math.expm1(-DT / tau),
                               rtol=RTOL, atol=1e-18)


def test_bad_inputs_are_refused() -> None:
    plant = dataclasses.replace(carousel_startup_plant(0), motors=CAROUSEL.motors())
    state = ExactState.initial(plant)
    with pytest.raises(ParameterError, match="'command' parameter of advance"):
        advance(plant, state, np.zeros(3), DT)
    with pytest.raises(ParameterError, match="'t1' parameter of advance"):
        advance(plant, state, np.zeros(plant.n), 0.0)
    with pytest.raises(ParameterError, match="'stuck' parameter of ExactState"):
        ExactState(0.0, 0.0, np.zeros(2), stuck=5)


# -- the certified no-event shortcut --------------------------------------------------------
def _closed_loop_plant(case: str) -> tuple[Plant, float]:
    plant = dataclasses.replace(carousel_startup_plant(2), motors=CAROUSEL.motors())
    if case == "lag+rate":      # gaps up to 0.08 m/s stay below r tau = 0.15 m/s: no ramp...
        plant = dataclasses.replace(plant, motors=Motors(lag=0.0075, rate_limit=20.0,
                                                         speed_limits=(-0.35, 0.35)))
    elif case == "lag+slow-rate":   # ... here r tau = 0.0075 m/s: many steps ramp (fallback)
        plant = dataclasses.replace(plant, motors=Motors(lag=0.0075, rate_limit=1.0,
                                                         speed_limits=(-0.35, 0.35)))
    elif case == "drag+force":
        return dataclasses.replace(plant, damping=0.3), 0.05
    return plant, 0.0


@pytest.mark.parametrize("case", ["lag", "lag+rate", "lag+slow-rate", "drag+force"])
def test_quiet_steps_equal_the_full_engine(case: str, monkeypatch: pytest.MonkeyPatch) -> None:
    # A closed loop's commands: near the body speed (so the body sticks to contacts and
    # contacts cross it), changing a little every step, or held for many steps while the
    # body stays stuck. From each state the step runs twice: with the certified shortcut
    # (when it applies) and with the full engine forced. Both evaluate the same closed forms
    # (V0 + r0 expm1_ratio(lam, S) free, v_k(S) stuck; u + (v0 - u) exp(-S/tau) per motor;
    # their integrals), with sums possibly in another order: rtol 1e-12, atol 1e-12 of the
    # speed scale 0.35 m/s (of 0.35 m/s * DT for displacements).
    from toolkit.simulation import _stepper

    plant, external = _closed_loop_plant(case)
    rng = np.random.default_rng(2024)
    state = ExactState(0.0, 0.0, np.clip(rng.uniform(-0.3, 0.3, plant.n), -0.35, 0.35))
    command = state.contact_speeds.copy()
    quiet = {True: 0, False: 0}           # shortcut taken, by stuck
    for k in range(600):
        phase = (k // 40) % 3
        if phase == 0:                    # changing: pulled towards the body speed
            command = np.clip(state.V + 0.6 * (command - state.V)
                              + rng.normal(0.0, 0.02, plant.n), -0.35, 0.35)
        elif phase == 1:                  # changing: a random walk, spread out again
            command = np.clip(command + rng.normal(0.0, 0.03, plant.n), -0.35, 0.35)
        # (phase 2: held)
        t1 = (k + 1) * DT
        monkeypatch.setattr(_stepper, "_QUIET", True)
        fast = advance(plant, state, command, t1, external=external)
        monkeypatch.setattr(_stepper, "_QUIET", False)
        full = advance(plant, state, command, t1, external=external)
        assert not full.shortcut
        if fast.shortcut:
            quiet[state.stuck is not None] += 1
            assert full.events == ()
            assert full.success and fast.success
            assert fast.state.stuck == full.state.stuck
            assert fast.state._pending == full.state._pending
            assert fast.message == full.message
        np.testing.assert_allclose(fast.state.V, full.state.V, rtol=RTOL, atol=ATOL)
        np.testing.assert_allclose(fast.state.contact_speeds, full.state.contact_speeds,
                                   rtol=RTOL, atol=ATOL)
        np.testing.assert_allclose(fast.body_displacement, full.body_displacement,
                                   rtol=RTOL, atol=ATOL * DT)
        np.testing.assert_allclose(fast.contact_displacements, full.contact_displacements,
                                   rtol=RTOL, atol=ATOL * DT)
        assert fast.state.t == full.state.t == t1
        assert not fast.state.contact_speeds.flags.writeable
        assert not fast.contact_displacements.flags.writeable
        state = full.state
    if case == "lag+slow-rate":
        assert 0 < quiet[True] + quiet[False] < 600, quiet
    else:                                 # the shortcut serves both kinds of quiet step
        assert quiet[True] >= 50 and quiet[False] >= 50, quiet


def test_quiet_steps_chain_like_the_engine(monkeypatch: pytest.MonkeyPatch) -> None:
    # 60 s of 50 Hz stepping with and without the shortcut: the same trajectory (rounding
    # differences of single steps do not grow: the tolerances of the per-step comparison).
    from toolkit.simulation import _stepper

    plant = dataclasses.replace(carousel_startup_plant(4), motors=CAROUSEL.motors())
    rng = np.random.default_rng(5)
    commands = np.clip(np.cumsum(rng.normal(0.0, 0.01, (3000, plant.n)), axis=0)
                       + rng.uniform(-0.2, 0.2, plant.n), -0.35, 0.35)
    runs = {}
    for flag in (True, False):
        monkeypatch.setattr(_stepper, "_QUIET", flag)
        state = ExactState(0.0, 0.0, commands[0])
        V, travel, quiet, modes, events = [], [], 0, [], []
        for k, command in enumerate(commands):
            step = advance(plant, state, command, (k + 1) * DT)
            state = step.state
            V.append(state.V)
            travel.append(step.body_displacement)
            quiet += step.shortcut
            modes.append(state.stuck)
            events.extend((e.kind, e.contact) for e in step.events)
        runs[flag] = np.array(V), np.array(travel), quiet, modes, events
    # (the walk clips several contacts to one speed limit: the stuck-group case is taken too)
    assert runs[True][2] > 1500 and runs[False][2] == 0
    np.testing.assert_allclose(runs[True][0], runs[False][0], rtol=RTOL, atol=ATOL)
    np.testing.assert_allclose(runs[True][1], runs[False][1], rtol=RTOL, atol=ATOL * DT)
    assert runs[True][3] == runs[False][3]
    assert runs[True][4] == runs[False][4]


def test_quiet_certificate_bounds_an_interior_approach(monkeypatch: pytest.MonkeyPatch) -> None:
    # The body (V = 0.1 s under 0.5 - 0.4 N, m = 1 kg) and contact 0 lagging from -0.002 m/s
    # towards u: the gap g(s) = 0.002 + 0.1 s - (u + 0.002)(1 - exp(-s / tau)) has its
    # minimum inside the step (s* = tau log(e / 0.1), e = (u + 0.002) / tau), below zero
    # for u above about 0.002 m/s, while g(DT) > 0 for u below about 0.0023 m/s: there the
    # contact crosses the body and back inside the step with both ends of the gap positive.
    # The certificate must see that minimum: the shortcut is never taken on a step with
    # events, and agrees with the engine on the others (tolerances: as in
    # test_quiet_steps_equal_the_full_engine).
    from toolkit.simulation import _stepper

    plant = Plant(ContactSet([-0.002, 0.5], [0.4, 0.5]), mass=1.0, motors=Motors(lag=0.0075))
    state = ExactState(0.0, 0.0, np.array([-0.002, 0.5]))
    decay = math.exp(-DT / 0.0075)
    taken = ends_apart_with_events = 0
    for u in np.linspace(0.0, 0.003, 301):
        command = np.array([u, 0.5])
        monkeypatch.setattr(_stepper, "_QUIET", True)
        fast = advance(plant, state, command, DT)
        monkeypatch.setattr(_stepper, "_QUIET", False)
        full = advance(plant, state, command, DT)
        if full.events and 0.1 * DT > u + (-0.002 - u) * decay:
            ends_apart_with_events += 1
        if fast.shortcut:
            taken += 1
            assert full.events == ()
        np.testing.assert_allclose(fast.state.V, full.state.V, rtol=RTOL, atol=ATOL)
        np.testing.assert_allclose(fast.body_displacement, full.body_displacement,
                                   rtol=RTOL, atol=ATOL * DT)
        np.testing.assert_allclose(fast.contact_displacements, full.contact_displacements,
                                   rtol=RTOL, atol=ATOL * DT)
    assert taken > 100 and ends_apart_with_events > 5, (taken, ends_apart_with_events)
