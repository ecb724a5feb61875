"""Figures of the design and simulation stages: the force curve, a simulation, a designed
schedule and the work-precision diagram.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ._figure import (_Z_CONTACTS, _Z_EXACT, _Z_PREDICTION, _Z_TARGET, _axes, _figure, _note, _thinned,
                      _thinning_note, _title)

#: Samples of the closed-form minimum-time braking curve.
_BRAKING_SAMPLES = 64


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

    from ..errors import ParameterError
    from ..schedule import braking_time

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
