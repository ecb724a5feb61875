"""Figures. Each function takes computed results and an optional ``ax`` and only draws.

matplotlib is imported here and nowhere else; importing :mod:`toolkit` does not load it.
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["plot_force_curve", "plot_simulation", "plot_schedule", "plot_precision", "figure_png"]


def _axes(ax: Any):
    if ax is not None:
        return ax
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    _, ax = plt.subplots(figsize=(6.0, 4.0), layout="constrained")
    return ax


def plot_force_curve(curve: Any, ax: Any = None, *, label: str | None = None):
    """Draw a :class:`toolkit.study.CurveSamples`: the staircase, its set-valued steps, the equilibrium.

    Returns the axes.
    """
    ax = _axes(ax)
    # Exact staircase: at every sample the vertical from the upper to the lower end of the
    # set-valued force (a zero-length segment away from contact speeds).
    x = np.repeat(curve.speeds, 2)
    y = np.column_stack((curve.upper, curve.lower)).ravel()
    ax.plot(x, y, color="C0", label=label or "F(V) (vertical: stiction interval)")
    lo, hi = curve.equilibrium
    ax.axvspan(lo, hi, color="C2", alpha=0.3) if hi > lo else ax.axvline(lo, color="C2")
    ax.plot([], [], color="C2", label=f"equilibrium [{lo:.4g}, {hi:.4g}] m/s")
    ax.axhline(0.0, color="k", lw=0.5)
    ax.set_xlabel("body speed V (m/s)")
    ax.set_ylabel("net contact force F (N)")
    ax.legend(loc="upper right", fontsize="small")
    return ax


def plot_simulation(result: Any, ax: Any = None):
    """Draw body speed V(t) over the contact speeds v_i(t) of a simulation result. Returns the axes."""
    ax = _axes(ax)
    t = np.asarray(result.t)
    speeds = np.asarray(result.contact_speeds)
    if speeds.ndim == 2 and speeds.shape[1] <= 50:
        ax.plot(t, speeds, color="0.6", lw=0.8, drawstyle="default")
        ax.plot([], [], color="0.6", lw=0.8, label="contact speeds v_i")
    fine, V = t, np.asarray(result.V)
    if getattr(result, "dense", None) is not None and t.size:
        fine = np.union1d(t, np.linspace(t[0], t[-1], 1001))   # exact between events
        V = result.speed_at(fine)
    ax.plot(fine, V, color="k", lw=1.6, label="body speed V")
    ax.set_xlabel("time t (s)")
    ax.set_ylabel("speed (m/s)")
    ax.set_title(f"{result.method}: {result.status.value}", fontsize="small")
    ax.legend(loc="best", fontsize="small")
    return ax


def plot_schedule(schedule: Any, check: Any = None, ax: Any = None):
    """Draw a designed schedule: commanded contact speeds (steps), the reference, the predicted
    body speed and, if given, the exact simulation of the schedule. Returns the axes."""
    ax = _axes(ax)
    times = np.asarray(schedule.times)
    ax.step(times, schedule.speeds, where="post", color="0.7", lw=0.8)
    ax.plot([], [], color="0.7", lw=0.8, label="commanded contact speeds")
    ax.plot(times, schedule.reference, "C1--", label="target")
    ax.plot(times, schedule.body_speed, "C0", label="predicted body speed")
    if check is not None:
        ax.plot(check.t, check.V, "k:", lw=1.5, label="exact simulation")
    ax.set_xlabel("time t (s)")
    ax.set_ylabel("speed (m/s)")
    ax.legend(loc="best", fontsize="small")
    return ax


def plot_precision(curves: Any, ax: Any = None, *, reference_time: float | None = None):
    """Log-log error against wall time, one series per method.

    Parameters
    ----------
    curves : sequence of WorkPrecisionCurve
        From :func:`toolkit.precision.work_precision_curves`. Runs a budget stopped are drawn
        with open markers (their error covers only the part they simulated).
    """
    ax = _axes(ax)
    floor = 1e-17   # an exact zero error drawn at the bottom of the log axis
    for index, curve in enumerate(curves):
        color = f"C{index % 10}"
        error = np.maximum(curve.max_error, floor)
        ax.loglog([], [], "o", color=color, label=curve.method)   # settings differ in kind: no lines
        done = np.asarray(curve.success)
        ax.loglog(curve.wall_time[done], error[done], "o", color=color)
        ax.loglog(curve.wall_time[~done], error[~done], "o", mfc="none", color=color)
    if reference_time is not None:
        ax.axvline(reference_time, color="k", ls="--", lw=1, label="exact (the reference)")
    ax.set_xlabel("wall time per run (s)")
    ax.set_ylabel("max |V error| over the run (m/s)")
    ax.legend(fontsize="small")
    return ax


def figure_png(ax: Any) -> bytes:
    """Render the figure of ``ax`` to PNG bytes and close it."""
    import io

    import matplotlib.pyplot as plt

    buffer = io.BytesIO()
    ax.figure.savefig(buffer, format="png", dpi=120)
    plt.close(ax.figure)
    return buffer.getvalue()
