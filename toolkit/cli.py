"""The ``active-contacts`` command line.

One function per subcommand (``_cmd_<name>``), registered in :func:`parser`; every exit
code is in :data:`EXIT_CODES` (also shown by ``--help``): 0 met, 1 a stability case failed,
2 a user error (one line on stderr, nothing written), 3 finished but missed the request
(outputs written, one ``shortfall:`` line), 130 interrupted, 141 the reader stopped reading.
``--json`` prints machine-readable output on stdout. Outputs are all or nothing: the output
folder is checked before any work and replaced as a whole at the end."""

from __future__ import annotations

import argparse
import contextlib
import math
import signal
import sys
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from . import __version__

if TYPE_CHECKING:
    from .scenes.build import SceneObjects
    from .scenes.spec import Scene
    from .shortfall import Shortfall

__all__ = ["main", "EXIT_CODES"]

EXIT_OK, EXIT_FAILED, EXIT_USAGE, EXIT_SHORTFALL, EXIT_INTERRUPTED, EXIT_PIPE = 0, 1, 2, 3, 130, 141

#: Every exit code of the command line and what it means (shown by ``--help``).
EXIT_CODES = {
    EXIT_OK: "the request was met",
    EXIT_FAILED: "stability: a case of the suite failed",
    EXIT_USAGE: "user error (bad arguments or scene, unreadable scene file, unwritable output; "
                "with --strict, a request known to fall short): one line on stderr, nothing written",
    EXIT_SHORTFALL: "finished but missed the request (simulation stopped early, target projected or "
                    "unreachable, speeds clipped to the limits, schedule unreachable, unverified or "
                    "unchecked, a wall-clock guard fired): outputs written, one 'shortfall:' line on stderr",
    EXIT_INTERRUPTED: "interrupted",
    EXIT_PIPE: "the reader of the standard output stopped reading (a pipe into head): ended quietly",
}


def _print_json(data: Any) -> None:
    from .scenes.report import to_json
    sys.stdout.write(to_json(data))


def _parsed(args: argparse.Namespace, section: str | None = None, purpose: str = "") -> Scene:
    """Load the SCENE argument (form only); refuse a sweep scene where the command needs
    contacts of its own, and, with ``section``, a scene that does not declare it."""
    from .errors import SceneError
    from .scenes.build import planar_scene_error, sweep_scene_error
    from .scenes.spec import load_scene
    scene = load_scene(args.scene)
    if scene.sweep is not None and args.command not in ("run", "sweep"):
        raise sweep_scene_error(scene, args.command)
    if scene.planar is not None and args.command not in ("run", "precision"):
        raise planar_scene_error(scene, args.command)
    if section is not None and getattr(scene, section) is None:
        raise SceneError(f"The scene {scene.name!r} has no [{section}] section {purpose}.")
    return scene


def _scene(args: argparse.Namespace, section: str | None = None, purpose: str = "") -> SceneObjects:
    """:func:`_parsed`, then built: every value checked (exit 2 on a bad one)."""
    from .scenes.build import build_scene
    return build_scene(_parsed(args, section, purpose))


def _out_dir(args: argparse.Namespace, scene: Scene) -> Path:
    """``--out``, or ``out/<scene name>``."""
    return Path(args.out) if args.out is not None else Path("out") / scene.name


def _known_shortfalls(objects: SceneObjects, args: argparse.Namespace,
                      stages: tuple[str, ...]) -> list[Shortfall]:
    """The shortfalls of ``stages`` known before any work; with ``--strict`` a refusal (exit 2)."""
    from .errors import SceneError
    from .scenes.study import request_shortfalls
    known = [s for s in request_shortfalls(objects) if s.stage in stages]
    if args.strict and known:
        raise SceneError(f"--strict: {known[0]}" + (f" (and {len(known) - 1} more)" if len(known) > 1 else ""))
    return known


def _finish(shortfalls: Sequence[Shortfall]) -> int:
    """Exit 0, or 3 with one line on stderr naming every shortfall."""
    from .scenes.report import shortfall_line
    if not shortfalls:
        return EXIT_OK
    print(f"active-contacts: {shortfall_line(shortfalls)}", file=sys.stderr)
    return EXIT_SHORTFALL


