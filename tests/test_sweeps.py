"""Sweeps: keyed random numbers, chunking, schedulers (local, process pool, Dask LocalCluster)
and the median-law experiment against closed forms."""

from __future__ import annotations

import sys

import numpy as np
import pytest

import toolkit as tk
from toolkit import ContactSet, ParameterError, ParameterTypeError, simulate_batch
from toolkit.experiments import (MeanMedian, MedianLaw, Outliers, ResidualFriction, carousel_wheels,
                                 ideal_median_law_slope, median_law_slope)
from toolkit.sweeps import RunKeys, run_keys, sweep

#: Every experiment with its non-idealities switched on, and a run count small enough to
#: sweep it several times (chunking, schedulers).
NONIDEAL = [
    (MedianLaw(friction_spread=0.2, wheel_radius_bias=0.01, wheel_radius_std=0.02, contact_radius_error=0.01,
               damping=0.1, compliance=0.02), 24),
    (MedianLaw(friction_spread=0.36, wheel_seed=0, wheel_radius_std=0.02), 24),
    (MeanMedian(friction_spread=0.3), 24),
    (Outliers(friction_spread=0.3, compliance=0.02, window=1.0), 6),
    (ResidualFriction(n=1, friction_spread=0.3, bearing_friction=0.05, bearing_drag=0.1, probes=16), 12),
]


def test_run_keys_draw_numpys_philox_streams():
    # Second method: the compiled counter-based draws of runs 3..11 (stream 2, seed above
    # 2**64: both key words used) are NumPy's Philox with counter (0, 0, i, 2) and that key,
    # bit for bit, and any grouping of the runs gives the same rows (identity).
    seed = 2**70 + 12345
    keys = run_keys(seed, 3, 12)
    u = keys.uniform(2, 9)
    for j in range(9):
        reference = np.random.Generator(np.random.Philox(counter=[0, 0, 3 + j, 2],
                                                         key=[seed % 2**64, seed >> 64]))
        np.testing.assert_array_equal(u[j], reference.random(9))
        np.testing.assert_array_equal(keys.generator(j, 2).random(9), u[j])
    np.testing.assert_array_equal(run_keys(seed, 7, 9).uniform(2, 9), u[4:6])
    np.testing.assert_array_equal(keys.uniform(2, 9, -0.35, 0.35), -0.35 + 0.7 * u)
    assert not np.array_equal(keys.uniform(1, 9), u)           # another stream
    with pytest.raises(ParameterError, match="'seed' parameter of run_keys"):
        run_keys(2**128, 0, 1)


def test_run_keys_normals_are_standard_normal():
    # Box-Muller on the keyed uniforms: mean 0, variance 1 and independent pairs, over 2e5
    # draws (standard errors 0.0022 for the mean, 0.0032 for the variance and the
    # correlation: tolerances 5 of them); a Kolmogorov-Smirnov test against scipy's normal
    # CDF at the 1e-3 level.
    from scipy import stats

    z = RunKeys(5, 0, 20_000).normal(1, 10)
    assert z.shape == (20_000, 10)
    assert abs(z.mean()) < 5 * 0.0022 and abs(z.var() - 1.0) < 5 * 0.0032
    assert abs(np.corrcoef(z[:, 0], z[:, 1])[0, 1]) < 5 * 0.0071
    assert stats.kstest(z.ravel(), "norm").pvalue > 1e-3


def test_tables_do_not_depend_on_chunking():
    # Each run depends on its own seed only, so any grouping gives the same numbers, bit for bit.
    a = sweep(MedianLaw(), 300, seed=3, chunk_size=7).table
    b = sweep(MedianLaw(), 300, seed=3, chunk_size=300).table
    assert a.equals(b)
    assert list(a["run"]) == list(range(300))


