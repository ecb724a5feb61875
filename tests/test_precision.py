"""Work-precision report: errors, flags, speedup and the rational reference."""

from __future__ import annotations

import itertools
import json
import math
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest

from toolkit.errors import ParameterError
from toolkit.model import ContactSet, Plant
import toolkit.analysis.precision as precision
from toolkit.model.carousel import CAROUSEL_ACCELERATION, carousel_startup_plant
from toolkit.analysis.precision import (MethodSetting, PrecisionReport, default_settings, exact_speedup,
                               precision_report, rational_trajectory, work_precision_curves)
from toolkit.scenes.spec import load_scene
from toolkit.scenes.build import build_scene
from toolkit.simulation import Budget, SimulationStatus, simulate
from toolkit.simulation._exact import _LANDSCAPES


@pytest.fixture(scope="module")
def carousel() -> Plant:
    return carousel_startup_plant(seed=7)


@pytest.fixture(scope="module")
def quick_report(carousel: Plant) -> PrecisionReport:
    return precision_report(carousel, 5.0, repeats=1, settings=default_settings(quick=True))


def test_carousel_plant_matches_the_paper_numbers(carousel: Plant) -> None:
    speeds = carousel.contacts.speeds
    assert carousel.n == 11 and np.all(np.abs(speeds) <= 0.35)
    assert carousel.contacts.total_force / carousel.mass == pytest.approx(CAROUSEL_ACCELERATION,
                                                                          rel=1e-15)
    np.testing.assert_array_equal(carousel_startup_plant(seed=7).contacts.speeds, speeds)


def test_startup11_design_is_the_benchmark_scene() -> None:
    # designs/startup11.toml lets the CLI reproduce `python -m toolkit.bench precision`.
    scene = load_scene(Path(__file__).parents[1] / "designs" / "startup11.toml")
    plant, reference = build_scene(scene).plant, carousel_startup_plant(seed=0)
    np.testing.assert_array_equal(plant.contacts.speeds, reference.contacts.speeds)
    np.testing.assert_array_equal(plant.contacts.forces, reference.contacts.forces)
    assert (plant.mass, plant.damping, plant.motors, plant.commands) == (1.0, 0.0, None, None)
    assert (scene.simulation.t_end, scene.simulation.v0) == (5.0, 0.0)


def test_rational_trajectory_closed_forms() -> None:
    # Startup from rest to the median of three contacts, F = +-1 N plateaus, m = 2 kg:
    # V = t/2 up to the contact at 0.1 (t = 0.2 s), where it sticks (|G| = 1 <= W = 1).
    plant = Plant(ContactSet([-1.0, 0.1, 2.0]), mass=2.0)
    times = np.array([0.0, 0.1, 0.2, 0.3, 10.0])
    np.testing.assert_array_equal(rational_trajectory(plant, 0.0, times),
                                  [0.0, 0.05, 0.1, 0.1, 0.1])
    # Even N from rest below the band: stops at the first edge it reaches (-0.35), stays.
    band = Plant(ContactSet([-0.35] * 2 + [0.35] * 2), mass=1.0)
    np.testing.assert_array_equal(rational_trajectory(band, -1.0, [0.0, 0.1625, 1.0]),
                                  [-1.0, -0.35, -0.35])
    with pytest.raises(ParameterError, match="'plant' parameter of rational_trajectory"):
        rational_trajectory(Plant(ContactSet([0.0]), mass=1.0, damping=1.0), 0.0, [1.0])


def test_rational_trajectory_crossing_times_are_exact_fractions() -> None:
    # Below every contact the force is F = 0.1 + 0.2 + 0.3 summed exactly (the doubles'
    # rational values, not the double 0.6), so V(t) = F t / m rounded once: compare bit for bit.
    plant = Plant(ContactSet([0.3, 0.7, 0.9], [0.1, 0.2, 0.3]), mass=0.7)
    force = Fraction(0.1) + Fraction(0.2) + Fraction(0.3)
    t = 0.2
    value = rational_trajectory(plant, 0.0, [t])[0]
    assert value == float(force / Fraction(0.7) * Fraction(t))
    assert force != Fraction(0.6)