def _cmd_run(args: argparse.Namespace) -> int:
    from .scenes._io import claim_output_dir
    from .scenes.report import study_summary, study_to_dict, write_study
    from .scenes.study import run_study
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
    from .scenes._io import claim_output_dir
    from .scenes.report import planar_to_dict, write_planar
    from .scenes.study import planar_scene
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
    from .scenes.study import force_curve
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
    from .scenes.report import shortfall_dicts
    from .scenes.study import allocate_scene, allocation_shortfalls
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
    from .scenes._io import claim_output_dir
    from .scenes.report import schedule_check, schedule_lines, shortfall_dicts, write_schedule
    from .scenes.study import design_scene_schedule, schedule_shortfalls
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
    from .analysis.precision import exact_speedup, precision_report, precision_shortfalls
    from .errors import SceneError
    from .scenes._io import claim_output_dir
    from .scenes.build import build_scene
    from .scenes.report import compile_line, write_precision
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
    from .scenes._io import claim_output_dir
    from .scenes.report import write_planar_precision
    from .scenes.study import planar_precision
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


# -- estimate: every estimator of the scene over one simulated encoder record -------

def _cmd_estimate(args: argparse.Namespace) -> int:
    from dataclasses import replace

    from .errors import SceneError
    from .model.record_io import read_record_csv, record_csv_text
    from .scenes._io import atomic_write_text, check_output_file, claim_output_dir, write_tree
    from .scenes.build import build_scene, check_record_outputs
    from .scenes.report import estimation_files, estimation_lines, estimation_to_dict, shortfall_dicts
    from .scenes.spec import EstimationSpec
    from .scenes.study import estimate_record, estimate_scene, estimation_shortfalls

    scene = _parsed(args)
    if args.record is not None and args.save_record is not None:
        raise SceneError("--save-record writes the simulated record; with --record there is none to write "
                         "(give one of the two).")
    save = None if args.save_record is None else check_output_file(args.save_record)
    if scene.estimation is None:      # the scene's own run, recorded: never another scenario
        if scene.sensors is None:
            raise SceneError(f"The scene {scene.name!r} has no [sensors] section (the encoders to "
                             "estimate from).")
        if args.record is not None:   # a recorded file: the section's estimators and priors
            scene = replace(scene, estimation=EstimationSpec())
        elif scene.simulation is None:
            raise SceneError(f"The scene {scene.name!r} has no [estimation] section and no [simulation] "
                             "run to record: add [estimation] (scenario = \"brake\", the startup-then-brake "
                             "record on the scene's wheel forces, as in the shipped 'estimate' design).")
        else:
            scene = replace(scene, estimation=EstimationSpec(scenario="simulation"))
    objects = build_scene(scene)
    record = None if args.record is None else read_record_csv(
        args.record, sensors=objects.estimation.sensors, motors=objects.estimation.plant.motors,
        progress=sys.stderr.isatty())
    if record is not None:
        check_record_outputs(record.n_samples, objects.estimation, args.record)
    with claim_output_dir(_out_dir(args, scene)) as out:
        study = estimate_scene(objects) if record is None else estimate_record(objects, record)
        shortfalls = estimation_shortfalls(objects, study)
        plots_too = scene.report is None or scene.report.plots
        written = write_tree(out, estimation_files(study, scene.name, plots_too=plots_too))
        if save is not None:
            written.append(atomic_write_text(save, record_csv_text(study.record)))
    if args.json:
        data = estimation_to_dict(study)
        data.pop("series")
        _print_json({"scene": scene.name, **data, "shortfalls": shortfall_dicts(shortfalls),
                     "written": [str(p) for p in written]})
    else:
        for line in estimation_lines(study):
            print(line)
        print(f"wrote {', '.join(str(p) for p in written)}")
    return _finish(shortfalls)


