"""The commands that run a scene's stages: ``run`` (every declared stage), ``curve``,
``allocate``, ``schedule``, ``precision`` and ``sweep``.
"""

from __future__ import annotations

import argparse
import sys
from typing import TYPE_CHECKING, Any

from ._common import EXIT_OK, _finish, _known_shortfalls, _out_dir, _parsed, _print_json, _scene

if TYPE_CHECKING:
    from ..scenes.build import SceneObjects


def _cmd_run(args: argparse.Namespace) -> int:
    from ..scenes._io import claim_output_dir
    from ..scenes.report import study_summary, study_to_dict, write_study
    from ..scenes.study import run_study
    objects = _scene(args)
    if objects.sweep is not None:          # a sweep scene's one stage
        args.runs = args.seed = args.scheduler = args.workers = None
        args.out = str(_out_dir(args, objects.scene))
        args.run_keys = True               # its JSON with every run's top-level keys
        return _cmd_sweep(args)
    if objects.planar is not None:         # a planar scene's one stage
        return _run_planar(args, objects)
    with claim_output_dir(_out_dir(args, objects.scene)) as out:
        result = run_study(objects, strict=args.strict)
        written = write_study(result, out)
    if args.json:
        _print_json({**study_to_dict(result), "written": [str(p) for p in written]})
    else:
        for line in study_summary(result):
            print(line)
        print(f"wrote {', '.join(str(p) for p in written)}")
    return _finish(result.shortfalls)


def _run_planar(args: argparse.Namespace, objects: SceneObjects) -> int:
    from ..scenes._io import claim_output_dir
    from ..scenes.report import planar_to_dict, write_planar
    from ..scenes.study import planar_scene
    scene = objects.scene
    with claim_output_dir(_out_dir(args, scene)) as out:
        result = planar_scene(objects)
        plots_too = scene.report is None or scene.report.plots
        written = write_planar(result, out, plots_too=plots_too, title=scene.name, stages=scene.stages)
    if args.json:
        _print_json({**planar_to_dict(result, scene.name, scene.stages), "written": [str(p) for p in written]})
    else:
        for line in result.lines():
            print(line)
        print(f"wrote {', '.join(str(p) for p in written)}")
    return _finish(result.shortfalls)


def _cmd_curve(args: argparse.Namespace) -> int:
    from ..scenes.study import force_curve
    curve = force_curve(_scene(args).contacts, args.points)
    if args.json:
        _print_json(curve.to_dict())
    else:
        lo, hi = curve.equilibrium
        print(f"F_tot = {curve.total_force:.6g} N; equilibrium [{lo:.6g}, {hi:.6g}] m/s")
        print(f"{len(curve.steps)} steps; F is constant between them")
        print(f"{'V (m/s)':>12} {'F below (N)':>12} {'F above (N)':>12}")
        for step in curve.steps:
            print(f"{step.speed:12.6g} {step.force_below:12.6g} {step.force_above:12.6g}")
    return EXIT_OK


def _cmd_allocate(args: argparse.Namespace) -> int:
    from ..scenes.report import shortfall_dicts
    from ..scenes.study import allocate_scene, allocation_shortfalls
    objects = _scene(args, "target", "to allocate")
    known = _known_shortfalls(objects, args, ("scene", "allocation"))
    result = allocate_scene(objects, strict=args.strict)
    shortfalls = [s for s in known if s.stage == "scene"] + allocation_shortfalls(objects, result)
    if args.json:
        _print_json({**result.to_dict(), "shortfalls": shortfall_dicts(shortfalls)})
    else:
        print(f"{result.method}: {result.status.value}")
        projected = ("" if result.projection is None else
                     f" (from the projected target, {result.projection.distance_sup:.6g} N from the request)")
        print(f"sup error {result.error_sup:.6g} N{projected}, L1 error {result.error_l1:.6g} N m/s, "
              f"bound {result.bound:.6g} N, gap {result.gap:.3g} N, {result.wall_time * 1e3:.2f} ms")
        print("speeds (m/s): " + ", ".join(f"{v:.6g}" for v in result.speeds))
    return _finish(shortfalls)


def _cmd_schedule(args: argparse.Namespace) -> int:
    from ..scenes._io import claim_output_dir
    from ..scenes.report import schedule_check, schedule_lines, shortfall_dicts, write_schedule
    from ..scenes.study import design_scene_schedule, schedule_shortfalls
    objects = _scene(args, "schedule", "to design")
    known = _known_shortfalls(objects, args, ("scene", "schedule"))
    with claim_output_dir(_out_dir(args, objects.scene)) as out:
        result, check = design_scene_schedule(objects)
        shortfalls = [s for s in known if s.stage == "scene"] + schedule_shortfalls(objects, result, check)
        written = write_schedule(result, out)
    verified = schedule_check(result, check)
    if args.json:
        _print_json({**result.to_dict(), "exact_check": verified, "shortfalls": shortfall_dicts(shortfalls),
                     "written": [str(p) for p in written]})
    else:
        for line in schedule_lines(result, check, shortfalls):
            print(line)
        print(f"wrote {', '.join(str(p) for p in written)}")
    return _finish(shortfalls)


