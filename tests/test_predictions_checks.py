"""The closed-loop prediction checks: measurements, sweeps, the CLI ``predict`` command."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from dataclasses import replace

import numpy as np
import pytest

from toolkit import ContactSet, ParameterError, Plant, Sensors, simulate_closed_loop
from toolkit.cli import main
from toolkit.controllers import FrictionBrake
from toolkit.model import Motors
from toolkit.model.carousel import CAROUSEL as HARDWARE
from toolkit.predictions import (Apparatus, CarryThen, CheckStatus, FrictionFractionProblem, ViscosityProblem,
                                 friction_fraction_check, prediction_checks, viscosity_check)
from toolkit.predictions._measure import (crossing_duration, crossing_time, crossing_time_constant,
                                          exponential_time_constant, proportional_fit, rig_friction,
                                          startup_time_constant)
from toolkit.predictions.viscosity import EQUILIBRIUM_MARGIN, plan_runs
from toolkit.predictions.theory import ONE_MINUS_INV_E, staircase_correction, transition_time

CAROUSEL = Apparatus.carousel()
PERIOD = 0.02   # s, the carousel's 50 Hz


# -- what is read off the samples -------------------------------------------------------------
def test_crossing_time_is_exact_on_a_linear_signal():
    t = np.arange(10) * 0.1
    v = 0.3 - 2.0 * t                                      # crosses -0.5 at t = 0.4
    # Interpolation of a line: rounding only, abs 1e-15 s.
    assert crossing_time(t, v, -0.5, -1.0) == pytest.approx(0.4, rel=0, abs=1e-15)
    assert math.isnan(crossing_time(t, v, -5.0, -1.0))
    assert crossing_duration(t, v, 0.3, -1.5, 0.1) == pytest.approx(0.9, rel=1e-14, abs=0)
    assert crossing_duration(t, v, 0.3, -5.0, 0.1) == math.inf


def test_startup_time_constant_of_a_sampled_exponential():
    # A true exponential sampled finely: the 63.2 % crossing is tau up to the chord's error,
    # (h^2 / 8) |V''| / |V'| = h^2 / (8 tau) at t = tau: 1.25e-7 s for h = 1e-3 s, tau = 1 s.
    # The settled value misses 0.5 e^-20 = 1e-9 m/s, which moves the level by 0.6e-9 m/s and
    # the crossing by 0.6e-9 / (0.5 / e) = 3.4e-9 s: abs 1e-6 s covers both.
    t = np.arange(0.0, 20.0, 1e-3)
    v = 0.2 - 0.5 * np.exp(-t / 1.0)
    tau, settled = crossing_time_constant(t, v, 5)
    assert settled == pytest.approx(0.2, rel=0, abs=2e-9)
    assert tau == pytest.approx(1.0, rel=0, abs=1e-6)
    assert startup_time_constant("crossing_63", t, v, 5) == (tau, settled)


@pytest.mark.parametrize("h", [0.3, 0.05])
def test_least_squares_time_constant_of_a_sampled_exponential(h):
    # The fit's model is the exponential itself with both ends held: on exact samples its
    # error is zero at the true tau (2.5 s), whatever the sampling; only the settled value's
    # miss, 0.5 e^-16 = 5.6e-8 m/s on a 40 s record, moves it: abs 1e-5 s.
    t = np.arange(0.0, 40.0 + h / 2, h)
    v = -0.1 + 0.5 * np.exp(-t / 2.5)
    tau, settled = exponential_time_constant(t, v, 1)
    assert tau == pytest.approx(2.5, rel=0, abs=1e-5)
    assert startup_time_constant("least_squares", t, v, 1) == (tau, settled)
    # Shifted clock: the fit starts at the first sample.
    assert exponential_time_constant(t + 3.0, v, 1)[0] == pytest.approx(tau, rel=1e-9)
    assert math.isnan(exponential_time_constant(t, np.full(t.size, 0.2), 3)[0])
    with pytest.raises(ParameterError, match="'definition' parameter of startup_time_constant"):
        startup_time_constant("exponential", t, v, 1)


def test_proportional_fit_of_exact_and_scattered_data():
    x = np.linspace(1.0, 4.0, 7)
    slope, r2 = proportional_fit(x, 2.5 * x)
    assert slope == pytest.approx(2.5, rel=1e-15) and r2 == pytest.approx(1.0, rel=0, abs=1e-15)
    # y = 2 x + (+-1 alternating): b = 2 + sum(+-x)/sum(x^2); R^2 by its definition.
    y = 2 * x + np.where(np.arange(7) % 2, 1.0, -1.0)
    b = 2 + np.dot(x, y - 2 * x) / np.dot(x, x)
    r2_def = 1 - np.sum((y - b * x) ** 2) / np.sum((y - y.mean()) ** 2)
    assert proportional_fit(x, y) == pytest.approx((b, r2_def), rel=1e-14)
    # y without scatter about its mean: no R^2 to give (nan), the slope still the fit's.
    slope, r2 = proportional_fit([1.0, 2.0, 4.0], [3.0, 3.0, 3.0])
    assert slope == 1.0 and math.isnan(r2)          # 21 / 21 exactly


def test_rig_friction_removes_the_inertia():
    # m dV/dt = F_c + F_rig with F_c = -0.8 N and a rig force held per period: V is exact.
    m, Fc, h = 1.5, -0.8, 0.02
    rig = np.array([0.1, 0.5, 0.9, 0.2, 0.7, 0.4])
    v = np.concatenate(([0.3], 0.3 + np.cumsum((Fc + rig) * h / m)))
    t = np.arange(v.size) * h
    # Exact up to rounding of a few sums: abs 1e-13 N.
    assert rig_friction(t, v, np.append(rig, 0.0), m, 1, 5) == pytest.approx(Fc, rel=0, abs=1e-13)


#: Uneven sample periods (h and 2h alternating, a jittered logger) and scales of mass and
#: force (powers of two: exact) for the readings below.
UNEVEN = np.cumsum([0.0, 0.25, 0.5, 0.25, 0.5, 0.25, 0.5, 0.25])
SCALES = [2.0 ** -20, 1.0, 2.0 ** 20]


@pytest.mark.parametrize("scale", SCALES)
def test_crossing_time_interpolates_between_its_own_samples(scale):
    """On samples at uneven times the crossing is interpolated between the two samples
    around it, each with its own time step: dyadic times and values make it exact. Falling
    through -0.25 scale between t = 1.5 and 1.75 (values 0.5 and -1.5 scale): t = 1.59375.
    Rising through 0.75 scale between t = 0.25 and 0.75 (0 and 2 scale): t = 0.4375.
    A sample exactly at the level is the crossing; a first sample already past it is
    ``times[0]``. Mutants killed: the first period for the sample's own, ``>=`` to ``>``."""
    t = UNEVEN
    down = np.array([3.0, 2.5, 2.0, 1.0, 0.5, -1.5, -2.0, -3.0]) * scale
    assert crossing_time(t, down, -0.25 * scale, -1.0) == 1.59375
    assert crossing_time(t, down, 1.0 * scale, -1.0) == t[3]
    assert crossing_time(t, down, 5.0 * scale, -1.0) == t[0]
    assert crossing_time(t, down, 5.0 * scale, 1.0) != crossing_time(t, down, 5.0 * scale, 1.0)  # nan
    up = np.array([-1.0, 0.0, 2.0, 2.5, 3.0, 3.5, 4.0, 4.5]) * scale
    assert crossing_time(t, up, 0.75 * scale, 1.0) == 0.4375
    assert crossing_time(t, up, 2.0 * scale, 1.0) == t[2]
    # Two samples at the level: the first of them.
    assert crossing_time(t, np.array([3.0, 1.0, 1.0, 0.0]) * scale, 1.0 * scale, -1.0) == t[1]
    # crossing_duration: the swing from 3 to -2.5 (scale) read at 2.5 and -2.0 (margin 0.5),
    # samples at t = 0.25 and 2.25 exactly, scaled to the full swing by 5.5 / 4.5.
    assert crossing_duration(t, down, 3.0 * scale, -2.5 * scale, 0.5 * scale) == (2.25 - 0.25) * 5.5 / 4.5