def _cmd_live(args: argparse.Namespace) -> int:
    from .live import run_live
    from .live.report import live_files, live_lines, live_to_dict
    from .live.runner import LiveStatus
    from .live.scene import scene_device, scene_loop, warm_loop
    from .scenes._io import claim_output_dir, write_tree
    from .shortfall import Shortfall

    objects = _scene(args, "control", "to run live")
    loop = scene_loop(objects, args.duration)
    device = scene_device(objects, args.device, loop.duration)
    scene = objects.scene

    def status(s: dict[str, float]) -> None:
        sys.stderr.write(f"\rt {s['t']:8.2f} s  V^ {s['estimate']:+.5f} +- {s['sigma']:.5f} m/s  u {s['command']:+.4f} "
                         f"m/s  p99 {s['p99_ms']:.2f} ms  missed {s['missed']}  ")
        sys.stderr.flush()

    with claim_output_dir(_out_dir(args, scene)) as out:
        warm_loop(loop)
        def started(hello: Any) -> None:
            if not args.json:
                print(f"live on {args.device}: {hello.wheels} wheels at {hello.rate:g} Hz; Ctrl-C stops "
                      "(zero commands sent)", flush=True)

        result = run_live(loop, device, status=status if sys.stderr.isatty() else None, started=started)
        if sys.stderr.isatty():
            sys.stderr.write("\n")
        truth, report = getattr(device, "truth", None), getattr(device, "report", None)
        plots_too = scene.report is None or scene.report.plots
        written = write_tree(out, live_files(result, truth, report, name=scene.name, plots_too=plots_too))
    if args.json:
        _print_json({"scene": scene.name, **live_to_dict(result, truth, report), "written": [str(p) for p in written]})
    else:
        for line in live_lines(result, truth):
            print(line)
        print(f"wrote {', '.join(str(p) for p in written)}")
    if result.status is LiveStatus.INTERRUPTED:
        print(f"active-contacts: {result.message}", file=sys.stderr)
        return EXIT_INTERRUPTED
    reached = float(result.record.times[-1]) if result.record is not None else 0.0
    return _finish([] if result.status is LiveStatus.COMPLETED else
                   [Shortfall("live", result.message, loop.duration - reached, "s")])


def _cmd_sweep(args: argparse.Namespace) -> int:
    from .scenes._io import claim_output_dir
    from .scenes.report import run_head, sweep_lines, sweep_to_dict, write_sweep
    from .scenes.study import check_sweep_table, sweep_scene, sweep_shortfalls
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


def _cmd_designs(args: argparse.Namespace) -> int:
    from .scenes.designs import copy_designs, design_names, design_text

    if args.copy is not None:
        written = copy_designs(args.copy)
        if args.json:
            _print_json({"written": [str(p) for p in written]})
        else:
            print(f"wrote {len(written)} designs into {args.copy}")
        return EXIT_OK
    names = design_names()
    if args.json:
        _print_json({"designs": list(names)})
    else:
        import tomllib

        for name in names:
            about = tomllib.loads(design_text(name)).get("scene", {}).get("description", "")
            print(f"{name:20} {about}")
        print("copy them for editing: active-contacts designs --copy DIR")
    return EXIT_OK


def _cmd_warm(args: argparse.Namespace) -> int:
    """Run every shipped design once, outputs discarded, so that every kernel they use is
    compiled and cached: after this, every design's first run starts warm."""
    import io
    import tempfile
    import time

    from tqdm import tqdm

    from . import _compiled
    from .scenes.designs import design_names, design_text

    names = design_names()
    started, compiled_before = time.perf_counter(), _compiled.compile_seconds()
    with tempfile.TemporaryDirectory(prefix="active-contacts-warm-") as folder:
        for name in tqdm(names, desc="warming", unit=" designs", file=sys.stderr, leave=False,
                         disable=args.json or not sys.stderr.isatty()):
            scene = Path(folder) / f"{name}.toml"
            scene.write_text(design_text(name), encoding="utf-8")
            run = argparse.Namespace(command="run", scene=str(scene), out=str(Path(folder) / "out" / name),
                                     json=False, strict=False)
            with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
                _cmd_run(run)            # (a design's own shortfalls do not matter here)
    compile_time = _compiled.compile_seconds() - compiled_before
    wall = time.perf_counter() - started
    if args.json:
        _print_json({"designs": list(names), "compile_time": compile_time, "wall_time": wall})
    else:
        print(f"{len(names)} shipped designs run once in {wall:.1f} s, {compile_time:.1f} s of it compiling "
              "kernels: they are cached, and every design's first run starts warm")
    return EXIT_OK


def _flags(row: Any) -> str:
    names = [name for name in ("chattering", "step_collapse", "creep", "stalled") if getattr(row, name)]
    return f" [{', '.join(names)}]" if names else ""


