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

from __future__ import annotations

import contextlib
import contextvars
import math
from collections.abc import Callable, Iterator, Sequence
from typing import Any

import numpy as np

__all__ = ["plot_live", "plot_force_curve", "plot_simulation", "plot_schedule", "plot_precision", "plot_estimation",
           "plot_closed_loop", "figure_png", "render_png", "offscreen",
           "plot_median_law", "plot_ratio_histogram", "plot_mean_median", "plot_outliers",
           "plot_summary_comparison", "plot_sweep", "plot_viscosity_check", "plot_friction_fraction_check",
           "MAX_LINES"]

#: Most contact-speed lines drawn in one panel; larger sets are thinned (and the panel says so).
MAX_LINES = 50
#: Error level (m/s) marked in the work-precision plot: the level of the exact method's speed-up.
#: Samples of the closed-form minimum-time braking curve.
_BRAKING_SAMPLES = 64
#: Drawing order: contact speeds < prediction < exact simulation < target.
_Z_CONTACTS, _Z_PREDICTION, _Z_EXACT, _Z_TARGET = 1.0, 3.0, 4.0, 6.0


#: Set inside :func:`offscreen`: figures are made without pyplot.
_OFFSCREEN: contextvars.ContextVar[bool] = contextvars.ContextVar("toolkit_plots_offscreen", default=False)


@contextlib.contextmanager
def offscreen() -> Iterator[None]:
    """Within this context the functions of this module draw new figures as plain
    :class:`matplotlib.figure.Figure` objects, outside ``pyplot``: no backend is chosen or
    used, nothing is shown, nothing needs closing (for figures that only go to files)."""
    token = _OFFSCREEN.set(True)
    try:
        yield
    finally:
        _OFFSCREEN.reset(token)


def _subplots(nrows: int, ncols: int, figsize: tuple[float, float], **options: Any) -> np.ndarray:
    """A new figure's axes, shape (nrows, ncols): with ``pyplot`` (the user's backend), or
    :func:`offscreen` without it."""
    if _OFFSCREEN.get():
        from matplotlib.figure import Figure

        return Figure(figsize=figsize, layout="constrained").subplots(nrows, ncols, squeeze=False, **options)
    import matplotlib.pyplot as plt

    _, axes = plt.subplots(nrows, ncols, figsize=figsize, layout="constrained", squeeze=False, **options)
    return axes


def _figure(nrows: int = 1, figsize: tuple[float, float] = (6.0, 4.0)):
    return tuple(_subplots(nrows, 1, figsize, sharex=nrows > 1)[:, 0])


def _axes(ax: Any, figsize: tuple[float, float] = (6.0, 4.0)):
    return ax if ax is not None else _figure(1, figsize)[0]


def _title(ax: Any, title: str | None, what: str) -> None:
    """``"<title>: <what>"`` (the scene name first), or ``what`` alone."""
    ax.set_title(f"{title}: {what}" if title else what, fontsize="medium")


def _note(ax: Any, text: str, *, corner: str = "lower left", color: str = "0.25") -> None:
    """A small text note in a corner of the axes (axes coordinates)."""
    x, ha = (0.01, "left") if corner.endswith("left") else (0.99, "right")
    y, va = (0.01, "bottom") if corner.startswith("lower") else (0.99, "top")
    ax.text(x, y, text, transform=ax.transAxes, ha=ha, va=va, fontsize="x-small", color=color,
            gid="note")


def _thinned(n: int, order: np.ndarray | None = None) -> np.ndarray:
    """Indices of at most ``MAX_LINES`` of ``n`` lines, evenly spread over ``order``
    (e.g. the contacts sorted by speed, so the drawn ones span the whole set)."""
    order = np.arange(n) if order is None else np.asarray(order)
    if n <= MAX_LINES:
        return order
    return order[np.unique(np.linspace(0, n - 1, MAX_LINES).round().astype(int))]


def _thinning_note(ax: Any, shown: int, n: int) -> None:
    if shown < n:
        _note(ax, f"showing {shown} of {n} contact speeds", corner="upper left")