def _cmd_precision(args: argparse.Namespace) -> int:
    from ..analysis.precision import exact_speedup, precision_report, precision_shortfalls
    from ..errors import SceneError
    from ..scenes._io import claim_output_dir
    from ..scenes.build import build_scene
    from ..scenes.report import compile_line, write_precision
    scene = _parsed(args)
    if scene.planar is not None:
        return _planar_precision(args, build_scene(scene))
    if scene.simulation is None:
        raise SceneError(f"The scene {scene.name!r} has no [simulation] section (t_end, v0) to compare "
                         "methods on.")
    objects = build_scene(scene)
    spec = objects.scene.simulation
    with claim_output_dir(args.out) as out:
        report = precision_report(objects.plant, spec.t_end, v0=spec.v0, repeats=args.repeats)
        written = write_precision(report, out, title=objects.scene.name) if out is not None else []
    if args.json:
        _print_json(report.to_dict())
    else:
        print(f"{'method':8} {'setting':46} {'max_error':>10} {'final_error':>11} {'wall_time':>10} "
              f"{'evals':>8}  status")
        for row in report.rows:
            print(f"{row.method:8} {row.setting:46} {row.max_error:10.2e} {row.final_error:11.2e} "
                  f"{row.wall_time:10.2e} {row.n_evaluations:8d}  {row.status.name}{_flags(row)}")
        print(compile_line(report.compile_time))
        if any(row.method == "exact" for row in report.rows):
            speedup = exact_speedup(report)
            print(f"exact {speedup.exact.wall_time:.2e} s; fastest reference with max_error <= "
                  f"{speedup.error_level:g} m/s: " + (
                      f"{speedup.reference.label} {speedup.reference.wall_time:.2e} s, "
                      f"ratio {speedup.ratio:.1f}x" if speedup.reference is not None else "none"))
        if written:
            print(f"wrote {', '.join(str(p) for p in written)}")
    return _finish(precision_shortfalls(report))


def _planar_precision(args: argparse.Namespace, objects: SceneObjects) -> int:
    """``precision`` on a planar scene: its work-precision report against the exact run."""
    from ..scenes._io import claim_output_dir
    from ..scenes.report import write_planar_precision
    from ..scenes.study import planar_precision
    with claim_output_dir(args.out) as out:
        report = planar_precision(objects)
        written = write_planar_precision(report, out, title=objects.scene.name) if out is not None else []
    if args.json:
        _print_json(report.to_dict())
    else:
        ref = report.reference
        print(f"reference: {ref.method} ({ref.setting}) {ref.wall_time:.2e} s")
        print(f"{'method':8} {'setting':30} {'max_error':>10} {'stop_error':>10} {'wall_time':>10} "
              f"{'steps':>7}  status")
        for row in report.rows:
            print(f"{row.method:8} {row.setting:30} {row.max_error:10.2e} {row.stop_error:10.2e} "
                  f"{row.wall_time:10.2e} {row.steps:7d}  {row.status}")
        if written:
            print(f"wrote {', '.join(str(p) for p in written)}")
    return EXIT_OK


def _cmd_sweep(args: argparse.Namespace) -> int:
    from ..scenes._io import claim_output_dir
    from ..scenes.report import run_head, sweep_lines, sweep_to_dict, write_sweep
    from ..scenes.study import check_sweep_table, sweep_scene, sweep_shortfalls
    objects = _scene(args, "sweep", "to run")
    scene = objects.scene
    if args.out is not None:
        check_sweep_table(objects, runs=args.runs, seed=args.seed)
    with claim_output_dir(args.out) as out:
        result = sweep_scene(objects, runs=args.runs, seed=args.seed, scheduler=args.scheduler,
                             workers=args.workers, progress=sys.stderr.isatty())
        shortfalls = sweep_shortfalls(result)
        statistics = scene.sweep.statistics
        plots_too = scene.report is None or scene.report.plots
        written = (write_sweep(result, out, statistics=statistics, shortfalls=shortfalls, plots_too=plots_too,
                               title=scene.name) if out is not None else [])
    if args.json:
        data = sweep_to_dict(result, statistics, shortfalls)
        if getattr(args, "run_keys", False):
            data = {**run_head(scene.name, scene.stages, shortfalls, result.compile_time), "sweep": data}
        _print_json({**data, "written": [str(p) for p in written]})
    else:
        for line in sweep_lines(result, statistics, shortfalls):
            print(line)
        if written:
            print(f"wrote {', '.join(str(p) for p in written)}")
    return _finish(shortfalls)


def _flags(row: Any) -> str:
    names = [name for name in ("chattering", "step_collapse", "creep", "stalled") if getattr(row, name)]
    return f" [{', '.join(names)}]" if names else ""
