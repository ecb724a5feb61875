"""Figures of the sweeps and prediction checks draw the data they are given."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")

import numpy as np  # noqa: E402
import pytest  # noqa: E402

import toolkit as tk  # noqa: E402


@pytest.fixture(scope="module")
def median_sweeps():
    return tk.sweep(tk.MedianLaw(), 60, seed=1), tk.sweep(tk.MedianLaw(friction_spread=0.2), 60, seed=1)


def test_median_law_plot_draws_the_runs_and_the_fits(median_sweeps):
    ideal, other = median_sweeps
    ax = tk.plot_median_law([ideal, other], labels=["ideal", "spread"])
    lines = ax.get_lines()
    # runs as points (identity), then each fit line with the summary's slope (rtol 1e-12)
    np.testing.assert_array_equal(lines[0].get_ydata(), ideal.table["speed"])
    x, y = lines[1].get_data()
    assert y[1] / x[1] == pytest.approx(ideal.summary["slope"], rel=1e-12)
    assert "paper: slope 1.065" in [t.get_text() for t in ax.get_legend().get_texts()]


def test_ratio_histogram_counts_the_kept_runs(median_sweeps):
    ideal, _ = median_sweeps
    ax = tk.plot_ratio_histogram([ideal])
    kept = np.abs(ideal.table["median"].to_numpy()) > 0.1 * 0.35
    counts, _ = np.histogram(np.clip(ideal.table["ratio"].to_numpy()[kept], 0, 1.6), bins=np.linspace(0, 1.6, 41))
    # The step outline's top edges are the bin counts (second method: numpy.histogram).
    (outline,) = ax.patches
    tops = outline.get_xy()[1:-1:2, 1]
    np.testing.assert_array_equal(tops[:counts.size], counts)


def test_sweep_plot_by_experiment():
    for experiment, runs in [(tk.MeanMedian(held="median", level=0.05), 10), (tk.Outliers(), 4),
                             (tk.ResidualFriction(n=1, friction_spread=0.1), 20)]:
        result = tk.sweep(experiment, runs, seed=0)
        ax = tk.plot_sweep(result, title="t")
        assert ax.get_title().startswith("t: ")


def test_summary_comparison_marks_the_paper_band():
    ax = tk.plot_summary_comparison({"a": (0.8, 0.01), "b": (1.0, 0.02)}, paper=(1.065, 0.01))
    (points,) = [line for line in ax.get_lines() if line.get_marker() == "o"]
    np.testing.assert_array_equal(points.get_xdata(), [0.8, 1.0])


def test_mean_median_plot_draws_both_panels():
    # Identity: the left panel's points are (median, speed) of the mean-held sweep, the right
    # panel's (mean, speed) of the median-held one; the note quotes its speed range.
    held_mean = tk.sweep(tk.MeanMedian(held="mean"), 12, seed=1)
    held_median = tk.sweep(tk.MeanMedian(held="median", level=0.05), 12, seed=2)
    left, right = tk.plot_mean_median(held_mean, held_median)
    (a,), (b,) = left.get_lines(), right.get_lines()
    np.testing.assert_array_equal(a.get_xdata(), held_mean.table["median"])
    np.testing.assert_array_equal(a.get_ydata(), held_mean.table["speed"])
    np.testing.assert_array_equal(b.get_xdata(), held_median.table["mean"])
    np.testing.assert_array_equal(b.get_ydata(), held_median.table["speed"])
    assert any("speed range 0 m/s" in t.get_text() for t in right.texts)


def test_outliers_plot_splits_the_runs_by_the_rule():
    # Runs where the rule held are circles, the others crosses, at (amplitude, max(deviation,
    # 1e-9)) (identity: the zero deviations are drawn on the 1e-9 m/s floor line).
    result = tk.sweep(tk.Outliers(window=1.0), 16, seed=3)
    ax = tk.plot_outliers(result)
    held_line, failed_line, floor = ax.get_lines()[:3]
    table = result.table
    held = table["held"].to_numpy()
    deviation = np.maximum(table["deviation"].to_numpy(), 1e-9)
    np.testing.assert_array_equal(held_line.get_xdata(), table["amplitude"][held])
    np.testing.assert_array_equal(held_line.get_ydata(), deviation[held])
    np.testing.assert_array_equal(failed_line.get_xdata(), table["amplitude"][~held])
    np.testing.assert_array_equal(failed_line.get_ydata(), deviation[~held])
    assert list(floor.get_ydata()) == [1e-9, 1e-9]


def test_viscosity_check_plot_draws_the_runs_and_the_three_lines():
    # Identity: the runs at (dF/dV / m, 1/tau) under the drawn definition; the fit line's
    # slope is k_fit, the ideal model's k_predicted, the purely viscous line's 1 (rtol 1e-12
    # for the division).
    from toolkit.predictions import ViscosityProblem, viscosity_check

    check = viscosity_check(ViscosityProblem(mode="ideal", runs=12, seed=0, start=(-1.0, 1.0)))
    for definition in ("least_squares", "crossing_63"):
        for starts in ("inside", "outside"):
            ax = tk.plot_viscosity_check([check], labels=["ideal"], definition=definition, starts=starts)
            points, fit, predicted, viscous = ax.get_lines()
            use = check.ok & (check.inside if starts == "inside" else ~check.inside)
            np.testing.assert_array_equal(points.get_xdata(), check.slope[use] / check.problem.apparatus.mass)
            np.testing.assert_array_equal(points.get_ydata(), 1.0 / check.tau[definition][use])
            expected = check.fit(definition, starts)
            for line, slope in ((fit, expected.k_fit), (predicted, expected.k_predicted), (viscous, 1.0)):
                x, y = line.get_data()
                assert y[1] / x[1] == pytest.approx(slope, rel=1e-12)
    only_inside = viscosity_check(ViscosityProblem(mode="ideal", runs=4, seed=0))
    with pytest.raises(tk.ParameterError, match="'starts' parameter of plot_viscosity_check"):
        tk.plot_viscosity_check([only_inside], starts="outside")


def test_friction_fraction_check_plot_draws_mu_and_dT_against_the_closed_forms():
    # Identity: left (n, mu/mu0) and the ideal n/5; right (mu/mu0, dT) where dT is finite and
    # the prediction dT = (m 2 v_max / F_tot) / (mu/mu0), 0.35 s / (mu/mu0) on the carousel
    # (closed form; rtol 1e-12).
    from toolkit.predictions import FrictionFractionProblem, friction_fraction_check

    check = friction_fraction_check(FrictionFractionProblem(mode="ideal"))
    left, right = tk.plot_friction_fraction_check([check], labels=["ideal"])
    points, ideal = left.get_lines()
    np.testing.assert_array_equal(points.get_xdata(), check.n)
    np.testing.assert_array_equal(points.get_ydata(), check.mu_ratio)
    np.testing.assert_allclose(ideal.get_ydata(), check.n / 5, rtol=1e-12)
    measured, predicted = right.get_lines()
    finite = np.isfinite(check.dT)
    np.testing.assert_array_equal(measured.get_xdata(), check.mu_ratio[finite])
    np.testing.assert_array_equal(measured.get_ydata(), check.dT[finite])
    x, y = predicted.get_data()
    np.testing.assert_allclose(x * y, 0.35, rtol=1e-12)


def test_plot_sweep_refuses_an_unknown_experiment():
    import dataclasses

    result = tk.sweep(tk.MedianLaw(), 3, seed=0)

    class Other:
        name = "mediann_law"

    with pytest.raises(tk.ParameterError, match="Did you mean 'median_law'"):
        tk.plot_sweep(dataclasses.replace(result, experiment=Other()))