# -- force curve ------------------------------------------------------------------------------
def plot_force_curve(curve: Any, ax: Any = None, *, label: str | None = None,
                     title: str | None = None):
    """Draw a :class:`toolkit.scenes.study.CurveSamples`: the staircase, its set-valued steps, the equilibrium.

    Parameters
    ----------
    curve : CurveSamples
    ax : matplotlib Axes, optional
    label : str, optional
        Legend label of the staircase.
    title : str, optional
        The scene name, put first in the title.

    Returns
    -------
    matplotlib Axes
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
    _title(ax, title, "force-speed curve")
    ax.legend(loc="upper right", fontsize="small")
    return ax


# -- simulation -------------------------------------------------------------------------------
def _equilibrium(ax: Any, lo: float, hi: float, what: str) -> None:
    """Shade the equilibrium set on a speed axis: a band for a zero-force band, a line for a point."""
    if hi > lo:
        ax.axhspan(lo, hi, color="C2", alpha=0.25, lw=0, zorder=0.5, gid="equilibrium",
                   label=f"{what} [{lo:.4g}, {hi:.4g}] m/s (zero force)")
    else:
        ax.axhline(lo, color="C2", lw=1.2, ls="--", zorder=0.5, gid="equilibrium",
                   label=f"{what} {lo:.4g} m/s")


def plot_simulation(result: Any, ax: Any = None, *, plant: Any = None, title: str | None = None):
    """Draw body speed V(t) over the contact speeds v_i(t) of a simulation result.

    Parameters
    ----------
    result : SimulationResult
    ax : matplotlib Axes, optional
    plant : Plant, optional
        The simulated plant: its equilibrium set (:meth:`~toolkit.Plant.equilibrium`, the
        weighted median of the final commands) is shaded, a band when it is a zero-force
        band, a line when it is a point.
    title : str, optional
        The scene name, put first in the title.

    Notes
    -----
    At most ``MAX_LINES`` contact speeds are drawn, evenly spread over the contacts
    sorted by initial speed; a note on the axes says how many of how many. A run that did
    not succeed carries its status in a corner note (none for a successful run).

    Returns
    -------
    matplotlib Axes
    """
    ax = _axes(ax)
    t = np.asarray(result.t)
    speeds = np.asarray(result.contact_speeds)
    if speeds.ndim == 2 and speeds.shape[1] and t.size:
        n = speeds.shape[1]
        shown = _thinned(n, np.argsort(speeds[0], kind="stable"))
        ax.plot(t, speeds[:, shown], color="0.6", lw=0.8, zorder=_Z_CONTACTS)
        ax.plot([], [], color="0.6", lw=0.8, label="contact speeds v_i")
        _thinning_note(ax, shown.size, n)
    if plant is not None:
        lo, hi = plant.equilibrium()
        final = " of the final commands" if getattr(plant, "commands", None) is not None else ""
        _equilibrium(ax, lo, hi, "equilibrium set" + final)
    fine, V = t, np.asarray(result.V)
    if getattr(result, "dense", None) is not None and t.size:
        fine = np.union1d(t, np.linspace(t[0], t[-1], 1001))   # exact between events
        V = result.speed_at(fine)
    ax.plot(fine, V, color="k", lw=1.6, zorder=_Z_EXACT, label="body speed V")
    ax.set_xlabel("time t (s)")
    ax.set_ylabel("speed (m/s)")
    setting = f", {result.setting}" if getattr(result, "setting", "") else ""
    _title(ax, title, f"{result.method} simulation{setting}")
    if not result.success:
        _note(ax, f"{result.status.value} at t = {result.t_final:.4g} s", corner="upper right",
              color="C3")
    ax.legend(loc="best", fontsize="small")
    return ax


# -- schedule ---------------------------------------------------------------------------------
def _braking_curve(schedule: Any, plant: Any) -> tuple[np.ndarray, np.ndarray] | None:
    """The closed-form minimum-time trajectory of a fast braking schedule, or None.

    Every command jumps to the speed limit after the hold (one period when the motors lag);
    :func:`~toolkit.schedule.braking_time` gives the first time ``T(g)`` the body reaches
    each speed ``g`` between ``v0`` and the goal, and the curve is ``(T(g), g)``: the
    trajectory no schedule within the limits can get ahead of (comparison principle). None
    when the result carries no closed-form minimum time or the plant does not reproduce it.
    """
    from dataclasses import replace

    from .errors import ParameterError
    from .schedule import braking_time

    target = getattr(schedule, "target", None)
    if plant is None or schedule.minimum_time is None or getattr(target, "duration", 0.0) is not None:
        return None
    v0, goal = float(schedule.body_speed[0]), float(target.speed)
    motors = plant.motors
    hold = schedule.period if motors is not None and motors.dynamic else 0.0
    free = replace(plant, commands=None)
    try:
        levels = np.linspace(v0, goal, _BRAKING_SAMPLES + 1)[1:]
        arrival = np.array([braking_time(free, v0, g, hold=hold) for g in levels])
    except ParameterError:
        return None
    if not math.isclose(arrival[-1], schedule.minimum_time, rel_tol=1e-9, abs_tol=1e-12):
        return None                       # another plant or other limits than the design's
    end = max(float(schedule.times[-1]), float(arrival[-1]))
    return (np.concatenate(([0.0, hold], arrival, [end])),
            np.concatenate(([v0, v0], levels, [goal])))


def _target_curve(schedule: Any) -> tuple[np.ndarray, np.ndarray]:
    """The target at the schedule's times, plus the knots of a SpeedTrajectory within them."""
    times = np.asarray(schedule.times)
    target = getattr(schedule, "target", None)
    knots = getattr(target, "times", None)
    if knots is None or not callable(target):
        return times, np.asarray(schedule.reference)
    fine = np.union1d(times, knots[(knots >= times[0]) & (knots <= times[-1])])
    return fine, np.asarray(target(fine), dtype=float)


