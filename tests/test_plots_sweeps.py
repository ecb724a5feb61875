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