@pytest.mark.parametrize(("experiment", "runs"), NONIDEAL, ids=lambda x: getattr(x, "name", str(x)))
def test_every_experiment_with_nonidealities_does_not_depend_on_chunking(experiment, runs):
    # Identity: run i's numbers depend on (seed, i) only (its own carousel from its own child
    # sequence, or the one carousel of wheel_seed), so chunks of 1, 5 and all give the same
    # table bit for bit.
    tables = [sweep(experiment, runs, seed=4, chunk_size=c).table for c in (1, 5, runs)]
    assert tables[0].equals(tables[1]) and tables[0].equals(tables[2])


@pytest.mark.slow
@pytest.mark.wall_clock      # a Dask cluster starts within timeouts: one at a time
def test_process_pool_and_dask_give_identical_tables_for_every_experiment():
    # The chunks are the same wherever they run: local, a process pool (fresh interpreters) and
    # a Dask LocalCluster give identical tables, bit for bit, for every experiment with its
    # non-idealities.
    local = [sweep(e, runs, seed=6, chunk_size=4).table for e, runs in NONIDEAL]
    for (experiment, runs), table in zip(NONIDEAL, local):
        pooled = sweep(experiment, runs, seed=6, chunk_size=4, scheduler="processes", workers=2)
        assert pooled.table.equals(table), experiment.name
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster:
        for (experiment, runs), table in zip(NONIDEAL, local):
            remote = sweep(experiment, runs, seed=6, chunk_size=4, scheduler=cluster.scheduler_address)
            assert remote.scheduler == "dask" and remote.table.equals(table), experiment.name


def test_one_wheel_seed_is_one_carousel_in_every_experiment():
    # The wheels of wheel_seed come from carousel_wheels in one fixed draw order (radius
    # normals first, always): the same loads in all four experiments, whether or not the
    # wheel radii are spread (identity, bit for bit).
    _, loads = carousel_wheels(np.random.default_rng(0), 10, 0.2, 0.36)
    keys = run_keys(1, 0, 3)
    for experiment in (MedianLaw(friction_spread=0.36, wheel_seed=0),
                       MedianLaw(friction_spread=0.36, wheel_seed=0, wheel_radius_std=0.05)):
        np.testing.assert_array_equal(experiment.draw(keys)[2], np.tile(loads, (3, 1)))
    np.testing.assert_array_equal(MeanMedian(friction_spread=0.36, wheel_seed=0).loads(keys), np.tile(loads, (3, 1)))
    np.testing.assert_array_equal(Outliers(friction_spread=0.36, wheel_seed=0).plant(keys)[0].contacts.forces,
                                  loads)
    np.testing.assert_array_equal(ResidualFriction(friction_spread=0.36, wheel_seed=0).contacts(keys).forces,
                                  loads)


def test_settled_check_reads_the_one_run_at_half_time():
    # The settled check needs the speed at half the horizon: simulate_batch(t_probe=...) reads
    # it from the run's own closed-form segments. Second method: a second batch stopped at
    # that time (the old way), rtol 1e-12 / atol 1e-15 (the same segment, evaluated at a
    # time inside it instead of as the end of a run). Drag makes some runs still move at the
    # probe (exponential approach); a short horizon leaves others before their stop.
    rng = np.random.default_rng(31)
    speeds = rng.uniform(-0.35, 0.35, (300, 10))
    forces = rng.uniform(0.1, 0.3, (300, 10))
    for t_end, damping in ((0.3, 0.0), (20.0, 0.5), (20.0, 0.0)):
        whole = simulate_batch(speeds, forces, 1.0, t_end, damping=damping, t_probe=0.5 * t_end)
        half = simulate_batch(speeds, forces, 1.0, 0.5 * t_end, damping=damping)
        np.testing.assert_allclose(whole.probe_speeds, half.final_speeds, rtol=1e-12, atol=1e-15)
    # The median law's settled column is the old two-run rule, run by run.
    experiment = MedianLaw(settle_time=0.2, damping=0.2)
    table = sweep(experiment, 200, seed=8).table
    _, actual, forces = experiment.draw(run_keys(8, 0, 200))
    old = np.abs(simulate_batch(actual, forces, 1.0, 0.2, damping=0.2).final_speeds
                 - simulate_batch(actual, forces, 1.0, 0.1, damping=0.2).final_speeds) <= 1e-9
    np.testing.assert_array_equal(table["settled"].to_numpy(), old)
    assert 0 < old.sum() < 200


