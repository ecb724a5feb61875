"""The ``active-contacts`` command line.

Exit codes: 0 on success, 2 for a user error (bad arguments, bad scene, missing file),
printed as one line on stderr without a traceback. ``--json`` prints machine-readable
output on stdout.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from . import __version__
from .errors import SceneError, ToolkitError
from .precision import exact_speedup, precision_report
from .report import (schedule_check, schedule_lines, study_summary, study_to_dict, to_json,
                     write_precision, write_schedule, write_study)
from .scene import Scene, load_scene
from .scene_build import scene_plant
from .stability import stability_suite
from .study import allocate_scene, design_scene_schedule, force_curve, run_study

__all__ = ["main"]

EXIT_OK, EXIT_FAILED, EXIT_USAGE = 0, 1, 2


def _print_json(data: Any) -> None:
    sys.stdout.write(to_json(data))


def _scene(args: argparse.Namespace, section: str | None = None, purpose: str = "") -> Scene:
    """Load the SCENE argument; with ``section``, refuse a scene that does not declare it."""
    scene = load_scene(args.scene)
    if section is not None and getattr(scene, section) is None:
        raise SceneError(f"The scene {scene.name!r} has no [{section}] section {purpose}.")
    return scene


def _out_dir(args: argparse.Namespace, scene: Scene) -> Path:
    """``--out``, or ``out/<scene name>``."""
    return Path(args.out) if args.out else Path("out") / scene.name


def _cmd_run(args: argparse.Namespace) -> int:
    scene = _scene(args)
    result = run_study(scene)
    written = write_study(result, _out_dir(args, scene))
    if args.json:
        _print_json({**study_to_dict(result), "written": [str(p) for p in written]})
    else:
        for line in study_summary(result):
            print(line)
        print(f"wrote {', '.join(str(p) for p in written)}")
    return EXIT_OK


def _cmd_curve(args: argparse.Namespace) -> int:
    curve = force_curve(_scene(args).contact_set(), args.points)
    if args.json:
        _print_json(curve.to_dict())
    else:
        lo, hi = curve.equilibrium
        print(f"F_tot = {curve.total_force:.6g} N; equilibrium [{lo:.6g}, {hi:.6g}] m/s")
        print(f"{'V (m/s)':>12} {'F (N)':>12}")
        stride = max(1, curve.speeds.size // 40)
        for v, f in zip(curve.speeds[::stride], curve.force[::stride]):
            print(f"{v:12.5f} {f:12.5f}")
    return EXIT_OK


def _cmd_allocate(args: argparse.Namespace) -> int:
    result = allocate_scene(_scene(args, "target", "to allocate"))
    if args.json:
        _print_json(result.to_dict())
    else:
        print(f"{result.method}: {result.status.value}")
        print(f"sup error {result.error_sup:.6g} N, L1 error {result.error_l1:.6g} N m/s, "
              f"bound {result.bound:.6g} N, gap {result.gap:.3g} N, {result.wall_time * 1e3:.2f} ms")
        print("speeds (m/s): " + ", ".join(f"{v:.6g}" for v in result.speeds))
    return EXIT_OK


def _cmd_schedule(args: argparse.Namespace) -> int:
    scene = _scene(args, "schedule", "to design")
    result, check = design_scene_schedule(scene)
    written = write_schedule(result, _out_dir(args, scene))
    verified = schedule_check(result, check)
    if args.json:
        _print_json({**result.to_dict(), "exact_check": verified, "written": [str(p) for p in written]})
    else:
        for line in schedule_lines(result, check):
            print(line)
        print(f"wrote {', '.join(str(p) for p in written)}")
    return EXIT_OK


def _cmd_precision(args: argparse.Namespace) -> int:
    scene = _scene(args, "simulation", "(t_end, v0) to compare methods on")
    report = precision_report(scene_plant(scene), scene.simulation.t_end, v0=scene.simulation.v0,
                              repeats=args.repeats)
    written = write_precision(report, args.out) if args.out else []
    if args.json:
        _print_json(report.to_dict())
    else:
        print(f"{'method':8} {'setting':46} {'max_error':>10} {'final_error':>11} {'wall_time':>10} "
              f"{'evals':>8}  status")
        for row in report.rows:
            print(f"{row.method:8} {row.setting:46} {row.max_error:10.2e} {row.final_error:11.2e} "
                  f"{row.wall_time:10.2e} {row.n_evaluations:8d}  {row.status.name}{_flags(row)}")
        if any(row.method == "exact" for row in report.rows):
            speedup = exact_speedup(report)
            print(f"exact {speedup.exact.wall_time:.2e} s; fastest reference with max_error <= "
                  f"{speedup.error_level:g} m/s: " + (
                      f"{speedup.reference.label} {speedup.reference.wall_time:.2e} s, "
                      f"ratio {speedup.ratio:.1f}x" if speedup.reference is not None else "none"))
        if written:
            print(f"wrote {', '.join(str(p) for p in written)}")
    return EXIT_OK


def _flags(row: Any) -> str:
    names = [name for name in ("chattering", "step_collapse", "creep", "stalled") if getattr(row, name)]
    return f" [{', '.join(names)}]" if names else ""


def _cmd_stability(args: argparse.Namespace) -> int:
    report = stability_suite(quick=args.quick)
    if args.json:
        _print_json(report.to_dict())
    else:
        print(f"{'case':34} {'method':8} {'finished':>8} {'finite':>6} {'events':>8} {'wall_time':>10}  ok")
        for case in report.cases:
            print(f"{case.name:34} {case.method:8} {case.finished!s:>8} {case.finite!s:>6} "
                  f"{case.events:8d} {case.wall_time:10.2e}  {case.ok}")
        print("all cases ok" if report.all_ok else "SOME CASES FAILED")
    return EXIT_OK if report.all_ok else EXIT_FAILED


def _at_least(low: int) -> Callable[[str], int]:
    def convert(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"must be an integer >= {low}, got {text!r}") from None
        if value < low:
            raise argparse.ArgumentTypeError(f"must be an integer >= {low}, got {value}")
        return value

    return convert


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="active-contacts",
        description="Design, simulate and analyse friction created by active contacts.")
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    commands = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)

    def command(name: str, handler: Callable[[argparse.Namespace], int], help_text: str,
                scene: bool = True) -> argparse.ArgumentParser:
        sub = commands.add_parser(name, help=help_text, description=help_text)
        if scene:
            sub.add_argument("scene", metavar="SCENE", help="a scene file (TOML), e.g. designs/carousel.toml")
        sub.add_argument("--json", action="store_true", help="machine-readable output on stdout")
        sub.set_defaults(handler=handler)
        return sub

    run = command("run", _cmd_run, "run every stage the scene declares and write results and plots")
    run.add_argument("--out", metavar="DIR", help="output folder (default: out/<scene name>)")
    curve = command("curve", _cmd_curve, "print the force-speed curve of the scene's contacts")
    curve.add_argument("--points", type=_at_least(2), default=801, help="samples (default 801)")
    command("allocate", _cmd_allocate, "allocate contact speeds that realize the scene's [target]")
    schedule = command("schedule", _cmd_schedule,
                       "design the scene's [schedule] and write schedule.csv and schedule.json")
    schedule.add_argument("--out", metavar="DIR", help="output folder (default: out/<scene name>)")
    precision = command("precision", _cmd_precision,
                        "work-precision report: every simulation method against the exact one")
    precision.add_argument("--repeats", type=_at_least(1), default=3, help="timing repeats (default 3)")
    precision.add_argument("--out", metavar="DIR", help="also write precision.json and precision.png here")
    stability = command("stability", _cmd_stability,
                        "stability suite over stiff and extreme cases (exit 1 if a case fails)", scene=False)
    stability.add_argument("--quick", action="store_true", help="the smaller, faster set of cases")
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``active-contacts`` console script; returns the exit code."""
    parser = _parser()
    args = parser.parse_args(argv)
    try:
        return args.handler(args)
    except ToolkitError as error:
        print(f"active-contacts: error: {error}", file=sys.stderr)
        return EXIT_USAGE
    except OSError as error:  # an output folder that is a file, no permission, a full disk
        print(f"active-contacts: error: cannot write the output: {error}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        print("active-contacts: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    raise SystemExit(main())
