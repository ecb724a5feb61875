"""Plots of planar results: they take results and only draw (matplotlib imported when one is
drawn, no backend chosen here)."""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["plot_sliding_disc", "plot_planar_precision"]


def plot_sliding_disc(result: Any, radius: float, *, terminal_ratio: float | None = None,
                      axes: Any = None, title: str | None = None) -> Any:
    """Speed, rim speed and their ratio of a disc sliding and spinning to rest.

    Parameters
    ----------
    result : PlanarSimulationResult
    radius : float, m
    terminal_ratio : float, optional
        Drawn as a horizontal line on the ratio panel (e.g. the published 0.653).
    axes : pair of matplotlib Axes, optional
    title : str, optional

    Returns
    -------
    pair of matplotlib Axes
    """
    import matplotlib.pyplot as plt

    if axes is None:
        fig, axes = plt.subplots(1, 2, figsize=(10, 3.6))
    else:
        fig = axes[0].figure
    t = result.t
    speed, rim = result.speed, np.abs(result.omega) * radius
    axes[0].plot(t, speed, label="|V| (m/s)")
    axes[0].plot(t, rim, label="R |omega| (m/s)")
    axes[0].set_xlabel("time (s)")
    axes[0].set_ylabel("speed (m/s)")
    axes[0].legend()
    moving = (speed > 0) & (rim > 0)
    axes[1].plot(t[moving], speed[moving] / rim[moving], label="|V| / (R |omega|)")
    if terminal_ratio is not None:
        axes[1].axhline(terminal_ratio, color="k", linestyle="--", linewidth=0.8,
                        label=f"terminal {terminal_ratio:.4g}")
    axes[1].set_xlabel("time (s)")
    axes[1].set_ylabel("ratio")
    axes[1].legend()
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    return axes


def plot_planar_precision(report: Any, *, ax: Any = None, title: str | None = None) -> Any:
    """Error against run time of a :class:`~toolkit.planar.precision.PlanarPrecisionReport`
    (log-log, one line per method); returns the Axes."""
    import matplotlib.pyplot as plt

    if ax is None:
        fig, ax = plt.subplots(figsize=(5.5, 4))
    else:
        fig = ax.figure
    for method in sorted({row.method for row in report.rows}):
        rows = [r for r in report.rows if r.method == method and np.isfinite(r.max_error)]
        ax.loglog([r.wall_time for r in rows], [max(r.max_error, 1e-17) for r in rows], "o-", label=method)
    ax.axvline(report.reference.wall_time, color="k", linestyle=":", linewidth=0.8, label="exact (time)")
    ax.set_xlabel("wall time (s)")
    ax.set_ylabel("max error (m/s)")
    ax.legend()
    if title:
        ax.set_title(title)
    fig.tight_layout()
    return ax