@pytest.mark.parametrize("mass", SCALES + [3.0])
def test_rig_friction_at_uneven_periods_and_several_masses(mass):
    """``m dV/dt = F_c + F_rig`` with the rig force held over each of uneven periods: the
    speeds are the exact sums, and the contacts' mean force over samples 1..6 is ``F_c`` (the
    sums round at a few eps of the largest term: rtol 1e-12). Forces scale with the mass.
    Mutants killed: the mass dropped from the inertia term, the rig force averaged over
    samples instead of over time."""
    Fc = -0.8 * mass
    rig = np.array([0.1, 0.5, 0.9, 0.2, 0.7, 0.4, 0.3]) * mass
    h = np.diff(UNEVEN)
    v = np.concatenate(([0.3], 0.3 + np.cumsum((Fc + rig) * h / mass)))
    assert rig_friction(UNEVEN, v, np.append(rig, 0.0), mass, 1, 6) == pytest.approx(Fc, rel=1e-12, abs=0.0)
    assert rig_friction(UNEVEN, v, np.append(rig, 0.0), mass, 0, 7) == pytest.approx(Fc, rel=1e-12, abs=0.0)


def test_crossing_time_constant_of_a_piecewise_linear_startup():
    """From 0 to a settled 1 (last two samples): the level ``1 - 1/e = 0.632...`` is crossed
    on the segment from (0.5, 0.5) to (1.0, 0.75), at ``0.5 + (0.632.. - 0.5) * 2`` s,
    measured from ``times[0] = 0.25``; the startup falling from 0 to -1 mirrors it. Mutant
    killed: the clock not shifted to the first sample."""
    t = 0.25 + np.array([0.0, 0.25, 0.5, 1.0, 1.5, 2.0, 3.0])
    v = np.array([0.0, 0.25, 0.5, 0.75, 0.9, 1.0, 1.0])
    level = 1.0 - math.exp(-1.0)
    expected = 0.5 + (level - 0.5) * (0.5 / 0.25)
    tau, settled = crossing_time_constant(t, v, 2)
    assert settled == 1.0
    assert tau == pytest.approx(expected, rel=4 * np.finfo(float).eps, abs=0.0)
    assert crossing_time_constant(t, -v, 2) == (tau, -1.0)
    assert crossing_time_constant(t, v, 3)[1] == pytest.approx(2.9 / 3, rel=1e-15)
    assert math.isnan(crossing_time_constant(t, np.full(7, 0.4), 2)[0])


def test_a_startup_within_rounding_of_its_start_is_unmoved():
    """``|settled - V0| <= 8 eps max|V|`` reads as no startup (nan): from 1 to ``1 - 8 eps``
    is exactly at the bound (max 1), from 1 to ``1 + 9 eps`` is above it (mutants: the factor
    8 to 9, ``<=`` to ``<``)."""
    eps = np.finfo(float).eps
    t = np.arange(4.0)
    at_bound = np.array([1.0, 1.0, 1.0, 1.0 - 8 * eps])
    assert math.isnan(crossing_time_constant(t, at_bound, 1)[0])
    assert math.isnan(exponential_time_constant(t, at_bound, 1)[0])
    assert not math.isnan(crossing_time_constant(t, np.array([1.0, 1.0, 1.0, 1.0 + 9 * eps]), 1)[0])


# -- the protocol controller -------------------------------------------------------------------
def test_carry_then_shifts_the_inner_clock():
    plant = CAROUSEL.run_plant(0.35, "ideal")
    run = simulate_closed_loop(plant, CarryThen(FrictionBrake(0.4, start=0.1), 0.2, 0.35), 0.5, v0=0.35)
    carried = run.times < 0.3 - 1e-9                       # 0.2 carried + 0.1 inner carry
    assert np.all(run.commands[carried] == 0.35)
    assert np.sort(run.commands[~carried][0]).tolist() == [-0.35] * 7 + [0.35] * 3


# -- viscosity ---------------------------------------------------------------------------------
def test_ideal_sweep_reads_the_ideal_model():
    # Ideal loop: the samples lie on the exact trajectory. Crossing rule: V(t) is piecewise
    # linear and concave on the way to the stop, so the chord between samples crosses the
    # 63.2 % level no earlier than V and at most one period later: 0 <= tau - C m / k <= h
    # (rounding: 1e-12 s). Least squares: the 50 Hz samples' sum against the prediction's
    # 1001-sample sum over the same window (the same path): measured within 0.46 %, rtol 1 %.
    # The settled speed is the resting speed exactly (the exact plant sticks on the contact).
    check = viscosity_check(ViscosityProblem(CAROUSEL, "ideal", runs=60, seed=4))
    assert check.ok.all() and check.runs == 60
    gap = check.tau["crossing_63"] - check.tau_predicted["crossing_63"]
    assert np.all(gap >= -1e-12) and np.all(gap <= PERIOD + 1e-12)
    np.testing.assert_allclose(check.tau["least_squares"], check.tau_predicted["least_squares"], rtol=1e-2)
    np.testing.assert_allclose(check.settled, check.design.settled_predicted, rtol=0, atol=1e-15)
    # The per-run crossing correction is the closed form at the run's start (rounding of the
    # allocation's speeds: rtol 1e-9).
    n = CAROUSEL.n
    np.testing.assert_allclose(check.correction["crossing_63"], staircase_correction(n, check.start), rtol=1e-9)
    # So 1/tau lies within a period of the prediction: k_fit >= k_predicted / (1 + h / tau_min).
    cross = check.fit("crossing_63")
    tau_min = check.tau_predicted["crossing_63"].min()
    assert cross.k_predicted / (1 + PERIOD / tau_min) <= cross.k_fit <= cross.k_predicted
    assert check.fit() is check.fit("least_squares") and check.k_fit == check.fit().k_fit
    # The fit reads several percent faster than the crossing (docs/physics.md section 6).
    assert check.fit("least_squares").k_predicted > 1.05 * cross.k_predicted
    assert check.met, check.message


def test_sweep_design_is_seeded_and_within_its_ranges():
    a = viscosity_check(ViscosityProblem(CAROUSEL, "ideal", runs=12, seed=7))
    b = viscosity_check(ViscosityProblem(CAROUSEL, "ideal", runs=12, seed=7), progress=True)
    c = viscosity_check(ViscosityProblem(CAROUSEL, "ideal", runs=12, seed=8))
    np.testing.assert_array_equal(a.tau["least_squares"], b.tau["least_squares"])
    assert not np.array_equal(a.slope, c.slope)
    assert np.all((a.design.spacing >= 0.02) & (a.design.spacing <= 0.06))
    np.testing.assert_allclose(a.slope, 2 * CAROUSEL.force / a.design.spacing, rtol=1e-15)


@pytest.mark.parametrize("n", [10, 20, 100])
def test_default_starts_lie_inside_the_spread_away_from_the_equilibrium(n):
    # The default design: every start inside the spread (at or above the lowest contact, or
    # mirrored) and at least 3 spacings from the equilibrium set (for even n the band's near
    # edge at 1/2 spacing from the centre); spacings 0.2/n .. 0.6/n m/s (n s = 0.2-0.6 m/s).
    problem = ViscosityProblem(Apparatus.carousel(n=n), "ideal", runs=200, seed=3)
    design = plan_runs(problem)
    half = (n - 1) / 2
    assert np.all(design.inside) and np.all(np.abs(design.start) <= half + 1e-12)
    assert np.all(np.abs(design.start) - problem.resting_position >= EQUILIBRIUM_MARGIN - 1e-12)
    assert np.all((design.spacing * n >= 0.2 - 1e-12) & (design.spacing * n <= 0.6 + 1e-12))
    # Both directions, about half each (binomial, 200 draws: 4 sd = 28).
    assert abs(np.sum(design.start < 0) - 100) <= 28


