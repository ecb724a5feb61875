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
from .errors import ToolkitError

__all__ = ["main"]

EXIT_OK, EXIT_FAILED, EXIT_USAGE = 0, 1, 2


def _print_json(data: Any) -> None:
    from .report import to_json

    sys.stdout.write(to_json(data))


def _cmd_run(args: argparse.Namespace) -> int:
    from .report import study_summary, study_to_dict, write_study
    from .scene import load_scene
    from .study import run_study

    scene = load_scene(args.scene)
    result = run_study(scene)
    out_dir = Path(args.out) if args.out else Path("out") / scene.name
    written = write_study(result, out_dir)
    if args.json:
        _print_json({**study_to_dict(result), "written": [str(p) for p in written]})
    else:
        for line in study_summary(result):
            print(line)
        print(f"wrote {', '.join(str(p) for p in written)}")
    return EXIT_OK


def _cmd_curve(args: argparse.Namespace) -> int:
    from .scene import load_scene
    from .study import force_curve

    scene = load_scene(args.scene)
    curve = force_curve(scene.contact_set(), args.points)
    if args.json:
        _print_json(curve.to_dict())
    else:
        lo, hi = curve.equilibrium
        print(f"F_tot = {curve.total_force:.6g} N; equilibrium [{lo:.6g}, {hi:.6g}] m/s")
        print(f"{'V (m/s)':>12} {'F (N)':>12}")
        for v, f in zip(curve.speeds[:: max(1, curve.speeds.size // 40)],
                        curve.force[:: max(1, curve.speeds.size // 40)]):
            print(f"{v:12.5f} {f:12.5f}")
    return EXIT_OK


def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be an integer >= 2, got {text!r}") from None
    if value < 2:
        raise argparse.ArgumentTypeError(f"must be an integer >= 2, got {value}")
    return value


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
    curve.add_argument("--points", type=_positive_int, default=801, help="samples (default 801)")
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
    except KeyboardInterrupt:
        print("active-contacts: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    raise SystemExit(main())