def test_even_n_from_rest_stops_at_the_near_band_edge():
    # Closed form (docs/physics.md section 6): ideal plant, equal loads, from rest the body stops at
    # clip(0, lo, hi) with [lo, hi] the zero-force band. The exact batch lands on the contact
    # speed itself, so the match is to rounding of the motion (atol 1e-15 m/s).
    experiment = MedianLaw(n=10)
    result = sweep(experiment, 200, seed=11)
    commanded, actual, forces = experiment.draw(run_keys(11, 0, 200))
    expected = [np.clip(0.0, *ContactSet(actual[j], forces[j]).equilibrium()) for j in range(200)]
    np.testing.assert_allclose(result.table["speed"], expected, rtol=0, atol=1e-15)
    np.testing.assert_array_equal(result.table["median"], np.median(commanded, axis=1))
    assert result.table["settled"].all()


def test_ideal_population_slope_two_ways():
    # The quadrature of ideal_median_law_slope against (a) a direct Monte Carlo of the closed
    # form y = clip(0, v_(5), v_(6)), x = (v_(5) + v_(6)) / 2 over 400000 sets (its slope's
    # standard error is about 0.009 sqrt(660 / 4e5) = 3.7e-4: tolerance 4 of them, 1.5e-3) and
    # (b) the exact simulator's sweep of 20000 runs, within 3 of the fit's own standard errors.
    population = ideal_median_law_slope(10)
    v = np.sort(np.random.default_rng(12).uniform(-1.0, 1.0, (400_000, 10)), axis=1)
    x, y = 0.5 * (v[:, 4] + v[:, 5]), np.clip(0.0, v[:, 4], v[:, 5])
    assert population == pytest.approx(float(x @ y) / float(x @ x), rel=0, abs=1.5e-3)
    summary = sweep(MedianLaw(), 20_000, seed=21).summary
    assert abs(summary["slope"] - population) < 3 * summary["slope_stderr"]
    # n = 2: y = clip(0, a, b) is 0 unless both speeds share a sign; E[xy] / E[x^2] by hand:
    # E[x^2] = E[(a+b)^2]/4 = (2/3 + 0)/4 = 1/6 (uniform on [-1, 1], independent), and
    # E[xy] = 2 P(both > 0) E[(a+b)/2 min(a, b) | both in (0, 1)] = 2 (1/4) (5/24) = 5/48
    # (min of two uniforms on (0,1): E[min^2] = 1/6, E[max min] = E[a b] = 1/4), so 5/8.
    assert ideal_median_law_slope(2) == pytest.approx(5 / 8, rel=1e-9)
    assert ideal_median_law_slope(9) == 1.0


def test_odd_n_follows_the_median_exactly():
    # Odd n, equal loads: the equilibrium is the median contact itself, slope 1 and every
    # ratio 1 (to the rounding of the exact motion: rtol 1e-12).
    result = sweep(MedianLaw(n=11), 150, seed=2)
    np.testing.assert_allclose(result.table["speed"], result.table["median"], rtol=1e-12, atol=1e-15)
    assert result.summary["slope"] == pytest.approx(1.0, rel=1e-12)