def _cmd_stability(args: argparse.Namespace) -> int:
    from .analysis.stability import case_label, stability_suite
    from .shortfall import Shortfall
    report = stability_suite(quick=args.quick)
    if args.json:
        _print_json(report.to_dict())
    else:
        print(f"{'case':34} {'method':8} {'finished':>8} {'finite':>6} {'events':>8} {'wall_time':>10}  ok")
        for case in report.cases:
            verdict = case.ok if case.judged else "unjudged (wall-clock guard)"
            print(f"{case.name:34} {case.method:8} {case.finished!s:>8} {case.finite!s:>6} "
                  f"{case.events:8d} {case.wall_time:10.2e}  {verdict}")
        print("all cases ok" if report.all_ok else "SOME CASES FAILED" if report.failed
              else "SOME CASES UNJUDGED")
    if report.failed:
        print("active-contacts: stability: failed: "
              + "; ".join(f"{case_label(c)}: {c.message}" for c in report.failed), file=sys.stderr)
        return EXIT_FAILED
    return _finish([Shortfall("stability", f"unjudged: the wall-clock guard stopped {case_label(c)} "
                              f"({c.message})", math.nan, "") for c in report.unjudged])


# -- predict: the paper's viscosity and friction-fraction predictions checked in the loop ----
def _cmd_predict(args: argparse.Namespace) -> int:
    from .scenes.report import compile_line
    from .shortfall import Shortfall
    from .predictions import Apparatus, prediction_checks

    if args.scene is None:
        apparatus = Apparatus.carousel()
    else:
        apparatus = _scene(args).apparatus()
    if args.contacts is not None:
        apparatus = apparatus.with_contacts(args.contacts)
    progress = not args.json and sys.stderr.isatty()
    result = prediction_checks(apparatus, runs=args.runs, seed=args.seed, progress=progress)
    if args.json:
        _print_json(result.to_dict())
    else:
        for label, check in result.checks():
            if hasattr(check, "fits"):
                print(f"{label}: {check.runs} runs on {apparatus.n} contacts, 1/tau = k dF/dV / m, "
                      f"{check.wall_time:.1f} s: {check.status.name}")
                for fit in check.fits:
                    print(f"  {fit.definition} ({fit.runs} starts {fit.starts} the spread): k_fit "
                          f"{fit.k_fit:.4f}, k_predicted {fit.k_predicted:.4f} (ratio {fit.ratio:.4f}), "
                          f"R^2 {fit.r2:.4f}")
            else:
                print(f"{label}: {check.status.name} ({check.wall_time:.1f} s)")
                for row in check.rows():
                    print(f"  n = {row['n']}: mu/mu0 {row['mu_ratio']:.4f} (predicted "
                          f"{row['mu_predicted']:.4g}), dT {_seconds(row['dT'])} (predicted "
                          f"{_seconds(row['dT_predicted'])})")
        if apparatus.sensors is None:
            print("the scene has no [sensors]: only the ideal checks ran")
        if apparatus.n % 2:
            print(f"friction fraction: left out ({apparatus.n} contacts; the split needs an even number)")
        print(compile_line(result.compile_time))
    return _finish([Shortfall("prediction", line, math.nan, "") for line in result.shortfalls()])


def _seconds(value: float | None) -> str:
    """A time for the predict summary: ``inf`` for None (no transition)."""
    return "inf" if value is None else f"{value:.4g} s"


def _bounded(name: str) -> Callable[[str], int]:
    """An integer flag with the bound of the scene key it also sets (:func:`~toolkit.scenes.spec.flag_limit`)
    or of its own entry in :data:`~toolkit.scenes.limits.FLAGS`."""
    from .scenes.limits import FLAGS
    from .scenes.spec import flag_limit
    limit = FLAGS.get(name) or flag_limit(name)

    def convert(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"must {limit.rule}, got {text!r}") from None
        if not limit.holds(value):
            raise argparse.ArgumentTypeError(f"must {limit.broken(value)}, got {value}")
        return value

    return convert


def _folder(text: str) -> str:
    """An output folder path: not empty (an empty one would silently mean the default)."""
    if not text.strip():
        raise argparse.ArgumentTypeError(f"must name a folder, got {text!r}")
    return text


def _file(text: str) -> str:
    """A file path: not empty."""
    if not text.strip():
        raise argparse.ArgumentTypeError(f"must name a file, got {text!r}")
    return text


