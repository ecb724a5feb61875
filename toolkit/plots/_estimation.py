"""Figures of estimation and control: the estimators against the truth, the closed loop and
a live run.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ._figure import _Z_EXACT, _figure, _note, _thinned, _thinning_note, _title

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