def test_slope_fit_closed_form():
    # y = 2 x exactly -> slope 2, stderr 0; y = x + r with r orthogonal to x -> slope 1 and,
    # by hand, stderr = sqrt(|r|^2 / (k - 1) / |x|^2) = sqrt(10 / 2 / 14).
    x = np.array([1.0, -2.0, 3.0])
    assert median_law_slope(x, 2 * x) == (2.0, 0.0)
    slope, stderr = median_law_slope(x, x + np.array([3.0, 0.0, -1.0]))   # r . x = 0
    assert slope == pytest.approx(1.0, rel=1e-15)
    assert stderr == pytest.approx(np.sqrt(10 / 2 / 14), rel=1e-15)
    # second method: numpy's least squares for the slope and the textbook standard error of a
    # regression through the origin, s^2 (X^T X)^-1 with s^2 = RSS / (k - 1) (rtol 1e-12)
    rng = np.random.default_rng(0)
    x = rng.normal(size=50)
    y = 0.7 * x + rng.normal(scale=0.1, size=50)
    coef, rss, _, _ = np.linalg.lstsq(x[:, None], y, rcond=None)
    slope, stderr = median_law_slope(x, y)
    assert slope == pytest.approx(coef[0], rel=1e-12)
    assert stderr == pytest.approx(np.sqrt(rss[0] / 49 * np.linalg.inv(x[:, None].T @ x[:, None])[0, 0]), rel=1e-12)


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
    _, actual, forces = experiment.draw(run_keys(9, 0, 120))
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
    _, actual, forces = experiment.draw(run_keys(4, 0, 100))
    expected = [np.clip(0.0, *ContactSet(actual[j], forces[j]).equilibrium()) for j in range(100)]
    settled = result.table["settled"].to_numpy()
    assert settled.mean() > 0.9            # a nearly balanced start can still creep at 20 s
    np.testing.assert_allclose(result.table["speed"][settled], np.array(expected)[settled], rtol=0, atol=1e-15)
    mean = forces.mean(axis=1) / (experiment.acceleration * experiment.mass / experiment.n)
    assert abs(mean.mean() - 1.0) < 0.02       # lognormal keeps the mean load (sd 0.2/sqrt(1000))


@pytest.mark.wall_clock
def test_process_pool_gives_identical_tables():
    local = sweep(MedianLaw(), 64, seed=8, chunk_size=16)
    pooled = sweep(MedianLaw(), 64, seed=8, chunk_size=16, scheduler="processes", workers=2)
    assert pooled.scheduler == "processes"
    assert pooled.table.equals(local.table)
    assert pooled.summary == local.summary


@pytest.mark.wall_clock
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
    result = sweep(Outliers(amplitude=0.3), 60, seed=3)
    table = result.table
    moved = table["deviation"].to_numpy() > 1e-12
    assert np.array_equal(moved, ~table["held"].to_numpy())
    # Both kinds of run occur: about 15 % of runs move, so all 60 held with probability
    # 0.85^60 ~ 6e-5 and all moved with less: not a property of this seed.
    assert 0 < moved.sum() < len(table)
    above = table["lowest_outlier"].to_numpy() > 0
    assert np.all(table["deviation"].to_numpy()[above] == 0.0)   # outliers above V*: untouched
    assert result.summary["rule_agreement"] == 1.0


@pytest.mark.parametrize("n", [1, 2, 3, 4, 5])
def test_residual_friction_ideal_split_is_n_over_5(n):
    # Closed forms: equal wheels give mu/mu0 = n/5 exactly and dT = m 2 v_max / (F_tot n/5)
    # (the exact event time; rtol 1e-12 for rounding).
    result = sweep(ResidualFriction(n=n), 3, seed=0)
    np.testing.assert_allclose(result.table["mu_ratio"], n / 5, rtol=1e-12)
    np.testing.assert_allclose(result.table["dT"], 1.0 * 2 * 0.35 / (2.0 * n / 5), rtol=1e-12)


def test_residual_friction_from_unequal_wheels_and_the_bearing():
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
    experiment = MeanMedian(held="median", level=0.05, gap=0.01, friction_spread=0.36, wheel_seed=0)
    result = sweep(experiment, 40, seed=2)
    keys = run_keys(2, 0, 40)
    loads = experiment.loads(keys)
    expected = [np.clip(0.0, *ContactSet(experiment.speeds(keys, j), loads[j]).equilibrium())
                for j in range(40)]
    np.testing.assert_allclose(result.table["speed"], expected, rtol=0, atol=1e-15)
    assert result.summary["speed_range"] == 0.0 and result.summary["mean_range"] > 0.03