def test_exact_row_is_exact_and_references_are_measured(quick_report: PrecisionReport) -> None:
    exact = quick_report.row("exact")
    assert exact.status is SimulationStatus.SUCCESS
    assert exact.max_error <= 1e-12
    radau = quick_report.row("radau")
    # tanh with eps = 1e-4: the smoothed solution lags the Coulomb one by about eps near each
    # contact speed; the error is between 0.1 eps and 10 eps.
    assert 1e-5 <= radau.max_error <= 1e-3
    moreau = quick_report.row("moreau")
    # First order: error below one step's speed change, h F_tot/m = 1e-3 * 2.
    assert 0 < moreau.max_error <= 2e-3
    assert moreau.final_error == 0.0                      # sticks exactly at the median
    for row in quick_report.rows:
        assert row.wall_time > 0 and math.isfinite(row.wall_time)


def test_moreau_error_includes_the_kink_between_steps() -> None:
    # Startup of three unit contacts at -1, 0.1, 2 m/s, m = 2 kg: V = a t with a = 1/2 m/s^2
    # up to the kink t* = 0.2 s, then V = 0.1 (it sticks). Implicit Euler with h = 0.08 s is
    # exact at its steps (V_k = a k h = 0.04 k until it sticks at 0.1 at t = 0.24 s), so an
    # error measured at its own steps is 0. Between the steps t_k = 0.16 and 0.24 it reports
    # the chord; the report's times include the event time t*, where the chord is below the
    # kink by a d (1 - d / h) with d = t* - t_k = h / 2: a h / 4 = 0.01 m/s, the largest gap
    # (both are linear on each side of t*). rtol 1e-12: a few roundings of values of order 0.1.
    plant = Plant(ContactSet([-1.0, 0.1, 2.0]), mass=2.0)
    settings = (MethodSetting("exact"), MethodSetting("moreau", {"step": 0.08}))
    report = precision_report(plant, 1.0, repeats=1, settings=settings)
    a, h, d = 0.5, 0.08, 0.04
    moreau = simulate(plant, 1.0, method="moreau", step=h)
    truth = rational_trajectory(plant, 0.0, moreau.t)
    assert np.max(np.abs(moreau.V - truth)) <= 1e-16            # exact at its own steps
    assert report.row("moreau").max_error == pytest.approx(a * d * (1 - d / h), rel=1e-12, abs=0)
    assert report.row("exact").max_error <= 1e-16


def test_sign_rk45_stalls_and_chatters(quick_report: PrecisionReport) -> None:
    rk45 = quick_report.row("rk45")
    assert rk45.stalled and rk45.status in (SimulationStatus.WALL_TIME, SimulationStatus.MAX_STEPS)
    assert rk45.chattering
    assert rk45.final_error == math.inf
    assert not quick_report.row("moreau").chattering
    assert not quick_report.row("exact").chattering


def test_to_dict_is_json(quick_report: PrecisionReport) -> None:
    data = json.loads(json.dumps(quick_report.to_dict()))
    assert [row["method"] for row in data["rows"]] == ["exact", "rk45", "radau", "moreau", "casadi"]
    for row in data["rows"]:
        assert {"method", "setting", "max_error", "final_error", "wall_time", "status"} <= set(row)
    assert data["rows"][1]["final_error"] is None         # inf: the stalled run never got there