class _Parser(argparse.ArgumentParser):
    """argparse with its errors on one line (exit 2), like every other user error."""

    def error(self, message: str) -> None:        # type: ignore[override]
        self.exit(EXIT_USAGE, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def parser() -> argparse.ArgumentParser:
    """The command line's argument parser: every subcommand, its flags and the exit codes.

    The command-line reference of the documentation is generated from it.
    """
    from .scenes.limits import FLAGS
    from .scenes.spec import ReportSpec
    parser = _Parser(
        prog="active-contacts",
        description="Design, simulate and analyse friction created by active contacts.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="exit codes:\n" + "\n".join(f"  {code:<4} {meaning}" for code, meaning in EXIT_CODES.items()))
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    commands = parser.add_subparsers(dest="command", metavar="COMMAND", required=True, parser_class=_Parser)

    def command(name: str, handler: Callable[[argparse.Namespace], int], help_text: str,
                scene: bool = True, strict: bool = False) -> argparse.ArgumentParser:
        sub = commands.add_parser(name, help=help_text, description=help_text)
        if scene:
            sub.add_argument("scene", metavar="SCENE", help="a scene file (TOML), e.g. designs/carousel.toml")
        sub.add_argument("--json", action="store_true", help="machine-readable output on stdout")
        if strict:
            sub.add_argument("--strict", action="store_true",
                             help="refuse (exit 2, before any work) a request known to fall short: a "
                                  "target that needs projection or lies beyond reach, speeds clipped "
                                  "to the motor limits, a schedule target beyond them")
        sub.set_defaults(handler=handler)
        return sub

    out_help = ("output folder, replaced as a whole (default: out/<scene name>); it must be new "
                "or hold only toolkit outputs")
    run = command("run", _cmd_run, "run every stage the scene declares and write results and plots",
                  strict=True)
    run.add_argument("--out", metavar="DIR", type=_folder, help=out_help)
    curve = command("curve", _cmd_curve, "print every step of the force-speed curve of the scene's "
                    "contacts (--json: also the sampled curve)")
    points = ReportSpec.key("curve_points")
    curve.add_argument("--points", type=_bounded("curve --points"), default=points.default,
                       help=f"samples in --json (default {points.default}; {points.limit.rule[3:]})")
    command("allocate", _cmd_allocate, "allocate contact speeds that realize the scene's [target]",
            strict=True)
    schedule = command("schedule", _cmd_schedule,
                       "design the scene's [schedule] and write schedule.csv and schedule.json", strict=True)
    schedule.add_argument("--out", metavar="DIR", type=_folder, help=out_help)
    precision = command("precision", _cmd_precision,
                        "work-precision report: every simulation method against the exact one")
    precision.add_argument("--repeats", type=_bounded("precision --repeats"), default=3,
                           help="timing repeats (default 3)")
    precision.add_argument("--out", metavar="DIR", type=_folder, help="also write precision.json and precision.png into "
                           "this folder, replaced as a whole")
    estimate = command("estimate", _cmd_estimate,
                       "simulate the scene's [estimation] record (default: startup then brake) and "
                       "score every estimator against the truth; writes estimate.json and estimate.png")
    estimate.add_argument("--out", metavar="DIR", type=_folder, help=out_help)
    estimate.add_argument("--record", metavar="FILE.csv", type=_file,
                          help="estimate from a recorded log (CSV: toolkit.model.record_io) instead of "
                               "a simulated record: estimates, NIS and the monitor's verdict, no truth")
    estimate.add_argument("--save-record", metavar="FILE.csv", type=_file,
                          help="also write the simulated record in the same CSV format")
    live = command("live", _cmd_live, "run the scene's [control] loop live on a device over serial (or on the "
                   "scene's world simulated on a pseudo-terminal): record, estimates, deadlines; docs/live.md")
    live.add_argument("--device", required=True, metavar="URL",
                      help="serial://PATH[?baud=N] (e.g. serial:///dev/ttyACM0?baud=115200), or 'sim' (the scene's "
                           "[control.truth] world simulated; sim?corrupt=P&silent_after=K&apply=sample for tests)")
    live.add_argument("--duration", type=float, metavar="S", help="seconds to run (default: control.duration)")
    live.add_argument("--out", metavar="DIR", type=_folder, help=out_help + "; record.csv replays with "
                      "'estimate SCENE --record DIR/record.csv'")
    sweep = command("sweep", _cmd_sweep, "run the scene's [sweep]: many seeded runs of one of the paper's "
                    "experiments, summary statistics, one table row per run")
    sweep.add_argument("--runs", type=_bounded("sweep --runs"), help="number of runs (default: the scene's)")
    sweep.add_argument("--seed", type=_bounded("sweep --seed"), help="root seed (default: the scene's)")
    sweep.add_argument("--scheduler", metavar="ADDRESS",
                       help="'processes' for a local process pool, or the address of a Dask scheduler "
                            "(tcp://host:port; needs pip install 'active-contacts[dask]'); default: "
                            "this process")
    sweep.add_argument("--workers", type=_bounded("sweep --workers"),
                       help="processes of the 'processes' pool (only with --scheduler processes)")
    sweep.add_argument("--out", metavar="DIR", type=_folder, help="write results.csv (one row per run), sweep.json and "
                       "sweep.png into this folder, replaced as a whole")
    designs = command("designs", _cmd_designs, "list the designs shipped with the toolkit (scene files); "
                      "--copy DIR writes them into DIR for editing", scene=False)
    designs.add_argument("--copy", metavar="DIR", help="write every shipped design into this folder "
                         "(created if needed; refused if a file of the same name is there)")
    command("warm", _cmd_warm, "compile and cache every kernel the shipped designs use (each design "
            "run once, outputs discarded), so that no later run waits for a compile", scene=False)
    stability = command("stability", _cmd_stability,
                        "stability suite over stiff and extreme cases (exit 1 if a case fails)", scene=False)
    stability.add_argument("--quick", action="store_true", help="the smaller, faster set of cases")
    predict = command("predict", _cmd_predict, "check the paper's viscosity and friction-fraction "
                      "predictions, ideal and with sensors, filter and motor lag in the loop (exit 3 "
                      "if a target is missed)", scene=False)
    predict.add_argument("scene", metavar="SCENE", nargs="?", default=None,
                         help="a scene file (TOML) with [body], [motors] and [sensors]; default: the "
                              "paper's carousel")
    predict.add_argument("--runs", type=_bounded("predict --runs"), default=490,
                         help="closed-loop runs of each viscosity sweep (default 490)")
    predict.add_argument("--seed", type=_bounded("predict --seed"), default=0, help="seed of the sweep (default 0)")
    predict.add_argument("--contacts", type=_bounded("predict --contacts"), default=None, metavar="N",
                         help="run the checks with N equal contacts sharing the apparatus's total "
                              "friction (default: the scene's, ten on the carousel); "
                              f"N {FLAGS['predict --contacts'].rule[3:]} (the viscosity check's default "
                              "starts need 5); the friction-fraction check needs N even")
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``active-contacts`` console script; returns the exit code.

    Everything past the standard library is imported in here, under the same handlers as the
    work: a Ctrl-C at any moment (while numpy loads, while workers start, while outputs are
    written) ends with one line and exit 130, never a traceback."""
    if sys.stdout is None:             # started with its standard output closed (>&-)
        return _stdout_closed()
    interrupted, previous = _interrupts_noted()
    try:
        with _interrupts_deferred(interrupted):
            try:
                args = parser().parse_args(argv)
            except SystemExit as done:  # --help, --version or a usage error: printed already
                raise SystemExit(_flushed(done.code)) from None
            from .errors import ToolkitError
            from .scenes import build, report, study  # noqa: F401  (what every command runs on)

        try:
            with _compiles_announced():
                code = args.handler(args)
            sys.stdout.flush()         # a write error found here is still this command's
            return code
        except ToolkitError as error:
            print(f"active-contacts: error: {error}", file=sys.stderr)
            return EXIT_USAGE
        except BrokenPipeError:
            if not _stdout_gone():
                raise
            return _reader_gone()
        except OSError as error:  # found only while writing: a full disk, a folder removed meanwhile
            print(f"active-contacts: error: cannot write the output: {error}", file=sys.stderr)
            return EXIT_USAGE
    except KeyboardInterrupt:
        print("active-contacts: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except Exception:
        if not interrupted:
            raise
        # What a Ctrl-C broke off (a compiled module's import turns it into an ImportError).
        print("active-contacts: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)


def _stdout_closed() -> int:
    """Exit 2 with one line: the command has nowhere to write its results."""
    if sys.stderr is not None:
        print("active-contacts: error: the standard output is closed; the command writes its results "
              "there (redirect it to a file, or to /dev/null to discard them).", file=sys.stderr)
    return EXIT_USAGE


def _flushed(code: Any) -> int:
    """``code`` once the standard output is flushed; a reader gone meanwhile ends quietly."""
    try:
        sys.stdout.flush()
    except BrokenPipeError:
        return _reader_gone()
    return code if isinstance(code, int) else EXIT_USAGE if code else EXIT_OK


def _stdout_gone() -> bool:
    """Whether the standard output is a pipe whose reader has closed it (``| head``)."""
    try:
        import select

        poll = select.poll()
        poll.register(sys.stdout.fileno(), select.POLLOUT)
        return any(events & (select.POLLERR | select.POLLHUP) for _, events in poll.poll(0))
    except (AttributeError, OSError, ValueError):    # no poll (Windows), no descriptor: assume so
        return True


def _reader_gone() -> int:
    """End quietly as a Unix filter does when its reader stops reading (exit 141, 128 +
    SIGPIPE); the standard output is pointed at /dev/null so the final flush stays silent."""
    import os

    try:
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
    except (AttributeError, OSError, ValueError):
        pass
    return EXIT_PIPE


@contextlib.contextmanager
def _interrupts_deferred(noted: list[int]) -> Iterator[None]:
    """While the command line imports what it runs on, Ctrl-C and SIGTERM are only noted, and
    raised once the imports are done: an interrupt raised inside an import may be turned into
    an ImportError (a compiled module's import does so) and then swallowed by a guard for an
    optional dependency, and the command would run on."""
    try:
        handlers = {signum: signal.signal(signum, lambda signum, frame: noted.append(signum))
                    for signum in (signal.SIGINT, signal.SIGTERM)}
    except ValueError:                 # not the main thread
        yield
        return
    try:
        yield
    finally:
        for signum, handler in handlers.items():
            signal.signal(signum, handler)
    if noted:
        raise KeyboardInterrupt(f"signal {noted[0]}")


def _interrupts_noted() -> tuple[list[int], dict[int, Any]]:
    """Ctrl-C (SIGINT) and SIGTERM raise ``KeyboardInterrupt`` (workers stopped, partial
    outputs removed, exit 130) and are noted in the returned list, so that an error they
    cause is known for what it is; returns it and the previous handlers (none off the main
    thread, where signals are not ours to take)."""
    noted: list[int] = []

    def interrupt(signum: int, frame: Any) -> None:
        noted.append(signum)
        raise KeyboardInterrupt(f"signal {signum}")

    previous: dict[int, Any] = {}
    try:
        for signum in (signal.SIGINT, signal.SIGTERM):
            previous[signum] = signal.signal(signum, interrupt)
    except ValueError:                 # not the main thread (an embedding caller's thread)
        pass
    return noted, previous


@contextlib.contextmanager
def _compiles_announced() -> Iterator[None]:
    """Say on stderr when kernels compile (a first run on an empty cache): one line before the
    first compile, a progress bar over the kernels where stderr is a terminal, and the time
    they took at the end of the command. Never on stdout; loading from the cache says nothing."""
    from . import _compiled

    state: dict[str, Any] = {"bar": None, "count": 0, "seconds": 0.0}
    stream = sys.stderr              # (bound now: a command may redirect its own stderr)

    def listener(event: str, kernel: str, seconds: float) -> None:
        if event == "start":
            if state["count"] == 0 and state["bar"] is None:
                note = _compiled.cache_note()
                print("active-contacts: compiling kernels (first run only: cached for the next runs"
                      + (f"; {note}" if note else "") + ")", file=stream, flush=True)
                if stream.isatty():
                    from tqdm import tqdm

                    state["bar"] = tqdm(desc="compiling", unit=" kernels", file=stream, leave=False)
            if state["bar"] is not None:
                state["bar"].set_postfix_str(kernel, refresh=True)
            return
        state["count"] += 1
        state["seconds"] += seconds
        if state["bar"] is not None:
            state["bar"].update(1)

    previous = _compiled.on_compile(listener)
    try:
        yield
    finally:
        _compiled.on_compile(previous)
        if state["bar"] is not None:
            state["bar"].close()
        if state["count"]:
            print(f"active-contacts: compiled {state['count']} kernels in {state['seconds']:.1f} s "
                  "(not charged to any budget)", file=stream, flush=True)


if __name__ == "__main__":
    raise SystemExit(main())
