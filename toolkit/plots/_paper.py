"""Figures of the paper's checks: the sweeps of its experiments (median law, mean against
median, outliers, residual friction) and the viscosity and friction-fraction checks.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from ._figure import _axes, _note, _subplots, _title


# -- sweeps of the paper's experiments ---------------------------------------------------------
def plot_median_law(results: Sequence[Any], ax: Any = None, *, labels: Sequence[str] | None = None,
                    paper_slope: float | None = 1.065, title: str | None = None):
    """Steady speed against the median contact speed (the paper's median law, its Fig. 3b),
    with the fit.

    Parameters
    ----------
    results : sequence of SweepResult
        Median-law sweeps (columns ``median``, ``speed``; summary ``slope``), e.g. the ideal
        model and a model with non-idealities, drawn over each other.
    labels : sequence of str, optional
    paper_slope : float or None
        Drawn as a dashed line (the paper's fit, 1.065).
    """
    ax = _axes(ax, (5.5, 4.5))
    labels = list(labels) if labels is not None else [f"sweep {j + 1}" for j in range(len(results))]
    reach = max(float(np.abs(r.table["median"]).max()) for r in results)
    line = np.array([-reach, reach])
    for result, label in zip(results, labels):
        slope = result.summary["slope"]
        points = ax.plot(result.table["median"], result.table["speed"], ".", ms=2.5, alpha=0.5,
                         label=f"{label}: slope {slope:.3f} +- {result.summary['slope_stderr']:.3f}")
        ax.plot(line, slope * line, color=points[0].get_color(), lw=1.2)
    if paper_slope is not None:
        ax.plot(line, paper_slope * line, "k--", lw=1, label=f"paper: slope {paper_slope:g}")
    ax.set_xlabel("median of the contact speeds (m/s)")
    ax.set_ylabel("steady body speed (m/s)")
    ax.legend(fontsize="x-small", loc="upper left")
    _note(ax, f"{results[0].runs} runs per sweep, fit y = k x through the origin", corner="lower right")
    _title(ax, title, "median law")
    return ax


def plot_ratio_histogram(results: Sequence[Any], ax: Any = None, *, labels: Sequence[str] | None = None,
                         title: str | None = None):
    """Histogram of ``speed / median`` over the runs with ``|median| > 0.1 v_max`` (the
    paper's inset of the median-law panel, its Fig. 3b)."""
    ax = _axes(ax, (5.0, 3.5))
    labels = list(labels) if labels is not None else [f"sweep {j + 1}" for j in range(len(results))]
    bins = np.linspace(0.0, 1.6, 41)
    for result, label in zip(results, labels):
        limit = 0.1 * result.experiment.speed_limit
        keep = np.abs(result.table["median"].to_numpy()) > limit
        ax.hist(np.clip(result.table["ratio"].to_numpy()[keep], bins[0], bins[-1]), bins=bins,
                histtype="step", lw=1.3, label=label)
    ax.axvline(1.0, color="k", lw=0.8, ls=":")
    _note(ax, f"ratios outside [{bins[0]:g}, {bins[-1]:g}] counted in the end bins", corner="upper left")
    ax.set_xlabel("steady speed / median")
    ax.set_ylabel("runs")
    ax.legend(fontsize="x-small")
    _title(ax, title, "speed / median")
    return ax


def plot_mean_median(held_mean: Any, held_median: Any, axes: Any = None, *, title: str | None = None):
    """The paper's mean-against-median panels (its Fig. 3c): speed against the median with
    the mean held (left) and against the mean with the median held (right)."""
    if axes is None:
        axes = tuple(_subplots(1, 2, (9.0, 3.6), sharey=True)[0])
    left, right = axes
    left.plot(held_mean.table["median"], held_mean.table["speed"], ".", ms=3)
    left.set_xlabel("median (m/s), mean held")
    left.set_ylabel("steady body speed (m/s)")
    right.plot(held_median.table["mean"], held_median.table["speed"], ".", ms=3, color="C1")
    right.set_xlabel("mean (m/s), median held")
    _title(left, title, "mean held, median varied")
    _title(right, title, "median held, mean varied")
    _note(right, f"speed range {held_median.summary['speed_range']:.2g} m/s over a mean range of "
                 f"{held_median.summary['mean_range']:.3g} m/s")
    return axes


def plot_outliers(result: Any, ax: Any = None, *, title: str | None = None):
    """Largest speed deviation against outlier amplitude; runs where the stiction rule held
    (the ideal model's prediction: no deviation) and where it failed."""
    ax = _axes(ax, (5.5, 3.8))
    table = result.table
    held = table["held"].to_numpy()
    floor = 1e-9
    deviation = np.maximum(table["deviation"].to_numpy(), floor)
    ax.semilogy(table["amplitude"][held], deviation[held], "o", ms=4, mfc="none", label="rule holds (predicted: none)")
    ax.semilogy(table["amplitude"][~held], deviation[~held], "x", ms=5, label="rule fails (outlier pulls)")
    ax.axhline(floor, color="0.6", lw=0.8, ls=":")
    ax.set_xlabel("outlier amplitude A (m/s)")
    ax.set_ylabel("largest |V - V*| (m/s)")
    ax.legend(fontsize="x-small")
    _note(ax, f"zero deviations drawn at {floor:g} m/s")
    _title(ax, title, "sinusoidal outliers")
    return ax


def plot_summary_comparison(values: dict[str, tuple[float, float]], ax: Any = None, *,
                            paper: tuple[float, float] | None = None, quantity: str = "slope",
                            title: str | None = None):
    """One summary statistic across model variants (value and standard error), with the
    paper's value and its uncertainty as a band.

    Parameters
    ----------
    values : dict of str to (float, float)
        Variant name -> (value, standard error).
    paper : (float, float), optional
        The paper's value and uncertainty.
    """
    ax = _axes(ax, (6.0, 0.45 * len(values) + 1.5))
    names = list(values)
    y = np.arange(len(names))[::-1]
    ax.errorbar([values[k][0] for k in names], y, xerr=[values[k][1] for k in names], fmt="o", capsize=3)
    if paper is not None:
        ax.axvspan(paper[0] - paper[1], paper[0] + paper[1], color="C3", alpha=0.2,
                   label=f"paper {paper[0]:g} +- {paper[1]:g}")
        ax.axvline(paper[0], color="C3", lw=1)
        ax.legend(fontsize="x-small", loc="lower right")
    ax.set_yticks(y, names, fontsize="small")
    ax.set_xlabel(quantity)
    _title(ax, title, f"{quantity} by model")
    return ax


def plot_sweep(result: Any, ax: Any = None, *, title: str | None = None):
    """The figure of one sweep, by experiment: median law (speed against median), outliers
    (deviation against amplitude), mean against median (speed against the varied quantity),
    residual friction (histogram of ``mu/mu0``)."""
    name = result.experiment.name
    if name == "median_law":
        return plot_median_law([result], ax, labels=[name], title=title)
    if name == "outliers":
        return plot_outliers(result, ax, title=title)
    ax = _axes(ax, (5.5, 3.8))
    table = result.table
    if name == "mean_median":
        varied = "median" if result.experiment.held == "mean" else "mean"
        ax.plot(table[varied], table["speed"], ".", ms=3)
        ax.set_xlabel(f"{varied} of the contact speeds (m/s), {result.experiment.held} held")
        ax.set_ylabel("steady body speed (m/s)")
        _title(ax, title, f"{result.experiment.held} held")
    elif name == "residual_friction":
        ax.hist(table["mu_ratio"], bins=40)
        ax.axvline(result.experiment.n / 5, color="k", lw=0.8, ls=":", label="ideal n/5")
        ax.set_xlabel("mu/mu0 (quasi-static)")
        ax.set_ylabel("runs")
        ax.legend(fontsize="x-small")
        _title(ax, title, f"residual friction, n = {result.experiment.n}")
    else:
        from ..errors import suggestion
        from ..errors import ParameterError, parameter_message

        raise ParameterError(parameter_message(
            "result", "plot_sweep", "be a sweep of median_law, mean_median, outliers or residual_friction",
            f"a sweep of {name!r}") + suggestion(name, ("median_law", "mean_median", "outliers",
                                                         "residual_friction")))
    return ax


def plot_viscosity_check(checks: Sequence[Any], ax: Any = None, *, labels: Sequence[str] | None = None,
                         definition: str | None = None, starts: str = "inside", title: str | None = None):
    """``1/tau`` against the commanded ``dF/dV / m`` (the paper's viscosity figure, its Fig. 5):
    each check's runs of one group of starts with their fit through the origin, the ideal
    model's prediction ``k_predicted`` and the purely viscous line.

    Parameters
    ----------
    checks : sequence of toolkit.predictions.ViscosityCheck
    definition : str, optional
        The time-constant definition drawn (default: each check's primary, ``"least_squares"``).
    starts : {"inside", "outside"}
        The group of starts drawn (the spread's inside by default).
    """
    ax = _axes(ax, (5.5, 4.5))
    labels = list(labels) if labels is not None else [c.problem.mode for c in checks]
    fits = [c.fit(definition, starts) for c in checks]
    if any(f is None for f in fits):
        from ..errors import ParameterError, parameter_message

        raise ParameterError(parameter_message("starts", "plot_viscosity_check",
                                               "name a group of starts every check has runs in", starts))
    name = fits[0].definition

    def group(c: Any) -> np.ndarray:
        return c.ok & (c.inside if starts == "inside" else ~c.inside)

    reach = max(float(np.max(c.slope[group(c)] / c.problem.apparatus.mass)) for c in checks)
    line = np.array([0.0, reach])
    for check, fit, label in zip(checks, fits, labels):
        use = group(check)
        x = check.slope[use] / check.problem.apparatus.mass
        points = ax.plot(x, 1.0 / check.tau[name][use], ".", ms=3, alpha=0.6,
                         label=f"{label}: k = {fit.k_fit:.3f}, R^2 {fit.r2:.3f}")
        ax.plot(line, fit.k_fit * line, color=points[0].get_color(), lw=1.2)
    ax.plot(line, fits[0].k_predicted * line, "k--", lw=1,
            label=f"ideal model: k = {fits[0].k_predicted:.3f}")
    ax.plot(line, line, color="0.6", lw=0.8, ls=":", label="purely viscous: k = 1")
    ax.set_xlabel("commanded dF/dV / m (1/s)")
    ax.set_ylabel(f"1 / tau (1/s), tau by {name}")
    ax.legend(fontsize="x-small", loc="upper left")
    _note(ax, f"{fits[0].runs} runs (starts {starts} the spread), {fits[0].n} contacts", corner="lower right")
    _title(ax, title, "startup time constant against viscosity")
    return ax


def plot_friction_fraction_check(checks: Sequence[Any], axes: Any = None, *,
                                 labels: Sequence[str] | None = None, title: str | None = None):
    """The paper's friction-fraction figure (its Fig. 6b, c): ``mu/mu0`` against the contacts
    reversed (left) and the transition time against ``mu/mu0`` with the prediction
    ``dT = m 2 v_max / (F_tot mu/mu0)`` (right).

    Parameters
    ----------
    checks : sequence of toolkit.predictions.FrictionFractionCheck
    """
    if axes is None:
        axes = tuple(_subplots(1, 2, (10.0, 3.8))[0])
    left, right = axes
    labels = list(labels) if labels is not None else [c.problem.mode for c in checks]
    for j, (check, label) in enumerate(zip(checks, labels)):
        marker = "os^v"[j % 4]
        left.plot(check.n, check.mu_ratio, marker, mfc="none", label=label)
        finite = np.isfinite(check.dT)
        right.plot(check.mu_ratio[finite], check.dT[finite], marker, mfc="none", label=label)
    first = checks[0]
    left.plot(first.n, first.mu_predicted, "k--", lw=1, label="ideal n/5")
    mu = np.linspace(0.15, 1.0, 64)
    moving = first.mu_predicted > 0
    scale = float(np.min(first.dT_predicted[moving] * first.mu_predicted[moving]))   # m 2 v_max / F_tot
    right.plot(mu, scale / mu, "k--", lw=1, label=f"dT = {scale:.3g} s / (mu/mu0)")
    left.set_xlabel("contacts reversed n")
    left.set_ylabel("mu / mu0")
    right.set_xlabel("mu / mu0")
    right.set_ylabel("transition time +v_max -> -v_max (s)")
    left.legend(fontsize="x-small")
    right.legend(fontsize="x-small")
    _title(left, title, "friction fraction")
    _title(right, title, "transition time")
    return axes
