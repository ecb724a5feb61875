"""Sweeps: seeds, chunking, schedulers (local, process pool, Dask LocalCluster) and the
median-law experiment against closed forms."""

from __future__ import annotations

import sys

import numpy as np
import pytest

from toolkit import ContactSet, ParameterError, ParameterTypeError
from toolkit.experiments import MedianLaw, median_law_slope
from toolkit.sweeps import run_seeds, sweep


def test_run_seeds_are_the_spawned_children():
    # Identity: SeedSequence(seed, spawn_key=(i,)) is child i of SeedSequence(seed).spawn().
    children = np.random.SeedSequence(7).spawn(12)
    direct = run_seeds(7, 3, 12)
    for a, b in zip(children[3:], direct):
        assert np.array_equal(a.generate_state(4), b.generate_state(4))


def test_tables_do_not_depend_on_chunking():
    # Each run depends on its own seed only, so any grouping gives the same numbers, bit for bit.
    a = sweep(MedianLaw(), 300, seed=3, chunk_size=7).table
    b = sweep(MedianLaw(), 300, seed=3, chunk_size=300).table
    assert a.equals(b)
    assert list(a["run"]) == list(range(300))


def test_even_n_from_rest_stops_at_the_near_band_edge():
    # Closed form (PHYSICS.md section 4): ideal plant, equal loads, from rest the body stops at
    # clip(0, lo, hi) with [lo, hi] the zero-force band. The exact batch lands on the contact
    # speed itself, so the match is to rounding of the motion (atol 1e-15 m/s).
    experiment = MedianLaw(n=10)
    result = sweep(experiment, 200, seed=11)
    commanded, actual, forces = experiment.draw(run_seeds(11, 0, 200))
    expected = [np.clip(0.0, *ContactSet(actual[j], forces[j]).equilibrium()) for j in range(200)]
    np.testing.assert_allclose(result.table["speed"], expected, rtol=0, atol=1e-15)
    np.testing.assert_array_equal(result.table["median"], np.median(commanded, axis=1))
    assert result.table["settled"].all()
    assert result.summary["slope"] < 0.85          # far below 1: the edge, not the midpoint


def test_odd_n_follows_the_median_exactly():
    # Odd n, equal loads: the equilibrium is the median contact itself, slope 1 and every
    # ratio 1 (to the rounding of the exact motion: rtol 1e-12).
    result = sweep(MedianLaw(n=11), 150, seed=2)
    np.testing.assert_allclose(result.table["speed"], result.table["median"], rtol=1e-12, atol=1e-15)
    assert result.summary["slope"] == pytest.approx(1.0, rel=1e-12)


def test_slope_fit_closed_form():
    # y = 2 x exactly -> slope 2, stderr 0; y = x + r with r orthogonal to x -> slope 1.
    x = np.array([1.0, -2.0, 3.0])
    assert median_law_slope(x, 2 * x) == (2.0, 0.0)
    slope, _ = median_law_slope(x, x + np.array([3.0, 0.0, -1.0]))   # r . x = 0
    assert slope == pytest.approx(1.0, rel=1e-15)


def test_calibration_errors_scale_the_slope_exactly():
    # Contact-radius error e divides every reported speed by (1 + e); a common wheel-radius
    # bias b scales every contact speed, hence every equilibrium, by (1 + b) (identities;
    # rtol 1e-12 for rounding of the products).
    base = sweep(MedianLaw(), 200, seed=5)
    radius = sweep(MedianLaw(contact_radius_error=0.05), 200, seed=5)
    np.testing.assert_allclose(radius.table["speed"], base.table["speed"] / 1.05, rtol=1e-12)
    bias = sweep(MedianLaw(wheel_radius_bias=0.03), 200, seed=5)
    np.testing.assert_allclose(bias.table["speed"], base.table["speed"] * 1.03, rtol=1e-12, atol=1e-15)
    assert bias.summary["slope"] == pytest.approx(1.03 * base.summary["slope"], rel=1e-12)


def test_compliance_moves_the_stop_into_the_band_by_k_f():
    # Closed form: a compliant contact's force is saturated-linear with width k f, so the body
    # from rest stops at clip(0, min(lo + k f, mid), max(hi - k f, mid)) where no other
    # contact lies within k f of the stop (runs where one does are left out). atol 1e-12 m/s.
    k = 0.02
    experiment = MedianLaw(compliance=k)
    result = sweep(experiment, 120, seed=9)
    _, actual, forces = experiment.draw(run_seeds(9, 0, 120))
    kf = k * forces[0, 0]
    checked = 0
    for j in range(120):
        lo, hi = ContactSet(actual[j], forces[j]).equilibrium()
        mid = 0.5 * (lo + hi)
        stop = float(np.clip(0.0, min(lo + kf, mid), max(hi - kf, mid)))
        others = np.abs(actual[j] - stop)
        if np.sum(others < 2 * kf) <= (1 if stop != 0.0 else 0) and (hi - lo) > 2 * kf:
            assert result.table["speed"][j] == pytest.approx(stop, abs=1e-12)
            checked += 1
    assert checked > 60