@pytest.mark.parametrize("n,mass,seed", [(7, 0.7, 11), (7, 1.0, 5), (6, 2.5, 1), (9, 0.7, 2)])
def test_staircases_with_a_crossing_one_ulp_from_a_sample_are_planned(n, mass, seed):
    # These designs once failed: the force curve's crossing of +-F_tot, interpolated between two
    # samples one rounding step apart, landed past the second and the curve was refused as
    # unsorted. Each run's staircase must now be planned: n finite speeds within the motors'
    # limits, its equilibrium (weighted median) at the run's planned v0 to rounding.
    apparatus = Apparatus.carousel(n=n, mass=mass)
    design = plan_runs(ViscosityProblem(apparatus, "ideal", runs=17, seed=seed))
    assert design.commanded.shape == (17, n) and np.all(np.isfinite(design.commanded))
    assert np.all(np.abs(design.commanded) <= apparatus.speed_limit * (1 + 1e-12))


def test_starts_outside_the_spread_are_fitted_apart():
    # Starts from one spacing below to one above the lowest contact: the runs below (p < 0)
    # form their own fits, never pooled with the starts inside, and are not judged.
    check = viscosity_check(ViscosityProblem(CAROUSEL, "ideal", runs=40, seed=2, start=(-1.0, 1.0)))
    for d in ("least_squares", "crossing_63"):
        inside, outside = check.fit(d, "inside"), check.fit(d, "outside")
        assert inside.runs == int(np.sum(check.inside)) and outside.runs == int(np.sum(~check.inside))
        assert inside.runs + outside.runs == 40 and outside.met is None and inside.met is True
        # Each group's k_fit is the proportional fit of its own runs only.
        use = check.inside
        assert inside.k_fit == pytest.approx(proportional_fit(check.slope[use], 1 / check.tau[d][use])[0],
                                             rel=1e-12)
    data = check.to_dict()
    assert data["runs_outside"] == int(np.sum(~check.inside)) and len(data["fits"]) == 4


def test_in_loop_sweep_meets_the_targets_on_a_small_sweep():
    # Encoders, Kalman filter and motor lag: the same targets as the full sweep (R^2 >= 0.98,
    # k_fit within 5 % of the prediction) for both definitions on 40 runs of seed 1.
    check = viscosity_check(ViscosityProblem(CAROUSEL, "loop", runs=40, seed=1))
    assert check.ok.all()
    for fit in check.fits:
        assert fit.r2 >= 0.98 and abs(fit.ratio - 1) <= 0.05, (fit, check.message)
        # The motor lag alone (the fit on the true speed of the same runs) is within the target too.
        assert abs(fit.k_fit_true / fit.k_predicted - 1) <= 0.05 and fit.r2_true >= 0.98
    assert check.met


def _same_check(a, b):
    """Every per-run array of two ViscosityChecks bitwise equal (a run is computed whole by one
    process with the same code and the same seed: nothing may differ, not even by rounding)."""
    for d in a.problem.definitions:
        for name in ("tau", "tau_true", "tau_predicted", "correction"):
            assert np.array_equal(getattr(a, name)[d], getattr(b, name)[d], equal_nan=True), (name, d)
    for name in ("slope", "v0", "settled_predicted", "stop_time", "window", "commanded"):
        assert np.array_equal(getattr(a.design, name), getattr(b.design, name)), name
    assert [s.entropy for s in a.design.seeds] == [s.entropy for s in b.design.seeds]
    assert [tuple(s.spawn_key) for s in a.design.seeds] == [tuple(s.spawn_key) for s in b.design.seeds]
    assert np.array_equal(a.settled, b.settled, equal_nan=True) and np.array_equal(a.ok, b.ok)
    assert a.message == b.message and a.status is b.status


@pytest.mark.parametrize("n, mass, runs, seed", [(10, 0.7, 23, 3), (9, 1.0, 17, 11), (8, 2.5, 9, 5)])
def test_in_loop_sweep_over_forked_workers_equals_one_process(n, mass, runs, seed):
    # The sweep's runs shared among 2 and 3 forked processes give every run's numbers exactly
    # (rtol = atol = 0) as one process does; odd and even n, run counts that do not divide.
    apparatus = Apparatus.carousel(n=n, mass=mass)
    problem = ViscosityProblem(apparatus, "loop", runs=runs, seed=seed)
    one = viscosity_check(problem, workers=1)
    for workers in (2, 3):
        _same_check(one, viscosity_check(problem, workers=workers))
    assert one.ok.all()


def test_forked_sweep_after_a_parallel_batch_kernel():
    # The ideal sweep's batch kernel runs on threads (prange) first; a forked in-loop sweep in
    # the same process afterwards must still finish and equal the one-process sweep (rtol = 0).
    viscosity_check(ViscosityProblem(CAROUSEL, "ideal", runs=64, seed=2))
    problem = ViscosityProblem(CAROUSEL, "loop", runs=12, seed=2)
    _same_check(viscosity_check(problem, workers=1), viscosity_check(problem, workers=2))


@pytest.mark.parametrize("seed", [0, 9])
def test_sweep_runs_equal_their_closed_loop_with_the_virtual_viscosity(seed):
    # The sweep replays each run's staircase as allocated in the plan; binding the run's
    # VirtualViscosity inside CarryThen (the controller as a user writes it) and running
    # simulate_closed_loop gives the same samples bitwise (rtol = atol = 0: the same table in
    # the same kernel), so the same tau under each definition.
    from toolkit.controllers import VirtualViscosity
    from toolkit.predictions.viscosity import _simulate_startups, measure_time_constants

    apparatus = Apparatus.carousel(n=9, mass=1.3)
    problem = ViscosityProblem(apparatus, "loop", runs=6, seed=seed)
    design = plan_runs(problem)
    records, failures = _simulate_startups(problem, design)
    assert not failures
    for r in range(design.runs):
        v0 = float(design.v0[r])
        controller = CarryThen(VirtualViscosity(float(design.slope[r])), problem.pre_roll, v0)
        run = simulate_closed_loop(apparatus.run_plant(v0, "loop"), controller,
                                   problem.pre_roll + float(design.stop_time[r]) + problem.tail,
                                   v0=v0, sensors=apparatus.sensors, seed=design.seeds[r])
        first = int(np.searchsorted(run.times, problem.pre_roll - 1e-9))
        times, estimate, speed = records[r]
        assert np.array_equal(times, run.times[first:] - run.times[first])
        assert np.array_equal(estimate, run.estimate[first:]) and np.array_equal(speed, run.speed[first:])
        alone = measure_time_constants(problem, [(times, run.estimate[first:], run.speed[first:])])
        swept = measure_time_constants(problem, [records[r]])
        for d in problem.definitions:
            assert alone["tau"][d][0] == swept["tau"][d][0] and alone["tau_true"][d][0] == swept["tau_true"][d][0]


def test_viscosity_check_refuses_bad_workers():
    for bad in (0, -1, 1.5, "2"):
        with pytest.raises((ParameterError, TypeError)) as info:
            viscosity_check(ViscosityProblem(CAROUSEL, "loop", runs=2), workers=bad)
        assert "'workers' parameter of viscosity_check" in str(info.value)


@pytest.mark.slow
@pytest.mark.parametrize("n", [10, 20, 100])
def test_full_sweeps_of_490_runs(n):
    # The criterion at full size, ideal and in the loop: for each definition k_fit
    # within 5 % of k_predicted and R^2 >= 0.98 over 490 runs (about 15 s per n).
    for mode in ("ideal", "loop"):
        check = viscosity_check(ViscosityProblem(Apparatus.carousel(n=n), mode))
        assert check.runs == 490 and check.ok.all()
        assert [f.runs for f in check.fits] == [490, 490]
        assert check.met, f"{mode}: {check.message}"