def test_outliers_rule_with_unequal_wheels_on_settled_runs():
    # Unequal loads, ideal motors: on runs that had settled when the outliers started, the
    # weighted stiction rule still decides exactly whether the body moves.
    table = sweep(Outliers(friction_spread=0.36, wheel_seed=0), 30, seed=3).table
    settled = table["settled"].to_numpy()
    assert settled.sum() >= 15
    moved = table["deviation"].to_numpy() > 1e-12
    np.testing.assert_array_equal(moved[settled], ~table["held"].to_numpy()[settled])


@pytest.mark.parametrize("bearing", [0.0, 0.1, 0.35, 0.39])
def test_transition_time_with_a_bearing(bearing):
    # Closed form (n = 1, equal wheels, F_n = 0.4 N, m = 1 kg, v = 0.35 m/s): the bearing
    # brakes above 0 and helps below, dT = m v / (F_n - F_b) + m v / (F_n + F_b) (the exact
    # event time; rtol 1e-12 for rounding). At F_b = 0.39 N that is 35.4 s, twenty times the
    # ideal 1.75 s: the horizon must come from the weakest force on the way, not from F(0).
    table = sweep(ResidualFriction(n=1, bearing_friction=bearing), 1, seed=0).table
    expected = 0.35 / (0.4 - bearing) + 0.35 / (0.4 + bearing)
    assert table["dT"][0] == pytest.approx(expected, rel=1e-12)


def test_bearing_drag_adds_to_the_residual_friction():
    # Closed form: at n = 0 with equal wheels the rig reads |c V|, whose mean over an even
    # number of midpoint probes is exactly c v_max / 2; mu0 (all wheels one way) reads
    # sum f_i = 2 N because -c V cancels over the symmetric probes: mu/mu0 = c v / (2 F_tot)
    # (rtol 1e-12, rounding of the 64-term mean).
    for c in (0.5, 1.0):
        table = sweep(ResidualFriction(n=0, bearing_drag=c), 2, seed=0).table
        np.testing.assert_allclose(table["mu0"], 2.0, rtol=1e-12)
        np.testing.assert_allclose(table["mu_ratio"], c * 0.35 / 2 / 2.0, rtol=1e-12)


def test_residual_friction_divides_by_each_carousels_own_total():
    # mu0 = sum f_i of the run's own wheels (a Coulomb bearing and drag cancel over the
    # symmetric probes), so mu_ratio = |band force| / sum f_i (identities, rtol 1e-12).
    experiment = ResidualFriction(n=0, friction_spread=0.36, bearing_drag=0.0)
    keys = run_keys(3, 0, 20)
    table = sweep(experiment, 20, seed=3).table
    totals = np.array([experiment.contacts(keys.run(j)).forces.sum() for j in range(20)])
    np.testing.assert_allclose(table["mu0"], totals, rtol=1e-12)
    np.testing.assert_allclose(table["mu_ratio"], np.abs(table["band_force"]) / totals, rtol=1e-12)


def test_mean_median_reports_runs_that_have_not_settled():
    # From rest the body needs at least |V*| / (F_tot / m) to reach V* (F_tot / m = 2 m/s^2),
    # so with settle_time 1 ms no run whose stop is farther than 2 mm/s from 0 has settled;
    # the sweep's shortfalls then name the count (a CLI exit 3).
    from toolkit.scenes.study import sweep_shortfalls

    result = sweep(MeanMedian(held="median", level=0.05, gap=0.01, settle_time=0.001), 10, seed=1)
    assert not result.table["settled"].any()
    assert result.summary["settled_fraction"] == 0.0
    (shortfall,) = sweep_shortfalls(result)
    assert "10 of 10 runs had not settled" in str(shortfall)
    settled = sweep(MeanMedian(held="median", level=0.05, gap=0.01), 10, seed=1)
    assert settled.table["settled"].all() and sweep_shortfalls(settled) == []