def _dense_exact(schedule: Any, check: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray | None] | None:
    """``(t, V_exact, target or None)`` between the controller times, from the dense output
    of ``check``; None without one. The target is known there for a SpeedTrajectory and a
    fast braking goal (a constant)."""
    if check is None or getattr(check, "dense", None) is None:
        return None
    times = np.asarray(schedule.times)
    end = min(float(times[-1]), float(check.t_final))
    fine = np.union1d(times[times <= end], np.linspace(0.0, end, min(32 * times.size, 4001)))
    V = check.speed_at(fine)
    target = getattr(schedule, "target", None)
    if callable(target):
        goal = np.asarray(target(fine), dtype=float)
    elif target is not None and getattr(target, "duration", 0.0) is None:
        goal = np.full(fine.shape, float(target.speed))
    else:
        goal = None
    return fine, V, goal


def plot_schedule(schedule: Any, check: Any = None, axes: Any = None, *, plant: Any = None,
                  title: str | None = None):
    """Draw a designed schedule over two panels: speeds, and the tracking error with its bounds.

    Top panel: the commanded contact speeds (steps), the predicted body speed, the exact
    simulation and, on top of them, the target. For a fast braking target (``Braking``
    without a duration) the target drawn is the closed-form minimum-time braking curve
    (needs ``plant``), not the goal speed from ``t = 0``.

    Bottom panel (log scale): the exact tracking error ``|V_exact - target|`` at the
    schedule's times (``exact_body_speed`` of the result against its ``reference``), the
    certified upper bound ``|V_pred - target| + prediction_bound`` (every solution of the
    exact model stays within ``prediction_bound`` of the prediction), and what no schedule
    beats: the ``lower_bound`` on the sup error (tracking), or the minimum-time curve's
    distance to the goal (fast braking).

    Parameters
    ----------
    schedule : ScheduleResult
    check : SimulationResult, optional
        An exact simulation of the schedule, drawn in the top panel in place of the result's
        own ``exact_body_speed`` (e.g. a denser one).
    axes : pair of matplotlib Axes, optional
        Speed panel and error panel; default a new figure with two rows sharing the time axis.
    plant : Plant, optional
        The plant the schedule was designed for (for the minimum-time braking curve).
    title : str, optional
        The scene name, put first in the title.

    Returns
    -------
    (Axes, Axes)
        The speed panel and the error panel.
    """
    top, bottom = axes if axes is not None else _figure(2, (6.0, 6.0))
    times = np.asarray(schedule.times)
    speeds = np.asarray(schedule.speeds)
    shown = _thinned(speeds.shape[1], np.argsort(speeds[0], kind="stable"))
    top.step(times, speeds[:, shown], where="post", color="0.7", lw=0.8, zorder=_Z_CONTACTS)
    top.plot([], [], color="0.7", lw=0.8, label="commanded contact speeds")
    _thinning_note(top, shown.size, speeds.shape[1])
    top.plot(times, schedule.body_speed, color="C0", lw=2.4, alpha=0.8, zorder=_Z_PREDICTION,
             label="predicted body speed")
    exact = np.asarray(schedule.exact_body_speed)
    has_exact = exact.size == times.size and bool(np.all(np.isfinite(exact)))
    dense = _dense_exact(schedule, check)
    if dense is not None:
        top.plot(dense[0], dense[1], color="k", lw=1.0, ls=(0, (1, 1)), zorder=_Z_EXACT,
                 label="exact simulation")
    elif check is not None:
        top.plot(check.t, check.V, color="k", lw=1.0, ls=(0, (1, 1)), zorder=_Z_EXACT,
                 label="exact simulation")
    elif has_exact:
        top.plot(times, exact, color="k", lw=1.0, ls=(0, (1, 1)), zorder=_Z_EXACT,
                 label="exact simulation")
    target = getattr(schedule, "target", None)
    fast_braking = target is not None and hasattr(target, "duration") and target.duration is None
    braking = _braking_curve(schedule, plant)
    target_style = dict(color="C3", lw=1.8, ls="--", zorder=_Z_TARGET, gid="target")
    if braking is not None:
        top.plot(*braking, **target_style,
                 label=f"target: minimum-time braking (closed form, {schedule.minimum_time:.4g} s)")
    elif fast_braking and schedule.minimum_time is not None:
        # Without the plant: the goal from the closed-form minimum time on (never before).
        start = float(schedule.minimum_time)
        top.plot([start, max(start, float(times[-1]))], [schedule.target.speed] * 2,
                 **target_style, label=f"target: goal, reached at the earliest at {start:.4g} s")
    else:
        top.plot(*_target_curve(schedule), **target_style, label="target")
    if schedule.minimum_time is not None:
        for ax in (top, bottom):
            ax.axvline(schedule.minimum_time, color="C3", lw=0.8, ls=":", zorder=_Z_CONTACTS)
    top.set_ylabel("speed (m/s)")
    _title(top, title, f"designed schedule ({schedule.method})")
    if not schedule.success:
        _note(top, schedule.status.value.split(":")[0] + ": " + schedule.message[:80],
              corner="upper right", color="C3")
    top.legend(loc="best", fontsize="x-small")

    reference = np.asarray(schedule.reference)
    certified = np.abs(np.asarray(schedule.body_speed) - reference) + schedule.prediction_bound
    bottom.plot(times, certified, color="C0", lw=1.2, ls="--", zorder=_Z_PREDICTION,
                gid="certified", label="certified bound |V_pred - target| + prediction bound (controller times)")
    if dense is not None and dense[2] is not None:
        bottom.plot(dense[0], np.abs(dense[1] - dense[2]), color="0.45", lw=0.8,
                    zorder=_Z_EXACT - 0.5, gid="dense error",
                    label="exact |V - target| between controller times")
    if has_exact:
        bottom.plot(times, np.abs(exact - reference), color="k", lw=0, marker="o", ms=2.5,
                    zorder=_Z_EXACT, gid="error", label="exact |V - target| at controller times")
    if braking is not None:
        bottom.plot(braking[0], np.abs(braking[1] - float(schedule.target.speed)), color="C3",
                    lw=1.2, ls="--", zorder=_Z_TARGET, gid="lower bound",
                    label="lower bound: minimum-time curve (no schedule is closer)")
    elif schedule.lower_bound is not None and schedule.lower_bound > 0:
        bottom.axhline(schedule.lower_bound, color="C3", lw=1.2, ls="--", zorder=_Z_TARGET,
                       gid="lower bound",
                       label=f"lower bound on the max error of any schedule ({schedule.lower_bound:.3g} m/s)")
    bottom.set_yscale("log", nonpositive="mask")
    bottom.set_xlabel("time t (s)")
    bottom.set_ylabel("tracking error (m/s)")
    bottom.legend(loc="best", fontsize="x-small")
    return top, bottom


