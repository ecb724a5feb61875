"""Figures. Each function takes computed results and an optional ``ax`` (``axes`` for two
panels) and only draws.

matplotlib is imported here and nowhere else; importing :mod:`toolkit` does not load it.
Every function takes a ``title`` (the scene name): figures leave the study that made them.

Backends: nothing here chooses or switches matplotlib's backend. Without ``ax`` a function
makes its figure with ``pyplot``, so it shows wherever the user's figures show (inline in
a notebook, a window in a script with ``plt.show()``). Figures written to files are drawn
:func:`offscreen` (:func:`render_png`): plain :class:`matplotlib.figure.Figure` objects that
no backend manages, so writing a report needs no backend, shows nothing and leaves the
user's ``pyplot`` state alone.
"""

from ._design import plot_force_curve, plot_precision, plot_schedule, plot_simulation
from ._estimation import _ESTIMATOR_STYLE, _FILTERS, plot_closed_loop, plot_estimation, plot_live
from ._figure import MAX_LINES, figure_png, offscreen, render_png
from ._paper import (plot_friction_fraction_check, plot_mean_median, plot_median_law, plot_outliers,
                     plot_ratio_histogram, plot_summary_comparison, plot_sweep, plot_viscosity_check)

__all__ = ["plot_live", "plot_force_curve", "plot_simulation", "plot_schedule", "plot_precision", "plot_estimation",
           "plot_closed_loop", "figure_png", "render_png", "offscreen",
           "plot_median_law", "plot_ratio_histogram", "plot_mean_median", "plot_outliers",
           "plot_summary_comparison", "plot_sweep", "plot_viscosity_check", "plot_friction_fraction_check",
           "MAX_LINES"]