def test_release_rise_closed_form():
    # Hold-then-release with compliant motors: a motor whose slip keeps its direction and stays
    # beyond k f of the settled speed keeps its load, rise exactly 0; one whose slip reverses
    # rises by 2 k f / (|u| - k f) (closed forms, rtol 1e-12).
    k = 0.05
    experiment = MedianLaw(compliance=k)
    keys = run_keys(5, 0, 30)
    rise = experiment.release_rise(keys)
    _, actual, forces = experiment.draw(keys)
    final = sweep(experiment, 30, seed=5).table["true_speed"].to_numpy()
    kf = k * forces
    checked = 0
    for j in range(30):
        for i in range(experiment.n):
            u, away = actual[j, i], abs(actual[j, i] - final[j])
            if abs(u) <= kf[j, i] or away < kf[j, i]:
                continue
            expected = 0.0 if np.sign(u - final[j]) == np.sign(u) else 2 * kf[j, i] / (abs(u) - kf[j, i])
            assert rise[j, i] == pytest.approx(expected, rel=1e-12, abs=1e-15)
            checked += 1
    assert checked > 200


@pytest.mark.parametrize(("build", "error", "match"), [
    (lambda: MedianLaw(n=10**5), ParameterError, "'n' parameter of MedianLaw must be <= 10000"),
    (lambda: MedianLaw(n=1e20), ParameterError, "'n' parameter of MedianLaw must be <= 10000"),
    (lambda: MedianLaw(wheel_radius_std=0.5), ParameterError, "'wheel_radius_std' parameter of MedianLaw must be <"),
    (lambda: MedianLaw(friction_spread=1e300), ParameterError, "'friction_spread' parameter of MedianLaw must be <="),
    (lambda: MedianLaw(speed_limit=1e300), ParameterError, "'speed_limit' parameter of MedianLaw must be <= 1000"),
    (lambda: MedianLaw(compliance=1e300), ParameterError, "'compliance' parameter of MedianLaw must droop"),
    (lambda: MedianLaw(settle_time=1e300), ParameterError, "'settle_time' parameter of MedianLaw must be <="),
    (lambda: MedianLaw(damping=1e300), ParameterError, "'damping' parameter of MedianLaw must be <="),
    (lambda: MedianLaw(name="x"), TypeError, "name"),
    (lambda: MeanMedian(n=10**7), ParameterError, "'n' parameter of MeanMedian must be <= 10000"),
    (lambda: MeanMedian(held=["mean"]), ParameterError, "'held' parameter of MeanMedian"),
    (lambda: MeanMedian(friction_spread=1e300), ParameterError, "'friction_spread' parameter of MeanMedian"),
    (lambda: Outliers(rate=1e9, window=1e9), ParameterError, "'window' parameter of Outliers must be <= 1e"),
    (lambda: Outliers(rate=1e9), ParameterError, "'window' parameter of Outliers must give at most"),
    (lambda: Outliers(frequency=30.0), ParameterError, "'frequency' parameter of Outliers must be <= rate / 2 = 25"),
    (lambda: Outliers(random_amplitude="no"), ParameterTypeError, "'random_amplitude' parameter of Outliers"),
    (lambda: Outliers(random_amplitude=0), ParameterTypeError, "'random_amplitude' parameter of Outliers"),
    (lambda: Outliers(compliance=1e300), ParameterError, "'compliance' parameter of Outliers"),
    (lambda: ResidualFriction(probes=10**10), ParameterError, "'probes' parameter of ResidualFriction must be <="),
    (lambda: ResidualFriction(n=6), ParameterError, "'n' parameter of ResidualFriction must be <= 5"),
    (lambda: ResidualFriction(bearing_drag=1e300), ParameterError, "'bearing_drag' parameter of ResidualFriction"),
    (lambda: ResidualFriction(wheel_seed=-1), ParameterError, "'wheel_seed' parameter of ResidualFriction"),
])
def test_bad_experiment_parameters_name_themselves(build, error, match):
    with pytest.raises(error, match=match):
        build()