def test_unequal_friction_moves_the_stop_to_the_weighted_median():
    # With a friction spread the equilibrium is the weighted median of the actual contacts
    # (a point almost surely); from rest the body stops there or at its near edge.
    experiment = MedianLaw(friction_spread=0.2)
    result = sweep(experiment, 100, seed=4)
    _, actual, forces = experiment.draw(run_seeds(4, 0, 100))
    expected = [np.clip(0.0, *ContactSet(actual[j], forces[j]).equilibrium()) for j in range(100)]
    settled = result.table["settled"].to_numpy()
    assert settled.mean() > 0.9            # a nearly balanced start can still creep at 20 s
    np.testing.assert_allclose(result.table["speed"][settled], np.array(expected)[settled], rtol=0, atol=1e-15)
    mean = forces.mean(axis=1) / (experiment.acceleration * experiment.mass / experiment.n)
    assert abs(mean.mean() - 1.0) < 0.02       # lognormal keeps the mean load (sd 0.2/sqrt(1000))


def test_process_pool_gives_identical_tables():
    local = sweep(MedianLaw(), 64, seed=8, chunk_size=16)
    pooled = sweep(MedianLaw(), 64, seed=8, chunk_size=16, scheduler="processes", workers=2)
    assert pooled.scheduler == "processes"
    assert pooled.table.equals(local.table)
    assert pooled.summary == local.summary


def test_dask_local_cluster_gives_identical_tables():
    distributed = pytest.importorskip("distributed")
    local = sweep(MedianLaw(), 96, seed=12, chunk_size=16)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster:
        remote = sweep(MedianLaw(), 96, seed=12, chunk_size=16, scheduler=cluster.scheduler_address)
    assert remote.scheduler == "dask"
    assert remote.table.equals(local.table)
    assert remote.summary == local.summary


def test_scheduler_without_dask_says_what_to_install(monkeypatch):
    monkeypatch.setitem(sys.modules, "distributed", None)     # import distributed -> ImportError
    with pytest.raises(ParameterError, match=r"pip install 'active-contacts\[dask\]'"):
        sweep(MedianLaw(), 4, scheduler="tcp://127.0.0.1:8786")


@pytest.mark.parametrize(("kwargs", "error", "match"), [
    ({"runs": 0}, ParameterError, "'runs' parameter of sweep must be >= 1"),
    ({"runs": 2.5}, ParameterTypeError, "'runs' parameter of sweep"),
    ({"seed": -1}, ParameterError, "'seed' parameter of sweep must be >= 0"),
    ({"chunk_size": 0}, ParameterError, "'chunk_size' parameter of sweep"),
])
def test_bad_sweep_arguments(kwargs, error, match):
    arguments = {"runs": 4} | kwargs
    with pytest.raises(error, match=match):
        sweep(MedianLaw(), arguments.pop("runs"), **arguments)


def test_bad_experiment_and_parameters():
    with pytest.raises(ParameterTypeError, match="'experiment' parameter of sweep"):
        sweep(object(), 3)
    with pytest.raises(ParameterError, match="'friction_spread' parameter of MedianLaw must be >= 0"):
        MedianLaw(friction_spread=-0.1)
    with pytest.raises(ParameterError, match="'contact_radius_error' parameter of MedianLaw"):
        MedianLaw(contact_radius_error=0.7)


def test_mean_median_closed_forms():
    # Closed form: from rest the body stops at clip(0, m - g, m + g) (equal loads), so with the
    # median held every run gives one speed although the mean varies; with the mean held the
    # mean is one number (to rounding of the rescaling, atol 1e-15 m/s) and the speed follows
    # the median.
    from toolkit.experiments import MeanMedian

    held_median = sweep(MeanMedian(held="median", level=0.05, gap=0.01), 80, seed=1)
    table = held_median.table
    np.testing.assert_allclose(table["speed"], 0.04, rtol=0, atol=1e-15)
    assert held_median.summary["mean_range"] > 0.03
    held_mean = sweep(MeanMedian(held="mean", level=0.0, gap=0.01), 80, seed=1)
    table = held_mean.table
    np.testing.assert_allclose(table["mean"], 0.0, rtol=0, atol=1e-15)
    expected = np.clip(0.0, table["median"] - 0.01, table["median"] + 0.01)
    np.testing.assert_allclose(table["speed"], expected, rtol=0, atol=1e-15)