def test_curves_and_speedup_are_consistent(quick_report: PrecisionReport) -> None:
    curves = {curve.method: curve for curve in work_precision_curves(quick_report)}
    assert set(curves) == {"exact", "rk45", "radau", "moreau", "casadi"}
    for curve in curves.values():
        assert np.all(np.diff(curve.wall_time) >= 0)
    speedup = exact_speedup(quick_report, error=1e-2)
    accurate = [row for row in quick_report.rows
                if row.method != "exact" and row.status is SimulationStatus.SUCCESS and row.max_error <= 1e-2]
    fastest = min(accurate, key=lambda row: row.wall_time)
    assert speedup.reference is fastest
    assert speedup.ratio == pytest.approx(fastest.wall_time / speedup.exact.wall_time, rel=1e-15)
    assert math.isnan(exact_speedup(quick_report, error=1e-30).ratio)


def test_creep_flag_fires_for_tanh_not_for_exact_or_moreau() -> None:
    # Even N: zero-force band (-0.35, 0.35). From V = 0.2 the exact solution stays put; the tanh
    # model pulls the body toward the middle of the band (the contacts at +-0.35 no longer
    # cancel: the force is f (tanh((0.35 - V)/eps) - tanh((0.35 + V)/eps)) != 0 for V != 0).
    plant = Plant(ContactSet([-0.35] * 5 + [0.35] * 5), mass=1.0)
    settings = (MethodSetting("exact"), MethodSetting("moreau", {"step": 1e-2}),
                MethodSetting("radau", {"friction": "tanh", "epsilon": 0.3}),
                MethodSetting("radau", {"friction": "tanh", "epsilon": 1e-3}))
    report = precision_report(plant, 20.0, v0=0.2, repeats=1, settings=settings)
    flags = [row.creep for row in report.rows]
    assert flags[:3] == [False, False, True]
    # eps = 1e-3: tanh(0.15/1e-3) = 1 - 2e-130: the pull is below rounding, no creep visible.
    assert flags[3] is False


def test_settings_are_validated() -> None:
    with pytest.raises(ParameterError, match="Did you mean"):
        simulate(carousel_startup_plant(), 1.0, method="rk45", rtoll=1e-3)
    with pytest.raises(ParameterError, match="'method' parameter of MethodSetting"):
        MethodSetting("euler")
    setting = MethodSetting("moreau", {"step": 1e-3}, Budget(wall_time=1.0))
    assert setting.kwargs == {"step": 1e-3}
    with pytest.raises(ParameterError, match="'repeats' parameter"):
        precision_report(carousel_startup_plant(), 1.0, repeats=0)


def test_timing_runs_repeats_round_robin_from_scratch(monkeypatch) -> None:
    # The call log of the timing loop, with simulate replaced by an instant fake: each
    # setting runs once (+ one warm call when it succeeded), then `repeats` rounds visit the
    # successful settings in order, each with its own batch size; a failed run is never
    # repeated, and every call starts with the exact method's cache of the plant empty.
    plant = carousel_startup_plant(seed=1)
    log: list[tuple[str, int]] = []

    def fake_simulate(plant_, t_end, *, v0, method, t_eval, budget, **options):
        log.append((method, len(_LANDSCAPES.get(plant_, {}))))
        _LANDSCAPES.setdefault(plant_, {})[b"fake"] = True   # what a warm cache would keep
        return type("Result", (), {"success": method != "rk45"})()

    monkeypatch.setattr(precision, "simulate", fake_simulate)
    settings = [MethodSetting("exact"), MethodSetting("rk45"), MethodSetting("moreau")]
    timings = precision._timed(plant, 1.0, 0.0, settings, 3, np.linspace(0.0, 1.0, 5))
    assert all(cached == 0 for _, cached in log)
    runs = [(method, len(list(group))) for method, group in
            itertools.groupby(method for method, _ in log)]
    assert runs[:3] == [("exact", 2), ("rk45", 1), ("moreau", 2)]
    rounds = runs[3:]
    assert [method for method, _ in rounds] == ["exact", "moreau"] * 3
    assert len({count for method, count in rounds if method == "exact"}) == 1   # one batch size
    assert len(timings) == 3 and all(wall > 0 for _, wall in timings)