@pytest.mark.parametrize(("kwargs", "error", "match"), [
    ({"scheduler": 5}, ParameterTypeError, "'scheduler' parameter of sweep must be None, 'processes'"),
    ({"scheduler": "Processes"}, ParameterError, "Did you mean 'processes'"),
    ({"scheduler": "threads"}, ParameterError, r"must be None, 'processes' or a Dask scheduler address tcp://"),
    ({"scheduler": ""}, ParameterError, "'scheduler' parameter of sweep"),
    ({"workers": 3}, ParameterError, "'workers' parameter of sweep must be given only with scheduler='processes'"),
    ({"workers": 0, "scheduler": "processes"}, ParameterError, "'workers' parameter of sweep must be >= 1"),
    ({"workers": "x"}, ParameterTypeError, "'workers' parameter of sweep"),
    ({"progress": "x"}, ParameterTypeError, "'progress' parameter of sweep"),
    ({"seed": 2**200}, ParameterError, "'seed' parameter of sweep must be < 2\\*\\*128"),
])
def test_bad_scheduler_and_workers(kwargs, error, match):
    with pytest.raises(error, match=match):
        sweep(MedianLaw(), 4, **kwargs)


def test_name_is_a_class_constant():
    # name is the experiment's key, not a field: fields() leaves it out and instances share it.
    from dataclasses import fields

    for cls in (MedianLaw, MeanMedian, Outliers, ResidualFriction):
        assert "name" not in {f.name for f in fields(cls)}
        assert cls().name == cls.name


# -- bootstrap: the sampling uncertainty of a sweep's numbers -----------------------------------
def test_bootstrap_of_a_mean_is_its_standard_error():
    # Closed form: the bootstrap distribution of a mean of n values has standard deviation
    # sd_pop / sqrt(n) (population sd, ddof 0). Estimated from 4000 resamples, the replicates'
    # sd carries a relative error of about 1 / sqrt(2 * 4000) = 1.1 %: rtol 5 % (4.5 sigma).
    from toolkit.sweeps import bootstrap

    result = tk.sweep(tk.MedianLaw(), 300, seed=5)
    speed = result.table["speed"].to_numpy()
    boot = bootstrap(result, lambda table: float(table["speed"].mean()), resamples=4000, seed=1)
    assert boot.value == pytest.approx(speed.mean(), rel=1e-12)
    assert boot.std == pytest.approx(speed.std() / np.sqrt(speed.size), rel=0.05)
    lo, hi = boot.interval(0.95)
    assert lo < boot.value < hi
    # A summary key recomputes the experiment's own statistic; map carries a function through.
    slope = bootstrap(result, "slope", resamples=200, seed=1)
    assert slope.value == pytest.approx(result.summary["slope"], rel=1e-12)
    bias = slope.map(lambda s: 1.065 / s - 1)
    np.testing.assert_allclose(bias.replicates, 1.065 / slope.replicates - 1, rtol=1e-15)
    # Same seed, same replicates.
    again = bootstrap(result, "slope", resamples=200, seed=1)
    np.testing.assert_array_equal(again.replicates, slope.replicates)


def test_bootstrap_refuses_what_it_cannot_resample():
    from toolkit.sweeps import bootstrap

    result = tk.sweep(tk.MedianLaw(), 20, seed=5)
    with pytest.raises(tk.ParameterError, match="Did you mean 'slope'"):
        bootstrap(result, "slop")
    with pytest.raises(tk.ParameterError, match="'resamples' parameter of bootstrap"):
        bootstrap(result, "slope", resamples=1)
    with pytest.raises(tk.ParameterTypeError, match="'result' parameter of bootstrap"):
        bootstrap(result.table, "slope")
