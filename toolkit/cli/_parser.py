"""The command line's argument parser: every subcommand, its flags and their types."""

from __future__ import annotations

import argparse
from collections.abc import Callable

from .. import __version__
from ._common import EXIT_CODES, EXIT_USAGE
from ._estimate import _cmd_estimate, _cmd_live
from ._shipped import _cmd_designs, _cmd_predict, _cmd_stability, _cmd_warm
from ._stages import _cmd_allocate, _cmd_curve, _cmd_precision, _cmd_run, _cmd_schedule, _cmd_sweep


def _bounded(name: str) -> Callable[[str], int]:
    """An integer flag with the bound of the scene key it also sets (:func:`~toolkit.scenes.spec.flag_limit`)
    or of its own entry in :data:`~toolkit.scenes.limits.FLAGS`."""
    from ..scenes.limits import FLAGS
    from ..scenes.spec import flag_limit
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
    from ..scenes.limits import FLAGS
    from ..scenes.spec import ReportSpec
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
    warm = command("warm", _cmd_warm, "compile and cache every kernel the shipped designs use (the kernels' "
                   "warm-ups in two processes at once, then each design run once, outputs discarded), so "
                   "that no later run waits for a compile", scene=False)
    warm.add_argument("--processes", type=int, choices=(1, 2), default=None,
                      help="processes that compile at once (default: 2 where this process may run on two "
                           "cores or more and fork, else 1)")
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