def test_outliers_move_the_body_exactly_when_the_stiction_rule_fails():
    # The rule 0 in [F(V*+), F(V*-)] at every instant decides whether the body moves: runs
    # that hold it keep V = V* exactly (deviation 0), the others move (> 1e-12 m/s).
    from toolkit.experiments import Outliers

    result = sweep(Outliers(amplitude=0.3), 24, seed=3)
    table = result.table
    moved = table["deviation"].to_numpy() > 1e-12
    assert np.array_equal(moved, ~table["held"].to_numpy())
    assert 0 < moved.sum() < len(table)                  # both kinds of run occur at this seed
    above = table["lowest_outlier"].to_numpy() > 0
    assert np.all(table["deviation"].to_numpy()[above] == 0.0)   # outliers above V*: untouched
    assert result.summary["rule_agreement"] == 1.0


@pytest.mark.parametrize("n", [1, 2, 3, 4, 5])
def test_residual_friction_ideal_split_is_n_over_5(n):
    # Closed forms: equal wheels give mu/mu0 = n/5 exactly and dT = m 2 v_max / (F_tot n/5)
    # (the exact event time; rtol 1e-12 for rounding).
    from toolkit.experiments import ResidualFriction

    result = sweep(ResidualFriction(n=n), 3, seed=0)
    np.testing.assert_allclose(result.table["mu_ratio"], n / 5, rtol=1e-12)
    np.testing.assert_allclose(result.table["dT"], 1.0 * 2 * 0.35 / (2.0 * n / 5), rtol=1e-12)


def test_residual_friction_from_unequal_wheels_and_the_bearing():
    from toolkit.experiments import ResidualFriction

    # Unequal wheels at n = 0: the band force sum_+ f_i - sum_- f_i has mean 0 and variance
    # s^2 * 10 f^2 (independent lognormal loads with mean f, relative std s). Over 4000 runs
    # the sample variance has a relative standard error of about sqrt(2/4000) ~ 2.2 % (a bit
    # more for the lognormal's tails): tolerance 12 %.
    s, f = 0.3, 0.2
    result = sweep(ResidualFriction(n=0, friction_spread=s), 4000, seed=5)
    band = result.table["band_force"].to_numpy()
    assert np.var(band, ddof=1) == pytest.approx(s * s * 10 * f * f, rel=0.12)
    assert abs(band.mean()) < 4 * np.sqrt(s * s * 10 * f * f / 4000)
    # A Coulomb bearing is a contact at speed 0: the rig reads F_b everywhere in the band.
    bearing = sweep(ResidualFriction(n=0, bearing_friction=0.18), 2, seed=0)
    np.testing.assert_allclose(bearing.table["mu_ratio"], 0.18 / 2.0, rtol=1e-12)


def test_unequal_loads_lognormal_moments():
    # spread 0: the mean exactly, nothing drawn; otherwise mean and relative std of the
    # lognormal (200000 draws: standard errors ~0.1 % and ~0.2 %, tolerances 1 %).
    from toolkit.model import unequal_loads

    rng = np.random.default_rng(0)
    np.testing.assert_array_equal(unequal_loads(0.2, 0.0, 5, rng), np.full(5, 0.2))
    assert rng.bit_generator.state == np.random.default_rng(0).bit_generator.state
    draws = unequal_loads(0.2, 0.3, 200_000, rng)
    assert draws.min() > 0
    assert draws.mean() == pytest.approx(0.2, rel=0.01)
    assert draws.std() / draws.mean() == pytest.approx(0.3, rel=0.01)


def test_mean_median_with_unequal_wheels_stops_at_the_weighted_equilibrium():
    # Closed form: from rest the body stops at clip(0, lo, hi) of the weighted equilibrium
    # set of the run's contacts (atol 1e-15 m/s); with the median pair held every run gives
    # one speed, whatever the mean (one carousel: the same loads in every run).
    from toolkit.experiments import MeanMedian

    experiment = MeanMedian(held="median", level=0.05, gap=0.01, friction_spread=0.36, wheel_seed=0)
    result = sweep(experiment, 40, seed=2)
    seeds = run_seeds(2, 0, 40)
    loads = experiment.loads(seeds)
    expected = [np.clip(0.0, *ContactSet(experiment.speeds(s), loads[j]).equilibrium())
                for j, s in enumerate(seeds)]
    np.testing.assert_allclose(result.table["speed"], expected, rtol=0, atol=1e-15)
    assert result.summary["speed_range"] == 0.0 and result.summary["mean_range"] > 0.03


def test_outliers_rule_with_unequal_wheels_on_settled_runs():
    # Unequal loads, ideal motors: on runs that had settled when the outliers started, the
    # weighted stiction rule still decides exactly whether the body moves.
    from toolkit.experiments import Outliers

    table = sweep(Outliers(friction_spread=0.36, wheel_seed=0), 30, seed=3).table
    settled = table["settled"].to_numpy()
    assert settled.sum() >= 15
    moved = table["deviation"].to_numpy() > 1e-12
    np.testing.assert_array_equal(moved[settled], ~table["held"].to_numpy()[settled])