def test_apparatus_with_contacts_keeps_the_total_friction():
    a = CAROUSEL.with_contacts(25)
    assert a.n == 25 and a.sensors.n_wheels == 25
    assert a.total_force == pytest.approx(CAROUSEL.total_force, rel=1e-15)
    assert a.mass == CAROUSEL.mass and a.plant.motors == CAROUSEL.plant.motors
    assert Apparatus.carousel(n=25).total_force == pytest.approx(a.total_force, rel=1e-15)
    with pytest.raises(ParameterError, match="'n' parameter of Apparatus.with_contacts"):
        CAROUSEL.with_contacts(0)


def test_viscosity_problem_refuses_what_it_cannot_run():
    with pytest.raises(ParameterError, match="'spacing' parameter of ViscosityProblem"):
        ViscosityProblem(CAROUSEL, spacing=(0.02, 0.09))              # 4.5 s > 0.35 m/s
    with pytest.raises(ParameterError, match="'start' parameter of ViscosityProblem"):
        ViscosityProblem(CAROUSEL, spacing=(0.02, 0.06), start=(-3.0, 1.0))   # start beyond v_max
    with pytest.raises(ParameterError, match="'definitions' parameter of ViscosityProblem"):
        ViscosityProblem(CAROUSEL, definitions=("least_squares", "least_squares"))
    with pytest.raises(ParameterError, match="'definitions' parameter of ViscosityProblem"):
        ViscosityProblem(CAROUSEL, definitions=("crossing",))
    with pytest.raises(ParameterError, match="'start' parameter of ViscosityProblem"):
        ViscosityProblem(CAROUSEL, start=(-1.0, 4.2))                 # inside the zero band
    with pytest.raises(ParameterError, match="'mode' parameter of ViscosityProblem"):
        ViscosityProblem(CAROUSEL, mode="exact")
    with pytest.raises(ParameterError, match="'mode' parameter of ViscosityProblem"):
        ViscosityProblem(Apparatus(CAROUSEL.plant), mode="loop")      # no sensors
    with pytest.raises(ParameterError, match="'runs' parameter of ViscosityProblem"):
        ViscosityProblem(CAROUSEL, runs=1)


# -- friction fraction -------------------------------------------------------------------------
def test_ideal_friction_fraction_is_exact():
    # Ideal loop: the rig reading is an identity (m dV/dt = F_c + F_rig integrated over the
    # window, F_c constant in the band), and V(t) is linear during the transition, so both
    # readings are exact up to rounding: mu/mu0 = j/5 (abs 1e-12) and, for j = 5 (every
    # contact reversed), dT = m 2 v_max / F_tot (rtol 1e-12); j = 0 never arrives.
    check = friction_fraction_check(FrictionFractionProblem(CAROUSEL, "ideal"))
    np.testing.assert_allclose(check.mu_ratio, np.arange(6) / 5, rtol=0, atol=1e-12)
    assert check.brake_force == pytest.approx(-CAROUSEL.total_force, rel=1e-12)
    full = CAROUSEL.mass * 2 * CAROUSEL.speed_limit / CAROUSEL.total_force
    assert check.dT[5] == pytest.approx(full, rel=1e-12)
    assert full == pytest.approx(0.35, rel=1e-15)          # the paper's 0.35 s at F_tot / m = 2
    np.testing.assert_allclose(check.dT[1:], transition_time(1.0, 0.35, 2.0, np.arange(1, 6) / 5), rtol=1e-12)
    assert check.dT[0] == math.inf and check.dT_predicted[0] == math.inf
    assert check.met


def test_in_loop_friction_fraction_meets_the_targets():
    # Encoders, motor lag; the Kalman filter in the rig's loop (told the rig's force) and in
    # the braking loop: the targets (0.02 on mu/mu0, 5 % on dT). Measured: |mu/mu0 -
    # j/5| <= 7e-6, |dT / dT_predicted - 1| <= 0.10 %.
    check = friction_fraction_check(FrictionFractionProblem(CAROUSEL, "loop"))
    assert check.problem.rig_estimator == "kalman"
    assert np.all(np.abs(check.mu_ratio - np.arange(6) / 5) <= 0.02)
    rel = np.abs(check.dT[1:] / check.dT_predicted[1:] - 1)
    assert np.all(rel <= 0.05) and check.dT[0] == math.inf
    assert check.met, check.message


def test_rig_on_the_filter_reads_friction_finer_than_on_differences():
    # Second method: the same rig closed on the central encoder's finite difference (the
    # baseline) also meets the 0.02 target (measured 1.5e-3), but the filter, which knows
    # the rig's force, reads mu/mu0 at least ten times closer to j/5 (measured 7e-6). The
    # braking runs use the filter in both, so dT is the same numbers.
    kf = friction_fraction_check(FrictionFractionProblem(CAROUSEL, "loop"))
    fd = friction_fraction_check(FrictionFractionProblem(CAROUSEL, "loop", rig_estimator="central_difference"))
    exact = np.arange(6) / 5
    assert fd.met, fd.message
    assert np.max(np.abs(kf.mu_ratio - exact)) <= np.max(np.abs(fd.mu_ratio - exact)) / 10
    np.testing.assert_array_equal(kf.dT, fd.dT)
    with pytest.raises(ParameterError, match="'rig_estimator' parameter of FrictionFractionProblem"):
        FrictionFractionProblem(CAROUSEL, "loop", rig_estimator="kalmann")


def test_friction_fraction_with_drag_falls_short():
    # Bearing drag (left out of the prediction) adds -c V to the force the rig reads: with
    # c = 0.4 N s/m the brake condition, read over 0.7 v_max .. 0.1 v_max (mean V = 0.14
    # m/s), gives F0 = -2.056 N, and j = 5, read over 0.4 v_max .. -0.8 v_max (mean -0.07
    # m/s), -1.972 N: mu/mu0 = 0.959, beyond the 0.02 target.
    plant = replace(CAROUSEL.plant, damping=0.4)
    check = friction_fraction_check(FrictionFractionProblem(Apparatus(plant), "ideal"))
    assert check.status is CheckStatus.SHORT and "j = 5: mu/mu0 0.959" in check.message
    assert check.mu_ratio[5] == pytest.approx(1.972 / 2.056, rel=0, abs=1e-3)
    with pytest.raises(ParameterError, match="'apparatus' parameter of FrictionFractionProblem"):
        odd = Plant(ContactSet([0.0] * 9, [0.2] * 9), 1.0, motors=Motors(speed_limits=(-0.35, 0.35)))
        FrictionFractionProblem(Apparatus(odd), "ideal")


def test_apparatus_refuses_what_the_experiments_do_not_cover():
    unequal = Plant(ContactSet([0.0] * 10, [0.2] * 9 + [0.3]), 1.0, motors=Motors(speed_limits=(-0.35, 0.35)))
    with pytest.raises(ParameterError, match="'plant.contacts.forces' parameter of Apparatus must be one equal") as error:
        Apparatus(unequal)
    assert error.value.parameter == "plant.contacts.forces"
    lopsided = Plant(ContactSet([0.0] * 10, [0.2] * 10), 1.0, motors=Motors(speed_limits=(-0.3, 0.35)))
    with pytest.raises(ParameterError, match="'plant.motors.speed_limits' parameter of Apparatus must be finite and "
                                             "symmetric"):
        Apparatus(lopsided)
    with pytest.raises(ParameterError, match="'sensors' parameter of Apparatus"):
        Apparatus(CAROUSEL.plant, HARDWARE.sensors(8))


