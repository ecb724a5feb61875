"""Turn study results into JSON and PNG files (the I/O side of :mod:`toolkit.scenes.study`).

Everything is rendered in memory first and then the output folder is replaced as a whole
(:func:`toolkit.scenes._io.write_tree`), so a failure leaves either the previous outputs or none.
An output folder holds the files of one command; a folder holding files the toolkit did not
write is refused.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from .. import plots
from ._io import atomic_write_text, write_tree
from ..analysis.precision import ERROR_LEVEL, work_precision_curves
from ..shortfall import Shortfall
from .study import StudyResult

__all__ = ["study_summary", "study_to_dict", "study_files", "write_study", "to_json", "schedule_csv",
           "schedule_check", "schedule_lines", "shortfall_dicts", "shortfall_line", "write_precision",
           "write_schedule", "estimation_to_dict", "estimation_lines", "estimation_files", "control_lines",
           "write_planar", "write_planar_precision", "planar_to_dict", "run_head", "RUN_KEYS"]


def _clean(value: Any) -> Any:
    """Make a value JSON-able: arrays to lists, non-finite floats to strings."""
    if isinstance(value, dict):
        return {str(k): _clean(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_clean(v) for v in value]
    if isinstance(value, np.ndarray):
        return _clean(value.tolist())
    if isinstance(value, (np.floating, float)):
        value = float(value)
        return value if math.isfinite(value) else str(value)
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, np.bool_):
        return bool(value)
    if hasattr(value, "value") and hasattr(value, "name"):  # enums: their human message
        return value.value
    return value


def to_json(data: Any) -> str:
    """Serialize with :func:`_clean` applied, indented, newline-terminated."""
    return json.dumps(_clean(data), indent=2) + "\n"


def _simulation_dict(sim: Any) -> dict[str, Any]:
    return {"method": sim.method, "status": sim.status, "message": sim.message,
            "final_speed": float(sim.V[-1]), "n_events": sim.n_events, "wall_time": sim.wall_time,
            "t": sim.t, "V": sim.V}


def schedule_csv(schedule: Any) -> str:
    """The schedule as CSV text: ``time_s, speed_0_mps, ...``, one row per controller period."""
    header, rows = schedule.to_rows()
    lines = [",".join(header)] + [",".join(repr(float(x)) for x in row) for row in rows]
    return "\n".join(lines) + "\n"


def schedule_check(schedule: Any, check: Any) -> dict[str, Any]:
    """How the exact nonsmooth simulation of a schedule compares with its prediction."""
    deviation = float(np.max(np.abs(np.asarray(check.V) - schedule.body_speed)))
    return {"method": check.method, "status": check.status, "max_deviation": deviation,
            "prediction_bound": float(schedule.prediction_bound),
            "within_bound": bool(deviation <= schedule.prediction_bound), "V": check.V}


def schedule_lines(schedule: Any, check: Any, shortfalls: Any = ()) -> list[str]:
    """Human lines on a designed schedule and its exact check.

    The last line is the status; for a target beyond the speed limits it is the
    ``"unreachable: ..."`` shortfall instead (such a schedule is the best possible, not
    what was asked for).
    """
    verified = schedule_check(schedule, check)
    head = f"schedule: {schedule.times.size - 1} periods of {schedule.period * 1e3:g} ms, {schedule.n} contacts; "
    if schedule.minimum_time is not None:
        arrival = "not reached" if schedule.arrival_time is None else f"{schedule.arrival_time:.4g} s"
        head += f"arrival {arrival} (closed-form minimum {schedule.minimum_time:.4g} s)"
    else:
        head += (f"tracking error {schedule.exact_tracking_error:.3g} m/s (exact model), lower bound "
                 f"{schedule.lower_bound:.3g} m/s")
    unreachable = [s.what for s in shortfalls if s.stage == "schedule" and s.what.startswith("unreachable")]
    return [head,
            f"exact simulation within {verified['max_deviation']:.2g} m/s of the prediction "
            f"(bound {verified['prediction_bound']:.2g} m/s)",
            unreachable[0] if unreachable else schedule.status.value]


def shortfall_dicts(shortfalls: Any) -> list[dict[str, Any]]:
    """JSON-able list of :class:`~toolkit.shortfall.Shortfall`."""
    return [shortfall.to_dict() for shortfall in shortfalls]


def shortfall_line(shortfalls: list[Shortfall] | tuple[Shortfall, ...]) -> str:
    """One line on everything missed: ``"shortfall: <stage>: <what>; ..."``."""
    return "shortfall: " + "; ".join(map(str, shortfalls))


def estimation_to_dict(study: Any) -> dict[str, Any]:
    """``estimators`` (a list of ``{name, rms, max_error, nees_mean, nees_band, wall_time,
    real_time_ratio}``: m/s, s), ``duration`` (the record's length, s) and ``compile_time``
    (s, the one-time cost paid before any estimator was timed), with the sample times, the
    truth and each estimator's speeds under ``series``."""
    return {"estimators": study.rows(), "duration": study.duration, "samples": study.record.n_samples,
            "compile_time": study.compile_time,
            "simulation_status": None if study.simulation is None else study.simulation.status,
            "series": {"times": study.record.times, "truth": study.record.truth_speed,
                       **{r.method: r.speed for r in study.results}}}


def estimation_csv(study: Any) -> str:
    """The estimates as CSV text: ``time_s``, then per estimator its speed and standard
    deviation (m/s) and, for the filters, the NIS of the central reading; one row per
    sample. A filter has no innovation at the first sample, so its NIS cell there is empty
    (a missing value to every CSV reader), never a number."""
    n = study.record.n_samples
    columns: list[tuple[str, Any]] = [("time_s", study.record.times)]
    for r in study.results:
        columns += [(f"{r.method}_speed_m_s", r.speed), (f"{r.method}_std_m_s", np.sqrt(r.variance))]
        if r.nis is not None:        # the innovations start at the second sample
            columns.append((f"{r.method}_nis", [None] * (n - r.nis.size) + r.nis.tolist()))
    lines = [",".join(name for name, _ in columns)]
    lines += [",".join("" if column[k] is None else repr(float(column[k])) for _, column in columns)
              for k in range(n)]
    return "\n".join(lines) + "\n"


def estimation_lines(study: Any) -> list[str]:
    """A table of the estimators' scores, one line each."""
    source = ("simulated" if study.simulation is not None else "recorded file"
              + (", no truth" if study.record.truth_speed is None else ", with the truth it carries"))
    lines = [f"estimation over {study.duration:g} s ({study.record.n_samples} samples, {source}):",
             f"  {'estimator':20} {'rms (mm/s)':>10} {'max (mm/s)':>10} {'NEES mean':>10} "
             f"{'in band':>7} {'NIS mean':>8} {'wall (ms)':>9} {'x real time':>11}"]

    def shown(value: Any, scale: float = 1.0, form: str = ".3g") -> str:
        return "-" if value is None else format(value * scale, form)

    for row in study.rows():
        lines.append(f"  {row['name']:20} {shown(row['rms'], 1e3):>10} {shown(row['max_error'], 1e3):>10} "
                     f"{shown(row['nees_mean']):>10} {shown(row['nees_in_band'], form='.2f'):>7} "
                     f"{shown(row['nis_mean']):>8} {row['wall_time'] * 1e3:9.3g} {row['real_time_ratio']:11.4g}")
    lines += [f"  {row['name']}: {row['monitor']}" for row in study.rows() if row["monitor"] is not None]
    lines.append(f"  ({compile_line(study.compile_time)})")
    return lines


def control_lines(study: Any) -> list[str]:
    """Human lines on a closed loop."""
    d = study.to_dict()
    seen = f"{d['estimator']} estimate" if d["estimator"] else "the true speed (ideal loop)"
    line = (f"closed loop ({d['controller']} on {seen}): V({d['times'][-1]:g} s) = {d['final_speed']:.6g} m/s, "
            f"{d['samples']} samples in {d['wall_time'] * 1e3:.1f} ms; {d['message']}")
    lines = [line]
    if d["estimator"]:
        lines.append(f"estimate error: RMS {d['estimate_rms_error'] * 1e3:.3g} mm/s, max "
                     f"{d['estimate_max_error'] * 1e3:.3g} mm/s")
    check = d["cross_check"]
    if check is not None:
        lines.append(f"cross-check against the smoothed model in python-control ({check['compared']}):")
        lines.append(f"  {'width (m/s)':>12} {'difference (m/s)':>17} {'order':>6}")
        orders = [None] + check["observed_orders"]
        for width, difference, order in zip(check["widths"], check["max_speed_differences"], orders):
            shown = "" if order is None else f"{order:.2f}"
            lines.append(f"  {width:12.3g} {difference:17.3g} {shown:>6}")
        lines.append(f"  fitted order {check['fitted_order']:.3g} (band {check['order_band'][0]:g} to "
                     f"{check['order_band'][1]:g}: {'converges' if check['converges'] else 'does NOT converge'}); "
                     f"{check['message']}")
    return lines


def estimation_files(study: Any, name: str, *, plots_too: bool = True) -> dict[str, bytes]:
    """``estimate.json``, ``estimate.csv`` (:func:`estimation_csv`) and (``plots_too``)
    ``estimate.png``, rendered in memory."""
    payload = {"estimate.json": to_json({"scene": name, **estimation_to_dict(study)}).encode(),
               "estimate.csv": estimation_csv(study).encode()}
    if plots_too:
        payload["estimate.png"] = plots.render_png(plots.plot_estimation, study, title=name)
    return payload


#: The keys every ``run --json`` (and ``result.json``, ``planar.json``) starts with, whatever
#: the scene's kind; the stages' results follow under their own names.
RUN_KEYS = ("scene", "stages", "met", "shortfalls", "compile_time")


def run_head(name: str, stages: Sequence[str], shortfalls: Any, compile_time: float) -> dict[str, Any]:
    """The :data:`RUN_KEYS` of a run: its scene, stages, whether it met every request, the
    shortfalls and the one-time compile cost (s) paid before any timed call."""
    return dict(zip(RUN_KEYS, (name, list(stages), not shortfalls, shortfall_dicts(shortfalls), compile_time)))


def study_to_dict(result: StudyResult) -> dict[str, Any]:
    """Everything the study computed, JSON-able."""
    out: dict[str, Any] = {**run_head(result.scene.name, result.stages, result.shortfalls, result.compile_time),
                           "curve": result.curve.to_dict(), "contacts": {
                               "speeds": result.contacts.speeds, "forces": result.contacts.forces}}
    if result.sensors is not None:
        out["sensors"] = result.sensors
    if result.allocation is not None:
        out["allocation"] = result.allocation.to_dict()
    if result.schedule is not None:
        out["schedule"] = {**result.schedule.to_dict(),
                           "exact_check": schedule_check(result.schedule, result.schedule_check)}
    if result.simulation is not None:
        out["simulation"] = _simulation_dict(result.simulation)
    if result.estimation is not None:
        out["estimation"] = estimation_to_dict(result.estimation)
    if result.control is not None:
        out["control"] = result.control.to_dict()
    return out


def study_summary(result: StudyResult) -> list[str]:
    """A few human lines on what the study found."""
    lo, hi = result.curve.equilibrium
    eq = f"{lo:.6g} m/s" if lo == hi else f"[{lo:.6g}, {hi:.6g}] m/s (zero-force band)"
    lines = [f"scene {result.scene.name}: {result.contacts.n} contacts, "
             f"F_tot = {result.curve.total_force:.6g} N, equilibrium {eq}"]
    for name, enc in (result.sensors or {}).items():
        lines.append(f"{name} encoder: {enc['distance_per_count'] * 1e6:.1f} um/count, "
                     f"{enc['speed_step'] * 1e3:.1f} mm/s per count at {enc['rate']:g} Hz"
                     + (f", backlash {enc['backlash_speed_step'] * 1e3:.0f} mm/s" if enc["backlash_speed_step"] else ""))
    if result.allocation is not None:
        a = result.allocation
        projected = ("" if a.projection is None else
                     f" (from the projected target, {a.projection.distance_sup:.4g} N from the request)")
        lines.append(f"allocation ({a.method}): sup error {a.error_sup:.4g} N{projected}, bound {a.bound:.4g} N, "
                     f"gap {a.gap:.2g} N; {a.status.value}")
    if result.schedule is not None:
        lines.extend(schedule_lines(result.schedule, result.schedule_check, result.shortfalls))
    if result.simulation is not None:
        s = result.simulation
        lines.append(f"simulation ({s.method}): V({s.t[-1]:g} s) = {s.V[-1]:.6g} m/s after "
                     f"{s.n_events} events in {s.wall_time * 1e3:.1f} ms; {s.status.value}")
    if result.estimation is not None:
        lines.extend(estimation_lines(result.estimation))
    if result.control is not None:
        lines.extend(control_lines(result.control))
    if result.compile_time:
        lines.append(compile_line(result.compile_time))
    lines.extend(f"shortfall: {shortfall}" for shortfall in result.shortfalls)
    return lines


def compile_line(seconds: float) -> str:
    """The one-time cost a report shows apart from its times (the policy of
    :mod:`toolkit._compiled`)."""
    return (f"compiled kernels loaded (or compiled) and each timed call run once first: "
            f"{seconds:.2f} s, in no time above")


def study_files(result: StudyResult) -> dict[str, bytes]:
    """Every output file of a study, rendered in memory: name -> bytes."""
    payload: dict[str, bytes] = {"result.json": to_json(study_to_dict(result)).encode()}
    report = result.scene.report
    if report is not None and report.plots:
        name = result.scene.name
        payload["force_curve.png"] = plots.render_png(plots.plot_force_curve, result.curve, title=name)
        if result.simulation is not None:
            payload["simulation.png"] = plots.render_png(
                plots.plot_simulation, result.simulation, plant=result.plant, title=name)
        if result.schedule is not None:
            payload["schedule.png"] = plots.render_png(
                plots.plot_schedule, result.schedule, result.schedule_check, plant=result.plant, title=name)
        if result.estimation is not None:
            payload["estimation.png"] = plots.render_png(plots.plot_estimation, result.estimation, title=name)
        if result.control is not None:
            c = result.control
            what = f"closed loop, {c.controller}" + (f" on the {c.estimator} estimate" if c.estimator else "")
            payload["closed_loop.png"] = plots.render_png(plots.plot_closed_loop, c.loop, title=name, what=what)
    if result.schedule is not None:
        payload["schedule.csv"] = schedule_csv(result.schedule).encode()
        payload["schedule.json"] = to_json(result.schedule.to_dict()).encode()
    return payload


def write_study(result: StudyResult, out_dir: str | Path) -> list[Path]:
    """Write ``result.json`` and, when the scene's ``[report]`` asks for plots, PNG figures
    (and the schedule's CSV and JSON), replacing ``out_dir`` as a whole.

    Returns the paths written. All content is rendered before the first file is written;
    a failure leaves ``out_dir`` as it was.
    """
    return write_tree(out_dir, study_files(result))


def write_precision(report: Any, out_dir: str | Path, *, title: str | None = None) -> list[Path]:
    """Write ``precision.json`` and the log-log plot ``precision.png`` of a precision report
    (``title``: the scene name shown in the plot's title)."""
    data = report.to_dict()
    exact = [row for row in report.rows if row.method == "exact" and not math.isfinite(row.max_error)]
    reference = exact[0].wall_time if exact else None
    png = plots.render_png(plots.plot_precision, work_precision_curves(report), error_level=ERROR_LEVEL,
                           reference_time=reference,
                           title=title)
    return write_tree(out_dir, {"precision.json": to_json(data).encode(), "precision.png": png})


def write_schedule(schedule: Any, out_dir: str | Path) -> list[Path]:
    """Write ``schedule.csv`` and ``schedule.json`` (firmware-playable) into ``out_dir``."""
    csv_text, json_text = schedule_csv(schedule), to_json(schedule.to_dict())
    return write_tree(out_dir, {"schedule.csv": csv_text.encode(), "schedule.json": json_text.encode()})


def sweep_to_dict(result: Any, statistics: tuple[str, ...] = (), shortfalls: Any = ()) -> dict[str, Any]:
    """JSON form of a sweep: experiment, runs, seed, scheduler, wall time, the summary
    statistics (only ``statistics`` when given) and the shortfalls. A statistic that is
    undefined (NaN, e.g. ``threshold_amplitude`` when no run moved) is ``null``; an infinite
    one (``dT_median`` when the body never arrives) is the string ``"inf"`` as elsewhere."""
    data = result.to_dict()
    if statistics:
        data["summary"] = {name: data["summary"][name] for name in statistics}
    data["summary"] = {name: (None if isinstance(value, float) and math.isnan(value) else value)
                       for name, value in data["summary"].items()}
    data["shortfalls"] = shortfall_dicts(shortfalls)
    return data


def sweep_lines(result: Any, statistics: tuple[str, ...] = (), shortfalls: Any = ()) -> list[str]:
    """Text summary of a sweep."""
    lines = [f"{result.experiment.name}: {result.runs} runs (seed {result.seed}, {result.scheduler}) "
             f"in {result.wall_time:.3g} s"]
    for name, value in result.summary.items():
        if not statistics or name in statistics:
            lines.append(f"  {name} = {value:.6g}")
    lines.extend(f"shortfall: {shortfall}" for shortfall in shortfalls)
    return lines


def write_sweep(result: Any, out_dir: str | Path, *, statistics: tuple[str, ...] = (),
                shortfalls: Any = (), plots_too: bool = True, title: str | None = None) -> list[Path]:
    """Write ``results.csv`` (one row per run), ``sweep.json`` (:func:`sweep_to_dict`) and,
    with ``plots_too``, ``sweep.png`` into ``out_dir``, replacing it as a whole."""
    payload = {"results.csv": result.table.to_csv(index=False, float_format="%.17g").encode(),
               "sweep.json": to_json(sweep_to_dict(result, statistics, shortfalls)).encode()}
    if plots_too:
        payload["sweep.png"] = plots.render_png(plots.plot_sweep, result, title=title)
    return write_tree(out_dir, payload)


def planar_to_dict(result: Any, name: str | None, stages: Sequence[str] = ("planar",)) -> dict[str, Any]:
    """JSON form of a planar scene's run: :func:`run_head`'s keys, then ``planar``."""
    return {**run_head(name, stages, result.shortfalls, result.compile_time), "planar": result.to_dict()}


def write_planar(result: Any, out_dir: str | Path, *, plots_too: bool = True,
                 title: str | None = None, stages: Sequence[str] = ("planar",)) -> list[Path]:
    """Write ``planar.json`` (:func:`planar_to_dict`) and, with
    ``plots_too``, ``planar.png`` (the trajectory of a disc or ring; the work-precision plot
    when the scene asks for it) into ``out_dir``, replacing it as a whole."""
    from ..planar.plots import plot_planar_precision, plot_sliding_disc

    payload = {"planar.json": to_json(planar_to_dict(result, title, stages)).encode()}
    region = result.objects.region
    if plots_too and region is not None:
        reference = result.published[0] if result.published is not None else result.closed_form_ratio
        payload["planar.png"] = plots.figure_png(plot_sliding_disc(
            result.simulation, region.radius, terminal_ratio=reference, title=title))
    if plots_too and result.precision is not None:
        payload["planar_precision.png"] = plots.figure_png(plot_planar_precision(result.precision, title=title))
    return write_tree(out_dir, payload)


def write_planar_precision(report: Any, out_dir: str | Path, *, title: str | None = None) -> list[Path]:
    """Write a planar work-precision report as ``precision.json`` and ``precision.png`` (what
    :func:`write_precision` writes for a 1-D scene) into ``out_dir``, replacing it as a whole."""
    from ..planar.plots import plot_planar_precision

    return write_tree(out_dir, {"precision.json": to_json(report.to_dict()).encode(),
                                "precision.png": plots.figure_png(plot_planar_precision(report, title=title))})


def write_text(path: str | Path, text: str) -> Path:
    """Write one text file atomically (CSV, JSON)."""
    return atomic_write_text(path, text)