# -- work-precision ---------------------------------------------------------------------------
#: Markers of the smoothing widths (one per distinct epsilon, finest last); unsmoothed: a disc.
_SMOOTHING_MARKERS = ("v", "s", "^", "D", "P", "X", "*")


def plot_precision(curves: Any, ax: Any = None, *, reference_time: float | None = None,
                   title: str | None = None, error_level: float | None = None):
    """Work-precision diagram: log-log error against wall time, one line per method family.

    As in DiffEqDevTools' work-precision diagrams, each family (a method with its integrator
    and friction law) is a line through its tolerance settings, named in the legend; a family
    smoothed at several widths ``epsilon`` has one line per width, in the family's colour and
    line style (solid for the first ten families, then dashed, then dotted), the width told by
    the marker (a second legend block). Unsmoothed families (``sign``, exact, Moreau) use
    discs.

    Parameters
    ----------
    curves : sequence of WorkPrecisionCurve
        From ``toolkit.analysis.precision.work_precision_curves``. Runs a budget stopped
        (or that failed) are drawn with hollow markers, explained in the legend (their error
        covers only the part they simulated).
    ax : matplotlib Axes, optional
    reference_time : float, optional, s
        Wall time of the exact method, drawn as a vertical line when its error is not
        measurable (no independent reference).
    title : str, optional
        The scene name, put first in the title.
    error_level : float, optional, m/s
        Drawn as a horizontal line.

    Notes
    -----
    A horizontal line marks ``error_level`` when given (the report passes
    ``toolkit.analysis.precision.ERROR_LEVEL``, 1e-6 m/s, the level of the exact
    method's speed-up). The legend sits beside the axes, so no label covers a point.

    Returns
    -------
    matplotlib Axes
    """
    ax = _axes(ax, (9.5, 5.5))
    floor = 1e-17   # an exact zero error drawn at the bottom of the log axis
    families = list(dict.fromkeys(curve.family or curve.method for curve in curves))
    colors = {family: f"C{index % 10}" for index, family in enumerate(families)}
    styles = {family: ("-", "--", ":")[min(index // 10, 2)] for index, family in enumerate(families)}
    widths = sorted({curve.smoothing for curve in curves if curve.smoothing is not None},
                    reverse=True)
    markers = {width: _SMOOTHING_MARKERS[index % len(_SMOOTHING_MARKERS)]
               for index, width in enumerate(widths)}
    hollow = False
    for curve in curves:
        family = curve.family or curve.method
        color, marker = colors[family], markers.get(curve.smoothing, "o")
        error = np.maximum(curve.max_error, floor)
        done = np.asarray(curve.success, dtype=bool)
        ax.loglog(curve.wall_time, error, styles[family], color=color, lw=1.2, zorder=2,
                  gid="family line")
        ax.loglog(curve.wall_time[done], error[done], marker, color=color, ms=5, ls="none", zorder=3)
        ax.loglog(curve.wall_time[~done], error[~done], marker, mfc="none", color=color, ms=5,
                  ls="none", zorder=3)
        hollow |= bool(np.any(~done))
    for family in families:                          # the legend: families, then widths
        ax.loglog([], [], styles[family], color=colors[family], lw=1.6, label=family, gid="family")
    for width in widths:
        ax.loglog([], [], markers[width], color="0.4", ls="none", label=f"epsilon = {width:g} m/s",
                  gid="smoothing")
    if hollow:
        ax.loglog([], [], "o", mfc="none", color="0.4", ls="none", gid="hollow",
                  label="hollow: stopped by a budget or failed\n(error over the part simulated)")
    if error_level is not None:
        shown = f"{error_level:.0e}".replace("e-0", "e-")
        ax.axhline(error_level, color="0.3", lw=0.8, ls="-.", zorder=1, gid="error level",
                   label=f"{shown} m/s error level")
        ax.text(0.995, error_level, f"{shown} m/s ", transform=ax.get_yaxis_transform(),
                ha="right", va="bottom", fontsize="x-small", color="0.3")
    if reference_time is not None:
        ax.axvline(reference_time, color="k", ls="--", lw=1, label="exact (the reference)")
    ax.set_xlabel("wall time per run (s)")
    ax.set_ylabel("max |V - V_exact| over the run (m/s)")
    _title(ax, title, "work-precision (error vs. run time)")
    ax.legend(fontsize="x-small", loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0)
    return ax


# -- estimation and the closed loop -------------------------------------------------------------
#: Line styles of the estimators (truth black; finite differences thin and pale).
_ESTIMATOR_STYLE = {"central_difference": dict(color="C7", lw=0.7, label="central finite difference"),
                    "wheel_difference": dict(color="C8", lw=0.7, label="wheel finite difference"),
                    "foaw_end": dict(color="C5", lw=0.8, label="FOAW end-fit"),
                    "foaw_best": dict(color="C6", lw=0.8, label="FOAW best-fit"),
                    "alpha_beta": dict(color="C9", lw=0.8, label="alpha-beta tracker"),
                    "kalman": dict(color="C0", lw=1.2, label="Kalman filter (default)"),
                    "kalman_nominal": dict(color="C1", lw=1.0, label="Kalman filter, nominal model"),
                    "rts": dict(color="C3", lw=1.0, ls="--", label="RTS smoother"),
                    "unscented": dict(color="C2", lw=1.0, label="unscented filter"),
                    "kalman_adaptive": dict(color="C4", lw=1.0, label="adaptive Kalman filter")}


#: The model-based filters an estimation figure is for: its error panel is scaled to them.
_FILTERS = ("kalman", "kalman_adaptive", "kalman_nominal", "rts", "unscented")
#: The error panel spans this many times the filters' largest error.
_ERROR_SPAN = 4.0


def plot_estimation(study: Any, axes: Any = None, *, title: str | None = None):
    """The estimators' speeds over time (top) and their errors against the truth (bottom); for
    a recorded file (no truth), their differences from the default Kalman filter's estimate.

    The error panel is the filters' (:data:`_FILTERS`): it spans :data:`_ERROR_SPAN` times
    their largest error, and an estimator whose error leaves that span (a finite difference,
    the alpha-beta tracker) is left out of it, named in the panel's legend; every estimator
    is in the top panel, with its RMS error.

    Parameters
    ----------
    study : EstimationStudy
        From :func:`toolkit.scenes.study.estimate_scene`.
    axes : pair of matplotlib Axes, optional
    title : str, optional
        The scene name.

    Returns
    -------
    pair of matplotlib Axes
    """
    top, bottom = axes if axes is not None else _figure(2, (7.0, 6.0))
    record = study.record
    t, truth = record.times, record.truth_speed
    against = "error"
    if truth is None:            # a recorded file: differences from the default filter (or the first)
        reference = next((r for r in study.results if r.method == "kalman"), study.results[0])
        truth, against = reference.speed, f"difference from {reference.method}"
    else:
        top.plot(t, truth, color="k", lw=1.6, label="truth V", zorder=_Z_EXACT)
    errors = {id(r): (r.speed - truth) * 1e3 for r in study.results}
    scale = [float(np.abs(errors[id(r)]).max()) for r in study.results if r.method in _FILTERS]
    limit = _ERROR_SPAN * max(scale) if scale and max(scale) > 0 else math.inf
    left_out = []
    for result in study.results:
        style = dict(_ESTIMATOR_STYLE.get(result.method, dict(lw=1.0, label=result.method)))
        name = style["label"]
        rms = f" (RMS {result.rms_error * 1e3:.3g} mm/s)" if result.rms_error is not None else ""
        style["label"] = name + rms
        top.plot(t, result.speed, **style)
        error = errors[id(result)]
        if result.method not in _FILTERS and np.abs(error).max() > limit:
            left_out.append(name)
            continue
        bottom.plot(t, error, **{**style, "label": name})
    top.set_ylabel("body speed (m/s)")
    bottom.set_ylabel(f"{against} (mm/s)")
    bottom.set_xlabel("time t (s)")
    if math.isfinite(limit):
        bottom.set_ylim(-limit, limit)
    if left_out:
        import textwrap

        bottom.plot([], [], ls="none", label=textwrap.fill(
            f"not shown, error beyond +-{limit:.3g} mm/s ({_ERROR_SPAN:g} x the filters'): {', '.join(left_out)}",
            width=50, break_on_hyphens=False))
    bottom.axhline(0.0, color="0.5", lw=0.5)
    bottom.legend(loc="lower right", fontsize="x-small")
    _title(top, title, f"speed from encoder counts at {1.0 / record.period:g} Hz")
    top.legend(loc="best", fontsize="x-small")
    return top, bottom


def plot_closed_loop(loop: Any, axes: Any = None, *, title: str | None = None,
                     what: str = "closed loop"):
    """Closed-loop body speed and the estimate the controller saw (top), commands (bottom).

    Parameters
    ----------
    loop : ClosedLoopResult
    axes : pair of matplotlib Axes, optional
    title : str, optional
        The scene name.
    what : str
        The loop's description in the title (e.g. the controller).

    Returns
    -------
    pair of matplotlib Axes
    """
    top, bottom = axes if axes is not None else _figure(2, (7.0, 6.0))
    t = loop.times
    top.plot(t, loop.speed, color="k", lw=1.6, label="body speed V", zorder=_Z_EXACT)
    if loop.record is not None:
        top.step(t, loop.estimate, where="post", color="C0", lw=1.0, label="estimate (controller input)")
    commands = np.asarray(loop.commands)
    n = commands.shape[1]
    shown = _thinned(n, np.argsort(commands[0], kind="stable"))
    bottom.step(t, commands[:, shown], where="post", color="0.5", lw=0.8)
    bottom.plot([], [], color="0.5", lw=0.8, label="commanded contact speeds")
    _thinning_note(bottom, shown.size, n)
    if np.any(loop.force != 0):
        twin = bottom.twinx()
        twin.step(t, loop.force, where="post", color="C1", lw=1.0)
        twin.set_ylabel("rig force (N)", color="C1")
    top.set_ylabel("speed (m/s)")
    bottom.set_ylabel("command (m/s)")
    bottom.set_xlabel("time t (s)")
    _title(top, title, what)
    if loop.status.name != "SUCCESS":
        _note(top, f"{loop.message} at t = {t[-1]:.4g} s", corner="upper right", color="C3")
    top.legend(loc="best", fontsize="small")
    bottom.legend(loc="best", fontsize="small")
    return top, bottom


def plot_live(result: Any, truth: Any = None, axes: Any = None, *, title: str | None = None):
    """A live run: the speed estimate with its 2-sigma band and, where known, the simulated
    device's true speed (top); the host's latency per sample against the deadline (bottom).

    Parameters
    ----------
    result : LiveResult
    truth : EncoderRecord, optional
        A simulated device's own record (its truth columns), matched by sequence number.
    axes : pair of matplotlib Axes, optional
    title : str, optional

    Returns
    -------
    pair of matplotlib Axes
    """
    top, bottom = axes if axes is not None else _figure(2, (7.0, 6.0))
    t = result.record.times
    sigma = np.sqrt(np.maximum(result.variance, 0.0))
    if truth is not None and truth.truth_speed is not None:
        top.plot(truth.times, truth.truth_speed, color="k", lw=1.6, label="true speed (simulated device)",
                 zorder=_Z_EXACT)
    top.fill_between(t, result.estimate - 2 * sigma, result.estimate + 2 * sigma, step="post", color="C0",
                     alpha=0.25, lw=0, label="2 sigma")
    top.step(t, result.estimate, where="post", color="C0", lw=1.0, label="estimate (controller input)")
    top.set_ylabel("speed (m/s)")
    latency = result.latency * 1e3
    bottom.plot(t, latency, ".", color="C2", ms=2, label="host latency")
    bottom.axhline(result.period * 1e3, color="C3", lw=1.0, label="deadline (one period)")
    bottom.set_yscale("log")
    bottom.set_ylabel("latency (ms)")
    bottom.set_xlabel("device time t (s)")
    _title(top, title, "live loop")
    if result.status.name != "COMPLETED":
        _note(top, result.message, corner="upper right", color="C3")
    top.legend(loc="best", fontsize="small")
    bottom.legend(loc="best", fontsize="small")
    return top, bottom


def figure_png(ax: Any) -> bytes:
    """Render the figure of ``ax`` (an Axes or a sequence of Axes of one figure, as
    :func:`plot_schedule` returns) to PNG bytes; a figure ``pyplot`` manages is closed."""
    import io

    if isinstance(ax, Sequence) or isinstance(ax, np.ndarray):
        ax = next(iter(np.ravel(np.asarray(ax, dtype=object))))
    figure = ax.figure
    buffer = io.BytesIO()
    figure.savefig(buffer, format="png", dpi=120)
    if getattr(figure.canvas, "manager", None) is not None:      # made by pyplot
        import matplotlib.pyplot as plt

        plt.close(figure)
    return buffer.getvalue()


def render_png(draw: Callable[..., Any], *args: Any, **kwargs: Any) -> bytes:
    """``draw(*args, **kwargs)`` (a function of this module) :func:`offscreen`, rendered to
    PNG bytes: what the reports write."""
    with offscreen():
        return figure_png(draw(*args, **kwargs))


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
        from .errors import suggestion
        from .errors import ParameterError, parameter_message

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
        from .errors import ParameterError, parameter_message

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