# -- both, and the command line ------------------------------------------------------------------
def test_prediction_checks_without_sensors_never_import_filterpy_or_control():
    code = ("import sys\n"
            "from toolkit.predictions import Apparatus, prediction_checks\n"
            "a = Apparatus.carousel()\n"
            "r = prediction_checks(Apparatus(a.plant), runs=4)\n"
            "assert r.viscosity is None and r.friction is None and r.viscosity_ideal.runs == 4\n"
            "print(sorted(m for m in ('filterpy', 'control') if m in sys.modules))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_cli_predict_json(capsys):
    assert main(["predict", "--runs", "6", "--json"]) == 0
    captured = capsys.readouterr()
    data = json.loads(captured.out)
    assert captured.err == ""                                # no progress bar with --json
    fits = data["viscosity"]["fits"]
    assert data["viscosity"]["n"] == 10 and len(fits) == 4
    assert [(f["mode"], f["definition"]) for f in fits] == [
        ("ideal", "least_squares"), ("ideal", "crossing_63"), ("loop", "least_squares"), ("loop", "crossing_63")]
    assert all({"definition", "n", "k_fit", "k_predicted", "r2", "runs"} <= set(f) for f in fits)
    assert all(f["runs"] == 6 and f["n"] == 10 and f["starts"] == "inside" for f in fits)
    assert data["viscosity"]["loop"]["runs"] == 6 and data["viscosity"]["loop"]["mode"] == "loop"
    rows = data["friction_fraction"]
    assert [row["n"] for row in rows] == list(range(6))
    assert all({"n", "mu_ratio", "dT", "dT_predicted"} <= set(row) for row in rows)
    assert rows[0]["dT"] is None and rows[0]["dT_predicted"] is None        # infinite
    assert rows[5]["dT_predicted"] == pytest.approx(0.35, rel=1e-12)
    assert rows[5]["ideal"]["dT"] == pytest.approx(0.35, rel=1e-12)


def test_cli_predict_exit_codes(tmp_path, capsys):
    scene = tmp_path / "drag.toml"
    scene.write_text('[scene]\nname = "drag"\n[contacts]\nspeeds = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, '
                     '0.0, 0.0]\nforces = 0.2\n[body]\nmass = 1.0\ndamping = 0.4\n[motors]\n'
                     'speed_limit = 0.35\nlag = 0.0075\n')
    assert main(["predict", str(scene), "--runs", "4"]) == 3
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("active-contacts: shortfall: prediction: ")
    unequal = tmp_path / "unequal.toml"
    unequal.write_text('[contacts]\nspeeds = [0.0, 0.1]\nforces = [0.2, 0.3]\n[body]\nmass = 1.0\n'
                       '[motors]\nspeed_limit = 0.35\n')
    assert main(["predict", str(unequal)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "one equal friction magnitude" in err[0] and "scene key 'contacts.forces'" in err[0]
    unbounded = tmp_path / "unbounded.toml"
    unbounded.write_text('[contacts]\nspeeds = [0.0, 0.1]\nforces = 0.2\n[body]\nmass = 1.0\n')
    assert main(["predict", str(unbounded)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "finite and symmetric" in err[0] and "scene key 'motors.speed_limit'" in err[0]


def test_cli_predict_with_contacts(capsys):
    # --contacts N: N equal wheels sharing the carousel's F_tot; the fits say n = N; the
    # friction-fraction check runs j = 0..N/2 (N even) or is left out (N odd).
    assert main(["predict", "--runs", "4", "--contacts", "20", "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["viscosity"]["n"] == 20 and {f["n"] for f in data["viscosity"]["fits"]} == {20}
    assert [row["n"] for row in data["friction_fraction"]] == list(range(11))
    assert main(["predict", "--runs", "4", "--contacts", "11"]) == 0
    out = capsys.readouterr().out
    assert "on 11 contacts" in out and "least_squares (4 starts inside the spread): k_fit" in out
    assert "friction fraction: left out (11 contacts" in out
    assert main(["predict", "--runs", "4", "--contacts", "11", "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["friction_fraction"] == [] and data["friction_fraction_status"] is None
    with pytest.raises(SystemExit) as exit_info:
        main(["predict", "--contacts", "0"])
    assert exit_info.value.code == 2
    assert "--contacts: must be an integer >= 5, got 0" in capsys.readouterr().err
    # The flag is bounded like the constructor it feeds (toolkit.scenes.limits.FLAGS).
    from toolkit.predictions.apparatus import MAX_CONTACTS
    from toolkit.scenes.limits import FLAGS

    assert FLAGS["predict --contacts"].high == MAX_CONTACTS
    with pytest.raises(SystemExit) as exit_info:
        main(["predict", "--contacts", "20000"])
    assert exit_info.value.code == 2
    assert "--contacts: must be an integer <= 10000, got 20000" in capsys.readouterr().err
    with pytest.raises(ParameterError, match="'n' parameter of Apparatus.with_contacts must be an integer in"):
        Apparatus.carousel().with_contacts(20000)


# -- the viscosity sweep's pieces, fast and exact ----------------------------------------------
from toolkit.predictions import viscosity as _visc                      # noqa: E402
from toolkit.predictions.theory import least_squares_correction        # noqa: E402
from toolkit.predictions.viscosity import (ViscosityDesign, draw_design, fit_viscosity,  # noqa: E402
                                           predict_time_constants)


@pytest.mark.parametrize(("kwargs", "error", "message"), [
    ({"apparatus": "carousel"}, TypeError,
     "The 'apparatus' parameter of ViscosityProblem must be an Apparatus. Got 'carousel' instead."),
    ({"spacing": 0.02}, TypeError,
     "The 'spacing' parameter of ViscosityProblem must be a pair (low, high). Got 0.02 instead."),
    ({"spacing": (0.05, 0.02)}, ParameterError,
     "The 'spacing' parameter of ViscosityProblem must have low <= high. Got (0.05, 0.02) instead."),
    ({"spacing": (0.0, 0.02)}, ParameterError,
     "The 'spacing' parameter of ViscosityProblem must be > 0. Got 0.0 instead."),
    ({"spacing": (0.02, 0.0)}, ParameterError,
     "The 'spacing' parameter of ViscosityProblem must be > 0. Got 0.0 instead."),
    ({"spacing": (0.02, 0.09)}, ParameterError,
     "The 'spacing' parameter of ViscosityProblem must keep the 10 contacts within +-0.35 m/s (at most "
     "0.0777778 m/s). Got (0.02, 0.09) instead."),
    ({"start": (1.0,)}, TypeError,
     "The 'start' parameter of ViscosityProblem must be a pair (low, high). Got (1.0,) instead."),
    ({"spacing": (0.02, 0.06), "start": (-3.0, 1.0)}, ParameterError,
     "The 'start' parameter of ViscosityProblem must put every start within +-0.35 m/s (the lowest start with "
     "the widest spacing lies 0.45 m/s from the reference). Got (-3.0, 1.0) instead."),
    # Even n: the band's near edge is 1/2 spacing from the centre, 4 spacings from the lowest
    # contact of 10; a start at 4 is inside it (3.75 is not: accepted below).
    ({"start": (-1.0, 4.0)}, ParameterError,
     "The 'start' parameter of ViscosityProblem must leave the start outside the equilibrium set (below 4 "
     "spacings from the lowest contact). Got (-1.0, 4.0) instead."),
    ({"apparatus": Apparatus.carousel(n=9), "start": (-1.0, 4.0)}, ParameterError,
     "The 'start' parameter of ViscosityProblem must leave the start outside the equilibrium set (below 4 "
     "spacings from the lowest contact). Got (-1.0, 4.0) instead."),
    ({"apparatus": Apparatus.carousel(n=4)}, ParameterError,
     "The 'apparatus' parameter of ViscosityProblem must have at least 5 contacts for the default starts (0 to "
     "1 spacing above the lowest contact) to lie below the equilibrium set, or be given starts (start). Got "
     "'4 contacts' instead."),
    ({"tail": 0.1, "tail_samples": 6}, ParameterError,
     "The 'tail_samples' parameter of ViscosityProblem must fit in the tail (0.1 s at 50 Hz). Got 6 instead."),
    ({"definitions": "least_squares"}, TypeError,
     "The 'definitions' parameter of ViscosityProblem must be a sequence of ['least_squares', 'crossing_63']. "
     "Got 'least_squares' instead."),
    ({"definitions": 3}, TypeError,
     "The 'definitions' parameter of ViscosityProblem must be a sequence of ['least_squares', 'crossing_63']. "
     "Got 3 instead."),
    ({"definitions": ("least_squares", "least_squares")}, ParameterError,
     "The 'definitions' parameter of ViscosityProblem must name each definition once, at least one. Got "
     "('least_squares', 'least_squares') instead."),
    ({"definitions": ()}, ParameterError,
     "The 'definitions' parameter of ViscosityProblem must name each definition once, at least one. Got () "
     "instead."),
    ({"targets": (1.5, 0.05)}, ParameterError,
     "The 'targets' parameter of ViscosityProblem must be <= 1. Got 1.5 instead."),
    ({"targets": (0.9, -0.05)}, ParameterError,
     "The 'targets' parameter of ViscosityProblem must be >= 0. Got -0.05 instead."),
    ({"runs": 1}, ParameterError, "The 'runs' parameter of ViscosityProblem must be >= 2. Got 1 instead."),
    ({"pre_roll": -0.1}, ParameterError,
     "The 'pre_roll' parameter of ViscosityProblem must be >= 0. Got -0.1 instead."),
    ({"tail": 0.0}, ParameterError, "The 'tail' parameter of ViscosityProblem must be > 0. Got 0.0 instead."),
    ({"tail_samples": 0}, ParameterError,
     "The 'tail_samples' parameter of ViscosityProblem must be >= 1. Got 0 instead."),
    ({"seed": -1}, ParameterError, "The 'seed' parameter of ViscosityProblem must be >= 0. Got -1 instead."),
])
def test_every_refusal_of_the_viscosity_problem_in_full(kwargs, error, message):
    """Each refusal matched whole: parameter, owner, rule and value (mutants: any of them
    changed, dropped or replaced by None, a bound moved)."""
    kwargs = {"apparatus": CAROUSEL, **kwargs}
    with pytest.raises(error) as info:
        ViscosityProblem(**kwargs)
    assert str(info.value) == message


def test_viscosity_problem_defaults_and_edges():
    """The defaults (spacing 0.2/n to 0.6/n, starts 0 to 1), the sample rate of the sensors
    (50 Hz, and 50 Hz without them), the resting position (1/2 for even n, 0 for odd), and the
    edges just inside the refusals above: a start at 3.75 spacings, a tail of 0.1 s holding 5
    samples, ``tail_samples`` 1, ``pre_roll`` 0."""
    p = ViscosityProblem(CAROUSEL)
    assert p.spacing == (0.02, 0.06) and p.start == (0.0, 1.0) and p.mode == "loop" and p.runs == 490
    assert p.rate == 50.0 and ViscosityProblem(Apparatus(CAROUSEL.plant), "ideal").rate == 50.0
    assert p.resting_position == 0.5 and ViscosityProblem(Apparatus.carousel(n=9)).resting_position == 0.0
    assert ViscosityProblem(CAROUSEL, start=(-1.0, 3.75)).start == (-1.0, 3.75)
    assert ViscosityProblem(CAROUSEL, tail=0.1, tail_samples=5).tail_samples == 5
    assert ViscosityProblem(CAROUSEL, tail_samples=1, pre_roll=0.0).pre_roll == 0.0
    assert ViscosityProblem(Apparatus.carousel(n=5)).definitions == ("least_squares", "crossing_63")
    assert ViscosityProblem(CAROUSEL, definitions=["crossing_63"]).definitions == ("crossing_63",)
    assert ViscosityProblem(CAROUSEL, targets=(1.0, 0.0)).targets == (1.0, 0.0)
    # Numbers of other types are stored as the type the fields declare.
    p = ViscosityProblem(CAROUSEL, runs=np.int64(12), pre_roll=0, tail=1, seed=np.int64(3), tail_samples=np.int64(4))
    assert type(p.runs) is int and type(p.pre_roll) is float and type(p.tail) is float and type(p.seed) is int
    assert type(p.tail_samples) is int
    with pytest.raises(TypeError) as info:
        viscosity_check("problem")
    assert str(info.value) == ("The 'problem' parameter of viscosity_check must be a ViscosityProblem. "
                               "Got 'problem' instead.")


@pytest.mark.parametrize("mass", SCALES)
def test_draw_design_identities(mass):
    """Per run: ``x0 = -+(half - position)`` (up: below the centre), ``v0 = x0 s`` and the
    slope ``2 f / s`` (f scales with the mass: ``k / m`` does not), ``inside`` exactly where
    ``position >= 0``; the draw depends on the seed only (the same at every mass)."""
    problem = ViscosityProblem(Apparatus.carousel(mass=mass), "ideal", runs=64, seed=5, start=(-1.0, 1.0))
    d = draw_design(problem)
    half = 4.5
    assert np.array_equal(np.abs(d["start"]), half - d["position"])
    assert np.array_equal(d["v0"], d["start"] * d["spacing"])
    assert np.array_equal(d["slope"], 2.0 * problem.apparatus.force / d["spacing"])
    assert np.array_equal(d["inside"], d["position"] >= 0.0) and 0 < d["inside"].sum() < 64
    assert 0 < np.sum(d["start"] < 0) < 64 and len(d["seeds"]) == 64
    ref = draw_design(ViscosityProblem(Apparatus.carousel(), "ideal", runs=64, seed=5, start=(-1.0, 1.0)))
    assert np.array_equal(d["start"], ref["start"]) and np.array_equal(d["slope"] / mass, ref["slope"])
    assert np.all((d["spacing"] >= 0.02) & (d["spacing"] <= 0.06)) and np.all(np.abs(d["position"]) <= 1.0)


@pytest.mark.parametrize("mass", SCALES)
def test_predicted_corrections_are_per_unit_mass(mass):
    """The least-squares correction of a run is ``least_squares_correction(n, x0, window k /
    m)``: with slopes ``(1, 2, 4) m / 8`` and windows ``8 W / (1, 2, 4)`` (dyadic: exact)
    it is that of ``W = 2, 3, 5`` at every mass, bit for bit. The crossing correction of the
    allocated staircase is the closed form ``staircase_correction(n, x0)`` (rounding of the
    allocation's speeds: rtol 1e-9). Mutant killed: the mass dropped from ``window k / m``
    (or from the crossing's ``C``): invisible at mass 1."""
    problem = ViscosityProblem(Apparatus.carousel(mass=mass), "ideal", runs=3, seed=1)
    design = plan_runs(problem)
    W = np.array([2.0, 3.0, 5.0])
    k = np.array([1.0, 2.0, 4.0]) * mass / 8
    dyadic = replace(design, slope=k, window=W * mass / k)
    least = predict_time_constants(replace(problem, definitions=("least_squares",)), dyadic)
    assert np.array_equal(least["least_squares"], least_squares_correction(10, design.start, W))
    C = predict_time_constants(replace(problem, definitions=("crossing_63",)), design)
    np.testing.assert_allclose(C["crossing_63"], staircase_correction(10, design.start), rtol=1e-9)


def _synthetic_check(monkeypatch, mass, tau_factor=(1.0, 1.0), window_off=None, bad_tau=None, inside=None,
                     failures=(), off_by=0.02, targets=(0.98, 0.05)):
    """viscosity_check on a sweep replaced by numbers: 6 runs of slopes 1..6 (times the
    mass), corrections 0.5 (least squares) and 0.8 (crossing), each run's tau ``tau_factor``
    times ``C m / k``, windows as planned."""
    problem = ViscosityProblem(Apparatus.carousel(mass=mass), "ideal", runs=6, targets=targets)
    slope = np.arange(1.0, 7.0) * mass
    runs = 6
    inside = np.array([True] * 4 + [False] * 2) if inside is None else inside
    window = np.full(runs, 0.5)
    design = ViscosityDesign(slope, np.full(runs, 0.04), np.full(runs, 0.1), np.zeros(runs), np.full(runs, -4.5),
                             inside, [None] * runs, np.zeros(runs), np.ones(runs), window, np.zeros((runs, 10)))
    correction = {"least_squares": np.full(runs, 0.5), "crossing_63": np.full(runs, 0.8)}
    tau = {d: f * correction[d] * mass / slope for d, f in zip(("least_squares", "crossing_63"), tau_factor)}
    measured_window = window.copy()
    if window_off is not None:
        measured_window[window_off] += off_by
    if bad_tau is not None:
        tau["crossing_63"][bad_tau] = -1.0
    measured = {"tau": tau, "tau_true": {d: t.copy() for d, t in tau.items()}, "settled": np.full(runs, 0.3),
                "window": measured_window}
    monkeypatch.setattr(_visc, "_sweep", lambda p, progress, workers: (design, measured, correction, list(failures)))
    return _visc.viscosity_check(problem)


@pytest.mark.parametrize("mass", SCALES)
def test_viscosity_check_assembles_its_fits_per_group(monkeypatch, mass):
    """Runs whose tau is exactly ``C m / k``: ``tau_predicted`` is that (mass scales exact),
    each group of starts is fitted on its own runs (4 inside, 2 outside), ``k_fit = 1 / C =
    k_predicted`` (rounding of two sums: rtol 4 eps), ``R^2 = 1`` to rounding, the targets met."""
    check = _synthetic_check(monkeypatch, mass)
    assert check.status is CheckStatus.MET and check.met and check.ok.all()
    assert np.array_equal(check.tau_predicted["least_squares"], 0.5 * mass / check.slope)
    inside, outside = check.fit(), check.fit("least_squares", "outside")
    assert check.fit() is check.fit("least_squares", "inside") and inside.starts == "inside"
    assert (inside.runs, outside.runs, outside.met, inside.met) == (4, 2, None, True)
    assert inside.definition == "least_squares" and inside.n == 10 and inside.mode == "ideal"
    for fit, C in ((inside, 0.5), (check.fit("crossing_63"), 0.8)):
        np.testing.assert_allclose([fit.k_fit, fit.k_predicted, fit.k_fit_true], 1 / C, rtol=4 * EPS_)
        np.testing.assert_allclose([fit.r2, fit.r2_corrected, fit.r2_true], 1.0, rtol=0, atol=4 * EPS_)
        np.testing.assert_allclose(fit.ratio, 1.0, rtol=4 * EPS_)
    assert check.k_fit == inside.k_fit and check.k_predicted == inside.k_predicted and check.r2 == inside.r2
    assert check.ratio == check.k_fit / check.k_predicted
    assert check.message == (f"least_squares: R^2 {inside.r2:.4f}, k_fit / k_predicted = {inside.ratio:.4f}; "
                             f"crossing_63: R^2 {check.fit('crossing_63').r2:.4f}, k_fit / k_predicted = "
                             f"{check.fit('crossing_63').ratio:.4f}")
    assert np.array_equal(check.v0, np.full(6, 0.1)) and np.array_equal(check.start, np.full(6, -4.5))
    assert np.array_equal(check.inside, [True] * 4 + [False] * 2) and check.runs == 6
    data = check.to_dict()
    assert data["runs_outside"] == 2 and data["status"] == "MET" and data["n"] == 10 and data["mode"] == "ideal"
    assert data["correction_range"] == {"least_squares": [0.5, 0.5], "crossing_63": [0.8, 0.8]}
    assert data["tau_ratio_range"] == {"least_squares": [1.0, 1.0], "crossing_63": [1.0, 1.0]}
    assert data["targets"] == {"r2_min": 0.98, "k_rel_max": 0.05} and data["runs"] == 6
    assert [f["starts"] for f in data["fits"]] == ["inside", "outside"] * 2
    fit_dict = data["fits"][0]
    assert set(fit_dict) == {"definition", "starts", "n", "mode", "runs", "k_fit", "k_predicted", "ratio", "r2",
                             "r2_corrected", "true_speed", "met"}
    assert fit_dict["r2_corrected"] == inside.r2_corrected and fit_dict["k_predicted"] == inside.k_predicted
    assert fit_dict["ratio"] == inside.ratio and fit_dict["true_speed"] == {"k_fit": inside.k_fit_true,
                                                                            "r2": inside.r2_true}
    with pytest.raises(ParameterError, match="'starts' parameter of ViscosityCheck.fit"):
        check.fit("least_squares", "below")
    with pytest.raises(ParameterError, match="'definition' parameter of ViscosityCheck.fit"):
        check.fit("crossing")


EPS_ = float(np.finfo(float).eps)


def test_viscosity_check_judges_each_target(monkeypatch):
    """A fit 9.1 % slower than predicted (tau 1.1 times C m / k) misses the 5 % target; one
    group with fewer than two runs gives no fit; a window other than planned (by a period)
    or a tau <= 0 fails its run, named with its number and values."""
    check = _synthetic_check(monkeypatch, 1.0, tau_factor=(1.1, 1.0))
    assert check.status is CheckStatus.SHORT and not check.met
    assert check.message == "least_squares: k_fit / k_predicted = 0.9091, off by 9.1% > 5%"
    assert check.fit().met is False and check.fit("crossing_63").met is True
    # Every start inside but one: the outside group is not fitted.
    one_out = np.array([True] * 5 + [False])
    check = _synthetic_check(monkeypatch, 1.0, inside=one_out)
    assert check.fit("least_squares", "outside") is None and len(check.fits) == 2
    # Every start outside: nothing to judge.
    check = _synthetic_check(monkeypatch, 1.0, inside=np.zeros(6, bool))
    assert check.status is CheckStatus.SHORT
    assert check.message == "fewer than two runs started inside the spread: nothing to judge"
    assert np.isnan(check.k_fit) and np.isnan(check.r2)
    check = _synthetic_check(monkeypatch, 1.0, window_off=2)
    assert check.status is CheckStatus.FAILED and check.ok.tolist() == [True, True, False, True, True, True]
    assert check.message == "1 of 6 runs failed (run 2: recorded 0.52 s after the switch, planned 0.5 s)"
    assert check.fit().runs == 3
    check = _synthetic_check(monkeypatch, 1.0, bad_tau=4)
    assert check.status is CheckStatus.FAILED and not check.ok[4]
    # The summary's ranges are over the runs measured (the failed run's tau = -1 left out).
    assert check.to_dict()["tau_ratio_range"]["crossing_63"] == [1.0, 1.0]
    assert check.message == "1 of 6 runs failed (run 4: no startup to measure under crossing_63 (tau = -1.0))"
    # A record within 1e-6 of a period (0.02 s) of the plan is the planned window; 1e-7 s off is not.
    assert _synthetic_check(monkeypatch, 1.0, window_off=2, off_by=1e-9).ok.all()
    assert not _synthetic_check(monkeypatch, 1.0, window_off=2, off_by=1e-7).ok[2]
    # R^2 exactly at its target meets it.
    r2 = _synthetic_check(monkeypatch, 1.0, tau_factor=(1.0, 1.0)).fit().r2
    assert _synthetic_check(monkeypatch, 1.0, targets=(r2, 0.05)).fit().met is True
    check = _synthetic_check(monkeypatch, 1.0, failures=["run 0: a plant step stopped", "run 5: x"])
    assert check.message == "2 of 6 runs failed (run 0: a plant step stopped)"


def test_verdict_reads_r2_below_its_target(monkeypatch):
    """Scatter in tau (alternately 0.5 and 2 times C m / k) brings R^2 below 0.98: named."""
    problem = ViscosityProblem(CAROUSEL, "ideal", runs=6)
    slope = np.arange(1.0, 7.0)
    design = ViscosityDesign(slope, np.full(6, 0.04), np.full(6, 0.1), np.zeros(6), np.full(6, -4.5),
                             np.ones(6, bool), [None] * 6, np.zeros(6), np.ones(6), np.full(6, 0.5),
                             np.zeros((6, 10)))
    corr = {"least_squares": np.full(6, 0.5)}
    tau = {"least_squares": 0.5 / slope * np.array([0.5, 2.0] * 3)}
    fits = fit_viscosity(replace(problem, definitions=("least_squares",)), design, tau, tau, corr, np.ones(6, bool))
    fit = fits[0]
    x = slope / CAROUSEL.mass
    assert (fit.k_fit, fit.r2) == proportional_fit(x, 1 / tau["least_squares"])
    assert fit.r2 < 0.98 and fit.met is False
    monkeypatch.setattr(_visc, "_sweep", lambda p, progress, workers: (
        design, {"tau": tau, "tau_true": tau, "settled": np.zeros(6), "window": np.full(6, 0.5)}, corr, []))
    check = _visc.viscosity_check(replace(problem, definitions=("least_squares",)))
    assert check.message.startswith(f"least_squares: R^2 {fit.r2:.4f} < 0.98")


@pytest.mark.parametrize(("mode", "runs", "workers", "idle", "shares"), [
    ("loop", 17, None, 8, 2),        # default: the idle cores, at most one per 8 runs
    ("loop", 17, None, 1, 1),        # one idle core: no fork
    ("loop", 40, None, 3, 3),
    ("loop", 5, 3, 8, 3),            # as many as asked
    ("loop", 2, 5, 8, 2),            # but never more than the runs
    ("ideal", 40, None, 8, 1),       # ideal: one batch, never forked
])
def test_sweep_shares_the_runs_and_joins_them_in_order(monkeypatch, mode, runs, workers, idle, shares):
    """The runs are split into ``shares`` contiguous parts (``fork_map`` replaced by a plain
    map that records the split; each part's work replaced by numbers naming its rows), and the
    parts' designs, dicts of arrays and lists are joined back in the runs' order: the sweep
    of every run, as one process would compute it."""
    seen = []

    def fake_rows(problem, drawn, rows, bar=None):
        r = rows.astype(float)
        design = ViscosityDesign(r, r + 1, r + 2, r + 3, r + 4, rows % 2 == 0, [int(x) for x in rows], r + 5, r + 6,
                                 r + 7, np.c_[r, r])
        return design, {"tau": {"least_squares": r * 10}, "window": r * 2}, {"crossing_63": r * 3}, [f"run {rows[0]}"]

    def plain_map(fn, items):
        seen.append([list(item) for item in items])
        return [fn(item) for item in items]

    monkeypatch.setattr(_visc, "_sweep_rows", fake_rows)
    monkeypatch.setattr(_visc, "fork_map", plain_map)
    monkeypatch.setattr(_visc, "idle_cores", lambda: idle)
    monkeypatch.setattr(_visc, "ensure_compiled", lambda *names: None)
    problem = ViscosityProblem(CAROUSEL, mode, runs=runs)
    design, measured, correction, failures = _visc._sweep(problem, False, workers)
    whole = np.arange(runs, dtype=float)
    if shares == 1:
        assert seen == [] and failures == ["run 0"]
    else:
        assert seen == [[list(part) for part in np.array_split(np.arange(runs), shares)]]
        assert failures == [f"run {part[0]}" for part in np.array_split(np.arange(runs), shares)]
    assert np.array_equal(design.slope, whole) and np.array_equal(design.commanded, np.c_[whole, whole])
    assert np.array_equal(design.window, whole + 7) and design.seeds == list(range(runs))
    assert np.array_equal(design.inside, np.arange(runs) % 2 == 0)
    assert np.array_equal(measured["tau"]["least_squares"], whole * 10) and np.array_equal(measured["window"], whole * 2)
    assert np.array_equal(correction["crossing_63"], whole * 3)


def test_progress_bar_on_stderr_only_when_asked(capsys):
    """``progress=True`` draws the sweep's bar (named by its mode) on stderr and clears it
    when done (its last character a carriage return, not a new line); without it nothing is
    written."""
    problem = ViscosityProblem(CAROUSEL, "ideal", runs=2, seed=3)
    viscosity_check(problem)
    assert capsys.readouterr().err == ""
    viscosity_check(problem, progress=True)
    captured = capsys.readouterr()
    assert captured.err.startswith("\rviscosity (ideal):") and captured.err.endswith("\r") and captured.out == ""


def test_measure_time_constants_reads_each_record():
    """Per record and definition: tau and the settled speed off the estimate, tau_true off the
    true speed in the loop (the same as tau in the ideal mode), the window the record's last
    time; a failed run (None) is NaN throughout. Second method: startup_time_constant on each
    array directly (bitwise)."""
    t = np.array([0.0, 0.25, 0.5, 1.0, 1.5, 2.0, 3.0])
    estimate = np.array([0.0, 0.25, 0.5, 0.75, 0.9, 1.0, 1.0])
    speed = np.array([0.0, 0.5, 0.75, 0.875, 0.95, 1.0, 1.0])
    for mode in ("loop", "ideal"):
        problem = ViscosityProblem(CAROUSEL, mode, runs=2, tail_samples=2)
        out = _visc.measure_time_constants(problem, [None, (t, estimate, speed)])
        assert np.isnan(out["window"][0]) and out["window"][1] == 3.0 and np.isnan(out["settled"][0])
        for d in problem.definitions:
            tau, settled = startup_time_constant(d, t, estimate, 2)
            assert np.isnan(out["tau"][d][0]) and np.isnan(out["tau_true"][d][0])
            assert out["tau"][d][1] == tau and out["settled"][1] == settled == 1.0
            true = tau if mode == "ideal" else startup_time_constant(d, t, speed, 2)[0]
            assert out["tau_true"][d][1] == true
        assert out["tau_true"]["crossing_63"][1] != out["tau"]["crossing_63"][1] or mode == "ideal"


def test_a_run_that_stops_is_a_failure_named_by_its_number(monkeypatch):
    """A closed loop (in the loop) or a batch run (ideal) that does not finish is recorded as
    None and named in the failures with the simulator's message or the batch's code; the
    others are measured. A share of one run (two runs over two processes) is swept too."""
    from types import SimpleNamespace

    from toolkit.simulation import SimulationStatus

    real_loop, real_batch = _visc.simulate_closed_loop, _visc.sampled_batch

    def loop(*args, **kwargs):
        run = real_loop(*args, **kwargs)
        if kwargs["v0"] == stop_at:
            return SimpleNamespace(times=run.times, estimate=run.estimate, speed=run.speed,
                                   status=SimulationStatus.MAX_STEPS, message="stopped: step budget exhausted")
        return run

    def batch(*args, **kwargs):
        out = dict(real_batch(*args, **kwargs))
        out["codes"] = np.array(out["codes"]).copy()
        out["codes"][1] = 3
        return out

    problem = ViscosityProblem(CAROUSEL, "loop", runs=2, seed=4)
    design = plan_runs(problem)
    stop_at = float(design.v0[1])
    monkeypatch.setattr(_visc, "simulate_closed_loop", loop)
    records, failures = _visc._simulate_startups(problem, design)
    assert records[0] is not None and records[1] is None
    assert failures == ["run 1: stopped: step budget exhausted"]
    monkeypatch.setattr(_visc, "sampled_batch", batch)
    ideal = ViscosityProblem(CAROUSEL, "ideal", runs=3, seed=4)
    records, failures = _visc._simulate_startups(ideal, plan_runs(ideal))
    assert records[1] is None and records[0] is not None and records[2] is not None
    assert failures == ["run 1: a plant step stopped (code 3)"]
    monkeypatch.undo()
    assert viscosity_check(problem, workers=2).ok.all()
